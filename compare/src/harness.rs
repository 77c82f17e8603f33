//! One side-by-side run: build both engines on the same meshes, generate the three ray classes of
//! BENCHMARKING.md, trace the same rays through every API of both engines on one pool of worker
//! threads (FTZ/DAZ set on each), time interleaved passes, and diff the answers.

use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;
use strahl::{
    BuildConfig, Camera, Coherence, HitPacket, HitStream, INVALID_ID, InstancedScene, PACKET_WIDTH, Query, RayStream,
    Scene, TriangleMesh, raygen,
};

use crate::accuracy::{self, Accuracy};
use crate::embree::{self, RTC_INVALID_GEOMETRY_ID, RTCHit, RTCRay, RTCRayHit};
use crate::kernel::{EmbreeNative, StrahlNative};
use crate::scenes::SceneSpec;

/// Rays per parallel work item for the single and packet APIs, and Embree's stream chunk.
pub const CHUNK: usize = 4096;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Class {
    Primary,
    Shadow,
    Diffuse,
}

impl Class {
    pub const ALL: [Class; 3] = [Class::Primary, Class::Shadow, Class::Diffuse];

    pub fn name(self) -> &'static str {
        match self {
            Class::Primary => "primary",
            Class::Shadow => "shadow",
            Class::Diffuse => "diffuse",
        }
    }

    /// Shadow rays ask for any hit; the others for the closest.
    pub fn occlusion(self) -> bool {
        self == Class::Shadow
    }

    /// Primary rays are traced with Embree's COHERENT flag (BENCHMARKING.md) and strahl's coherent
    /// stream mode; shadow and diffuse rays as incoherent.
    pub fn coherent(self) -> bool {
        self == Class::Primary
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Api {
    Single,
    Packet,
    Stream,
}

impl Api {
    pub const ALL: [Api; 3] = [Api::Single, Api::Packet, Api::Stream];

    pub fn name(self) -> &'static str {
        match self {
            Api::Single => "single",
            Api::Packet => "packet",
            Api::Stream => "stream",
        }
    }
}

/// How a timed call is fed (BENCHMARKING.md, issue 28).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Each engine traces from its own native input layout, prepared before the timed region;
    /// only the query calls are timed (`kernel.rs`). The headline.
    Kernel,
    /// Both engines fed from the same SoA ray stream inside the timed region, each in the best
    /// way its API allows, answers read into the same arrays: what a caller pays.
    AsCalled,
}

impl Mode {
    pub const ALL: [Mode; 2] = [Mode::Kernel, Mode::AsCalled];

    pub fn name(self) -> &'static str {
        match self {
            Mode::Kernel => "kernel",
            Mode::AsCalled => "as_called",
        }
    }
}

/// An affine transform as Embree's `RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR`: the three columns of the
/// linear part, then the translation.
pub fn column_major(m: &glam::Affine3A) -> [f32; 12] {
    let mut c = [0.0f32; 12];
    for (k, col) in [m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis, m.translation].iter().enumerate() {
        c[3 * k..3 * k + 3].copy_from_slice(&col.to_array());
    }
    c
}

/// Quartiles of a set of values: `[q1, median, q3]` (NaN if empty).
pub fn quartiles(v: &[f64]) -> [f64; 3] {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    if s.is_empty() {
        return [f64::NAN; 3];
    }
    s.sort_by(f64::total_cmp);
    // Linear interpolation between order statistics.
    let q = |p: f64| {
        let x = p * (s.len() - 1) as f64;
        let (i, f) = (x.floor() as usize, x.fract());
        if i + 1 < s.len() { s[i] * (1.0 - f) + s[i + 1] * f } else { s[i] }
    };
    [q(0.25), q(0.5), q(0.75)]
}

/// Per-ray answers of one engine: `t` (+inf for a miss; 0 for an occluded shadow ray) and ids
/// (`INVALID_ID` for a miss; geometry 0 for an occluded shadow ray, whose primitive is unknown;
/// instance `INVALID_ID` outside instanced scenes).
#[derive(Clone, Debug, PartialEq)]
pub struct Answers {
    pub t: Vec<f32>,
    pub geom: Vec<u32>,
    pub prim: Vec<u32>,
    pub inst: Vec<u32>,
}

/// One chunk of [`Answers`] being filled.
pub(crate) struct AnswerSlice<'a> {
    t: &'a mut [f32],
    geom: &'a mut [u32],
    prim: &'a mut [u32],
    inst: &'a mut [u32],
}

impl AnswerSlice<'_> {
    fn len(&self) -> usize {
        self.t.len()
    }

    #[inline]
    fn set(&mut self, k: usize, (t, g, p, i): (f32, u32, u32, u32)) {
        (self.t[k], self.geom[k], self.prim[k], self.inst[k]) = (t, g, p, i);
    }
}

impl Answers {
    pub fn misses(n: usize) -> Self {
        Self {
            t: vec![f32::INFINITY; n],
            geom: vec![INVALID_ID; n],
            prim: vec![INVALID_ID; n],
            inst: vec![INVALID_ID; n],
        }
    }

    pub fn len(&self) -> usize {
        self.t.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    pub fn hit(&self, i: usize) -> bool {
        self.geom[i] != INVALID_ID
    }

    /// The triangle answer `i` names: (instance, geometry, primitive).
    pub fn key(&self, i: usize) -> (u32, u32, u32) {
        (self.inst[i], self.geom[i], self.prim[i])
    }

    pub(crate) fn set(&mut self, i: usize, (t, g, p, n): (f32, u32, u32, u32)) {
        (self.t[i], self.geom[i], self.prim[i], self.inst[i]) = (t, g, p, n);
    }

    /// Runs `f(start, slice)` over chunks of [`CHUNK`] entries in parallel, each chunk a job of
    /// its own (see `strahl::scene::STREAM_CHUNK` for why).
    fn par_fill(&mut self, f: impl Fn(usize, &mut AnswerSlice<'_>) + Sync) {
        (
            self.t.par_chunks_mut(CHUNK),
            self.geom.par_chunks_mut(CHUNK),
            self.prim.par_chunks_mut(CHUNK),
            self.inst.par_chunks_mut(CHUNK),
        )
            .into_par_iter()
            .enumerate()
            .with_max_len(1)
            .for_each(|(k, (t, geom, prim, inst))| f(k * CHUNK, &mut AnswerSlice { t, geom, prim, inst }));
    }
}

/// Throughput samples of one engine and API.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Samples {
    pub seconds: Vec<f64>,
}

impl Samples {
    pub fn best(&self) -> f64 {
        self.seconds.iter().copied().fold(f64::INFINITY, f64::min)
    }

