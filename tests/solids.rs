//! Solids (issue 30): primitives placed by affine maps and combined by CSG, checked against
//! point membership (`Solid::contains`, evaluated on the tree in float64) and across the query
//! forms (single, packet, stream; closest and any hit; tree against brute force).

use std::sync::Arc;

use glam::DVec3;
use glam::{Affine3A, Quat, Vec3};
use strahl::{
    Blob, BlobComponent, BuildConfig, CsgOp, Error, HitStream, Implicit, MeshSolid, Potential, Primitive,
    QuarticSolver, Query, Ray, RayPacket, RayStream, Scene, Solid, SpatialQuery, TriangleMesh,
};

/// A small deterministic generator (xorshift), uniform in [0, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next()
    }
    fn vec(&mut self, r: f32) -> Vec3 {
        Vec3::new(self.range(-r, r), self.range(-r, r), self.range(-r, r))
    }
}

fn placed(p: Primitive, scale: Vec3, angle: f32, at: Vec3) -> Solid {
    Solid::new(p).transformed(Affine3A::from_scale_rotation_translation(
        scale,
        Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), angle),
        at,
    ))
}

/// The die of the issue: a cube intersected with a sphere, minus pips, on a CSG tree.
fn die() -> Solid {
    let body = Solid::intersection(vec![
        Solid::new(Primitive::Box),
        Solid::new(Primitive::Sphere).transformed(Affine3A::from_scale(Vec3::splat(1.35))),
    ]);
    let pip = |at: Vec3| {
        Solid::new(Primitive::Sphere).transformed(Affine3A::from_scale_rotation_translation(
            Vec3::splat(0.18),
            Quat::IDENTITY,
            at,
        ))
    };
    let mut pips = vec![pip(Vec3::new(0.0, 0.0, 1.0))];
    for s in [-0.5, 0.5] {
        pips.push(pip(Vec3::new(1.0, s, s)));
        pips.push(pip(Vec3::new(s, 1.0, -s)));
    }
    Solid::difference(vec![body, Solid::union(pips)])
}

/// A solid of every closed primitive, and some CSG.
fn gallery() -> Vec<Solid> {
    vec![
        placed(Primitive::Sphere, Vec3::new(1.0, 0.5, 0.7), 0.3, Vec3::new(-3.0, 0.0, 0.0)),
        placed(Primitive::Box, Vec3::new(0.8, 0.3, 0.5), 0.7, Vec3::new(0.0, 3.0, 0.0)),
        placed(Primitive::Cylinder, Vec3::new(0.5, 0.5, 1.5), 1.1, Vec3::new(3.0, 0.0, 0.0)),
        placed(Primitive::Cone { r0: 0.8, r1: 0.2 }, Vec3::ONE, 0.4, Vec3::new(0.0, -3.0, 0.0)),
        placed(Primitive::Cone { r0: 0.0, r1: 1.0 }, Vec3::ONE, 2.0, Vec3::new(-3.0, -3.0, 0.0)),
        placed(Primitive::Torus { major: 1.0, minor: 0.3 }, Vec3::ONE, 0.9, Vec3::new(3.0, 3.0, 0.0)),
        placed(Primitive::Torus { major: 1.0, minor: 0.05 }, Vec3::ONE, 1.3, Vec3::new(-3.0, 3.0, 0.0)),
        die().transformed(Affine3A::from_rotation_translation(Quat::from_rotation_y(0.5), Vec3::new(0.0, 0.0, 0.0))),
        // A hyperboloid of one sheet, x² + y² − z² − 0.25 ≤ 0, clipped by a box.
        Solid::intersection(vec![
            Solid::new(Primitive::Quadric { coeffs: [1.0, 1.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.25] }),
            Solid::new(Primitive::Box),
        ])
        .transformed(Affine3A::from_translation(Vec3::new(3.0, -3.0, 0.0))),
        // A box cut by a tilted half-space.
        Solid::intersection(vec![
            Solid::new(Primitive::Box),
            Solid::new(Primitive::Plane).transformed(Affine3A::from_rotation_x(0.6)),
        ])
        .transformed(Affine3A::from_translation(Vec3::new(0.0, 0.0, 3.0))),
        // Superellipsoids: a rounded box, and a pinched star (non-convex, with thin tips).
        placed(Primitive::Superellipsoid { e: 0.25, n: 0.6 }, Vec3::splat(0.9), 0.5, Vec3::new(-3.0, 0.0, 3.0)),
        placed(Primitive::Superellipsoid { e: 2.5, n: 3.0 }, Vec3::ONE, 0.8, Vec3::new(3.0, 0.0, 3.0)),
        // Blobs with each potential, one carved by a negative component.
        placed(blob(Potential::Pov), Vec3::ONE, 0.3, Vec3::new(0.0, 3.0, 3.0)),
        placed(blob(Potential::Wyvill), Vec3::ONE, 1.0, Vec3::new(0.0, -3.0, 3.0)),
        placed(blob(Potential::Rational { d: 2.0 }), Vec3::splat(0.8), 1.7, Vec3::new(-3.0, 3.0, 3.0)),
        placed(blob(Potential::InverseSquare), Vec3::ONE, 2.2, Vec3::new(3.0, 3.0, 3.0)),
        // Super-toroids: a squared ring, and a pinched one (thin edges).
        placed(
            Primitive::Supertoroid { major: 1.0, minor: 0.35, e: 0.3, n: 0.4 },
            Vec3::ONE,
            0.6,
            Vec3::new(-3.0, 0.0, -3.0),
        ),
        placed(
            Primitive::Supertoroid { major: 1.0, minor: 0.3, e: 2.2, n: 2.5 },
            Vec3::ONE,
            1.4,
            Vec3::new(3.0, 0.0, -3.0),
        ),
        // Super-hyperboloids of one and two sheets.
        placed(
            Primitive::Superhyperboloid { e: 0.5, n: 1.5, sheets: 1, height: 1.0 },
            Vec3::splat(0.8),
            0.2,
            Vec3::new(0.0, 3.0, -3.0),
        ),
        placed(
            Primitive::Superhyperboloid { e: 1.5, n: 0.7, sheets: 2, height: 1.8 },
            Vec3::splat(0.7),
            2.4,
            Vec3::new(0.0, -3.0, -3.0),
        ),
        // Ratioquadrics: a pinched star (rounded tips) and a rounded box.
        placed(Primitive::Ratioquadric { p: 0.05, q: 0.2, r: 0.1 }, Vec3::ONE, 0.9, Vec3::new(-3.0, 3.0, -3.0)),
        placed(Primitive::Ratioquadric { p: 8.0, q: 8.0, r: 3.0 }, Vec3::ONE, 1.9, Vec3::new(3.0, 3.0, -3.0)),
        // Closed triangle meshes in CSG: a tessellated ball minus an inside-out (clockwise)
        // mesh cube, cut by an analytic cylinder.
        mesh_csg()
            .transformed(Affine3A::from_rotation_translation(Quat::from_rotation_z(0.3), Vec3::new(3.0, -3.0, -3.0))),
    ]
}

