//! Results out: the terminal table, a Markdown report, the JSON file, the ratio chart and one shaded
//! picture per scene.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use serde::Serialize;

use crate::accuracy::{Case, Disagreements};
use crate::harness::{Api, BuildResult, ClassResult, Mode, SceneResult, quartiles};

#[derive(Serialize)]
pub struct Report {
    pub threads: usize,
    pub date: String,
    pub machine: String,
    pub strahl_commit: String,
    pub width: u32,
    pub passes: usize,
    pub scenes: Vec<SceneJson>,
    /// Geometric mean over flat scenes × classes of the best-vs-best ratio.
    pub geomean_best_ratio: f64,
    /// The same over instanced scenes × classes (`null` if none ran).
    pub geomean_best_ratio_instanced: Option<f64>,
    /// The flat scenes' geometric mean in as-called mode (both engines fed from one SoA stream).
    pub geomean_best_ratio_as_called: f64,
    /// The geometric mean of the per-class median pair ratios (kernel mode, best vs best).
    pub geomean_median_pair_ratio: f64,
    /// Instanced against flattened strahl with the world moved away from the origin.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub instancing_translations: Vec<crate::harness::TranslationRow>,
    /// Throughput, build time and memory against triangle count (with `--scaling`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub scaling: Vec<ScalingRow>,
    /// Every triangle test × box test against Embree's modes (with `--accuracy`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub accuracy: Option<crate::methods::AccuracyReport>,
}

#[derive(Serialize)]
pub struct SceneJson {
    pub name: String,
    pub triangles: usize,
    pub build: BuildResult,
    pub build_ratio: f64,
    /// strahl HIGH over Embree HIGH build time (NaN for instanced scenes).
    pub high_build_ratio: f64,
    pub instanced: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instances: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instanced_triangles: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub memory_bytes: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flattened_memory_bytes: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instancing: Option<crate::harness::InstancedInfo>,
    pub classes: Vec<ClassJson>,
}

#[derive(Serialize)]
pub struct Engines {
    pub strahl: Apis,
    pub embree: Apis,
}

#[derive(Serialize)]
pub struct Apis {
    pub single: f64,
    pub packet: f64,
    pub stream: f64,
}

/// Quartiles `[q1, median, q3]` of each API's speed ratio over the interleaved pass pairs.
#[derive(Serialize)]
pub struct ApisSpread {
    pub single: [f64; 3],
    pub packet: [f64; 3],
    pub stream: [f64; 3],
}

/// One timing mode's figures for a class.
#[derive(Serialize)]
pub struct ModeJson {
    pub mode: &'static str,
    pub mrays: Engines,
    pub mrays_median: Engines,
    /// Best pass over best pass, per API.
    pub ratio: Apis,
    /// Quartiles of the per-pass-pair ratios, per API.
    pub ratio_spread: ApisSpread,
    /// Best API's best pass over the other engine's.
    pub best_ratio: f64,
    /// Quartiles of the per-pass best-vs-best ratios; "faster" only where q1 > 1.
    pub best_ratio_spread: [f64; 3],
    pub best_api: (&'static str, &'static str),
}

fn mode_json(c: &ClassResult, mode: Mode) -> ModeJson {
    let apis = |e: usize, median: bool| Apis {
        single: c.mrays_in(mode, e, Api::Single, median),
        packet: c.mrays_in(mode, e, Api::Packet, median),
        stream: c.mrays_in(mode, e, Api::Stream, median),
    };
    let r = |a: Api| ratio(c.mrays_in(mode, 0, a, false), c.mrays_in(mode, 1, a, false));
    let q = |a: Api| quartiles(&c.pair_ratios(mode, a));
    ModeJson {
        mode: mode.name(),
        mrays: Engines { strahl: apis(0, false), embree: apis(1, false) },
        mrays_median: Engines { strahl: apis(0, true), embree: apis(1, true) },
        ratio: Apis { single: r(Api::Single), packet: r(Api::Packet), stream: r(Api::Stream) },
        ratio_spread: ApisSpread { single: q(Api::Single), packet: q(Api::Packet), stream: q(Api::Stream) },
        best_ratio: c.best_ratio_in(mode),
        best_ratio_spread: quartiles(&c.best_pair_ratios(mode)),
        best_api: (c.best_in(mode, 0).0.name(), c.best_in(mode, 1).0.name()),
    }
}

