//! `compare --torus` (issue 30): the torus's quartic solvers side by side, speed against
//! accuracy. One ring torus (major radius 1, tube 0.25, about the y axis) as a strahl solid,
//! built once per [`QuarticSolver`]; camera rays from near and from 1000× farther, and rays
//! aimed 1e-4 and 1e-6 of the tube's radius inside and outside its silhouettes. The reference
//! is independent of every quartic: sphere tracing the torus's exact distance function
//! `|(√(x² + z²) − R, y)| − r` in float64 (1-Lipschitz, so no crossing is stepped over), then
//! marching inside to the exit; rays that pass within 1e-8 r of the surface or cross a chord
//! shorter than 3e-4 r (a penetration of about 1e-8 r) are ties, counted apart. Stress sets
//! (`stress`) try to break the solvers: thin tubes, rays tangent to the inner and outer
//! equator (near-double roots), a camera 10⁵ times farther.

use std::path::Path;

use anyhow::Context;
use glam::{DVec2, DVec3, Vec3};
use serde::{Deserialize, Serialize};
use strahl::{
    BuildConfig, Camera, Coherence, HitStream, Primitive, QuarticSolver, Query, Ray, RayStream, Scene, Solid, raygen,
};

use crate::spheres::{interleaved_mrays, rel_quantiles, scatter};

/// The torus of the speed comparison: major radius 1, tube 0.25.
const TORUS: Torus = Torus { major: 1.0, minor: 0.25 };

/// A ring torus about the y axis, for the float64 reference.
#[derive(Clone, Copy, Debug)]
struct Torus {
    major: f64,
    minor: f64,
}

/// One solver's row.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SolverRow {
    pub solver: String,
    /// Median Mrays/s of the near camera's coherent stream.
    pub mrays: f64,
    /// Relative t error (p50, p99.9, max) against the reference, rays both hit (ties apart).
    pub near_t_error: [f64; 3],
    pub far_t_error: [f64; 3],
    /// Share of rays hit or missed wrongly (ties apart).
    pub near_wrong: f64,
    pub far_wrong: f64,
    pub silhouette_wrong: f64,
}

/// The whole run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TorusReport {
    #[serde(flatten)]
    pub run: crate::report::RunInfo,
    /// Rays per set that were ties (near, far, silhouette).
    pub ties: [usize; 3],
    pub silhouette_rays: usize,
    pub rows: Vec<SolverRow>,
    /// Ray sets built to break a solver (thin tubes, near-double roots, a far camera); absent
    /// in reports written before they were added.
    #[serde(default)]
    pub stress: Vec<StressRow>,
}

/// One stress set: every solver's wrong share and t error on the same rays.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StressRow {
    /// Tube radius over major radius.
    pub minor_over_major: f64,
    /// What the rays do.
    pub set: String,
    pub rays: usize,
    /// Rays that pass within 1e-8 r of the surface or cross a chord shorter than 3e-4 r.
    pub ties: usize,
    /// Per solver, in `QuarticSolver::ALL` order: (name, wrong share, t error p50 / p99.9 / max).
    pub solvers: Vec<(String, f64, [f64; 3])>,
}

impl Torus {
    fn sdf(self, p: DVec3) -> f64 {
        DVec2::new((p.x * p.x + p.z * p.z).sqrt() - self.major, p.y).length() - self.minor
    }

    /// The reference first crossing of `ray` (its `t`), and whether the ray is a tie.
    fn truth(self, ray: &Ray) -> (Option<f64>, bool) {
        truth(self, ray)
    }

    fn solid(self) -> Solid {
        Solid::new(Primitive::Torus { major: self.major as f32, minor: self.minor as f32 })
    }
}

