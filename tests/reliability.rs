//! Regression tests for the hostile-input findings of issue 33: each input once broke a promise
//! (a panic on a valid ray, a hit the BVH lost that brute force finds, a hit outside the query
//! interval). See RELIABILITY.md.

mod common;

use common::*;
use glam::Vec3;
use strahl::{
    BoxTest, BuildConfig, Coherence, HitPacket, HitStream, Query, Ray, RayPacket, RayStream, Scene, TriangleMesh,
    TriangleTest, procedural,
};

/// Every query shape answers `rays` on `scene` as brute force does (hit or miss, and `t` within
/// `rel` where both hit); occlusion agrees with the closest hit.
fn agrees_with_brute_force(scene: &Scene, rays: &[Ray], rel: f32, what: &str) {
    for (i, r) in rays.iter().enumerate() {
        let b = scene.intersect_brute_force(r);
        let s = scene.intersect(r);
        assert_eq!(s.is_some(), b.is_some(), "{what}: ray {i} {r:?}: single {s:?} brute force {b:?}");
        if let (Some(s), Some(b)) = (s, b) {
            assert!((s.t - b.t).abs() <= rel * b.t.abs(), "{what}: ray {i}: t {} vs {}", s.t, b.t);
        }
        assert_eq!(scene.occluded(r), b.is_some(), "{what}: ray {i} occluded");
    }
    for chunk in rays.chunks(16) {
        let p = RayPacket::from_rays(chunk);
        let mut hp = HitPacket::default();
        scene.intersect_packet(&p, &mut hp);
        let occ = scene.occluded_packet(&p);
        for (l, r) in chunk.iter().enumerate() {
            let b = scene.intersect_brute_force(r).is_some();
            assert_eq!(hp.get(l).is_some(), b, "{what}: packet lane {l} {r:?}");
            assert_eq!(occ & (1 << l) != 0, b, "{what}: occluded packet lane {l} {r:?}");
        }
    }
    let s: RayStream = rays.iter().copied().collect();
    for c in [Coherence::Coherent, Coherence::Incoherent] {
        let mut h = HitStream::default();
        scene.intersect_stream(&s, &mut h, c);
        let mut o = Vec::new();
        scene.occluded_stream(&s, &mut o, c);
        for (i, r) in rays.iter().enumerate() {
            let b = scene.intersect_brute_force(r).is_some();
            assert_eq!(h.get(i).is_some(), b, "{what}: stream {c:?} ray {i} {r:?}");
            assert_eq!(o[i], b, "{what}: occluded stream {c:?} ray {i} {r:?}");
        }
    }
}

/// Every triangle test with the conservative box test (the one that promises to lose no hit).
fn configs() -> Vec<BuildConfig> {
    TriangleTest::ALL.iter().map(|&t| BuildConfig::default().with_tests(t, BoxTest::Conservative)).collect()
}

/// Finding 1: a ray far from the scene, parallel to two axes, with a negative `tnear` panicked in
/// the single-ray walk (an empty child slot entered through NaN slab distances).
#[test]
fn far_origins_parallel_to_axes_do_not_panic() {
    let scene = scene_of(vec![procedural::uv_sphere(Vec3::ZERO, 1.0, 16, 32)]);
    for z in [-1e21f32, -3e20, 1e25, -1e38, 3.0e38] {
        for tnear in [-1.0f32, 0.0, -1e30] {
            for dir in [Vec3::Y, Vec3::X, -Vec3::Y, Vec3::new(0.0, 1.0, 1e-30)] {
                let r = Ray::segment(Vec3::new(0.0, 0.0, z), dir, tnear, f32::INFINITY);
                agrees_with_brute_force(&scene, &[r], 1e-5, "far origin");
            }
        }
    }
}

