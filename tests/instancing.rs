//! Two-level scenes against their references: every query shape against brute force over all
//! instances, against each other, and against the same world flattened into one BVH.

mod common;

use common::{random_soup, rng_vec};
use glam::{Affine3A, Quat, Vec3};
use strahl::raygen::{Pcg32, uniform_direction};
use strahl::{
    BoxTest, BuildConfig, Coherence, Error, HitPacket, HitStream, INVALID_ID, Instance, InstancedScene, PACKET_WIDTH,
    Query, Ray, RayPacket, RayStream, TriangleMesh, TriangleTest, procedural,
};

/// Three objects (a sphere, a triangle soup of two meshes, a flat quad) placed `n` times with
/// random rotations, scales (non-uniform, some mirrored) and translations in `[-extent, extent]³`
/// around `offset`.
fn world(n: usize, extent: f32, offset: Vec3, seed: u64) -> (Vec<Vec<TriangleMesh>>, Vec<Instance>) {
    let quad = TriangleMesh::from_slices(
        "quad",
        &[-1.0, 0.0, -1.0, 1.0, 0.0, -1.0, 1.0, 0.0, 1.0, -1.0, 0.0, 1.0],
        &[0, 1, 2, 0, 2, 3],
    )
    .unwrap();
    let objects = vec![
        vec![procedural::uv_sphere(Vec3::ZERO, 1.0, 12, 24)],
        vec![random_soup(seed, 200, 0.3), random_soup(seed + 1, 100, 0.2)],
        vec![quad],
    ];
    let mut rng = Pcg32::new(seed, 3);
    let instances = (0..n)
        .map(|i| {
            let axis = uniform_direction(&mut rng);
            let angle = rng.next_f32() * std::f32::consts::TAU;
            let mut scale = rng_vec(&mut rng, 0.3, 1.5);
            if i % 7 == 3 {
                scale.x = -scale.x;
            }
            let t = offset + rng_vec(&mut rng, -extent, extent);
            Instance::new(
                i % 3,
                Affine3A::from_scale_rotation_translation(scale, Quat::from_axis_angle(axis, angle), t),
            )
        })
        .collect();
    (objects, instances)
}

/// Rays from random points of the world's box towards other random points of it.
fn rays(n: usize, extent: f32, offset: Vec3, seed: u64) -> Vec<Ray> {
    let mut rng = Pcg32::new(seed, 5);
    (0..n)
        .map(|_| {
            let o = offset + rng_vec(&mut rng, -1.5 * extent, 1.5 * extent);
            let to = offset + rng_vec(&mut rng, -extent, extent);
            Ray::new(o, to - o)
        })
        .collect()
}

#[test]
fn every_query_matches_brute_force_over_instances() {
    for (test, boxes) in [
        (TriangleTest::MollerTrumbore, BoxTest::Conservative),
        (TriangleTest::Watertight, BoxTest::Conservative),
        (TriangleTest::MollerTrumbore, BoxTest::Fast),
    ] {
        let (objects, instances) = world(60, 4.0, Vec3::ZERO, 1);
        let scene = InstancedScene::build(objects, instances, &BuildConfig::default().with_tests(test, boxes)).unwrap();
        let rays = rays(3000, 4.0, Vec3::ZERO, 2);
        let mut hits = 0;
        for (i, r) in rays.iter().enumerate() {
            let a = scene.intersect(r);
            let b = scene.intersect_brute_force(r);
            // The same object-space rays and tests: the same distance, bit for bit.
            assert_eq!(a.map(|h| h.t), b.map(|h| h.t), "{test:?}/{boxes:?} ray {i}");
            if let (Some(a), Some(b)) = (a, b) {
                hits += 1;
                assert_ne!(a.inst_id, INVALID_ID);
                // A different instance only where two surfaces meet at exactly this distance.
                if a.inst_id != b.inst_id {
                    assert_eq!(a.t, b.t);
                }
            }
            assert_eq!(scene.occluded(r), b.is_some(), "{test:?}/{boxes:?} occlusion of ray {i}");
        }
        assert!(hits > 500 && hits < 2900, "a test set that both hits and misses: {hits}");
    }
}

