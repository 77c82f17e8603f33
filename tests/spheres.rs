//! Analytic spheres (issue 30): every query shape against brute force over the same scene, the
//! sphere tests against float64 roots, mixed mesh-and-sphere scenes, bad input, persistence.

use glam::{DVec3, Vec3};
use strahl::raygen::Pcg32;
use strahl::shapes::sphere_roots_f64;
use strahl::{
    BoxTest, BuildConfig, Camera, Coherence, Error, HitPacket, HitStream, Instance, InstancedScene, PACKET_WIDTH,
    Query, Ray, RayPacket, RayStream, Scene, SphereSet, SphereTest, offset_ray_origin, procedural, raygen,
};

fn flake(levels: u32) -> SphereSet {
    SphereSet::from_pairs("flake", &procedural::sphereflake_spheres(levels)).unwrap()
}

/// A mesh (a tessellated sphere and a floor) and two sphere sets in one scene.
fn mixed(test: SphereTest, boxes: BoxTest) -> Scene {
    let meshes = vec![procedural::uv_sphere(Vec3::new(2.5, 0.0, 0.0), 0.8, 10, 20), {
        let mut q = procedural::quad(12.0, 12.0);
        q.map_positions(|p| p - Vec3::Y * 1.2);
        q
    }];
    let extra = SphereSet::new(
        "pair",
        vec![Vec3::new(-2.5, 0.0, 0.3), Vec3::new(-2.2, 0.4, -0.2)],
        vec![0.6, 0.3], // overlapping spheres
    )
    .unwrap();
    let cfg = BuildConfig { sphere_test: test, box_test: boxes, ..BuildConfig::default() };
    Scene::build_with_spheres(meshes, vec![flake(2), extra], &cfg).unwrap()
}

fn random_rays(n: usize, seed: u64) -> RayStream {
    let mut rng = Pcg32::new(seed, 11);
    let mut v = |s: f32| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 * s - Vec3::splat(s);
    (0..n)
        .map(|i| {
            let o = v(5.0);
            let d = v(1.5) - o;
            match i % 17 {
                0 => Ray::new(o, Vec3::ZERO),
                1 => Ray::new(o, Vec3::new(f32::NAN, 1.0, 0.0)),
                2 => Ray::segment(o, d, 0.0, 0.4),
                3 => Ray::new(Vec3::ZERO, d), // from inside the flake's big sphere
                _ => Ray::new(o, d * (0.5 + (i % 5) as f32)),
            }
        })
        .collect()
}

