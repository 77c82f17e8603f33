//! `compare --spheres` (issue 30): analytic spheres side by side with Embree's native spheres,
//! the three sphere tests charted speed against accuracy, and the analytic sphereflake against
//! its tessellations ("model no more than a scene needs").
//!
//! - **Engines**: Haines' sphereflake as strahl spheres (the robust test) and as Embree
//!   `RTC_GEOMETRY_TYPE_SPHERE_POINT` (its `FLOAT4` vertex buffer filled before the build); the
//!   same primary, shadow and diffuse rays; kernel mode (each engine's native ray layout prepared
//!   outside the timed region, `kernel.rs`), the three APIs each, interleaved passes, 2 threads.
//!   Each engine's hit distances are measured against the float64 roots of the sphere it names;
//!   a hit/miss disagreement is decided in float64 on the sphere the hitting engine named
//!   (closest hit) or over all spheres (occlusion).
//! - **Tests**: the level-3 flake (820 spheres) from a near camera and from a camera 1000 times
//!   farther with the view narrowed to the same framing, and rays aimed 1e-4 of a radius inside
//!   and outside every silhouette; float64 truth by brute force over every sphere; Mrays/s of
//!   the stream API on the near camera.
//! - **Tessellations**: the same flake as UV spheres of 6×12 to 48×96 quads against the analytic
//!   spheres: memory, build time, Mrays/s of primary rays (stream), silhouette error (rays whose
//!   hit or miss differs from the float64 truth) and normal error.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};
use strahl::raygen::{self, Offset};
use strahl::shapes::sphere_roots_f64;
use strahl::{
    BuildConfig, Camera, Coherence, HitStream, Query, Ray, RayStream, Scene, SphereSet, SphereTest, procedural,
};

use crate::embree;
use crate::harness::{Class, quartiles};
pub use crate::kernel::ApiTimes;
use crate::kernel::Timed;

