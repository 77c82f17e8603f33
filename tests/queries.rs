//! The queries beyond the first hit (`strahl::query`): every hit, crossings, closest point,
//! inside/outside and signed distance, against brute force over every triangle and against
//! analytic answers, for flat and instanced scenes.

mod common;

use common::{random_rays, random_soup, rng_vec};
use glam::{Affine3A, DVec3, Quat, Vec3};
use strahl::procedural::{cuboid, uv_sphere};
use strahl::query::{SpatialQuery, batch};
use strahl::raygen::Pcg32;
use strahl::{BuildConfig, Hit, Instance, InstancedScene, Query, Ray, Scene, TriangleMesh, intersect_triangle};

/// Every hit of `ray`, by testing every triangle with the scene's triangle test.
fn brute_all_hits(meshes: &[TriangleMesh], cfg: &BuildConfig, ray: &Ray) -> Vec<(u32, u32, f32)> {
    let mut out = Vec::new();
    for (g, m) in meshes.iter().enumerate() {
        for i in 0..m.triangle_count() {
            if !m.is_hittable(i) {
                continue;
            }
            if let Some((t, _, _)) = intersect_triangle(cfg.triangle_test, ray, m.triangle(i)) {
                out.push((g as u32, i as u32, t));
            }
        }
    }
    out.sort_by(|a, b| a.2.total_cmp(&b.2).then((a.0, a.1).cmp(&(b.0, b.1))));
    out
}

/// Distance from `p` to triangle `abc` by a method of its own: the projection onto the plane if it
/// falls inside, else the nearest of the three edges as segments (float64).
fn brute_distance(meshes: &[TriangleMesh], p: Vec3) -> f64 {
    let p = p.as_dvec3();
    let seg = |a: DVec3, b: DVec3| {
        let ab = b - a;
        let s = ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
        (a + ab * s - p).length()
    };
    let mut best = f64::INFINITY;
    for m in meshes {
        for i in 0..m.triangle_count() {
            if !m.is_hittable(i) {
                continue;
            }
            let [a, b, c] = m.triangle(i).map(|v| v.as_dvec3());
            let n = (b - a).cross(c - a).normalize();
            let q = p - n * (p - a).dot(n);
            let inside = [(a, b), (b, c), (c, a)].iter().all(|&(x, y)| (y - x).cross(q - x).dot(n) >= 0.0);
            let d = if inside { (p - q).length() } else { seg(a, b).min(seg(b, c)).min(seg(c, a)) };
            best = best.min(d);
        }
    }
    best
}

fn key(h: &Hit) -> (u32, u32) {
    (h.geom_id, h.prim_id)
}

#[test]
fn all_hits_match_brute_force_for_every_triangle_test() {
    let meshes = vec![random_soup(1, 3000, 0.2), uv_sphere(Vec3::new(0.2, 0.1, 0.0), 0.7, 12, 24)];
    for cfg in [BuildConfig::default(), BuildConfig::watertight(), BuildConfig::high()] {
        let scene = Scene::build(meshes.clone(), &cfg).unwrap();
        let mut hits = Vec::new();
        let (mut total, mut rays_with_many) = (0, 0);
        for ray in random_rays(7, 400) {
            scene.all_hits(&ray, &mut hits);
            let want = brute_all_hits(&meshes, &cfg, &ray);
            let got: Vec<(u32, u32)> = hits.iter().map(key).collect();
            let want_keys: Vec<(u32, u32)> = want.iter().map(|w| (w.0, w.1)).collect();
            let (mut g, mut w) = (got.clone(), want_keys.clone());
            g.sort();
            w.sort();
            assert_eq!(g, w, "{:?} with {:?}", ray, cfg.triangle_test);
            // Nearest first, and the first is the closest hit.
            assert!(hits.windows(2).all(|p| p[0].t <= p[1].t));
            if let Some(first) = hits.first() {
                assert_eq!(first.t, scene.intersect(&ray).unwrap().t);
            }
            total += hits.len();
            rays_with_many += (hits.len() > 2) as usize;
        }
        assert!(total > 1000 && rays_with_many > 100, "the rays cross many surfaces: {total}, {rays_with_many}");
    }
}

