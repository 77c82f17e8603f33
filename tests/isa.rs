//! Every instruction-set level this machine runs answers every query like the others: the same
//! hits, with distances that differ by float rounding only (fused against separate multiply-adds where the crate is compiled without FMA),
//! for every triangle test and box test, flat and instanced, single rays, packets and streams;
//! and the same for analytic spheres with every sphere test and for solids with every quartic
//! solver.
//!
//! This file is its own test binary (its own process), so switching the level with
//! `strahl::simd::set_isa` cannot disturb other tests. The whole suite also runs once per level
//! through `STRAHL_ISA` (`.ci/run`).

mod common;

use common::{assert_same_hit, random_rays, random_soup};
use glam::{Affine3A, Quat, Vec3};
use strahl::procedural::{self, uv_sphere};
use strahl::simd::{Isa, isa, set_isa};
use strahl::{
    BoxTest, BuildConfig, Coherence, Hit, HitStream, Instance, InstancedScene, QuarticSolver, Query, Ray, RayPacket,
    RayStream, Scene, SphereSet, SphereTest, TriangleTest,
};

/// The level is one setting for the whole process: the tests here take turns.
static LEVEL: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Every answer a scene gives for `rays`, through each query shape.
struct Answers {
    single: Vec<Option<Hit>>,
    occluded: Vec<bool>,
    packets: Vec<Option<Hit>>,
    packet_occluded: Vec<bool>,
    streams: [Vec<Option<Hit>>; 2],
    stream_occluded: [Vec<bool>; 2],
}

fn answers<Q: Query>(q: &Q, rays: &[Ray]) -> Answers {
    let single = rays.iter().map(|r| q.intersect(r)).collect();
    let occluded = rays.iter().map(|r| q.occluded(r)).collect();
    let mut packets = vec![None; rays.len()];
    let mut packet_occluded = vec![false; rays.len()];
    for (k, chunk) in rays.chunks(16).enumerate() {
        let p = RayPacket::from_rays(chunk);
        q.intersect_packet_each(&p, |lane, h| packets[16 * k + lane] = Some(*h));
        let m = q.occluded_packet(&p);
        for lane in 0..chunk.len() {
            packet_occluded[16 * k + lane] = m & (1 << lane) != 0;
        }
    }
    let mut stream = RayStream::with_capacity(rays.len());
    for r in rays {
        stream.push(r);
    }
    let mut streams: [Vec<Option<Hit>>; 2] = Default::default();
    let mut stream_occluded: [Vec<bool>; 2] = Default::default();
    for (i, c) in [Coherence::Coherent, Coherence::Incoherent].into_iter().enumerate() {
        let mut hits = HitStream::misses(0);
        q.intersect_stream(&stream, &mut hits, c);
        streams[i] = (0..rays.len()).map(|k| hits.get(k)).collect();
        q.occluded_stream(&stream, &mut stream_occluded[i], c);
    }
    Answers { single, occluded, packets, packet_occluded, streams, stream_occluded }
}

fn same(a: &Answers, b: &Answers, what: &str) {
    // Rounding may move a hit by a few ulps; a ray grazing an edge may then find the neighbour
    // (assert_same_hit accepts a different triangle at the same distance).
    let rel = 2e-5;
    for i in 0..a.single.len() {
        assert_same_hit(a.single[i], b.single[i], rel, &format!("{what}: single ray {i}"));
        assert_same_hit(a.packets[i], b.packets[i], rel, &format!("{what}: packet ray {i}"));
        for s in 0..2 {
            assert_same_hit(a.streams[s][i], b.streams[s][i], rel, &format!("{what}: stream {s} ray {i}"));
        }
    }
    let flips = |x: &[bool], y: &[bool]| x.iter().zip(y).filter(|(p, q)| p != q).count();
    // Occlusion of rays from outside towards a closed soup: a flip needs a ray through a shared
    // edge within rounding, rarer than 1 in 1000 here.
    let limit = a.occluded.len() / 1000 + 1;
    assert!(flips(&a.occluded, &b.occluded) <= limit, "{what}: single occlusion");
    assert!(flips(&a.packet_occluded, &b.packet_occluded) <= limit, "{what}: packet occlusion");
    for s in 0..2 {
        assert!(flips(&a.stream_occluded[s], &b.stream_occluded[s]) <= limit, "{what}: stream occlusion {s}");
    }
}