/// Settings of a sphere run.
pub struct Settings {
    /// Sphereflake levels for the engine comparison.
    pub levels: Vec<u32>,
    /// Primary rays are `width²`.
    pub width: u32,
    /// Timed passes per engine and API.
    pub passes: usize,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EngineClass {
    pub class: String,
    pub rays: usize,
    pub hit_rate: f64,
    pub apis: Vec<ApiTimes>,
    /// strahl's best API over Embree's best API, per pass: quartiles.
    pub best_ratio_quartiles: [f64; 3],
    pub hit_miss_agreement: f64,
    /// Among rays both hit: the same sphere.
    pub prim_agreement: f64,
    /// Disagreements the float64 decision calls errors of each engine, and ties (a ray within
    /// 1e-6 relative of a silhouette, or at the interval's ends).
    pub strahl_errors: usize,
    pub embree_errors: usize,
    pub ties: usize,
    /// Relative t error against the float64 root of the sphere each engine names (closest hit):
    /// median, 99.9th percentile, maximum.
    pub strahl_t_error: [f64; 3],
    pub embree_t_error: [f64; 3],
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EngineScene {
    pub levels: u32,
    pub spheres: usize,
    pub strahl_build_ms: f64,
    pub embree_build_ms: f64,
    pub strahl_bytes: usize,
    pub classes: Vec<EngineClass>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MethodRow {
    pub test: String,
    /// Stream API, primary rays of the near camera, median Mrays/s.
    pub mrays: f64,
    /// Per camera (near, far): relative t error median / p99.9 / max against float64, and the
    /// fraction of rays whose hit or miss differs from float64 (silhouette ties excluded).
    pub near_t_error: [f64; 3],
    pub far_t_error: [f64; 3],
    pub near_wrong: f64,
    pub far_wrong: f64,
    /// Rays from the near camera aimed 1e-4 of the radius inside and outside each sphere's
    /// silhouette (16 around each of the 820): the fraction whose hit or miss differs from
    /// float64 (ties excluded).
    pub silhouette_wrong: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TessRow {
    /// "analytic" or "STACKS×SLICES".
    pub model: String,
    pub primitives: usize,
    pub bytes: usize,
    pub build_ms: f64,
    pub mrays: f64,
    /// Fraction of primary rays whose hit or miss differs from the analytic float64 truth.
    pub silhouette_error: f64,
    /// Mean and maximum angle (degrees) between the reported normal's line and the true normal.
    pub normal_error_mean: f64,
    pub normal_error_max: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SphereReport {
    pub date: String,
    pub machine: String,
    pub commit: String,
    pub threads: usize,
    pub width: u32,
    pub passes: usize,
    pub engines: Vec<EngineScene>,
    pub methods: Vec<MethodRow>,
    pub tessellations: Vec<TessRow>,
}

fn flake_set(levels: u32) -> anyhow::Result<SphereSet> {
    Ok(SphereSet::from_pairs("sphereflake", &procedural::sphereflake_spheres(levels))?)
}

fn near_camera() -> Camera {
    Camera::look_at(Vec3::new(2.1, 1.3, 2.1), Vec3::new(0.0, 0.1, 0.0), Vec3::Y, 60.0)
}

/// A camera `k` times farther from the flake along the same line, its field of view narrowed to
/// keep the framing.
fn far_camera(k: f32) -> Camera {
    let (eye, at) = (Vec3::new(2.1, 1.3, 2.1), Vec3::new(0.0, 0.1, 0.0));
    let fov = 2.0 * ((30f32.to_radians()).tan() / k).atan();
    Camera::look_at(at + (eye - at) * k, at, Vec3::Y, fov.to_degrees())
}

/// Median Mrays/s of each scene's coherent closest-hit stream over `rays`, the scenes timed in
/// interleaved passes (one warm-up pass, then `passes`, each starting one scene later), so that
/// the machine's drift falls on all of them alike. Also returns each scene's hits.
pub(crate) fn interleaved_mrays(
    pool: &rayon::ThreadPool,
    scenes: &[Scene],
    rays: &RayStream,
    passes: usize,
) -> (Vec<f64>, Vec<HitStream>) {
    let mut secs = vec![Vec::new(); scenes.len()];
    let mut hits = vec![HitStream::default(); scenes.len()];
    for pass in 0..=passes {
        for k in 0..scenes.len() {
            let i = (pass + k) % scenes.len();
            let t = Instant::now();
            pool.install(|| scenes[i].intersect_stream_par(rays, &mut hits[i], Coherence::Coherent));
            if pass > 0 {
                secs[i].push(t.elapsed().as_secs_f64());
            }
        }
    }
    let m = secs
        .iter_mut()
        .map(|s| {
            s.sort_by(f64::total_cmp);
            rays.len() as f64 / s[s.len() / 2] / 1e6
        })
        .collect();
    (m, hits)
}

/// The float64 truth for one ray over spheres: the nearest root in `(tnear, tfar]`, the sphere,
/// and whether the ray passes within 1e-6 relative of some silhouette it might flip on.
fn truth(spheres: &[(Vec3, f32)], ray: &Ray) -> (Option<(f64, usize)>, bool) {
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    let (tn, tf) = (ray.tnear.max(0.0) as f64, ray.tfar as f64);
    let mut best: Option<(f64, usize)> = None;
    let mut tie = false;
    let dn = d.normalize();
    for (i, &(c, r)) in spheres.iter().enumerate() {
        let f: DVec3 = c.as_dvec3() - o;
        let along = f.dot(dn);
        let dist = (f - dn * along).length();
        if (dist - r as f64).abs() <= 1e-6 * f.length().max(r as f64) && along > -(r as f64) {
            tie = true;
        }
        if let Some((t0, t1)) = sphere_roots_f64(c.as_dvec3(), r as f64, o, d) {
            for t in [t0, t1] {
                if t > tn && t <= tf && best.is_none_or(|b| t < b.0) {
                    best = Some((t, i));
                    break;
                }
            }
        }
    }
    (best, tie)
}

pub(crate) fn rel_quantiles(mut v: Vec<f64>) -> [f64; 3] {
    if v.is_empty() {
        return [0.0; 3];
    }
    v.sort_by(f64::total_cmp);
    let q = |f: f64| v[((v.len() - 1) as f64 * f).round() as usize];
    [q(0.5), q(0.999), *v.last().unwrap_or(&0.0)]
}

/// Runs every part and writes `spheres.md`, `spheres.json` and the two charts into `out`.
pub fn run(
    settings: &Settings,
    pool: &rayon::ThreadPool,
    device: &embree::Device,
    out: &Path,
    mut progress: impl FnMut(&str),
) -> anyhow::Result<SphereReport> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut engines = Vec::new();
    for &levels in &settings.levels {
        progress(&format!("engines, level {levels}"));
        engines.push(run_engines(levels, settings, pool, device)?);
    }
    progress("sphere tests");
    let methods = run_methods(settings, pool)?;
    progress("tessellations");
    let tessellations = run_tessellations(settings, pool)?;
    let threads = pool.current_num_threads();
    let report = SphereReport {
        date: crate::report::today(),
        machine: crate::report::machine(),
        commit: crate::report::commit(),
        threads,
        width: settings.width,
        passes: settings.passes,
        engines,
        methods,
        tessellations,
    };
    std::fs::write(out.join("spheres.json"), serde_json::to_string_pretty(&report)?)?;
    std::fs::write(out.join("spheres.md"), markdown(&report))?;
    charts(out, &report)?;
    Ok(report)
}

fn run_engines(
    levels: u32,
    settings: &Settings,
    pool: &rayon::ThreadPool,
    device: &embree::Device,
) -> anyhow::Result<EngineScene> {
    let set = flake_set(levels)?;
    let spheres: Vec<(Vec3, f32)> = (0..set.len()).map(|i| set.sphere(i)).collect();
    let cfg = BuildConfig::default();
    let (mut strahl_build_ms, mut embree_build_ms) = (f64::INFINITY, f64::INFINITY);
    let (mut scene, mut escene) = (None, None);
    // Interleaved build rounds, the least time of each kept.
    for _ in 0..3 {
        let s = pool.install(|| Scene::build_with_spheres(vec![], vec![set.clone()], &cfg))?;
        strahl_build_ms = strahl_build_ms.min(s.sphere_stats().build_ms);
        scene = Some(s);
        let e = embree::Scene::build_spheres(device, std::slice::from_ref(&set), embree::Quality::Medium)?;
        embree_build_ms = embree_build_ms.min(e.build_ms);
        escene = Some(e);
    }
    let (Some(scene), Some(escene)) = (scene, escene) else { unreachable!("three rounds ran") };
    let w = settings.width;
    let (primary, _) = raygen::primary(&near_camera(), w, w);
    let mut hits = HitStream::default();
    pool.install(|| scene.intersect_stream_par(&primary, &mut hits, Coherence::Coherent));
    let light = Vec3::new(-3.0, 6.0, 4.0);
    let (shadow, _) = raygen::shadow_with(&primary, &hits, light, Offset::Normal);
    let (diffuse, _) = raygen::diffuse_with(&primary, &hits, 7, Offset::Normal);
    let mut classes = Vec::new();
    for (class, rays) in [(Class::Primary, &primary), (Class::Shadow, &shadow), (Class::Diffuse, &diffuse)] {
        classes.push(engine_class(&scene, &escene, &spheres, rays, class, settings.passes, pool));
    }
    Ok(EngineScene {
        levels,
        spheres: set.len(),
        strahl_build_ms,
        embree_build_ms,
        strahl_bytes: scene.sphere_stats().bytes,
        classes,
    })
}

fn engine_class(
    scene: &Scene,
    escene: &embree::Scene,
    spheres: &[(Vec3, f32)],
    rays: &RayStream,
    class: Class,
    passes: usize,
    pool: &rayon::ThreadPool,
) -> EngineClass {
    let n = rays.len();
    let timed = Timed::run(scene, escene, rays, class, passes, pool);
    let (apis, ratios) = (timed.apis(n), timed.best_ratios());
    let answers = timed.answers;
    let [s, e] = &answers;
    let (mut agree, mut both, mut same, mut se, mut ee, mut ties) = (0, 0, 0, 0, 0, 0);
    let (mut s_err, mut e_err) = (Vec::new(), Vec::new());
    let mut brute_left = 256;
    for i in 0..n {
        let ray = rays.get(i);
        let (sh, eh) = (s.hit(i), e.hit(i));
        if sh == eh {
            agree += 1;
            if sh && !class.occlusion() {
                both += 1;
                same += (s.key(i) == e.key(i)) as usize;
            }
        } else if class.occlusion() {
            if brute_left > 0 {
                brute_left -= 1;
                match truth(spheres, &ray) {
                    (_, true) => ties += 1,
                    (Some(_), false) => *(if sh { &mut ee } else { &mut se }) += 1,
                    (None, false) => *(if sh { &mut se } else { &mut ee }) += 1,
                }
            }
        } else {
            // The sphere the hitting engine named, in float64.
            let k = if sh { s.prim[i] } else { e.prim[i] } as usize;
            let (c, r) = spheres[k];
            let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
            let f = c.as_dvec3() - o;
            let dn = d.normalize();
            let dist = (f - dn * f.dot(dn)).length();
            if (dist - r as f64).abs() <= 1e-6 * f.length() {
                ties += 1;
            } else {
                let real = sphere_roots_f64(c.as_dvec3(), r as f64, o, d).is_some_and(|(t0, t1)| {
                    [t0, t1].iter().any(|&t| t > ray.tnear.max(0.0) as f64 && t <= ray.tfar as f64)
                });
                *(if real == sh { &mut ee } else { &mut se }) += 1;
            }
        }
        if !class.occlusion() {
            for (a, errs) in [(s, &mut s_err), (e, &mut e_err)] {
                if a.hit(i) {
                    let (c, r) = spheres[a.prim[i] as usize];
                    if let Some((t0, t1)) =
                        sphere_roots_f64(c.as_dvec3(), r as f64, ray.origin.as_dvec3(), ray.dir.as_dvec3())
                    {
                        let t = if t0 > ray.tnear.max(0.0) as f64 { t0 } else { t1 };
                        errs.push(((a.t[i] as f64 - t) / t).abs());
                    }
                }
            }
        }
    }
    EngineClass {
        class: class.name().to_string(),
        rays: n,
        hit_rate: (0..n).filter(|&i| s.hit(i)).count() as f64 / n.max(1) as f64,
        apis,
        best_ratio_quartiles: quartiles(&ratios),
        hit_miss_agreement: agree as f64 / n.max(1) as f64,
        prim_agreement: if both == 0 { 1.0 } else { same as f64 / both as f64 },
        strahl_errors: se,
        embree_errors: ee,
        ties,
        strahl_t_error: rel_quantiles(s_err),
        embree_t_error: rel_quantiles(e_err),
    }
}

/// Relative t errors and the wrong hit/miss fraction of `hits` against the float64 truth.
fn against_truth(spheres: &[(Vec3, f32)], rays: &RayStream, hits: &HitStream) -> ([f64; 3], f64, Vec<f64>) {
    use rayon::prelude::*;
    let per_ray: Vec<(Option<f64>, bool, Option<f64>)> = (0..rays.len())
        .into_par_iter()
        .map(|i| {
            let ray = rays.get(i);
            let (t, tie) = truth(spheres, &ray);
            let h = hits.get(i);
            let wrong = h.is_some() != t.is_some() && !tie;
            let err = match (h, t) {
                (Some(h), Some((t, _))) => Some(((h.t as f64 - t) / t).abs()),
                _ => None,
            };
            // Normal error in degrees where both hit.
            let nerr = match (h, t) {
                (Some(h), Some((t, k))) => {
                    let p = ray.origin.as_dvec3() + ray.dir.as_dvec3() * t;
                    let n = (p - spheres[k].0.as_dvec3()).normalize();
                    let m = h.ng.as_dvec3().normalize();
                    // Up to sign: a triangle's geometric normal follows its winding.
                    Some(n.dot(m).abs().min(1.0).acos().to_degrees())
                }
                _ => None,
            };
            (err, wrong, nerr)
        })
        .collect();
    let errs: Vec<f64> = per_ray.iter().filter_map(|r| r.0).collect();
    let wrong = per_ray.iter().filter(|r| r.1).count() as f64 / rays.len().max(1) as f64;
    let nerrs: Vec<f64> = per_ray.iter().filter_map(|r| r.2).collect();
    (rel_quantiles(errs), wrong, nerrs)
}

fn run_methods(settings: &Settings, pool: &rayon::ThreadPool) -> anyhow::Result<Vec<MethodRow>> {
    let set = flake_set(3)?;
    let spheres: Vec<(Vec3, f32)> = (0..set.len()).map(|i| set.sphere(i)).collect();
    let w = settings.width.min(512);
    let (near, _) = raygen::primary(&near_camera(), w, w);
    let (far, _) = raygen::primary(&far_camera(1000.0), w, w);
    let scenes = SphereTest::ALL
        .iter()
        .map(|&test| {
            let cfg = BuildConfig { sphere_test: test, ..BuildConfig::default() };
            Ok(pool.install(|| Scene::build_with_spheres(vec![], vec![set.clone()], &cfg))?)
        })
        .collect::<anyhow::Result<Vec<Scene>>>()?;
    let (speeds, near_hits) = interleaved_mrays(pool, &scenes, &near, settings.passes);
    // Silhouette-aimed rays: from the near camera's eye to points at (1 ± 1e-4) radii from each
    // centre, across the line of sight, 16 around each sphere.
    let eye = Vec3::new(2.1, 1.3, 2.1);
    let mut sil = RayStream::default();
    for &(c, r) in &spheres {
        let view = (c - eye).normalize();
        let (a, b) = view.any_orthonormal_pair();
        for k in 0..16 {
            let phi = k as f32 * 2.399_963; // the golden angle
            let u = a * phi.cos() + b * phi.sin();
            for side in [1.0 - 1e-4, 1.0 + 1e-4] {
                sil.push(&Ray::new(eye, c + u * (r * side) - eye));
            }
        }
    }
    let mut rows = Vec::new();
    for (k, test) in SphereTest::ALL.into_iter().enumerate() {
        let (near_t_error, near_wrong, _) = pool.install(|| against_truth(&spheres, &near, &near_hits[k]));
        let mut hits = HitStream::default();
        pool.install(|| scenes[k].intersect_stream_par(&far, &mut hits, Coherence::Coherent));
        let (far_t_error, far_wrong, _) = pool.install(|| against_truth(&spheres, &far, &hits));
        pool.install(|| scenes[k].intersect_stream_par(&sil, &mut hits, Coherence::Incoherent));
        let (_, silhouette_wrong, _) = pool.install(|| against_truth(&spheres, &sil, &hits));
        rows.push(MethodRow {
            test: test.name().to_string(),
            mrays: speeds[k],
            near_t_error,
            far_t_error,
            near_wrong,
            far_wrong,
            silhouette_wrong,
        });
    }
    Ok(rows)
}

fn run_tessellations(settings: &Settings, pool: &rayon::ThreadPool) -> anyhow::Result<Vec<TessRow>> {
    let set = flake_set(3)?;
    let spheres: Vec<(Vec3, f32)> = (0..set.len()).map(|i| set.sphere(i)).collect();
    let w = settings.width.min(512);
    let (rays, _) = raygen::primary(&near_camera(), w, w);
    // (model, primitives, bytes of tree and geometry, build ms) per scene, all built first so
    // that their passes interleave.
    let mut models = Vec::new();
    let mut scenes = Vec::new();
    let analytic = pool.install(|| Scene::build_with_spheres(vec![], vec![set.clone()], &BuildConfig::default()))?;
    let st = analytic.sphere_stats().clone();
    models.push(("analytic".to_string(), set.len(), st.bytes + set.bytes(), st.build_ms));
    scenes.push(analytic);
    for (stacks, slices) in [(6, 12), (12, 24), (24, 48), (48, 96)] {
        let mesh = procedural::sphereflake(3, stacks, slices);
        let tris = mesh.triangle_count();
        let mesh_bytes = mesh.positions().len() * 12 + tris * 12;
        let scene = pool.install(|| Scene::build(vec![mesh], &BuildConfig::default()))?;
        models.push((format!("{stacks}×{slices}"), tris, scene.stats().bytes + mesh_bytes, scene.stats().build_ms));
        scenes.push(scene);
    }
    let (speeds, hits) = interleaved_mrays(pool, &scenes, &rays, settings.passes);
    let mut rows = Vec::new();
    for (k, (model, primitives, bytes, build_ms)) in models.into_iter().enumerate() {
        let (_, wrong, nerrs) = pool.install(|| against_truth(&spheres, &rays, &hits[k]));
        rows.push(TessRow {
            model,
            primitives,
            bytes,
            build_ms,
            mrays: speeds[k],
            silhouette_error: wrong,
            normal_error_mean: nerrs.iter().sum::<f64>() / nerrs.len().max(1) as f64,
            normal_error_max: nerrs.iter().copied().fold(0.0, f64::max),
        });
    }
    Ok(rows)
}

/// The report as Markdown.
pub fn markdown(r: &SphereReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "# Analytic spheres: strahl against Embree, the sphere tests, the tessellations\n");
    let _ = writeln!(
        s,
        "{} · {} · commit {} · {} threads · {}² primary rays · {} passes · `cargo run --release -p compare -- --spheres`\n",
        r.date, r.machine, r.commit, r.threads, r.width, r.passes
    );
    let _ = writeln!(s, "## strahl spheres against Embree `SPHERE_POINT` (kernel mode, same rays)\n");
    let _ = writeln!(
        s,
        "| level | spheres | class | strahl single / packet / stream | Embree single / packet / stream | best ÷ best (q1 / median / q3) | hit/miss agreement | errors strahl / Embree / ties | t error p99.9 strahl / Embree |"
    );
    let _ = writeln!(s, "|---:|---:|---|---|---|---|---:|---|---|");
    for e in &r.engines {
        for c in &e.classes {
            let f = |a: &[ApiTimes], strahl: bool| {
                a.iter()
                    .map(|x| format!("{:.1}", if strahl { x.strahl } else { x.embree }))
                    .collect::<Vec<_>>()
                    .join(" / ")
            };
            let q = c.best_ratio_quartiles;
            let t = if c.class == "shadow" {
                "–".to_string()
            } else {
                format!("{:.1e} / {:.1e}", c.strahl_t_error[1], c.embree_t_error[1])
            };
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {:.2} / **{:.2}** / {:.2} | {:.4}% | {} / {} / {} | {} |",
                e.levels,
                e.spheres,
                c.class,
                f(&c.apis, true),
                f(&c.apis, false),
                q[0],
                q[1],
                q[2],
                c.hit_miss_agreement * 100.0,
                c.strahl_errors,
                c.embree_errors,
                c.ties,
                t
            );
        }
    }
    let _ = writeln!(s, "\nBuilds (least of 3 interleaved rounds):\n");
    let _ = writeln!(s, "| level | spheres | strahl ms | Embree ms | strahl tree bytes |");
    let _ = writeln!(s, "|---:|---:|---:|---:|---:|");
    for e in &r.engines {
        let _ = writeln!(
            s,
            "| {} | {} | {:.2} | {:.2} | {} |",
            e.levels, e.spheres, e.strahl_build_ms, e.embree_build_ms, e.strahl_bytes
        );
    }
    let _ = writeln!(s, "\n## The three sphere tests (level 3, 820 spheres; float64 truth by brute force)\n");
    let _ = writeln!(
        s,
        "| test | Mrays/s (stream, primary) | near camera: t error median / p99.9 / max | wrong hit/miss | camera 1000× farther: t error median / p99.9 / max | wrong hit/miss | silhouette-aimed (±1e-4 r): wrong hit/miss |"
    );
    let _ = writeln!(s, "|---|---:|---|---:|---|---:|---:|");
    for m in &r.methods {
        let e = |x: [f64; 3]| format!("{:.1e} / {:.1e} / {:.1e}", x[0], x[1], x[2]);
        let _ = writeln!(
            s,
            "| {} | {:.1} | {} | {:.4}% | {} | {:.4}% | {:.4}% |",
            m.test,
            m.mrays,
            e(m.near_t_error),
            m.near_wrong * 100.0,
            e(m.far_t_error),
            m.far_wrong * 100.0,
            m.silhouette_wrong * 100.0
        );
    }
    let _ = writeln!(s, "\n## Analytic against tessellated (level 3, primary rays, stream API)\n");
    let _ = writeln!(
        s,
        "| model | primitives | memory (MB) | build ms | Mrays/s | silhouette error | normal error mean / max (°) |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---|");
    for t in &r.tessellations {
        let _ = writeln!(
            s,
            "| {} | {} | {:.2} | {:.2} | {:.1} | {:.3}% | {:.3} / {:.3} |",
            t.model,
            t.primitives,
            t.bytes as f64 / 1e6,
            t.build_ms,
            t.mrays,
            t.silhouette_error * 100.0,
            t.normal_error_mean,
            t.normal_error_max
        );
    }
    s
}

/// A scatter chart: one labelled point per `(label, error, Mrays/s)`, the error on a log axis
/// (decade labels only), the Pareto front drawn and its points ringed, written to `path`
/// (900×520 PNG).
pub(crate) fn scatter(path: &Path, title: &str, xdesc: &str, points: Vec<(String, f64, f64)>) -> anyhow::Result<()> {
    use plotters::prelude::*;
    let root = BitMapBackend::new(path, (900, 520)).into_drawing_area();
    root.fill(&WHITE)?;
    let xs: Vec<f64> = points.iter().map(|p| p.1.max(1e-12).log10()).collect();
    let (xmin, xmax) = xs.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let ymax = points.iter().map(|p| p.2).fold(1.0, f64::max) * 1.25;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(60)
        .build_cartesian_2d((xmin - 0.5).floor()..(xmax + 2.5).ceil(), 0f64..ymax)?;
    chart
        .configure_mesh()
        .x_desc(xdesc)
        .y_desc("Mrays/s (higher is better)")
        // Decades only: plotters also places ticks between them.
        .x_label_formatter(&|x| {
            if (x - x.round()).abs() < 1e-6 { format!("1e{:.0}", x.round()) } else { String::new() }
        })
        .label_style(("sans-serif", 14))
        .draw()?;
    // The Pareto front: the points no other point beats on both error and speed, joined from
    // the most accurate to the fastest as a staircase (what is reachable: at least this fast
    // at this error or worse).
    let mut front: Vec<(f64, f64)> = points
        .iter()
        .zip(&xs)
        .filter(|(p, x)| !points.iter().zip(&xs).any(|(q, y)| *y <= **x && q.2 >= p.2 && (*y < **x || q.2 > p.2)))
        .map(|(p, &x)| (x, p.2))
        .collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut stairs = Vec::new();
    for (i, &(x, y)) in front.iter().enumerate() {
        if i > 0 {
            stairs.push((x, front[i - 1].1));
        }
        stairs.push((x, y));
    }
    let red = RGBColor(200, 40, 40);
    chart
        .draw_series(LineSeries::new(stairs, red.stroke_width(2)))?
        .label("Pareto front (no method both more accurate and faster)")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], red.stroke_width(2)));
    chart.draw_series(front.iter().map(|&(x, y)| Circle::new((x, y), 10, red.stroke_width(2))))?;
    chart.draw_series(points.iter().zip(&xs).map(|(p, &x)| Circle::new((x, p.2), 6, BLUE.filled())))?;
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .draw()?;
    // Labels above their points, every second one below, so that neighbours do not overlap.
    chart.draw_series(points.iter().zip(&xs).enumerate().map(|(i, (p, &x))| {
        let dy = if i % 2 == 0 { 0.03 } else { -0.07 };
        Text::new(p.0.clone(), (x, p.2 + ymax * dy), ("sans-serif", 14))
    }))?;
    root.present()?;
    Ok(())
}