#[derive(Serialize)]
pub struct ClassJson {
    pub class: &'static str,
    pub rays: usize,
    pub hit_rate: f64,
    pub hit_miss_agreement: f64,
    pub prim_agreement: f64,
    pub t_rel_median: f64,
    pub t_rel_p999: f64,
    pub t_rel_max: f64,
    pub disagreements: Disagreements,
    pub worst: Vec<Case>,
    pub mrays: Engines,
    pub mrays_median: Engines,
    pub ratio: Apis,
    pub best_ratio: f64,
    pub best_api: (&'static str, &'static str),
    /// The mode of the figures above: always "kernel" (the headline).
    pub mode: &'static str,
    /// Quartiles of the kernel-mode best-vs-best pair ratios.
    pub best_ratio_spread: [f64; 3],
    /// Quartiles of the kernel-mode single-ray pair ratios.
    pub single_ratio_spread: [f64; 3],
    /// Both modes in full: `kernel` and `as_called`.
    pub modes: [ModeJson; 2],
    pub strahl_apis_consistent: f64,
    pub embree_apis_consistent: f64,
    /// Instanced scenes: strahl instanced against strahl flattened on the same rays (`null` where
    /// the flattened world was too large to build).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flat_agreement: Option<Option<crate::harness::FlatAgreement>>,
}

fn apis(c: &ClassResult, engine: usize, median: bool) -> Apis {
    Apis {
        single: c.mrays(engine, Api::Single, median),
        packet: c.mrays(engine, Api::Packet, median),
        stream: c.mrays(engine, Api::Stream, median),
    }
}

fn ratio(a: f64, b: f64) -> f64 {
    if b > 0.0 { a / b } else { 0.0 }
}

pub fn build_report(results: &[SceneResult], threads: usize, width: u32, passes: usize) -> Report {
    let mut logs = Vec::new();
    let mut logs_inst = Vec::new();
    let mut logs_called = Vec::new();
    let mut logs_median = Vec::new();
    let scenes = results
        .iter()
        .map(|r| SceneJson {
            name: r.name.clone(),
            triangles: r.triangles,
            build: r.build.clone(),
            build_ratio: ratio(r.build.strahl_ms, r.build.embree_ms),
            high_build_ratio: ratio(r.build.strahl_high_ms, r.build.embree_high_ms),
            instanced: r.instanced.is_some(),
            instances: r.instanced.as_ref().map(|i| i.instances),
            instanced_triangles: r.instanced.as_ref().map(|i| i.instanced_triangles),
            memory_bytes: r.instanced.as_ref().map(|i| i.memory_bytes),
            flattened_memory_bytes: r.instanced.as_ref().map(|i| i.flattened_memory_bytes),
            instancing: r.instanced.clone(),
            classes: r
                .classes
                .iter()
                .map(|c| {
                    let br = c.best_ratio();
                    let modes = [mode_json(c, Mode::Kernel), mode_json(c, Mode::AsCalled)];
                    if br > 0.0 {
                        if r.instanced.is_some() { &mut logs_inst } else { &mut logs }.push(br.ln());
                    }
                    if r.instanced.is_none() {
                        if modes[1].best_ratio > 0.0 {
                            logs_called.push(modes[1].best_ratio.ln());
                        }
                        if modes[0].best_ratio_spread[1] > 0.0 {
                            logs_median.push(modes[0].best_ratio_spread[1].ln());
                        }
                    }
                    ClassJson {
                        class: c.class.name(),
                        rays: c.rays,
                        hit_rate: c.hit_rate,
                        hit_miss_agreement: c.accuracy.hit_miss_agreement,
                        prim_agreement: c.accuracy.prim_agreement,
                        t_rel_median: c.accuracy.t_rel_median,
                        t_rel_p999: c.accuracy.t_rel_p999,
                        t_rel_max: c.accuracy.t_rel_max,
                        disagreements: c.accuracy.classified.clone(),
                        worst: c.accuracy.worst.clone(),
                        mrays: Engines { strahl: apis(c, 0, false), embree: apis(c, 1, false) },
                        mrays_median: Engines { strahl: apis(c, 0, true), embree: apis(c, 1, true) },
                        ratio: Apis {
                            single: ratio(c.mrays(0, Api::Single, false), c.mrays(1, Api::Single, false)),
                            packet: ratio(c.mrays(0, Api::Packet, false), c.mrays(1, Api::Packet, false)),
                            stream: ratio(c.mrays(0, Api::Stream, false), c.mrays(1, Api::Stream, false)),
                        },
                        best_ratio: br,
                        best_api: (c.best(0).0.name(), c.best(1).0.name()),
                        mode: Mode::Kernel.name(),
                        best_ratio_spread: modes[0].best_ratio_spread,
                        single_ratio_spread: modes[0].ratio_spread.single,
                        modes,
                        strahl_apis_consistent: c.strahl_apis_consistent,
                        embree_apis_consistent: c.embree_apis_consistent,
                        flat_agreement: r.instanced.as_ref().map(|_| c.flat_agreement.clone()),
                    }
                })
                .collect(),
        })
        .collect();
    let gm = |l: &[f64]| if l.is_empty() { 0.0 } else { (l.iter().sum::<f64>() / l.len() as f64).exp() };
    Report {
        threads,
        date: today(),
        machine: machine(),
        strahl_commit: commit(),
        width,
        passes,
        scenes,
        geomean_best_ratio: gm(&logs),
        geomean_best_ratio_instanced: (!logs_inst.is_empty()).then(|| gm(&logs_inst)),
        geomean_best_ratio_as_called: gm(&logs_called),
        geomean_median_pair_ratio: gm(&logs_median),
        instancing_translations: Vec::new(),
        scaling: Vec::new(),
        accuracy: None,
    }
}

