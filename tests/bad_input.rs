//! Bad input gets a typed error or a defined answer, never a panic.

mod common;

use common::*;
use glam::Vec3;
use strahl::Query;
use strahl::{BuildConfig, Coherence, Error, HitPacket, HitStream, Ray, RayPacket, RayStream, Scene, TriangleMesh};

fn tmp(name: &str, text: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("strahl-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn bad_rays() -> Vec<Ray> {
    let o = Vec3::new(0.1, 0.1, 5.0);
    let d = Vec3::new(0.0, 0.0, -1.0);
    vec![
        Ray::new(o, Vec3::ZERO),
        Ray::new(o, Vec3::new(f32::NAN, 0.0, -1.0)),
        Ray::new(Vec3::new(f32::NAN, 0.0, 0.0), d),
        Ray::new(Vec3::new(f32::INFINITY, 0.0, 0.0), d),
        Ray::new(o, Vec3::new(0.0, 0.0, f32::NEG_INFINITY)),
        Ray::segment(o, d, 6.0, 1.0),
        Ray::segment(o, d, f32::NAN, 10.0),
        Ray::segment(o, d, 0.0, f32::NAN),
    ]
}

fn answers_bad_rays_with_misses(scene: &Scene) {
    let rays = bad_rays();
    for r in &rays {
        assert!(scene.intersect(r).is_none(), "{r:?}");
        assert!(!scene.occluded(r), "{r:?}");
    }
    let p = RayPacket::from_rays(&rays);
    let mut hp = HitPacket::default();
    scene.intersect_packet(&p, &mut hp);
    assert!((0..rays.len()).all(|l| hp.get(l).is_none()));
    assert_eq!(scene.occluded_packet(&p), 0);
    let s: RayStream = rays.iter().copied().collect();
    for c in [Coherence::Coherent, Coherence::Incoherent] {
        let mut h = HitStream::default();
        scene.intersect_stream_par(&s, &mut h, c);
        assert!((0..s.len()).all(|i| h.get(i).is_none()));
        let mut o = Vec::new();
        scene.occluded_stream(&s, &mut o, c);
        assert!(o.iter().all(|&x| !x));
    }
}

#[test]
fn bad_rays_miss_a_real_scene() {
    let scene = Scene::from_obj(data("cornell_box.obj"), &BuildConfig::default()).unwrap();
    answers_bad_rays_with_misses(&scene);
    let unit = scene_of(vec![
        TriangleMesh::from_slices("t", &[-1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0, 0.0], &[0, 1, 2]).unwrap(),
    ]);
    answers_bad_rays_with_misses(&unit);
    // The same origin and direction with a good interval does hit.
    assert!(unit.intersect(&Ray::new(Vec3::new(0.1, 0.1, 5.0), Vec3::new(0.0, 0.0, -1.0))).is_some());
}

#[test]
fn empty_scenes_miss_everything() {
    for meshes in [vec![], vec![TriangleMesh::default()], vec![TriangleMesh::from_slices("e", &[], &[]).unwrap()]] {
        let scene = scene_of(meshes);
        assert!(scene.bounds().is_none());
        assert_eq!(scene.stats().triangles, 0);
        let r = Ray::new(Vec3::ZERO, Vec3::X);
        assert!(scene.intersect(&r).is_none() && !scene.occluded(&r));
        let mut h = HitStream::default();
        scene.intersect_stream_par(&random_rays(1, 100).into_iter().collect(), &mut h, Coherence::Coherent);
        assert!((0..100).all(|i| h.get(i).is_none()));
        answers_bad_rays_with_misses(&scene);
    }
}

#[test]
fn nan_and_degenerate_triangles_are_skipped_not_hit() {
    let nan = f32::NAN;
    let inf = f32::INFINITY;
    #[rustfmt::skip]
    let p = [
        -1.0, -1.0, 0.0,  1.0, -1.0, 0.0,  0.0, 1.0, 0.0,   // 0..3: a good triangle at z = 0
        nan, 0.0, -1.0,   1.0, 0.0, -1.0,  0.0, 1.0, -1.0,  // 3..6: NaN corner at z = -1
        -1.0, -1.0, 1.0,  inf, -1.0, 1.0,  0.0, 1.0, 1.0,   // 6..9: infinite corner at z = 1
        -1.0, 0.0, 2.0,   0.0, 0.0, 2.0,   1.0, 0.0, 2.0,   // 9..12: collinear at z = 2
    ];
    let idx = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 0, 0, 0];
    let scene = scene_of(vec![TriangleMesh::from_slices("m", &p, &idx).unwrap()]);
    assert_eq!(scene.stats().triangles, 1);
    assert_eq!(scene.stats().skipped_triangles, 4);
    let (lo, hi) = scene.bounds().unwrap();
    assert!(lo.is_finite() && hi.is_finite());
    // From above, through all four layers: only the good triangle is ever hit.
    let hit = scene.intersect(&Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::new(0.0, 0.0, -1.0))).unwrap();
    assert_eq!(hit.prim_id, 0);
    assert!(!hit.t.is_nan() && !hit.u.is_nan() && hit.ng.is_finite());
}

#[test]
fn malformed_obj_files_are_errors() {
    assert!(matches!(Scene::from_obj("/no/such/file.obj", &BuildConfig::default()), Err(Error::Io { .. })));
    let p = tmp("garbage.obj", "v 1 2\nf 1 2 3\n");
    assert!(Scene::from_obj(&p, &BuildConfig::default()).is_err());
    let p = tmp("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
    assert!(Scene::from_obj(&p, &BuildConfig::default()).is_err());
    let p = tmp("binary.obj", "\u{0}\u{1}\u{2}garbage\u{ff}");
    let r = Scene::from_obj(&p, &BuildConfig::default());
    // Either an error or an empty scene: never a panic.
    if let Ok(s) = r {
        assert_eq!(s.stats().triangles, 0);
    }
    let p = tmp("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 0\nf 1 2 3\nf 4 2 3\n");
    if let Ok(s) = Scene::from_obj(&p, &BuildConfig::default()) {
        assert_eq!(s.stats().triangles, 1);
    }
}

#[test]
fn out_of_range_indices_are_typed_errors() {
    let e = TriangleMesh::from_slices("m", &[0.0; 9], &[0, 1, 7]).unwrap_err();
    assert!(matches!(e, Error::IndexOutOfRange { index: 7, .. }), "{e}");
}

#[test]
fn tiny_and_signed_zero_directions_give_finite_hits() {
    let scene = scene_of(vec![
        TriangleMesh::from_slices("t", &[-1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0, 0.0], &[0, 1, 2]).unwrap(),
    ]);
    for d in [
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::new(-0.0, -0.0, -1.0),
        Vec3::new(1e-30, -1e-30, -1.0),
        Vec3::new(-0.0, 1e-38, -1e-3),
    ] {
        // Origins exactly on the bounding box planes (x = ±1, y = −1, y = 1).
        for o in
            [Vec3::new(0.0, 0.0, 3.0), Vec3::new(-1.0, -1.0, 3.0), Vec3::new(0.0, 1.0, 3.0), Vec3::new(0.2, -1.0, 3.0)]
        {
            let r = Ray::new(o, d);
            let h = scene.intersect(&r);
            let b = scene.intersect_brute_force(&r);
            assert_same_hit(h, b, 1e-6, "tiny dir");
            if let Some(h) = h {
                assert!(h.t.is_finite() && h.u.is_finite() && h.v.is_finite());
            }
        }
        assert!(scene.intersect(&Ray::new(Vec3::new(0.0, 0.0, 3.0), d)).is_some(), "{d}");
    }
}
