//! `compare`: trace the same rays with strahl and Embree, report speed and accuracy side by side.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Parser;
use compare::harness::{self, Answers, Class, Settings};
use compare::{embree, methods, rayfile, report, scenes};
use indicatif::{ProgressBar, ProgressStyle};

/// Trace the same rays with strahl and Intel Embree 3 on the same threads; report Mrays/s per
/// engine, API and ray class, build times, and hit agreement decided in float64.
#[derive(Parser, Debug)]
#[command(version, about)]
struct Args {
    /// OBJ files or folders holding one. Without any: the scenes in data/ (or the shared ones with
    /// --shared).
    scenes: Vec<PathBuf>,
    /// Run the seven shared benchmark scenes from ../shared/scenes with their cameras and lights.
    #[arg(long)]
    shared: bool,
    /// Also run the project's data/ scenes (with --shared or explicit scenes).
    #[arg(long)]
    data: bool,
    /// Image width and height in pixels (primary rays = width²).
    #[arg(long, default_value_t = 1024)]
    width: u32,
    /// Timed passes after one warm-up pass, per mode (kernel and as-called), the two engines
    /// interleaved pass by pass (at least 1; 7 or more for ratios with a usable spread).
    #[arg(long, default_value_t = 7)]
    passes: usize,
    /// Tracing and build threads for both engines.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Output folder for report.md, ratio.png and the scene pictures.
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// Write all figures as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write every ray set and both engines' hits to this folder (BENCHMARKING.md formats).
    #[arg(long)]
    dump_rays: Option<PathBuf>,
    /// Trace a ray file with both engines on the scene given as the one positional argument.
    #[arg(long)]
    trace_rays: Option<PathBuf>,
    /// With --trace-rays: any-hit (occlusion) queries instead of closest hits.
    #[arg(long)]
    occlusion: bool,
    /// Write the generated sphereflake to this OBJ file and exit.
    #[arg(long)]
    write_obj: Option<PathBuf>,
    /// Also measure every triangle test × box test against Embree default and ROBUST: leaks,
    /// edge/vertex-aimed rays, t error, agreement, speed (adds `accuracy` to the JSON and two charts).
    #[arg(long)]
    accuracy: bool,
    /// Stacks and slices of the leak test's sphere (ACCURACY.md: 500 × 1000).
    #[arg(long, default_value_t = 500)]
    leak_stacks: u32,
    /// Internal: build SCENE (an OBJ path or `sphereflake`) with Embree at MEDIUM and HIGH on a
    /// verbose device and let Embree print its BVH statistics (read by the parent harness).
    #[arg(long, hide = true)]
    embree_stats_of: Option<String>,
    /// Also run the scaling series: sphereflakes from 11 thousand to 11 million triangles at up to
    /// 512×512 primary rays and 3 passes; adds `scaling` to the JSON and scaling.png.
    #[arg(long)]
    scaling: bool,
    /// Render scene files (the positional arguments; default data/{whitted,cornell,beer}.toml, and
    /// data/sibenik_{fisheye,omnimax,panorama}.toml and data/sponza_still_life.toml when the shared scenes
    /// are present) with
    /// strahl, with strahl on Embree and with POV-Ray; write render.md, render.json and the
    /// images to --out, then exit.
    #[arg(long)]
    render: bool,
    /// Analytic spheres (issue 30): the sphereflake at --sphere-levels as strahl spheres and as
    /// Embree SPHERE_POINT geometry on the same rays, the three sphere tests against float64,
    /// and the analytic flake against its tessellations; writes spheres.md, spheres.json,
    /// sphere_tests.png and tessellation.png to --out, then exits.
    #[arg(long)]
    spheres: bool,
    /// Torus solvers (issue 30): Ferrari, bracketed and Laguerre on one torus, speed against
    /// accuracy (against sphere tracing its exact distance function); writes torus.md,
    /// torus.json and torus_solvers.png to --out, then exits.
    #[arg(long)]
    torus: bool,
    /// Implicit shapes (issue 30): strahl's interval root isolation against marching with
    /// 8–512 steps on superellipsoids and a blob, speed against accuracy (camera and grazing
    /// rays); writes implicit.md, implicit.json, implicit_superquadrics.png and
    /// implicit_metaballs.png to --out, then exits.
    #[arg(long)]
    implicit: bool,
    /// Solid families (issue 30) in kernel mode: 512 placed solids per family (quadrics, torus,
    /// superquadrics, blob, CSG) as strahl solids and as Embree user geometry running the same
    /// intersection code, on the same primary, shadow and diffuse rays, the three APIs each;
    /// writes solids.md, solids.json and solids.png to --out, then exits.
    #[arg(long)]
    solids: bool,
    /// With --solids: only these families (by the report's names, e.g. `box,torus,CSG die`).
    #[arg(long, value_delimiter = ',')]
    families: Vec<String>,
    /// Redraw the charts of --spheres, --torus, --implicit or --solids into --out from their JSON
    /// report (spheres.json, torus.json, implicit.json or solids.json), without measuring.
    #[arg(long, alias = "spheres-charts-from")]
    charts_from: Option<PathBuf>,
    /// Sphereflake levels for --spheres (level 3: 820 spheres, 6: 597,871).
    #[arg(long, value_delimiter = ',', default_value = "3,5,6")]
    sphere_levels: Vec<u32>,
    /// Exit with an error if any scene and class has hit/miss agreement below this fraction.
    #[arg(long)]
    min_agreement: Option<f64>,
}

