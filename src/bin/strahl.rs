//! The `strahl` command line: `strahl render SCENE.toml -o out.png`.

use std::path::PathBuf;
use std::time::Instant;

use clap::{Parser, Subcommand, ValueEnum};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use strahl::render::{Projection, RayKind, RenderCamera, Renderer};
use strahl::{BuildConfig, SceneFile};

#[derive(Parser)]
#[command(version, about = "strahl: a data-oriented packet/SIMD ray tracer")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene file (format: data/README.md) to a PNG (8-bit sRGB) or EXR (linear float).
    Render(RenderArgs),
}

#[derive(Clone, Copy, ValueEnum)]
enum Backend {
    /// strahl's own BVH and kernels (the comparison harness also renders with Embree).
    Strahl,
}

#[derive(clap::Args)]
struct RenderArgs {
    /// The scene file.
    scene: PathBuf,
    /// Output image: `.png` (8-bit sRGB) or `.exr` (linear 32-bit float).
    #[arg(short, long, default_value = "out.png")]
    output: PathBuf,
    /// Image width and height in pixels (default: the scene's [render] table, else 640×480).
    #[arg(long)]
    width: Option<u32>,
    #[arg(long)]
    height: Option<u32>,
    /// Samples per pixel.
    #[arg(long)]
    spp: Option<u32>,
    /// Maximum recursion depth of reflected and refracted rays.
    #[arg(long)]
    max_depth: Option<u32>,
    /// Contribution cut-off: child rays weighing less are not traced (0 traces to max depth).
    #[arg(long)]
    bailout: Option<f32>,
    /// Worker threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    #[arg(long, value_enum, default_value = "strahl")]
    backend: Backend,
    /// Also write the ray tree of pixel X,Y next to the image: every ray as JSON
    /// (`<output>.raytree.json`) and drawn over the scene seen from a second viewpoint
    /// (`<output>.raytree.png`; primary white, shadow yellow or dark red when blocked, reflected
    /// blue, refracted magenta).
    #[arg(long, value_name = "X,Y", value_parser = parse_pixel)]
    ray_tree: Option<(u32, u32)>,
    /// The ray-tree picture's viewpoint and target (default: beside the camera, looking at the
    /// tree).
    #[arg(long, value_name = "EX,EY,EZ,AX,AY,AZ", value_parser = parse_view)]
    ray_tree_view: Option<[f32; 6]>,
    /// Trace depth-first, one ray at a time (the textbook recursion), instead of the wavefront.
    #[arg(long)]
    recursive: bool,
}

fn parse_pixel(s: &str) -> Result<(u32, u32), String> {
    let (x, y) = s.split_once(',').ok_or("expected X,Y")?;
    Ok((x.trim().parse().map_err(|e| format!("X: {e}"))?, y.trim().parse().map_err(|e| format!("Y: {e}"))?))
}

fn parse_view(s: &str) -> Result<[f32; 6], String> {
    let v: Vec<f32> =
        s.split(',').map(|x| x.trim().parse::<f32>().map_err(|e| format!("{x}: {e}"))).collect::<Result<_, _>>()?;
    let v: [f32; 6] = v.try_into().map_err(|_| "expected six numbers: eye x, y, z and target x, y, z".to_string())?;
    if v.iter().any(|x| !x.is_finite()) {
        return Err("the view must be finite".into());
    }
    Ok(v)
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Render(args) => render(args),
    }
}

