//! Embree 3 as the renderer's query backend: [`strahl::render::Renderer`] over
//! [`EmbreeBackend`] renders the same frames with Embree's BVH and kernels, for the frame-time
//! ratio and the pixel agreement of the two images.
//!
//! The renderer hands every backend the same SoA [`RayStream`]s (one wavefront's, up to 4096 rays),
//! so Embree's stream queries convert them into its own records (`RTCRayHit`/`RTCRay`, in
//! thread-local buffers reused across calls) and call `rtcIntersect1M`/`rtcOccluded1M`, and write
//! the answers back. The first bounce (camera rays and their shadow feelers) gets Embree's
//! coherent flag, later bounces the incoherent one; occlusion queries never get it where Embree
//! runs AVX-512 (see `coherent_occlusion`).
//! The conversion is part of Embree's time here, as reading the stream is part of strahl's.
//! [`EmbreeBackend::set_packets`] switches the streams to `rtcIntersect16`/`rtcOccluded16` on
//! runs of 16 consecutive rays (a 4×4 tile of camera rays), the API the kernel harness found
//! best for some ray classes; `compare --render` times both and reports both.

use std::cell::RefCell;
use std::fmt::Write as _;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use glam::{Affine3A, Mat3, Vec3};
use rayon::prelude::*;
use strahl::{
    Coherence, Hit, HitSlice, HitStream, INVALID_ID, Instance, Query, Ray, RayPacket, RayStream, STREAM_CHUNK,
    TriangleMesh,
};

use crate::embree::{self, Device, RTC_INVALID_GEOMETRY_ID, RTCRay, RTCRayHit};
use crate::harness::{column_major, embree_ray_of, empty_hit, quartiles};
use crate::kernel::{empty_packet, set_lane};

/// A two-level Embree scene answering strahl's [`Query`].
pub struct EmbreeBackend {
    scene: embree::Scene,
    /// Per instance: Embree 3 reports instance hits' normals in object space; strahl's in world
    /// space by the cofactor matrix `det(M)·M⁻ᵀ` (which flips with a mirroring transform's winding).
    cofactor: Vec<Mat3>,
    /// Per instance: its object's mesh count (geometry ids from it on are sphere sets, whose
    /// normals strahl keeps outward under mirrors) and whether the transform mirrors.
    sphere_from: Vec<(u32, bool)>,
    /// Streams through `rtcIntersect16`/`rtcOccluded16` instead of the `1M` calls.
    packets: AtomicBool,
    /// Whether coherent occlusion queries get Embree's coherent flag (see
    /// [`coherent_occlusion`]).
    coherent_occlusion: bool,
    _device: Device,
}

thread_local! {
    static HIT_BUF: RefCell<Vec<RTCRayHit>> = const { RefCell::new(Vec::new()) };
    static RAY_BUF: RefCell<Vec<RTCRay>> = const { RefCell::new(Vec::new()) };
}

/// Embree's packet of the active lanes of `rays` (under strahl's bad-ray rules) and its valid mask.
fn packet(rays: &RayPacket) -> (embree::RTCRayHit16, [i32; 16]) {
    let mut p = empty_packet();
    let mut valid = [0i32; 16];
    for l in 0..16 {
        if rays.is_active(l) {
            set_lane(&mut p, l, &embree_ray_of(&rays.get(l), l as u32));
            valid[l] = -1;
        }
    }
    (p, valid)
}

/// Embree's packet of rays `start..start + n` (`n ≤ 16`) of a stream, all lanes valid (bad rays
/// become empty intervals, as in the `1M` records).
fn stream_packet(rays: &RayStream, start: usize, n: usize) -> (embree::RTCRayHit16, [i32; 16]) {
    let mut p = empty_packet();
    let mut valid = [0i32; 16];
    for l in 0..n {
        set_lane(&mut p, l, &embree_ray_of(&rays.get(start + l), (start + l) as u32));
        valid[l] = -1;
    }
    (p, valid)
}

/// Lane `l` of a traced packet as a single record (its `tfar` and hit).
fn lane_record(p: &embree::RTCRayHit16, l: usize) -> RTCRayHit {
    let h = &p.hit;
    RTCRayHit {
        ray: RTCRay { tfar: p.ray.tfar[l], ..embree_ray_of(&Ray::new(Vec3::ZERO, Vec3::X), l as u32) },
        hit: embree::RTCHit {
            Ng_x: h.Ng_x[l],
            Ng_y: h.Ng_y[l],
            Ng_z: h.Ng_z[l],
            u: h.u[l],
            v: h.v[l],
            primID: h.primID[l],
            geomID: h.geomID[l],
            instID: [h.instID[0][l]],
        },
    }
}