    pub fn median(&self) -> f64 {
        let mut s = self.seconds.clone();
        s.sort_by(f64::total_cmp);
        if s.is_empty() { f64::NAN } else { s[s.len() / 2] }
    }
}

/// Everything measured for one ray class of one scene.
#[derive(Clone, Debug)]
pub struct ClassResult {
    pub class: Class,
    pub rays: usize,
    pub hit_rate: f64,
    pub accuracy: Accuracy,
    /// `[mode][engine][api]` (mode as in [`Mode::ALL`]; engine 0 = strahl, 1 = Embree): pass `k`
    /// of every list was timed in the same interleaved round.
    pub samples: [[[Samples; 3]; 2]; 2],
    /// Whether each engine's packet and stream answers equal its single-ray answers.
    pub strahl_apis_consistent: f64,
    pub embree_apis_consistent: f64,
    /// Instanced scenes built flat too: strahl instanced against strahl flattened.
    pub flat_agreement: Option<FlatAgreement>,
}

impl ClassResult {
    /// Kernel-mode Mrays/s (the headline), best or median pass.
    pub fn mrays(&self, engine: usize, api: Api, median: bool) -> f64 {
        self.mrays_in(Mode::Kernel, engine, api, median)
    }

    pub fn mrays_in(&self, mode: Mode, engine: usize, api: Api, median: bool) -> f64 {
        let s = &self.samples[mode as usize][engine][api as usize];
        let secs = if median { s.median() } else { s.best() };
        if secs > 0.0 && secs.is_finite() { self.rays as f64 / secs / 1e6 } else { 0.0 }
    }

    /// The fastest kernel-mode API of an engine by best time, with its Mrays/s.
    pub fn best(&self, engine: usize) -> (Api, f64) {
        self.best_in(Mode::Kernel, engine)
    }

    pub fn best_in(&self, mode: Mode, engine: usize) -> (Api, f64) {
        Api::ALL
            .iter()
            .map(|&a| (a, self.mrays_in(mode, engine, a, false)))
            .fold((Api::Single, 0.0), |b, x| if x.1 > b.1 { x } else { b })
    }

    /// Kernel-mode best-vs-best ratio (strahl's best API's best pass over Embree's).
    pub fn best_ratio(&self) -> f64 {
        self.best_ratio_in(Mode::Kernel)
    }

    pub fn best_ratio_in(&self, mode: Mode) -> f64 {
        let (e, s) = (self.best_in(mode, 1).1, self.best_in(mode, 0).1);
        if e > 0.0 { s / e } else { 0.0 }
    }

    /// Speed ratios strahl/Embree of the interleaved pass pairs of one API.
    pub fn pair_ratios(&self, mode: Mode, api: Api) -> Vec<f64> {
        let m = &self.samples[mode as usize];
        let (s, e) = (&m[0][api as usize].seconds, &m[1][api as usize].seconds);
        s.iter().zip(e).map(|(s, e)| e / s).collect()
    }

    /// Best-vs-best speed ratios of the interleaved passes: in each pass, each engine's fastest
    /// API against the other's.
    pub fn best_pair_ratios(&self, mode: Mode) -> Vec<f64> {
        let m = &self.samples[mode as usize];
        let passes = m[0][0].seconds.len();
        let fastest =
            |e: usize, k: usize| Api::ALL.iter().map(|&a| m[e][a as usize].seconds[k]).fold(f64::INFINITY, f64::min);
        (0..passes).map(|k| fastest(1, k) / fastest(0, k)).collect()
    }
}

/// Build figures of both engines.
#[derive(Clone, Debug, Default, Serialize)]
pub struct BuildResult {
    pub strahl_ms: f64,
    pub embree_ms: f64,
    pub embree_high_ms: f64,
    /// strahl's HIGH preset (spatial splits, `BuildConfig::high`): build time, SAH cost, bytes per
    /// triangle and leaf references (NaN / 0 for instanced scenes).
    pub strahl_high_ms: f64,
    pub strahl_high_sah: f64,
    pub strahl_high_bytes_per_tri: f64,
    pub strahl_high_references: usize,
    pub strahl_sah: f64,
    pub strahl_bytes_per_tri: f64,
    pub strahl_bytes: usize,
    pub strahl_inner_nodes: usize,
    pub strahl_leaves: usize,
    pub strahl_depth: usize,
    /// Embree's own statistics (`verbose=2`, read from a child process): SAH cost and BVH bytes
    /// per triangle at MEDIUM and HIGH. `None` if they could not be read.
    pub embree_bytes_per_tri: Option<f64>,
    pub embree_sah: Option<f64>,
    pub embree_high_sah: Option<f64>,
    pub embree_high_bytes_per_tri: Option<f64>,
    /// Triangles strahl's tree leaves out (zero area, non-finite corners); Embree keeps them.
    pub strahl_skipped_triangles: usize,
    /// Where strahl left triangles out, the `embree_*` statistics above are from a second pair of
    /// Embree builds over the triangles strahl keeps, and these (MEDIUM, HIGH) from its builds over
    /// all the scene's triangles.
    pub embree_all_triangles: Option<[EmbreeTreeStats; 2]>,
}

/// Embree's statistics of one build: SAH cost and bytes per primitive.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct EmbreeTreeStats {
    pub sah: f64,
    pub bytes_per_tri: f64,
}

/// Embree's statistics for a scene: MEDIUM and HIGH over the scene's triangles, and where strahl
/// left triangles out, MEDIUM and HIGH again over the triangles strahl's tree holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EmbreeStats {
    pub all: [EmbreeTreeStats; 2],
    pub same_triangles: Option<[EmbreeTreeStats; 2]>,
}

/// The line `--embree-stats-of` prints before its builds over the triangles strahl keeps.
pub const SAME_TRIANGLES_MARK: &str = "strahl: the same builds over the hittable triangles only";

/// `meshes` without the triangles strahl's tree leaves out (`TriangleMesh::is_hittable`).
pub fn hittable_meshes(meshes: &[TriangleMesh]) -> anyhow::Result<Vec<TriangleMesh>> {
    meshes
        .iter()
        .map(|m| {
            let indices = m.indices().iter().enumerate().filter(|(i, _)| m.is_hittable(*i)).map(|(_, t)| *t).collect();
            Ok(TriangleMesh::new(m.name.clone(), m.positions().to_vec(), indices)?)
        })
        .collect()
}

impl BuildResult {
    /// Takes Embree's figures over the same triangles as strahl's tree where they differ from the
    /// scene's, keeping the scene's in the `embree_all_*` fields.
    pub fn set_embree_stats(&mut self, stats: &EmbreeStats) {
        let [medium, high] = stats.same_triangles.unwrap_or(stats.all);
        self.embree_sah = Some(medium.sah);
        self.embree_bytes_per_tri = Some(medium.bytes_per_tri);
        self.embree_high_sah = Some(high.sah);
        self.embree_high_bytes_per_tri = Some(high.bytes_per_tri);
        if stats.same_triangles.is_some() {
            self.embree_all_triangles = Some(stats.all);
        }
    }
}