fn project_dir(rel: &str) -> PathBuf {
    let here = Path::new(rel);
    if here.exists() {
        return here.to_path_buf();
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    if let Some(p) = &args.write_obj {
        return write_sphereflake(p);
    }
    if let Some(scene) = &args.embree_stats_of {
        let spec = match scene.strip_prefix("sphereflake:") {
            Some(params) => {
                let p: Vec<u32> = params.split(':').map(str::parse).collect::<Result<_, _>>()?;
                let [levels, stacks, slices] = p[..] else { bail!("sphereflake:LEVELS:STACKS:SLICES") };
                scenes::SceneSpec {
                    source: scenes::Source::Sphereflake { levels, stacks, slices },
                    ..scenes::sphereflake()
                }
            }
            None => scenes::from_path(Path::new(scene))?,
        };
        let meshes = spec.load()?;
        let device = embree::Device::new(&format!("threads={},verbose=2", args.threads))?;
        for q in [embree::Quality::Medium, embree::Quality::High] {
            embree::Scene::build(&device, &meshes, q, false)?;
        }
        // strahl's tree leaves out triangles that can never be hit (zero area, non-finite corners);
        // Embree keeps them. Two trees over different triangles have incomparable SAH costs, so
        // Embree builds again over the triangles strahl keeps, if it left any out.
        let hittable = harness::hittable_meshes(&meshes)?;
        if hittable.iter().map(|m| m.triangle_count()).sum::<usize>()
            < meshes.iter().map(|m| m.triangle_count()).sum::<usize>()
        {
            println!("{}", harness::SAME_TRIANGLES_MARK);
            for q in [embree::Quality::Medium, embree::Quality::High] {
                embree::Scene::build(&device, &hittable, q, false)?;
            }
        }
        return Ok(());
    }
    if args.threads == 0 || args.width == 0 || args.passes == 0 {
        bail!("--threads, --width and --passes must be positive");
    }
    // 1M rays take about 100 MB per ray class and engine; 16384² would take tens of GB.
    if args.width > 8192 {
        bail!("--width {} is above the 8192 supported (primary rays = width²)", args.width);
    }
    if let Some(m) = args.min_agreement
        && !(0.0..=1.0).contains(&m)
    {
        bail!("--min-agreement {m} is not a fraction between 0 and 1");
    }
    if args.occlusion && args.trace_rays.is_none() {
        bail!("--occlusion applies to --trace-rays only");
    }
    let pool = compare::pool(args.threads)?;
    if args.render {
        return render_comparison(&args, &pool);
    }
    let device = embree::Device::new(&format!("threads={}", args.threads))?;
    if let Some(json) = &args.charts_from {
        let bytes = std::fs::read(json).with_context(|| format!("reading {}", json.display()))?;
        std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
        return match json.file_name().and_then(|n| n.to_str()) {
            Some("spheres.json") => compare::spheres::charts(&args.out, &serde_json::from_slice(&bytes)?),
            Some("torus.json") => compare::torus::chart(&args.out, &serde_json::from_slice(&bytes)?),
            Some("implicit.json") => compare::implicit::chart(&args.out, &serde_json::from_slice(&bytes)?),
            Some("solids.json") => compare::solids::chart(&args.out, &serde_json::from_slice(&bytes)?),
            _ => bail!(
                "--charts-from {}: expected spheres.json, torus.json, implicit.json or solids.json",
                json.display()
            ),
        };
    }
    if args.implicit {
        let r = compare::implicit::run(args.width as usize, args.passes, &pool, &args.out)?;
        print!("{}", compare::implicit::markdown(&r));
        return Ok(());
    }
    if args.solids {
        // Embree's layout: one user geometry per solid (the default), or all solids as the
        // primitives of one geometry; PERFORMANCE.md has both.
        let one_geometry = match std::env::var("EMBREE_SOLIDS").as_deref() {
            Ok("one-geometry") => true,
            Ok("per-solid") | Err(_) => false,
            Ok(other) => bail!("EMBREE_SOLIDS={other:?}: expected per-solid or one-geometry"),
        };
        let r = compare::solids::run(args.width as usize, args.passes, &args.families, one_geometry, &pool, &args.out)?;
        print!("{}", compare::solids::markdown(&r));
        return Ok(());
    }
    if args.torus {
        let r = compare::torus::run(args.width as usize, args.passes, &pool, &args.out)?;
        print!("{}", compare::torus::markdown(&r));
        return Ok(());
    }
    if args.spheres {
        if let Some(&l) = args.sphere_levels.iter().find(|&&l| l > 7) {
            bail!("--sphere-levels {l}: at most 7 (4.8 million spheres)");
        }
        let settings =
            compare::spheres::Settings { levels: args.sphere_levels.clone(), width: args.width, passes: args.passes };
        let r = compare::spheres::run(&settings, &pool, &device, &args.out, |step| eprintln!("spheres: {step}"))?;
        print!("{}", compare::spheres::markdown(&r));
        return Ok(());
    }
    if let Some(rays) = &args.trace_rays {
        return trace_file(&args, rays, &pool, &device);
    }

    let mut specs = Vec::new();
    if args.shared {
        let root = project_dir("../shared/scenes");
        let found = scenes::shared(&root);
        if found.is_empty() {
            bail!("--shared: no scenes found under {}", root.display());
        }
        specs.extend(found);
    }
    for p in &args.scenes {
        specs.push(scenes::from_path(p)?);
    }
    if specs.is_empty() || args.data {
        specs.extend(scenes::data(&project_dir("data")));
    }

    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let settings = Settings {
        width: args.width,
        passes: args.passes,
        keep_rays: args.dump_rays.is_some() || args.accuracy,
        ..Settings::default()
    };
    let bar = progress_bar(specs.len());
    let mut results = Vec::new();
    for spec in &specs {
        let mut r = harness::run_scene(spec, &pool, &device, &settings, |step| {
            bar.step(format!("{}: {step}", spec.name));
        })?;
        if let Some(stats) = harness::embree_stats(spec, args.threads) {
            r.build.set_embree_stats(&stats);
        }
        report::write_image(&args.out.join(format!("{}.png", r.name)), &r.image, r.width)?;
        if let Some(dir) = &args.dump_rays {
            if r.instanced.is_none() {
                dump(dir, spec, &r)?;
            } else {
                eprintln!("--dump-rays: {} is instanced; its rays are not written", r.name);
            }
        }
        results.push(r);
    }
    bar.finish();

    let mut rep = report::build_report(&results, args.threads, args.width, args.passes);
    if args.scaling {
        let small = Settings {
            width: args.width.min(512),
            passes: args.passes.min(3),
            build_repeats: 2,
            keep_rays: false,
            ..Settings::default()
        };
        let series = scenes::scaling();
        let bar = progress_bar(series.len());
        let mut rows = Vec::new();
        for spec in &series {
            let mut r = harness::run_scene(spec, &pool, &device, &small, |step| {
                bar.step(format!("scaling {}: {step}", spec.name));
            })?;
            if let Some(stats) = harness::embree_stats(spec, args.threads) {
                r.build.set_embree_stats(&stats);
            }
            rows.push(report::ScalingRow::of(&r));
        }
        bar.finish();
        rep.scaling = rows;
        if let Err(e) = report::scaling_chart(&args.out.join("scaling.png"), &rep.scaling) {
            eprintln!("scaling chart skipped: {e:#}");
        }
    }
    // Instanced against flattened with the world moved out to 1e6, on the forest scene.
    if let Some(spec) = specs.iter().find(|s| s.name == "forest")
        && let Some(file) = spec.scene_file()?
    {
        eprintln!("instancing: instanced vs flattened at translations 1 to 1e6 ({})", file.path.display());
        rep.instancing_translations = harness::translation_sweep(&file, &pool, args.width.min(512), settings.seed)?;
    }
    if args.accuracy {
        let scenes_rays: Vec<methods::SceneRays> = specs
            .iter()
            .zip(&results)
            .filter(|(spec, _)| !matches!(spec.source, scenes::Source::SceneFile(_)))
            .map(|(spec, r)| {
                Ok(methods::SceneRays {
                    meshes: spec.load()?,
                    sets: r.ray_sets.iter().map(|(c, rays, _, e)| (*c, rays.clone(), e.clone())).collect(),
                })
            })
            .collect::<anyhow::Result<_>>()?;
        let ms = methods::Settings {
            sphere: (args.leak_stacks, 2 * args.leak_stacks),
            passes: args.passes.clamp(1, 3),
            ..methods::Settings::default()
        };
        let bar = Progress::new(ProgressBar::new_spinner());
        let acc = methods::run(&scenes_rays, &project_dir("../shared/scenes"), &pool, &device, &ms, |m| {
            bar.step(format!("accuracy: {m}"));
        })?;
        bar.finish();
        if let Err(e) = methods::charts(&args.out, &acc) {
            eprintln!("accuracy charts skipped: {e:#}");
        }
        rep.accuracy = Some(acc);
    }
    let md = report::markdown(&rep);
    println!("{md}");
    std::fs::write(args.out.join("report.md"), &md)?;
    report::write_json(&args.out.join("results.json"), &rep)?;
    if let Some(j) = &args.json {
        report::write_json(j, &rep)?;
    }
    match report::ratio_chart(&args.out.join("ratio.png"), &rep) {
        Ok(()) => {
            eprintln!("wrote {}/report.md, results.json, ratio.png and one picture per scene", args.out.display())
        }
        Err(e) => eprintln!("chart skipped: {e:#}"),
    }
    if let Some(min) = args.min_agreement {
        for s in &rep.scenes {
            for c in &s.classes {
                if c.hit_miss_agreement < min {
                    bail!("{} {}: hit/miss agreement {:.6} is below {min}", s.name, c.class, c.hit_miss_agreement);
                }
            }
        }
    }
    Ok(())
}

/// A progress bar over `scenes` scenes of five steps each.
fn progress_bar(scenes: usize) -> Progress {
    let bar = ProgressBar::new((scenes * 5) as u64);
    bar.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} {elapsed} {msg}").expect("valid template"));
    Progress::new(bar)
}

