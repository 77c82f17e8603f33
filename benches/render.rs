//! One frame of each render scene in data/ (strahl backend, 2 threads, the scene's own size,
//! samples and depth); throughput in rays traced (all kinds) per second.

use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use strahl::render::Renderer;
use strahl::{BuildConfig, InstancedScene, SceneFile};

fn frames(c: &mut Criterion) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .start_handler(|_| {
            strahl::simd::set_flush_denormals();
        })
        .build()
        .unwrap();
    let mut g = c.benchmark_group("render");
    g.sample_size(10);
    for name in ["whitted", "cornell", "beer"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(format!("{name}.toml"));
        let file = SceneFile::read(&path).unwrap();
        let objects = file.load_objects().unwrap();
        let world = file.world(&objects).unwrap();
        let scene = InstancedScene::build(objects, file.instances.clone(), &BuildConfig::default()).unwrap();
        let camera = file.camera.unwrap().render_camera().unwrap();
        let r = Renderer { query: &scene, world: &world, camera, settings: file.render.settings };
        let (_, stats) = pool.install(|| r.render(&|_| {})).unwrap();
        g.throughput(Throughput::Elements(stats.total_rays()));
        g.bench_function(name, |b| b.iter(|| pool.install(|| r.render(&|_| {})).unwrap()));
    }
    g.finish();
}

criterion_group!(benches, frames);
criterion_main!(benches);