/// Embree's BVH statistics for a scene. Embree 3 has no API for them, but prints them on a
/// `verbose=2` device, so the harness runs itself as a child (`--embree-stats-of`) and reads the
/// `total : sah = …, #bytes/prim = …` lines.
pub fn embree_stats(spec: &SceneSpec, threads: usize) -> Option<EmbreeStats> {
    let arg = match &spec.source {
        crate::scenes::Source::Obj(p) => p.to_string_lossy().into_owned(),
        crate::scenes::Source::Sphereflake { levels, stacks, slices } => {
            format!("sphereflake:{levels}:{stacks}:{slices}")
        }
        crate::scenes::Source::SceneFile(_) => return None,
    };
    let exe = std::env::current_exe().ok()?;
    let out = std::process::Command::new(exe)
        .args(["--threads", &threads.to_string(), "--embree-stats-of", &arg])
        .output()
        .ok()?;
    parse_embree_stats(&String::from_utf8_lossy(&out.stdout))
}

/// Reads [`EmbreeStats`] from the output of `--embree-stats-of`.
fn parse_embree_stats(text: &str) -> Option<EmbreeStats> {
    let (all, same) = match text.split_once(SAME_TRIANGLES_MARK) {
        Some((a, s)) => (a, Some(s)),
        None => (text, None),
    };
    let pair = |text: &str| -> Option<[EmbreeTreeStats; 2]> {
        let stats: Vec<EmbreeTreeStats> = text
            .lines()
            .filter(|l| l.trim_start().starts_with("total") && l.contains("sah =") && l.contains("#bytes/prim"))
            .filter_map(|l| {
                let num = |key: &str| {
                    l.split(key).nth(1)?.split_whitespace().next()?.trim_end_matches(',').parse::<f64>().ok()
                };
                Some(EmbreeTreeStats { sah: num("sah =")?, bytes_per_tri: num("#bytes/prim =")? })
            })
            .collect();
        (stats.len() >= 2).then(|| [stats[0], stats[1]])
    };
    Some(EmbreeStats { all: pair(all)?, same_triangles: same.and_then(pair) })
}

pub struct SceneResult {
    pub name: String,
    pub triangles: usize,
    pub build: BuildResult,
    pub classes: Vec<ClassResult>,
    /// Figures of an instanced scene; `None` for a flat one.
    pub instanced: Option<InstancedInfo>,
    /// A shaded picture of the primary hits (RGB, `width × width`).
    pub image: Vec<u8>,
    pub width: u32,
    /// The ray sets and strahl's and Embree's answers, for `--dump-rays`.
    pub ray_sets: Vec<(Class, RayStream, Answers, Answers)>,
}

/// What an instanced scene adds to the report.
#[derive(Clone, Debug, Serialize)]
pub struct InstancedInfo {
    pub instances: usize,
    /// Triangles over all instances (each instance counts its object's triangles).
    pub instanced_triangles: u64,
    /// Triangles stored once per object.
    pub unique_triangles: usize,
    /// strahl's instanced build: object BVHs, top level and instance records.
    pub memory_bytes: usize,
    /// The flattened build: measured where it was built, else estimated from each object's bytes
    /// per triangle (`flattened_measured` says which).
    pub flattened_memory_bytes: u64,
    pub flattened_measured: bool,
    /// Wall time of the flattened build, if it was built.
    pub flattened_build_ms: Option<f64>,
}

/// Instanced against flattened strahl on the same rays.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FlatAgreement {
    pub rays: usize,
    pub hit_miss_agreement: f64,
    /// Of the rays both hit, the share that hit the same triangle (the rest are edge ties).
    pub same_triangle: f64,
    /// `|t_instanced − t_flattened|` in units in the last place of the flattened t, over rays that
    /// hit the same triangle: median, 99.9th percentile, largest.
    pub t_ulps_median: f64,
    pub t_ulps_p999: f64,
    pub t_ulps_max: f64,
}

/// Flattened builds past this many triangles are estimated, not built (memory and time).
pub const FLATTEN_LIMIT: u64 = 40_000_000;

/// Harness settings.
#[derive(Clone, Debug)]
pub struct Settings {
    pub width: u32,
    pub passes: usize,
    pub seed: u64,
    pub build_repeats: usize,
    /// Keep the ray sets in the result (for dumping).
    pub keep_rays: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Self { width: 1024, passes: 7, seed: 1, build_repeats: 5, keep_rays: false }
    }
}

/// A scene built by both engines, ready for rays.
struct Built<'a, Q: Query> {
    scene: &'a Q,
    escene: &'a embree::Scene,
    world: &'a dyn accuracy::World,
    bounds: Option<(Vec3, Vec3)>,
    /// The flattened build of an instanced scene, to compare with.
    flat: Option<&'a Scene>,
    /// Secondary rays leave the surface by `offset_ray_origin` instead of BENCHMARKING.md's
    /// `tnear = 1e-4 × diagonal`, which in a world 900 units across skips the first 0.09 units of
    /// every ray (instanced scenes are not in BENCHMARKING.md's table).
    normal_offset: bool,
    /// See [`flat_geometry_offsets`].
    geom_offsets: Vec<u32>,
}

/// Runs one scene through both engines.
pub fn run_scene(
    spec: &SceneSpec,
    pool: &rayon::ThreadPool,
    device: &embree::Device,
    settings: &Settings,
    mut progress: impl FnMut(&str),
) -> anyhow::Result<SceneResult> {
    progress("loading");
    if let Some(file) = spec.scene_file()? {
        return run_instanced(spec, &file, pool, device, settings, progress);
    }
    let meshes = spec.load()?;
    let triangles: usize = meshes.iter().map(|m| m.triangle_count()).sum();

    // Builds: each engine on the same 2 threads, in interleaved rounds (BENCHMARKING.md's rule
    // for passes), best of each.
    progress("building");
    let (mut scene, mut escene, mut high) = (None, None, None);
    let [strahl_ms, embree_ms, embree_high_ms, strahl_high_ms] = build_rounds(
        settings.build_repeats,
        [
            &mut || {
                let s = pool.install(|| Scene::build(meshes.clone(), &BuildConfig::default()))?;
                let ms = s.stats().build_ms;
                scene = Some(s);
                Ok(ms)
            },
            &mut || {
                let e = embree::Scene::build(device, &meshes, embree::Quality::Medium, false)?;
                let ms = e.build_ms;
                escene = Some(e);
                Ok(ms)
            },
            &mut || Ok(embree::Scene::build(device, &meshes, embree::Quality::High, false)?.build_ms),
            &mut || {
                let s = pool.install(|| Scene::build(meshes.clone(), &BuildConfig::high()))?;
                let ms = s.stats().build_ms;
                high = Some(s);
                Ok(ms)
            },
        ],
    )?;
    let (Some(scene), Some(escene), Some(high)) = (scene, escene, high) else {
        unreachable!("build_rounds runs every build at least once")
    };
    let hs = high.stats();
    let st = scene.stats();
    let build = BuildResult {
        strahl_ms,
        embree_ms,
        embree_high_ms,
        strahl_high_ms,
        strahl_high_sah: hs.sah,
        strahl_high_bytes_per_tri: hs.bytes_per_triangle,
        strahl_high_references: hs.references,
        strahl_sah: st.sah,
        strahl_bytes_per_tri: st.bytes_per_triangle,
        strahl_bytes: st.bytes,
        strahl_inner_nodes: st.inner_nodes,
        strahl_leaves: st.leaves,
        strahl_depth: st.depth,
        embree_bytes_per_tri: None,
        embree_sah: None,
        embree_high_sah: None,
        embree_high_bytes_per_tri: None,
        strahl_skipped_triangles: st.skipped_triangles,
        embree_all_triangles: None,
    };
    let ((eye, at), light) = spec.view_and_light(scene.bounds());
    let camera = Camera::look_at(eye, at, Vec3::Y, 60.0);
    let world = accuracy::Flat(&meshes);
    let built = Built {
        scene: &scene,
        escene: &escene,
        world: &world,
        bounds: scene.bounds(),
        flat: None,
        normal_offset: false,
        geom_offsets: Vec::new(),
    };
    let (classes, ray_sets, image) = run_rays(&built, &camera, light, pool, settings, progress);
    Ok(SceneResult {
        name: spec.name.clone(),
        triangles,
        build,
        classes,
        instanced: None,
        image,
        width: settings.width,
        ray_sets,
    })
}