/// Criterion: every query shape (single ray, packet, stream of either coherence, parallel
/// stream; closest and any hit) gives brute force's answer, for each sphere test and box test,
/// in a scene mixing meshes and spheres; a fair share of the rays hit spheres and triangles.
#[test]
fn every_query_shape_matches_brute_force() {
    let rays = random_rays(3000, 1);
    let cam = Camera::look_at(Vec3::new(0.0, 1.0, 6.0), Vec3::ZERO, Vec3::Y, 60.0);
    let (primary, _) = raygen::primary(&cam, 64, 48);
    for test in SphereTest::ALL {
        for boxes in BoxTest::ALL {
            let scene = mixed(test, boxes);
            let meshes = scene.meshes().len() as u32;
            for (rays, what) in [(&rays, "random"), (&primary, "primary")] {
                let (mut sphere_hits, mut tri_hits) = (0, 0);
                let expect: Vec<_> = (0..rays.len()).map(|i| scene.intersect_brute_force(&rays.get(i))).collect();
                for (i, e) in expect.iter().enumerate() {
                    let r = rays.get(i);
                    assert_eq!(scene.intersect(&r), *e, "{test:?} {boxes:?} {what} ray {i}");
                    assert_eq!(scene.occluded(&r), e.is_some(), "{test:?} {boxes:?} {what} occluded ray {i}");
                    match e {
                        Some(h) if h.geom_id >= meshes => sphere_hits += 1,
                        Some(_) => tri_hits += 1,
                        None => {}
                    }
                }
                assert!(sphere_hits > rays.len() / 10 && tri_hits > rays.len() / 20, "{sphere_hits} {tri_hits}");
                for k in (0..rays.len()).step_by(PACKET_WIDTH) {
                    let n = (rays.len() - k).min(PACKET_WIDTH);
                    let p: RayPacket = rays.packet(k, n);
                    let mut hp = HitPacket::default();
                    scene.intersect_packet(&p, &mut hp);
                    let occ = scene.occluded_packet(&p);
                    for l in 0..n {
                        assert_eq!(hp.get(l), expect[k + l], "{test:?} {boxes:?} {what} packet ray {}", k + l);
                        assert_eq!(occ & (1 << l) != 0, expect[k + l].is_some(), "{what} packet occlusion {}", k + l);
                    }
                }
                for c in [Coherence::Coherent, Coherence::Incoherent] {
                    let (mut hs, mut hp) = (HitStream::default(), HitStream::default());
                    scene.intersect_stream(rays, &mut hs, c);
                    scene.intersect_stream_par(rays, &mut hp, c);
                    let (mut os, mut op) = (Vec::new(), Vec::new());
                    scene.occluded_stream(rays, &mut os, c);
                    scene.occluded_stream_par(rays, &mut op, c);
                    for (i, e) in expect.iter().enumerate() {
                        assert_eq!(hs.get(i), *e, "{test:?} {boxes:?} {what} {c:?} stream ray {i}");
                        assert_eq!(hp.get(i), *e, "{test:?} {boxes:?} {what} {c:?} parallel stream ray {i}");
                        assert_eq!(os[i], e.is_some(), "{what} {c:?} occlusion stream ray {i}");
                        assert_eq!(op[i], e.is_some(), "{what} {c:?} parallel occlusion stream ray {i}");
                    }
                }
            }
        }
    }
}

/// The nearest root over all spheres in float64, in `(0, inf)`.
fn reference_t(spheres: &[(Vec3, f32)], o: Vec3, d: Vec3) -> Option<f64> {
    let (o, d) = (o.as_dvec3(), d.as_dvec3());
    let mut best: Option<f64> = None;
    for &(c, r) in spheres {
        if let Some((t0, t1)) = sphere_roots_f64(c.as_dvec3(), r as f64, o, d) {
            let t = if t0 > 0.0 { t0 } else { t1 };
            if t > 0.0 && best.is_none_or(|b| t < b) {
                best = Some(t);
            }
        }
    }
    best
}

/// Criterion: camera rays at the level-2 analytic sphereflake from 3.6 units away and from
/// 3600 (the field of view narrowed to keep the framing): the robust test's hit distances lie
/// within 2e-6 relative of the float64 roots at both distances, and it agrees with float64 on
/// hit or miss except for rays within 1e-6 relative of a silhouette. The seeds' two forms are
/// printed (they fail at the far camera: the chart in the README).
#[test]
fn robust_test_matches_float64_near_and_far() {
    for dist in [3.6f32, 3600.0] {
        let spheres = procedural::sphereflake_spheres(2);
        let eye = Vec3::new(0.0, 0.8, 3.5).normalize() * dist;
        let fov = 2.0 * (1.7 / dist).atan().to_degrees();
        let cam = Camera::look_at(eye, Vec3::ZERO, Vec3::Y, fov);
        let (rays, _) = raygen::primary(&cam, 96, 72);
        for test in SphereTest::ALL {
            let cfg = BuildConfig { sphere_test: test, ..BuildConfig::default() };
            let scene =
                Scene::build_with_spheres(vec![], vec![SphereSet::from_pairs("f", &spheres).unwrap()], &cfg).unwrap();
            let mut hits = HitStream::default();
            scene.intersect_stream(&rays, &mut hits, Coherence::Coherent);
            let (mut worst, mut disagree, mut hit_count) = (0.0f64, 0, 0);
            for i in 0..rays.len() {
                let r = rays.get(i);
                let e = reference_t(&spheres, r.origin, r.dir);
                match (hits.get(i), e) {
                    (Some(h), Some(t)) => {
                        worst = worst.max((h.t as f64 - t).abs() / t);
                        hit_count += 1;
                    }
                    (None, None) => {}
                    _ => {
                        // Within 1e-4 relative of a silhouette, either answer is fair.
                        let near_edge = spheres.iter().any(|&(c, rad)| {
                            let (o, d) = (r.origin.as_dvec3(), r.dir.as_dvec3().normalize());
                            let f: DVec3 = c.as_dvec3() - o;
                            let dist = (f - d * f.dot(d)).length();
                            (dist - rad as f64).abs() <= 1e-6 * f.length()
                        });
                        if !near_edge {
                            disagree += 1;
                        }
                    }
                }
            }
            eprintln!(
                "{test:?} from distance {dist}: {hit_count} hits, worst relative t error {worst:.2e}, {disagree} far from silhouettes disagree"
            );
            if test == SphereTest::Robust {
                assert!(hit_count > rays.len() / 5, "{hit_count} hits");
                assert!(worst < 2e-6, "robust test from {dist}: {worst:e}");
                assert_eq!(disagree, 0, "robust test from {dist}");
            }
        }
    }
}

