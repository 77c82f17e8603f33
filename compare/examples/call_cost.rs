//! Diagnostic: what one single-ray call costs in each engine, on one thread, for rays that miss
//! the scene's box (almost nothing but the call: set-up, one node test, the answer) and for rays
//! from the middle of the scene in random directions; with a scene file's camera, also for its
//! primary, shadow and diffuse rays (`primary|shadow|diffuse`: rounds of both engines alternated,
//! each round's strahl/Embree time ratio, so that the machine's drift cancels out of A/B runs).
//!
//! `cargo run --release -p compare --example call_cost -- scene.toml [miss|inside|primary|shadow|diffuse] [rounds]`
//! (`BOX=fast` builds strahl with the fast box test.) The figures are for finding per-call costs;
//! throughput claims come from the harness (`compare`), which traces the same rays on 2 threads.
//! As in the harness's kernel mode, each engine reads its own records prepared before the timed
//! loop (strahl a `Vec<Ray>`, Embree a `Vec<RTCRayHit>`/`Vec<RTCRay>` copied from pristine ones
//! untimed): records built right before each call cost Embree up to a third of its speed.
use std::time::Instant;

use compare::embree::{self, Quality, RTC_INVALID_GEOMETRY_ID, RTCRayHit};
use compare::harness::{embree_ray, empty_hit};
use glam::Vec3;
use strahl::{BuildConfig, Query, Ray, RayStream, SceneFile, raygen::Pcg32};

fn main() -> anyhow::Result<()> {
    strahl::simd::set_flush_denormals();
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| "data/forest.toml".into());
    let mode = args.next().unwrap_or_default();
    let inside = mode == "inside";
    let mut cfg = BuildConfig::default();
    if std::env::var("BOX").is_ok_and(|v| v == "fast") {
        cfg.box_test = strahl::BoxTest::Fast;
    }
    let file = SceneFile::read(&path)?;
    let scene = file.build(&cfg)?.flatten(&cfg)?;
    let device = embree::Device::new("")?;
    let escene = embree::Scene::build(&device, scene.meshes(), Quality::Medium, false)?;
    if matches!(mode.as_str(), "primary" | "shadow" | "diffuse") {
        let rounds = args.next().and_then(|r| r.parse().ok()).unwrap_or(15);
        return camera_rays(&file, &scene, &escene, &mode, rounds);
    }
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
    let pristine: Vec<RTCRayHit> = (0..n).map(|i| RTCRayHit { ray: embree_ray(&rays, i), hit: empty_hit() }).collect();
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
        let mut work = pristine.clone();
        let t = Instant::now();
        for rh in &mut work {
            escene.intersect1(rh, false);
        }
        let embree_ns = t.elapsed().as_secs_f64() * 1e9 / n as f64;
        let ehits = work.iter().filter(|rh| rh.hit.geomID != RTC_INVALID_GEOMETRY_ID).count();
        println!(
            "strahl from the stream {strahl_ns:.1} ns per call ({hits} hits), Embree from a Vec<RTCRayHit> {embree_ns:.1} ns per call ({ehits} hits)"
        );
    }
    Ok(())
}

/// Alternated rounds of both engines' single-ray APIs over one class of a scene file's camera
/// rays (the harness's classes, 1024×1024): per round the time of each, and the median ratio.
fn camera_rays(
    file: &SceneFile,
    scene: &strahl::Scene,
    escene: &embree::Scene,
    mode: &str,
    rounds: usize,
) -> anyhow::Result<()> {
    use strahl::{Coherence, HitStream, raygen};
    let cam = file.camera.as_ref().ok_or_else(|| anyhow::anyhow!("no camera"))?.camera();
    let (primary, _) = raygen::primary(&cam, 1024, 1024);
    let mut hits = HitStream::default();
    scene.intersect_stream(&primary, &mut hits, Coherence::Coherent);
    let diag = scene.bounds().map(|(lo, hi)| (hi - lo).length()).unwrap_or(1.0);
    let rays = match mode {
        "diffuse" => raygen::diffuse(&primary, &hits, 1, 1e-4 * diag).0,
        "shadow" => {
            let light = file.lights.first().map(|l| l.position).unwrap_or(cam.eye + Vec3::Y);
            raygen::shadow_with(&primary, &hits, light, raygen::Offset::Normal).0
        }
        _ => primary,
    };
    let any = mode == "shadow";
    let n = rays.len();
    let ray_vec: Vec<Ray> = (0..n).map(|i| rays.get(i)).collect();
    let pristine: Vec<RTCRayHit> = (0..n).map(|i| RTCRayHit { ray: embree_ray(&rays, i), hit: empty_hit() }).collect();
    let mut answers = vec![false; n];
    let mut strahl_pass = || {
        let t = Instant::now();
        for (r, a) in ray_vec.iter().zip(&mut answers) {
            *a = if any { scene.occluded(r) } else { scene.intersect(r).is_some() };
        }
        (t.elapsed().as_secs_f64(), answers.iter().filter(|&&a| a).count())
    };
    let mut work = pristine.clone();
    let mut work_r: Vec<_> = pristine.iter().map(|rh| rh.ray).collect();
    let mut embree_pass = || {
        // Fresh records, not timed.
        work.copy_from_slice(&pristine);
        work_r.iter_mut().zip(&pristine).for_each(|(r, p)| *r = p.ray);
        let t = Instant::now();
        if any {
            for r in &mut work_r {
                escene.occluded1(r, false);
            }
        } else {
            for rh in &mut work {
                escene.intersect1(rh, false);
            }
        }
        let secs = t.elapsed().as_secs_f64();
        let hits = if any {
            work_r.iter().filter(|r| r.tfar == f32::NEG_INFINITY).count()
        } else {
            work.iter().filter(|rh| rh.hit.geomID != RTC_INVALID_GEOMETRY_ID).count()
        };
        (secs, hits)
    };
    let (mut ratios, mut best) = (Vec::new(), (f64::INFINITY, f64::INFINITY));
    for round in 0..rounds {
        let (s, e) = if round % 2 == 0 {
            let s = strahl_pass();
            (s, embree_pass())
        } else {
            let e = embree_pass();
            (strahl_pass(), e)
        };
        if s.1 != e.1 {
            println!("round {round}: {} strahl hits, {} Embree hits", s.1, e.1);
        }
        ratios.push(e.0 / s.0);
        best = (best.0.min(s.0), best.1.min(e.0));
    }
    ratios.sort_by(f64::total_cmp);
    println!(
        "{mode}: {n} rays, 1 thread, {rounds} alternated rounds: strahl {:.2}, Embree {:.2} Mrays/s (best); \
         speed ratio strahl/Embree median {:.3} (quartiles {:.3}-{:.3})",
        n as f64 / best.0 / 1e6,
        n as f64 / best.1 / 1e6,
        ratios[rounds / 2],
        ratios[rounds / 4],
        ratios[3 * rounds / 4]
    );
    Ok(())
}