#[test]
fn all_hits_respect_the_interval_and_bad_rays_hit_nothing() {
    let scene = Scene::build(vec![cuboid(Vec3::ZERO, Vec3::ONE)], &BuildConfig::watertight()).unwrap();
    let mut hits = Vec::new();
    let o = Vec3::new(0.3, 0.4, -1.0);
    scene.all_hits(&Ray::new(o, Vec3::Z), &mut hits);
    assert_eq!(hits.iter().map(|h| h.t).collect::<Vec<_>>(), vec![1.0, 2.0]);
    scene.all_hits(&Ray::segment(o, Vec3::Z, 1.0, 2.0), &mut hits);
    assert_eq!(hits.len(), 1, "tnear is exclusive, tfar inclusive");
    assert_eq!(hits[0].t, 2.0);
    for bad in [
        Ray::new(o, Vec3::ZERO),
        Ray::new(Vec3::NAN, Vec3::Z),
        Ray::new(o, Vec3::new(f32::NAN, 0.0, 1.0)),
        Ray::segment(o, Vec3::Z, 3.0, 1.0),
    ] {
        scene.all_hits(&bad, &mut hits);
        assert!(hits.is_empty(), "{bad:?}");
        assert_eq!(scene.count_crossings(&bad), 0);
    }
    let empty = Scene::build(vec![], &BuildConfig::default()).unwrap();
    assert_eq!(empty.count_crossings(&Ray::new(o, Vec3::Z)), 0);
    assert!(empty.closest_point(o, f32::INFINITY).is_none());
    assert!(!empty.contains(o));
    assert_eq!(empty.signed_distance(o), f32::INFINITY);
}

/// Rays through the edges and corners of a closed box hit two or more triangles at one point;
/// each crossing counts once, so every ray through the box crosses it exactly twice.
#[test]
fn rays_through_shared_edges_and_vertices_cross_once() {
    let scene = Scene::build(vec![cuboid(Vec3::ZERO, Vec3::ONE)], &BuildConfig::watertight()).unwrap();
    let mut raw = Vec::new();
    let mut shared = 0;
    // Through each face's diagonal (the edge its two triangles share), its corners and its edges'
    // midpoints, from outside, straight and slanted.
    let targets = [[0.5, 0.5], [0.25, 0.25], [0.75, 0.75], [0.0, 0.0], [1.0, 1.0], [0.0, 0.5], [0.5, 1.0], [0.3, 0.7]];
    for axis in 0..3 {
        for &[a, b] in &targets {
            for slant in [Vec3::ZERO, Vec3::new(0.01, 0.02, 0.015)] {
                let mut o = Vec3::splat(0.0);
                o[(axis + 1) % 3] = a;
                o[(axis + 2) % 3] = b;
                o[axis] = -1.0;
                let mut d = Vec3::ZERO;
                d[axis] = 1.0;
                let d = (d + slant).normalize();
                let ray = Ray::new(o - d * 0.0, d);
                scene.all_hits(&ray, &mut raw);
                let crossings = scene.count_crossings(&ray);
                shared += (raw.len() > crossings) as usize;
                // Rays along the box's own faces (a or b on the boundary without a slant) graze
                // it; every other ray enters and leaves once.
                let on_boundary = [a, b].iter().any(|&x| x == 0.0 || x == 1.0);
                if on_boundary && slant == Vec3::ZERO {
                    assert!(crossings.is_multiple_of(2), "{ray:?}: {crossings}");
                } else if !on_boundary {
                    assert_eq!(crossings, 2, "{ray:?}: {raw:?}");
                }
            }
        }
    }
    assert!(shared >= 6, "rays through shared edges met two triangles at once ({shared} rays)");
}

#[test]
fn closest_points_match_brute_force() {
    let meshes = vec![random_soup(3, 2000, 0.15), uv_sphere(Vec3::ZERO, 0.5, 10, 20)];
    let scene = Scene::build(meshes.clone(), &BuildConfig::high()).unwrap();
    let mut rng = Pcg32::new(5, 1);
    for _ in 0..300 {
        let p = rng_vec(&mut rng, -2.0, 2.0);
        let c = scene.closest_point(p, f32::INFINITY).unwrap();
        let want = brute_distance(&meshes, p);
        assert!((c.distance as f64 - want).abs() <= 1e-5 * (1.0 + want), "{p}: {} vs {want}", c.distance);
        // The point lies on the triangle it names, and its barycentrics reproduce it.
        let [a, b, cc] = meshes[c.geom_id as usize].triangle(c.prim_id as usize);
        let q = a * (1.0 - c.u - c.v) + b * c.u + cc * c.v;
        assert!((q - c.point).length() < 1e-5, "{q} vs {}", c.point);
        assert!(((c.point - p).length() - c.distance).abs() < 1e-5);
        // A bound below the distance finds nothing.
        assert!(scene.closest_point(p, c.distance * 0.999).is_none());
    }
    assert!(scene.closest_point(Vec3::NAN, 1.0).is_none());
    assert!(scene.closest_point(Vec3::ZERO, f32::NAN).is_none());
    assert!(scene.closest_point(Vec3::ZERO, -1.0).is_none());
}