/// Criterion: a ray leaving a sphere's surface along the normal, its origin moved off the
/// surface by [`offset_ray_origin`] (the renderer's secondary rays), never hits that sphere
/// again, with any test. Without the offset (`tnear = 0` from the computed hit point) a float
/// test may find the sphere again at a tiny distance; the robust test keeps that distance below
/// 1e-5 of the radius (the origin's own rounding), the count is printed for each test.
#[test]
fn no_self_hits_leaving_the_surface() {
    for test in SphereTest::ALL {
        let cfg = BuildConfig { sphere_test: test, ..BuildConfig::default() };
        let scene = Scene::build_with_spheres(vec![], vec![flake(1)], &cfg).unwrap();
        let cam = Camera::look_at(Vec3::new(0.3, 1.0, 3.0), Vec3::ZERO, Vec3::Y, 50.0);
        let (rays, _) = raygen::primary(&cam, 48, 48);
        let (mut raw_self, mut offset_self, mut hits, mut worst) = (0, 0, 0, 0.0f32);
        for i in 0..rays.len() {
            let r = rays.get(i);
            let Some(h) = scene.intersect(&r) else { continue };
            hits += 1;
            let p = r.origin + r.dir * h.t;
            let n = h.ng.normalize();
            let same = |h2: Option<strahl::Hit>| h2.filter(|h2| (h2.prim_id, h2.geom_id) == (h.prim_id, h.geom_id));
            if let Some(h2) = same(scene.intersect(&Ray::new(p, n))) {
                raw_self += 1;
                worst = worst.max(h2.t / scene.spheres()[0].radii()[h.prim_id as usize]);
            }
            offset_self += same(scene.intersect(&Ray::new(offset_ray_origin(p, h.ng), n))).is_some() as usize;
        }
        eprintln!(
            "{test:?}: of {hits} rays leaving along the normal, {raw_self} hit their sphere again from the hit \
             point (largest t {worst:.1e} radii), {offset_self} from the offset origin"
        );
        assert!(hits > 500);
        assert_eq!(offset_self, 0, "{test:?}: self-hits from offset origins");
        if test == SphereTest::Robust {
            assert!(worst < 1e-5, "robust test: self-hit at {worst:e} radii");
        }
    }
}

