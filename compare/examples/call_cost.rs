//! Diagnostic: what one single-ray call costs in each engine, on one thread, for rays that miss
//! the scene's box (almost nothing but the call: set-up, one node test, the answer) and for rays
//! from the middle of the scene in random directions.
//!
//! `cargo run --release -p compare --example call_cost -- scene.toml [miss|inside]`
//! (`BOX=fast` builds strahl with the fast box test.) The figures are for finding per-call costs;
//! throughput claims come from the harness (`compare`), which traces the same rays on 2 threads.
use std::time::Instant;

use compare::embree::{self, Quality, RTC_INVALID_GEOMETRY_ID, RTCRayHit};
use compare::harness::{embree_ray, empty_hit};
use glam::Vec3;
use strahl::{BuildConfig, Query, Ray, RayStream, SceneFile, raygen::Pcg32};

fn main() -> anyhow::Result<()> {
    strahl::simd::set_flush_denormals();
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| "data/forest.toml".into());
    let inside = args.next().is_some_and(|m| m == "inside");
    let mut cfg = BuildConfig::default();
    if std::env::var("BOX").is_ok_and(|v| v == "fast") {
        cfg.box_test = strahl::BoxTest::Fast;
    }
    let scene = SceneFile::read(&path)?.build(&cfg)?.flatten(&cfg)?;
    let device = embree::Device::new("")?;
    let escene = embree::Scene::build(&device, scene.meshes(), Quality::Medium, false)?;
    let (lo, hi) = scene.bounds().ok_or_else(|| anyhow::anyhow!("empty scene"))?;
    let (c, size) = ((lo + hi) * 0.5, (hi - lo).max_element());
    let n = 1 << 20;
    let mut rng = Pcg32::new(7, 1);
    let mut rays = RayStream::default();
    for _ in 0..n {
        let (a, b, d) = (rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5);
        rays.push(&if inside {
            Ray::new(c + Vec3::new(a, b, d) * 0.01 * size, Vec3::new(b, d, a))
        } else {
            // From beyond the box's far side, looking away from it.
            Ray::new(Vec3::new(c.x + a * size, c.y + b * size, hi.z + size), Vec3::new(a, b, 1.0))
        });
    }
    let ray_vec: Vec<Ray> = (0..n).map(|i| rays.get(i)).collect();
    for _ in 0..3 {
        let t = Instant::now();
        let mut hits = 0;
        for r in &ray_vec {
            hits += scene.intersect(r).is_some() as usize;
        }
        println!("strahl from a Vec<Ray>: {:.1} ns per call ({hits} hits)", t.elapsed().as_secs_f64() * 1e9 / n as f64);
        let t = Instant::now();
        let mut hits = 0;
        for i in 0..n {
            hits += scene.intersect(&rays.get(i)).is_some() as usize;
        }
        let strahl_ns = t.elapsed().as_secs_f64() * 1e9 / n as f64;
        let t = Instant::now();
        let mut ehits = 0;
        for i in 0..n {
            let mut rh = RTCRayHit { ray: embree_ray(&rays, i), hit: empty_hit() };
            escene.intersect1(&mut rh, false);
            ehits += (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) as usize;
        }
        let embree_ns = t.elapsed().as_secs_f64() * 1e9 / n as f64;
        println!("strahl {strahl_ns:.1} ns per call ({hits} hits), Embree {embree_ns:.1} ns per call ({ehits} hits)");
    }
    Ok(())
}
