//! Accuracy and robustness of every triangle test and box test, after `../shared/ACCURACY.md`.
//! Each test states its pass criterion; rates are measured on fixed-seed ray sets.

mod common;

use glam::Vec3;
use strahl::Query;
use strahl::raygen::{self, Offset};
use strahl::{
    BoxTest, BuildConfig, Camera, Coherence, HitStream, Ray, RayStream, Scene, TriangleMesh, TriangleTest, procedural,
};

fn build(mesh: &TriangleMesh, t: TriangleTest, b: BoxTest) -> Scene {
    Scene::build(vec![mesh.clone()], &BuildConfig::default().with_tests(t, b)).unwrap()
}

fn misses(scene: &Scene, rays: &RayStream) -> usize {
    let mut h = HitStream::default();
    scene.intersect_stream_par(rays, &mut h, Coherence::Incoherent);
    for i in 0..h.len() {
        if let Some(hit) = h.get(i) {
            assert!(hit.t.is_finite() && hit.u.is_finite() && hit.v.is_finite(), "NaN or inf in a hit: {hit:?}");
        }
    }
    (0..h.len()).filter(|&i| h.get(i).is_none()).count()
}

/// Criterion: the watertight test with conservative boxes lets no ray out of a closed, finely
/// tessellated sphere, wherever the sphere is (offsets 0 to 1e6, after Embree's WatertightTest).
/// Möller–Trumbore's leak count is printed for comparison.
#[test]
fn watertight_never_leaks_from_inside() {
    for offset in [0.0f32, 1e3, 1e4, 1e5, 1e6] {
        let center = Vec3::new(1.0, 0.37, -0.71) * offset;
        let sphere = procedural::uv_sphere(center, 1.0, 100, 200);
        let rays = raygen::inside_rays(center, 0.5, 20_000, 7);
        let wt = misses(&build(&sphere, TriangleTest::Watertight, BoxTest::Conservative), &rays);
        let mt = misses(&build(&sphere, TriangleTest::MollerTrumbore, BoxTest::Fast), &rays);
        eprintln!("offset {offset:e}: leaks watertight {wt}, Möller–Trumbore {mt} of {}", rays.len());
        assert_eq!(wt, 0, "watertight leaked at offset {offset}");
    }
}

/// Criterion: rays aimed at shared edges and at vertices of closed meshes never miss with the
/// watertight test, neither through the BVH nor against the adjacent triangles alone.
#[test]
fn edge_and_vertex_aimed_rays_never_miss_with_watertight() {
    let mut meshes = vec![
        ("sphere", procedural::uv_sphere(Vec3::ZERO, 1.0, 60, 120)),
        ("far sphere", procedural::uv_sphere(Vec3::new(1e4, -2e4, 3e3), 1.0, 60, 120)),
    ];
    if let Some(p) = common::shared_scene("igea/igea.obj") {
        meshes.push(("igea", strahl::load_obj(p).unwrap().remove(0)));
    }
    for (name, mesh) in &meshes {
        let scene = build(mesh, TriangleTest::Watertight, BoxTest::Conservative);
        let edges = raygen::edge_aimed_rays(mesh, 20_000, 3);
        let verts = raygen::vertex_aimed_rays(mesh, 10_000, 4);
        assert!(!edges.is_empty() && !verts.is_empty());
        let edge_rays: RayStream = edges.iter().map(|(r, _)| *r).collect();
        let vert_rays: RayStream = verts.iter().map(|(r, _)| *r).collect();
        assert_eq!(misses(&scene, &edge_rays), 0, "{name}: edge-aimed rays missed");
        assert_eq!(misses(&scene, &vert_rays), 0, "{name}: vertex-aimed rays missed");
        // Aimed at an exactly representable point of the edge (far from the origin the target is
        // rounded, and may fall in a neighbour), the ray hits one of the edge's two triangles.
        if *name == "sphere" {
            let hits_any = |r: &Ray, tris: &[u32]| {
                tris.iter().any(|&t| {
                    strahl::intersect_triangle(TriangleTest::Watertight, r, mesh.triangle(t as usize)).is_some()
                })
            };
            assert!(
                edges.iter().all(|(r, t)| hits_any(r, t)),
                "{name}: an edge-aimed ray passed between its triangles"
            );
        }
    }
}