/// Criterion: bad spheres are typed errors naming the set and the sphere; bad rays miss; an
/// empty sphere list leaves a mesh scene's answers unchanged; placing spheres by a transform
/// that would make them ellipsoids is a typed error.
#[test]
fn bad_spheres_and_rays() {
    let c = vec![Vec3::ZERO, Vec3::X];
    for (radii, index) in
        [(vec![1.0, 0.0], 1), (vec![-1.0, 1.0], 0), (vec![1.0, f32::NAN], 1), (vec![f32::INFINITY, 1.0], 0)]
    {
        match SphereSet::new("s", c.clone(), radii.clone()) {
            Err(Error::BadSphere { set, index: i, .. }) => assert_eq!((set.as_str(), i), ("s", index), "{radii:?}"),
            other => panic!("{radii:?}: {other:?}"),
        }
    }
    assert!(matches!(SphereSet::new("s", vec![Vec3::NAN], vec![1.0]), Err(Error::BadSphere { index: 0, .. })));
    assert!(matches!(SphereSet::new("s", vec![Vec3::splat(1e30)], vec![1.0]), Err(Error::BadSphere { .. })));
    assert!(matches!(SphereSet::new("s", c.clone(), vec![1.0]), Err(Error::BadSphere { .. })));
    let empty = SphereSet::new("none", vec![], vec![]).unwrap();
    let scene = Scene::build_with_spheres(vec![], vec![empty.clone()], &BuildConfig::default()).unwrap();
    assert!(scene.intersect(&Ray::new(Vec3::Z, -Vec3::Z)).is_none());
    assert!(scene.bounds().is_none());
    let one = SphereSet::new("one", vec![Vec3::ZERO], vec![1.0]).unwrap();
    let scene = Scene::build_with_spheres(vec![], vec![one.clone()], &BuildConfig::default()).unwrap();
    for bad in [
        Ray::new(Vec3::Z * 3.0, Vec3::ZERO),
        Ray::new(Vec3::Z * 3.0, Vec3::new(0.0, f32::NAN, -1.0)),
        Ray::new(Vec3::new(f32::INFINITY, 0.0, 3.0), -Vec3::Z),
        Ray::segment(Vec3::Z * 3.0, -Vec3::Z, 5.0, 1.0),
    ] {
        assert!(scene.intersect(&bad).is_none() && !scene.occluded(&bad), "{bad:?}");
    }
    let h = scene.intersect(&Ray::new(Vec3::Z * 3.0, -Vec3::Z)).unwrap();
    assert_eq!((h.t, h.prim_id, h.geom_id), (2.0, 0, 0));
    assert!((h.ng - Vec3::Z).length() < 1e-6);
    let squash = glam::Affine3A::from_scale(Vec3::new(1.0, 2.0, 1.0));
    let err = InstancedScene::from_scenes(
        vec![scene],
        vec![Instance::new(0, glam::Affine3A::IDENTITY), Instance::new(0, squash)],
    );
    assert!(matches!(err, Err(Error::SphereInstanceNotSimilar { instance: 1 })), "{err:?}");
}

/// Criterion: a scene with spheres survives `to_bytes`/`from_bytes` with every answer equal.
#[test]
fn persisted_scene_keeps_its_spheres() {
    let scene = mixed(SphereTest::Geometric, BoxTest::Fast);
    let back = Scene::from_bytes(&scene.to_bytes()).unwrap();
    assert_eq!(back.spheres(), scene.spheres());
    assert_eq!(back.sphere_test(), SphereTest::Geometric);
    let rays = random_rays(2000, 9);
    for i in 0..rays.len() {
        assert_eq!(back.intersect(&rays.get(i)), scene.intersect(&rays.get(i)), "ray {i}");
    }
}

