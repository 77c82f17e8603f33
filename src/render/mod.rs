//! The seeds' recursive ray tracer (Whitted 1980, the lecture's SHADE) on strahl's streams.
//!
//! A [`Renderer`] is generic over the [`Query`] backend: strahl's scenes, or any other engine
//! that answers closest-hit and any-hit queries with the same ids (the comparison harness plugs
//! in Embree). It runs as *wavefronts*: the camera rays of a run of pixels, in 4×4 tiles, are
//! traced as one coherent stream; every hit is shaded ([`shade::shade`]) into streams of shadow
//! feelers (any-hit, one per light) and a stream of reflected and refracted rays (closest hit),
//! each ray carrying its pixel and path weight ([`shade::Path`]); bounce by bounce until no path
//! is left. Runs are spread over the rayon pool. The same
//! optics run depth-first, one ray at a time, in [`Renderer::render_recursive`] (the reference the
//! tests hold the wavefront to) and [`Renderer::ray_tree`] (the lecture's ray tree of one pixel).
//!
//! Images do not depend on the number of threads: every pixel's samples are seeded by the pixel,
//! and the contributions of a bounce are summed in ray order.

pub mod camera;
pub mod feelers;
pub mod image;
pub mod light;
pub mod material;
pub mod shade;
pub mod surface;
pub mod texture;
pub mod tree;

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

pub use camera::{Projection, RenderCamera};
pub use image::Image;
pub use light::{Light, LightKind};
pub use material::{FresnelMode, Material, Texture};
pub use shade::{Emission, Path, RayKind, ShadeCounts};
pub use surface::Surfaces;

use crate::camera::tile_order;
use crate::error::{Error, Result};
use crate::ray::{HitStream, Ray, RayStream};
use crate::raygen::Pcg32;
use crate::scene::{Coherence, Query};

/// Largest image side, in pixels.
pub const MAX_IMAGE_SIDE: u32 = 1 << 15;
/// Most samples per pixel.
pub const MAX_SPP: u32 = 1 << 12;
/// Deepest recursion.
pub const MAX_DEPTH: u32 = 64;

/// Image size, sampling and recursion limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Image width in pixels (at least 1).
    pub width: u32,
    /// Image height in pixels (at least 1).
    pub height: u32,
    /// Samples per pixel: 1 traces the pixel centre; more are stratified and jittered.
    pub spp: u32,
    /// Primary rays have depth 0; reflected and refracted rays are spawned up to this depth
    /// (POV-Ray's `max_trace_level`, 5 by default there too).
    pub max_depth: u32,
    /// A child ray whose path weight's largest channel falls below this is not spawned (the
    /// lecture's "Beitrag zu klein"; POV-Ray's `adc_bailout`, 1/255 by default there too).
    pub bailout: f32,
    /// Seed of the per-pixel jitter.
    pub seed: u64,
    /// Shadow feelers pass through transparent surfaces, their light filtered by each surface's
    /// transmission (POV-Ray's default); otherwise any surface blocks them (Whitted's).
    pub filtered_shadows: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Self { width: 640, height: 480, spp: 1, max_depth: 5, bailout: 1.0 / 255.0, seed: 0, filtered_shadows: false }
    }
}

impl Settings {
    /// Typed errors for sizes and counts out of range.
    pub fn check(&self) -> Result<()> {
        let bad = |m: String| Err(Error::RenderSettings(m));
        if !(1..=MAX_IMAGE_SIDE).contains(&self.width) || !(1..=MAX_IMAGE_SIDE).contains(&self.height) {
            return bad(format!("image size {}×{}: each side must be 1 to {MAX_IMAGE_SIDE}", self.width, self.height));
        }
        if !(1..=MAX_SPP).contains(&self.spp) {
            return bad(format!("{} samples per pixel: must be 1 to {MAX_SPP}", self.spp));
        }
        if self.max_depth > MAX_DEPTH {
            return bad(format!("maximum depth {}: at most {MAX_DEPTH}", self.max_depth));
        }
        if !(0.0..=1.0).contains(&self.bailout) {
            return bad(format!("bailout {}: must lie in [0, 1]", self.bailout));
        }
        Ok(())
    }
}