/// A closed mesh as a solid.
fn mesh_solid(m: TriangleMesh) -> Solid {
    Solid::new(Primitive::Mesh(Arc::new(MeshSolid::new(m).unwrap())))
}

/// A mesh cube with its triangles wound the other way (normals inwards).
fn inside_out_cube(lo: Vec3, hi: Vec3) -> TriangleMesh {
    let c = strahl::procedural::cuboid(lo, hi);
    let flipped = c.indices().iter().map(|&[a, b, c]| [a, c, b]).collect();
    TriangleMesh::new("inside-out cube", c.positions().to_vec(), flipped).unwrap()
}

fn mesh_csg() -> Solid {
    Solid::intersection(vec![
        Solid::difference(vec![
            mesh_solid(strahl::procedural::uv_sphere(Vec3::ZERO, 1.0, 16, 24)),
            mesh_solid(inside_out_cube(Vec3::splat(-0.45), Vec3::splat(1.2))),
        ]),
        Solid::new(Primitive::Cylinder).transformed(Affine3A::from_scale_rotation_translation(
            Vec3::new(0.8, 0.8, 2.0),
            Quat::IDENTITY,
            Vec3::new(0.0, 0.0, -1.0),
        )),
    ])
}

/// User implicit surfaces (sphere tracing): a gyroid shell cut to a ball (not a distance: its
/// Lipschitz bound is 5·2√3 < 18), and a box minus a rounded box given by its signed distance
/// (bound 1) with its analytic gradient.
fn implicit_gallery() -> Vec<Solid> {
    let gyroid = Implicit::new(
        |p: DVec3| {
            let q = p * 5.0;
            let g = q.x.sin() * q.y.cos() + q.y.sin() * q.z.cos() + q.z.sin() * q.x.cos();
            (g.abs() - 0.4).max((p.length() - 1.0) * 18.0)
        },
        18.0,
        Vec3::splat(-1.05),
        Vec3::splat(1.05),
    );
    let rounded = |p: DVec3| (p.abs() - DVec3::splat(0.5)).max(DVec3::ZERO).length() - 0.35;
    let rounded = Implicit::new(rounded, 1.0, Vec3::splat(-0.9), Vec3::splat(0.9)).with_gradient(move |p| {
        let q = (p.abs() - DVec3::splat(0.5)).max(DVec3::ZERO);
        q * p.signum()
    });
    let hollow = Solid::difference(vec![
        Solid::new(Primitive::Box).transformed(Affine3A::from_scale(Vec3::new(1.0, 0.6, 1.0))),
        Solid::new(Primitive::Implicit(Arc::new(rounded))),
    ]);
    vec![
        placed(Primitive::Implicit(Arc::new(gyroid)), Vec3::ONE, 0.4, Vec3::new(0.0, 0.0, -3.0)),
        hollow
            .transformed(Affine3A::from_rotation_translation(Quat::from_rotation_x(0.7), Vec3::new(-3.0, -3.0, -3.0))),
    ]
}