/// Criterion: the queries beyond the first hit see spheres: every crossing of random rays
/// (entering and leaving roots) against brute force over the float64 roots, `contains` for
/// points inside and outside disjoint spheres, and the closest point against brute force, in a
/// scene that also holds a mesh.
#[test]
fn spatial_queries_see_spheres() {
    use strahl::SpatialQuery;
    let spheres: Vec<(Vec3, f32)> = (0..40)
        .map(|i| {
            let (x, z) = ((i % 8) as f32 * 2.5 - 9.0, (i / 8) as f32 * 2.5 - 5.0);
            (Vec3::new(x, 0.3 * (i % 3) as f32, z), 0.4 + 0.1 * (i % 5) as f32)
        })
        .collect();
    let set = SphereSet::from_pairs("grid", &spheres).unwrap();
    let cfg = BuildConfig::default();
    let mut floor = procedural::quad(30.0, 30.0);
    floor.map_positions(|p| p - Vec3::Y * 2.0);
    let scene = Scene::build_with_spheres(vec![floor], vec![set], &cfg).unwrap();
    let rays = random_rays(500, 3);
    let mut out = Vec::new();
    let mut checked = 0;
    for i in 0..rays.len() {
        let r = rays.get(i);
        if !r.is_valid() {
            continue;
        }
        scene.all_hits(&r, &mut out);
        let sphere_ts: Vec<f32> = out.iter().filter(|h| h.geom_id == 1).map(|h| h.t).collect();
        let mut expect: Vec<f64> = Vec::new();
        for &(c, rad) in &spheres {
            if let Some((t0, t1)) = sphere_roots_f64(c.as_dvec3(), rad as f64, r.origin.as_dvec3(), r.dir.as_dvec3()) {
                expect.extend([t0, t1].into_iter().filter(|&t| t > r.tnear.max(0.0) as f64 && t <= r.tfar as f64));
            }
        }
        expect.sort_by(f64::total_cmp);
        assert_eq!(sphere_ts.len(), expect.len(), "ray {i}: {sphere_ts:?} against {expect:?}");
        for (a, b) in sphere_ts.iter().zip(&expect) {
            assert!((*a as f64 - b).abs() <= 1e-5 * b.max(1.0), "ray {i}: {a} against {b}");
        }
        checked += expect.len();
    }
    assert!(checked > 50, "{checked} crossings");
    let mut rng = Pcg32::new(5, 1);
    for k in 0..400 {
        let p = Vec3::new(rng.next_f32() * 22.0 - 11.0, rng.next_f32() * 2.0 - 0.8, rng.next_f32() * 14.0 - 7.0);
        let dist = spheres.iter().map(|&(c, r)| (p - c).length() - r).fold(f32::INFINITY, f32::min);
        if dist.abs() > 1e-3 {
            assert_eq!(scene.contains(p), dist < 0.0, "point {k} {p}, signed distance {dist}");
        }
        let cp = scene.closest_point(p, f32::INFINITY).unwrap();
        let floor_d = (p.y + 2.0).abs();
        let expect = dist.abs().min(floor_d);
        assert!((cp.distance - expect).abs() < 1e-4, "point {k}: {} against {expect}", cp.distance);
        if dist.abs() < floor_d - 1e-3 {
            assert_eq!(cp.geom_id, 1, "point {k}");
            assert!((cp.point - p).length() - cp.distance < 1e-4);
        }
    }
}