/// Finding 2: rays reaching behind their origin. Negative `tnear` is clamped to 0 (Embree's
/// valid range starts there too), in every query and in brute force: the hit at t ≈ −12.1 is no
/// hit of the interval [−1000, 0], and the same ray over [−1000, 20] finds the hit ahead of it.
#[test]
fn negative_tnear_is_clamped_to_zero_everywhere() {
    let quad = TriangleMesh::from_slices(
        "x7",
        &[7.0, -1.0, -1.0, 7.0, 1.0, -1.0, 7.0, 1.0, 1.0, 7.0, -1.0, 1.0],
        &[0, 1, 2, 0, 2, 3],
    )
    .unwrap();
    let back = TriangleMesh::from_slices(
        "x-7",
        &[-7.0, -1.0, -1.0, -7.0, 1.0, -1.0, -7.0, 1.0, 1.0, -7.0, -1.0, 1.0],
        &[0, 1, 2, 0, 2, 3],
    )
    .unwrap();
    for config in configs() {
        let scene = Scene::build(vec![quad.clone(), back.clone()], &config).unwrap();
        let o = Vec3::new(19.1, 0.2, 0.3);
        let behind = Ray::segment(o, Vec3::X, -1000.0, 0.0);
        assert!(scene.intersect_brute_force(&behind).is_none());
        agrees_with_brute_force(&scene, &[behind], 1e-6, "behind");
        let ahead = Ray::segment(Vec3::ZERO, Vec3::X, -1000.0, 20.0);
        assert!((scene.intersect(&ahead).unwrap().t - 7.0).abs() < 1e-5);
        let mut rays = vec![behind, ahead];
        let mut rng = strahl::raygen::Pcg32::new(7, 1);
        for _ in 0..200 {
            let o = rng_vec(&mut rng, -10.0, 10.0);
            let d = rng_vec(&mut rng, -1.0, 1.0);
            let tn = -100.0 * rng.next_f32();
            rays.push(Ray::segment(o, d, tn, 100.0 * rng.next_f32() - 20.0));
        }
        agrees_with_brute_force(&scene, &rays, 1e-5, "negative tnear");
    }
}

/// Möller–Trumbore in float64 over the float32 inputs: `(t, smallest barycentric)`.
fn exact(r: &Ray, tri: [Vec3; 3]) -> Option<(f64, f64)> {
    let v = |p: Vec3| [p.x as f64, p.y as f64, p.z as f64];
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross =
        |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (o, d) = (v(r.origin), v(r.dir));
    let (p0, p1, p2) = (v(tri[0]), v(tri[1]), v(tri[2]));
    let (e1, e2) = (sub(p1, p0), sub(p2, p0));
    let p = cross(d, e2);
    let det = dot(e1, p);
    if det == 0.0 {
        return None;
    }
    let s = sub(o, p0);
    let u = dot(s, p) / det;
    let q = cross(s, e1);
    let w = dot(d, q) / det;
    let t = dot(e2, q) / det;
    let m = u.min(w).min(1.0 - u - w);
    (m >= 0.0 && t > r.tnear.max(0.0) as f64 && t <= r.tfar as f64).then_some((t, m))
}

/// The float64 closest hit of `r` over `mesh`, if it lies at least `margin` (barycentric) inside
/// its triangle.
fn clear_hit(mesh: &TriangleMesh, r: &Ray, margin: f64) -> Option<f64> {
    let p = mesh.positions();
    let best = mesh
        .indices()
        .iter()
        .filter_map(|i| exact(r, [p[i[0] as usize], p[i[1] as usize], p[i[2] as usize]]))
        .min_by(|a, b| a.0.total_cmp(&b.0))?;
    (best.1 >= margin).then_some(best.0)
}