/// The gallery and the user implicit surfaces.
fn gallery_all() -> Vec<Solid> {
    let mut all = gallery();
    all.extend(implicit_gallery());
    all
}

/// Three balls in a row and one carving ball.
fn blob(potential: Potential) -> Primitive {
    let c =
        |x: f32, y: f32, radius: f32, strength: f32| BlobComponent { center: Vec3::new(x, y, 0.0), radius, strength };
    let threshold = if potential == Potential::InverseSquare { 4.0 } else { 0.3 };
    let components =
        vec![c(-0.6, 0.0, 0.8, 1.0), c(0.0, 0.1, 0.7, 1.0), c(0.6, 0.0, 0.8, 1.0), c(0.0, -0.3, 0.4, -1.5)];
    Primitive::Blob(Arc::new(Blob::new(threshold, potential, components)))
}

fn scene_of(solids: Vec<Solid>, solver: QuarticSolver) -> Scene {
    let cfg = BuildConfig { quartic_solver: solver, ..BuildConfig::default() };
    Scene::build_with_solids(Vec::new(), Vec::new(), solids, &cfg).unwrap()
}

/// Random rays from outside the gallery towards points inside it.
fn rays(n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng(seed);
    (0..n)
        .map(|_| {
            let o = rng.vec(1.0).normalize() * 12.0;
            let target = rng.vec(4.2);
            Ray::new(o, (target - o) * rng.range(0.5, 2.0))
        })
        .collect()
}

#[test]
fn every_hit_is_a_change_of_membership() {
    let solids = gallery_all();
    let scene = scene_of(solids.clone(), QuarticSolver::Bracketed);
    let mut checked = 0;
    let mut per_solid = vec![0usize; solids.len()];
    for ray in rays(20_000, 7) {
        let mut hits = Vec::new();
        scene.for_each_hit(&ray, |h| hits.push(*h));
        for h in &hits {
            let solid = &solids[h.geom_id as usize];
            let len = ray.dir.length();
            // Membership a little before and after the crossing, 2e-4 in world length: the
            // points straddle the surface unless another surface of the solid lies that near.
            let eps = 2e-4 / len;
            let (before, after) = (solid.contains(ray.at(h.t - eps)), solid.contains(ray.at(h.t + eps)));
            let facing_in = h.ng.dot(ray.dir) < 0.0;
            if before != after {
                // Entering where the outward normal faces the ray.
                assert_eq!(after, facing_in, "ray {ray:?} hit {h:?}: normal against membership");
                checked += 1;
                per_solid[h.geom_id as usize] += 1;
            } else {
                // Only near another crossing of the same solid (a thin wall, an edge).
                let near = hits.iter().any(|o| o.geom_id == h.geom_id && o != h && (o.t - h.t).abs() * len < 1e-3);
                assert!(near, "ray {ray:?}: hit {h:?} changes no membership ({before})");
            }
        }
    }
    assert!(checked > 10_000, "{checked}");
    assert!(per_solid.iter().all(|&n| n > 100), "crossings checked per solid: {per_solid:?}");
}

#[test]
fn membership_by_crossing_parity_matches_point_membership() {
    let solids = gallery_all();
    let scene = scene_of(solids.clone(), QuarticSolver::Bracketed);
    let mut rng = Rng(99);
    let (mut inside, mut mismatches) = (0, 0);
    for _ in 0..20_000 {
        let p = rng.vec(4.2);
        let dir = rng.vec(1.0);
        let ray = Ray::new(p, dir);
        let mut counts = vec![0usize; solids.len()];
        scene.for_each_hit(&ray, |h| counts[h.geom_id as usize] += 1);
        for (s, &c) in solids.iter().zip(&counts) {
            let member = s.contains(p);
            inside += member as usize;
            if member != (c % 2 == 1) {
                mismatches += 1;
            }
        }
    }
    // A ray through an edge or a tangent may miscount; the rate must stay tiny.
    assert!(inside > 500, "{inside}");
    assert!(mismatches <= 2, "{mismatches} of 20000×{} points misclassified", solids.len());
}

