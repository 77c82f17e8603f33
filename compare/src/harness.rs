//! One side-by-side run: build both engines on the same meshes, generate the three ray classes of
//! BENCHMARKING.md, trace the same rays through every API of both engines on one pool of worker
//! threads (FTZ/DAZ set on each), time interleaved passes, and diff the answers.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;
use strahl::{
    BuildConfig, Camera, Coherence, HitPacket, HitStream, INVALID_ID, PACKET_WIDTH, Query, RayStream, Scene,
    TriangleMesh, raygen,
};

use crate::accuracy::{self, Accuracy};
use crate::embree::{self, RTC_INVALID_GEOMETRY_ID, RTCHit, RTCHit16, RTCRay, RTCRay16, RTCRayHit, RTCRayHit16};
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

/// Per-ray answers of one engine: `t` (+inf for a miss; 0 for an occluded shadow ray) and ids
/// (`INVALID_ID` for a miss; geometry 0 for an occluded shadow ray, whose primitive is unknown).
#[derive(Clone, Debug, PartialEq)]
pub struct Answers {
    pub t: Vec<f32>,
    pub geom: Vec<u32>,
    pub prim: Vec<u32>,
}

impl Answers {
    pub fn misses(n: usize) -> Self {
        Self { t: vec![f32::INFINITY; n], geom: vec![INVALID_ID; n], prim: vec![INVALID_ID; n] }
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

    /// Runs `f(start, t, geom, prim)` over chunks of [`CHUNK`] entries in parallel.
    fn par_fill(&mut self, f: impl Fn(usize, &mut [f32], &mut [u32], &mut [u32]) + Sync) {
        (self.t.par_chunks_mut(CHUNK), self.geom.par_chunks_mut(CHUNK), self.prim.par_chunks_mut(CHUNK))
            .into_par_iter()
            .enumerate()
            .for_each(|(k, (t, g, p))| f(k * CHUNK, t, g, p));
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
    /// `[engine][api]`, engine 0 = strahl, 1 = Embree.
    pub samples: [[Samples; 3]; 2],
    /// Whether each engine's packet and stream answers equal its single-ray answers.
    pub strahl_apis_consistent: f64,
    pub embree_apis_consistent: f64,
}

impl ClassResult {
    pub fn mrays(&self, engine: usize, api: Api, median: bool) -> f64 {
        let s = &self.samples[engine][api as usize];
        let secs = if median { s.median() } else { s.best() };
        if secs > 0.0 && secs.is_finite() { self.rays as f64 / secs / 1e6 } else { 0.0 }
    }

    /// The fastest API of an engine by best time, with its Mrays/s.
    pub fn best(&self, engine: usize) -> (Api, f64) {
        Api::ALL
            .iter()
            .map(|&a| (a, self.mrays(engine, a, false)))
            .fold((Api::Single, 0.0), |b, x| if x.1 > b.1 { x } else { b })
    }

    pub fn best_ratio(&self) -> f64 {
        let (e, s) = (self.best(1).1, self.best(0).1);
        if e > 0.0 { s / e } else { 0.0 }
    }
}

/// Build figures of both engines.
#[derive(Clone, Debug, Default, Serialize)]
pub struct BuildResult {
    pub strahl_ms: f64,
    pub embree_ms: f64,
    pub embree_high_ms: f64,
    pub strahl_sah: f64,
    pub strahl_bytes_per_tri: f64,
    pub strahl_bytes: usize,
    pub strahl_inner_nodes: usize,
    pub strahl_leaves: usize,
    pub strahl_depth: usize,
    /// Embree's own statistics (`verbose=2`, read from a child process): SAH cost and BVH bytes
    /// per triangle at MEDIUM, SAH at HIGH. `None` if they could not be read.
    pub embree_bytes_per_tri: Option<f64>,
    pub embree_sah: Option<f64>,
    pub embree_high_sah: Option<f64>,
}

/// Embree's BVH statistics for a scene, as `[(sah, bytes per primitive)]` for MEDIUM then HIGH:
/// Embree 3 has no API for them, but prints them on a `verbose=2` device, so the harness runs
/// itself as a child (`--embree-stats-of`) and reads the `total : sah = …, #bytes/prim = …` lines.
pub fn embree_stats(spec: &SceneSpec, threads: usize) -> Option<Vec<(f64, f64)>> {
    let arg = match &spec.source {
        crate::scenes::Source::Obj(p) => p.to_string_lossy().into_owned(),
        crate::scenes::Source::Sphereflake { .. } => "sphereflake".to_string(),
    };
    let exe = std::env::current_exe().ok()?;
    let out = std::process::Command::new(exe)
        .args(["--threads", &threads.to_string(), "--embree-stats-of", &arg])
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&out.stdout);
    let stats: Vec<(f64, f64)> = text
        .lines()
        .filter(|l| l.trim_start().starts_with("total") && l.contains("sah =") && l.contains("#bytes/prim"))
        .filter_map(|l| {
            let num =
                |key: &str| l.split(key).nth(1)?.split_whitespace().next()?.trim_end_matches(',').parse::<f64>().ok();
            Some((num("sah =")?, num("#bytes/prim =")?))
        })
        .collect();
    (stats.len() >= 2).then_some(stats)
}

pub struct SceneResult {
    pub name: String,
    pub triangles: usize,
    pub build: BuildResult,
    pub classes: Vec<ClassResult>,
    /// A shaded picture of the primary hits (RGB, `width × width`).
    pub image: Vec<u8>,
    pub width: u32,
    /// The ray sets and strahl's and Embree's answers, for `--dump-rays`.
    pub ray_sets: Vec<(Class, RayStream, Answers, Answers)>,
}

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
        Self { width: 1024, passes: 5, seed: 1, build_repeats: 3, keep_rays: false }
    }
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
    let meshes = spec.load()?;
    let triangles: usize = meshes.iter().map(|m| m.triangle_count()).sum();

    // Builds: best of a few, each engine on the same 2 threads.
    progress("building");
    let mut scene = None;
    let mut strahl_ms = f64::INFINITY;
    for _ in 0..settings.build_repeats.max(1) {
        let s = pool.install(|| Scene::build(meshes.clone(), &BuildConfig::default()))?;
        strahl_ms = strahl_ms.min(s.stats().build_ms);
        scene = Some(s);
    }
    let scene = scene.expect("built at least once");
    let mut embree_ms = f64::INFINITY;
    let mut escene = None;
    for _ in 0..settings.build_repeats.max(1) {
        let e = embree::Scene::build(device, &meshes, embree::Quality::Medium, false)?;
        embree_ms = embree_ms.min(e.build_ms);
        escene = Some(e);
    }
    let escene = escene.expect("built at least once");
    let embree_high_ms = embree::Scene::build(device, &meshes, embree::Quality::High, false)?.build_ms;
    let st = scene.stats();
    let build = BuildResult {
        strahl_ms,
        embree_ms,
        embree_high_ms,
        strahl_sah: st.sah,
        strahl_bytes_per_tri: st.bytes_per_triangle,
        strahl_bytes: st.bytes,
        strahl_inner_nodes: st.inner_nodes,
        strahl_leaves: st.leaves,
        strahl_depth: st.depth,
        embree_bytes_per_tri: None,
        embree_sah: None,
        embree_high_sah: None,
    };

    // Ray sets, all derived from strahl's primary hits so both engines trace identical rays.
    let ((eye, at), light) = spec.view_and_light(scene.bounds());
    let camera = Camera::look_at(eye, at, Vec3::Y, 60.0);
    let w = settings.width;
    let (primary, pixels) = raygen::primary(&camera, w, w);
    let mut primary_hits = HitStream::default();
    pool.install(|| scene.intersect_stream_par(&primary, &mut primary_hits, Coherence::Coherent));
    let diag = scene.bounds().map(|(lo, hi)| (hi - lo).length()).unwrap_or(1.0);
    let eps = 1e-4 * diag;
    let (shadow, shadow_src) = raygen::shadow(&primary, &primary_hits, light, eps);
    let (diffuse, _) = raygen::diffuse(&primary, &primary_hits, settings.seed, eps);

    let mut classes = Vec::new();
    let mut ray_sets = Vec::new();
    let mut shadow_answers = None;
    for (class, rays) in [(Class::Primary, &primary), (Class::Shadow, &shadow), (Class::Diffuse, &diffuse)] {
        progress(class.name());
        let (result, s_ans, e_ans) = run_class(&scene, &escene, &meshes, rays, class, pool, settings);
        if class == Class::Shadow {
            shadow_answers = Some(s_ans.clone());
        }
        if settings.keep_rays {
            ray_sets.push((class, rays.clone(), s_ans, e_ans));
        }
        classes.push(result);
    }

    let image = shade(&primary, &primary_hits, &pixels, &shadow_src, shadow_answers.as_ref(), w);
    Ok(SceneResult { name: spec.name.clone(), triangles, build, classes, image, width: w, ray_sets })
}