/// Where and how a run of one of the shape reports (`--torus`, `--implicit`, `--solids`) was
/// made: flattened into each report's JSON, so the fields stay top-level keys.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct RunInfo {
    pub date: String,
    pub machine: String,
    pub commit: String,
    pub threads: usize,
    /// Camera rays per side.
    pub width: usize,
    pub passes: usize,
}

impl RunInfo {
    /// This run on `threads` threads.
    pub fn now(threads: usize, width: usize, passes: usize) -> Self {
        Self { date: today(), machine: machine(), commit: commit(), threads, width, passes }
    }

    /// `date; machine; commit C; N threads; W² camera rays, median of P interleaved passes`.
    pub fn line(&self) -> String {
        format!(
            "{}; {}; commit {}; {} threads; {}² camera rays, median of {} interleaved passes",
            self.date, self.machine, self.commit, self.threads, self.width, self.passes
        )
    }
}

pub(crate) fn today() -> String {
    std::process::Command::new("date")
        .arg("-u")
        .arg("+%Y-%m-%d %H:%M UTC")
        .output()
        .ok()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default()
}

/// The CPU as `/proc/cpuinfo` names it, with its CPUID family and model (virtual machines often
/// say only "AMD EPYC", which spans Zen 1 to Zen 5), the cores visible and strahl's kernel level.
pub(crate) fn machine() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let field = |key: &str| {
        info.lines()
            .find(|l| l.split(':').next().is_some_and(|k| k.trim() == key))
            .and_then(|l| l.split(':').nth(1))
            .map(|v| v.trim().to_string())
    };
    let mut cpu = field("model name").unwrap_or_else(|| "unknown CPU".into());
    if let (Some(family), Some(model)) = (field("cpu family"), field("model")) {
        cpu = format!("{cpu} (family {family}, model {model})");
    }
    let cores = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0);
    format!("{cpu}, {cores} cores visible, strahl kernels: {}", strahl::isa())
}

