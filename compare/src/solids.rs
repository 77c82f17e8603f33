//! `compare --solids` (issue 30): each solid family in kernel mode against Embree user geometry.
//!
//! - **Scenes**: per family, 512 solids of that family on a jittered 8×8×8 lattice, each turned
//!   and scaled unevenly at random (the seeds' ellipsoid: a canonical shape placed by an affine
//!   map), built as one flat strahl scene and as one flat Embree scene of
//!   `RTC_GEOMETRY_TYPE_USER` geometries (one per solid, as `embree::Scene::build_mixed` makes
//!   them) whose callbacks run strahl's own solid intersection
//!   ([`strahl::shapes::PreparedSolid`]). Both engines intersect each solid with the same code,
//!   so the figures isolate what the engines do around it: the BVH over the solids, its
//!   traversal, and the call per candidate solid (Embree's callback, strahl's inlined walk).
//!   `EMBREE_SOLIDS=one-geometry` (read by `main`) gives Embree the other layout a user might choose, all solids
//!   as the primitives of one user geometry (`embree::Scene::build_solid_set`); measured both
//!   ways, the two layouts trace within the run's noise of each other (PERFORMANCE.md).
//! - **Rays**: primary rays of a camera outside the lattice, shadow rays to a point light and
//!   diffuse bounces from the primary hits (strahl's stream answers, offset along the normal):
//!   kernel mode (`kernel.rs`), the three APIs of each engine, interleaved passes.
//! - **Agreement**: both engines run one intersection routine per solid, so they should agree on
//!   every ray up to which of two solids wins a tie; the report counts rays whose hit/miss
//!   differs and, among rays both hit, those whose solid or leaf differs or whose `t` differs
//!   by more than 1e-6 relative. The accuracy of each family's own routine against float64 is
//!   the business of `--torus` and `--implicit` (and the tests).
//! - **Output**: `solids.md`, `solids.json` and `solids.png` (the ratios as grouped bars).

use std::path::Path;
use std::sync::Arc;

use anyhow::Context;
use glam::{Affine3A, Quat, Vec3};
use serde::{Deserialize, Serialize};
use strahl::raygen::{self, Offset, Pcg32};
use strahl::shapes::PreparedSolid;
use strahl::{
    Blob, BlobComponent, BuildConfig, Camera, Coherence, HitStream, Potential, Primitive, Query, RayStream, Scene,
    Solid,
};

use crate::embree;
use crate::harness::{Class, quartiles};
use crate::kernel::{API_NAMES, ApiTimes, Timed};

/// Solids per side of the lattice.
const SIDE: usize = 8;

/// One family, one ray class.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SolidClass {
    pub class: String,
    pub rays: usize,
    /// Share of rays strahl hits.
    pub hit_rate: f64,
    pub apis: Vec<ApiTimes>,
    /// Each engine's fastest API (by median).
    pub strahl_best: String,
    pub embree_best: String,
    /// Embree's best over strahl's best, per pass: quartiles (above 1: strahl faster).
    pub best_ratio_quartiles: [f64; 3],
    /// Rays whose hit or miss differs between the engines.
    pub hit_miss_differ: usize,
    /// Among rays both hit (closest hit): another solid or leaf, or `t` apart by more than
    /// 1e-6 relative.
    pub key_differ: usize,
    pub t_differ: usize,
}

/// One family's scene and classes.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SolidFamily {
    pub family: String,
    pub solids: usize,
    /// Least of three interleaved builds.
    pub strahl_build_ms: f64,
    pub embree_build_ms: f64,
    pub classes: Vec<SolidClass>,
}

/// The whole run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SolidsReport {
    #[serde(flatten)]
    pub run: crate::report::RunInfo,
    /// Embree's layout of the solids: `per-solid` (one user geometry each) or `one-geometry`.
    #[serde(default)]
    pub embree_layout: String,
    pub families: Vec<SolidFamily>,
}