#[test]
fn queries_agree_across_forms() {
    let scene = scene_of(gallery_all(), QuarticSolver::Bracketed);
    let rays = rays(4096, 3);
    let single: Vec<_> = rays.iter().map(|r| scene.intersect(r)).collect();
    let hits = single.iter().filter(|h| h.is_some()).count();
    assert!(hits > 1000 && hits < 4000, "{hits}");
    for (r, h) in rays.iter().zip(&single) {
        assert_eq!(scene.intersect_brute_force(r), *h);
        assert_eq!(scene.occluded(r), h.is_some());
    }
    for (k, chunk) in rays.chunks(16).enumerate() {
        let p = RayPacket::from_rays(chunk);
        let mut lanes = vec![None; 16];
        scene.intersect_packet_each(&p, |l, h| lanes[l] = Some(*h));
        assert_eq!(&lanes[..chunk.len()], &single[16 * k..16 * k + chunk.len()]);
        let occ = scene.occluded_packet(&p);
        for (l, h) in single[16 * k..16 * k + chunk.len()].iter().enumerate() {
            assert_eq!(occ >> l & 1 == 1, h.is_some());
        }
    }
    let mut stream = RayStream::with_capacity(rays.len());
    rays.iter().for_each(|r| stream.push(r));
    for coherence in [strahl::Coherence::Coherent, strahl::Coherence::Incoherent] {
        let mut out = HitStream::misses(rays.len());
        scene.intersect_stream_par(&stream, &mut out, coherence);
        for (i, h) in single.iter().enumerate() {
            assert_eq!(out.get(i), *h, "ray {i}");
        }
    }
}

/// Camera packets (one origin, 4×4 tiles: the walk's frustum path) and packets with inactive,
/// NaN, zero-direction and `tnear > tfar` lanes answer as single rays do, for closest and any
/// hit, in both box tests.
#[test]
fn camera_packets_and_bad_lanes_agree_with_single_rays() {
    for box_test in [strahl::BoxTest::Conservative, strahl::BoxTest::Fast] {
        let cfg = BuildConfig { box_test, ..BuildConfig::default() };
        let scene = Scene::build_with_solids(Vec::new(), Vec::new(), gallery_all(), &cfg).unwrap();
        let camera = strahl::Camera::look_at(Vec3::new(3.0, 5.0, 11.0), Vec3::ZERO, Vec3::Y, 50.0);
        let (stream, _) = strahl::raygen::primary(&camera, 64, 64);
        let mut hits = 0;
        for k in (0..stream.len()).step_by(16) {
            let mut p = stream.packet(k, 16);
            let singles: Vec<Ray> = (0..16).map(|l| p.get(l)).collect();
            // Every fifth packet loses lanes: one inactive, one NaN, one zero direction, one
            // with tnear > tfar.
            let spoiled = k / 16 % 5 == 0;
            if spoiled {
                p.active &= !(1 << 3);
                p.dx[5] = f32::NAN;
                (p.dx[7], p.dy[7], p.dz[7]) = (0.0, 0.0, 0.0);
                (p.tnear[9], p.tfar[9]) = (2.0, 1.0);
            }
            let mut lanes = [None; 16];
            scene.intersect_packet_each(&p, |l, h| lanes[l] = Some(*h));
            let occ = scene.occluded_packet(&p);
            for l in 0..16 {
                let want = if spoiled && [3, 5, 7, 9].contains(&l) { None } else { scene.intersect(&singles[l]) };
                hits += want.is_some() as usize;
                assert_eq!(lanes[l], want, "{box_test:?}, packet {k}, lane {l}");
                assert_eq!(occ >> l & 1 == 1, want.is_some(), "{box_test:?}, packet {k}, lane {l}");
            }
        }
        assert!(hits > 500 && hits < 3500, "{hits}");
    }
}

#[test]
fn torus_solvers_agree_away_from_tangents() {
    let torus = || vec![placed(Primitive::Torus { major: 1.0, minor: 0.25 }, Vec3::ONE, 0.7, Vec3::ZERO)];
    let reference = scene_of(torus(), QuarticSolver::Bracketed);
    for solver in [QuarticSolver::Ferrari, QuarticSolver::Laguerre] {
        let other = scene_of(torus(), solver);
        let mut rng = Rng(5);
        let (mut hits, mut differ) = (0, 0);
        for _ in 0..20_000 {
            let o = rng.vec(1.0).normalize() * 5.0;
            let ray = Ray::new(o, rng.vec(1.3) - o);
            match (other.intersect(&ray), reference.intersect(&ray)) {
                (Some(x), Some(y)) => {
                    hits += 1;
                    assert!((x.t - y.t).abs() <= 1e-5 * x.t, "{solver:?}: {x:?} {y:?}");
                }
                (None, None) => {}
                _ => differ += 1,
            }
        }
        assert!(hits > 5000, "{hits}");
        assert!(differ <= 4, "{solver:?}: {differ} rays hit with one solver only");
    }
}

