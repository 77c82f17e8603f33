//! Serialized scenes (what a Python pickle carries): `Scene::from_bytes` and
//! `InstancedScene::from_bytes` answer with a scene or `Error::Serialized`, never a panic, hang
//! or abort; a loaded scene writes back the same bytes (a two-level one, bytes that load back
//! to themselves) and answers every query kind.
#![no_main]

use glam::Vec3;
use libfuzzer_sys::fuzz_target;
use strahl::query::SpatialQuery;
use strahl::{Coherence, HitStream, InstancedScene, Ray, RayStream, Scene};

/// A few rays through the scene's box, and one point, through every query kind.
fn exercise<Q: SpatialQuery>(q: &Q, bounds: Option<(Vec3, Vec3)>) {
    let (lo, hi) = bounds.unwrap_or((Vec3::splat(-1.0), Vec3::splat(1.0)));
    let (lo, hi) = (lo.clamp(Vec3::splat(-1e6), Vec3::splat(1e6)), hi.clamp(Vec3::splat(-1e6), Vec3::splat(1e6)));
    let c = (lo + hi) * 0.5;
    let rays: RayStream = (0..24)
        .map(|i| {
            let a = i as f32 * 0.7;
            Ray::new(c + Vec3::new(a.cos(), 0.5, a.sin()) * (hi - lo).length().max(1.0), Vec3::new(-a.cos(), -0.3, -a.sin()))
        })
        .collect();
    let mut hits = HitStream::default();
    q.intersect_stream(&rays, &mut hits, Coherence::Coherent);
    q.intersect_stream(&rays, &mut hits, Coherence::Incoherent);
    let mut occ = Vec::new();
    q.occluded_stream(&rays, &mut occ, Coherence::Incoherent);
    let mut all = Vec::new();
    for i in 0..4 {
        let r = rays.get(i);
        let _ = (q.intersect(&r), q.occluded(&r));
        q.crossings(&r, &mut all);
    }
    let _ = (q.closest_point(c, f32::INFINITY), q.contains(c), q.signed_distance(c));
}

fuzz_target!(|data: &[u8]| {
    if data.starts_with(b"STRAHLIN") {
        if let Ok(s) = InstancedScene::from_bytes(data) {
            // The objects' prefetch flags are decided anew for the placed whole, so the bytes
            // written back may differ from the input in them; written once, they stay.
            let once = s.to_bytes();
            let again = InstancedScene::from_bytes(&once).expect("a written two-level scene loads").to_bytes();
            assert_eq!(once, again, "a two-level scene's bytes are stable");
            exercise(&s, s.bounds());
        }
    } else if let Ok(s) = Scene::from_bytes(data) {
        // Version 1 and 2 bytes (no sphere or solid section) are read and written back as the
        // current version.
        let once = s.to_bytes();
        if data.get(8..12) == Some(&once[8..12]) {
            assert_eq!(once, data, "a loaded scene writes back its bytes");
        } else {
            let again = Scene::from_bytes(&once).expect("a written scene loads").to_bytes();
            assert_eq!(once, again, "a scene's bytes are stable once written");
        }
        exercise(&s, s.bounds());
    }
});