/// Criterion: scaling the mesh and the rays by 10^k (k = −6…6) changes no primitive hit by a ray
/// that passes clearly inside a triangle (float64 barycentric margin above 1e-4), for every test;
/// and the watertight test lets no ray out of the closed sphere at any scale.
#[test]
fn scale_invariance() {
    let base = procedural::uv_sphere(Vec3::ZERO, 1.0, 24, 48);
    let rays = raygen::inside_rays(Vec3::ZERO, 0.5, 3000, 9);
    for test in TriangleTest::ALL {
        let reference = build(&base, test, BoxTest::Conservative);
        let clear: Vec<(usize, u32)> = (0..rays.len())
            .filter_map(|i| {
                let h = reference.intersect(&rays.get(i))?;
                let (_, b) = strahl::exact_hit(rays.get(i).origin, rays.get(i).dir, base.triangle(h.prim_id as usize))?;
                (b.iter().all(|&x| x > 1e-4)).then_some((i, h.prim_id))
            })
            .collect();
        assert!(clear.len() > rays.len() * 9 / 10, "{test:?}: too few clear hits ({})", clear.len());
        for k in -6i32..=6 {
            let s = 10f32.powi(k);
            let mut m = base.clone();
            m.map_positions(|p| p * s);
            let scene = build(&m, test, BoxTest::Conservative);
            let scaled: RayStream =
                (0..rays.len()).map(|i| Ray::new(rays.get(i).origin * s, rays.get(i).dir)).collect();
            for &(i, prim) in &clear {
                let h = scene.intersect(&scaled.get(i));
                assert_eq!(h.map(|h| h.prim_id), Some(prim), "{test:?} scale 1e{k}: ray {i}");
            }
            if test.is_watertight() {
                assert_eq!(misses(&scene, &scaled), 0, "watertight leaked at scale 1e{k}");
            }
        }
    }
}

/// Criterion: secondary rays leaving hit points with the normal offset (`Offset::Normal`,
/// tnear = 0) never hit the surface they start on, at offsets 0…1e4 and scales 1e-3…1e3: on a
/// sphere seen from outside, diffuse rays (which leave a convex surface) must all miss, and
/// shadow rays towards a light on the lit side must never be occluded — wherever the sphere spans
/// at least 4096 ulps of its own coordinates (the method's stated range; smaller cases are printed).
/// Holds for Möller–Trumbore and the watertight test; Badouel is measured in the report instead.
#[test]
fn reintersection_from_hit_points() {
    for offset in [0.0f32, 1e2, 1e4] {
        for scale in [1e-3f32, 1.0, 1e3] {
            let center = Vec3::new(0.6, -0.2, 0.3) * offset;
            let sphere = procedural::uv_sphere(center, scale, 48, 96);
            let cam = Camera::look_at(center + Vec3::new(0.0, 0.5, 4.0) * scale, center, Vec3::Y, 40.0);
            let light = center + Vec3::new(3.0, 5.0, 4.0) * scale;
            for test in [TriangleTest::MollerTrumbore, TriangleTest::Watertight] {
                let scene = build(&sphere, test, BoxTest::Conservative);
                let (primary, _) = raygen::primary(&cam, 96, 96);
                let mut hits = HitStream::default();
                scene.intersect_stream(&primary, &mut hits, Coherence::Coherent);
                let (diffuse, _) = raygen::diffuse_with(&primary, &hits, 5, Offset::Normal);
                assert!(diffuse.len() > 1000);
                let self_hits = diffuse.len() - misses(&scene, &diffuse);
                // Shadow rays from points facing the light.
                let mut lit = RayStream::default();
                let (shadow, src) = raygen::shadow_with(&primary, &hits, light, Offset::Normal);
                for (k, &i) in src.iter().enumerate() {
                    let n = Vec3::new(hits.ng_x[i as usize], hits.ng_y[i as usize], hits.ng_z[i as usize]);
                    if n.normalize().dot((light - shadow.get(k).origin).normalize()) > 0.05 {
                        lit.push(&shadow.get(k));
                    }
                }
                let mut occ = Vec::new();
                scene.occluded_stream(&lit, &mut occ, Coherence::Incoherent);
                let false_occ = occ.iter().filter(|&&o| o).count();
                // The offset is 256 ulps of the largest coordinate along the normal: as large as
                // the whole sphere when the sphere spans only a few hundred ulps (151 of 2,677 lit
                // points falsely occluded at 140 ulps across; 65 with per-coordinate ulps).
                let ulps_across = scale / (center.abs().max_element().max(scale) * f32::EPSILON);
                eprintln!(
                    "{test:?} offset {offset:e} scale {scale:e} ({ulps_across:.0} ulps across): self-hits {self_hits} of {}, false occlusions {false_occ} of {}",
                    diffuse.len(),
                    lit.len()
                );
                if ulps_across >= 4096.0 {
                    assert_eq!(self_hits, 0, "{test:?} offset {offset} scale {scale}: diffuse self-hits");
                    assert_eq!(false_occ, 0, "{test:?} offset {offset} scale {scale}: false occlusion");
                }
            }
        }
    }
}