/// [`Torus::truth`].
fn truth(torus: Torus, ray: &Ray) -> (Option<f64>, bool) {
    let Torus { major, minor } = torus;
    let sdf = |p: DVec3| torus.sdf(p);
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    let len = d.length();
    let u = d / len;
    let rb = major + minor + 1e-6;
    let b = o.dot(u);
    let disc = rb * rb - (o - b * u).length_squared();
    if disc <= 0.0 {
        return (None, false);
    }
    let (s0, s1) = ((-b - disc.sqrt()).max(ray.tnear.max(0.0) as f64 * len), -b + disc.sqrt());
    let smax = s1.min(ray.tfar as f64 * len);
    // Points far from the origin carry absolute rounding of |o|·ε: the surface is reached within
    // that, and every step moves at least that far (else far rays stall on rounding noise).
    let eps = 1e-13 * (1.0 + o.length());
    let mut s = s0;
    let mut closest = f64::INFINITY;
    for _ in 0..20_000_000 {
        if s > smax {
            return (None, closest < 1e-8 * minor);
        }
        let f = sdf(o + s * u);
        if f < eps {
            // At the surface: cross it, then march inside to the exit to measure the chord.
            let (mut e, mut inside) = (s, false);
            for _ in 0..20_000_000 {
                let g = sdf(o + e * u);
                inside |= g < 0.0;
                if (inside && g > 0.0) || e > s1 {
                    break;
                }
                e += g.abs().max(eps);
            }
            return (Some(s / len), e - s < 3e-4 * minor);
        }
        closest = closest.min(f);
        s += f.max(eps);
    }
    (None, true)
}

/// `(t error quantiles, wrong share, ties)` of `hits` against the reference over `rays`.
fn against_truth(pool: &rayon::ThreadPool, torus: Torus, rays: &RayStream, hits: &HitStream) -> ([f64; 3], f64, usize) {
    use rayon::prelude::*;
    let per: Vec<(Option<f64>, bool, bool)> = pool.install(|| {
        (0..rays.len())
            .into_par_iter()
            .map(|i| {
                let r = rays.get(i);
                let (t, tie) = torus.truth(&r);
                let got = hits.get(i);
                let wrong = !tie && t.is_some() != got.is_some();
                let err = match (t, got) {
                    (Some(t), Some(h)) if !tie => Some(((h.t as f64) - t).abs() / t),
                    _ => None,
                };
                (err, wrong, tie)
            })
            .collect()
    });
    let errs: Vec<f64> = per.iter().filter_map(|p| p.0).collect();
    let wrong = per.iter().filter(|p| p.1).count() as f64 / rays.len().max(1) as f64;
    (rel_quantiles(errs), wrong, per.iter().filter(|p| p.2).count())
}

fn eye() -> Vec3 {
    Vec3::new(0.0, 2.0, -3.4)
}

/// Rays from the near eye aimed 1e-4 r and 1e-6 r inside and outside the torus's silhouettes: for each of
/// `n` angles about the axis, the tube angles where the surface turns from the eye (found by
/// bisection on `n · (p − eye)`), the aim point moved along the normal.
fn silhouette_rays(n: usize) -> RayStream {
    let Torus { major, minor } = TORUS;
    let e = eye().as_dvec3();
    let at = |th: f64, ph: f64| {
        let (c, s) = (th.cos(), th.sin());
        let nrm = DVec3::new(ph.cos() * c, ph.sin(), ph.cos() * s);
        let p = DVec3::new((major + minor * ph.cos()) * c, minor * ph.sin(), (major + minor * ph.cos()) * s);
        (p, nrm)
    };
    let g = |th: f64, ph: f64| {
        let (p, nrm) = at(th, ph);
        nrm.dot(p - e)
    };
    let mut out = RayStream::default();
    for k in 0..n {
        let th = k as f64 * std::f64::consts::TAU / n as f64;
        let steps = 64;
        for j in 0..steps {
            let (mut a, mut b) = (
                j as f64 * std::f64::consts::TAU / steps as f64,
                (j + 1) as f64 * std::f64::consts::TAU / steps as f64,
            );
            if g(th, a).signum() == g(th, b).signum() {
                continue;
            }
            for _ in 0..60 {
                let m = 0.5 * (a + b);
                if g(th, m).signum() == g(th, a).signum() {
                    a = m;
                } else {
                    b = m;
                }
            }
            let (p, nrm) = at(th, 0.5 * (a + b));
            for side in [-1e-4, 1e-4, -1e-6, 1e-6] {
                let target = p + nrm * (side * minor);
                out.push(&Ray::new(eye(), (target - e).as_vec3()));
            }
        }
    }
    out
}