#[test]
fn ellipsoid_normals_are_the_gradient() {
    // The seeds' ellipsoid: a unit sphere scaled by (2, 1, 0.5); its outward normal at p is
    // (x/4, y, 4z) normalized.
    let e = Solid::new(Primitive::Sphere).transformed(Affine3A::from_scale(Vec3::new(2.0, 1.0, 0.5)));
    let scene = scene_of(vec![e], QuarticSolver::Bracketed);
    let mut rng = Rng(11);
    for _ in 0..1000 {
        let o = rng.vec(1.0).normalize() * 6.0;
        let ray = Ray::new(o, rng.vec(0.4) - o);
        if let Some(h) = scene.intersect(&ray) {
            let p = ray.at(h.t);
            let want = Vec3::new(p.x / 4.0, p.y, 4.0 * p.z).normalize();
            assert!(h.ng.normalize().dot(want) > 0.99999, "{:?} {want}", h.ng);
            let on = (p / Vec3::new(2.0, 1.0, 0.5)).length();
            assert!((on - 1.0).abs() < 1e-5, "{on}");
        }
    }
}

#[test]
fn rays_starting_inside_hit_the_way_out() {
    let scene = scene_of(vec![die()], QuarticSolver::Bracketed);
    let h = scene.intersect(&Ray::new(Vec3::ZERO, Vec3::Z)).unwrap();
    // The pip at z = 1 carves the face: its surface is 0.18 in.
    assert!((h.t - 0.82).abs() < 1e-5, "{h:?}");
    // The die's outward normal there points out of its material, into the pip's hollow.
    assert!(h.ng.dot(Vec3::Z) > 0.99, "{h:?}");
    let h = scene.intersect(&Ray::new(Vec3::ZERO, -Vec3::Y)).unwrap();
    assert!((h.t - 1.0).abs() < 1e-6 && h.ng.dot(-Vec3::Y) > 0.99, "{h:?}");
}

