//! The BVH finds exactly what testing every triangle finds, with the same triangle test.

mod common;

use common::*;
use glam::Vec3;
use strahl::Query;
use strahl::{
    BoxTest, BuildConfig, Camera, Coherence, HitStream, Ray, RayStream, Scene, TriangleTest, procedural, raygen,
};

fn check_scene(scene: &Scene, rays: &[Ray], what: &str) -> usize {
    let mut hits = 0;
    for (i, r) in rays.iter().enumerate() {
        let bvh = scene.intersect(r);
        let brute = scene.intersect_brute_force(r);
        assert_same_hit(bvh, brute, 1e-6, &format!("{what} ray {i}"));
        assert_eq!(scene.occluded(r), brute.is_some(), "{what} ray {i}: occluded");
        hits += brute.is_some() as usize;
    }
    hits
}

#[test]
fn random_soups_match_brute_force() {
    for (seed, n, size) in [(1, 10, 0.5), (2, 1000, 0.1), (3, 20_000, 0.02)] {
        let scene = scene_of(vec![random_soup(seed, n, size)]);
        let rays = random_rays(seed, 4000);
        let hits = check_scene(&scene, &rays, &format!("soup {n}"));
        assert!(hits > 100 && hits < rays.len(), "test rays should both hit and miss ({hits})");
    }
}

#[test]
fn every_build_preset_matches_brute_force() {
    let mesh = random_soup(9, 3000, 0.05);
    let rays = random_rays(9, 2000);
    for cfg in [
        BuildConfig::default(),
        BuildConfig::fast(),
        BuildConfig::high(),
        BuildConfig { min_leaf: 1, max_leaf: 1, ..BuildConfig::default() },
        BuildConfig { max_leaf: 60, ..BuildConfig::default() },
        BuildConfig { parallel_threshold: 64, ..BuildConfig::default() },
    ]
    .into_iter()
    .chain(TriangleTest::ALL.iter().flat_map(|&t| BoxTest::ALL.map(|b| BuildConfig::default().with_tests(t, b))))
    {
        let scene = Scene::build(vec![mesh.clone()], &cfg).unwrap();
        check_scene(&scene, &rays, &format!("{cfg:?}"));
    }
}

#[test]
fn tied_and_flat_geometry_matches_brute_force() {
    // A grid of coplanar quads (flat boxes, shared edges) hit by axis-parallel and grazing rays.
    let mut p = Vec::new();
    let mut idx = Vec::new();
    for j in 0..20 {
        for i in 0..20 {
            let b = p.len() as u32;
            let (x, z) = (i as f32 * 0.1, j as f32 * 0.1);
            p.extend([
                Vec3::new(x, 0.0, z),
                Vec3::new(x + 0.1, 0.0, z),
                Vec3::new(x + 0.1, 0.0, z + 0.1),
                Vec3::new(x, 0.0, z + 0.1),
            ]);
            idx.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        }
    }
    let scene = scene_of(vec![strahl::TriangleMesh::new("grid", p, idx).unwrap()]);
    let mut rays = Vec::new();
    let mut rng = strahl::raygen::Pcg32::new(4, 4);
    for _ in 0..3000 {
        let o = Vec3::new(rng.next_f32() * 2.0, 1.0, rng.next_f32() * 2.0);
        rays.push(Ray::new(o, Vec3::new(0.0, -1.0, 0.0)));
        rays.push(Ray::new(o, Vec3::new(rng.next_f32() - 0.5, -1.0, rng.next_f32() - 0.5)));
    }
    let hits = check_scene(&scene, &rays, "grid");
    assert!(hits > 2000);
}

#[test]
fn real_meshes_match_brute_force() {
    let mut scenes: Vec<(String, Scene, Camera)> = Vec::new();
    let cornell = Scene::from_obj(data("cornell_box.obj"), &BuildConfig::default()).unwrap();
    assert_eq!(cornell.triangle_count(), 32);
    let cam = Camera::look_at(Vec3::new(278.0, 273.0, -450.0), Vec3::new(278.0, 273.0, 0.0), Vec3::Y, 60.0);
    scenes.push(("cornell".into(), cornell, cam));
    let flake = scene_of(vec![procedural::sphereflake(2, 6, 12)]);
    let cam = Camera::look_at(Vec3::new(0.0, 1.2, 4.5), Vec3::new(0.0, 0.3, 0.0), Vec3::Y, 60.0);
    scenes.push(("sphereflake".into(), flake, cam));
    if let Some(p) = shared_scene("bunny/bunny.obj") {
        let cam = Camera::look_at(Vec3::new(-0.017, 0.13, 0.17), Vec3::new(-0.017, 0.10, 0.0), Vec3::Y, 60.0);
        scenes.push(("bunny".into(), Scene::from_obj(p, &BuildConfig::default()).unwrap(), cam));
    }
    for (name, scene, cam) in &scenes {
        let (primary, _) = raygen::primary(cam, 48, 48);
        let rays: Vec<Ray> = (0..primary.len()).map(|i| primary.get(i)).collect();
        let hits = check_scene(scene, &rays, name);
        assert!(hits > 0, "{name}: the camera should see the scene");
        // Secondary rays from the hit points, with a tiny tnear, exercise rays starting on surfaces.
        let mut h = HitStream::default();
        scene.intersect_stream(&primary, &mut h, Coherence::Incoherent);
        let diag = scene.bounds().map(|(lo, hi)| (hi - lo).length()).unwrap();
        let (diffuse, _) = raygen::diffuse(&primary, &h, 5, 1e-4 * diag);
        let (shadow, _) = raygen::shadow(&primary, &h, cam.eye + Vec3::Y * diag * 0.3, 1e-4 * diag);
        for s in [&diffuse, &shadow] {
            let rays: Vec<Ray> = (0..s.len()).map(|i| s.get(i)).collect();
            check_scene(scene, &rays, name);
        }
    }
}