/// Runs the comparison and writes `torus.md`, `torus.json` and `torus_solvers.png` into `out`.
pub fn run(width: usize, passes: usize, pool: &rayon::ThreadPool, out: &Path) -> anyhow::Result<TorusReport> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let scenes = solver_scenes(TORUS)?;
    let w = width.min(512) as u32;
    let near_cam = Camera::look_at(eye(), Vec3::ZERO, Vec3::Y, 50.0);
    let k = 1000.0;
    let fov = 2.0 * ((25f32.to_radians()).tan() / k).atan();
    let far_cam = Camera::look_at(eye() * k, Vec3::ZERO, Vec3::Y, fov.to_degrees());
    let (near, _) = raygen::primary(&near_cam, w, w);
    let (far, _) = raygen::primary(&far_cam, w, w);
    let sil = silhouette_rays(720);
    let (speeds, near_hits) = interleaved_mrays(pool, &scenes, &near, passes);
    let mut rows = Vec::new();
    let mut ties = [0; 3];
    for (i, solver) in QuarticSolver::ALL.into_iter().enumerate() {
        let (near_t_error, near_wrong, t0) = against_truth(pool, TORUS, &near, &near_hits[i]);
        let mut hits = HitStream::default();
        pool.install(|| scenes[i].intersect_stream_par(&far, &mut hits, Coherence::Coherent));
        let (far_t_error, far_wrong, t1) = against_truth(pool, TORUS, &far, &hits);
        pool.install(|| scenes[i].intersect_stream_par(&sil, &mut hits, Coherence::Incoherent));
        let (_, silhouette_wrong, t2) = against_truth(pool, TORUS, &sil, &hits);
        ties = [t0, t1, t2];
        rows.push(SolverRow {
            solver: solver.name().to_string(),
            mrays: speeds[i],
            near_t_error,
            far_t_error,
            near_wrong,
            far_wrong,
            silhouette_wrong,
        });
    }
    let report = TorusReport {
        run: crate::report::RunInfo::now(pool.current_num_threads(), w as usize, passes),
        ties,
        silhouette_rays: sil.len(),
        rows,
        stress: stress(pool)?,
    };
    std::fs::write(out.join("torus.json"), serde_json::to_string_pretty(&report)?)?;
    std::fs::write(out.join("torus.md"), markdown(&report))?;
    chart(out, &report)?;
    Ok(report)
}

/// One scene of `torus` per quartic solver, in `QuarticSolver::ALL` order.
fn solver_scenes(torus: Torus) -> anyhow::Result<Vec<Scene>> {
    QuarticSolver::ALL
        .iter()
        .map(|&quartic_solver| {
            let cfg = BuildConfig { quartic_solver, ..BuildConfig::default() };
            Ok(Scene::build_with_solids(vec![], vec![], vec![torus.solid()], &cfg)?)
        })
        .collect()
}

/// Rays in the equatorial plane (and `lift · r` above it), one per angle of `n` about the axis,
/// each tangent to the circle of radius `rho` about the axis, starting `4 (R + r)` before the
/// tangent point: at `rho = R − r` the line touches the tube's inner equator (a double root
/// between the first and the last), at `rho = R + r` its outer equator (a double first root).
fn tangent_rays(torus: Torus, rho: &[f64], lift: f64, n: usize) -> RayStream {
    let mut out = RayStream::default();
    for k in 0..n {
        let a = k as f64 * std::f64::consts::TAU / n as f64 + 0.1;
        let (c, s) = (a.cos(), a.sin());
        for &r in rho {
            let p = DVec3::new(r * c, lift * torus.minor, r * s);
            let t = DVec3::new(-s, 0.0, c);
            let o = p - t * 4.0 * (torus.major + torus.minor);
            out.push(&Ray::new(o.as_vec3(), t.as_vec3()));
        }
    }
    out
}