#[test]
fn bad_solids_are_typed_errors() {
    let bad = |s: Solid| match Scene::build_with_solids(
        Vec::new(),
        Vec::new(),
        vec![Solid::new(Primitive::Box), s],
        &BuildConfig::default(),
    ) {
        Err(Error::BadSolid { index: 1, message }) => message,
        other => panic!("{other:?}"),
    };
    bad(Solid::new(Primitive::Cone { r0: -1.0, r1: 1.0 }));
    bad(Solid::new(Primitive::Cone { r0: 0.0, r1: 0.0 }));
    bad(Solid::new(Primitive::Torus { major: 1.0, minor: 1.5 }));
    bad(Solid::new(Primitive::Torus { major: f32::NAN, minor: 0.5 }));
    bad(Solid::new(Primitive::Quadric { coeffs: [f32::NAN; 10] }));
    bad(Solid::new(Primitive::Quadric { coeffs: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0] }));
    bad(Solid::new(Primitive::Superellipsoid { e: 0.0, n: 1.0 }));
    bad(Solid::new(Primitive::Superellipsoid { e: 1.0, n: f32::NAN }));
    bad(Solid::new(Primitive::Supertoroid { major: 1.0, minor: 1.0, e: 1.0, n: 1.0 }));
    bad(Solid::new(Primitive::Supertoroid { major: 1.0, minor: 0.5, e: 0.001, n: 1.0 }));
    // Within the exponents' range, but (major + minor)^(2/e) overflows float64's bounds.
    bad(Solid::new(Primitive::Supertoroid { major: 1e6, minor: 0.5, e: 0.01, n: 1.0 }));
    bad(Solid::new(Primitive::Superhyperboloid { e: 1.0, n: 1.0, sheets: 3, height: 1.0 }));
    bad(Solid::new(Primitive::Superhyperboloid { e: 1.0, n: 1.0, sheets: 2, height: 1.0 }));
    bad(Solid::new(Primitive::Superhyperboloid { e: 1.0, n: 1.0, sheets: 1, height: f32::INFINITY }));
    bad(Solid::new(Primitive::Superhyperboloid { e: f32::NAN, n: 1.0, sheets: 1, height: 1.0 }));
    bad(Solid::new(Primitive::Ratioquadric { p: 0.0, q: 1.0, r: 1.0 }));
    bad(Solid::new(Primitive::Ratioquadric { p: 1.0, q: 1e4, r: 1.0 }));
    let user = |l: f64, lo: Vec3, hi: Vec3| {
        Solid::new(Primitive::Implicit(Arc::new(Implicit::new(|p: DVec3| p.length() - 1.0, l, lo, hi))))
    };
    assert!(bad(user(f64::NAN, -Vec3::ONE, Vec3::ONE)).contains("Lipschitz"));
    bad(user(-1.0, -Vec3::ONE, Vec3::ONE));
    bad(user(1.0, Vec3::ONE, -Vec3::ONE));
    bad(user(1.0, -Vec3::ONE, Vec3::new(1.0, f32::INFINITY, 1.0)));
    let ball = |radius: f32, strength: f32| BlobComponent { center: Vec3::ZERO, radius, strength };
    let blob = |t: f32, p: Potential, c: Vec<BlobComponent>| Solid::new(Primitive::Blob(Arc::new(Blob::new(t, p, c))));
    bad(blob(0.5, Potential::Pov, vec![]));
    bad(blob(0.5, Potential::Pov, vec![ball(1.0, -1.0)]));
    bad(blob(0.0, Potential::Pov, vec![ball(1.0, 1.0)]));
    bad(blob(0.5, Potential::Pov, vec![ball(0.0, 1.0)]));
    bad(blob(0.5, Potential::Pov, vec![ball(1.0, f32::INFINITY)]));
    bad(blob(0.5, Potential::Rational { d: -1.0 }, vec![ball(1.0, 1.0)]));
    bad(blob(0.5, Potential::Pov, vec![BlobComponent { center: Vec3::NAN, radius: 1.0, strength: 1.0 }]));
    assert!(bad(Solid::new(Primitive::Plane)).contains("unbounded"));
    assert!(bad(Solid::union(vec![Solid::new(Primitive::Box), Solid::new(Primitive::Plane)])).contains("unbounded"));
    bad(Solid::union(Vec::new()));
    bad(Solid::intersection(vec![Solid::new(Primitive::Box), Solid::new(Primitive::Disc)]));
    bad(Solid::new(Primitive::Box).transformed(Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0))));
    bad(Solid::new(Primitive::Box).transformed(Affine3A::from_translation(Vec3::splat(f32::NAN))));
    bad(Solid::new(Primitive::Sphere).transformed(Affine3A::from_scale(Vec3::splat(1e30))));
    // A disc alone is a surface; an unbounded quadric clipped by a box is bounded.
    let ok = Scene::build_with_solids(
        Vec::new(),
        Vec::new(),
        vec![
            Solid::new(Primitive::Disc).transformed(Affine3A::from_translation(Vec3::new(0.0, 0.0, 2.0))),
            Solid::Csg(CsgOp::Intersection, vec![Solid::new(Primitive::Plane), Solid::new(Primitive::Box)]),
        ],
        &BuildConfig::default(),
    )
    .unwrap();
    let h = ok.intersect(&Ray::new(Vec3::new(0.3, 0.2, 5.0), -Vec3::Z)).unwrap();
    assert_eq!((h.t, h.geom_id), (3.0, 0));
    // Invalid rays miss.
    for r in [Ray::new(Vec3::splat(f32::NAN), Vec3::X), Ray::new(Vec3::ZERO, Vec3::ZERO)] {
        assert!(ok.intersect(&r).is_none() && !ok.occluded(&r));
    }
}