#[test]
fn inside_and_signed_distance_of_closed_meshes() {
    let (lo, hi) = (Vec3::new(-0.3, -0.2, -0.4), Vec3::new(0.5, 0.6, 0.3));
    let center = Vec3::new(2.0, 0.0, 0.0);
    let meshes = vec![cuboid(lo, hi), uv_sphere(center, 0.8, 24, 48)];
    let scene = Scene::build(meshes.clone(), &BuildConfig::watertight()).unwrap();
    let mut rng = Pcg32::new(9, 3);
    let points: Vec<Vec3> =
        (0..4000).map(|_| rng_vec(&mut rng, -1.0, 1.0) * Vec3::new(2.0, 1.0, 1.0) + Vec3::X).collect();
    let inside = batch::contains(&scene, &points, 3);
    let sdf = batch::signed_distances(&scene, &points, 3);
    let mut wrong = 0;
    let mut n_inside = 0;
    for ((&p, &ins), &d) in points.iter().zip(&inside).zip(&sdf) {
        let in_box = p.cmpgt(lo).all() && p.cmplt(hi).all();
        // The tessellated sphere lies inside the true one; skip the thin shell between them.
        let r = (p - center).length();
        let in_ball = r < 0.8;
        let near_shell = (r - 0.8).abs() < 0.01;
        if near_shell {
            continue;
        }
        n_inside += (in_box || in_ball) as usize;
        wrong += (ins != (in_box || in_ball)) as usize;
        assert_eq!(d < 0.0, ins, "{p}");
        assert!((d.abs() as f64 - brute_distance(&meshes, p)).abs() < 1e-5, "{p}");
    }
    assert_eq!(wrong, 0);
    assert!(n_inside > 300, "{n_inside} points inside");
}

/// Instanced scenes answer as their flattened twin does, under rotation, non-uniform scale and
/// mirroring.
#[test]
fn instanced_queries_match_the_flattened_scene() {
    let object = vec![uv_sphere(Vec3::ZERO, 0.5, 8, 16), cuboid(Vec3::new(0.6, -0.2, -0.2), Vec3::new(1.0, 0.2, 0.2))];
    let instances = vec![
        Instance::new(0, Affine3A::IDENTITY),
        Instance::new(
            0,
            Affine3A::from_scale_rotation_translation(
                Vec3::new(0.5, 1.5, 0.8),
                Quat::from_rotation_y(0.7),
                Vec3::new(1.5, 0.3, -0.2),
            ),
        ),
        Instance::new(
            0,
            Affine3A::from_scale_rotation_translation(
                Vec3::new(-1.0, 0.7, 1.2),
                Quat::from_rotation_x(-0.4),
                Vec3::new(-1.2, -0.5, 0.4),
            ),
        ),
    ];
    let cfg = BuildConfig::watertight();
    let inst = InstancedScene::build(vec![object], instances, &cfg).unwrap();
    let flat = inst.flatten(&cfg).unwrap();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut many = 0;
    for ray in random_rays(21, 2000) {
        let ray = Ray { origin: ray.origin * 1.5, ..ray };
        inst.crossings(&ray, &mut a);
        flat.crossings(&ray, &mut b);
        assert_eq!(a.len(), b.len(), "{ray:?}");
        for (x, y) in a.iter().zip(&b) {
            assert!((x.t - y.t).abs() <= 1e-4 * x.t.abs().max(1.0), "{ray:?}");
            assert!(x.ng.normalize().dot(y.ng.normalize()) > 0.999);
            assert_ne!(x.inst_id, u32::MAX);
        }
        many += (a.len() >= 4) as usize;
    }
    assert!(many > 20, "{many} rays cross two solids");
    let mut rng = Pcg32::new(4, 4);
    let points: Vec<Vec3> = (0..500).map(|_| rng_vec(&mut rng, -2.5, 2.5)).collect();
    let (ci, cf) = (batch::closest_points(&inst, &points), batch::closest_points(&flat, &points));
    for ((p, x), y) in points.iter().zip(&ci).zip(&cf) {
        let (x, y) = (x.unwrap(), y.unwrap());
        assert!((x.distance - y.distance).abs() <= 1e-5 * (1.0 + y.distance), "{p}: {} vs {}", x.distance, y.distance);
    }
    assert_eq!(batch::contains(&inst, &points, 3), batch::contains(&flat, &points, 3));
    assert_eq!(batch::contains(&inst, &points, 1), batch::contains(&flat, &points, 1));
}