/// Finding 3: a mesh with one far outlier vertex and rays from about 1e28–1e31 away. The
/// promise is about geometry: a ray whose float64 hit lies clearly inside a triangle is found by
/// every query, at a `t` near the float64 one. (Float32 triangle tests this far out compute
/// barycentrics with errors of order one; brute force with them is no reference here. Badouel's
/// test projects the hit point `o + t·d`, which loses everything below `|o|`'s last place: at
/// 1e28 it accepts and rejects at random, BVH or not, and is left out.)
#[test]
fn far_outliers_and_far_origins_lose_no_hits() {
    let mut soup = random_soup(3, 300, 0.2);
    let (mut p, mut idx) = (soup.positions().to_vec(), soup.indices().to_vec());
    let n = p.len() as u32;
    p.extend([Vec3::new(0.0, 0.0, 5e30), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)]);
    idx.push([n, n + 1, n + 2]);
    // Beyond `MAX_COORDINATE` (finding 4) the mesh is refused; the outlier goes to the bound.
    assert!(matches!(
        TriangleMesh::new("outlier", p.clone(), idx.clone()),
        Err(strahl::Error::CoordinateOutOfRange { vertex: 900, .. })
    ));
    p[n as usize].z = strahl::MAX_COORDINATE;
    soup = TriangleMesh::new("outlier", p, idx).unwrap();
    let mut rng = strahl::raygen::Pcg32::new(9, 2);
    let mut rays = Vec::new();
    let mut t64 = Vec::new();
    for k in 0..2000u32 {
        let far = 10f32.powi(28 + (k % 4) as i32) * if k % 8 < 4 { 1.0 } else { -1.0 };
        let o = match k % 3 {
            0 => Vec3::new(far, 0.0, 0.0),
            1 => Vec3::new(0.0, far, 0.0),
            _ => Vec3::new(0.0, 0.0, far),
        } + rng_vec(&mut rng, -1.0, 1.0);
        let i = soup.indices()[(k % 300) as usize];
        let c =
            (soup.positions()[i[0] as usize] + soup.positions()[i[1] as usize] + soup.positions()[i[2] as usize]) / 3.0;
        let r = Ray::new(o, c - o);
        if let Some(t) = clear_hit(&soup, &r, 0.05) {
            rays.push(r);
            t64.push(t);
        }
    }
    assert!(rays.len() > 500, "{} clear rays", rays.len());
    for config in configs().into_iter().filter(|c| c.triangle_test != TriangleTest::Badouel) {
        let scene = Scene::build(vec![soup.clone()], &config).unwrap();
        let what = format!("far outlier, {:?}", config.triangle_test);
        let s: RayStream = rays.iter().copied().collect();
        let mut h = HitStream::default();
        scene.intersect_stream(&s, &mut h, Coherence::Incoherent);
        let mut o = Vec::new();
        scene.occluded_stream(&s, &mut o, Coherence::Incoherent);
        let mut lost = Vec::new();
        for (i, r) in rays.iter().enumerate() {
            let single = scene.intersect(r);
            let ok = |t: Option<f32>| t.is_some_and(|t| ((t as f64 - t64[i]) / t64[i]).abs() < 1e-3);
            if !ok(single.map(|h| h.t)) || !ok(h.get(i).map(|h| h.t)) || !scene.occluded(r) || !o[i] {
                lost.push((i, single, scene.intersect_brute_force(r).map(|h| h.t), t64[i]));
            }
        }
        assert!(
            lost.is_empty(),
            "{what}: {} of {} lost, e.g. {:?}",
            lost.len(),
            rays.len(),
            &lost[..lost.len().min(3)]
        );
    }
}

/// Finding 4: triangles of size 1e14 and up were never hit (Möller–Trumbore's third-degree
/// products overflow). Coordinates beyond `MAX_COORDINATE` are now a typed error when the mesh is
/// made, and the largest accepted triangles are hit by every test.
#[test]
fn huge_triangles_are_rejected_or_hit() {
    for size in [1e14f32, 1e17, 1e19] {
        let err = TriangleMesh::from_slices("huge", &[0.0, 0.0, size, size, 0.0, size, 0.0, size, size], &[0, 1, 2]);
        assert!(matches!(err, Err(strahl::Error::CoordinateOutOfRange { vertex: 0, .. })), "{size}: {err:?}");
    }
    let m = strahl::MAX_COORDINATE;
    let big = TriangleMesh::from_slices("big", &[-m, -m, m, m, -m, m, -m, m, m], &[0, 1, 2]).unwrap();
    for config in configs() {
        let scene = Scene::build(vec![big.clone()], &config).unwrap();
        let mut rays = Vec::new();
        for (o, d) in [
            (Vec3::new(-0.5 * m, -0.5 * m, -m), Vec3::new(0.0, 0.0, 2.0 * m)),
            (Vec3::new(-0.5 * m, -0.5 * m, 0.0), Vec3::Z),
            (Vec3::new(0.0, 0.0, -m), Vec3::new(-0.25, -0.25, 1.0)),
            (Vec3::new(-m, -m, -m), Vec3::new(0.2 * m, 0.3 * m, m)),
        ] {
            let r = Ray::new(o, d);
            let t = clear_hit(&big, &r, 0.01).expect("a clear hit in float64");
            let h = scene.intersect(&r).unwrap_or_else(|| panic!("{:?}: {r:?} missed", config.triangle_test));
            assert!(((h.t as f64 - t) / t).abs() < 1e-4, "{:?}: t {} vs {t}", config.triangle_test, h.t);
            rays.push(r);
        }
        agrees_with_brute_force(&scene, &rays, 1e-4, "largest triangle");
    }
    // Moved beyond the bound after construction: left out like a NaN triangle, never hit.
    let mut moved = big.clone();
    moved.map_positions(|p| p * 4.0);
    let scene = scene_of(vec![moved]);
    assert_eq!(scene.stats().skipped_triangles, 1);
    assert!(scene.intersect(&Ray::new(Vec3::new(-m, -m, 0.0), Vec3::Z)).is_none());
}