fn cofactor(m: &Affine3A) -> Mat3 {
    let l = Mat3::from(m.matrix3);
    l.inverse().transpose() * l.determinant()
}

impl EmbreeBackend {
    /// Builds `objects` placed by `instances` with Embree's default (medium) quality.
    pub fn build(objects: &[Vec<TriangleMesh>], instances: &[Instance]) -> anyhow::Result<Self> {
        Self::build_mixed(objects, &[], instances)
    }

    /// [`build`](Self::build) with each object's analytic spheres after its meshes, as Embree's
    /// `RTC_GEOMETRY_TYPE_SPHERE_POINT` geometries.
    pub fn build_mixed(
        objects: &[Vec<TriangleMesh>],
        spheres: &[Vec<strahl::SphereSet>],
        instances: &[Instance],
    ) -> anyhow::Result<Self> {
        Self::build_with_solids(objects, spheres, &[], instances)
    }

    /// [`build_mixed`](Self::build_mixed) with each object's solids after its sphere sets, as
    /// Embree user geometry running strahl's solid intersection (so the comparison isolates the
    /// acceleration structure and dispatch).
    pub fn build_with_solids(
        objects: &[Vec<TriangleMesh>],
        spheres: &[Vec<strahl::SphereSet>],
        solids: &[Vec<strahl::Solid>],
        instances: &[Instance],
    ) -> anyhow::Result<Self> {
        let device = Device::new("threads=2")?;
        let xfms: Vec<(usize, [f32; 12])> = instances.iter().map(|i| (i.object, column_major(&i.transform))).collect();
        let prepared = solids
            .iter()
            .map(|o| o.iter().map(|s| strahl::shapes::PreparedSolid::new(s, Default::default())).collect())
            .collect::<strahl::Result<Vec<Vec<_>>>>()?;
        let scene =
            embree::Scene::build_instanced_mixed(&device, objects, spheres, &prepared, &xfms, embree::Quality::Medium)?;
        let cofactor = instances.iter().map(|i| cofactor(&i.transform)).collect();
        let sphere_from = instances
            .iter()
            .map(|i| {
                let meshes = objects.get(i.object).map_or(0, |o| o.len()) as u32;
                (meshes, i.transform.matrix3.determinant() < 0.0)
            })
            .collect();
        Ok(Self {
            scene,
            cofactor,
            sphere_from,
            packets: AtomicBool::new(false),
            coherent_occlusion: coherent_occlusion(),
            _device: device,
        })
    }

    /// Answers streams through `rtcIntersect16`/`rtcOccluded16` on runs of 16 consecutive rays
    /// (`true`) or through `rtcIntersect1M`/`rtcOccluded1M` (`false`, the default).
    pub fn set_packets(&self, on: bool) {
        self.packets.store(on, Ordering::Relaxed);
    }

    fn hit(&self, rh: &RTCRayHit) -> Option<Hit> {
        let h = &rh.hit;
        if h.geomID == RTC_INVALID_GEOMETRY_ID {
            return None;
        }
        let inst = h.instID[0];
        let ng = Vec3::new(h.Ng_x, h.Ng_y, h.Ng_z);
        let ng = match self.cofactor.get(inst as usize) {
            Some(c) => match self.sphere_from.get(inst as usize) {
                // A sphere's normal stays outward under a mirror, as strahl's.
                Some(&(first, true)) if h.geomID >= first => -(*c * ng),
                _ => *c * ng,
            },
            None => ng,
        };
        let inst_id = if inst == RTC_INVALID_GEOMETRY_ID { INVALID_ID } else { inst };
        Some(Hit { t: rh.ray.tfar, u: h.u, v: h.v, ng, prim_id: h.primID, geom_id: h.geomID, inst_id })
    }
}

