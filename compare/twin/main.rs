//! Builds of strahl side by side in one process, so that host noise falls on both alike:
//! `nat` and `dep` are the working tree compiled with and without `-C target-cpu=native` (a
//! dependency build), `nat0` and `dep0` the same for a base commit. `app SCENE PAIRS A B`
//! builds SCENE's meshes (one flattened scene) with A and B in turn, PAIRS times each (the
//! order swapped every pair, three pairs of warm-up first), and prints the median and quartiles
//! of the per-pair time ratio B/A, by wall clock (`app SCENE PAIRS A B high`: with
//! `BuildConfig::high`, spatial splits). `app SCENE PAIRS A B CLASS API` times ray
//! queries instead: CLASS is `primary`, `shadow` or `diffuse` (the harness's classes, from the
//! scene file's camera and first light, 1024² primary rays or `TWIN_WIDTH`², seed 1, epsilon
//! 1e-4 × the scene's diagonal) and API `stream`, `packet` or `single`; a build named `nat:avx512` (any level name
//! after a colon) runs that copy at that kernel level. The rays are made once, by `nat`, and every
//! build traces the same ones; the builds' answers are compared before timing. Set up by
//! `run.sh`. A scene file path with `@inst` after it (`data/forest.toml@inst`) is traced as the
//! two-level scene the file builds, instances walked by ray transformation; without, as one flat
//! scene of it (spheres and solids stay analytic either way).
use std::time::Instant;

type Run = Box<dyn FnMut() -> f64>;

/// A ray set as plain arrays (ox, oy, oz, dx, dy, dz, tnear, tfar), so that every copy of the
/// library can make its own `RayStream` of the same rays.
type Rays = [Vec<f32>; 8];

/// The image's width and height in primary rays: 1024, or `TWIN_WIDTH` (256 is the criterion
/// benches' size, whose rays stay in the cache).
fn width() -> u32 {
    std::env::var("TWIN_WIDTH").ok().and_then(|s| s.parse().ok()).unwrap_or(1024)
}

/// The class's rays, made by the `nat` copy the way the harness makes them.
fn make_rays(path: &str, class: &str) -> Rays {
    let (path, two_level) = scene_path(path);
    let file = strahl_nat::SceneFile::read(path).unwrap();
    let built = file.build(&Default::default()).unwrap();
    let diag = built.bounds().map(|(lo, hi)| (hi - lo).length()).unwrap_or(1.0);
    if two_level {
        rays_of(&built, &file, diag, class)
    } else {
        rays_of(&built.flatten(&Default::default()).unwrap(), &file, diag, class)
    }
}

/// [`make_rays`] on one form of the scene.
fn rays_of<Q: strahl_nat::Query>(scene: &Q, file: &strahl_nat::SceneFile, diag: f32, class: &str) -> Rays {
    use strahl_nat::{Coherence, HitStream, raygen};
    let camera = file.camera.as_ref().expect("the scene file needs a camera").camera();
    let light = file.lights.first().expect("the scene file needs a light").position;
    let (primary, _) = raygen::primary(&camera, width(), width());
    let mut hits = HitStream::default();
    scene.intersect_stream(&primary, &mut hits, Coherence::Coherent);
    let offset = raygen::Offset::Epsilon(1e-4 * diag);
    let r = match class {
        "primary" => primary,
        "shadow" => raygen::shadow_with(&primary, &hits, light, offset).0,
        "diffuse" => raygen::diffuse_with(&primary, &hits, 1, offset).0,
        _ => panic!("unknown class {class}"),
    };
    [r.ox, r.oy, r.oz, r.dx, r.dy, r.dz, r.tnear, r.tfar]
}

