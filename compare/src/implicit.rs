//! `compare --implicit` (issue 30): root finding on implicit shapes, speed against accuracy.
//! strahl's interval root isolation (guaranteed: no crossing further than 1e-9 of the shape's
//! size from its neighbour is skipped) against the classic marcher — the field sampled at `N`
//! even steps along the chord through the bounds, the first change of sign refined by
//! bisection — for `N` = 8 to 512, and against strahl's sphere tracing of the same field given
//! as a user [`strahl::Implicit`] with a Lipschitz bound (where the field has one), on a pinched
//! superellipsoid (thin tips), a rounded box, a ratioquadric star and a blob with a thin neck. Camera rays, and grazing rays: tangent to the surface at random
//! points, moved 1e-3 and 1e-5 of the shape's size inside and outside (inside ones cross a
//! thin cap, which a marcher steps over). The reference marches 4096 steps; where a method
//! disagrees with it, 2²⁰ steps decide (resolving features down to 1e-6 of the chord), and an
//! earlier crossing a method reports counts as real where the field changes sign within 2e-6
//! of it (a chord thinner than the reference resolves). Every method reports `t` in float32.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use strahl::shapes::PreparedSolid;
use strahl::{Blob, BlobComponent, Camera, Primitive, QuarticSolver, Ray, RayStream, Solid, raygen};

use crate::spheres::scatter;

/// One method on one shape.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MethodRow {
    pub shape: String,
    pub method: String,
    /// Median Mrays/s over the camera rays (2 threads, interleaved passes).
    pub mrays: f64,
    /// Share of camera rays hit or missed wrongly.
    pub camera_wrong: f64,
    /// Share of grazing rays hit or missed wrongly.
    pub grazing_wrong: f64,
    /// Relative t error against the reference (p50, p99.9, max), rays both hit.
    pub t_error: [f64; 3],
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ImplicitReport {
    #[serde(flatten)]
    pub run: crate::report::RunInfo,
    pub grazing_rays: usize,
    pub rows: Vec<MethodRow>,
}

/// The shapes: name and primitive (each about unit size at the origin).
fn shapes() -> Vec<(&'static str, Primitive)> {
    let c =
        |x: f32, y: f32, radius: f32, strength: f32| BlobComponent { center: Vec3::new(x, y, 0.0), radius, strength };
    // Two balls joined by a neck a little above the threshold, and a carving ball.
    let blob = Blob::new(
        0.5,
        strahl::Potential::Pov,
        vec![c(-0.55, 0.0, 0.75, 1.0), c(0.55, 0.0, 0.75, 1.0), c(0.0, 0.0, 0.45, 0.6), c(0.0, 0.5, 0.4, -1.0)],
    );
    vec![
        ("pinched superellipsoid e = n = 3", Primitive::Superellipsoid { e: 3.0, n: 3.0 }),
        ("rounded box e = n = 0.2", Primitive::Superellipsoid { e: 0.2, n: 0.2 }),
        // Blanc & Schlick's star: thin tips like the pinched superellipsoid's, but smooth ones.
        ("ratioquadric star p = q = r = 0.05", Primitive::Ratioquadric { p: 0.05, q: 0.05, r: 0.05 }),
        ("blob with a neck", Primitive::Blob(Arc::new(blob))),
    ]
}