/// Build rounds stop once they have taken this long in all (after the least number asked for).
const BUILD_BUDGET: Duration = Duration::from_millis(300);

/// At most this many build rounds.
const MAX_BUILD_ROUNDS: usize = 200;

/// Times `builds` (each returns its build time in ms) in interleaved rounds, as the tracing passes
/// are: every round runs each build once, starting one build later than the round before. At
/// least `min_rounds` rounds, then more while all rounds so far took less than [`BUILD_BUDGET`]
/// (at most [`MAX_BUILD_ROUNDS`]): builds of microseconds are timed up to 200 times, those of
/// seconds `min_rounds` times. Returns each build's least time.
fn build_rounds<const N: usize>(
    min_rounds: usize,
    builds: [&mut dyn FnMut() -> anyhow::Result<f64>; N],
) -> anyhow::Result<[f64; N]> {
    let start = Instant::now();
    let mut best = [f64::INFINITY; N];
    let mut round = 0;
    while round < min_rounds.max(1) || (start.elapsed() < BUILD_BUDGET && round < MAX_BUILD_ROUNDS) {
        for k in 0..N {
            let i = (round + k) % N;
            best[i] = best[i].min(builds[i]()?);
        }
        round += 1;
    }
    Ok(best)
}

/// Runs one instanced scene (a scene file) through both engines, and through strahl flattened
/// where that fits.
fn run_instanced(
    spec: &SceneSpec,
    file: &strahl::SceneFile,
    pool: &rayon::ThreadPool,
    device: &embree::Device,
    settings: &Settings,
    mut progress: impl FnMut(&str),
) -> anyhow::Result<SceneResult> {
    if file.load_spheres()?.iter().any(|s| !s.is_empty()) {
        anyhow::bail!(
            "{}: analytic spheres are compared by `compare --spheres` (against Embree's SPHERE_POINT) and \
             rendered by `compare --render`; the scene-file harness compares triangle scenes",
            file.path.display()
        );
    }
    if file.load_solids().iter().any(|s| !s.is_empty()) {
        anyhow::bail!(
            "{}: solids are rendered by `compare --render` (Embree tracing them as user geometry) and their \
             solvers measured by `compare --torus`; the scene-file harness compares triangle scenes",
            file.path.display()
        );
    }
    let objects = file.load_objects()?;
    progress("building");
    let cfg = BuildConfig::default();
    let xfms: Vec<(usize, [f32; 12])> = file.instances.iter().map(|i| (i.object, column_major(&i.transform))).collect();
    let (mut scene, mut escene) = (None, None);
    let [strahl_ms, embree_ms] = build_rounds(
        settings.build_repeats,
        [
            &mut || {
                let s = pool.install(|| InstancedScene::build(objects.clone(), file.instances.clone(), &cfg))?;
                let ms = s.stats().objects_build_ms + s.stats().top_build_ms;
                scene = Some(s);
                Ok(ms)
            },
            &mut || {
                let e = embree::Scene::build_instanced(device, &objects, &xfms, embree::Quality::Medium)?;
                let ms = e.build_ms;
                escene = Some(e);
                Ok(ms)
            },
        ],
    )?;
    let (Some(scene), Some(escene)) = (scene, escene) else {
        unreachable!("build_rounds runs every build at least once")
    };
    let st = scene.stats().clone();
    let flat = if st.instanced_triangles <= FLATTEN_LIMIT {
        progress("flattening");
        Some(pool.install(|| scene.flatten(&cfg))?)
    } else {
        None
    };
    let instanced = InstancedInfo {
        instances: st.instances,
        instanced_triangles: st.instanced_triangles,
        unique_triangles: st.unique_triangles,
        memory_bytes: st.bytes,
        flattened_memory_bytes: flat.as_ref().map_or(st.flattened_bytes, |f| f.stats().bytes as u64),
        flattened_measured: flat.is_some(),
        flattened_build_ms: flat.as_ref().map(|f| f.stats().build_ms),
    };
    let object_stats: Vec<_> = scene.objects().iter().map(|o| o.stats().clone()).collect();
    let build = BuildResult {
        strahl_ms,
        embree_ms,
        embree_high_ms: f64::NAN,
        strahl_high_ms: f64::NAN,
        strahl_high_sah: f64::NAN,
        strahl_high_bytes_per_tri: f64::NAN,
        strahl_high_references: 0,
        strahl_sah: f64::NAN,
        strahl_bytes_per_tri: st.bytes as f64 / st.unique_triangles.max(1) as f64,
        strahl_bytes: st.bytes,
        strahl_inner_nodes: object_stats.iter().map(|s| s.inner_nodes).sum(),
        strahl_leaves: object_stats.iter().map(|s| s.leaves).sum(),
        strahl_depth: object_stats.iter().map(|s| s.depth).max().unwrap_or(0),
        embree_bytes_per_tri: None,
        embree_sah: None,
        embree_high_sah: None,
        embree_high_bytes_per_tri: None,
        strahl_skipped_triangles: object_stats.iter().map(|s| s.skipped_triangles).sum(),
        embree_all_triangles: None,
    };
    let bounds = scene.bounds();
    let camera = match &file.camera {
        Some(c) => c.camera(),
        None => {
            let ((eye, at), _) = spec.view_and_light(bounds);
            Camera::look_at(eye, at, Vec3::Y, 60.0)
        }
    };
    let light = file.lights.first().map_or(spec.view_and_light(bounds).1, |l| l.position);
    let world = accuracy::InstancedWorld::new(&objects, &file.instances);
    let built = Built {
        scene: &scene,
        escene: &escene,
        world: &world,
        bounds,
        flat: flat.as_ref(),
        normal_offset: true,
        geom_offsets: flat_geometry_offsets(&scene),
    };
    let (classes, ray_sets, image) = run_rays(&built, &camera, light, pool, settings, progress);
    Ok(SceneResult {
        name: spec.name.clone(),
        triangles: st.unique_triangles,
        build,
        classes,
        instanced: Some(instanced),
        image,
        width: settings.width,
        ray_sets,
    })
}