/// The canonical solid of each family (before its placement).
fn families() -> Vec<(&'static str, Solid)> {
    let s = Solid::new;
    let at = |p: Vec3| Affine3A::from_translation(p);
    let scaled = |k: f32, p: Vec3| Affine3A::from_scale_rotation_translation(Vec3::splat(k), Quat::IDENTITY, p);
    // A die: a cube rounded by a sphere, with pips carved into three faces.
    let pips = [
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(1.0, 0.4, 0.4),
        Vec3::new(1.0, -0.4, -0.4),
        Vec3::new(0.45, 0.45, 1.0),
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(-0.45, -0.45, 1.0),
    ];
    let die = Solid::difference(
        std::iter::once(Solid::intersection(vec![
            s(Primitive::Box),
            s(Primitive::Sphere).transformed(scaled(1.45, Vec3::ZERO)),
        ]))
        .chain(pips.iter().map(|&p| s(Primitive::Sphere).transformed(scaled(0.2, p))))
        .collect(),
    );
    let blob = Blob::new(
        0.4,
        Potential::Pov,
        [(-0.5, 0.0, 1.0), (0.5, 0.1, 1.0), (0.0, 0.7, 0.8), (0.0, -0.3, -0.4)]
            .into_iter()
            .map(|(x, y, strength)| BlobComponent { center: Vec3::new(x, y, 0.0), radius: 0.9, strength })
            .collect(),
    );
    vec![
        ("sphere", s(Primitive::Sphere)),
        ("box", s(Primitive::Box)),
        ("cylinder", s(Primitive::Cylinder).transformed(at(Vec3::new(0.0, 0.0, -0.5)))),
        ("cone", s(Primitive::Cone { r0: 1.0, r1: 0.2 }).transformed(at(Vec3::new(0.0, 0.0, -0.5)))),
        ("torus", s(Primitive::Torus { major: 0.75, minor: 0.25 })),
        (
            "quadric ∩ box",
            Solid::intersection(vec![
                s(Primitive::Quadric { coeffs: [1.0, -1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.2] }),
                s(Primitive::Box),
            ]),
        ),
        ("superellipsoid", s(Primitive::Superellipsoid { e: 0.3, n: 0.6 })),
        ("supertoroid", s(Primitive::Supertoroid { major: 0.7, minor: 0.3, e: 0.4, n: 0.4 })),
        ("blob", s(Primitive::Blob(Arc::new(blob)))),
        ("CSG die", die),
    ]
}

/// 512 copies of `shape` on a jittered lattice of unit cells in `[0, 8]³`, each turned at
/// random and scaled to 0.25–0.45 of a cell per axis.
fn lattice(shape: &Solid, seed: u64) -> Vec<Solid> {
    let mut rng = Pcg32::new(seed, 30);
    let mut out = Vec::with_capacity(SIDE * SIDE * SIDE);
    for i in 0..SIDE * SIDE * SIDE {
        let cell = Vec3::new((i % SIDE) as f32, (i / SIDE % SIDE) as f32, (i / (SIDE * SIDE)) as f32);
        let mut r = || rng.next_f32();
        let jitter = Vec3::new(r(), r(), r()) * 0.2 - 0.1;
        let axis = raygen::uniform_direction(&mut rng);
        let angle = std::f32::consts::TAU * rng.next_f32();
        let mut r = || rng.next_f32();
        let scale = Vec3::new(r(), r(), r()) * 0.2 + 0.25;
        let m = Affine3A::from_scale_rotation_translation(
            scale,
            Quat::from_axis_angle(axis, angle),
            cell + Vec3::splat(0.5) + jitter,
        );
        out.push(shape.clone().transformed(m));
    }
    out
}