/// Everything shading needs: surfaces (normals, materials), materials, lights and the
/// environment.
#[derive(Clone, Debug)]
pub struct World {
    /// Per hit: material, shading normal and texture coordinates.
    pub surfaces: Surfaces,
    /// The materials surfaces refer to by index.
    pub materials: Vec<Material>,
    /// Image textures, named by [`Texture::Image`] materials.
    pub textures: Vec<texture::ImageTexture>,
    /// The light sources.
    pub lights: Vec<Light>,
    /// Ambient light, times each material's `ambient · diffuse`.
    pub ambient: Vec3,
    /// Colour of rays that leave the scene.
    pub background: Vec3,
}

impl World {
    /// Whether any material lets light through (filtered shadows need closest hits only then).
    pub fn has_transparent(&self) -> bool {
        self.materials.iter().any(Material::is_transparent)
    }

    /// Typed errors for materials, lights or colours that are out of range, and for surfaces that
    /// name materials the table does not have.
    pub fn check(&self) -> Result<()> {
        let bad = |m: String| Err(Error::RenderSettings(m));
        if self.materials.is_empty() || self.materials.len() > u32::MAX as usize {
            return bad(format!("{} materials: need 1 to 2^32 − 1", self.materials.len()));
        }
        for (i, m) in self.materials.iter().enumerate() {
            m.check().or_else(|e| bad(format!("material {i}: {e}")))?;
            if let Some(Texture::Image { index }) = m.texture
                && index as usize >= self.textures.len()
            {
                return bad(format!("material {i} names texture {index}, but there are {}", self.textures.len()));
            }
        }
        for (i, l) in self.lights.iter().enumerate() {
            l.check().or_else(|e| bad(format!("light {i}: {e}")))?;
        }
        if let Some(m) = self.surfaces.max_material()
            && m as usize >= self.materials.len()
        {
            return bad(format!("a surface names material {m}, but there are {}", self.materials.len()));
        }
        for (name, c) in [("ambient", self.ambient), ("background", self.background)] {
            if !(c.is_finite() && c.min_element() >= 0.0) {
                return bad(format!("{name} colour {c} must be finite and not negative"));
            }
        }
        Ok(())
    }
}

/// What a render did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderStats {
    /// Rays traced, by [`RayKind`] (primary, shadow, reflected, refracted).
    pub rays: [u64; 4],
    /// Secondary rays not traced because their path weight fell below the bailout.
    pub counts_cut_by_weight: u64,
    /// Secondary rays not traced because the path reached the maximum depth.
    pub counts_cut_by_depth: u64,
    /// Refractions that became total internal reflections.
    pub total_internal_reflections: u64,
    /// Wall time of the whole render.
    pub seconds: f64,
    /// Thread time (summed over the worker threads) in the queries, and in shading.
    pub trace_seconds: f64,
    /// Thread time in shading and ray generation.
    pub shade_seconds: f64,
    /// Worker threads of the render.
    pub threads: u32,
}

impl RenderStats {
    /// All rays traced.
    pub fn total_rays(&self) -> u64 {
        self.rays.iter().sum()
    }

    /// Share of the workers' time spent in the queries.
    pub fn query_share(&self) -> f64 {
        self.trace_seconds / (self.seconds * self.threads.max(1) as f64)
    }

    fn merge(&mut self, o: &RenderStats) {
        for k in 0..4 {
            self.rays[k] += o.rays[k];
        }
        self.counts_cut_by_weight += o.counts_cut_by_weight;
        self.counts_cut_by_depth += o.counts_cut_by_depth;
        self.total_internal_reflections += o.total_internal_reflections;
        self.trace_seconds += o.trace_seconds;
        self.shade_seconds += o.shade_seconds;
    }

    fn add(&mut self, c: &ShadeCounts) {
        self.counts_cut_by_weight += c.cut_by_weight;
        self.counts_cut_by_depth += c.cut_by_depth;
        self.total_internal_reflections += c.tir;
    }
}