/// Traces one ray set through all APIs of both engines, interleaved, and diffs the answers.
fn run_class(
    scene: &Scene,
    escene: &embree::Scene,
    meshes: &[TriangleMesh],
    rays: &RayStream,
    class: Class,
    pool: &rayon::ThreadPool,
    settings: &Settings,
) -> (ClassResult, Answers, Answers) {
    let n = rays.len();
    let mut samples: [[Samples; 3]; 2] = Default::default();
    let mut answers: [[Answers; 3]; 2] = std::array::from_fn(|_| std::array::from_fn(|_| Answers::misses(n)));
    let pristine = embree_stream_rays(rays);
    let mut work_rh: Vec<RTCRayHit> = Vec::new();
    let mut work_r: Vec<RTCRay> = Vec::new();
    let mut hits = HitStream::default();
    let mut occ = Vec::new();
    for pass in 0..=settings.passes {
        for api in Api::ALL {
            // Alternate which engine goes first, so neither always runs on a warmer cache.
            let order = if pass % 2 == 0 { [0, 1] } else { [1, 0] };
            for engine in order {
                // Fresh inputs before every pass; copying is not timed.
                if engine == 1 && api == Api::Stream {
                    if class.occlusion() {
                        work_r.clear();
                        work_r.extend(pristine.iter().map(|rh| rh.ray));
                    } else {
                        work_rh.clear();
                        work_rh.extend_from_slice(&pristine);
                    }
                }
                let out = &mut answers[engine][api as usize];
                let start = Instant::now();
                pool.install(|| match (engine, api) {
                    (0, Api::Single) => strahl_single(scene, rays, class, out),
                    (0, Api::Packet) => strahl_packet(scene, rays, class, out),
                    (0, Api::Stream) => strahl_stream(scene, rays, class, &mut hits, &mut occ),
                    (_, Api::Single) => embree_single(escene, rays, class, out),
                    (_, Api::Packet) => embree_packet(escene, rays, class, out),
                    (_, Api::Stream) => embree_stream(escene, class, &mut work_rh, &mut work_r),
                });
                let secs = start.elapsed().as_secs_f64();
                if pass > 0 {
                    samples[engine][api as usize].seconds.push(secs);
                }
                // Collect stream answers (not timed).
                if api == Api::Stream {
                    let out = &mut answers[engine][api as usize];
                    if engine == 0 {
                        collect_strahl(class, &hits, &occ, out);
                    } else {
                        collect_embree(class, &work_rh, &work_r, out);
                    }
                }
            }
        }
    }
    let [s, e] = answers;
    let consistent = |a: &[Answers; 3]| {
        let same =
            (0..n).filter(|&i| (1..3).all(|k| a[k].geom[i] == a[0].geom[i] && a[k].prim[i] == a[0].prim[i])).count();
        if n == 0 { 1.0 } else { same as f64 / n as f64 }
    };
    let strahl_apis_consistent = consistent(&s);
    let embree_apis_consistent = consistent(&e);
    let [s_single, _, _] = s;
    let [e_single, _, _] = e;
    let acc = accuracy::compare(meshes, rays, class.occlusion(), &s_single, &e_single);
    let hit_rate = if n == 0 { 0.0 } else { (0..n).filter(|&i| s_single.hit(i)).count() as f64 / n as f64 };
    let result = ClassResult {
        class,
        rays: n,
        hit_rate,
        accuracy: acc,
        samples,
        strahl_apis_consistent,
        embree_apis_consistent,
    };
    (result, s_single, e_single)
}