/// Runs the families named in `only` (all when empty; an unknown name is an error), Embree's
/// solids as the primitives of one user geometry if `one_geometry`, else one geometry each.
pub fn run(
    width: usize,
    passes: usize,
    only: &[String],
    one_geometry: bool,
    pool: &rayon::ThreadPool,
    out: &Path,
) -> anyhow::Result<SolidsReport> {
    let all = families();
    if let Some(bad) = only.iter().find(|o| !all.iter().any(|(n, _)| n == o)) {
        let names: Vec<&str> = all.iter().map(|(n, _)| *n).collect();
        anyhow::bail!("--families: no family {bad:?}; the families are {}", names.join(", "));
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let device = embree::Device::new(&format!("threads={}", pool.current_num_threads()))?;
    let w = width as u32;
    let camera = Camera::look_at(Vec3::new(13.0, 10.0, 16.0), Vec3::splat(4.0), Vec3::Y, 45.0);
    let light = Vec3::new(-6.0, 20.0, 10.0);
    let cfg = BuildConfig::default();
    let mut families_out = Vec::new();
    for (seed, (name, shape)) in all.into_iter().enumerate() {
        if !only.is_empty() && !only.iter().any(|o| o == name) {
            continue;
        }
        eprintln!("solids: {name}");
        let solids = lattice(&shape, seed as u64);
        let prepared =
            solids.iter().map(|s| PreparedSolid::new(s, cfg.quartic_solver)).collect::<strahl::Result<Vec<_>>>()?;
        let (mut strahl_build_ms, mut embree_build_ms) = (f64::INFINITY, f64::INFINITY);
        let (mut scene, mut escene) = (None, None);
        for _ in 0..3 {
            let s = pool.install(|| Scene::build_with_solids(vec![], vec![], solids.clone(), &cfg))?;
            strahl_build_ms = strahl_build_ms.min(s.solid_stats().build_ms);
            scene = Some(s);
            let e = if one_geometry {
                embree::Scene::build_solid_set(&device, &prepared, embree::Quality::Medium)?
            } else {
                embree::Scene::build_mixed(&device, &[], &[], &prepared, embree::Quality::Medium, false)?
            };
            embree_build_ms = embree_build_ms.min(e.build_ms);
            escene = Some(e);
        }
        let (Some(scene), Some(escene)) = (scene, escene) else { unreachable!("three rounds ran") };
        let (primary, _) = raygen::primary(&camera, w, w);
        let mut hits = HitStream::default();
        pool.install(|| scene.intersect_stream_par(&primary, &mut hits, Coherence::Coherent));
        let (shadow, _) = raygen::shadow_with(&primary, &hits, light, Offset::Normal);
        let (diffuse, _) = raygen::diffuse_with(&primary, &hits, 7, Offset::Normal);
        let mut classes = Vec::new();
        for (class, rays) in [(Class::Primary, &primary), (Class::Shadow, &shadow), (Class::Diffuse, &diffuse)] {
            classes.push(solid_class(&scene, &escene, rays, class, passes, pool));
        }
        families_out.push(SolidFamily {
            family: name.to_string(),
            solids: solids.len(),
            strahl_build_ms,
            embree_build_ms,
            classes,
        });
    }
    let report = SolidsReport {
        run: crate::report::RunInfo::now(pool.current_num_threads(), width, passes),
        embree_layout: if one_geometry { "one-geometry" } else { "per-solid" }.to_string(),
        families: families_out,
    };
    std::fs::write(out.join("solids.json"), serde_json::to_string_pretty(&report)?)?;
    std::fs::write(out.join("solids.md"), markdown(&report))?;
    chart(out, &report)?;
    Ok(report)
}

/// `solids.png` from a report: the best-vs-best ratio per family and ray class.
pub fn chart(out: &Path, report: &SolidsReport) -> anyhow::Result<()> {
    let groups: Vec<(String, [Option<f64>; 3])> = report
        .families
        .iter()
        .map(|f| {
            let of = |cl: &str| f.classes.iter().find(|c| c.class == cl).map(|c| c.best_ratio_quartiles[1]);
            (f.family.clone(), [of("primary"), of("shadow"), of("diffuse")])
        })
        .collect();
    crate::report::class_bars(
        &out.join("solids.png"),
        &format!(
            "Solids: strahl / Embree user geometry (same solid code), best API vs best API ({} threads)",
            report.run.threads
        ),
        &groups,
    )
}

fn solid_class(
    scene: &Scene,
    escene: &embree::Scene,
    rays: &RayStream,
    class: Class,
    passes: usize,
    pool: &rayon::ThreadPool,
) -> SolidClass {
    let n = rays.len();
    let timed = Timed::run(scene, escene, rays, class, passes, pool);
    let [s, e] = &timed.answers;
    let (mut hit_miss_differ, mut key_differ, mut t_differ) = (0, 0, 0);
    for i in 0..n {
        if s.hit(i) != e.hit(i) {
            hit_miss_differ += 1;
        } else if s.hit(i) && !class.occlusion() {
            key_differ += (s.key(i) != e.key(i)) as usize;
            t_differ += ((s.t[i] - e.t[i]).abs() > 1e-6 * s.t[i].abs()) as usize;
        }
    }
    SolidClass {
        class: class.name().to_string(),
        rays: n,
        hit_rate: (0..n).filter(|&i| s.hit(i)).count() as f64 / n.max(1) as f64,
        apis: timed.apis(n),
        strahl_best: API_NAMES[timed.best(0)].to_string(),
        embree_best: API_NAMES[timed.best(1)].to_string(),
        best_ratio_quartiles: quartiles(&timed.best_ratios()),
        hit_miss_differ,
        key_differ,
        t_differ,
    }
}

/// The report as Markdown: one row per family and class.
pub fn markdown(r: &SolidsReport) -> String {
    let mut s = format!(
        "Solids in kernel mode against Embree user geometry running the same intersection code \
         ({}; Embree's layout: {}). Mrays/s of each engine's best API; the ratio is Embree's \
         time over strahl's per pass (median [quartiles]; above 1: strahl faster).\n\n",
        r.run.line(),
        r.embree_layout
    );
    s.push_str("| family | build ms strahl / Embree | class | rays | hit rate | strahl Mrays/s (API) | Embree Mrays/s (API) | best vs best | hit/miss differ | solid or t differ |\n");
    s.push_str("|---|---:|---|---:|---:|---:|---:|---|---:|---:|\n");
    for f in &r.families {
        for (k, c) in f.classes.iter().enumerate() {
            let best = |name: &str, strahl: bool| {
                let a = c.apis.iter().find(|a| a.api == name);
                let m = a.map_or(f64::NAN, |a| if strahl { a.strahl } else { a.embree });
                format!("{m:.2} ({name})")
            };
            let (fam, build) = if k == 0 {
                (format!("{} ({})", f.family, f.solids), format!("{:.1} / {:.1}", f.strahl_build_ms, f.embree_build_ms))
            } else {
                (String::new(), String::new())
            };
            let q = c.best_ratio_quartiles;
            s.push_str(&format!(
                "| {fam} | {build} | {} | {} | {:.1}% | {} | {} | **{:.2}** [{:.2}–{:.2}] | {} | {} / {} |\n",
                c.class,
                c.rays,
                100.0 * c.hit_rate,
                best(&c.strahl_best, true),
                best(&c.embree_best, false),
                q[1],
                q[0],
                q[2],
                c.hit_miss_differ,
                c.key_differ,
                c.t_differ
            ));
        }
    }
    s
}