#[test]
fn batch_hit_lists_agree_with_single_queries() {
    let scene = Scene::build(vec![random_soup(8, 2000, 0.2)], &BuildConfig::watertight()).unwrap();
    let rays = random_rays(3, 1000);
    let lists = batch::hit_lists(&scene, &rays, true);
    let mut counts = vec![0; rays.len()];
    batch::count_hits(&scene, &rays, true, &mut counts);
    assert_eq!(lists.splits.len(), rays.len() + 1);
    let mut one = Vec::new();
    for (i, r) in rays.iter().enumerate() {
        scene.crossings(r, &mut one);
        assert_eq!(&lists.hits[lists.splits[i]..lists.splits[i + 1]], &one[..]);
        assert_eq!(counts[i] as usize, one.len());
    }
    assert!(lists.hits.len() > 1000);
}

/// The generalized winding number of a closed mesh at `p` (Jacobson et al. 2013): the sum of the
/// triangles' signed solid angles (Van Oosterom–Strackee) over 4π, in float64.
fn winding_number(meshes: &[TriangleMesh], p: Vec3) -> f64 {
    let p = p.as_dvec3();
    let mut sum = 0.0;
    for m in meshes {
        for i in 0..m.triangle_count() {
            let [a, b, c] = m.triangle(i).map(|v| v.as_dvec3() - p);
            let (la, lb, lc) = (a.length(), b.length(), c.length());
            let det = a.dot(b.cross(c));
            let den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
            sum += det.atan2(den);
        }
    }
    sum / (2.0 * std::f64::consts::PI)
}

/// The shared scenes' one closed mesh, Igea (when present): inside/outside by crossing parity
/// against generalized winding numbers, for points near the surface and far from it.
#[test]
fn inside_test_agrees_with_winding_numbers_on_igea() {
    let Some(path) = common::shared_scene("igea/igea.obj") else {
        eprintln!("../shared/scenes/igea not present: skipped");
        return;
    };
    let meshes = strahl::load_obj(path).unwrap();
    let scene = Scene::build(meshes.clone(), &BuildConfig::watertight()).unwrap();
    let (lo, hi) = scene.bounds().unwrap();
    let mut rng = Pcg32::new(17, 2);
    let mut points: Vec<Vec3> = (0..150).map(|_| lo + (hi - lo) * rng_vec(&mut rng, 0.0, 1.0)).collect();
    // Near the surface: triangle centres moved off by 0.1% of the diagonal, either way.
    let m = &meshes[0];
    let step = (hi - lo).length() * 1e-3;
    for k in 0..150 {
        let i = (rng.next_f32() * m.triangle_count() as f32) as usize % m.triangle_count();
        let [a, b, c] = m.triangle(i);
        let n = (b - a).cross(c - a).normalize_or_zero();
        let side = if k % 2 == 0 { 1.0 } else { -1.0 };
        points.push((a + b + c) / 3.0 + n * step * side);
    }
    let inside = batch::contains(&scene, &points, 3);
    let (mut wrong, mut n_in) = (0, 0);
    for (p, &got) in points.iter().zip(&inside) {
        let w = winding_number(&meshes, *p);
        assert!(!(0.1..0.9).contains(&w), "Igea is closed: winding numbers are 0 or 1, got {w} at {p}");
        let want = w > 0.5;
        n_in += want as usize;
        wrong += (got != want) as usize;
    }
    assert_eq!(wrong, 0, "{wrong} of {} points on the wrong side", points.len());
    assert!(n_in > 50, "{n_in} points inside");
}