fn coherence(class: Class) -> Coherence {
    if class.coherent() { Coherence::Coherent } else { Coherence::Incoherent }
}

pub(crate) fn strahl_single(scene: &Scene, rays: &RayStream, class: Class, out: &mut Answers) {
    out.par_fill(|start, t, g, p| {
        for k in 0..t.len() {
            let r = rays.get(start + k);
            if class.occlusion() {
                let o = scene.occluded(&r);
                (t[k], g[k], p[k]) = if o { (0.0, 0, 0) } else { (f32::INFINITY, INVALID_ID, INVALID_ID) };
            } else {
                (t[k], g[k], p[k]) = match scene.intersect(&r) {
                    Some(h) => (h.t, h.geom_id, h.prim_id),
                    None => (f32::INFINITY, INVALID_ID, INVALID_ID),
                };
            }
        }
    });
}

pub(crate) fn strahl_packet(scene: &Scene, rays: &RayStream, class: Class, out: &mut Answers) {
    out.par_fill(|start, t, g, p| {
        let mut hp = HitPacket::default();
        for k in (0..t.len()).step_by(PACKET_WIDTH) {
            let m = (t.len() - k).min(PACKET_WIDTH);
            let packet = rays.packet(start + k, m);
            if class.occlusion() {
                let bits = scene.occluded_packet(&packet);
                for l in 0..m {
                    let o = bits & (1 << l) != 0;
                    (t[k + l], g[k + l], p[k + l]) =
                        if o { (0.0, 0, 0) } else { (f32::INFINITY, INVALID_ID, INVALID_ID) };
                }
            } else {
                scene.intersect_packet(&packet, &mut hp);
                t[k..k + m].copy_from_slice(&hp.t[..m]);
                g[k..k + m].copy_from_slice(&hp.geom_id[..m]);
                p[k..k + m].copy_from_slice(&hp.prim_id[..m]);
            }
        }
    });
}