/// A progress bar on a terminal; elsewhere (CI logs, a pipe), where indicatif draws nothing, one
/// plain line per step with the time since the start.
struct Progress {
    bar: Option<ProgressBar>,
    start: std::time::Instant,
}

impl Progress {
    fn new(bar: ProgressBar) -> Self {
        use std::io::IsTerminal;
        Self { bar: std::io::stderr().is_terminal().then_some(bar), start: std::time::Instant::now() }
    }

    fn step(&self, msg: String) {
        match &self.bar {
            Some(b) => {
                b.set_message(msg);
                b.inc(1);
            }
            None => eprintln!("[{:7.1} s] {msg}", self.start.elapsed().as_secs_f64()),
        }
    }

    fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

fn dump(dir: &Path, spec: &scenes::SceneSpec, r: &harness::SceneResult) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let offsets = rayfile::offsets(&spec.load()?);
    for (class, rays, s, e) in &r.ray_sets {
        let base = format!("{}_{}", r.name, class.name());
        rayfile::write_rays(&dir.join(format!("{base}.rays")), rays)?;
        rayfile::write_hits(&dir.join(format!("{base}.strahl.hits")), s, &offsets)?;
        rayfile::write_hits(&dir.join(format!("{base}.embree.hits")), e, &offsets)?;
    }
    Ok(())
}