pub(crate) fn commit() -> String {
    std::process::Command::new("git")
        // This checkout's commit, wherever the harness is run from.
        .args(["-C", env!("CARGO_MANIFEST_DIR"), "rev-parse", "--short", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default()
}

fn pct(x: f64) -> String {
    format!("{:.4}%", x * 100.0)
}

/// The results as a Markdown document (also what the terminal shows).
pub fn markdown(r: &Report) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# strahl vs Embree 3.13.5\n");
    let _ = writeln!(
        s,
        "{} · {} · {} threads for both engines · {}×{} primary rays · best of {} passes · strahl {}\n",
        r.date, r.machine, r.threads, r.width, r.width, r.passes, r.strahl_commit
    );
    let inst = r.geomean_best_ratio_instanced.map_or("none ran".to_string(), |g| format!("**{g:.2}×**"));
    let _ = writeln!(
        s,
        "Kernel mode (each engine traces from its own native inputs, prepared before timing; only the query calls timed). \
         Geometric mean of best-vs-best ratios (strahl/Embree, best passes): **{:.2}×** over flat scenes (median pair ratios: {:.2}×), \
         {inst} over instanced scenes; as called (both fed from one SoA stream in the timed loop): {:.2}× over flat scenes\n",
        r.geomean_best_ratio, r.geomean_median_pair_ratio, r.geomean_best_ratio_as_called
    );
    let spread = |q: [f64; 3]| {
        let mark = if q[0] > 1.0 {
            " ▲"
        } else if q[2] < 1.0 {
            " ▼"
        } else {
            ""
        };
        format!("{:.2} [{:.2}–{:.2}]{mark}", q[1], q[0], q[2])
    };
    let _ = writeln!(s, "## Throughput (Mrays/s, best pass, kernel mode) and accuracy\n");
    let _ = writeln!(
        s,
        "Ratios: best pass over best pass, then the median and quartiles over the {} interleaved pass pairs \
         (▲ faster: lower quartile above 1; ▼ slower: upper quartile below 1).\n",
        r.passes
    );
    let _ = writeln!(
        s,
        "| scene | class | rays | hit rate | hit/miss agree | prim agree | t rel p99.9 | strahl single / packet / stream | Embree single / packet / stream | best ratio | pairs: median [q1–q3] | single: median [q1–q3] |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for sc in &r.scenes {
        for c in &sc.classes {
            let m = &c.mrays;
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.1}% | {} | {} | {:.1e} | {:.1} / {:.1} / {:.1} | {:.1} / {:.1} / {:.1} | **{:.2}×** ({} vs {}) | {} | {} |",
                sc.name,
                c.class,
                c.rays,
                c.hit_rate * 100.0,
                pct(c.hit_miss_agreement),
                pct(c.prim_agreement),
                c.t_rel_p999,
                m.strahl.single,
                m.strahl.packet,
                m.strahl.stream,
                m.embree.single,
                m.embree.packet,
                m.embree.stream,
                c.best_ratio,
                c.best_api.0,
                c.best_api.1,
                spread(c.best_ratio_spread),
                spread(c.single_ratio_spread),
            );
        }
    }
    let _ = writeln!(
        s,
        "\n## As called (Mrays/s, best pass): both engines fed from one SoA ray stream inside the timed loop\n"
    );
    let _ = writeln!(
        s,
        "| scene | class | strahl single / packet / stream | Embree single / packet / stream | best ratio | pairs: median [q1–q3] |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|---:|");
    for sc in &r.scenes {
        for c in &sc.classes {
            let a = &c.modes[1];
            let m = &a.mrays;
            let _ = writeln!(
                s,
                "| {} | {} | {:.1} / {:.1} / {:.1} | {:.1} / {:.1} / {:.1} | {:.2}× | {} |",
                sc.name,
                c.class,
                m.strahl.single,
                m.strahl.packet,
                m.strahl.stream,
                m.embree.single,
                m.embree.packet,
                m.embree.stream,
                a.best_ratio,
                spread(a.best_ratio_spread),
            );
        }
    }
    let _ = writeln!(s, "\n## Build (2 threads, best of interleaved rounds)\n");
    let _ = writeln!(
        s,
        "| scene | triangles | strahl ms | Embree MEDIUM ms | ratio | SAH strahl / Embree MEDIUM | strahl HIGH ms | Embree HIGH ms | HIGH ratio | SAH strahl HIGH / Embree HIGH | B/tri strahl / Embree (MEDIUM), strahl / Embree (HIGH) | nodes | leaves | depth |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let opt = |x: Option<f64>| x.map(|v| format!("{v:.1}")).unwrap_or_else(|| "–".into());
    // Instanced scenes have no flat SAH or HIGH build: NaN shows as a dash.
    let num = |x: f64| if x.is_finite() { format!("{x:.1}") } else { "–".into() };
    for sc in &r.scenes {
        let b = &sc.build;
        let _ = writeln!(
            s,
            "| {} | {} | {:.1} | {:.1} | {:.2}× | {} / {} | {} | {} | {} | {} / {} | {:.1} / {}, {} / {} | {} | {} | {} |",
            sc.name,
            sc.triangles,
            b.strahl_ms,
            b.embree_ms,
            sc.build_ratio,
            num(b.strahl_sah),
            opt(b.embree_sah),
            num(b.strahl_high_ms),
            num(b.embree_high_ms),
            if b.strahl_high_ms.is_finite() { format!("{:.2}×", sc.high_build_ratio) } else { "–".into() },
            num(b.strahl_high_sah),
            opt(b.embree_high_sah),
            b.strahl_bytes_per_tri,
            opt(b.embree_bytes_per_tri),
            num(b.strahl_high_bytes_per_tri),
            opt(b.embree_high_bytes_per_tri),
            b.strahl_inner_nodes,
            b.strahl_leaves,
            b.strahl_depth
        );
    }
    for sc in &r.scenes {
        let b = &sc.build;
        if let Some([medium, high]) = b.embree_all_triangles {
            let _ = writeln!(
                s,
                "\n{}: strahl leaves out {} of the {} triangles (zero area or non-finite corners: they can never \
                 be hit); Embree keeps them. Its SAH and bytes per triangle above are from a second pair of \
                 builds over the {} triangles strahl keeps; over all {} they are {:.2} and {:.1} (MEDIUM), \
                 {:.2} and {:.1} (HIGH). The build times are over all of them for both engines.",
                sc.name,
                b.strahl_skipped_triangles,
                sc.triangles,
                sc.triangles - b.strahl_skipped_triangles,
                sc.triangles,
                medium.sah,
                medium.bytes_per_tri,
                high.sah,
                high.bytes_per_tri
            );
        }
    }
    instancing_markdown(&mut s, r);
    scaling_markdown(&mut s, &r.scaling);
    let _ = writeln!(s, "\n## Disagreements, decided in float64\n");
    let _ = writeln!(
        s,
        "| scene | class | edge/vertex tie | depth tie | strahl error | Embree error | undecided | APIs consistent (strahl / Embree) |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|");
    for sc in &r.scenes {
        for c in &sc.classes {
            let d = &c.disagreements;
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {} | {} / {} |",
                sc.name,
                c.class,
                d.edge_or_vertex_tie,
                d.depth_tie,
                d.strahl_error,
                d.embree_error,
                d.undecided,
                pct(c.strahl_apis_consistent),
                pct(c.embree_apis_consistent)
            );
        }
    }
    if let Some(a) = &r.accuracy {
        let _ = writeln!(s, "\n## Methods: speed against accuracy\n");
        let _ = writeln!(
            s,
            "Leak test: {}. Closed meshes for edge/vertex-aimed rays: {}.\n",
            a.leak_test,
            a.closed_meshes.join(", ")
        );
        let _ = writeln!(
            s,
            "| method | box test | Mrays/s primary / shadow / diffuse | leak rate at offset 0 / 1e3 / 1e4 / 1e5 / 1e6 | edge zero-hit | edge double-hit | vertex zero-hit | t ulps median / p99.9 | agree Embree default / ROBUST | watertight |"
        );
        let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|---:|---|");
        let leaks = |m: &std::collections::BTreeMap<&str, f64>| {
            crate::methods::OFFSETS.iter().map(|o| format!("{:.2e}", m[o.0])).collect::<Vec<_>>().join(" / ")
        };
        for m in &a.methods {
            let _ = writeln!(
                s,
                "| {} | {} | {:.1} / {:.1} / {:.1} | {} | {:.2e} | {:.2e} | {:.2e} | {} / {} | {} / {} | {} |",
                m.name,
                m.box_test,
                m.mrays.primary,
                m.mrays.shadow,
                m.mrays.diffuse,
                leaks(&m.leak_rate),
                m.edge_zero_hit_rate,
                m.edge_double_hit_rate,
                m.vertex_zero_hit_rate,
                m.t_ulp_median,
                m.t_ulp_p999,
                pct(m.embree_default_agreement),
                pct(m.embree_robust_agreement),
                if m.watertight { "yes" } else { "no" }
            );
        }
        for e in &a.embree {
            let _ = writeln!(
                s,
                "| Embree {} | (Embree) | {:.1} / {:.1} / {:.1} | {} | {:.2e} | – | {:.2e} | – | – | – |",
                e.mode,
                e.mrays.primary,
                e.mrays.shadow,
                e.mrays.diffuse,
                leaks(&e.leak_rate),
                e.edge_zero_hit_rate,
                e.vertex_zero_hit_rate
            );
        }
    }
    let worst: Vec<(&str, &str, &Case)> = r
        .scenes
        .iter()
        .flat_map(|sc| sc.classes.iter().flat_map(move |c| c.worst.iter().map(move |w| (sc.name.as_str(), c.class, w))))
        .collect();
    if !worst.is_empty() {
        let _ = writeln!(s, "\nWorst cases (up to 5 per scene and class):\n");
        let _ = writeln!(
            s,
            "| scene | class | ray | kind | verdict | strahl (t, geom, prim) | Embree (t, geom, prim) | min barycentric (f64) |"
        );
        let _ = writeln!(s, "|---|---|---:|---|---|---|---|---:|");
        for (sc, cl, w) in worst {
            let _ = writeln!(
                s,
                "| {sc} | {cl} | {} | {} | {} | {:?} | {:?} | {:.2e} |",
                w.ray, w.kind, w.verdict, w.strahl, w.embree, w.min_barycentric
            );
        }
    }
    s
}