/// Criterion: degenerate rays (±0 and tiny direction components, origins on box planes, NaN and
/// infinite components, tnear > tfar, zero direction) give a defined answer with every test and
/// box test: no panic, no NaN in a hit, the same answer as brute force.
#[test]
fn degenerate_rays_with_every_method() {
    let mesh = procedural::uv_sphere(Vec3::ZERO, 1.0, 12, 24);
    let mut rays = vec![
        Ray::new(Vec3::new(0.0, 0.0, 3.0), Vec3::new(0.0, 0.0, -1.0)),
        Ray::new(Vec3::new(0.0, 0.0, 3.0), Vec3::new(-0.0, -0.0, -1.0)),
        Ray::new(Vec3::new(0.0, 0.0, 3.0), Vec3::new(1e-30, -1e-30, -1.0)),
        Ray::new(Vec3::new(1.0, 1.0, 3.0), Vec3::new(0.0, 0.0, -1.0)),
        Ray::new(Vec3::new(-1.0, 0.0, 3.0), Vec3::new(0.0, 0.0, -1.0)),
        Ray::new(Vec3::new(0.0, 0.0, 0.0), Vec3::new(1e-38, 0.0, 0.0)),
        Ray::new(Vec3::ZERO, Vec3::ZERO),
        Ray::new(Vec3::new(f32::NAN, 0.0, 0.0), Vec3::X),
        Ray::new(Vec3::ZERO, Vec3::new(f32::INFINITY, 0.0, 0.0)),
        Ray::segment(Vec3::ZERO, Vec3::X, 2.0, 1.0),
    ];
    let mut rng = raygen::Pcg32::new(3, 3);
    for _ in 0..200 {
        rays.push(Ray::new(raygen::uniform_direction(&mut rng) * 2.0, raygen::uniform_direction(&mut rng)));
    }
    for t in TriangleTest::ALL {
        for b in BoxTest::ALL {
            let scene = build(&mesh, t, b);
            for (i, r) in rays.iter().enumerate() {
                let h = scene.intersect(r);
                if let Some(h) = h {
                    assert!(h.t.is_finite() && h.u.is_finite() && h.v.is_finite() && h.ng.is_finite(), "{t:?} ray {i}");
                }
                common::assert_same_hit(h, scene.intersect_brute_force(r), 1e-6, &format!("{t:?} {b:?} ray {i}"));
                assert_eq!(scene.occluded(r), h.is_some());
            }
            assert!(scene.intersect(&rays[0]).is_some() && scene.intersect(&rays[2]).is_some(), "{t:?}");
        }
    }
}

