//! Profiling aid: traces a scene file's primary rays (packets and single rays) on one thread.
//! `cargo run --release --example instprof -- data/forest.toml [packet|packet16 (flat, or `inst`)|api1|api1d|api1d2|api1par|single|diffuse|diffusep|shadow|shadow1|build|ibuild|ctx] [repeats] [flat|inst]`
//! (`shadow` and `diffusep` trace as packets, `shadow1` and `diffuse` one ray at a time; `ao` and `aop`
//! ask whether the diffuse rays are occluded, one at a time and as packets; `diffuseo` and `aoo` trace
//! the diffuse rays pre-sorted by direction octant in groups of 4,096, as consecutive packets; the `api1` modes call
//! the single-ray API (`api1do` on the octant-sorted diffuse rays) on the flattened scene, or with `inst` on the two-level one; `api1par` runs it on
//! every rayon thread over chunks of 4,096 camera rays, as the harness does.)
//! `MAX_LEAF`, `TRAV_COST`, `SPLIT` (spatial split factor) and `BOX=fast` override the build settings.
use std::time::Instant;

use strahl::{BuildConfig, Coherence, HitStream, Query, SceneFile, raygen};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let file = SceneFile::read(args.get(1).map(String::as_str).unwrap_or("data/forest.toml"))?;
    let mode = args.get(2).cloned().unwrap_or_else(|| "packet".into());
    let repeats: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(5);
    let mut cfg = BuildConfig::default();
    if let Some(v) = std::env::var("MAX_LEAF").ok().and_then(|v| v.parse().ok()) {
        cfg.max_leaf = v;
    }
    if let Some(v) = std::env::var("TRAV_COST").ok().and_then(|v| v.parse().ok()) {
        cfg.traversal_cost = v;
    }
    if let Some(v) = std::env::var("PAR").ok().and_then(|v| v.parse().ok()) {
        cfg.parallel_threshold = v;
    }
    if let Some(v) = std::env::var("SPLIT").ok().and_then(|v| v.parse().ok()) {
        cfg.split_factor = v;
    }
    if std::env::var("BOX").is_ok_and(|v| v == "fast") {
        cfg.box_test = strahl::BoxTest::Fast;
    }
    if mode == "build" {
        // Build time of the flat scene (all cores of the rayon pool), best of `repeats`.
        let meshes: Vec<_> = file.build(&BuildConfig::default())?.flatten(&BuildConfig::default())?.meshes().to_vec();
        let mut best = f64::INFINITY;
        let mut inner = f64::INFINITY;
        // As the harness does: each build runs while the previous scene is still alive.
        let mut last = None;
        for _ in 0..repeats {
            let m = meshes.clone();
            let t = Instant::now();
            let s = strahl::Scene::build(m, &cfg)?;
            best = best.min(t.elapsed().as_secs_f64());
            inner = inner.min(s.stats().build_ms);
            last = Some(s);
        }
        std::hint::black_box(last);
        println!("build_ms (as the harness reports it): {inner:.4}");
        let m = meshes.clone();
        let st = strahl::Scene::build(m, &cfg)?.stats().clone();
        println!(
            "build: {:.1} ms (best of {repeats}), SAH {:.3}, {} references for {} triangles, {:.1} B/tri",
            best * 1e3,
            st.sah,
            st.references,
            st.triangles,
            st.bytes_per_triangle
        );
        return Ok(());
    }
    if mode == "ctx" {
        // The first object's build called directly, inside a one-element `par_iter` map, and as
        // the two-level build's objects (`build_ms` against `objects_build_ms`), best of `repeats`.
        use rayon::prelude::*;
        let objects = file.load_objects()?;
        let meshes = objects[0].clone();
        let (mut a, mut b, mut c) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        for _ in 0..repeats {
            let s = strahl::Scene::build(meshes.clone(), &cfg)?;
            a = a.min(s.stats().build_ms);
            drop(s);
            let v: Vec<strahl::Scene> =
                vec![meshes.clone()].into_par_iter().map(|m| strahl::Scene::build(m, &cfg).unwrap()).collect();
            b = b.min(v[0].stats().build_ms);
            drop(v);
            let s = strahl::InstancedScene::build(vec![meshes.clone()], file.instances.clone(), &cfg)?;
            c = c.min(s.stats().objects_build_ms);
        }
        println!("ctx: direct {a:.2}, in par_iter {b:.2}, instanced {c:.2}");
        return Ok(());
    }
    if mode == "ibuild" {
        // Two-level build time (objects, then the instance level), best of `repeats`, as the
        // harness reports it.
        let objects = file.load_objects()?;
        let (mut objs, mut top) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..repeats {
            let s = strahl::InstancedScene::build(objects.clone(), file.instances.clone(), &cfg)?;
            objs = objs.min(s.stats().objects_build_ms);
            top = top.min(s.stats().top_build_ms);
        }
        println!("ibuild: objects {objs:.2} ms, instance level {top:.2} ms (best of {repeats})");
        return Ok(());
    }
    let scene = file.build(&cfg)?;
    let cam = file.camera.ok_or("no camera")?.camera();
    let (primary, _) = raygen::primary(&cam, 1024, 1024);
    let mut hits = HitStream::default();
    scene.intersect_stream(&primary, &mut hits, Coherence::Coherent);
    let diag = scene.bounds().map(|(lo, hi)| (hi - lo).length()).unwrap_or(1.0);
    let (diffuse, _) = raygen::diffuse(&primary, &hits, 1, 1e-4 * diag);
    let light = file.lights.first().map(|l| l.position).unwrap_or(cam.eye + glam::Vec3::Y);
    let (shadow, _) = raygen::shadow_with(&primary, &hits, light, raygen::Offset::Normal);
    // The diffuse rays ordered by direction octant within groups of 4,096 (`diffuseo`, `aoo`).
    let mut diffuse_oct = strahl::RayStream::default();
    for g in (0..diffuse.len()).step_by(4096) {
        let m = (diffuse.len() - g).min(4096);
        let oct = |i: usize| {
            let d = diffuse.get(i).dir;
            (d.x < 0.0) as u8 | ((d.y < 0.0) as u8) << 1 | ((d.z < 0.0) as u8) << 2
        };
        for o in 0..8 {
            for i in g..g + m {
                if oct(i) == o {
                    diffuse_oct.push(&diffuse.get(i));
                }
            }
        }
    }
    let (rays, coherence) = match mode.as_str() {
        "diffuseo" => (&diffuse_oct, Coherence::Coherent),
        "single" => (&primary, Coherence::Incoherent),
        "diffuse" => (&diffuse, Coherence::Incoherent),
        "diffusep" => (&diffuse, Coherence::Coherent),
        "shadow" => (&shadow, Coherence::Coherent),
        "shadow1" => (&shadow, Coherence::Incoherent),
        "ao" => (&diffuse, Coherence::Incoherent),
        "aop" => (&diffuse, Coherence::Coherent),
        "aoo" => (&diffuse_oct, Coherence::Coherent),
        _ => (&primary, Coherence::Coherent),
    };
    if mode == "packet16" {
        // The packet API on consecutive packets of 16 camera rays (no groups); flattened unless
        // `inst` is given.
        let mut hp = strahl::HitPacket::default();
        let mut best = f64::INFINITY;
        let inst = args.iter().any(|a| a == "inst");
        let flat = if inst { None } else { Some(scene.flatten(&cfg)?) };
        for _ in 0..repeats {
            let t = Instant::now();
            for k in (0..primary.len()).step_by(strahl::PACKET_WIDTH) {
                let p = primary.packet(k, strahl::PACKET_WIDTH);
                match &flat {
                    Some(f) => f.intersect_packet(&p, &mut hp),
                    None => scene.intersect_packet(&p, &mut hp),
                }
                std::hint::black_box(&hp);
            }
            best = best.min(t.elapsed().as_secs_f64());
        }
        println!(
            "packet16 ({}): {:.2} Mrays/s (1 thread, best of {repeats})",
            if inst { "instanced" } else { "flat" },
            primary.len() as f64 / best / 1e6
        );
        return Ok(());
    }
    if mode == "api1par" {
        // The single-ray API on camera rays over chunks of 4,096 rays on all rayon threads, as the
        // harness's `single` column runs it (`RAYON_NUM_THREADS` sets the threads).
        use rayon::prelude::*;
        let flat = scene.flatten(&cfg)?;
        let n = primary.len();
        let (mut t_out, mut g_out, mut p_out, mut i_out) =
            (vec![0.0f32; n], vec![0u32; n], vec![0u32; n], vec![0u32; n]);
        let mut best = f64::INFINITY;
        for _ in 0..repeats {
            let t = Instant::now();
            (
                t_out.par_chunks_mut(4096),
                g_out.par_chunks_mut(4096),
                p_out.par_chunks_mut(4096),
                i_out.par_chunks_mut(4096),
            )
                .into_par_iter()
                .enumerate()
                .for_each(|(c, (t, g, p, i))| {
                    for k in 0..t.len() {
                        let h = flat.intersect(&primary.get(c * 4096 + k));
                        (t[k], g[k], p[k], i[k]) =
                            h.map_or((f32::INFINITY, !0, !0, !0), |h| (h.t, h.geom_id, h.prim_id, h.inst_id));
                    }
                });
            best = best.min(t.elapsed().as_secs_f64());
        }
        std::hint::black_box(&t_out);
        println!(
            "api1par ({} threads): {:.2} Mrays/s (best of {repeats})",
            rayon::current_num_threads(),
            primary.len() as f64 / best / 1e6
        );
        return Ok(());
    }
    if mode == "api1" || mode == "api1d" || mode == "api1d2" || mode == "api1do" {
        // The single-ray API, one call per ray (as the harness's `single` column); `api1d2`
        // traces each diffuse ray twice in a row, the second time with a warm cache.
        let rays = match mode.as_str() {
            "api1" => &primary,
            "api1do" => &diffuse_oct,
            _ => &diffuse,
        };
        let twice = mode == "api1d2";
        // Flattened unless `inst` is given (then the two-level scene).
        let inst = args.iter().any(|a| a == "inst");
        let flat = if inst { None } else { Some(scene.flatten(&cfg)?) };
        let q: &dyn Fn(&strahl::Ray) -> Option<strahl::Hit> = match &flat {
            Some(f) => &|r| f.intersect(r),
            None => &|r| scene.intersect(r),
        };
        let mut best = f64::INFINITY;
        let mut sum = 0.0f32;
        for _ in 0..repeats {
            let t = Instant::now();
            for i in 0..rays.len() {
                // The whole hit, as the harness's answers take it (with `t` alone the compiler
                // drops the hit record's normal and ids).
                if let Some(h) = q(&rays.get(i)) {
                    sum += h.t + h.ng.x + (h.prim_id ^ h.geom_id) as f32;
                }
                if twice && let Some(h) = q(&rays.get(i)) {
                    sum += h.t;
                }
            }
            best = best.min(t.elapsed().as_secs_f64());
        }
        std::hint::black_box(sum);
        println!(
            "{mode} ({}): {:.2} Mrays/s (1 thread, best of {repeats})",
            if inst { "instanced" } else { "flat" },
            rays.len() as f64 / best / 1e6
        );
        return Ok(());
    }
    let occlusion = mode.starts_with("shadow") || mode.starts_with("ao");
    let mut occ = Vec::new();
    let flat = if args.iter().any(|a| a == "flat") { Some(scene.flatten(&cfg)?) } else { None };
    let mut best = f64::INFINITY;
    for _ in 0..repeats {
        let t = Instant::now();
        match (&flat, occlusion) {
            (Some(f), false) => f.intersect_stream(rays, &mut hits, coherence),
            (Some(f), true) => f.occluded_stream(rays, &mut occ, coherence),
            (None, false) => scene.intersect_stream(rays, &mut hits, coherence),
            (None, true) => scene.occluded_stream(rays, &mut occ, coherence),
        }
        best = best.min(t.elapsed().as_secs_f64());
    }
    println!("{mode}: {:.2} Mrays/s (1 thread, best of {repeats})", rays.len() as f64 / best / 1e6);
    Ok(())
}
