//! Diagnostic: one thread, one ray file (BENCHMARKING.md format), closest hits: strahl's
//! incoherent stream and single-ray API against Embree 3's `rtcIntersect1M` and `rtcIntersect1`,
//! rounds alternated, best round each. For finding where a gap comes from; throughput claims
//! come from the harness (`compare`) and `python/benchmarks/vs_open3d.py`.
//!
//! `cargo run --release -p compare --example ray_file_speed -- scene.obj rays.rays [watertight]`
use std::time::Instant;

use compare::embree::{self, Quality, RTCRayHit};
use compare::harness::{embree_ray, empty_hit};
use strahl::{BuildConfig, Coherence, HitStream, Query, Ray, Scene};

fn main() -> anyhow::Result<()> {
    strahl::simd::set_flush_denormals();
    let mut args = std::env::args().skip(1);
    let obj = args.next().ok_or_else(|| anyhow::anyhow!("scene.obj rays.rays"))?;
    let rays_path = args.next().ok_or_else(|| anyhow::anyhow!("scene.obj rays.rays"))?;
    let watertight = args.next().is_some_and(|a| a == "watertight");
    let meshes = strahl::load_obj(&obj)?;
    let cfg = if watertight { BuildConfig::watertight() } else { BuildConfig::default() };
    let scene = Scene::build(meshes.clone(), &cfg)?;
    let device = embree::Device::new("threads=1")?;
    let escene = embree::Scene::build(&device, &meshes, Quality::Medium, watertight)?;
    let rays = compare::rayfile::read_rays(std::path::Path::new(&rays_path))?;
    let n = rays.len();
    let ray_vec: Vec<Ray> = (0..n).map(|i| rays.get(i)).collect();
    let pristine: Vec<RTCRayHit> = (0..n).map(|i| RTCRayHit { ray: embree_ray(&rays, i), hit: empty_hit() }).collect();
    let mut best = [f64::INFINITY; 4];
    let mut hits = HitStream::misses(0);
    for _ in 0..5 {
        let t = Instant::now();
        scene.intersect_stream(&rays, &mut hits, Coherence::Incoherent);
        best[0] = best[0].min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let mut k = 0;
        for r in &ray_vec {
            k += scene.intersect(r).is_some() as usize;
        }
        best[1] = best[1].min(t.elapsed().as_secs_f64());
        let mut rh = pristine.clone();
        let t = Instant::now();
        escene.intersect1m(&mut rh, false);
        best[2] = best[2].min(t.elapsed().as_secs_f64());
        let mut rh = pristine.clone();
        let t = Instant::now();
        for r in rh.iter_mut() {
            escene.intersect1(r, false);
        }
        best[3] = best[3].min(t.elapsed().as_secs_f64());
        assert!(k <= n);
    }
    let m = |s: f64| n as f64 / s / 1e6;
    println!(
        "Mrays/s, 1 thread: strahl stream {:.2}, strahl single {:.2}, Embree 3 1M {:.2}, Embree 3 single {:.2}",
        m(best[0]),
        m(best[1]),
        m(best[2]),
        m(best[3])
    );
    Ok(())
}