/// One ray of a pixel's ray tree.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TreeNode {
    /// Index of the ray this one was spawned by; `None` for the primary ray.
    pub parent: Option<usize>,
    /// Primary, shadow, reflected or refracted.
    pub kind: RayKind,
    /// Recursion depth: 0 for the primary ray.
    pub depth: u32,
    /// Where the ray starts.
    pub origin: [f32; 3],
    /// Its direction.
    pub dir: [f32; 3],
    /// Where the ray stopped, in units of `dir`: its hit (or, for a shadow feeler, its blocker),
    /// `None` for a miss or an unblocked feeler.
    pub t: Option<f32>,
    /// The segment's end for shadow feelers (the light; `None` for directional lights).
    pub tfar: Option<f32>,
    /// The path weight the ray carries (for shadow feelers: the light it brings if unblocked).
    pub weight: [f32; 3],
}

impl TreeNode {
    /// A shadow feeler of the node `parent` at `depth`, stopped at `blocker` (its `t`) or not,
    /// bringing `radiance` if unblocked.
    fn shadow(parent: Option<usize>, depth: u32, r: &Ray, blocker: Option<f32>, radiance: Vec3) -> Self {
        Self {
            parent,
            kind: RayKind::Shadow,
            depth,
            origin: r.origin.to_array(),
            dir: r.dir.to_array(),
            t: blocker,
            tfar: r.tfar.is_finite().then_some(r.tfar),
            weight: radiance.to_array(),
        }
    }
}

/// Camera rays per wavefront: one parallel task, and the longest stream it traces.
pub const WAVE: usize = 4096;

/// A renderer over query backend `Q`.
pub struct Renderer<'a, Q: Query> {
    /// The intersection backend.
    pub query: &'a Q,
    /// Surfaces, materials, textures and lights.
    pub world: &'a World,
    /// The camera.
    pub camera: RenderCamera,
    /// Image size, sampling and recursion limits.
    pub settings: Settings,
}

thread_local! {
    static WAVE_BUFFERS: std::cell::RefCell<Wave> = std::cell::RefCell::new(Wave::default());
}

/// The reusable buffers of one wavefront (one per worker thread).
#[derive(Default)]
struct Wave {
    rays: RayStream,
    paths: Vec<Path>,
    hits: HitStream,
    /// Per light: shadow feelers and, per feeler, (pixel, radiance if unblocked).
    shadows: Vec<(RayStream, Vec<(u32, Vec3)>)>,
    occluded: Vec<bool>,
    next_rays: RayStream,
    next_paths: Vec<Path>,
    /// Filtered shadows: the feelers still travelling, and the next round's.
    chain: RayStream,
    chain_info: Vec<(u32, Vec3)>,
    next_chain: RayStream,
    next_info: Vec<(u32, Vec3)>,
    chain_hits: HitStream,
}