fn strahl_stream(scene: &Scene, rays: &RayStream, class: Class, hits: &mut HitStream, occ: &mut Vec<bool>) {
    if class.occlusion() {
        scene.occluded_stream_par(rays, occ, coherence(class));
    } else {
        scene.intersect_stream_par(rays, hits, coherence(class));
    }
}

fn collect_strahl(class: Class, hits: &HitStream, occ: &[bool], out: &mut Answers) {
    for i in 0..out.len() {
        if class.occlusion() {
            (out.t[i], out.geom[i], out.prim[i]) =
                if occ[i] { (0.0, 0, 0) } else { (f32::INFINITY, INVALID_ID, INVALID_ID) };
        } else {
            (out.t[i], out.geom[i], out.prim[i]) = (hits.t[i], hits.geom_id[i], hits.prim_id[i]);
        }
    }
}

#[inline]
fn embree_ray(rays: &RayStream, i: usize) -> RTCRay {
    RTCRay {
        org_x: rays.ox[i],
        org_y: rays.oy[i],
        org_z: rays.oz[i],
        tnear: rays.tnear[i],
        dir_x: rays.dx[i],
        dir_y: rays.dy[i],
        dir_z: rays.dz[i],
        time: 0.0,
        tfar: rays.tfar[i],
        mask: u32::MAX,
        id: i as u32,
        flags: 0,
    }
}

fn empty_hit() -> RTCHit {
    RTCHit {
        geomID: RTC_INVALID_GEOMETRY_ID,
        primID: RTC_INVALID_GEOMETRY_ID,
        instID: [RTC_INVALID_GEOMETRY_ID],
        ..Default::default()
    }
}

fn embree_stream_rays(rays: &RayStream) -> Vec<RTCRayHit> {
    (0..rays.len()).map(|i| RTCRayHit { ray: embree_ray(rays, i), hit: empty_hit() }).collect()
}

pub(crate) fn embree_single(scene: &embree::Scene, rays: &RayStream, class: Class, out: &mut Answers) {
    let coherent = class.coherent();
    out.par_fill(|start, t, g, p| {
        for k in 0..t.len() {
            if class.occlusion() {
                let mut r = embree_ray(rays, start + k);
                scene.occluded1(&mut r, coherent);
                let o = r.tfar == f32::NEG_INFINITY;
                (t[k], g[k], p[k]) = if o { (0.0, 0, 0) } else { (f32::INFINITY, INVALID_ID, INVALID_ID) };
            } else {
                let mut rh = RTCRayHit { ray: embree_ray(rays, start + k), hit: empty_hit() };
                scene.intersect1(&mut rh, coherent);
                (t[k], g[k], p[k]) = if rh.hit.geomID != RTC_INVALID_GEOMETRY_ID {
                    (rh.ray.tfar, rh.hit.geomID, rh.hit.primID)
                } else {
                    (f32::INFINITY, INVALID_ID, INVALID_ID)
                };
            }
        }
    });
}