/// Finding 5: hits at `t = 0` with `tnear = 0` (a huge determinant rounds `t` to 0), and
/// barycentrics of infinity or NaN (a tiny one overflows its reciprocal). Every hit lies in
/// `(tnear, tfar]` with finite barycentrics in [0, 1].
#[test]
fn hits_lie_in_the_open_interval_with_finite_barycentrics() {
    let tri = TriangleMesh::from_slices("t", &[-1.0, -1.0, 1.0, 1.0, -1.0, 1.0, 0.0, 1.0, 1.0], &[0, 1, 2]).unwrap();
    let tiny =
        TriangleMesh::from_slices("tiny", &[0.0, 0.0, 2.0, 1e-20, 0.0, 2.0, 0.0, 1e-20, 2.0], &[0, 1, 2]).unwrap();
    let mut rays = Vec::new();
    for s in [1.0f32, 1e30, 1e34, 3e37, 1e-15, 1e-17] {
        for o in [Vec3::ZERO, Vec3::new(0.1, 0.1, 0.0), Vec3::new(0.0, 0.0, 1.0), Vec3::new(1e-21, 1e-21, 1.9)] {
            rays.push(Ray::new(o, Vec3::new(0.01, -0.02, 1.0) * s));
            rays.push(Ray::new(o, Vec3::Z * s));
        }
    }
    for config in configs() {
        let scene = Scene::build(vec![tri.clone(), tiny.clone()], &config).unwrap();
        for r in &rays {
            let hits = [scene.intersect(r), scene.intersect_brute_force(r)];
            let mut hp = HitPacket::default();
            scene.intersect_packet(&RayPacket::from_rays(&[*r]), &mut hp);
            for h in hits.into_iter().chain([hp.get(0)]).flatten() {
                assert!(h.t > r.tnear && h.t <= r.tfar, "{:?}: {r:?}: t {}", config.triangle_test, h.t);
                assert!(
                    (0.0..=1.0).contains(&h.u) && (0.0..=1.0).contains(&h.v) && h.u + h.v <= 1.0 + 1e-6,
                    "{:?}: {r:?}: u {} v {}",
                    config.triangle_test,
                    h.u,
                    h.v
                );
            }
        }
    }
}

/// Finding 11: `RayStream::packet` clamps to the stream, from any start.
#[test]
fn stream_packets_clamp_from_any_start() {
    let s: RayStream = random_rays(1, 20).into_iter().collect();
    assert_eq!(s.packet(16, 16).active, 0b1111);
    for start in [20, 21, 1000, usize::MAX] {
        assert_eq!(s.packet(start, 16).active, 0, "start {start}");
    }
}