/// Traces `rays` through one copy's scene (flattened, or two-level with `@inst`) with one API: a
/// closure that returns the time in ms and the answers (t and primitive of closest hits; for
/// occlusion see [`occluded`]).
macro_rules! tracer {
    ($k:ident, $path:expr, $rays:expr, $class:expr, $api:expr, $level:expr) => {{
        use $k::{Coherence, HitPacket, HitStream, Isa, PACKET_WIDTH, Query, RayStream};
        // The copy's kernel level for this run: the named one, else the copy's own choice
        // (`STRAHL_ISA` included), read before any run has set it.
        let isa = match $level {
            Some(name) => Isa::from_name(name).unwrap_or_else(|| panic!("unknown level {name}")),
            None => $k::isa(),
        };
        let (path, two_level) = scene_path($path);
        let built = $k::SceneFile::read(path).unwrap().build(&Default::default()).unwrap();
        let [ox, oy, oz, dx, dy, dz, tnear, tfar] = $rays.clone();
        let rays = RayStream { ox, oy, oz, dx, dy, dz, tnear, tfar };
        // The two-level scene as built, or one flat scene of it; one closure body for either.
        fn trace<Q: Query + 'static>(scene: Q, rays: RayStream, isa: Isa, class: &str, api: &str) -> Trace {
            let occlusion = class == "shadow";
            let coherence = if class == "primary" { Coherence::Coherent } else { Coherence::Incoherent };
            let api = api.to_string();
            let n = rays.len();
            let mut hits = HitStream::default();
            let mut occ = Vec::new();
            let mut out = vec![(0f32, 0u32); n];
            Box::new(move || {
                $k::set_isa(isa).unwrap();
                let t = Instant::now();
                match (api.as_str(), occlusion) {
                    ("stream", true) => scene.occluded_stream(&rays, &mut occ, coherence),
                    ("stream", false) => scene.intersect_stream(&rays, &mut hits, coherence),
                    ("packet", _) => {
                        let mut hp = HitPacket::default();
                        for k in (0..n).step_by(PACKET_WIDTH) {
                            let m = (n - k).min(PACKET_WIDTH);
                            let p = rays.packet(k, m);
                            if occlusion {
                                let bits = scene.occluded_packet(&p);
                                for l in 0..m {
                                    out[k + l] = (occluded(bits >> l & 1 != 0), 0);
                                }
                            } else {
                                scene.intersect_packet(&p, &mut hp);
                                for l in 0..m {
                                    out[k + l] = (hp.t[l], hp.prim_id[l]);
                                }
                            }
                        }
                    }
                    ("single", _) => {
                        for (i, o) in out.iter_mut().enumerate() {
                            let r = rays.get(i);
                            *o = if occlusion {
                                (occluded(scene.occluded(&r)), 0)
                            } else {
                                scene.intersect(&r).map_or((f32::INFINITY, u32::MAX), |h| (h.t, h.prim_id))
                            };
                        }
                    }
                    _ => panic!("unknown api {api}"),
                }
                let ms = t.elapsed().as_secs_f64() * 1e3;
                match (api.as_str(), occlusion) {
                    ("stream", true) => (ms, occ.iter().map(|&b| (occluded(b), 0)).collect()),
                    ("stream", false) => {
                        let hit = |i| hits.get(i).map_or((f32::INFINITY, u32::MAX), |h| (h.t, h.prim_id));
                        (ms, (0..n).map(hit).collect())
                    }
                    _ => (ms, out.clone()),
                }
            }) as Trace
        }
        if two_level {
            trace(built, rays, isa, $class, $api)
        } else {
            trace(built.flatten(&Default::default()).unwrap(), rays, isa, $class, $api)
        }
    }};
}

type Trace = Box<dyn FnMut() -> (f64, Vec<(f32, u32)>)>;

/// An occlusion answer in the closest-hit form: 0 where occluded (finite, a hit), +inf where not.
fn occluded(o: bool) -> f32 {
    if o { 0.0 } else { f32::INFINITY }
}

/// A scene argument: a scene file, traced as one flat scene, or with `@inst` after it as the
/// two-level scene the file builds (instances walked by ray transformation).
fn scene_path(arg: &str) -> (&str, bool) {
    arg.strip_suffix("@inst").map_or((arg, false), |p| (p, true))
}

/// A build's tracer; `name` may carry a kernel level after a colon (`nat:avx512`), set before
/// each of its runs, so that two levels of one copy can alternate.
fn make_trace(name: &str, path: &str, rays: &Rays, class: &str, api: &str) -> Trace {
    let (name, level) = name.split_once(':').map_or((name, None), |(n, l)| (n, Some(l)));
    match name {
        "nat" => tracer!(strahl_nat, path, rays, class, api, level),
        "dep" => tracer!(strahl_dep, path, rays, class, api, level),
        "nat0" => tracer!(strahl_nat0, path, rays, class, api, level),
        "dep0" => tracer!(strahl_dep0, path, rays, class, api, level),
        _ => panic!("unknown build {name}"),
    }
}