/// One scene of the scaling series.
#[derive(Serialize)]
pub struct ScalingRow {
    pub name: String,
    pub triangles: usize,
    /// `(class, strahl best Mrays/s, Embree best Mrays/s)`.
    pub mrays: Vec<(&'static str, f64, f64)>,
    /// Every API: `(class, strahl single/packet/stream, Embree single/packet/stream)` in Mrays/s.
    pub apis: Vec<(&'static str, [f64; 3], [f64; 3])>,
    pub hit_miss_agreement_min: f64,
    pub strahl_build_ms: f64,
    pub embree_build_ms: f64,
    pub strahl_bytes_per_tri: f64,
    pub embree_bytes_per_tri: Option<f64>,
}

impl ScalingRow {
    pub fn of(r: &SceneResult) -> Self {
        Self {
            name: r.name.clone(),
            triangles: r.triangles,
            mrays: r.classes.iter().map(|c| (c.class.name(), c.best(0).1, c.best(1).1)).collect(),
            apis: r
                .classes
                .iter()
                .map(|c| {
                    (c.class.name(), Api::ALL.map(|a| c.mrays(0, a, false)), Api::ALL.map(|a| c.mrays(1, a, false)))
                })
                .collect(),
            hit_miss_agreement_min: r.classes.iter().map(|c| c.accuracy.hit_miss_agreement).fold(1.0, f64::min),
            strahl_build_ms: r.build.strahl_ms,
            embree_build_ms: r.build.embree_ms,
            strahl_bytes_per_tri: r.build.strahl_bytes_per_tri,
            embree_bytes_per_tri: r.build.embree_bytes_per_tri,
        }
    }
}

/// Two panels against triangle count (log scales): best-API Mrays/s per class for both engines,
/// and build time for both.
pub fn scaling_chart(path: &Path, rows: &[ScalingRow]) -> anyhow::Result<()> {
    use plotters::prelude::*;
    if !ensure_font() {
        anyhow::bail!("no DejaVu font found for chart labels (apt-get install fonts-dejavu-core)");
    }
    if rows.is_empty() {
        return Ok(());
    }
    let tmin = rows.iter().map(|r| r.triangles).min().unwrap_or(1).max(1) as f64 / 1.5;
    let tmax = rows.iter().map(|r| r.triangles).max().unwrap_or(1).max(1) as f64 * 1.5;
    let root = BitMapBackend::new(path, (1400, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(820);
    let colors = [RGBColor(66, 133, 244), RGBColor(52, 168, 83), RGBColor(234, 67, 53)];
    let mr = |f: &dyn Fn(&(&str, f64, f64)) -> f64| rows.iter().flat_map(|r| r.mrays.iter().map(f)).collect::<Vec<_>>();
    let all: Vec<f64> = [mr(&|m| m.1), mr(&|m| m.2)].concat();
    let ymin = all.iter().copied().fold(f64::INFINITY, f64::min).max(0.01) / 1.5;
    let ymax = all.iter().copied().fold(0.0, f64::max) * 1.5;
    let mut chart = ChartBuilder::on(&left)
        .caption("Mrays/s (best API) against triangles, 2 threads; dashed: Embree", ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d((tmin..tmax).log_scale(), (ymin..ymax).log_scale())?;
    chart.configure_mesh().x_desc("triangles").y_desc("Mrays/s").label_style(("sans-serif", 14)).draw()?;
    for (k, class) in ["primary", "shadow", "diffuse"].iter().enumerate() {
        let pts = |engine: usize| -> Vec<(f64, f64)> {
            rows.iter()
                .filter_map(|r| {
                    r.mrays
                        .iter()
                        .find(|m| m.0 == *class)
                        .map(|m| (r.triangles as f64, if engine == 0 { m.1 } else { m.2 }))
                })
                .collect()
        };
        let c = colors[k];
        chart
            .draw_series(LineSeries::new(pts(0), c.stroke_width(3)))?
            .label(format!("strahl {class}"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3)));
        chart
            .draw_series(DashedLineSeries::new(pts(1), 6, 4, c.stroke_width(2)))?
            .label(format!("Embree {class}"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(1)));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .draw()?;
    let bmin = rows.iter().flat_map(|r| [r.strahl_build_ms, r.embree_build_ms]).fold(f64::INFINITY, f64::min).max(0.01);
    let bmax = rows.iter().flat_map(|r| [r.strahl_build_ms, r.embree_build_ms]).fold(0.0, f64::max);
    let mut chart = ChartBuilder::on(&right)
        .caption("build ms against triangles", ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d((tmin..tmax).log_scale(), (bmin / 1.5..bmax * 1.5).log_scale())?;
    chart.configure_mesh().x_desc("triangles").y_desc("ms").label_style(("sans-serif", 14)).draw()?;
    let black = RGBColor(40, 40, 40);
    chart
        .draw_series(LineSeries::new(
            rows.iter().map(|r| (r.triangles as f64, r.strahl_build_ms)),
            black.stroke_width(3),
        ))?
        .label("strahl")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], black.stroke_width(3)));
    chart
        .draw_series(DashedLineSeries::new(
            rows.iter().map(|r| (r.triangles as f64, r.embree_build_ms)),
            6,
            4,
            black.stroke_width(2),
        ))?
        .label("Embree MEDIUM")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], black.stroke_width(1)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .draw()?;
    root.present()?;
    Ok(())
}

/// The scaling series as a Markdown table.
fn scaling_markdown(s: &mut String, rows: &[ScalingRow]) {
    if rows.is_empty() {
        return;
    }
    let _ = writeln!(s, "\n## Scaling (best API, Mrays/s strahl / Embree)\n");
    let _ = writeln!(
        s,
        "| scene | triangles | primary | shadow | diffuse | min hit/miss agree | build ms strahl / Embree (best of 2) | B/tri strahl / Embree |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        let cell = |k: usize| {
            r.mrays.get(k).map(|m| format!("{:.1} / {:.1} ({:.2}×)", m.1, m.2, m.1 / m.2)).unwrap_or_default()
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {:.1} / {:.1} | {:.1} / {} |",
            r.name,
            r.triangles,
            cell(0),
            cell(1),
            cell(2),
            pct(r.hit_miss_agreement_min),
            r.strahl_build_ms,
            r.embree_build_ms,
            r.strahl_bytes_per_tri,
            r.embree_bytes_per_tri.map(|b| format!("{b:.1}")).unwrap_or_else(|| "–".into())
        );
    }
}

/// The instanced scenes' memory and flat agreement, and the translation sweep.
fn instancing_markdown(s: &mut String, r: &Report) {
    let inst: Vec<&SceneJson> = r.scenes.iter().filter(|sc| sc.instanced).collect();
    if inst.is_empty() && r.instancing_translations.is_empty() {
        return;
    }
    let _ = writeln!(s, "\n## Instancing\n");
    let _ = writeln!(
        s,
        "| scene | instances | instanced triangles | unique triangles | strahl memory | flattened memory | instanced vs flattened: hit/miss agree, t ulps median / p99.9 / max (primary, shadow, diffuse) |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---|");
    for sc in inst {
        let Some(i) = &sc.instancing else { continue };
        let flat: Vec<String> = sc
            .classes
            .iter()
            .map(|c| match c.flat_agreement.as_ref().and_then(|f| f.as_ref()) {
                Some(f) => format!(
                    "{} {} (same triangle {}), {:.0} / {:.0} / {:.0}",
                    c.class,
                    pct(f.hit_miss_agreement),
                    pct(f.same_triangle),
                    f.t_ulps_median,
                    f.t_ulps_p999,
                    f.t_ulps_max
                ),
                None => format!("{} –", c.class),
            })
            .collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.1} MiB | {:.1} MiB{} | {} |",
            sc.name,
            i.instances,
            i.instanced_triangles,
            i.unique_triangles,
            i.memory_bytes as f64 / (1 << 20) as f64,
            i.flattened_memory_bytes as f64 / (1 << 20) as f64,
            if i.flattened_measured { "" } else { " (estimated)" },
            flat.join("; ")
        );
    }
    if !r.instancing_translations.is_empty() {
        let _ = writeln!(s, "\nInstanced against flattened, the world moved by a translation:\n");
        let _ = writeln!(
            s,
            "| translation | class | rays | hit/miss agree | same triangle | t ulps median | t ulps p99.9 | t ulps max |"
        );
        let _ = writeln!(s, "|---:|---|---:|---:|---:|---:|---:|---:|");
        for t in &r.instancing_translations {
            let f = &t.agreement;
            let _ = writeln!(
                s,
                "| {:.0e} | {} | {} | {} | {} | {:.1} | {:.1} | {:.0} |",
                t.translation,
                t.class,
                f.rays,
                pct(f.hit_miss_agreement),
                pct(f.same_triangle),
                f.t_ulps_median,
                f.t_ulps_p999,
                f.t_ulps_max
            );
        }
    }
}