/// The stress sets: tubes of 1/4, 1/100 and 1/1000 of the major radius, each with rays tangent
/// to the inner and the outer equator (offsets 0, ±1e-4 r and ±1e-6 r, in the plane and 1e-3 r
/// above it) and a camera 10⁵ times farther than the near one.
fn stress(pool: &rayon::ThreadPool) -> anyhow::Result<Vec<StressRow>> {
    let mut rows = Vec::new();
    for ratio in [0.25, 0.01, 0.001] {
        let torus = Torus { major: 1.0, minor: ratio };
        let scenes = solver_scenes(torus)?;
        let offsets = [0.0, 1e-4, -1e-4, 1e-6, -1e-6];
        let around = |rho: f64| offsets.iter().map(|o| rho + o * torus.minor).collect::<Vec<_>>();
        let mut inner = tangent_rays(torus, &around(torus.major - torus.minor), 0.0, 720);
        let mut outer = tangent_rays(torus, &around(torus.major + torus.minor), 0.0, 720);
        for (set, rho) in [(&mut inner, torus.major - torus.minor), (&mut outer, torus.major + torus.minor)] {
            let lifted = tangent_rays(torus, &around(rho), 1e-3, 720);
            for i in 0..lifted.len() {
                set.push(&lifted.get(i));
            }
        }
        let k = 1e5;
        let fov = 2.0 * ((25f32.to_radians()).tan() / k).atan();
        let cam = Camera::look_at(eye() * k, Vec3::ZERO, Vec3::Y, fov.to_degrees());
        let (far, _) = raygen::primary(&cam, 256, 256);
        for (set, rays, coherence) in [
            ("tangent to the inner equator", &inner, Coherence::Incoherent),
            ("tangent to the outer equator", &outer, Coherence::Incoherent),
            ("camera 10^5 times farther", &far, Coherence::Coherent),
        ] {
            let mut solvers = Vec::new();
            let mut ties = 0;
            for (scene, solver) in scenes.iter().zip(QuarticSolver::ALL) {
                let mut hits = HitStream::default();
                pool.install(|| scene.intersect_stream_par(rays, &mut hits, coherence));
                let (err, wrong, t) = against_truth(pool, torus, rays, &hits);
                ties = t;
                solvers.push((solver.name().to_string(), wrong, err));
            }
            rows.push(StressRow { minor_over_major: ratio, set: set.to_string(), rays: rays.len(), ties, solvers });
        }
    }
    Ok(rows)
}

/// `torus_solvers.png` from a report.
pub fn chart(out: &Path, report: &TorusReport) -> anyhow::Result<()> {
    if !crate::report::ensure_font() {
        anyhow::bail!("no DejaVu font found for chart labels (apt-get install fonts-dejavu-core)");
    }
    scatter(
        &out.join("torus_solvers.png"),
        "Torus quartic solvers: speed against accuracy (camera 1000× farther)",
        "relative t error, 99.9th percentile (log; left is better)",
        report
            .rows
            .iter()
            .map(|r| {
                let wrong = (r.far_wrong + r.silhouette_wrong) * 100.0;
                (format!("{} ({wrong:.2}% wrong far + silhouette)", r.solver), r.far_t_error[1], r.mrays)
            })
            .collect(),
    )
}

/// The report as Markdown.
pub fn markdown(r: &TorusReport) -> String {
    let mut s = format!(
        "Torus solvers ({}; {} silhouette-aimed rays). Ties apart: near {}, far {}, silhouette {}.\n\n",
        r.run.line(),
        r.silhouette_rays,
        r.ties[0],
        r.ties[1],
        r.ties[2]
    );
    s.push_str("| solver | Mrays/s (near) | t error near p50 / p99.9 / max | far p50 / p99.9 / max | wrong near | wrong far | wrong at silhouettes |\n");
    s.push_str("|---|---:|---|---|---:|---:|---:|\n");
    for row in &r.rows {
        let q = |e: [f64; 3]| format!("{:.1e} / {:.1e} / {:.1e}", e[0], e[1], e[2]);
        s.push_str(&format!(
            "| {} | {:.1} | {} | {} | {:.4}% | {:.4}% | {:.3}% |\n",
            row.solver,
            row.mrays,
            q(row.near_t_error),
            q(row.far_t_error),
            100.0 * row.near_wrong,
            100.0 * row.far_wrong,
            100.0 * row.silhouette_wrong
        ));
    }
    if let Some(first) = r.stress.first() {
        s.push_str("\nStress sets: rays built to break a solver. Per solver: wrong hit/miss share, t error p99.9 / max (ties apart).\n\n| r / R | set | rays | ties |");
        for (name, ..) in &first.solvers {
            s.push_str(&format!(" {name} |"));
        }
        s.push_str("\n|---:|---|---:|---:|");
        s.push_str(&"---|".repeat(first.solvers.len()));
        s.push('\n');
        for row in &r.stress {
            s.push_str(&format!("| {} | {} | {} | {} |", row.minor_over_major, row.set, row.rays, row.ties));
            for (_, wrong, e) in &row.solvers {
                s.push_str(&format!(" {:.3}%, {:.1e} / {:.1e} |", 100.0 * wrong, e[1], e[2]));
            }
            s.push('\n');
        }
    }
    s
}