/// The classic marcher: `steps` even samples of the field along the chord through `bounds`,
/// the first sign change refined by 60 bisections. The ray's `t` of the first crossing.
fn march(prim: &Primitive, bounds: (DVec3, DVec3), ray: &Ray, steps: usize) -> Option<f64> {
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    let (mut t0, mut t1) = (ray.tnear.max(0.0) as f64, ray.tfar as f64);
    for k in 0..3 {
        if d[k] == 0.0 {
            if o[k] < bounds.0[k] || o[k] > bounds.1[k] {
                return None;
            }
            continue;
        }
        let (a, b) = ((bounds.0[k] - o[k]) / d[k], (bounds.1[k] - o[k]) / d[k]);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    if t0 >= t1 {
        return None;
    }
    let f = |t: f64| prim.field(o + t * d);
    let h = (t1 - t0) / steps as f64;
    let (mut a, mut fa) = (t0, f(t0));
    if fa <= 0.0 {
        return Some(t0);
    }
    for i in 1..=steps {
        let b = t0 + h * i as f64;
        let fb = f(b);
        if fb <= 0.0 {
            let (mut lo, mut hi) = (a, b);
            for _ in 0..60 {
                let m = 0.5 * (lo + hi);
                if f(m) <= 0.0 { hi = m } else { lo = m }
            }
            return Some(hi);
        }
        (a, fa) = (b, fb);
    }
    let _ = fa;
    None
}

/// A Lipschitz bound of the shape's field, where it has one: the rounded box's field is a
/// 10-norm minus 1 (bound 1: every p-norm with p ≥ 2 is), the POV-Ray blob's is the threshold
/// minus `Σ s (1 − r²/R²)²`, whose slope along r peaks at `8 / (3√3 R)` per unit strength. The
/// pinched superellipsoid has none (its slope is infinite at the cusps), so sphere tracing
/// cannot be applied to it; the ratioquadric's is finite but not derived here.
fn lipschitz(prim: &Primitive) -> Option<f64> {
    match prim {
        Primitive::Superellipsoid { e, n } if *e <= 1.0 && *n <= 1.0 => Some(1.0),
        Primitive::Blob(b) if b.potential() == strahl::Potential::Pov => Some(
            b.components().iter().map(|c| c.strength.abs() as f64 * 8.0 / (3.0 * 3f64.sqrt() * c.radius as f64)).sum(),
        ),
        _ => None,
    }
}

/// A method: strahl's isolation, strahl's sphere tracing of the same field given as a user
/// [`strahl::Implicit`] with its Lipschitz bound, or the marcher with `N` steps.
#[derive(Clone, Copy, PartialEq)]
enum Method {
    Interval,
    SphereTrace,
    March(usize),
}

impl Method {
    fn name(self) -> String {
        match self {
            Method::Interval => "strahl interval isolation".into(),
            Method::SphereTrace => "strahl sphere tracing (Lipschitz)".into(),
            Method::March(n) => format!("march {n} + bisection"),
        }
    }

    /// `traced`: the field as a user implicit surface, for sphere tracing.
    fn trace(
        self,
        prim: &Primitive,
        solid: &PreparedSolid,
        traced: Option<&PreparedSolid>,
        bounds: (DVec3, DVec3),
        ray: &Ray,
    ) -> Option<f64> {
        match self {
            Method::Interval => solid.intersect(ray).map(|h| h.0 as f64),
            Method::SphereTrace => traced.and_then(|s| s.intersect(ray)).map(|h| h.0 as f64),
            // Hits report t in float32, as strahl's do.
            Method::March(n) => march(prim, bounds, ray, n).map(|t| t as f32 as f64),
        }
    }
}

/// Grazing rays: for random directions from the centre, the surface point there (bisection
/// along the direction: the shapes are star-shaped about their centres), a tangent direction,
/// and rays along it moved `±1e-3` and `±1e-5` of the size along the normal.
fn grazing_rays(prim: &Primitive, n: usize, seed: u64) -> RayStream {
    let mut s = seed;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut out = RayStream::default();
    let grad = |p: DVec3| {
        let h = 1e-7;
        DVec3::new(
            prim.field(p + DVec3::X * h) - prim.field(p - DVec3::X * h),
            prim.field(p + DVec3::Y * h) - prim.field(p - DVec3::Y * h),
            prim.field(p + DVec3::Z * h) - prim.field(p - DVec3::Z * h),
        )
        .normalize_or_zero()
    };
    while out.len() < n {
        let dir = DVec3::new(rnd(), rnd(), rnd()).normalize_or_zero();
        if dir == DVec3::ZERO || prim.field(DVec3::ZERO) > 0.0 {
            continue;
        }
        let (mut lo, mut hi) = (0.0, 3.0);
        for _ in 0..80 {
            let m = 0.5 * (lo + hi);
            if prim.field(dir * m) <= 0.0 { lo = m } else { hi = m }
        }
        let p = dir * lo;
        let nrm = grad(p);
        if nrm == DVec3::ZERO || !nrm.is_finite() {
            continue;
        }
        let tangent = nrm.cross(DVec3::new(rnd(), rnd(), rnd())).normalize_or_zero();
        if tangent == DVec3::ZERO {
            continue;
        }
        for off in [-1e-3, 1e-3, -1e-5, 1e-5] {
            let aim = p + nrm * off;
            let o = aim - tangent * 4.0;
            out.push(&Ray::new(o.as_vec3(), tangent.as_vec3()));
        }
    }
    out
}

/// The reference first crossing: 4096 steps, or 2²⁰ where `disputed`.
fn truth(prim: &Primitive, bounds: (DVec3, DVec3), ray: &Ray, disputed: bool) -> Option<f64> {
    march(prim, bounds, ray, if disputed { 1 << 20 } else { 4096 })
}

/// Whether the field changes sign within `2e-6·(1 + t)` of `t` along the ray (20,000 samples:
/// the float32 `t` of a hit lies that close to its crossing).
fn confirmed(prim: &Primitive, ray: &Ray, t: f64) -> bool {
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    let w = 2e-6 * (1.0 + t);
    let inside = |s: f64| prim.field(o + s * d) <= 0.0;
    let first = inside(t - w);
    (1..=20_000).any(|k| inside(t - w + 2.0 * w * k as f64 / 20_000.0) != first)
}

/// Whether a method's answer `got` disagrees with the reference `want` (hit against miss, or
/// another crossing: t apart by more than 1e-4 relative).
fn differs(got: Option<f64>, want: Option<f64>) -> bool {
    match (got, want) {
        (Some(a), Some(b)) => (a - b).abs() > 1e-4 * b.abs().max(1e-3),
        (a, b) => a.is_some() != b.is_some(),
    }
}

/// Runs the comparison and writes `implicit.md`, `implicit.json` and the two charts of
/// [`chart`].
pub fn run(width: usize, passes: usize, pool: &rayon::ThreadPool, out: &Path) -> anyhow::Result<ImplicitReport> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let w = width.min(256) as u32;
    let methods = [
        Method::Interval,
        Method::SphereTrace,
        Method::March(8),
        Method::March(32),
        Method::March(128),
        Method::March(512),
    ];
    let mut rows = Vec::new();
    let mut grazing_count = 0;
    for (name, prim) in shapes() {
        let solid = PreparedSolid::new(&Solid::new(prim.clone()), QuarticSolver::default())?;
        let (lo, hi) = solid.bounds();
        let bounds = (lo.as_dvec3(), hi.as_dvec3());
        let traced = match lipschitz(&prim) {
            Some(l) => {
                let field = prim.clone();
                let user = strahl::Implicit::new(move |p| field.field(p), l, lo, hi);
                let user = Solid::new(Primitive::Implicit(Arc::new(user)));
                Some(PreparedSolid::new(&user, QuarticSolver::default())?)
            }
            None => None,
        };
        let traced = traced.as_ref();
        let applies = |m: Method| m != Method::SphereTrace || traced.is_some();
        let cam = Camera::look_at(Vec3::new(1.6, 1.9, -3.2), Vec3::ZERO, Vec3::Y, 40.0);
        let (camera, _) = raygen::primary(&cam, w, w);
        let camera: Vec<Ray> = (0..camera.len()).map(|i| camera.get(i)).collect();
        let grazing = grazing_rays(&prim, 4000, 0x9e37_79b9);
        let grazing: Vec<Ray> = (0..grazing.len()).map(|i| grazing.get(i)).collect();
        grazing_count = grazing.len();
        // Speed: camera rays, methods interleaved pass by pass.
        let mut secs = vec![Vec::new(); methods.len()];
        for pass in 0..=passes {
            for k in 0..methods.len() {
                let i = (pass + k) % methods.len();
                if !applies(methods[i]) {
                    continue;
                }
                let t = Instant::now();
                let hits: usize = pool.install(|| {
                    camera.par_iter().filter(|r| methods[i].trace(&prim, &solid, traced, bounds, r).is_some()).count()
                });
                std::hint::black_box(hits);
                if pass > 0 {
                    secs[i].push(t.elapsed().as_secs_f64());
                }
            }
        }
        // Accuracy against the reference, disputed rays settled finely.
        let judge = |rays: &[Ray], m: Method| -> (f64, Vec<f64>) {
            let per: Vec<(bool, Option<f64>)> = pool.install(|| {
                rays.par_iter()
                    .map(|r| {
                        let got = m.trace(&prim, &solid, traced, bounds, r);
                        let mut want = truth(&prim, bounds, r, false);
                        if differs(got, want) {
                            want = truth(&prim, bounds, r, true);
                        }
                        // A crossing found before the reference's (or where it sees none) that
                        // the field confirms in float64 is real: a chord thinner than the
                        // reference's steps (measured: 1.3e-6 long, at the pinched shape's edge).
                        if let Some(t) = got
                            && differs(got, want)
                            && want.is_none_or(|w| t < w)
                            && confirmed(&prim, r, t)
                        {
                            want = Some(t);
                        }
                        let err = got.zip(want).map(|(a, b)| (a - b).abs() / b.abs().max(1e-3));
                        (differs(got, want), err)
                    })
                    .collect()
            });
            let wrong = per.iter().filter(|p| p.0).count() as f64 / rays.len().max(1) as f64;
            (wrong, per.iter().filter_map(|p| p.1).collect())
        };
        for (i, &m) in methods.iter().enumerate() {
            if !applies(m) {
                continue;
            }
            let (camera_wrong, mut errs) = judge(&camera, m);
            let (grazing_wrong, e2) = judge(&grazing, m);
            errs.extend(e2);
            let mut s = secs[i].clone();
            s.sort_by(f64::total_cmp);
            let median = s[s.len() / 2];
            rows.push(MethodRow {
                shape: name.to_string(),
                method: m.name(),
                mrays: camera.len() as f64 / median / 1e6,
                camera_wrong,
                grazing_wrong,
                t_error: crate::spheres::rel_quantiles(errs),
            });
        }
    }
    let report = ImplicitReport {
        run: crate::report::RunInfo::now(pool.current_num_threads(), w as usize, passes),
        grazing_rays: grazing_count,
        rows,
    };
    std::fs::write(out.join("implicit.json"), serde_json::to_string_pretty(&report)?)?;
    std::fs::write(out.join("implicit.md"), markdown(&report))?;
    chart(out, &report)?;
    Ok(report)
}