#[test]
fn packets_and_streams_equal_single_rays() {
    let (objects, instances) = world(40, 3.0, Vec3::ZERO, 7);
    let scene = InstancedScene::build(objects, instances.clone(), &BuildConfig::default()).unwrap();
    let mut rays = rays(1000, 3.0, Vec3::ZERO, 8);
    // Camera-like packets too: 16 rays from one origin, so the frustum path is taken.
    let eye = Vec3::new(0.5, 9.0, -11.0);
    let mut rng = Pcg32::new(9, 1);
    for _ in 0..(16 * 40) {
        rays.push(Ray::new(eye, -eye + rng_vec(&mut rng, -2.0, 2.0)));
    }
    // Diffuse-like packets: 16 rays from points a hair apart inside an instance, in random
    // directions, so the object is walked as a packet (close origins, no shared one).
    for inst in instances.iter().take(20) {
        let at = Vec3::from(inst.transform.translation);
        for _ in 0..PACKET_WIDTH {
            rays.push(Ray::new(at + rng_vec(&mut rng, -1e-3, 1e-3), uniform_direction(&mut rng)));
        }
    }
    // And a few bad rays in between.
    rays[5] = Ray::new(Vec3::NAN, Vec3::X);
    rays[17] = Ray::new(Vec3::ZERO, Vec3::ZERO);
    let single: Vec<_> = rays.iter().map(|r| scene.intersect(r)).collect();
    for (k, chunk) in rays.chunks(PACKET_WIDTH).enumerate() {
        let p = RayPacket::from_rays(chunk);
        let mut hp = HitPacket::default();
        scene.intersect_packet(&p, &mut hp);
        let occ = scene.occluded_packet(&p);
        for (l, r) in chunk.iter().enumerate() {
            let i = k * PACKET_WIDTH + l;
            assert_eq!(hp.get(l), single[i], "packet lane {l} of ray {i}");
            assert_eq!(occ & (1 << l) != 0, scene.occluded(r), "packet occlusion of ray {i}");
        }
    }
    let stream: RayStream = rays.iter().copied().collect();
    for coherence in [Coherence::Coherent, Coherence::Incoherent] {
        let mut hs = HitStream::default();
        scene.intersect_stream_par(&stream, &mut hs, coherence);
        let mut occ = Vec::new();
        scene.occluded_stream_par(&stream, &mut occ, coherence);
        for i in 0..rays.len() {
            assert_eq!(hs.get(i), single[i], "{coherence:?} stream ray {i}");
            assert_eq!(occ[i], single[i].is_some(), "{coherence:?} stream occlusion of ray {i}");
        }
    }
}

#[test]
fn instanced_and_flattened_agree_and_normals_are_in_world_space() {
    let (objects, instances) = world(50, 4.0, Vec3::ZERO, 11);
    let cfg = BuildConfig::watertight();
    let scene = InstancedScene::build(objects, instances, &cfg).unwrap();
    let flat = scene.flatten(&cfg).unwrap();
    assert_eq!(flat.triangle_count() as u64, scene.stats().instanced_triangles);
    let rays = rays(5000, 4.0, Vec3::ZERO, 12);
    let (mut agree, mut hits, mut same_triangle) = (0, 0, 0);
    for r in &rays {
        let (a, b) = (scene.intersect(r), flat.intersect(r));
        if a.is_some() == b.is_some() {
            agree += 1;
        }
        if let (Some(a), Some(b)) = (a, b) {
            hits += 1;
            // Flattened geometry ids run instance by instance, object mesh by object mesh.
            let first_geom: u32 = scene.instances()[..a.inst_id as usize]
                .iter()
                .map(|i| scene.objects()[i.object].meshes().len() as u32)
                .sum();
            if b.geom_id == first_geom + a.geom_id && b.prim_id == a.prim_id {
                same_triangle += 1;
                assert!((a.t - b.t).abs() <= 1e-5 * a.t.max(1.0), "t {} vs {}", a.t, b.t);
                let c = a.ng.normalize().dot(b.ng.normalize());
                assert!(c > 0.9999, "world normal {} vs flattened {}", a.ng, b.ng);
                assert!((a.ng.length() / b.ng.length() - 1.0).abs() < 1e-3, "{} vs {}", a.ng, b.ng);
            }
        }
    }
    // Elsewhere one engine grazed an edge the other missed by a rounding.
    assert!(same_triangle as f64 >= 0.999 * hits as f64, "{same_triangle} of {hits} hits on the same triangle");
    assert!(hits > 1000);
    assert!(agree as f64 / rays.len() as f64 >= 0.999, "hit/miss agreement {agree} of {}", rays.len());
}

#[test]
fn far_translations_keep_object_precision() {
    // At 1e6 the flattened vertices are rounded to 1/16; the instanced object keeps its own
    // precision, so watertight instances still answer every ray brute force over instances does.
    for offset in [1e3f32, 1e6] {
        let o = Vec3::new(offset, -offset, 0.5 * offset);
        let (objects, instances) = world(30, 4.0, o, 21);
        let scene = InstancedScene::build(objects, instances, &BuildConfig::watertight()).unwrap();
        for r in rays(1500, 4.0, o, 22) {
            assert_eq!(scene.intersect(&r).map(|h| h.t), scene.intersect_brute_force(&r).map(|h| h.t));
        }
    }
}