pub(crate) fn embree_packet(scene: &embree::Scene, rays: &RayStream, class: Class, out: &mut Answers) {
    let coherent = class.coherent();
    out.par_fill(|start, t, g, p| {
        let mut rh = Box::new(RTCRayHit16 {
            ray: RTCRay16 {
                org_x: [0.0; 16],
                org_y: [0.0; 16],
                org_z: [0.0; 16],
                tnear: [0.0; 16],
                dir_x: [0.0; 16],
                dir_y: [0.0; 16],
                dir_z: [0.0; 16],
                time: [0.0; 16],
                tfar: [0.0; 16],
                mask: [u32::MAX; 16],
                id: [0; 16],
                flags: [0; 16],
            },
            hit: RTCHit16 {
                Ng_x: [0.0; 16],
                Ng_y: [0.0; 16],
                Ng_z: [0.0; 16],
                u: [0.0; 16],
                v: [0.0; 16],
                primID: [RTC_INVALID_GEOMETRY_ID; 16],
                geomID: [RTC_INVALID_GEOMETRY_ID; 16],
                instID: [[RTC_INVALID_GEOMETRY_ID; 16]],
            },
        });
        for k in (0..t.len()).step_by(16) {
            let m = (t.len() - k).min(16);
            let mut valid = [0i32; 16];
            let r = &mut rh.ray;
            for l in 0..m {
                let i = start + k + l;
                valid[l] = -1;
                r.org_x[l] = rays.ox[i];
                r.org_y[l] = rays.oy[i];
                r.org_z[l] = rays.oz[i];
                r.tnear[l] = rays.tnear[i];
                r.dir_x[l] = rays.dx[i];
                r.dir_y[l] = rays.dy[i];
                r.dir_z[l] = rays.dz[i];
                r.tfar[l] = rays.tfar[i];
                r.id[l] = i as u32;
            }
            if class.occlusion() {
                scene.occluded16(&valid, &mut rh.ray, coherent);
                for l in 0..m {
                    let o = rh.ray.tfar[l] == f32::NEG_INFINITY;
                    (t[k + l], g[k + l], p[k + l]) =
                        if o { (0.0, 0, 0) } else { (f32::INFINITY, INVALID_ID, INVALID_ID) };
                }
            } else {
                rh.hit.geomID = [RTC_INVALID_GEOMETRY_ID; 16];
                scene.intersect16(&valid, &mut rh, coherent);
                for l in 0..m {
                    let gid = rh.hit.geomID[l];
                    (t[k + l], g[k + l], p[k + l]) = if gid != RTC_INVALID_GEOMETRY_ID {
                        (rh.ray.tfar[l], gid, rh.hit.primID[l])
                    } else {
                        (f32::INFINITY, INVALID_ID, INVALID_ID)
                    };
                }
            }
        }
    });
}

fn embree_stream(scene: &embree::Scene, class: Class, rh: &mut [RTCRayHit], r: &mut [RTCRay]) {
    let coherent = class.coherent();
    if class.occlusion() {
        r.par_chunks_mut(CHUNK).for_each(|c| scene.occluded1m(c, coherent));
    } else {
        rh.par_chunks_mut(CHUNK).for_each(|c| scene.intersect1m(c, coherent));
    }
}

fn collect_embree(class: Class, rh: &[RTCRayHit], r: &[RTCRay], out: &mut Answers) {
    for i in 0..out.len() {
        if class.occlusion() {
            let o = r[i].tfar == f32::NEG_INFINITY;
            (out.t[i], out.geom[i], out.prim[i]) =
                if o { (0.0, 0, 0) } else { (f32::INFINITY, INVALID_ID, INVALID_ID) };
        } else {
            let h = &rh[i];
            (out.t[i], out.geom[i], out.prim[i]) = if h.hit.geomID != RTC_INVALID_GEOMETRY_ID {
                (h.ray.tfar, h.hit.geomID, h.hit.primID)
            } else {
                (f32::INFINITY, INVALID_ID, INVALID_ID)
            };
        }
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
pub fn trace_once(
    scene: &Scene,
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