/// The answers of `flat` and `world` at every level in `levels`, each checked against the
/// first level's ([`same`]); returns the first level's.
fn at_every_level<F: Query, W: Query>(
    levels: &[Isa],
    flat: &F,
    world: &W,
    rays: &[Ray],
    what: &str,
) -> (Answers, Answers) {
    let mut per_level: Vec<(Isa, Answers, Answers)> = levels
        .iter()
        .map(|&l| {
            set_isa(l).unwrap();
            assert_eq!(isa(), l);
            (l, answers(flat, rays), answers(world, rays))
        })
        .collect();
    let (l0, flat0, world0) = per_level.remove(0);
    for (l, f, w) in &per_level {
        same(&flat0, f, &format!("{what} flat, {l0} vs {l}"));
        same(&world0, w, &format!("{what} instanced, {l0} vs {l}"));
    }
    (flat0, world0)
}

#[test]
fn every_level_answers_like_the_compiled_one() {
    let _turn = LEVEL.lock().unwrap_or_else(|e| e.into_inner());
    let levels: Vec<Isa> = Isa::ALL.into_iter().filter(|i| i.supported()).collect();
    for i in Isa::ALL {
        assert_eq!(set_isa(i).is_ok(), i.supported(), "{i}");
    }
    let mut rays = random_rays(71, 3000);
    // Camera-like rays from one origin, so that packets share an origin (frusta, groups).
    for k in 0..1024 {
        let (x, y) = ((k % 32) as f32 / 16.0 - 1.0, (k / 32) as f32 / 16.0 - 1.0);
        rays.push(Ray::new(Vec3::new(0.0, 0.0, 3.0), Vec3::new(x, y, -3.0)));
    }
    for test in [TriangleTest::MollerTrumbore, TriangleTest::Badouel, TriangleTest::Watertight] {
        for box_test in [BoxTest::Conservative, BoxTest::Fast] {
            let cfg = BuildConfig { triangle_test: test, box_test, ..BuildConfig::default() };
            let meshes = vec![random_soup(5, 2000, 0.1), uv_sphere(Vec3::new(0.2, -0.1, 0.0), 0.6, 24, 48)];
            let scene = Scene::build(meshes.clone(), &cfg).unwrap();
            let world = InstancedScene::build(
                vec![meshes],
                vec![
                    Instance::new(0, Affine3A::IDENTITY),
                    Instance::new(
                        0,
                        Affine3A::from_rotation_translation(Quat::from_rotation_y(0.7), Vec3::new(0.5, 0.3, -0.4)),
                    ),
                ],
                &cfg,
            )
            .unwrap();
            let (flat0, _) = at_every_level(&levels, &scene, &world, &rays, &format!("{test:?}/{box_test:?}"));
            // And the compiled level agrees with brute force (the levels' own checks are the suite's).
            for (r, h) in rays.iter().zip(&flat0.single).step_by(7) {
                assert_same_hit(
                    scene.intersect_brute_force(r),
                    *h,
                    2e-5,
                    &format!("{test:?}/{box_test:?} brute force"),
                );
            }
        }
    }
}

/// Analytic spheres (a sphereflake and two overlapping spheres beside a mesh), flat and
/// instanced, with every sphere test and box test: every level answers like the first.
#[test]
fn every_level_answers_like_the_compiled_one_on_spheres() {
    let _turn = LEVEL.lock().unwrap_or_else(|e| e.into_inner());
    let levels: Vec<Isa> = Isa::ALL.into_iter().filter(|i| i.supported()).collect();
    let mut rays = random_rays(72, 2000);
    for k in 0..1024 {
        let (x, y) = ((k % 32) as f32 / 16.0 - 1.0, (k / 32) as f32 / 16.0 - 1.0);
        rays.push(Ray::new(Vec3::new(0.0, 0.3, 4.0), Vec3::new(x, y, -3.0)));
    }
    for test in SphereTest::ALL {
        for box_test in [BoxTest::Conservative, BoxTest::Fast] {
            let cfg = BuildConfig { sphere_test: test, box_test, ..BuildConfig::default() };
            let sets = || {
                vec![
                    SphereSet::from_pairs("flake", &procedural::sphereflake_spheres(3)).unwrap(),
                    SphereSet::new("pair", vec![Vec3::new(-0.9, 0.0, 0.3), Vec3::new(-0.7, 0.3, 0.0)], vec![0.4, 0.2])
                        .unwrap(),
                ]
            };
            let mesh = || vec![uv_sphere(Vec3::new(1.2, 0.0, 0.0), 0.3, 12, 24)];
            let scene = Scene::build_with_spheres(mesh(), sets(), &cfg).unwrap();
            let world = InstancedScene::from_scenes(
                vec![Scene::build_with_spheres(mesh(), sets(), &cfg).unwrap()],
                vec![
                    Instance::new(0, Affine3A::IDENTITY),
                    Instance::new(
                        0,
                        Affine3A::from_scale_rotation_translation(
                            Vec3::splat(0.5),
                            Quat::from_rotation_y(0.7),
                            Vec3::new(0.5, 0.3, -0.4),
                        ),
                    ),
                ],
            )
            .unwrap();
            let what = format!("{test:?}/{box_test:?} spheres");
            let (flat0, _) = at_every_level(&levels, &scene, &world, &rays, &what);
            let sphere_hits = flat0.single.iter().flatten().filter(|h| h.geom_id >= 1).count();
            assert!(sphere_hits > rays.len() / 10, "{test:?}: only {sphere_hits} sphere hits");
            for (r, h) in rays.iter().zip(&flat0.single).step_by(5) {
                assert_same_hit(
                    scene.intersect_brute_force(r),
                    *h,
                    2e-5,
                    &format!("{test:?}/{box_test:?} brute force"),
                );
            }
        }
    }
}