impl Query for EmbreeBackend {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let mut rh = RTCRayHit { ray: embree_ray_of(ray, 0), hit: empty_hit() };
        self.scene.intersect1(&mut rh, false);
        self.hit(&rh)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        let mut r = embree_ray_of(ray, 0);
        self.scene.occluded1(&mut r, false);
        r.tfar == f32::NEG_INFINITY
    }

    fn intersect_packet_each(&self, rays: &RayPacket, mut f: impl FnMut(usize, &Hit)) {
        let (mut p, valid) = packet(rays);
        self.scene.intersect16(&valid, &mut p, false);
        for l in (0..16).filter(|&l| valid[l] != 0) {
            let rh = lane_record(&p, l);
            if let Some(hit) = self.hit(&rh) {
                f(l, &hit);
            }
        }
    }

    fn occluded_packet(&self, rays: &RayPacket) -> u32 {
        let (mut p, valid) = packet(rays);
        self.scene.occluded16(&valid, &mut p.ray, false);
        (0..16).filter(|&l| valid[l] != 0 && p.ray.tfar[l] == f32::NEG_INFINITY).fold(0, |m, l| m | 1 << l)
    }

    fn intersect_stream(&self, rays: &RayStream, hits: &mut HitStream, coherence: Coherence) {
        hits.reset(rays.len());
        self.intersect_chunk(rays, 0, hits.as_slice_mut(), coherence == Coherence::Coherent);
    }

    fn occluded_stream(&self, rays: &RayStream, occluded: &mut Vec<bool>, coherence: Coherence) {
        occluded.clear();
        occluded.resize(rays.len(), false);
        self.occluded_chunk(rays, 0, occluded, coherence == Coherence::Coherent);
    }

    fn intersect_stream_par(&self, rays: &RayStream, hits: &mut HitStream, coherence: Coherence) {
        hits.reset(rays.len());
        let coherent = coherence == Coherence::Coherent;
        hits.par_chunks_mut(STREAM_CHUNK)
            .enumerate()
            .with_max_len(1)
            .for_each(|(i, out)| self.intersect_chunk(rays, i * STREAM_CHUNK, out, coherent));
    }

    fn occluded_stream_par(&self, rays: &RayStream, occluded: &mut Vec<bool>, coherence: Coherence) {
        occluded.clear();
        occluded.resize(rays.len(), false);
        let coherent = coherence == Coherence::Coherent;
        occluded
            .par_chunks_mut(STREAM_CHUNK)
            .enumerate()
            .with_max_len(1)
            .for_each(|(i, out)| self.occluded_chunk(rays, i * STREAM_CHUNK, out, coherent));
    }
}

impl EmbreeBackend {
    /// Rays `start..start + out.len()` through `rtcIntersect1M`, in Embree's records built in a
    /// thread-local buffer; answers written into `out` (misses left as they are).
    fn intersect_chunk(&self, rays: &RayStream, start: usize, mut out: HitSlice<'_>, coherent: bool) {
        if self.packets.load(Ordering::Relaxed) {
            let n = out.len();
            for k in (0..n).step_by(16) {
                let m = (n - k).min(16);
                let (mut p, valid) = stream_packet(rays, start + k, m);
                self.scene.intersect16(&valid, &mut p, coherent);
                for l in 0..m {
                    if let Some(hit) = self.hit(&lane_record(&p, l)) {
                        out.set(k + l, &hit);
                    }
                }
            }
            return;
        }
        HIT_BUF.with_borrow_mut(|buf| {
            buf.clear();
            let n = out.len();
            buf.extend(
                (start..start + n).map(|k| RTCRayHit { ray: embree_ray_of(&rays.get(k), k as u32), hit: empty_hit() }),
            );
            self.scene.intersect1m(buf, coherent);
            for (k, rh) in buf.iter().enumerate() {
                if let Some(hit) = self.hit(rh) {
                    out.set(k, &hit);
                }
            }
        });
    }

    /// Rays `start..start + out.len()` through `rtcOccluded1M`.
    fn occluded_chunk(&self, rays: &RayStream, start: usize, out: &mut [bool], coherent: bool) {
        if self.packets.load(Ordering::Relaxed) {
            let n = out.len();
            for k in (0..n).step_by(16) {
                let m = (n - k).min(16);
                let (mut p, valid) = stream_packet(rays, start + k, m);
                self.scene.occluded16(&valid, &mut p.ray, coherent && self.coherent_occlusion);
                for l in 0..m {
                    out[k + l] = p.ray.tfar[l] == f32::NEG_INFINITY;
                }
            }
            return;
        }
        RAY_BUF.with_borrow_mut(|buf| {
            buf.clear();
            buf.extend((start..start + out.len()).map(|k| embree_ray_of(&rays.get(k), k as u32)));
            self.scene.occluded1m(buf, coherent && self.coherent_occlusion);
            for (o, r) in out.iter_mut().zip(buf.iter()) {
                *o = r.tfar == f32::NEG_INFINITY;
            }
        });
    }
}