#[test]
fn instanced_solids_match_their_flattened_twin() {
    use strahl::{Instance, InstancedScene};
    let object = Scene::build_with_solids(Vec::new(), Vec::new(), gallery_all(), &BuildConfig::default()).unwrap();
    let instances = vec![
        Instance::new(0, Affine3A::IDENTITY),
        // Non-uniform scale, turn and a mirror: solids take any invertible affine map.
        Instance::new(
            0,
            Affine3A::from_scale_rotation_translation(
                Vec3::new(-0.7, 1.3, 0.9),
                Quat::from_rotation_y(0.8),
                Vec3::new(15.0, 1.0, -2.0),
            ),
        ),
    ];
    let inst = InstancedScene::from_scenes(vec![object], instances).unwrap();
    let flat = inst.flatten(&BuildConfig::default()).unwrap();
    let mut rng = Rng(21);
    let mut hits = 0;
    let rays: Vec<Ray> = (0..4000)
        .map(|_| {
            let o = Vec3::new(7.0, 0.0, 0.0) + rng.vec(1.0).normalize() * 25.0;
            let target = Vec3::new(rng.range(-5.0, 20.0), rng.range(-5.0, 5.0), rng.range(-7.0, 5.0));
            Ray::new(o, target - o)
        })
        .collect();
    for r in &rays {
        let (a, b) = (inst.intersect(r), flat.intersect(r));
        assert_eq!(a.is_some(), b.is_some(), "{r:?} {a:?} {b:?}");
        if let (Some(a), Some(b)) = (a, b) {
            hits += 1;
            assert!((a.t - b.t).abs() <= 1e-5 * a.t, "{a:?} {b:?}");
            assert!(a.ng.normalize().dot(b.ng.normalize()) > 0.9999, "{a:?} {b:?}");
        }
        assert_eq!(inst.occluded(r), flat.occluded(r));
    }
    assert!(hits > 500, "{hits}");
    for chunk in rays.chunks(16) {
        let p = RayPacket::from_rays(chunk);
        inst.intersect_packet_each(&p, |l, h| {
            let want = flat.intersect(&chunk[l]).unwrap();
            assert!((h.t - want.t).abs() <= 1e-5 * h.t);
        });
        let want = chunk.iter().enumerate().fold(0u32, |m, (l, r)| m | (flat.occluded(r) as u32) << l);
        assert_eq!(inst.occluded_packet(&p), want);
    }
}

#[test]
fn solids_survive_serialization() {
    let cfg = BuildConfig { quartic_solver: QuarticSolver::Ferrari, ..BuildConfig::default() };
    let scene = Scene::build_with_solids(Vec::new(), Vec::new(), gallery(), &cfg).unwrap();
    let bytes = scene.to_bytes();
    let back = Scene::from_bytes(&bytes).unwrap();
    assert_eq!(back.solids(), scene.solids());
    assert_eq!(back.quartic_solver(), QuarticSolver::Ferrari);
    assert_eq!(back.to_bytes(), bytes);
    for r in rays(2000, 17) {
        assert_eq!(back.intersect(&r), scene.intersect(&r));
    }
    // Truncated or damaged bytes are errors, never panics.
    for cut in (bytes.len() - 400..bytes.len()).step_by(7) {
        assert!(Scene::from_bytes(&bytes[..cut]).is_err());
    }
    // A user's implicit surface (a closure) has no bytes: reading its marker is an error.
    let user = Scene::build_with_solids(Vec::new(), Vec::new(), implicit_gallery(), &cfg).unwrap();
    let err = Scene::from_bytes(&user.to_bytes()).unwrap_err();
    assert!(matches!(&err, Error::Serialized(m) if m.contains("closure")), "{err}");
    // A solid nested too deep is refused when built, and when read back.
    let mut deep = Solid::new(Primitive::Box);
    for _ in 0..300 {
        deep = Solid::union(vec![deep]);
    }
    assert!(matches!(
        Scene::build_with_solids(Vec::new(), Vec::new(), vec![deep.clone()], &BuildConfig::default()),
        Err(Error::BadSolid { index: 0, .. })
    ));
    assert!(!deep.contains(Vec3::ZERO));
}

#[test]
fn rays_from_inside_always_find_the_way_out() {
    let wedge = Solid::intersection(vec![
        Solid::new(Primitive::Box).transformed(Affine3A::from_scale_rotation_translation(
            Vec3::splat(0.6),
            Quat::IDENTITY,
            Vec3::new(1.9, 0.6, -1.6),
        )),
        Solid::new(Primitive::Plane).transformed(Affine3A::from_rotation_translation(
            Quat::from_rotation_arc(Vec3::Z, Vec3::new(1.0, 1.0, 0.0).normalize()),
            Vec3::new(1.9, 0.0, -1.6) + Vec3::new(1.0, 1.0, 0.0).normalize() * (0.9 / 2f32.sqrt()),
        )),
    ]);
    let scene = scene_of(vec![wedge.clone()], QuarticSolver::Bracketed);
    let mut rng = Rng(8);
    let mut lost = 0;
    let mut tried = 0;
    for _ in 0..100_000 {
        let p = Vec3::new(1.9, 0.6, -1.6) + rng.vec(0.6);
        if !wedge.contains(p) {
            continue;
        }
        tried += 1;
        if scene.intersect(&Ray::new(p, rng.vec(1.0))).is_none() {
            lost += 1;
        }
    }
    assert!(tried > 10_000);
    assert_eq!(lost, 0, "{lost} of {tried} rays from inside hit nothing");
}