/// The charts from a report, one per family as the issue asks: `implicit_superquadrics.png`
/// (the superellipsoids) and `implicit_metaballs.png` (the blob); each point one method, its
/// figures over the family's shapes it applies to.
pub fn chart(out: &Path, report: &ImplicitReport) -> anyhow::Result<()> {
    if !crate::report::ensure_font() {
        anyhow::bail!("no DejaVu font found for chart labels (apt-get install fonts-dejavu-core)");
    }
    let is_blob = |shape: &str| shapes().iter().any(|(n, p)| *n == shape && matches!(p, Primitive::Blob(_)));
    for (file, title, blob) in [
        ("implicit_superquadrics.png", "Superquadrics: root finding, speed against accuracy", false),
        ("implicit_metaballs.png", "Metaballs: root finding, speed against accuracy", true),
    ] {
        let rows: Vec<&MethodRow> = report.rows.iter().filter(|r| is_blob(&r.shape) == blob).collect();
        let mut names: Vec<&str> = Vec::new();
        for r in &rows {
            if !names.contains(&r.method.as_str()) {
                names.push(&r.method);
            }
        }
        let shapes = rows.iter().map(|r| r.shape.as_str()).collect::<std::collections::BTreeSet<_>>().len();
        let points = names
            .iter()
            .map(|&name| {
                let mine: Vec<&&MethodRow> = rows.iter().filter(|r| r.method == name).collect();
                let wrong = mine.iter().map(|r| r.grazing_wrong).sum::<f64>() / mine.len() as f64;
                // The harmonic mean: the rate of tracing the same rays through each shape.
                let mrays = mine.len() as f64 / mine.iter().map(|r| 1.0 / r.mrays).sum::<f64>();
                let only = if mine.len() < shapes {
                    format!(", {} of {shapes} shapes: the ones given a Lipschitz bound", mine.len())
                } else {
                    String::new()
                };
                let label = if wrong == 0.0 {
                    format!("{name} (none wrong: drawn at 1e-5{only})")
                } else {
                    format!("{name} ({:.2}% wrong{only})", wrong * 100.0)
                };
                (label, wrong.max(1e-5), mrays)
            })
            .collect();
        let x = if shapes > 1 {
            format!("grazing rays hit or missed wrongly, mean over {shapes} shapes (log; left is better)")
        } else {
            "grazing rays hit or missed wrongly (log; left is better)".to_string()
        };
        scatter(&out.join(file), title, &x, points)?;
    }
    Ok(())
}

/// The report as Markdown.
pub fn markdown(r: &ImplicitReport) -> String {
    let mut s = format!("Implicit shapes ({}; {} grazing rays a shape).\n\n", r.run.line(), r.grazing_rays);
    s.push_str("| shape | method | Mrays/s | wrong (camera) | wrong (grazing) | t error p50 / p99.9 / max |\n");
    s.push_str("|---|---|---:|---:|---:|---|\n");
    for row in &r.rows {
        s.push_str(&format!(
            "| {} | {} | {:.2} | {:.3}% | {:.2}% | {:.1e} / {:.1e} / {:.1e} |\n",
            row.shape,
            row.method,
            row.mrays,
            100.0 * row.camera_wrong,
            100.0 * row.grazing_wrong,
            row.t_error[0],
            row.t_error[1],
            row.t_error[2]
        ));
    }
    s
}