/// Findings 6, 7 and 9: scene files that once aborted on allocation or were silently accepted
/// are typed errors naming the entry and the numbers.
#[test]
fn scene_file_limits_are_typed_errors() {
    let p = std::path::Path::new("/scenes/x.toml");
    let cases = [
        (
            "[mesh.b]\nsphere = { radius = 1.0, stacks = 4, slices = 4 }\n[[grid]]\nmesh = \"b\"\ncount = [4096, 4096, 4]\nspacing = [1.0, 1.0, 1.0]\n[[grid]]\nmesh = \"b\"\ncount = [4096, 4096, 4]\nspacing = [1.0, 1.0, 1.0]\n",
            "instances in all",
        ),
        (
            "[mesh.b]\nsphere = { radius = 1.0, stacks = 4, slices = 4 }\n[[grid]]\nmesh = \"b\"\ncount = [4097, 4096, 1]\nspacing = [1.0, 1.0, 1.0]\n",
            "2^24",
        ),
        ("[mesh.f]\nsphereflake = { levels = 12, stacks = 8, slices = 16 }\n", "triangles"),
        ("[mesh.s]\nsphere = { radius = 1.0, stacks = 100000, slices = 100000 }\n", "triangles"),
        ("[mesh.s]\nsphere = { radius = 1e30, stacks = 4, slices = 4 }\n", "radius"),
        ("[[light]]\nposition = [nan, 0.0, 0.0]\n", "light 0"),
        ("[[light]]\nposition = [1e30, 0.0, 0.0]\n", "light 0"),
        ("[[light]]\nposition = [0.0, 0.0, 0.0]\ncolor = [-1.0, 0.0, 0.0]\n", "light 0"),
        (
            "[mesh.s]\nsphere = { radius = 1.0, stacks = 4, slices = 4 }\n[[instance]]\nmesh = \"s\"\nmatrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 2]]\n",
            "fourth row",
        ),
        (
            "[mesh.s]\nsphere = { radius = 1.0, stacks = 4, slices = 4 }\n[[instance]]\nmesh = \"s\"\nmatrix = [[1, 0, 0, 0], [0, 1, 0, 0]]\n",
            "2 rows",
        ),
    ];
    for (text, needle) in cases {
        match strahl::SceneFile::parse(text, p) {
            Err(e @ strahl::Error::SceneFile { .. }) => assert!(e.to_string().contains(needle), "{needle}: {e}"),
            other => panic!("{needle}: {other:?}"),
        }
    }
    let ok = "[mesh.s]\nsphere = { radius = 1.0, stacks = 4, slices = 4 }\n[[instance]]\nmesh = \"s\"\nmatrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n";
    assert_eq!(strahl::SceneFile::parse(ok, p).unwrap().instances.len(), 1);
}

/// Found by the differential fuzz target: the closest-hit walk popped a child whose entry
/// distance lay just beyond `tfar` and skipped it, though the node test (widened by the rounding
/// bound) had let it in and the triangle's hit lay within `tfar`: occlusion found the hit, closest
/// hit did not. The pop checks now use the same widened bound as the node tests.
#[test]
fn closest_hit_keeps_children_the_widened_test_entered() {
    let s = |i: f32| i * 2f32.powi(-19);
    let raw = |x: f32| x;
    #[rustfmt::skip]
    let tris: [[[f32; 3]; 3]; 20] = [
        [[s(0.), s(41.), s(113.)], [s(113.), s(113.), s(64.)], [s(0.), s(3.), s(3.)]],
        [[s(3.), s(3.), s(-1.)], [s(0.), s(3.), s(-1.)], [s(3.), s(3.), s(3.)]],
        [[s(8.), s(3.), s(37.)], [s(59.), s(113.), s(113.)], [s(113.), raw(5.473821e-39), s(3.)]],
        [[s(18.), s(41.), s(75.)], [s(75.), s(39.), s(39.)], [s(39.), s(75.), s(75.)]],
        [[s(75.), s(39.), s(39.)], [s(39.), s(39.), s(14.)], [s(75.), s(75.), s(75.)]],
        [[s(0.), s(75.), s(75.)], [s(75.), s(75.), s(75.)], [s(75.), s(75.), s(75.)]],
        [[s(75.), s(75.), s(39.)], [raw(3.77381e-40), s(0.), s(59.)], [raw(13312048.0), s(75.), s(75.)]],
        [[s(75.), raw(13323184.0), s(75.)], [s(39.), s(39.), s(39.)], [s(39.), s(75.), s(75.)]],
        [[s(75.), s(39.), s(39.)], [s(39.), s(75.), s(75.)], [s(75.), s(75.), s(75.)]],
        [[s(75.), s(75.), s(75.)], [s(75.), s(75.), s(39.)], [s(39.), s(39.), s(39.)]],
        [[s(75.), s(75.), s(75.)], [s(75.), s(75.), s(75.)], [s(39.), s(39.), s(39.)]],
        [[s(39.), s(39.), s(39.)], [s(75.), s(75.), s(75.)], [s(75.), s(-80.), s(75.)]],
        [[s(75.), s(39.), s(39.)], [s(39.), s(39.), s(39.)], [s(39.), s(75.), s(75.)]],
        [[s(75.), s(75.), s(75.)], [s(75.), s(0.), s(0.)], [s(0.), s(75.), s(75.)]],
        [[s(75.), s(75.), s(75.)], [s(-112.), s(75.), s(75.)], [s(75.), s(39.), s(39.)]],
        [[s(75.), s(75.), s(75.)], [s(75.), s(37.), s(37.)], [s(5.), s(75.), s(75.)]],
        [[s(39.), s(39.), s(39.)], [s(39.), s(39.), s(39.)], [s(39.), s(14.), s(75.)]],
        [[s(75.), s(75.), s(75.)], [s(0.), s(0.), s(75.)], [s(75.), s(75.), s(75.)]],
        [[s(75.), s(75.), s(75.)], [s(75.), s(75.), s(39.)], [s(39.), s(75.), s(75.)]],
        [[s(75.), s(75.), raw(13323083.0)], [s(75.), s(39.), s(39.)], [raw(4.0736475e-17), s(59.), s(0.)]],
    ];
    let p: Vec<Vec3> = tris.iter().flatten().map(|&c| Vec3::from(c)).collect();
    let idx: Vec<[u32; 3]> = (0..20u32).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect();
    let mesh = TriangleMesh::new("fuzz", p, idx).unwrap();
    let ray = Ray::segment(Vec3::new(0.0, s(59.0), s(5.0)), Vec3::new(0.0, s(-64.0), 5.439747e-39), 0.0, s(126.0));
    for config in [BuildConfig::high(), BuildConfig::default()] {
        for test in TriangleTest::ALL {
            let scene = Scene::build(vec![mesh.clone()], &config.with_tests(test, BoxTest::Conservative)).unwrap();
            agrees_with_brute_force(&scene, &[ray], 1e-5, &format!("{test:?}"));
        }
    }
}

