//! Kernel mode (BENCHMARKING.md's headline): each engine traces from its own native input layout,
//! prepared before the timed region, and only the query calls are timed.
//!
//! - strahl: an array of [`Ray`]s (single), of [`RayPacket`]s (packet: 4×4 tiles or 16 consecutive
//!   rays), the SoA [`RayStream`] (stream); answers into arrays of `Option<Hit>` / `bool`,
//!   [`HitPacket`]s / occlusion masks, a [`HitStream`].
//! - Embree: arrays of `RTCRayHit` / `RTCRay` (`rtcIntersect1`, `rtcIntersect1M`), of
//!   64-byte-aligned `RTCRayHit16` / `RTCRay16` with their valid masks (`rtcIntersect16`); the
//!   records are copied from pristine ones before each pass (untimed) and answered in place.
//!
//! The answers are read back after the timed region ([`StrahlNative::answers`],
//! [`EmbreeNative::answers`]).

use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use strahl::{Hit, HitPacket, HitStream, PACKET_WIDTH, Query, Ray, RayPacket, RayStream};

use crate::embree::{self, RTCRay, RTCRay16, RTCRayHit, RTCRayHit16};
use crate::harness::{
    Answers, CHUNK, Class, coherence, embree_answer, embree_ray, empty_hit, hit_answer, occlusion_answer,
};

/// Packets per parallel work item (as many rays as [`CHUNK`]).
const PACKETS_PER_ITEM: usize = CHUNK / PACKET_WIDTH;

/// strahl's native inputs and outputs for one ray set.
pub struct StrahlNative {
    rays: Vec<Ray>,
    packets: Vec<RayPacket>,
    stream: RayStream,
    hits: Vec<Option<Hit>>,
    occluded: Vec<bool>,
    hit_packets: Vec<HitPacket>,
    occluded_packets: Vec<u32>,
    hit_stream: HitStream,
    occluded_stream: Vec<bool>,
}

impl StrahlNative {
    pub fn new(rays: &RayStream) -> Self {
        let n = rays.len();
        let packets: Vec<RayPacket> =
            (0..n).step_by(PACKET_WIDTH).map(|k| rays.packet(k, (n - k).min(PACKET_WIDTH))).collect();
        let np = packets.len();
        Self {
            rays: (0..n).map(|i| rays.get(i)).collect(),
            packets,
            stream: rays.clone(),
            hits: vec![None; n],
            occluded: vec![false; n],
            hit_packets: vec![HitPacket::default(); np],
            occluded_packets: vec![0; np],
            hit_stream: HitStream::default(),
            occluded_stream: Vec::new(),
        }
    }

    pub fn single<Q: Query>(&mut self, scene: &Q, class: Class) {
        if class.occlusion() {
            self.rays.par_chunks(CHUNK).zip(self.occluded.par_chunks_mut(CHUNK)).with_max_len(1).for_each(|(r, o)| {
                for (r, o) in r.iter().zip(o) {
                    *o = scene.occluded(r);
                }
            });
        } else {
            self.rays.par_chunks(CHUNK).zip(self.hits.par_chunks_mut(CHUNK)).with_max_len(1).for_each(|(r, h)| {
                for (r, h) in r.iter().zip(h) {
                    *h = scene.intersect(r);
                }
            });
        }
    }

    pub fn packet<Q: Query>(&mut self, scene: &Q, class: Class) {
        let chunks = self.packets.par_chunks(PACKETS_PER_ITEM);
        if class.occlusion() {
            chunks.zip(self.occluded_packets.par_chunks_mut(PACKETS_PER_ITEM)).with_max_len(1).for_each(|(p, o)| {
                for (p, o) in p.iter().zip(o) {
                    *o = scene.occluded_packet(p);
                }
            });
        } else {
            chunks.zip(self.hit_packets.par_chunks_mut(PACKETS_PER_ITEM)).with_max_len(1).for_each(|(p, h)| {
                for (p, h) in p.iter().zip(h) {
                    scene.intersect_packet(p, h);
                }
            });
        }
    }

    pub fn stream<Q: Query>(&mut self, scene: &Q, class: Class) {
        if class.occlusion() {
            scene.occluded_stream_par(&self.stream, &mut self.occluded_stream, coherence(class));
        } else {
            scene.intersect_stream_par(&self.stream, &mut self.hit_stream, coherence(class));
        }
    }