/// Slivers and tiny triangles (ACCURACY.md test 4): a fan of 1:1000 slivers and a grid of tiny
/// triangles, seen from ever farther away. Criterion: against a float64 brute-force reference
/// (ties within 1e-6 relative t count as matches), Möller–Trumbore and the watertight test match
/// the primitive of at least 99% of the hits up to a distance of 1e2; every rate is printed. (Measured:
/// about 98.8% at 1e3, 93% at 1e4, and under 50% from 1e5 on for every test, where the ray origin's
/// ulp exceeds the slivers' width.)
#[test]
fn slivers_and_tiny_triangles_by_distance() {
    let mut p = Vec::new();
    let mut idx = Vec::new();
    // 400 slivers 1 long and 1e-3 wide around the origin.
    for i in 0..400u32 {
        let a = i as f32 / 400.0 * std::f32::consts::TAU;
        let (d, s) = (Vec3::new(a.cos(), a.sin(), 0.0), Vec3::new(-a.sin(), a.cos(), 0.0) * 1e-3);
        let b = p.len() as u32;
        p.extend([Vec3::ZERO + d * 0.01, d + s, d - s]);
        idx.push([b, b + 1, b + 2]);
    }
    // A 40×40 grid of triangles 1e-4 across just behind.
    for j in 0..40 {
        for i in 0..40 {
            let o = Vec3::new(-0.002 + i as f32 * 1e-4, -0.002 + j as f32 * 1e-4, -0.01);
            let b = p.len() as u32;
            p.extend([o, o + Vec3::new(1e-4, 0.0, 0.0), o + Vec3::new(0.0, 1e-4, 0.0)]);
            idx.push([b, b + 1, b + 2]);
        }
    }
    let mesh = TriangleMesh::new("slivers", p, idx).unwrap();
    let reference = |r: &Ray| -> Option<(u32, f64)> {
        (0..mesh.triangle_count())
            .filter_map(|i| {
                let (t, b) = strahl::exact_hit(r.origin, r.dir, mesh.triangle(i))?;
                (b.iter().all(|&x| x >= 0.0) && t > r.tnear as f64 && t <= r.tfar as f64).then_some((i as u32, t))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
    };
    for distance in [1.0f32, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6] {
        let eye = Vec3::new(0.3, 0.2, 1.0).normalize() * distance;
        // A narrow camera aimed at the slivers, so that the scene fills the image at any distance.
        let fov = 2.0 * (1.2 / distance).atan().to_degrees();
        let cam = Camera::look_at(eye, Vec3::ZERO, Vec3::Y, fov);
        let (rays, _) = raygen::primary(&cam, 64, 64);
        let refs: Vec<Option<(u32, f64)>> = (0..rays.len()).map(|i| reference(&rays.get(i))).collect();
        let n_ref = refs.iter().filter(|r| r.is_some()).count();
        assert!(n_ref > 100, "distance {distance}: too few reference hits ({n_ref})");
        for test in TriangleTest::ALL {
            let scene = build(&mesh, test, BoxTest::Conservative);
            let mut matched = 0;
            for (i, want) in refs.iter().enumerate() {
                let Some((prim, t64)) = *want else { continue };
                if let Some(h) = scene.intersect(&rays.get(i)) {
                    let tie = strahl::exact_hit(rays.get(i).origin, rays.get(i).dir, mesh.triangle(h.prim_id as usize))
                        .is_some_and(|(t, _)| (t - t64).abs() <= 1e-6 * t64.abs());
                    matched += (h.prim_id == prim || tie) as usize;
                }
            }
            let rate = matched as f64 / n_ref as f64;
            eprintln!("distance {distance:e} {test:?}: primitive match {:.4} of {n_ref}", rate);
            if distance <= 1e2 && test != TriangleTest::Badouel {
                assert!(rate >= 0.99, "{test:?} at distance {distance}: match rate {rate}");
            }
        }
    }
}
