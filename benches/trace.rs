//! Criterion benchmarks of the kernels: BVH build, and primary, shadow and diffuse rays through the
//! single, packet and stream APIs on one thread; shadow rays also through the octant groups that
//! occlusion streams of trees out of the cache take (`groups`). `Throughput::Elements` makes criterion print rays/s.
//!
//! Scenes: a generated sphereflake (always), its analytic twin of 820 spheres (always), the
//! instanced forest of `data/forest.toml` (always),
//! and the shared bunny and Sponza when `../shared/scenes` is present. Ray sets are built once per
//! scene with fixed seeds.

use std::path::Path;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use strahl::Query;
use strahl::{
    BuildConfig, Camera, Coherence, HitPacket, HitStream, PACKET_WIDTH, RayStream, Scene, TriangleMesh, procedural,
    raygen,
};

struct Case {
    name: &'static str,
    meshes: Vec<TriangleMesh>,
    eye: Vec3,
    at: Vec3,
    light: Vec3,
}

fn cases() -> Vec<Case> {
    let mut v = vec![Case {
        name: "sphereflake",
        meshes: vec![procedural::sphereflake(2, 16, 32)],
        eye: Vec3::new(0.0, 1.3, 3.4),
        at: Vec3::new(0.0, 0.25, 0.0),
        light: Vec3::new(3.0, 6.0, 4.0),
    }];
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes");
    for (name, file, eye, at, light) in [
        ("bunny", "bunny/bunny.obj", [-0.017, 0.13, 0.17], [-0.017, 0.10, 0.0], [0.1, 0.3, 0.2]),
        ("sponza", "sponza_dabrovic/sponza.obj", [-10.0, 3.0, 0.0], [10.0, 4.0, 0.0], [0.0, 12.0, 0.0]),
    ] {
        if let Ok(meshes) = strahl::load_obj(shared.join(file)) {
            v.push(Case { name, meshes, eye: eye.into(), at: at.into(), light: light.into() });
        }
    }
    v
}

fn bench_build(c: &mut Criterion) {
    let mut g = c.benchmark_group("build");
    g.sample_size(10);
    for case in cases() {
        let tris: usize = case.meshes.iter().map(|m| m.triangle_count()).sum();
        g.throughput(Throughput::Elements(tris as u64));
        for (preset, cfg) in [("medium", BuildConfig::default()), ("high", BuildConfig::high())] {
            g.bench_function(BenchmarkId::new(case.name, preset), |b| {
                b.iter(|| Scene::build(case.meshes.clone(), &cfg).unwrap())
            });
        }
    }
    g.finish();
}

fn trace_all<Q: Query>(scene: &Q, rays: &RayStream, occlusion: bool, api: &str, coherence: Coherence) -> usize {
    match (api, occlusion) {
        ("single", false) => (0..rays.len()).filter(|&i| scene.intersect(&rays.get(i)).is_some()).count(),
        ("single", true) => (0..rays.len()).filter(|&i| scene.occluded(&rays.get(i))).count(),
        ("packet", false) => {
            let mut hp = HitPacket::default();
            let mut n = 0;
            for k in (0..rays.len()).step_by(PACKET_WIDTH) {
                scene.intersect_packet(&rays.packet(k, PACKET_WIDTH), &mut hp);
                n += hp.prim_id.iter().filter(|&&p| p != strahl::INVALID_ID).count();
            }
            n
        }
        ("packet", true) => (0..rays.len())
            .step_by(PACKET_WIDTH)
            .map(|k| scene.occluded_packet(&rays.packet(k, PACKET_WIDTH)).count_ones() as usize)
            .sum(),
        ("groups", true) => {
            // The occlusion kernel of trees out of the cache, on any tree: groups of up to 32
            // rays of one direction octant, in stream order within each octant.
            let oct = |i: usize| {
                let r = rays.get(i);
                [r.dir.x, r.dir.y, r.dir.z]
                    .iter()
                    .enumerate()
                    .fold(0, |o, (a, x)| o | (x.is_sign_negative() as u32) << a)
            };
            let mut n = 0;
            for o in 0..8 {
                let ids: Vec<u16> = (0..rays.len()).filter(|&i| oct(i) == o).map(|i| i as u16).collect();
                for g in ids.chunks(32) {
                    n += scene.occluded_octant_rays(rays, 0, g, o).count_ones() as usize;
                }
            }
            n
        }
        (_, false) => {
            let mut h = HitStream::default();
            scene.intersect_stream(rays, &mut h, coherence);
            h.prim_id.iter().filter(|&&p| p != strahl::INVALID_ID).count()
        }
        (_, true) => {
            let mut o = Vec::new();
            scene.occluded_stream(rays, &mut o, coherence);
            o.iter().filter(|&&x| x).count()
        }
    }
}