    /// The answers of the last `single`, `packet` (api 1) or `stream` (api 2) call.
    pub fn answers(&self, class: Class, api: usize, out: &mut Answers) {
        for i in 0..out.len() {
            let a = match (api, class.occlusion()) {
                (0, true) => occlusion_answer(self.occluded[i]),
                (0, false) => hit_answer(self.hits[i]),
                (1, true) => occlusion_answer(self.occluded_packets[i / PACKET_WIDTH] & (1 << (i % PACKET_WIDTH)) != 0),
                (1, false) => hit_answer(self.hit_packets[i / PACKET_WIDTH].get(i % PACKET_WIDTH)),
                (_, true) => occlusion_answer(self.occluded_stream[i]),
                (_, false) => hit_answer(self.hit_stream.get(i)),
            };
            out.set(i, a);
        }
    }
}

/// One API's median speed on both engines.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ApiTimes {
    pub api: String,
    /// Median Mrays/s over the passes.
    pub strahl: f64,
    pub embree: f64,
}

/// The three APIs' names, in the order [`Timed`] indexes them.
pub const API_NAMES: [&str; 3] = ["single", "packet", "stream"];

/// One ray set traced in kernel mode on both engines, interleaved: one warm-up pass, then
/// `passes` timed ones; each pass times the three APIs, each API both engines, the engine
/// that goes first alternating pass by pass, so that the machine's drift falls on both alike.
pub struct Timed {
    /// Seconds per timed pass, `[engine][api]` (engine 0 strahl, 1 Embree).
    pub secs: [[Vec<f64>; 3]; 2],
    /// Each engine's answers from its last stream pass.
    pub answers: [Answers; 2],
}

impl Timed {
    pub fn run<Q: Query + Sync>(
        scene: &Q,
        escene: &embree::Scene,
        rays: &RayStream,
        class: Class,
        passes: usize,
        pool: &rayon::ThreadPool,
    ) -> Self {
        let n = rays.len();
        let mut sn = StrahlNative::new(rays);
        let mut en = EmbreeNative::new(rays);
        let mut secs: [[Vec<f64>; 3]; 2] = Default::default();
        let mut answers = [Answers::misses(n), Answers::misses(n)];
        for pass in 0..=passes {
            for api in 0..3 {
                let order = if pass % 2 == 0 { [0, 1] } else { [1, 0] };
                for engine in order {
                    if engine == 1 {
                        en.refresh(class, api);
                    }
                    let start = Instant::now();
                    pool.install(|| match (engine, api) {
                        (0, 0) => sn.single(scene, class),
                        (0, 1) => sn.packet(scene, class),
                        (0, _) => sn.stream(scene, class),
                        (_, 0) => en.single(escene, class),
                        (_, 1) => en.packet(escene, class),
                        _ => en.stream(escene, class),
                    });
                    let t = start.elapsed().as_secs_f64();
                    if pass > 0 {
                        secs[engine][api].push(t);
                    }
                    if pass == passes && api == 2 {
                        if engine == 0 {
                            sn.answers(class, api, &mut answers[0]);
                        } else {
                            en.answers(class, api, &mut answers[1]);
                        }
                    }
                }
            }
        }
        Self { secs, answers }
    }

    fn median(&self, engine: usize, api: usize) -> f64 {
        let mut s = self.secs[engine][api].clone();
        s.sort_by(f64::total_cmp);
        s.get(s.len() / 2).copied().unwrap_or(f64::NAN)
    }

    /// Median Mrays/s of each API on both engines, for `n` rays.
    pub fn apis(&self, n: usize) -> Vec<ApiTimes> {
        (0..3)
            .map(|a| ApiTimes {
                api: API_NAMES[a].to_string(),
                strahl: n as f64 / self.median(0, a) / 1e6,
                embree: n as f64 / self.median(1, a) / 1e6,
            })
            .collect()
    }

    /// Each engine's best API (by median time).
    pub fn best(&self, engine: usize) -> usize {
        (0..3).min_by(|&a, &b| self.median(engine, a).total_cmp(&self.median(engine, b))).unwrap_or(2)
    }

    /// Per timed pass: Embree's time with its best API over strahl's with its best (above 1:
    /// strahl faster).
    pub fn best_ratios(&self) -> Vec<f64> {
        let (bs, be) = (self.best(0), self.best(1));
        self.secs[0][bs].iter().zip(&self.secs[1][be]).map(|(s, e)| e / s).collect()
    }
}

/// One 64-byte-aligned 16-ray packet of Embree's with its valid mask.
#[derive(Clone, Copy)]
pub struct EmbreePacket {
    valid: [i32; 16],
    rh: RTCRayHit16,
}

/// Embree's native inputs for one ray set: pristine records and the work copies traced in place.
pub struct EmbreeNative {
    pristine_rh: Vec<RTCRayHit>,
    pristine_r: Vec<RTCRay>,
    pristine_p: Vec<EmbreePacket>,
    rh: Vec<RTCRayHit>,
    r: Vec<RTCRay>,
    p: Vec<EmbreePacket>,
}