/// The builder's binning (object and spatial splits) runs at the active level too: every level
/// builds the same tree, to the bit (the binning has no multiply-add to fuse). Serial builds: a
/// parallel build with spatial splits shares its split budget between threads, so its tree may
/// depend on which subtree spends it first.
#[test]
fn every_level_builds_the_same_tree() {
    let _turn = LEVEL.lock().unwrap_or_else(|e| e.into_inner());
    let levels: Vec<Isa> = Isa::ALL.into_iter().filter(|i| i.supported()).collect();
    // Large enough for parallel binning chunks and the run-length binning of coherent input.
    let meshes = vec![random_soup(9, 30_000, 0.05), uv_sphere(Vec3::new(0.2, -0.1, 0.0), 0.6, 96, 192)];
    for cfg in [BuildConfig::default(), BuildConfig::high()] {
        let cfg = BuildConfig { parallel_threshold: usize::MAX, ..cfg };
        let mut seen = Vec::new();
        for &l in levels.iter().chain(&levels) {
            set_isa(l).unwrap();
            let s = Scene::build(meshes.clone(), &cfg).unwrap();
            let st = s.stats();
            seen.push((l, (st.inner_nodes, st.leaves, st.blocks, st.references, st.sah.to_bits(), st.depth)));
        }
        assert!(seen[0].1.3 > 30_000, "spatial splits or not, every triangle is referenced");
        for (l, st) in &seen[1..] {
            assert_eq!(*st, seen[0].1, "{l} against {}", seen[0].0);
        }
    }
}

/// Solids (data/solids.toml: CSG, tori, quadrics, superquadrics, blobs, an implicit surface),
/// instanced as the file places them and flat, with every box test and quartic solver: every
/// level answers like the first. Their walks and root finders run at the level too.
#[test]
fn every_level_answers_like_the_compiled_one_on_solids() {
    let _turn = LEVEL.lock().unwrap_or_else(|e| e.into_inner());
    let levels: Vec<Isa> = Isa::ALL.into_iter().filter(|i| i.supported()).collect();
    let file =
        strahl::SceneFile::read(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/solids.toml")).unwrap();
    let mut rays = random_rays(73, 1500);
    for k in 0..1024 {
        let (x, y) = ((k % 32) as f32 / 16.0 - 1.0, (k / 32) as f32 / 16.0 - 1.0);
        rays.push(Ray::new(Vec3::new(0.0, 2.5, -7.0), Vec3::new(3.0 * x, 1.5 * y - 1.0, 7.0)));
    }
    for solver in QuarticSolver::ALL {
        for box_test in [BoxTest::Conservative, BoxTest::Fast] {
            let cfg = BuildConfig { quartic_solver: solver, box_test, ..BuildConfig::default() };
            let world = file.build(&cfg).unwrap();
            let flat = Scene::build_with_solids(vec![], vec![], file.load_solids().concat(), &cfg).unwrap();
            let what = format!("{solver:?}/{box_test:?} solids");
            let (flat0, world0) = at_every_level(&levels, &flat, &world, &rays, &what);
            let solid_hits = world0.single.iter().flatten().count();
            assert!(solid_hits > rays.len() / 5, "{solver:?}: only {solid_hits} hits");
            assert!(flat0.single.iter().flatten().count() > rays.len() / 10, "{solver:?}: flat solids hit");
        }
    }
}