#[test]
fn far_from_origin_matches_brute_force() {
    for offset in [1e3f32, 1e4, 1e5, 1e6] {
        let mut mesh = random_soup(21, 2000, 0.05);
        let shift = Vec3::new(offset, -offset * 0.5, offset * 0.25);
        mesh.map_positions(|p| p + shift);
        let rays: Vec<Ray> = random_rays(21, 2000).into_iter().map(|r| Ray::new(r.origin + shift, r.dir)).collect();
        // The conservative box test loses nothing the triangle test finds, for every method whose
        // hits lie inside the triangle's box. Badouel intersects the plane first: beyond an offset
        // of 1e4 its t is off by more than the triangles' size (n·v0 cancels), so it reports hits
        // outside the triangle that no traversal would enter; the accuracy report measures that.
        for t in TriangleTest::ALL.into_iter().filter(|&t| t != TriangleTest::Badouel || offset <= 1e4) {
            let cfg = BuildConfig::default().with_tests(t, BoxTest::Conservative);
            let scene = Scene::build(vec![mesh.clone()], &cfg).unwrap();
            check_scene(&scene, &rays, &format!("offset {offset} {t:?}"));
        }
    }
}

#[test]
fn streams_of_any_length() {
    let scene = scene_of(vec![random_soup(3, 500, 0.1)]);
    for n in [0usize, 1, 15, 16, 17, 4097] {
        let rays: RayStream = random_rays(n as u64, n).into_iter().collect();
        let mut hits = HitStream::default();
        scene.intersect_stream_par(&rays, &mut hits, Coherence::Coherent);
        assert_eq!(hits.len(), n);
        for i in 0..n {
            assert_same_hit(hits.get(i), scene.intersect_brute_force(&rays.get(i)), 1e-6, "stream");
        }
    }
}

#[test]
fn geometry_ids_for_every_method() {
    // Three unit spheres along x; a ray down onto each must report that sphere's geometry id.
    let meshes: Vec<_> =
        (0..3).map(|g| procedural::uv_sphere(Vec3::new(3.0 * g as f32, 0.0, 0.0), 1.0, 8, 16)).collect();
    for t in TriangleTest::ALL {
        let scene = Scene::build(meshes.clone(), &BuildConfig::default().with_tests(t, BoxTest::Conservative)).unwrap();
        for g in 0..3u32 {
            let r = Ray::new(Vec3::new(3.0 * g as f32 + 0.1, 5.0, 0.05), Vec3::new(0.0, -1.0, 0.0));
            let h = scene.intersect(&r).unwrap_or_else(|| panic!("{t:?}: sphere {g} missed"));
            assert_eq!(h.geom_id, g, "{t:?}");
            assert!(h.ng.normalize().y > 0.5, "{t:?}: the normal of the top of a sphere points up: {}", h.ng);
        }
    }
}

#[test]
fn negative_and_signed_zero_tnear_match_brute_force() {
    // A negative `tnear` counts as 0 (`Ray`'s interval rule); rays with a negative `tnear`,
    // starting at `-0.0`, or bounded on both sides must find what brute force finds, and a
    // segment wholly behind the origin finds nothing.
    for test in TriangleTest::ALL {
        for boxes in BoxTest::ALL {
            let scene =
                Scene::build(vec![random_soup(21, 5000, 0.05)], &BuildConfig::default().with_tests(test, boxes))
                    .unwrap();
            for (k, (tnear, tfar)) in
                [(-0.0, f32::INFINITY), (-0.5, f32::INFINITY), (f32::NEG_INFINITY, 0.3), (-2.0, -0.5), (0.2, 0.6)]
                    .into_iter()
                    .enumerate()
            {
                // A segment wholly behind the origin: turn the ray around, so it still crosses the soup.
                let flip = if tfar < 0.0 { -1.0 } else { 1.0 };
                let rays: Vec<Ray> = random_rays(30 + k as u64, 1500)
                    .into_iter()
                    .map(|r| Ray { tnear, tfar, dir: r.dir * flip, ..r })
                    .collect();
                let hits = check_scene(&scene, &rays, &format!("{test:?} {boxes:?} ({tnear}, {tfar})"));
                if tfar < 0.0 {
                    assert_eq!(hits, 0, "{test:?} ({tnear}, {tfar}): behind the origin");
                } else {
                    assert!(hits > 10, "{test:?} ({tnear}, {tfar}): {hits} hits");
                }
            }
        }
    }
}