#[test]
fn bad_instances_get_typed_errors_and_empty_worlds_miss() {
    let sphere = || vec![vec![procedural::uv_sphere(Vec3::ZERO, 1.0, 8, 16)]];
    let cfg = BuildConfig::default();
    let e = InstancedScene::build(sphere(), vec![Instance::new(1, Affine3A::IDENTITY)], &cfg).unwrap_err();
    assert!(matches!(e, Error::UnknownObject { instance: 0, object: 1, objects: 1 }), "{e}");
    for m in [
        Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0)),
        Affine3A::from_translation(Vec3::new(f32::NAN, 0.0, 0.0)),
        Affine3A::from_scale(Vec3::splat(f32::INFINITY)),
    ] {
        let e = InstancedScene::build(sphere(), vec![Instance::new(0, Affine3A::IDENTITY), Instance::new(0, m)], &cfg)
            .unwrap_err();
        assert!(matches!(e, Error::BadTransform { instance: 1 }), "{e}");
    }
    let ray = Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z);
    let empty = InstancedScene::build(sphere(), vec![], &cfg).unwrap();
    assert!(empty.intersect(&ray).is_none() && !empty.occluded(&ray) && empty.bounds().is_none());
    // An instance of an object with nothing hittable in it is left out of the top level.
    let nothing = TriangleMesh::from_slices("nan", &[f32::NAN; 9], &[0, 1, 2]).unwrap();
    let s = InstancedScene::build(vec![vec![nothing]], vec![Instance::new(0, Affine3A::IDENTITY)], &cfg).unwrap();
    assert!(s.intersect(&ray).is_none());
    let one = InstancedScene::build(sphere(), vec![Instance::new(0, Affine3A::IDENTITY)], &cfg).unwrap();
    let h = one.intersect(&ray).expect("the sphere");
    assert_eq!(h.inst_id, 0);
    assert!((h.t - 4.0).abs() < 0.05);
}

#[test]
fn memory_counts_objects_once() {
    let (objects, instances) = world(300, 20.0, Vec3::ZERO, 31);
    let scene = InstancedScene::build(objects, instances, &BuildConfig::default()).unwrap();
    let s = scene.stats();
    assert_eq!(s.instances, 300);
    assert!(s.instanced_triangles > 50 * s.unique_triangles as u64);
    assert!((s.bytes as u64) * 10 < s.flattened_bytes, "{} vs {}", s.bytes, s.flattened_bytes);
}

#[test]
fn offset_secondary_rays_do_not_hit_their_own_convex_instance() {
    // Rays leaving a sphere outward can hit nothing in a world of that one sphere. The sphere is
    // small and far out, so the object-space transform of a ray origin rounds by about as much as
    // an offset based on each coordinate's own ulps would move it (the error of one run's
    // big world). Leaving by `offset_ray_origin` must still never hit the sphere again.
    let mut self_hits = 0;
    let mut rays = 0;
    for (k, t) in
        [Vec3::new(3.0, 0.4, -157.0), Vec3::new(-900.0, 0.2, 40.0), Vec3::new(1e4, 1e4, 0.3)].iter().enumerate()
    {
        let objects = vec![vec![procedural::uv_sphere(Vec3::ZERO, 0.05, 16, 32)]];
        let rot = Quat::from_axis_angle(Vec3::new(0.3, 1.0, 0.2).normalize(), 0.7);
        let inst = Instance::new(0, Affine3A::from_scale_rotation_translation(Vec3::splat(1.3), rot, *t));
        let scene = InstancedScene::build(objects, vec![inst], &BuildConfig::watertight()).unwrap();
        let mut rng = Pcg32::new(40 + k as u64, 1);
        for _ in 0..4000 {
            let from = *t + uniform_direction(&mut rng) * 2.0;
            let Some(h) = scene.intersect(&Ray::new(from, *t - from)) else { continue };
            let p = from + (*t - from) * h.t;
            // Facing the way the ray came from, i.e. outward.
            let n = if h.ng.dot(*t - from) < 0.0 { h.ng } else { -h.ng };
            let o = strahl::offset_ray_origin(p, n);
            let mut d = uniform_direction(&mut rng);
            if d.dot(n) < 0.0 {
                d = -d;
            }
            rays += 1;
            if scene.occluded(&Ray::new(o, d)) {
                self_hits += 1;
            }
        }
    }
    assert!(rays > 10_000, "{rays}");
    assert_eq!(self_hits, 0, "{self_hits} of {rays} outward rays hit their own sphere");
}

#[test]
fn prebuilt_objects_must_share_their_tests() {
    let sphere = || vec![procedural::uv_sphere(Vec3::ZERO, 1.0, 8, 16)];
    let a = strahl::Scene::build(sphere(), &BuildConfig::default()).unwrap();
    let b = strahl::Scene::build(sphere(), &BuildConfig::watertight()).unwrap();
    let place = |o| Instance::new(o, Affine3A::from_translation(Vec3::new(3.0 * o as f32, 0.0, 0.0)));
    let e = InstancedScene::from_scenes(vec![a.clone(), b], vec![place(0), place(1)]).unwrap_err();
    assert!(matches!(e, Error::MixedTests), "{e}");
    let same = InstancedScene::from_scenes(vec![a.clone(), a], vec![place(0), place(1)]).unwrap();
    let h = same.intersect(&Ray::new(Vec3::new(3.0, 5.0, 0.0), Vec3::new(0.0, -1.0, 0.0))).unwrap();
    assert_eq!(h.inst_id, 1);
    assert_eq!(
        same.intersect(&Ray::new(Vec3::new(3.0, 5.0, 0.0), -Vec3::Y)),
        same.intersect_brute_force(&Ray::new(Vec3::new(3.0, 5.0, 0.0), -Vec3::Y))
    );
}