fn trace_file(args: &Args, rays_path: &Path, pool: &rayon::ThreadPool, device: &embree::Device) -> anyhow::Result<()> {
    let [scene_path] = args.scenes.as_slice() else {
        bail!("--trace-rays needs exactly one scene (an OBJ file or folder)");
    };
    let spec = scenes::from_path(scene_path)?;
    let meshes = spec.load()?;
    let rays = rayfile::read_rays(rays_path)?;
    let scene = pool.install(|| strahl::Scene::build(meshes.clone(), &strahl::BuildConfig::default()))?;
    let escene = embree::Scene::build(device, &meshes, embree::Quality::Medium, false)?;
    let class = if args.occlusion { Class::Shadow } else { Class::Diffuse };
    let (s, e) = harness::trace_once(&scene, &escene, &rays, class, pool);
    let acc = compare::accuracy::compare(&compare::accuracy::Flat(&meshes), &rays, args.occlusion, &s, &e);
    std::fs::create_dir_all(&args.out)?;
    let offsets = rayfile::offsets(&meshes);
    let stem = rays_path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "rays".into());
    let sp = args.out.join(format!("{stem}.strahl.hits"));
    let ep = args.out.join(format!("{stem}.embree.hits"));
    rayfile::write_hits(&sp, &s, &offsets)?;
    rayfile::write_hits(&ep, &e, &offsets)?;
    let hits = |a: &Answers| (0..a.len()).filter(|&i| a.hit(i)).count();
    println!(
        "{} rays: strahl {} hits, Embree {} hits, hit/miss agreement {:.6}, primitive agreement {:.6}\nwrote {} and {}",
        rays.len(),
        hits(&s),
        hits(&e),
        acc.hit_miss_agreement,
        acc.prim_agreement,
        sp.display(),
        ep.display()
    );
    Ok(())
}