pub fn write_json(path: &Path, r: &Report) -> anyhow::Result<()> {
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d)?;
    }
    let text = serde_json::to_string_pretty(r)?;
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

pub fn write_image(path: &Path, rgb: &[u8], w: u32) -> anyhow::Result<()> {
    image::save_buffer(path, rgb, w, w, image::ExtendedColorType::Rgb8)
        .with_context(|| format!("writing {}", path.display()))
}

/// A font for chart labels: DejaVu Sans from Debian's fonts-dejavu-core (installed by `.ci/setup`).
fn load_font() -> Option<&'static [u8]> {
    for p in [
        "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
        "/usr/share/fonts/TTF/DejaVuSans.ttf",
        "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    ] {
        if let Ok(b) = std::fs::read(p) {
            return Some(Box::leak(b.into_boxed_slice()));
        }
    }
    None
}

/// Registers the chart font once; false if none is installed.
pub fn ensure_font() -> bool {
    use std::sync::OnceLock;
    static OK: OnceLock<bool> = OnceLock::new();
    *OK.get_or_init(|| match load_font() {
        Some(b) => plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, b).is_ok(),
        None => false,
    })
}

/// Grouped bars of the best-vs-best ratio per scene and ray class, with the parity line.
pub fn ratio_chart(path: &Path, r: &Report) -> anyhow::Result<()> {
    let groups: Vec<(String, [Option<f64>; 3])> = r
        .scenes
        .iter()
        .map(|s| {
            let of = |cl: &str| s.classes.iter().find(|c| c.class == cl).map(|c| c.best_ratio);
            (s.name.clone(), [of("primary"), of("shadow"), of("diffuse")])
        })
        .collect();
    class_bars(path, &format!("strahl / Embree throughput, best API vs best API ({} threads)", r.threads), &groups)
}