impl EmbreeNative {
    pub fn new(rays: &RayStream) -> Self {
        let n = rays.len();
        let pristine_rh: Vec<RTCRayHit> =
            (0..n).map(|i| RTCRayHit { ray: embree_ray(rays, i), hit: empty_hit() }).collect();
        let pristine_r = pristine_rh.iter().map(|rh| rh.ray).collect();
        let pristine_p = (0..n)
            .step_by(16)
            .map(|k| {
                let mut p = EmbreePacket { valid: [0; 16], rh: empty_packet() };
                for l in 0..(n - k).min(16) {
                    p.valid[l] = -1;
                    set_lane(&mut p.rh, l, &pristine_rh[k + l].ray);
                }
                p
            })
            .collect();
        Self { pristine_rh, pristine_r, pristine_p, rh: Vec::new(), r: Vec::new(), p: Vec::new() }
    }

    /// Fresh work records for the next pass of `api` (untimed).
    pub fn refresh(&mut self, class: Class, api: usize) {
        self.rh.clear();
        self.r.clear();
        self.p.clear();
        match (api, class.occlusion()) {
            (1, _) => self.p.extend_from_slice(&self.pristine_p),
            (_, true) => self.r.extend_from_slice(&self.pristine_r),
            (_, false) => self.rh.extend_from_slice(&self.pristine_rh),
        }
    }

    pub fn single(&mut self, scene: &embree::Scene, class: Class) {
        let c = class.coherent();
        if class.occlusion() {
            self.r
                .par_chunks_mut(CHUNK)
                .with_max_len(1)
                .for_each(|ch| ch.iter_mut().for_each(|r| scene.occluded1(r, c)));
        } else {
            self.rh
                .par_chunks_mut(CHUNK)
                .with_max_len(1)
                .for_each(|ch| ch.iter_mut().for_each(|r| scene.intersect1(r, c)));
        }
    }

    pub fn packet(&mut self, scene: &embree::Scene, class: Class) {
        let c = class.coherent();
        let occ = class.occlusion();
        self.p.par_chunks_mut(PACKETS_PER_ITEM).with_max_len(1).for_each(|ch| {
            for p in ch {
                if occ {
                    scene.occluded16(&p.valid, &mut p.rh.ray, c);
                } else {
                    scene.intersect16(&p.valid, &mut p.rh, c);
                }
            }
        });
    }

    pub fn stream(&mut self, scene: &embree::Scene, class: Class) {
        let c = class.coherent();
        if class.occlusion() {
            self.r.par_chunks_mut(CHUNK).with_max_len(1).for_each(|ch| scene.occluded1m(ch, c));
        } else {
            self.rh.par_chunks_mut(CHUNK).with_max_len(1).for_each(|ch| scene.intersect1m(ch, c));
        }
    }

    /// The answers of the last traced `api` (0 single, 1 packet, 2 stream).
    pub fn answers(&self, class: Class, api: usize, out: &mut Answers) {
        for i in 0..out.len() {
            let a = if api == 1 {
                let (p, l) = (&self.p[i / 16].rh, i % 16);
                if class.occlusion() {
                    occlusion_answer(p.ray.tfar[l] == f32::NEG_INFINITY)
                } else {
                    embree_answer(p.ray.tfar[l], p.hit.geomID[l], p.hit.primID[l], p.hit.instID[0][l])
                }
            } else if class.occlusion() {
                occlusion_answer(self.r[i].tfar == f32::NEG_INFINITY)
            } else {
                let h = &self.rh[i];
                embree_answer(h.ray.tfar, h.hit.geomID, h.hit.primID, h.hit.instID[0])
            };
            out.set(i, a);
        }
    }
}

/// An all-inactive packet with every hit id invalid.
pub fn empty_packet() -> RTCRayHit16 {
    use crate::embree::{RTC_INVALID_GEOMETRY_ID as INV, RTCHit16};
    RTCRayHit16 {
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
            primID: [INV; 16],
            geomID: [INV; 16],
            instID: [[INV; 16]],
        },
    }
}

pub(crate) fn set_lane(p: &mut RTCRayHit16, l: usize, r: &RTCRay) {
    let q = &mut p.ray;
    (q.org_x[l], q.org_y[l], q.org_z[l], q.tnear[l]) = (r.org_x, r.org_y, r.org_z, r.tnear);
    (q.dir_x[l], q.dir_y[l], q.dir_z[l], q.tfar[l], q.id[l]) = (r.dir_x, r.dir_y, r.dir_z, r.tfar, r.id);
}