type RaySets = Vec<(Class, RayStream, Answers, Answers)>;

/// Generates the three ray classes from the camera and light, traces them through both engines
/// (and the flattened build, if any), and shades a picture.
fn run_rays<Q: Query>(
    b: &Built<'_, Q>,
    camera: &Camera,
    light: Vec3,
    pool: &rayon::ThreadPool,
    settings: &Settings,
    mut progress: impl FnMut(&str),
) -> (Vec<ClassResult>, RaySets, Vec<u8>) {
    // Ray sets, all derived from strahl's primary hits so both engines trace identical rays.
    let w = settings.width;
    let (primary, pixels) = raygen::primary(camera, w, w);
    let mut primary_hits = HitStream::default();
    pool.install(|| b.scene.intersect_stream_par(&primary, &mut primary_hits, Coherence::Coherent));
    let diag = b.bounds.map(|(lo, hi)| (hi - lo).length()).unwrap_or(1.0);
    let offset = if b.normal_offset { raygen::Offset::Normal } else { raygen::Offset::Epsilon(1e-4 * diag) };
    let (shadow, shadow_src) = raygen::shadow_with(&primary, &primary_hits, light, offset);
    let (diffuse, _) = raygen::diffuse_with(&primary, &primary_hits, settings.seed, offset);

    let mut classes = Vec::new();
    let mut ray_sets = Vec::new();
    let mut shadow_answers = None;
    for (class, rays) in [(Class::Primary, &primary), (Class::Shadow, &shadow), (Class::Diffuse, &diffuse)] {
        progress(class.name());
        let (mut result, s_ans, e_ans) = run_class(b.scene, b.escene, b.world, rays, class, pool, settings);
        if let Some(flat) = b.flat {
            let mut f_ans = Answers::misses(rays.len());
            pool.install(|| strahl_single(flat, rays, class, &mut f_ans));
            result.flat_agreement = Some(flat_agreement(&s_ans, &f_ans, &b.geom_offsets));
        }
        if class == Class::Shadow {
            shadow_answers = Some(s_ans.clone());
        }
        if settings.keep_rays {
            ray_sets.push((class, rays.clone(), s_ans, e_ans));
        }
        classes.push(result);
    }
    let image = shade(&primary, &primary_hits, &pixels, &shadow_src, shadow_answers.as_ref(), w);
    (classes, ray_sets, image)
}

/// The flattened geometry id of each instance's first mesh ([`InstancedScene::flatten`] numbers
/// meshes instance by instance).
pub fn flat_geometry_offsets(scene: &InstancedScene) -> Vec<u32> {
    scene
        .instances()
        .iter()
        .scan(0u32, |acc, i| {
            let first = *acc;
            *acc += scene.objects()[i.object].meshes().len() as u32;
            Some(first)
        })
        .collect()
}

/// Hit/miss agreement between instanced answers `a` and flattened answers `f` of the same rays,
/// how often both hit the same triangle, and the `t` difference in ulps where they do.
pub fn flat_agreement(a: &Answers, f: &Answers, geom_offsets: &[u32]) -> FlatAgreement {
    let n = a.len();
    let agree = (0..n).filter(|&i| a.hit(i) == f.hit(i)).count();
    let both: Vec<usize> = (0..n).filter(|&i| a.hit(i) && f.hit(i)).collect();
    let same = |i: usize| match geom_offsets.get(a.inst[i] as usize) {
        Some(&g0) => g0 + a.geom[i] == f.geom[i] && a.prim[i] == f.prim[i],
        // Occluded shadow rays carry no triangle.
        None => true,
    };
    let same_rays: Vec<usize> = both.iter().copied().filter(|&i| same(i)).collect();
    let mut ulps: Vec<f64> = same_rays
        .iter()
        .filter(|&&i| f.t[i] > 0.0)
        .map(|&i| (a.t[i] as f64 - f.t[i] as f64).abs() / (f.t[i].next_up() - f.t[i]) as f64)
        .collect();
    ulps.sort_by(f64::total_cmp);
    let q = |x: f64| if ulps.is_empty() { 0.0 } else { ulps[((ulps.len() - 1) as f64 * x).round() as usize] };
    FlatAgreement {
        rays: n,
        hit_miss_agreement: if n == 0 { 1.0 } else { agree as f64 / n as f64 },
        same_triangle: if both.is_empty() { 1.0 } else { same_rays.len() as f64 / both.len() as f64 },
        t_ulps_median: q(0.5),
        t_ulps_p999: q(0.999),
        t_ulps_max: ulps.last().copied().unwrap_or(0.0),
    }
}