/// Grouped bars, one group per name, one bar per ray class (primary, shadow, diffuse; a
/// missing class leaves a gap), on a ratio axis with the parity line at 1.
pub(crate) fn class_bars(path: &Path, title: &str, groups: &[(String, [Option<f64>; 3])]) -> anyhow::Result<()> {
    use plotters::prelude::*;
    if !ensure_font() {
        anyhow::bail!("no DejaVu font found for chart labels (apt-get install fonts-dejavu-core)");
    }
    let classes = ["primary", "shadow", "diffuse"];
    let colors = [RGBColor(66, 133, 244), RGBColor(52, 168, 83), RGBColor(234, 67, 53)];
    let ymax = groups.iter().flat_map(|(_, v)| v.iter().flatten().copied()).fold(1.2f64, f64::max) * 1.3;
    let root = BitMapBackend::new(path, (1200, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let n = groups.len().max(1);
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 24))
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(60)
        .build_cartesian_2d(0f64..n as f64, 0f64..ymax)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_desc("ratio (higher is faster than Embree)")
        .label_style(("sans-serif", 15))
        .draw()?;
    // Names centred under their groups of bars.
    for (i, (name, _)) in groups.iter().enumerate() {
        let (px, py) = chart.backend_coord(&(i as f64 + 0.5, 0.0));
        let half = (name.chars().count() as i32 * 7) / 2;
        root.draw(&Text::new(name.to_string(), (px - half, py + 10), ("sans-serif", 14)))?;
    }
    for (k, cl) in classes.iter().enumerate() {
        let bars: Vec<(f64, f64)> =
            groups.iter().enumerate().filter_map(|(i, (_, v))| v[k].map(|y| (i as f64, y))).collect();
        let color = colors[k];
        chart
            .draw_series(bars.iter().map(|&(x, y)| {
                let x0 = x + 0.12 + 0.25 * k as f64;
                Rectangle::new([(x0, 0.0), (x0 + 0.24, y)], color.filled())
            }))?
            .label(*cl)
            .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 12, y + 6)], color.filled()));
    }
    chart.draw_series(LineSeries::new(vec![(0.0, 1.0), (n as f64, 1.0)], BLACK.stroke_width(2)))?;
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()?;
    root.present()?;
    Ok(())
}