#[test]
fn a_mesh_cube_crosses_where_the_box_does() {
    // The watertight test's crossings of a closed mesh cube (either winding) against the slab
    // test, to float32 precision; rays through its edges and corners included.
    for mesh in [strahl::procedural::cuboid(-Vec3::ONE, Vec3::ONE), inside_out_cube(-Vec3::ONE, Vec3::ONE)] {
        let cube = scene_of(vec![mesh_solid(mesh)], QuarticSolver::default());
        let exact = scene_of(vec![Solid::new(Primitive::Box)], QuarticSolver::default());
        let mut rng = Rng(5);
        let mut rays: Vec<Ray> = (0..5000)
            .map(|_| {
                let o = rng.vec(1.0).normalize() * 4.0;
                Ray::new(o, rng.vec(1.1) - o)
            })
            .collect();
        // Through edges and corners exactly.
        rays.extend([Vec3::new(1.0, 1.0, 0.3), Vec3::ONE, Vec3::new(-1.0, 0.2, 1.0)].map(|p| Ray::new(p * 3.0, -p)));
        for r in &rays {
            let (mut a, mut b) = (Vec::new(), Vec::new());
            cube.for_each_hit(r, |h| a.push(*h));
            exact.for_each_hit(r, |h| b.push(*h));
            a.sort_by(|x, y| x.t.total_cmp(&y.t));
            b.sort_by(|x, y| x.t.total_cmp(&y.t));
            assert_eq!(a.len(), b.len(), "{r:?} {a:?} {b:?}");
            for (x, y) in a.iter().zip(&b) {
                assert!((x.t - y.t).abs() <= 1e-5 * y.t.abs().max(1.0), "{r:?} {x:?} {y:?}");
                // Outward normals, whichever way the mesh winds.
                assert!(x.ng.normalize().dot(y.ng.normalize()) > 0.999, "{r:?} {x:?} {y:?}");
            }
        }
    }
}

#[test]
fn meshes_that_bound_no_solid_are_refused() {
    let quad = strahl::procedural::quad(1.0, 1.0);
    let err = MeshSolid::new(quad).unwrap_err();
    assert!(matches!(&err, Error::BadSolid { message, .. } if message.contains("not closed")), "{err}");
    // One triangle of a cube turned the other way: its edges run twice one way.
    let c = strahl::procedural::cuboid(-Vec3::ONE, Vec3::ONE);
    let mut idx = c.indices().to_vec();
    idx[0] = [idx[0][0], idx[0][2], idx[0][1]];
    assert!(MeshSolid::new(TriangleMesh::new("twisted", c.positions().to_vec(), idx).unwrap()).is_err());
    assert!(MeshSolid::new(TriangleMesh::new("empty", Vec::new(), Vec::new()).unwrap()).is_err());
    let nan = TriangleMesh::new("nan", vec![Vec3::NAN; 3], vec![[0, 1, 2]]).unwrap();
    assert!(MeshSolid::new(nan).is_err());
}

#[test]
fn scene_files_cut_closed_obj_meshes() {
    // A closed OBJ cube (8 vertices, 12 triangles) minus an analytic sphere, from a scene file;
    // an open OBJ (one quad) is refused naming the node.
    let dir = std::env::temp_dir().join(format!("strahl-mesh-csg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cube = strahl::procedural::cuboid(-Vec3::ONE, Vec3::ONE);
    let mut obj = String::new();
    for p in cube.positions() {
        obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    for t in cube.indices() {
        obj += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    std::fs::write(dir.join("cube.obj"), obj).unwrap();
    std::fs::write(dir.join("quad.obj"), "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n").unwrap();
    let text = "[mesh.m]\nsolid = { difference = [ { obj = \"cube.obj\" }, { sphere = { center = [1.0, 1.0, 1.0], radius = 1.0 } } ] }\n\
                [[instance]]\nmesh = \"m\"\n";
    let file = strahl::SceneFile::parse(text, &dir.join("x.toml")).unwrap();
    let scene = file.build(&BuildConfig::default()).unwrap();
    // Straight down the cube's corner (1, 1, ·) the sphere's hollow comes first.
    let down = Ray::new(Vec3::new(0.9, 0.9, 5.0), -Vec3::Z);
    let h = scene.intersect(&down).unwrap();
    let sphere_z = 1.0 - (1.0f32 - 0.02).sqrt();
    assert!((h.t - (5.0 - sphere_z)).abs() < 1e-4, "{h:?}");
    let straight = scene.intersect(&Ray::new(Vec3::new(-0.5, -0.5, 5.0), -Vec3::Z)).unwrap();
    assert!((straight.t - 4.0).abs() < 1e-5 && straight.ng.z > 0.0, "{straight:?}");
    let open = text.replace("cube.obj", "quad.obj");
    let err = strahl::SceneFile::parse(&open, &dir.join("x.toml")).unwrap_err().to_string();
    assert!(err.contains("solid.difference[0]") && err.contains("not closed"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