#[test]
fn spatial_splits_match_brute_force() {
    // Long thin triangles across the scene make spatial splits worth it: each is referenced on
    // several sides of the planes that cut it, each reference bounded by its part only. Near the
    // origin and 1e5 away (the clipped parts' padding must cover the rounding there too).
    for offset in [0.0f32, 1e5] {
        let mut rng = strahl::raygen::Pcg32::new(21, 5);
        let mut p = Vec::new();
        let mut idx = Vec::new();
        for i in 0..1500u32 {
            let a = rng_vec(&mut rng, -1.0, 1.0);
            let long = rng_vec(&mut rng, -1.5, 1.5);
            let thin = rng_vec(&mut rng, -0.02, 0.02);
            let o = Vec3::splat(offset);
            p.extend([o + a, o + a + long, o + a + long * 0.5 + thin]);
            idx.push([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        let mesh = strahl::TriangleMesh::new("slivers", p, idx).unwrap();
        let rays: Vec<Ray> =
            random_rays(22, 3000).into_iter().map(|r| Ray { origin: r.origin + Vec3::splat(offset), ..r }).collect();
        for (t, b) in TriangleTest::ALL.iter().flat_map(|&t| BoxTest::ALL.map(|b| (t, b))) {
            // Far from the origin, the fast box test lets rays slip between boxes, and Badouel's
            // test (plane distance, then projected barycentrics) accepts points up to ~0.01 off
            // these 0.02-wide slivers, outside any box of the triangle: both fail without spatial
            // splits too (`far_from_origin_matches_brute_force` has no slivers).
            if offset != 0.0 && (b == BoxTest::Fast || t == TriangleTest::Badouel) {
                continue;
            }
            let cfg = BuildConfig::high().with_tests(t, b);
            let scene = Scene::build(vec![mesh.clone()], &cfg).unwrap();
            let st = scene.stats();
            assert_eq!(st.triangles + st.skipped_triangles, 1500);
            assert!(
                st.references > st.triangles && st.references as f32 <= 1.2 * st.triangles as f32 + 64.0,
                "spatial splits should copy some references, within the budget: {} of {}",
                st.references,
                st.triangles
            );
            let plain = Scene::build(vec![mesh.clone()], &BuildConfig::default().with_tests(t, b)).unwrap();
            assert!(st.sah < plain.stats().sah, "SAH {} with spatial splits vs {} without", st.sah, plain.stats().sah);
            let hits = check_scene(&scene, &rays, &format!("spatial {t:?} {b:?} offset {offset}"));
            assert!(hits > 300, "{hits}");
        }
    }
}

#[test]
fn interleaved_meshes_report_their_own_triangles() {
    // A 40 × 40 grid of small triangles on z = 0, cell k in mesh (k · 7) mod 13 of 16 meshes
    // (meshes 0, 6 and 15 empty), so that leaves mix meshes and the builder's fill has to find
    // each triangle's mesh. A ray straight down onto each cell must report that cell's mesh and
    // its index there: the brute force walks the same blocks, so it cannot catch a block filled
    // from the wrong mesh.
    const N: usize = 40;
    let full = [1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12, 13, 14];
    let mut meshes: Vec<(Vec<Vec3>, Vec<[u32; 3]>)> = vec![(Vec::new(), Vec::new()); 16];
    let mut expect = Vec::new();
    for k in 0..N * N {
        let (x, y) = ((k % N) as f32, (k / N) as f32);
        let g = full[k * 7 % full.len()];
        let (p, idx) = &mut meshes[g];
        let base = p.len() as u32;
        p.extend([Vec3::new(x, y, 0.0), Vec3::new(x + 0.8, y, 0.0), Vec3::new(x, y + 0.8, 0.0)]);
        expect.push((Vec3::new(x + 0.2, y + 0.2, 1.0), g as u32, idx.len() as u32));
        idx.push([base, base + 1, base + 2]);
    }
    let meshes: Vec<_> = meshes
        .into_iter()
        .enumerate()
        .map(|(g, (p, i))| strahl::TriangleMesh::new(format!("m{g}"), p, i).unwrap())
        .collect();
    for cfg in [
        BuildConfig::default(),
        BuildConfig::fast(),
        BuildConfig::high(),
        BuildConfig { parallel_threshold: 64, ..BuildConfig::default() },
    ] {
        let scene = Scene::build(meshes.clone(), &cfg).unwrap();
        for &(o, g, p) in &expect {
            let h = scene
                .intersect(&Ray::new(o, Vec3::NEG_Z))
                .unwrap_or_else(|| panic!("{cfg:?}: cell of mesh {g} missed"));
            assert_eq!((h.geom_id, h.prim_id), (g, p), "{cfg:?}");
            assert!((h.t - 1.0).abs() < 1e-6, "{cfg:?}: t {}", h.t);
        }
    }
}