macro_rules! runner {
    ($k:ident, $path:expr, $high:expr) => {{
        let m = $k::SceneFile::read(scene_path($path).0)
            .unwrap()
            .build(&Default::default())
            .unwrap()
            .flatten(&Default::default())
            .unwrap()
            .meshes()
            .to_vec();
        let cfg = if $high { $k::BuildConfig::high() } else { $k::BuildConfig::default() };
        let mut keep = None;
        Box::new(move || {
            let m = m.clone();
            let t = Instant::now();
            let s = $k::Scene::build(m, &cfg).unwrap();
            let r = t.elapsed().as_secs_f64() * 1e3;
            keep = Some(std::hint::black_box(s));
            r
        }) as Run
    }};
}

/// A build's builder run: the default settings, or with `high` those of `BuildConfig::high`
/// (spatial splits).
fn make(name: &str, path: &str, high: bool) -> Run {
    match name {
        "nat" => runner!(strahl_nat, path, high),
        "dep" => runner!(strahl_dep, path, high),
        "nat0" => runner!(strahl_nat0, path, high),
        "dep0" => runner!(strahl_dep0, path, high),
        _ => panic!("unknown build {name}"),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = &args[1];
    let pairs: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(50);
    let an = args.get(3).cloned().unwrap_or_else(|| "nat".into());
    let bn = args.get(4).cloned().unwrap_or_else(|| "dep".into());
    let (mut a, mut b): (Run, Run) = match args.get(5) {
        None => (make(&an, path, false), make(&bn, path, false)),
        Some(q) if q == "high" => (make(&an, path, true), make(&bn, path, true)),
        Some(class) => {
            let api = args.get(6).map_or("stream", |s| s.as_str());
            let rays = make_rays(path, class);
            let (mut ta, mut tb) = (make_trace(&an, path, &rays, class, api), make_trace(&bn, path, &rays, class, api));
            let (ra, rb) = (ta().1, tb().1);
            // Hit or miss (occluded or not) alike, the same primitive, and the largest relative t
            // difference where both hit the same one: the builds may round differently (FMA or
            // not), no more.
            let agree = ra.iter().zip(&rb).filter(|(x, y)| x.0.is_finite() == y.0.is_finite()).count();
            let same_prim = ra.iter().zip(&rb).filter(|(x, y)| x.1 == y.1).count();
            let same = ra.iter().zip(&rb).filter(|(x, y)| x == y).count();
            let worst = ra
                .iter()
                .zip(&rb)
                .filter(|(x, y)| x.1 == y.1 && x.0.is_finite() && y.0.is_finite() && x.0 > 0.0)
                .map(|(x, y)| ((x.0 - y.0) / x.0).abs())
                .fold(0f32, f32::max);
            println!(
                "{class} {api}: {} rays; {an} and {bn} agree on {agree} hits or misses and {same_prim} primitives, \
                 {same} answers bit-identical, largest relative t difference on the same primitive {worst:.1e}",
                ra.len()
            );
            (Box::new(move || ta().0), Box::new(move || tb().0))
        }
    };
    for _ in 0..3 {
        a();
        b();
    }
    let (mut va, mut vb) = (Vec::new(), Vec::new());
    for i in 0..pairs {
        if i % 2 == 0 {
            va.push(a());
            vb.push(b());
        } else {
            vb.push(b());
            va.push(a());
        }
    }
    let stat = |mut q: Vec<f64>| {
        q.sort_by(f64::total_cmp);
        (q[q.len() / 2], q[q.len() / 4], q[3 * q.len() / 4])
    };
    let (w, wl, wh) = stat(va.iter().zip(&vb).map(|(x, y)| y / x).collect());
    let med = |v: &Vec<f64>| stat(v.clone()).0;
    println!(
        "{path} pairs {pairs}: {an} {:.2} ms, {bn} {:.2} ms (medians); {bn}/{an} time {w:.3} [IQR {wl:.3}-{wh:.3}]",
        med(&va),
        med(&vb)
    );
}