/// One render scene's figures.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RenderRow {
    pub scene: String,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub max_depth: u32,
    pub triangles: u64,
    /// Rays of one frame by kind: primary, shadow, reflected, refracted.
    pub rays: [u64; 4],
    /// Median frame times over the interleaved passes, seconds.
    pub strahl_s: f64,
    pub embree_s: f64,
    /// Quartiles of the per-pass ratios strahl time / Embree time (below 1: strahl faster).
    pub ratio_quartiles: [f64; 3],
    /// The same with Embree answering the streams through `rtcIntersect16`/`rtcOccluded16`.
    pub embree16_s: f64,
    pub ratio16_quartiles: [f64; 3],
    /// Median share of the worker threads' time spent inside the queries, per backend.
    pub strahl_query_share: f64,
    pub embree_query_share: f64,
    pub embree16_query_share: f64,
    /// Pixels whose 8-bit sRGB colours differ by more than 1 in some channel, strahl vs Embree.
    pub embree_pixels_differing: u64,
    pub embree16_pixels_differing: u64,
    /// strahl's whole job (read, load, build, render, write PNG), seconds, median of the passes.
    pub strahl_job_s: f64,
    /// POV-Ray's whole process, seconds (median of its runs), and its image against strahl's.
    pub povray_s: Option<f64>,
    pub povray_psnr_db: Option<f64>,
    /// Fraction of pixels within 8/255 in every channel of POV-Ray's.
    pub povray_close: Option<f64>,
    /// Rays the contribution cut-off saved in one frame, and the largest 8-bit difference it made.
    pub cut_by_weight: u64,
    pub bailout_rays_without: u64,
    pub bailout_max_diff: u8,
}

fn median(v: &[f64]) -> f64 {
    quartiles(v)[1]
}

/// Largest per-channel difference of two 8-bit images, and how many pixels differ by more than `tol`.
fn diff8(a: &[u8], b: &[u8], tol: u8) -> (u8, u64) {
    let mut worst = 0;
    let mut count = 0;
    for (p, q) in a.chunks(3).zip(b.chunks(3)) {
        let d = p.iter().zip(q).map(|(x, y)| x.abs_diff(*y)).max().unwrap_or(0);
        worst = worst.max(d);
        count += (d > tol) as u64;
    }
    (worst, count)
}

/// Peak signal-to-noise ratio of two 8-bit images of the same size, in dB (infinite if equal).
pub fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let mse = a.iter().zip(b).map(|(x, y)| (*x as f64 - *y as f64).powi(2)).sum::<f64>() / a.len() as f64;
    if mse == 0.0 { f64::INFINITY } else { 10.0 * (255.0f64 * 255.0 / mse).log10() }
}