impl<Q: Query> Renderer<'_, Q> {
    /// Sample `s` of pixel `(x, y)`: the centre for one sample per pixel, otherwise a jittered
    /// point in stratum `s` of a √spp × √spp grid (rounded up), seeded by pixel and sample.
    pub fn camera_ray(&self, x: u32, y: u32, s: u32) -> Option<Ray> {
        let (w, h) = (self.settings.width, self.settings.height);
        let (dx, dy) = if self.settings.spp == 1 {
            (0.5, 0.5)
        } else {
            let n = (self.settings.spp as f32).sqrt().ceil() as u32;
            let mut rng = Pcg32::new(self.settings.seed ^ ((y as u64) << 32 | x as u64), s as u64);
            (((s % n) as f32 + rng.next_f32()) / n as f32, (((s / n) % n) as f32 + rng.next_f32()) / n as f32)
        };
        self.camera.ray(x as f32 + dx, y as f32 + dy, w, h)
    }

    fn check(&self) -> Result<()> {
        self.settings.check()?;
        self.world.check()
    }

    /// Renders the image as a wavefront on the current rayon pool. `progress` is called with
    /// the number of camera samples finished so far (of `width · height · spp`), from any thread.
    ///
    /// The image's pixels, in 4×4-tile order, are cut into runs of about [`WAVE`] camera rays;
    /// each run is one wavefront, traced bounce by bounce on one thread (streams of up to
    /// `WAVE` rays, and the shadow feelers of each bounce light by light), and the runs are
    /// spread over the pool. A run's rays carry their pixel's index within the run, and each run
    /// sums into its own pixels, so no bounce has a serial gather step and no two threads share
    /// a pixel.
    pub fn render(&self, progress: &(dyn Fn(u64) + Sync)) -> Result<(Image, RenderStats)> {
        self.check()?;
        let start = Instant::now();
        let s = &self.settings;
        let pixels = tile_order(s.width, s.height);
        let per_run = (WAVE / s.spp as usize).max(1);
        let done = std::sync::atomic::AtomicU64::new(0);
        let runs: Vec<(Vec<Vec3>, RenderStats)> = pixels
            .par_chunks(per_run)
            .with_max_len(1)
            .map(|run| {
                // One set of buffers per worker thread, kept for the next render too
                // (`map_init` would make one per split of the work: fresh pages each run).
                // A backend whose queries run rayon work could let this thread start another
                // run while one is in progress: that run gets fresh buffers instead.
                let out = WAVE_BUFFERS.with(|cell| match cell.try_borrow_mut() {
                    Ok(mut wave) => self.wavefront(&mut wave, run),
                    Err(_) => self.wavefront(&mut Wave::default(), run),
                });
                let n = done.fetch_add(run.len() as u64 * s.spp as u64, std::sync::atomic::Ordering::Relaxed);
                progress(n + run.len() as u64 * s.spp as u64);
                out
            })
            .collect();
        let mut stats = RenderStats { threads: rayon::current_num_threads() as u32, ..Default::default() };
        let mut image = Image::new(s.width, s.height);
        let scale = 1.0 / s.spp as f32;
        for (run, (acc, st)) in pixels.chunks(per_run).zip(&runs) {
            for (&(x, y), a) in run.iter().zip(acc) {
                image.pixels[(y * s.width + x) as usize] = *a * scale;
            }
            stats.merge(st);
        }
        stats.seconds = start.elapsed().as_secs_f64();
        Ok((image, stats))
    }

    /// One wavefront over the pixels `run`: returns their summed samples and the statistics.
    fn wavefront(&self, w: &mut Wave, run: &[(u32, u32)]) -> (Vec<Vec3>, RenderStats) {
        let s = &self.settings;
        let mut stats = RenderStats::default();
        let mut acc = vec![Vec3::ZERO; run.len()];
        // Camera rays: sample-major, each sample's pixels in tile order (coherent packets).
        w.rays.clear();
        w.paths.clear();
        for sample in 0..s.spp {
            for (i, &(x, y)) in run.iter().enumerate() {
                if let Some(r) = self.camera_ray(x, y, sample) {
                    w.rays.push(&r);
                    w.paths.push(Path::camera(i as u32, x, y, sample));
                }
            }
        }
        stats.rays[RayKind::Primary as usize] += w.rays.len() as u64;
        let lights = self.world.lights.len();
        w.shadows.resize_with(lights, Default::default);
        let mut bounce = 0;
        while !w.rays.is_empty() {
            let coherence = if bounce == 0 { Coherence::Coherent } else { Coherence::Incoherent };
            let t0 = Instant::now();
            self.query.intersect_stream(&w.rays, &mut w.hits, coherence);
            stats.trace_seconds += t0.elapsed().as_secs_f64();

            let t0 = Instant::now();
            for (rays, info) in &mut w.shadows {
                rays.clear();
                info.clear();
            }
            w.next_rays.clear();
            w.next_paths.clear();
            let mut counts = ShadeCounts::default();
            for i in 0..w.rays.len() {
                let ray = w.rays.get(i);
                let hit = w.hits.get(i);
                let path = &w.paths[i];
                let (shadows, next_rays, next_paths) = (&mut w.shadows, &mut w.next_rays, &mut w.next_paths);
                shade::shade(self.world, s, &ray, hit.as_ref(), path, &mut counts, |e| match e {
                    Emission::Radiance(c) => acc[path.pixel as usize] += c,
                    Emission::Shadow { ray, radiance, light } => {
                        let (rays, info) = &mut shadows[light as usize];
                        rays.push(&ray);
                        info.push((path.pixel, radiance));
                    }
                    Emission::Shadows(b) => {
                        let (rays, info) = &mut shadows[b.light as usize];
                        let n = b.len;
                        rays.extend_lanes(b.origin, [&b.dir[0][..n], &b.dir[1][..n], &b.dir[2][..n]], 0.0, 1.0);
                        info.extend(
                            (0..n)
                                .map(|l| (path.pixel, Vec3::new(b.radiance[0][l], b.radiance[1][l], b.radiance[2][l]))),
                        );
                    }
                    Emission::Child { ray, path, kind } => {
                        next_rays.push(&ray);
                        next_paths.push(path);
                        stats.rays[kind as usize] += 1;
                    }
                });
            }
            stats.add(&counts);
            stats.shade_seconds += t0.elapsed().as_secs_f64();

            // Shadow feelers, light by light (each light's feelers share a direction).
            let Wave { shadows, occluded, chain, chain_info, next_chain, next_info, chain_hits, .. } = &mut *w;
            for (rays, info) in shadows.iter() {
                if rays.is_empty() {
                    continue;
                }
                if !s.filtered_shadows || !self.world.has_transparent() {
                    let t0 = Instant::now();
                    self.query.occluded_stream(rays, occluded, coherence);
                    stats.trace_seconds += t0.elapsed().as_secs_f64();
                    stats.rays[RayKind::Shadow as usize] += rays.len() as u64;
                    for (&(p, c), &o) in info.iter().zip(occluded.iter()) {
                        if !o {
                            acc[p as usize] += c;
                        }
                    }
                    continue;
                }
                // Filtered: closest hits, and through transparent surfaces again, round by round.
                chain.clone_from(rays);
                chain_info.clone_from(info);
                for _ in 0..shade::MAX_SHADOW_CROSSINGS {
                    if chain.is_empty() {
                        break;
                    }
                    let t0 = Instant::now();
                    self.query.intersect_stream(chain, chain_hits, coherence);
                    stats.trace_seconds += t0.elapsed().as_secs_f64();
                    stats.rays[RayKind::Shadow as usize] += chain.len() as u64;
                    next_chain.clear();
                    next_info.clear();
                    for (i, &(p, c)) in chain_info.iter().enumerate() {
                        match chain_hits.get(i) {
                            None => acc[p as usize] += c,
                            Some(h) => {
                                if let shade::ShadowStep::Through { ray, radiance } =
                                    shade::shadow_through(self.world, s, &chain.get(i), &h, c)
                                {
                                    next_chain.push(&ray);
                                    next_info.push((p, radiance));
                                }
                            }
                        }
                    }
                    std::mem::swap(chain, next_chain);
                    std::mem::swap(chain_info, next_info);
                }
            }
            std::mem::swap(&mut w.rays, &mut w.next_rays);
            std::mem::swap(&mut w.paths, &mut w.next_paths);
            bounce += 1;
        }
        (acc, stats)
    }

    /// Renders depth-first, one ray at a time, pixel by pixel in parallel: the textbook recursion,
    /// the reference for [`render`](Self::render).
    pub fn render_recursive(&self) -> Result<(Image, RenderStats)> {
        self.check()?;
        let start = Instant::now();
        let s = &self.settings;
        let rows: Vec<(Vec<Vec3>, RenderStats)> = (0..s.height)
            .into_par_iter()
            .map(|y| {
                let mut st = RenderStats::default();
                let row = (0..s.width)
                    .map(|x| {
                        let mut sum = Vec3::ZERO;
                        for sample in 0..s.spp {
                            if let Some(r) = self.camera_ray(x, y, sample) {
                                let path = Path::camera(0, x, y, sample);
                                sum += self.trace_depth_first(&r, &path, RayKind::Primary, None, &mut st, &mut None);
                            }
                        }
                        sum / s.spp as f32
                    })
                    .collect();
                (row, st)
            })
            .collect();
        let mut image = Image::new(s.width, s.height);
        let mut stats = RenderStats::default();
        for (y, (row, st)) in rows.into_iter().enumerate() {
            image.pixels[y * s.width as usize..][..s.width as usize].copy_from_slice(&row);
            stats.merge(&st);
        }
        stats.threads = rayon::current_num_threads() as u32;
        stats.seconds = start.elapsed().as_secs_f64();
        Ok((image, stats))
    }

    /// The ray tree of pixel `(x, y)`'s first sample: every primary, shadow, reflected and
    /// refracted ray, parents before children, with the pixel's colour from this sample.
    pub fn ray_tree(&self, x: u32, y: u32) -> Result<(Vec<TreeNode>, Vec3)> {
        self.check()?;
        if x >= self.settings.width || y >= self.settings.height {
            return Err(Error::RenderSettings(format!(
                "pixel ({x}, {y}) lies outside the {}×{} image",
                self.settings.width, self.settings.height
            )));
        }
        let mut nodes = Vec::new();
        let mut st = RenderStats::default();
        let colour = match self.camera_ray(x, y, 0) {
            Some(r) => {
                let path = Path::camera(0, x, y, 0);
                self.trace_depth_first(&r, &path, RayKind::Primary, None, &mut st, &mut Some(&mut nodes))
            }
            None => Vec3::ZERO,
        };
        Ok((nodes, colour))
    }

    /// The recursion: traces `ray`, shades it, follows its shadow feelers and children.
    fn trace_depth_first(
        &self,
        ray: &Ray,
        path: &Path,
        kind: RayKind,
        parent: Option<usize>,
        stats: &mut RenderStats,
        tree: &mut Option<&mut Vec<TreeNode>>,
    ) -> Vec3 {
        let hit = self.query.intersect(ray);
        stats.rays[kind as usize] += 1;
        let me = tree.as_mut().map(|t| {
            t.push(TreeNode {
                parent,
                kind,
                depth: path.depth,
                origin: ray.origin.to_array(),
                dir: ray.dir.to_array(),
                t: hit.map(|h| h.t),
                tfar: None,
                weight: path.weight.to_array(),
            });
            t.len() - 1
        });
        let mut emitted = Vec::new();
        let mut counts = ShadeCounts::default();
        shade::shade(self.world, &self.settings, ray, hit.as_ref(), path, &mut counts, |e| match e {
            Emission::Shadows(b) => {
                emitted.extend(b.feelers().map(|(ray, radiance)| Emission::Shadow { ray, radiance, light: b.light }))
            }
            Emission::Radiance(c) => emitted.push(Emission::Radiance(c)),
            Emission::Shadow { ray, radiance, light } => emitted.push(Emission::Shadow { ray, radiance, light }),
            Emission::Child { ray, path, kind } => emitted.push(Emission::Child { ray, path, kind }),
        });
        stats.add(&counts);
        let mut sum = Vec3::ZERO;
        for e in emitted {
            match e {
                Emission::Radiance(c) => sum += c,
                Emission::Shadow { ray: r, radiance, .. }
                    if self.settings.filtered_shadows && self.world.has_transparent() =>
                {
                    let (mut r, mut c) = (r, radiance);
                    let mut lit = false;
                    for _ in 0..shade::MAX_SHADOW_CROSSINGS {
                        stats.rays[RayKind::Shadow as usize] += 1;
                        let hit = self.query.intersect(&r);
                        if let Some(t) = tree.as_mut() {
                            t.push(TreeNode::shadow(me, path.depth, &r, hit.map(|h| h.t), c));
                        }
                        let Some(h) = hit else {
                            lit = true;
                            break;
                        };
                        match shade::shadow_through(self.world, &self.settings, &r, &h, c) {
                            shade::ShadowStep::Blocked => break,
                            shade::ShadowStep::Through { ray, radiance } => (r, c) = (ray, radiance),
                        }
                    }
                    if lit {
                        sum += c;
                    }
                }
                Emission::Shadow { ray: r, radiance, .. } => {
                    stats.rays[RayKind::Shadow as usize] += 1;
                    let blocked = self.query.occluded(&r);
                    if let Some(t) = tree.as_mut() {
                        let blocker = if blocked { self.query.intersect(&r).map(|h| h.t) } else { None };
                        t.push(TreeNode::shadow(me, path.depth, &r, blocker, radiance));
                    }
                    if !blocked {
                        sum += radiance;
                    }
                }
                Emission::Child { ray: r, path: p, kind: k } => {
                    sum += self.trace_depth_first(&r, &p, k, me, stats, tree);
                }
                Emission::Shadows(_) => unreachable!("batches are unpacked as they are emitted"),
            }
        }
        sum
    }
}