/// Traces one ray set through all APIs of both engines in both modes, interleaved pass by pass
/// (each pass: kernel mode, then as-called; in each, per API, the engines in alternating order),
/// and diffs the answers (those of kernel mode, read back after each timed call).
fn run_class<Q: Query>(
    scene: &Q,
    escene: &embree::Scene,
    world: &dyn accuracy::World,
    rays: &RayStream,
    class: Class,
    pool: &rayon::ThreadPool,
    settings: &Settings,
) -> (ClassResult, Answers, Answers) {
    let n = rays.len();
    let mut samples: [[[Samples; 3]; 2]; 2] = Default::default();
    let mut answers: [[Answers; 3]; 2] = std::array::from_fn(|_| std::array::from_fn(|_| Answers::misses(n)));
    // Native inputs of kernel mode, and the as-called mode's answer arrays and Embree's stream
    // records (allocated here, filled in the timed region), all prepared before any timing.
    let mut sn = StrahlNative::new(rays);
    let mut en = EmbreeNative::new(rays);
    let mut scratch = Answers::misses(n);
    let mut work_rh = vec![RTCRayHit::default(); if class.occlusion() { 0 } else { n }];
    let mut work_r = vec![RTCRay::default(); if class.occlusion() { n } else { 0 }];
    let mut hits = HitStream::default();
    let mut occ = Vec::new();
    for pass in 0..=settings.passes {
        for mode in Mode::ALL {
            for api in Api::ALL {
                // Alternate which engine goes first, so neither always runs on a warmer cache.
                let order = if pass % 2 == 0 { [0, 1] } else { [1, 0] };
                for engine in order {
                    if mode == Mode::Kernel && engine == 1 {
                        en.refresh(class, api as usize);
                    }
                    let start = Instant::now();
                    pool.install(|| match (mode, engine, api) {
                        (Mode::Kernel, 0, Api::Single) => sn.single(scene, class),
                        (Mode::Kernel, 0, Api::Packet) => sn.packet(scene, class),
                        (Mode::Kernel, 0, Api::Stream) => sn.stream(scene, class),
                        (Mode::Kernel, _, Api::Single) => en.single(escene, class),
                        (Mode::Kernel, _, Api::Packet) => en.packet(escene, class),
                        (Mode::Kernel, _, Api::Stream) => en.stream(escene, class),
                        (Mode::AsCalled, 0, Api::Single) => strahl_single(scene, rays, class, &mut scratch),
                        (Mode::AsCalled, 0, Api::Packet) => strahl_packet(scene, rays, class, &mut scratch),
                        (Mode::AsCalled, 0, Api::Stream) => {
                            strahl_stream_as_called(scene, rays, class, &mut hits, &mut occ, &mut scratch)
                        }
                        (Mode::AsCalled, _, Api::Single) => embree_single(escene, rays, class, &mut scratch),
                        (Mode::AsCalled, _, Api::Packet) => embree_packet(escene, rays, class, &mut scratch),
                        (Mode::AsCalled, _, Api::Stream) => {
                            embree_stream_as_called(escene, rays, class, &mut work_rh, &mut work_r, &mut scratch)
                        }
                    });
                    let secs = start.elapsed().as_secs_f64();
                    if pass > 0 {
                        samples[mode as usize][engine][api as usize].seconds.push(secs);
                    }
                    // Read kernel mode's answers back (not timed).
                    if mode == Mode::Kernel && (pass == 0 || pass == settings.passes) {
                        let out = &mut answers[engine][api as usize];
                        if engine == 0 {
                            sn.answers(class, api as usize, out);
                        } else {
                            en.answers(class, api as usize, out);
                        }
                    }
                }
            }
        }
    }
    let [s, e] = answers;
    let consistent = |a: &[Answers; 3]| {
        let same = (0..n).filter(|&i| (1..3).all(|k| a[k].key(i) == a[0].key(i))).count();
        if n == 0 { 1.0 } else { same as f64 / n as f64 }
    };
    let strahl_apis_consistent = consistent(&s);
    let embree_apis_consistent = consistent(&e);
    let [s_single, _, _] = s;
    let [e_single, _, _] = e;
    let acc = accuracy::compare(world, rays, class.occlusion(), &s_single, &e_single);
    let hit_rate = if n == 0 { 0.0 } else { (0..n).filter(|&i| s_single.hit(i)).count() as f64 / n as f64 };
    let result = ClassResult {
        class,
        rays: n,
        hit_rate,
        accuracy: acc,
        samples,
        strahl_apis_consistent,
        embree_apis_consistent,
        flat_agreement: None,
    };
    (result, s_single, e_single)
}

pub(crate) fn coherence(class: Class) -> Coherence {
    if class.coherent() { Coherence::Coherent } else { Coherence::Incoherent }
}

/// A miss, and an occluded shadow ray (whose primitive any-hit queries do not report).
const MISS: (f32, u32, u32, u32) = (f32::INFINITY, INVALID_ID, INVALID_ID, INVALID_ID);
const OCCLUDED: (f32, u32, u32, u32) = (0.0, 0, 0, INVALID_ID);

pub(crate) fn occlusion_answer(o: bool) -> (f32, u32, u32, u32) {
    if o { OCCLUDED } else { MISS }
}

pub(crate) fn hit_answer(h: Option<strahl::Hit>) -> (f32, u32, u32, u32) {
    h.map_or(MISS, |h| (h.t, h.geom_id, h.prim_id, h.inst_id))
}

pub(crate) fn embree_answer(t: f32, geom: u32, prim: u32, inst: u32) -> (f32, u32, u32, u32) {
    if geom != RTC_INVALID_GEOMETRY_ID { (t, geom, prim, inst) } else { MISS }
}

pub(crate) fn strahl_single<Q: Query>(scene: &Q, rays: &RayStream, class: Class, out: &mut Answers) {
    out.par_fill(|start, o| {
        for k in 0..o.len() {
            let r = rays.get(start + k);
            o.set(
                k,
                if class.occlusion() { occlusion_answer(scene.occluded(&r)) } else { hit_answer(scene.intersect(&r)) },
            );
        }
    });
}

pub(crate) fn strahl_packet<Q: Query>(scene: &Q, rays: &RayStream, class: Class, out: &mut Answers) {
    out.par_fill(|start, o| {
        let mut hp = HitPacket::default();
        for k in (0..o.len()).step_by(PACKET_WIDTH) {
            let m = (o.len() - k).min(PACKET_WIDTH);
            let packet = rays.packet(start + k, m);
            if class.occlusion() {
                let bits = scene.occluded_packet(&packet);
                for l in 0..m {
                    o.set(k + l, occlusion_answer(bits & (1 << l) != 0));
                }
            } else {
                scene.intersect_packet(&packet, &mut hp);
                o.t[k..k + m].copy_from_slice(&hp.t[..m]);
                o.geom[k..k + m].copy_from_slice(&hp.geom_id[..m]);
                o.prim[k..k + m].copy_from_slice(&hp.prim_id[..m]);
                o.inst[k..k + m].copy_from_slice(&hp.inst_id[..m]);
            }
        }
    });
}

fn strahl_stream<Q: Query>(scene: &Q, rays: &RayStream, class: Class, hits: &mut HitStream, occ: &mut Vec<bool>) {
    if class.occlusion() {
        scene.occluded_stream_par(rays, occ, coherence(class));
    } else {
        scene.intersect_stream_par(rays, hits, coherence(class));
    }
}

/// Embree's `FLT_LARGE` (1.844e18): its `ray.valid()` asserts that no origin or direction
/// component exceeds it in magnitude (an abort, in Debian's build).
pub const EMBREE_LARGE: f32 = 1.844e18;

/// Whether Embree accepts rays with these components (strahl's validity aside).
#[inline]
fn embree_range(o: [f32; 3], d: [f32; 3]) -> bool {
    o.iter().chain(&d).all(|x| x.abs() <= EMBREE_LARGE)
}

/// Ray `i` of `rays` as Embree's single-ray struct (mask all ones, id `i`), under strahl's rules
/// for bad rays, which Embree's own checks would abort on (`ray.valid()`): a negative `tnear`
/// counts as 0, and a ray strahl calls invalid (NaN or infinite fields, a zero direction,
/// `tnear > tfar`) becomes an empty interval at the origin, which misses and is not occluded. So
/// does a ray outside Embree's range (a component beyond [`EMBREE_LARGE`]); strahl answers those
/// itself (its slab terms saturate), so the two engines may differ there.
#[inline]
pub fn embree_ray(rays: &RayStream, i: usize) -> RTCRay {
    embree_ray_of(&rays.get(i), i as u32)
}

/// [`embree_ray`] of one ray, with id `id`.
#[inline]
pub fn embree_ray_of(r: &strahl::Ray, id: u32) -> RTCRay {
    let (o, d, tnear, tfar) = if r.is_valid() && embree_range(r.origin.to_array(), r.dir.to_array()) {
        (r.origin, r.dir, r.tnear.max(0.0), r.tfar)
    } else {
        (Vec3::ZERO, Vec3::Z, 0.0, 0.0)
    };
    RTCRay {
        org_x: o.x,
        org_y: o.y,
        org_z: o.z,
        tnear,
        dir_x: d.x,
        dir_y: d.y,
        dir_z: d.z,
        time: 0.0,
        tfar,
        mask: u32::MAX,
        id,
        flags: 0,
    }
}