/// Criterion: a two-level scene whose objects hold spheres (one with a mesh too), placed by
/// rotations, mirrors, uniform scales and translations, answers every query shape as its
/// flattened twin does (hits, normals in world space, instance ids mapped), and as brute force
/// over the instances; all hits and closest points agree with the flattened twin.
#[test]
fn instanced_spheres_match_their_flattened_twin() {
    use glam::{Affine3A, Quat};
    use strahl::SpatialQuery;
    let cfg = BuildConfig::default();
    let flake = Scene::build_with_spheres(vec![], vec![flake(1)], &cfg).unwrap();
    let mixed_obj = Scene::build_with_spheres(
        vec![procedural::cuboid(Vec3::splat(-0.5), Vec3::splat(0.5))],
        vec![SphereSet::new("ball", vec![Vec3::new(0.0, 1.0, 0.0)], vec![0.5]).unwrap()],
        &cfg,
    )
    .unwrap();
    let mut instances = Vec::new();
    for i in 0..12 {
        let a = i as f32 * 0.7;
        let s = 0.5 + 0.15 * (i % 4) as f32;
        let rot = Quat::from_euler(glam::EulerRot::XYZ, a, 0.3 * a, -a);
        let mut m = Affine3A::from_scale_rotation_translation(
            Vec3::splat(s),
            rot,
            Vec3::new((i % 4) as f32 * 3.0 - 4.5, (i / 4) as f32 * 2.5 - 2.5, -1.0),
        );
        if i % 5 == 0 {
            m *= Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0)); // a mirror
        }
        instances.push(Instance::new(i % 2, m));
    }
    let scene = InstancedScene::from_scenes(vec![flake, mixed_obj], instances.clone()).unwrap();
    let flat = scene.flatten(&cfg).unwrap();
    let rays = random_rays(3000, 21);
    let cam = Camera::look_at(Vec3::new(0.0, 0.5, 9.0), Vec3::ZERO, Vec3::Y, 70.0);
    let (primary, _) = raygen::primary(&cam, 48, 48);
    for (rays, what) in [(&rays, "random"), (&primary, "primary")] {
        let mut hits = 0;
        let (mut hs, mut os) = (HitStream::default(), Vec::new());
        scene.intersect_stream(rays, &mut hs, Coherence::Incoherent);
        scene.occluded_stream(rays, &mut os, Coherence::Incoherent);
        let (mut hc, mut oc) = (HitStream::default(), Vec::new());
        scene.intersect_stream(rays, &mut hc, Coherence::Coherent);
        scene.occluded_stream(rays, &mut oc, Coherence::Coherent);
        for i in 0..rays.len() {
            let r = rays.get(i);
            let (a, f, b) = (scene.intersect(&r), flat.intersect(&r), scene.intersect_brute_force(&r));
            assert_eq!(a.is_some(), f.is_some(), "{what} ray {i}: {a:?} against flattened {f:?}");
            assert_eq!(a.map(|h| h.inst_id), b.map(|h| h.inst_id), "{what} ray {i} against brute force");
            if let (Some(a), Some(f)) = (a, f) {
                hits += 1;
                assert!((a.t - f.t).abs() <= 1e-4 * f.t.max(1.0), "{what} ray {i}: t {} against {}", a.t, f.t);
                assert!(
                    a.ng.normalize().dot(f.ng.normalize()) > 0.999,
                    "{what} ray {i}: {:?} against {:?}",
                    a.ng,
                    f.ng
                );
            }
            assert_eq!(scene.occluded(&r), a.is_some(), "{what} occluded ray {i}");
            assert_eq!(
                hs.get(i).map(|h| (h.inst_id, h.prim_id)),
                a.map(|h| (h.inst_id, h.prim_id)),
                "{what} incoherent {i}"
            );
            assert_eq!(
                hc.get(i).map(|h| (h.inst_id, h.prim_id)),
                a.map(|h| (h.inst_id, h.prim_id)),
                "{what} coherent {i}"
            );
            assert_eq!((os[i], oc[i]), (a.is_some(), a.is_some()), "{what} occlusion streams {i}");
        }
        assert!(hits > rays.len() / 10, "{what}: {hits} hits");
    }
    let (mut a, mut f) = (Vec::new(), Vec::new());
    for i in 0..300 {
        let r = rays.get(i);
        scene.all_hits(&r, &mut a);
        flat.all_hits(&r, &mut f);
        assert_eq!(a.len(), f.len(), "all hits of ray {i}");
        for (x, y) in a.iter().zip(&f) {
            assert!((x.t - y.t).abs() <= 1e-4 * y.t.max(1.0), "all hits of ray {i}");
        }
    }
    let mut rng = Pcg32::new(8, 8);
    for k in 0..200 {
        let p = Vec3::new(rng.next_f32() * 12.0 - 6.0, rng.next_f32() * 8.0 - 4.0, rng.next_f32() * 4.0 - 3.0);
        let (a, f) = (scene.closest_point(p, f32::INFINITY).unwrap(), flat.closest_point(p, f32::INFINITY).unwrap());
        assert!((a.distance - f.distance).abs() < 1e-4, "point {k}: {} against {}", a.distance, f.distance);
    }
}