/// Renders one scene file with strahl, with strahl on Embree, and with POV-Ray (when installed),
/// `passes` interleaved timed frames each after a warm-up; writes the three images to `out`.
pub fn compare_scene(
    path: &Path,
    out: &Path,
    passes: usize,
    threads: usize,
    pool: &rayon::ThreadPool,
) -> anyhow::Result<RenderRow> {
    use strahl::render::Renderer;
    let name = path.file_stem().map_or("scene".into(), |s| s.to_string_lossy().into_owned());
    let file = strahl::SceneFile::read(path)?;
    let objects = file.load_objects()?;
    let world = file.world(&objects)?;
    let settings = file.render.settings;
    let camera =
        file.camera.and_then(|c| c.render_camera()).ok_or_else(|| anyhow::anyhow!("{}: no camera", path.display()))?;
    let triangles = objects
        .iter()
        .zip(0..)
        .map(|(o, k)| {
            let n: usize = o.iter().map(|m| m.triangle_count()).sum();
            n as u64 * file.instances.iter().filter(|i| i.object == k).count() as u64
        })
        .sum();
    let spheres = file.load_spheres()?;
    let (scene, backend) = pool.install(|| -> anyhow::Result<_> {
        let scene = file.build_from(objects.clone(), &strahl::BuildConfig::default())?;
        Ok((scene, EmbreeBackend::build_with_solids(&objects, &spheres, &file.load_solids(), &file.instances)?))
    })?;
    let ours = Renderer { query: &scene, world: &world, camera, settings };
    let theirs = Renderer { query: &backend, world: &world, camera, settings };
    let none = |_| {};
    let (mut img_s, mut stats) = pool.install(|| ours.render(&none))?;
    let (mut img_e, _) = pool.install(|| theirs.render(&none))?;
    backend.set_packets(true);
    let (mut img_e16, _) = pool.install(|| theirs.render(&none))?;
    let (mut ts, mut te, mut qs, mut qe, mut ratios) = (vec![], vec![], vec![], vec![], vec![]);
    let (mut te16, mut qe16, mut ratios16) = (vec![], vec![], vec![]);
    for _ in 0..passes {
        let (i, s) = pool.install(|| ours.render(&none))?;
        backend.set_packets(false);
        let (j, e) = pool.install(|| theirs.render(&none))?;
        backend.set_packets(true);
        let (j16, e16) = pool.install(|| theirs.render(&none))?;
        ts.push(s.seconds);
        te.push(e.seconds);
        te16.push(e16.seconds);
        qs.push(s.query_share());
        qe.push(e.query_share());
        qe16.push(e16.query_share());
        ratios.push(s.seconds / e.seconds);
        ratios16.push(s.seconds / e16.seconds);
        (img_s, stats, img_e, img_e16) = (i, s, j, j16);
    }
    img_s.write(&out.join(format!("{name}_strahl.png")))?;
    img_e.write(&out.join(format!("{name}_embree.png")))?;
    let (s8, e8) = (img_s.to_srgb8(), img_e.to_srgb8());
    let (_, embree_pixels_differing) = diff8(&s8, &e8, 1);
    let (_, embree16_pixels_differing) = diff8(&s8, &img_e16.to_srgb8(), 1);
    // The bailout's saving: the same frame with the cut-off at 0.
    let all = Renderer { settings: strahl::render::Settings { bailout: 0.0, ..settings }, ..ours };
    let (img_all, stats_all) = pool.install(|| all.render(&none))?;
    let (bailout_max_diff, _) = diff8(&s8, &img_all.to_srgb8(), 0);
    // strahl's whole job, as POV-Ray's process does it.
    let mut jobs = Vec::new();
    for _ in 0..passes.clamp(1, 3) {
        let t0 = Instant::now();
        pool.install(|| -> anyhow::Result<()> {
            let f = strahl::SceneFile::read(path)?;
            let objs = f.load_objects()?;
            let w = f.world(&objs)?;
            let sc = f.build_from(objs, &strahl::BuildConfig::default())?;
            let r = Renderer { query: &sc, world: &w, camera, settings };
            r.render(&none)?.0.write(&out.join(format!("{name}_strahl.png")))?;
            Ok(())
        })?;
        jobs.push(t0.elapsed().as_secs_f64());
    }
    let (mut povray_s, mut povray_psnr_db, mut povray_close) = (None, None, None);
    if crate::povray::available() {
        let pov = crate::povray::pov_path(out, &name);
        std::fs::write(&pov, crate::povray::export(&file, &objects, &world, &settings)?)?;
        let png = out.join(format!("{name}_povray.png"));
        let mut times = Vec::new();
        for _ in 0..passes.clamp(1, 3) {
            times.push(crate::povray::render(&pov, &png, &settings, threads)?);
        }
        let p8 = image::open(&png)?.to_rgb8().into_raw();
        if p8.len() == s8.len() {
            povray_psnr_db = Some(psnr(&s8, &p8));
            let (_, far) = diff8(&s8, &p8, 8);
            povray_close = Some(1.0 - far as f64 / (s8.len() / 3) as f64);
        }
        povray_s = Some(median(&times));
    }
    Ok(RenderRow {
        scene: name,
        width: settings.width,
        height: settings.height,
        spp: settings.spp,
        max_depth: settings.max_depth,
        triangles,
        rays: stats.rays,
        strahl_s: median(&ts),
        embree_s: median(&te),
        ratio_quartiles: quartiles(&ratios),
        embree16_s: median(&te16),
        ratio16_quartiles: quartiles(&ratios16),
        strahl_query_share: median(&qs),
        embree_query_share: median(&qe),
        embree16_query_share: median(&qe16),
        embree_pixels_differing,
        embree16_pixels_differing,
        strahl_job_s: median(&jobs),
        povray_s,
        povray_psnr_db,
        povray_close,
        cut_by_weight: stats.counts_cut_by_weight,
        bailout_rays_without: stats_all.total_rays(),
        bailout_max_diff,
    })
}