fn bench_rays(c: &mut Criterion) {
    for case in cases() {
        let scene = Scene::build(case.meshes, &BuildConfig::default()).unwrap();
        let cam = Camera::look_at(case.eye, case.at, Vec3::Y, 60.0);
        bench_scene(c, case.name, &scene, scene.bounds(), &cam, case.light);
    }
    // The same sphereflake's shape as analytic spheres (issue 30): level 3, 820 spheres.
    let flake = strahl::SphereSet::from_pairs("flake", &procedural::sphereflake_spheres(3)).unwrap();
    let scene = Scene::build_with_spheres(vec![], vec![flake], &BuildConfig::default()).unwrap();
    let cam = Camera::look_at(Vec3::new(2.1, 1.3, 2.1), Vec3::new(0.0, 0.1, 0.0), Vec3::Y, 60.0);
    bench_scene(c, "sphereflake_analytic", &scene, scene.bounds(), &cam, Vec3::new(-3.0, 6.0, 4.0));
    // Solids (issue 30): data/solids.toml's CSG die, torus, cone, cylinder, quadric and more,
    // placed by its instances, on its floor.
    let file = strahl::SceneFile::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("data/solids.toml")).unwrap();
    let scene = file.build(&BuildConfig::default()).unwrap();
    let cam = file.camera.unwrap().camera();
    bench_scene(c, "solids", &scene, scene.bounds(), &cam, file.lights[0].position);
    // Instanced: 762 instances, 13.5 million placed triangles.
    let file = strahl::SceneFile::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("data/forest.toml")).unwrap();
    let scene = file.build(&BuildConfig::default()).unwrap();
    let cam = file.camera.unwrap().camera();
    bench_scene(c, "forest_instanced", &scene, scene.bounds(), &cam, file.lights[0].position);
}

fn bench_scene<Q: Query>(
    c: &mut Criterion,
    name: &str,
    scene: &Q,
    bounds: Option<(Vec3, Vec3)>,
    cam: &Camera,
    light: Vec3,
) {
    let (primary, _) = raygen::primary(cam, 256, 256);
    let mut hits = HitStream::default();
    scene.intersect_stream(&primary, &mut hits, Coherence::Coherent);
    let eps = 1e-4 * bounds.map(|(lo, hi)| (hi - lo).length()).unwrap_or(1.0);
    let (shadow, _) = raygen::shadow(&primary, &hits, light, eps);
    let (diffuse, _) = raygen::diffuse(&primary, &hits, 1, eps);
    let mut g = c.benchmark_group(format!("rays/{name}"));
    g.sample_size(10);
    for (class, rays, occlusion, coherence) in [
        ("primary", &primary, false, Coherence::Coherent),
        ("shadow", &shadow, true, Coherence::Incoherent),
        ("diffuse", &diffuse, false, Coherence::Incoherent),
    ] {
        g.throughput(Throughput::Elements(rays.len() as u64));
        let apis: &[&str] =
            if occlusion { &["single", "packet", "stream", "groups"] } else { &["single", "packet", "stream"] };
        for &api in apis {
            g.bench_with_input(BenchmarkId::new(class, api), rays, |b, rays| {
                b.iter(|| trace_all(scene, rays, occlusion, api, coherence))
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench_build, bench_rays);
criterion_main!(benches);