/// Found by the differential fuzz target (no flush-to-zero): a tiny determinant let `tfar·|det|`
/// round up to the smallest denormal, and Möller–Trumbore reported `t` ≈ 2·`tfar`. Every hit now
/// lies within `tfar` once divided, whatever the floating-point mode.
#[test]
fn hits_stay_within_tfar_when_the_scaled_test_underflows() {
    let s = |i: f32| i * 2f32.powi(-52);
    let raw = |x: f32| x;
    #[rustfmt::skip]
    let tris: [[[f32; 3]; 3]; 8] = [
        [[s(0.), s(-85.), s(59.)], [s(113.), s(113.), s(64.)], [s(0.), s(3.), s(3.)]],
        [[s(3.), s(3.), s(-1.)], [s(0.), s(3.), f32::NAN], [s(3.), s(3.), s(3.)]],
        [[s(3.), s(3.), s(37.)], [s(113.), s(113.), s(113.)], [s(4.), raw(2.1381e-41), s(3.)]],
        [[s(3.), s(3.), s(3.)], [s(3.), s(59.), s(0.)], [s(37.), s(3.), s(3.)]],
        [[s(0.), s(59.), s(113.)], [s(113.), s(113.), raw(5.473821e-39)], [s(3.), s(3.), s(3.)]],
        [[s(3.), s(3.), s(0.)], [s(27.), s(37.), s(0.)], [s(0.), s(0.), s(113.)]],
        [[s(35.), s(4.), raw(2.1381e-41)], [s(3.), s(3.), s(35.)], [s(3.), s(3.), s(3.)]],
        [[s(3.), s(0.), s(45.)], [s(3.), s(3.), s(113.)], [s(113.), s(39.), raw(0.0019531387)]],
    ];
    let p: Vec<Vec3> = tris.iter().flatten().map(|&c| Vec3::from(c)).collect();
    let idx: Vec<[u32; 3]> = (0..8u32).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect();
    let mesh = TriangleMesh::new("fuzz", p, idx).unwrap();
    let ray = Ray::segment(Vec3::splat(s(3.0)), Vec3::new(s(39.0), 0.0019531387, s(3.0)), 3.8500897e-37, s(3.0));
    for config in [BuildConfig::high(), BuildConfig::default()] {
        for test in TriangleTest::ALL {
            let scene = Scene::build(vec![mesh.clone()], &config.with_tests(test, BoxTest::Conservative)).unwrap();
            let mut hp = HitPacket::default();
            scene.intersect_packet(&RayPacket::from_rays(&[ray]), &mut hp);
            for h in [scene.intersect(&ray), scene.intersect_brute_force(&ray), hp.get(0)].into_iter().flatten() {
                assert!(
                    h.t > ray.tnear && h.t <= ray.tfar,
                    "{test:?}: t {} outside ({}, {}]",
                    h.t,
                    ray.tnear,
                    ray.tfar
                );
            }
        }
    }
}