/// The Markdown table of [`compare_scene`] rows.
pub fn table(rows: &[RenderRow], threads: usize, passes: usize) -> String {
    let mut s = format!(
        "Frame times: median of {passes} interleaved passes, {threads} threads; ratio quartiles of the pass pairs. \
         POV-Ray: whole process (parse, render, write), median of up to 3 runs; strahl job: read, load, build, render, write.\n\n\
         | scene | size | rays (prim / shadow / refl / refr) | strahl frame | strahl on Embree 1M | ratio (q1 / med / q3) | strahl on Embree 16 | ratio (q1 / med / q3) | share in queries (strahl / Embree 1M / 16) | Mrays/s strahl | pixels ≠ Embree (1M / 16) | strahl job | POV-Ray | POV-Ray ÷ strahl job | PSNR vs POV-Ray | within 8/255 |\n\
         |---|---|---|---:|---:|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|\n"
    );
    for r in rows {
        let total: u64 = r.rays.iter().sum();
        let pov = |x: Option<f64>, f: &dyn Fn(f64) -> String| x.map_or("—".into(), f);
        writeln!(
            s,
            "| {} | {}×{}, {} spp, depth {} | {} / {} / {} / {} | {:.1} ms | {:.1} ms | {:.2} / {:.2} / {:.2} | {:.1} ms | {:.2} / {:.2} / {:.2} | {:.0}% / {:.0}% / {:.0}% | {:.1} | {} / {} | {:.0} ms | {} | {} | {} | {} |",
            r.scene,
            r.width,
            r.height,
            r.spp,
            r.max_depth,
            r.rays[0],
            r.rays[1],
            r.rays[2],
            r.rays[3],
            r.strahl_s * 1e3,
            r.embree_s * 1e3,
            r.ratio_quartiles[0],
            r.ratio_quartiles[1],
            r.ratio_quartiles[2],
            r.embree16_s * 1e3,
            r.ratio16_quartiles[0],
            r.ratio16_quartiles[1],
            r.ratio16_quartiles[2],
            100.0 * r.strahl_query_share,
            100.0 * r.embree_query_share,
            100.0 * r.embree16_query_share,
            total as f64 / r.strahl_s / 1e6,
            r.embree_pixels_differing,
            r.embree16_pixels_differing,
            r.strahl_job_s * 1e3,
            pov(r.povray_s, &|x| format!("{:.0} ms", x * 1e3)),
            pov(r.povray_s, &|x| format!("{:.1}×", x / r.strahl_job_s)),
            pov(r.povray_psnr_db, &|x| format!("{x:.1} dB")),
            pov(r.povray_close, &|x| format!("{:.1}%", 100.0 * x)),
        )
        .unwrap();
    }
    s.push_str("\nContribution cut-off (bailout) per frame: ");
    for r in rows {
        let saved = r.bailout_rays_without.saturating_sub(r.rays.iter().sum());
        write!(
            s,
            "{}: {} rays saved of {} ({:.1}%), largest 8-bit change {}; ",
            r.scene,
            saved,
            r.bailout_rays_without,
            100.0 * saved as f64 / r.bailout_rays_without.max(1) as f64,
            r.bailout_max_diff
        )
        .unwrap();
    }
    s.push('\n');
    s
}

/// Whether occlusion queries may be given Embree's coherent flag. Not where Embree runs its
/// 16-wide AVX-512 kernels: their coherent occlusion path (`occludedCoherent`, the frustum walk,
/// which `rtcOccluded16` and, through its conversion to packets, `rtcOccluded1M` take) hung in
/// Embree 3.13.5 on the render scenes' bounce-0 shadow rays (AMD EPYC family 26, Zen 5: the
/// Whitted frame once spun for over an hour; when retried, the Whitted and Cornell frames had
/// not finished after 60 to 240 s, in `rtcOccluded16` and in `rtcOccluded1M`; with the
/// incoherent flag, or with `isa=avx2`, each renders in well under a second). Closest-hit
/// queries keep the flag. `EMBREE_ISA` naming a narrower ISA than AVX-512 restores it.
fn coherent_occlusion() -> bool {
    let narrower = std::env::var("EMBREE_ISA").is_ok_and(|i| !i.trim().is_empty() && !i.contains("avx512"));
    #[cfg(target_arch = "x86_64")]
    let avx512 = std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
        && std::arch::is_x86_feature_detected!("avx512bw")
        && std::arch::is_x86_feature_detected!("avx512dq");
    #[cfg(not(target_arch = "x86_64"))]
    let avx512 = false;
    narrower || !avx512
}