fn render(args: RenderArgs) -> anyhow::Result<()> {
    let Backend::Strahl = args.backend;
    if args.threads == 0 {
        anyhow::bail!("--threads must be at least 1");
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .start_handler(|_| {
            strahl::simd::set_flush_denormals();
        })
        .build()?;
    let file = SceneFile::read(&args.scene)?;
    let camera = file
        .camera
        .as_ref()
        .and_then(|c| c.render_camera())
        .ok_or_else(|| anyhow::anyhow!("{}: the scene file has no [camera]", args.scene.display()))?;
    let mut settings = file.render.settings;
    settings.width = args.width.unwrap_or(settings.width);
    settings.height = args.height.unwrap_or(settings.height);
    settings.spp = args.spp.unwrap_or(settings.spp);
    settings.max_depth = args.max_depth.unwrap_or(settings.max_depth);
    settings.bailout = args.bailout.unwrap_or(settings.bailout);
    settings.check()?;
    if let Some((x, y)) = args.ray_tree
        && (x >= settings.width || y >= settings.height)
    {
        anyhow::bail!("--ray-tree {x},{y} lies outside the {}×{} image", settings.width, settings.height);
    }

    let t0 = Instant::now();
    let (scene, world) = pool.install(|| -> anyhow::Result<_> {
        let objects = file.load_objects()?;
        let world = file.world(&objects)?;
        let scene = file.build_from(objects, &BuildConfig::default())?;
        Ok((scene, world))
    })?;
    let build_s = t0.elapsed().as_secs_f64();
    let renderer = Renderer { query: &scene, world: &world, camera, settings };

    let total = settings.width as u64 * settings.height as u64 * settings.spp as u64;
    let bar = ProgressBar::new(total);
    bar.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} samples, {elapsed} {msg}")?);
    let started = Instant::now();
    let (image, stats) = pool.install(|| {
        if args.recursive {
            renderer.render_recursive()
        } else {
            renderer.render(&|done| {
                bar.set_position(done);
                let s = started.elapsed().as_secs_f64();
                bar.set_message(format!("{:.1} k samples/s", done as f64 / s.max(1e-9) / 1e3));
            })
        }
    })?;
    bar.finish_and_clear();
    image.write(&args.output)?;
    let k = |kind: RayKind| stats.rays[kind as usize];
    println!(
        "{}: {}×{}, {} spp, depth {}, {} threads; build {:.2} s, render {:.3} s ({:.0}% of thread time in queries, {:.0}% shading); rays: {} primary, {} shadow, {} reflected, {} refracted = {} ({:.1} Mrays/s); cut by weight {}, by depth {}",
        args.output.display(),
        settings.width,
        settings.height,
        settings.spp,
        settings.max_depth,
        args.threads,
        build_s,
        stats.seconds,
        100.0 * stats.query_share(),
        100.0 * stats.shade_seconds / (stats.seconds * stats.threads.max(1) as f64),
        k(RayKind::Primary),
        k(RayKind::Shadow),
        k(RayKind::Reflected),
        k(RayKind::Refracted),
        stats.total_rays(),
        stats.total_rays() as f64 / stats.seconds / 1e6,
        stats.counts_cut_by_weight,
        stats.counts_cut_by_depth,
    );
    if let Some((x, y)) = args.ray_tree {
        let (nodes, colour) = pool.install(|| renderer.ray_tree(x, y))?;
        let path = args.output.with_extension("raytree.json");
        let json = serde_json::json!({ "pixel": [x, y], "color": colour.to_array(), "rays": nodes });
        std::fs::write(&path, serde_json::to_string_pretty(&json)?)
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
        println!("{}: ray tree of pixel ({x}, {y}), {} rays", path.display(), nodes.len());
        // Rays that leave the scene are drawn as long as the tree is wide.
        let miss = strahl::render::tree::tree_extent(&nodes).map_or(1.0, |(_, r)| 2.0 * r);
        let view = match args.ray_tree_view {
            Some(v) => RenderCamera::look_at(
                Vec3::new(v[0], v[1], v[2]),
                Vec3::new(v[3], v[4], v[5]),
                camera.up,
                Projection::Pinhole { fov_deg: 60.0 },
            ),
            None => strahl::render::tree::side_view(&camera, &nodes, 60.0),
        }
        .ok_or_else(|| anyhow::anyhow!("--ray-tree-view: the eye and target must differ"))?;
        let picture = pool.install(|| renderer.ray_tree_picture(&nodes, view, miss))?;
        let path = args.output.with_extension("raytree.png");
        picture.write(&path)?;
        println!("{}: the ray tree seen from {}", path.display(), view.eye);
    }
    Ok(())
}