/// `sphere_tests.png` (Mrays/s against the far camera's p99.9 t error) and `tessellation.png`
/// (Mrays/s against silhouette error, memory in the labels).
pub fn charts(dir: &Path, r: &SphereReport) -> anyhow::Result<()> {
    if !crate::report::ensure_font() {
        anyhow::bail!("no DejaVu font found for chart labels (apt-get install fonts-dejavu-core)");
    }
    scatter(
        &dir.join("sphere_tests.png"),
        "Sphere tests: speed against accuracy (camera 1000× farther)",
        "relative t error, 99.9th percentile (log; left is better)",
        r.methods
            .iter()
            .map(|m| (format!("{} ({:.2}% wrong hit/miss)", m.test, m.far_wrong * 100.0), m.far_t_error[1], m.mrays))
            .collect(),
    )?;
    scatter(
        &dir.join("tessellation.png"),
        "Analytic sphereflake against its tessellations (level 3)",
        "silhouette error: rays hit/missed wrongly (log; left is better)",
        r.tessellations
            .iter()
            .map(|t| {
                let mem = if t.bytes < 1_000_000 {
                    format!("{:.0} kB", t.bytes as f64 / 1e3)
                } else {
                    format!("{:.1} MB", t.bytes as f64 / 1e6)
                };
                let zero = if t.silhouette_error == 0.0 { ", none wrong: drawn at 1e-7" } else { "" };
                (format!("{} ({mem}{zero})", t.model), t.silhouette_error.max(1e-7), t.mrays)
            })
            .collect(),
    )?;
    Ok(())
}