/// Embree's hit struct before a query: every id invalid.
pub fn empty_hit() -> RTCHit {
    RTCHit {
        geomID: RTC_INVALID_GEOMETRY_ID,
        primID: RTC_INVALID_GEOMETRY_ID,
        instID: [RTC_INVALID_GEOMETRY_ID],
        ..Default::default()
    }
}

/// Embree's single-ray API fed from the SoA stream as a caller would, in the best way its API
/// allows: each run of 16 rays is converted into a small array of records first and traced
/// after, so that `rtcIntersect1`'s wide loads never wait on the stores that just wrote the
/// record (a record built field by field right before each call cost Embree up to a third of its
/// speed: issue 28).
pub(crate) fn embree_single(scene: &embree::Scene, rays: &RayStream, class: Class, out: &mut Answers) {
    let coherent = class.coherent();
    out.par_fill(|start, o| {
        let mut rh = [RTCRayHit::default(); 16];
        for k in (0..o.len()).step_by(16) {
            let m = (o.len() - k).min(16);
            for (l, x) in rh[..m].iter_mut().enumerate() {
                *x = RTCRayHit { ray: embree_ray(rays, start + k + l), hit: empty_hit() };
            }
            for (l, x) in rh[..m].iter_mut().enumerate() {
                if class.occlusion() {
                    scene.occluded1(&mut x.ray, coherent);
                    o.set(k + l, occlusion_answer(x.ray.tfar == f32::NEG_INFINITY));
                } else {
                    scene.intersect1(x, coherent);
                    o.set(k + l, embree_answer(x.ray.tfar, x.hit.geomID, x.hit.primID, x.hit.instID[0]));
                }
            }
        }
    });
}

/// Embree's 16-ray API fed from the SoA stream as a caller would: each field copied into the
/// packet 16 floats at a time (as `RayStream::packet` fills strahl's), then strahl's rules for
/// bad rays applied lane by lane (see [`embree_ray`]).
pub(crate) fn embree_packet(scene: &embree::Scene, rays: &RayStream, class: Class, out: &mut Answers) {
    let coherent = class.coherent();
    out.par_fill(|start, o| {
        let mut rh = Box::new(crate::kernel::empty_packet());
        for k in (0..o.len()).step_by(16) {
            let m = (o.len() - k).min(16);
            let i = start + k;
            let r = &mut rh.ray;
            r.org_x[..m].copy_from_slice(&rays.ox[i..i + m]);
            r.org_y[..m].copy_from_slice(&rays.oy[i..i + m]);
            r.org_z[..m].copy_from_slice(&rays.oz[i..i + m]);
            r.tnear[..m].copy_from_slice(&rays.tnear[i..i + m]);
            r.dir_x[..m].copy_from_slice(&rays.dx[i..i + m]);
            r.dir_y[..m].copy_from_slice(&rays.dy[i..i + m]);
            r.dir_z[..m].copy_from_slice(&rays.dz[i..i + m]);
            r.tfar[..m].copy_from_slice(&rays.tfar[i..i + m]);
            let valid: [i32; 16] = std::array::from_fn(|l| {
                let ok = l < m && {
                    let f = |x: f32| x.is_finite();
                    let d = [r.dir_x[l], r.dir_y[l], r.dir_z[l]];
                    f(r.org_x[l])
                        && f(r.org_y[l])
                        && f(r.org_z[l])
                        && d.iter().all(|&x| f(x))
                        && d.iter().any(|x| x.abs() >= strahl::ray::MIN_DIRECTION)
                        && r.tnear[l] <= r.tfar[l]
                        && embree_range([r.org_x[l], r.org_y[l], r.org_z[l]], d)
                };
                -(ok as i32)
            });
            for t in &mut r.tnear {
                *t = t.max(0.0);
            }
            if class.occlusion() {
                scene.occluded16(&valid, &mut rh.ray, coherent);
                for l in 0..m {
                    o.set(k + l, occlusion_answer(valid[l] != 0 && rh.ray.tfar[l] == f32::NEG_INFINITY));
                }
            } else {
                rh.hit.geomID = [RTC_INVALID_GEOMETRY_ID; 16];
                rh.hit.instID = [[RTC_INVALID_GEOMETRY_ID; 16]];
                scene.intersect16(&valid, &mut rh, coherent);
                for l in 0..m {
                    let h = &rh.hit;
                    o.set(k + l, embree_answer(rh.ray.tfar[l], h.geomID[l], h.primID[l], h.instID[0][l]));
                }
            }
        }
    });
}

/// Embree's stream API fed from the SoA stream as a caller would: the records converted into
/// `rh` / `r` (allocated by the caller beforehand, `rays.len()` long) chunk by chunk in parallel,
/// traced, and the answers read into `out` in parallel.
fn embree_stream_as_called(
    scene: &embree::Scene,
    rays: &RayStream,
    class: Class,
    rh: &mut [RTCRayHit],
    r: &mut [RTCRay],
    out: &mut Answers,
) {
    if class.occlusion() {
        r.par_chunks_mut(CHUNK).enumerate().with_max_len(1).for_each(|(c, ch)| {
            for (k, x) in ch.iter_mut().enumerate() {
                *x = embree_ray(rays, c * CHUNK + k);
            }
        });
    } else {
        rh.par_chunks_mut(CHUNK).enumerate().with_max_len(1).for_each(|(c, ch)| {
            for (k, x) in ch.iter_mut().enumerate() {
                *x = RTCRayHit { ray: embree_ray(rays, c * CHUNK + k), hit: empty_hit() };
            }
        });
    }
    embree_stream(scene, class, rh, r);
    let (rh, r) = (&*rh, &*r);
    out.par_fill(|start, o| {
        for k in 0..o.len() {
            let i = start + k;
            o.set(
                k,
                if class.occlusion() {
                    occlusion_answer(r[i].tfar == f32::NEG_INFINITY)
                } else {
                    embree_answer(rh[i].ray.tfar, rh[i].hit.geomID, rh[i].hit.primID, rh[i].hit.instID[0])
                },
            );
        }
    });
}

/// strahl's stream API fed from the caller's SoA stream, its answers read into `out` in parallel.
fn strahl_stream_as_called<Q: Query>(
    scene: &Q,
    rays: &RayStream,
    class: Class,
    hits: &mut HitStream,
    occ: &mut Vec<bool>,
    out: &mut Answers,
) {
    strahl_stream(scene, rays, class, hits, occ);
    let (hits, occ) = (&*hits, &*occ);
    out.par_fill(|start, o| {
        for k in 0..o.len() {
            let i = start + k;
            o.set(k, if class.occlusion() { occlusion_answer(occ[i]) } else { hit_answer(hits.get(i)) });
        }
    });
}

