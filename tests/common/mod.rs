//! Helpers shared by the integration tests: seeded random meshes and rays, and comparison of hits.
#![allow(dead_code)]

use std::path::PathBuf;

use glam::Vec3;
use strahl::raygen::Pcg32;
use strahl::{Hit, Ray, Scene, TriangleMesh};

pub fn rng_vec(rng: &mut Pcg32, lo: f32, hi: f32) -> Vec3 {
    Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * (hi - lo) + Vec3::splat(lo)
}

/// `n` random triangles with corners near random centres in `[-1, 1]³`, sizes up to `size`.
pub fn random_soup(seed: u64, n: usize, size: f32) -> TriangleMesh {
    let mut rng = Pcg32::new(seed, 11);
    let mut p = Vec::with_capacity(3 * n);
    let mut idx = Vec::with_capacity(n);
    for i in 0..n {
        let c = rng_vec(&mut rng, -1.0, 1.0);
        for _ in 0..3 {
            p.push(c + rng_vec(&mut rng, -size, size));
        }
        let b = 3 * i as u32;
        idx.push([b, b + 1, b + 2]);
    }
    TriangleMesh::new("soup", p, idx).unwrap()
}

/// Rays from random points in `[-2, 2]³` towards random points in `[-1, 1]³`.
pub fn random_rays(seed: u64, n: usize) -> Vec<Ray> {
    let mut rng = Pcg32::new(seed, 12);
    (0..n)
        .map(|_| {
            let o = rng_vec(&mut rng, -2.0, 2.0);
            let t = rng_vec(&mut rng, -1.0, 1.0);
            Ray::new(o, t - o)
        })
        .collect()
}

/// A shared benchmark scene, if this checkout has `../shared/scenes` beside it.
pub fn shared_scene(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes").join(rel);
    p.exists().then_some(p)
}

pub fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data").join(rel)
}

/// Two closest-hit answers agree: same hit/miss; same primitive, or a different one at the same
/// distance (a tie between triangles sharing the hit point); t within `rel` relative.
pub fn assert_same_hit(a: Option<Hit>, b: Option<Hit>, rel: f32, what: &str) {
    match (a, b) {
        (None, None) => {}
        (Some(a), Some(b)) => {
            let tol = rel * a.t.abs().max(b.t.abs()).max(f32::MIN_POSITIVE);
            assert!((a.t - b.t).abs() <= tol, "{what}: t {} vs {}", a.t, b.t);
            if (a.geom_id, a.prim_id) != (b.geom_id, b.prim_id) {
                assert_eq!(a.t, b.t, "{what}: different primitives at different distances: {a:?} vs {b:?}");
            } else {
                // The same triangle: the same record (normal and instance exactly, the
                // barycentrics within the depth tolerance's share).
                assert_eq!((a.ng, a.inst_id), (b.ng, b.inst_id), "{what}: normal or instance differ: {a:?} vs {b:?}");
                let uv_tol = rel.max(f32::EPSILON) * 4.0;
                assert!(
                    (a.u - b.u).abs() <= uv_tol && (a.v - b.v).abs() <= uv_tol,
                    "{what}: barycentrics differ: {a:?} vs {b:?}"
                );
            }
        }
        _ => panic!("{what}: hit/miss differ: {a:?} vs {b:?}"),
    }
}

pub fn scene_of(meshes: Vec<TriangleMesh>) -> Scene {
    Scene::build(meshes, &strahl::BuildConfig::default()).unwrap()
}