fn write_sphereflake(p: &Path) -> anyhow::Result<()> {
    use std::io::Write;
    let scenes::Source::Sphereflake { levels, stacks, slices } = scenes::sphereflake().source else {
        unreachable!("the sphereflake spec is procedural")
    };
    let m = strahl::procedural::sphereflake(levels, stacks, slices);
    let mut f = std::io::BufWriter::new(std::fs::File::create(p).with_context(|| format!("creating {}", p.display()))?);
    writeln!(f, "# Haines' sphereflake, generated by strahl::procedural::sphereflake({levels}, {stacks}, {slices})")?;
    for v in m.positions() {
        writeln!(f, "v {} {} {}", v.x, v.y, v.z)?;
    }
    for t in m.indices() {
        writeln!(f, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
    }
    f.flush()?;
    eprintln!("wrote {} ({} triangles)", p.display(), m.triangle_count());
    Ok(())
}

fn render_comparison(args: &Args, pool: &rayon::ThreadPool) -> anyhow::Result<()> {
    let scenes: Vec<PathBuf> = if args.scenes.is_empty() {
        let mut v: Vec<PathBuf> =
            ["whitted", "cornell", "beer"].iter().map(|n| project_dir("data").join(format!("{n}.toml"))).collect();
        // The Sibenik views need the shared scenes (not part of this repository).
        if project_dir("../shared/scenes/sibenik/sibenik.obj").exists() {
            v.extend(
                ["sibenik_fisheye", "sibenik_omnimax", "sibenik_panorama"]
                    .iter()
                    .map(|n| project_dir("data").join(format!("{n}.toml"))),
            );
        }
        if project_dir("../shared/scenes/sponza_dabrovic/sponza.obj").exists() {
            v.push(project_dir("data").join("sponza_still_life.toml"));
        }
        v
    } else {
        args.scenes.clone()
    };
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    if !compare::povray::available() {
        eprintln!("povray is not installed: rendering with strahl and Embree only");
    }
    let mut rows = Vec::new();
    for s in &scenes {
        eprintln!("rendering {}", s.display());
        rows.push(compare::render::compare_scene(s, &args.out, args.passes, args.threads, pool)?);
    }
    let md = compare::render::table(&rows, args.threads, args.passes);
    print!("{md}");
    std::fs::write(args.out.join("render.md"), &md)?;
    std::fs::write(args.out.join("render.json"), serde_json::to_string_pretty(&rows)?)?;
    if let Some(j) = &args.json {
        std::fs::write(j, serde_json::to_string_pretty(&rows)?)?;
    }
    Ok(())
}