fn embree_stream(scene: &embree::Scene, class: Class, rh: &mut [RTCRayHit], r: &mut [RTCRay]) {
    let coherent = class.coherent();
    if class.occlusion() {
        r.par_chunks_mut(CHUNK).with_max_len(1).for_each(|c| scene.occluded1m(c, coherent));
    } else {
        rh.par_chunks_mut(CHUNK).with_max_len(1).for_each(|c| scene.intersect1m(c, coherent));
    }
}

/// Eye-light shading of the primary hits, darkened where the shadow ray was occluded.
fn shade(
    rays: &RayStream,
    hits: &HitStream,
    pixels: &[u32],
    shadow_src: &[u32],
    shadow: Option<&Answers>,
    w: u32,
) -> Vec<u8> {
    let mut lit = vec![true; rays.len()];
    if let Some(s) = shadow {
        for (k, &src) in shadow_src.iter().enumerate() {
            lit[src as usize] = !s.hit(k);
        }
    }
    let mut img = vec![0u8; (w * w * 3) as usize];
    for i in 0..rays.len() {
        let px = pixels[i] as usize * 3;
        let rgb = match hits.get(i) {
            Some(h) => {
                let c = h.ng.normalize_or_zero().dot(rays.get(i).dir.normalize_or_zero()).abs();
                let v = (0.1 + 0.9 * c * if lit[i] { 1.0 } else { 0.35 }).clamp(0.0, 1.0);
                let g = (v * 255.0) as u8;
                [g, g, (v * 235.0 + 20.0).min(255.0) as u8]
            }
            None => [24, 28, 40],
        };
        img[px..px + 3].copy_from_slice(&rgb);
    }
    img
}

/// Traces `rays` once with each engine's single-ray API (for ray files and tests).
pub fn trace_once<Q: Query>(
    scene: &Q,
    escene: &embree::Scene,
    rays: &RayStream,
    class: Class,
    pool: &rayon::ThreadPool,
) -> (Answers, Answers) {
    let mut s = Answers::misses(rays.len());
    let mut e = Answers::misses(rays.len());
    pool.install(|| {
        strahl_single(scene, rays, class, &mut s);
        embree_single(escene, rays, class, &mut e);
    });
    (s, e)
}

/// One row of the translation sweep: a class of rays at one translation.
#[derive(Clone, Debug, Serialize)]
pub struct TranslationRow {
    pub translation: f64,
    pub class: &'static str,
    pub agreement: FlatAgreement,
}

/// Translations of the sweep: the world, camera and light moved by `(T, T, T)`.
pub const TRANSLATIONS: [f32; 7] = [1.0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6];

/// Builds the scene file's world instanced and flattened at every translation of
/// [`TRANSLATIONS`] and compares the two on primary, shadow and diffuse rays (`width²` primary
/// rays; secondary rays leave the surface by `offset_ray_origin`, which scales with the
/// coordinates, so the epsilon does not decide the outcome far out).
pub fn translation_sweep(
    file: &strahl::SceneFile,
    pool: &rayon::ThreadPool,
    width: u32,
    seed: u64,
) -> anyhow::Result<Vec<TranslationRow>> {
    let objects = file.load_objects()?;
    let cam = file.camera.ok_or_else(|| anyhow::anyhow!("{}: the sweep needs a camera", file.path.display()))?;
    let light = file.lights.first().map_or(cam.eye, |l| l.position);
    let cfg = BuildConfig::default();
    let mut rows = Vec::new();
    for &t in &TRANSLATIONS {
        let shift = Vec3::splat(t);
        let m = glam::Affine3A::from_translation(shift);
        let instances: Vec<strahl::Instance> =
            file.instances.iter().map(|i| strahl::Instance::new(i.object, m * i.transform)).collect();
        let scene = pool.install(|| InstancedScene::build(objects.clone(), instances, &cfg))?;
        let flat = pool.install(|| scene.flatten(&cfg))?;
        let offsets = flat_geometry_offsets(&scene);
        let camera = Camera::look_at(cam.eye + shift, cam.look_at + shift, cam.up, cam.fov_deg);
        let (primary, _) = raygen::primary(&camera, width, width);
        let mut hits = HitStream::default();
        pool.install(|| scene.intersect_stream_par(&primary, &mut hits, Coherence::Coherent));
        let (shadow, _) = raygen::shadow_with(&primary, &hits, light + shift, raygen::Offset::Normal);
        let (diffuse, _) = raygen::diffuse_with(&primary, &hits, seed, raygen::Offset::Normal);
        for (class, rays) in [(Class::Primary, &primary), (Class::Shadow, &shadow), (Class::Diffuse, &diffuse)] {
            let mut a = Answers::misses(rays.len());
            let mut f = Answers::misses(rays.len());
            pool.install(|| {
                strahl_single(&scene, rays, class, &mut a);
                strahl_single(&flat, rays, class, &mut f);
            });
            let agreement = flat_agreement(&a, &f, &offsets);
            rows.push(TranslationRow { translation: t as f64, class: class.name(), agreement });
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embree_stats_split_at_the_same_triangles_mark() {
        let line = |sah: f64, b: f64| {
            format!(
                "  total            : sah =  {sah:.3} (100.00%), #bytes =   1.00 MB (100.00%), #bytes/prim =  {b:.2}\n"
            )
        };
        let noise = "  total : used =  22.001 MB, free =   0.122 MB, #bytes/prim =  66.81\n";
        let all = format!("{}{noise}{}", line(11.101, 64.19), line(11.133, 66.68));
        let s = parse_embree_stats(&all).unwrap();
        assert_eq!(s.all[0], EmbreeTreeStats { sah: 11.101, bytes_per_tri: 64.19 });
        assert_eq!(s.all[1], EmbreeTreeStats { sah: 11.133, bytes_per_tri: 66.68 });
        assert_eq!(s.same_triangles, None);
        let both = format!("{all}{SAME_TRIANGLES_MARK}\n{}{}", line(11.5, 63.27), line(11.499, 66.24));
        let s = parse_embree_stats(&both).unwrap();
        assert_eq!(s.all[0].sah, 11.101);
        assert_eq!(s.same_triangles.unwrap()[0], EmbreeTreeStats { sah: 11.5, bytes_per_tri: 63.27 });
        let mut b = BuildResult::default();
        b.set_embree_stats(&s);
        assert_eq!((b.embree_sah, b.embree_high_sah), (Some(11.5), Some(11.499)));
        assert_eq!(b.embree_all_triangles.unwrap()[0].sah, 11.101);
        assert!(parse_embree_stats(&line(1.0, 2.0)).is_none(), "one build is not a MEDIUM and HIGH pair");
    }

    #[test]
    fn hittable_meshes_drop_exactly_the_unhittable_triangles() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(2.0, 0.0, 0.0)];
        let m = TriangleMesh::new("m", p, vec![[0, 1, 2], [0, 1, 3], [2, 1, 0]]).unwrap();
        let h = hittable_meshes(&[m]).unwrap();
        assert_eq!(h[0].indices(), &[[0, 1, 2], [2, 1, 0]]);
    }
}