/// Criterion: a scene file's analytic spheres render as their finely tessellated twins do
/// (mean 8-bit difference below 2 and 97% of the pixels within 8/255; measured: identical at
/// 96×72), while a smaller ball changes over 5% of the pixels (the control), and the new keys'
/// bad uses are `Error::SceneFile`.
#[test]
fn scene_file_spheres_render_like_their_tessellation() {
    use strahl::SceneFile;
    use strahl::render::Renderer;
    let dir = std::env::temp_dir().join(format!("strahl-spheres-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = |ball: &str| {
        format!(
            r#"
[camera]
eye = [0.0, 1.5, -4.0]
look_at = [0.0, 0.6, 0.0]
fov = 45.0
[render]
width = 96
height = 72
max_depth = 4
[[light]]
position = [-4.0, 8.0, -6.0]
[material.mirror]
color = 0.1
reflect = 0.6
specular = 0.8
shininess = 100.0
[material.floor]
color = [0.8, 0.1, 0.1]
checker = {{ color = [0.9, 0.9, 0.2], size = 0.5 }}
[mesh.floor]
quad = {{ size = [20.0, 20.0] }}
material = "floor"
[mesh.ball]
{ball}
material = "mirror"
[[instance]]
mesh = "floor"
[[instance]]
mesh = "ball"
translate = [0.0, 0.8, 0.0]
scale = 0.8
"#
        )
    };
    let render = |text: String, name: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let file = SceneFile::read(&path).unwrap();
        let objects = file.load_objects().unwrap();
        let world = file.world(&objects).unwrap();
        let q = file.build_from(objects, &BuildConfig::default()).unwrap();
        let camera = file.camera.unwrap().render_camera().unwrap();
        let settings = file.render.settings;
        Renderer { query: &q, world: &world, camera, settings }.render(&|_| {}).unwrap().0.to_srgb8()
    };
    let a = render(scene("sphere = { radius = 1.0 }\nanalytic = true"), "analytic.toml");
    let b = render(scene("sphere = { radius = 1.0, stacks = 256, slices = 512 }"), "tessellated.toml");
    let mean = a.iter().zip(&b).map(|(x, y)| x.abs_diff(*y) as f64).sum::<f64>() / a.len() as f64;
    let close = a.chunks(3).zip(b.chunks(3)).filter(|(p, q)| p.iter().zip(*q).all(|(x, y)| x.abs_diff(*y) <= 8)).count()
        as f64
        / (a.len() / 3) as f64;
    eprintln!("analytic against tessellated: mean difference {mean:.2}, {:.1}% within 8/255", close * 100.0);
    assert!(mean < 2.0 && close > 0.97, "mean {mean}, close {close}");
    // The control: a smaller ball changes many pixels, so the two renders above did show it.
    let c = render(scene("sphere = { radius = 0.7 }\nanalytic = true"), "smaller.toml");
    let changed =
        a.chunks(3).zip(c.chunks(3)).filter(|(p, q)| p.iter().zip(*q).any(|(x, y)| x.abs_diff(*y) > 8)).count();
    assert!(changed * 20 > a.len() / 3, "a smaller ball changed only {changed} pixels");
    for (bad, what) in [
        ("quad = { size = [1.0, 1.0] }\nanalytic = true", "analytic"),
        ("sphere = { radius = 1.0, stacks = 4, slices = 8 }\nanalytic = true", "do not apply"),
        ("sphere = { radius = 1.0 }", "needs `stacks` and `slices`"),
        ("sphereflake = { levels = 8 }\nanalytic = true", "at most 7"),
        ("sphere = { radius = -1.0 }\nanalytic = true", "radius"),
    ] {
        let path = dir.join("bad.toml");
        std::fs::write(&path, scene(bad)).unwrap();
        match SceneFile::read(&path) {
            Err(Error::SceneFile { message, .. }) => assert!(message.contains(what), "{bad}: {message}"),
            other => panic!("{bad}: {other:?}"),
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
