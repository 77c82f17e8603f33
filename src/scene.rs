//! The public query API: the [`Query`] trait, and the flat [`Scene`]. A built scene answers closest-hit (`intersect*`) and any-hit
//! (`occluded*`) queries for single rays, packets and streams, serially or in parallel.
//!
//! A `Scene` is immutable once built, `Send + Sync`, and can be queried from many threads at once.

use std::path::Path;

use glam::Vec3;
use rayon::prelude::*;

use crate::bvh::group::GROUP;
use crate::bvh::stream::{STREAM_RAYS, octant_of_dir};
use crate::bvh::{BoxTest, BuildConfig, BuildStats, Bvh};
use crate::error::Result;
use crate::geometry::TriangleTest;
use crate::geometry::{TriangleMesh, load_obj};
use crate::ray::{Hit, HitPacket, HitSlice, HitStream, PACKET_WIDTH, Ray, RayPacket, RayStream};
use crate::shapes::solid_tree::SolidBvh;
use crate::shapes::tree::SphereBvh;
use crate::shapes::{QuarticSolver, Solid, SphereSet, SphereTest};
use crate::simd::{Level, with_level};

/// How a stream query groups its rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coherence {
    /// Neighbouring rays take similar paths (camera rays in 4×4 tiles, shadow rays from them
    /// towards one light): closest-hit queries trace each [`GROUP`] of consecutive packets of
    /// [`PACKET_WIDTH`] rays together (one 8×8 pixel block of camera rays; see
    /// [`Query::intersect_group_each`]), any-hit queries trace packet by packet.
    Coherent,
    /// Rays are unrelated (diffuse bounces). Closest-hit queries sort each group of 4096 rays
    /// by direction octant and trace them 16 at a time as packets, walked per lane (each stack
    /// entry keeping the lanes' entry distances) down to nodes few lanes enter, which each lane
    /// then walks alone (Embree's hybrid walk). Any-hit queries trace 16 consecutive rays of
    /// one direction octant as a packet (shadow rays towards one light, mostly: 3× faster than
    /// one by one) and the others one at a time in octant order. Two-level scenes trace every
    /// query as packets of 16 consecutive rays (see [`Query::INCOHERENT_PACKETS`]).
    Incoherent,
}

/// Rays per parallel work item of the `*_par` stream queries (a multiple of [`PACKET_WIDTH`]).
///
/// Each chunk is a rayon job of its own (`with_max_len(1)`). Left to rayon's adaptive splitting,
/// two threads split 256 chunks into pieces of 32–64 chunks that are never split again unless
/// stolen, so one thread could sit idle while the other finished its last piece. In the harness,
/// 2 threads, only the single-ray passes running, Sponza's single-ray API ran 10.6 Mrays/s that way
/// and 14.25 with a job per chunk (Embree's `rtcIntersect1` in the same loop: 14.3 → 17.5).
pub const STREAM_CHUNK: usize = 4096;

/// Meshes, spheres and solids, and a BVH over each kind (see [`crate::shapes`]).
#[derive(Clone, Debug)]
pub struct Scene {
    meshes: Vec<TriangleMesh>,
    bvh: Bvh,
    spheres: Vec<SphereSet>,
    shapes: SphereBvh,
    solids: Vec<Solid>,
    solid_tree: SolidBvh,
}

impl Scene {
    /// A scene from its parts, the meshes' tree checked by the caller (`persist`); the sphere
    /// tree is built here.
    pub(crate) fn from_parts(
        meshes: Vec<TriangleMesh>,
        bvh: Bvh,
        spheres: Vec<SphereSet>,
        solids: Vec<Solid>,
        cfg: BuildConfig,
    ) -> Result<Self> {
        let cfg = BuildConfig { box_test: bvh.box_test, ..cfg };
        let shapes = SphereBvh::build(&spheres, meshes.len(), &cfg)?;
        let solid_tree = SolidBvh::build(&solids, meshes.len() + spheres.len(), &cfg)?;
        Ok(Self { meshes, bvh, spheres, shapes, solids, solid_tree })
    }

    /// The sphere test the scene's spheres are intersected with.
    pub fn sphere_test(&self) -> SphereTest {
        self.shapes.test
    }

    /// Builds the BVH over `meshes` on the current rayon pool. Geometry ids are indices into
    /// `meshes`. An empty list gives an empty scene that every ray misses.
    pub fn build(meshes: Vec<TriangleMesh>, config: &BuildConfig) -> Result<Self> {
        Self::build_with_spheres(meshes, Vec::new(), config)
    }

    /// Builds a scene of meshes and analytic spheres: one BVH over the triangles, one over the
    /// spheres (tested with `config.sphere_test`). Geometry ids: meshes first, in order, then
    /// the sphere sets (set `s` is geometry `meshes.len() + s`).
    pub fn build_with_spheres(
        meshes: Vec<TriangleMesh>,
        spheres: Vec<SphereSet>,
        config: &BuildConfig,
    ) -> Result<Self> {
        Self::build_with_solids(meshes, spheres, Vec::new(), config)
    }

    /// Builds a scene of meshes, analytic spheres and solids (primitives placed by affine maps
    /// and combined by CSG; see [`Solid`]): one BVH per kind. Geometry ids: the meshes, then the
    /// sphere sets, then the solids (solid `i` is geometry `meshes.len() + spheres.len() + i`;
    /// a hit's `prim_id` is the index of the primitive hit among the solid's leaves, in the
    /// order they appear in its tree). Solids are checked: [`Error::BadSolid`](crate::Error)
    /// names the first that cannot be built.
    pub fn build_with_solids(
        meshes: Vec<TriangleMesh>,
        spheres: Vec<SphereSet>,
        solids: Vec<Solid>,
        config: &BuildConfig,
    ) -> Result<Self> {
        let bvh = Bvh::build(&meshes, config)?;
        let shapes = SphereBvh::build(&spheres, meshes.len(), config)?;
        let solid_tree = SolidBvh::build(&solids, meshes.len() + spheres.len(), config)?;
        Ok(Self { meshes, bvh, spheres, shapes, solids, solid_tree })
    }

    /// The solids (geometry ids from `meshes().len() + spheres().len()` on).
    pub fn solids(&self) -> &[Solid] {
        &self.solids
    }

    /// The quartic solver the scene's tori are intersected with.
    pub fn quartic_solver(&self) -> QuarticSolver {
        self.solid_tree.solver
    }

    /// The solid tree's build statistics (`shapes` solids; all zero without solids).
    pub fn solid_stats(&self) -> &BuildStats {
        &self.solid_tree.stats
    }

    /// The solid tree (empty without solids).
    pub(crate) fn solid_tree(&self) -> &SolidBvh {
        &self.solid_tree
    }

    /// The sphere sets (geometry ids from `meshes().len()` on).
    pub fn spheres(&self) -> &[SphereSet] {
        &self.spheres
    }

    /// The sphere tree's build statistics (`shapes` spheres; all zero without spheres).
    pub fn sphere_stats(&self) -> &BuildStats {
        &self.shapes.stats
    }

    /// Whether the scene holds spheres or solids.
    #[inline(always)]
    fn has_shapes(&self) -> bool {
        !self.shapes.is_empty() || !self.solid_tree.is_empty()
    }

    /// Loads an OBJ file (one geometry per object/group) and builds it.
    pub fn from_obj(path: impl AsRef<Path>, config: &BuildConfig) -> Result<Self> {
        Self::build(load_obj(path)?, config)
    }

    /// The meshes the scene was built from (their index is `Hit::geom_id`).
    pub fn meshes(&self) -> &[TriangleMesh] {
        &self.meshes
    }

    /// The triangle and box tests this scene was built for.
    pub fn tests(&self) -> (TriangleTest, BoxTest) {
        (self.bvh.test, self.bvh.box_test)
    }

    /// Build statistics: time, sizes, counts, SAH cost.
    pub fn stats(&self) -> &BuildStats {
        &self.bvh.stats
    }

    /// Bounds of the hittable triangles, the spheres and the solids, or `None` for an empty
    /// scene.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let join = |a: Option<(Vec3, Vec3)>, b: Option<(Vec3, Vec3)>| match (a, b) {
            (Some(a), Some(b)) => Some((a.0.min(b.0), a.1.max(b.1))),
            (a, b) => a.or(b),
        };
        join(join(self.bvh.bounds, self.shapes.bounds), self.solid_tree.bounds)
    }

    /// Number of triangles over all meshes (hittable or not).
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.triangle_count()).sum()
    }

    /// The closest hit by testing every triangle, with the same triangle test as the BVH: the
    /// reference the BVH is tested against. O(triangles) per ray.
    pub fn intersect_brute_force(&self, ray: &Ray) -> Option<Hit> {
        let tri = self.bvh.brute_force(ray).map(|h| self.bvh.hit_record(&h));
        let bounded = Ray { tfar: tri.map_or(ray.tfar, |h| h.t), ..*ray };
        let sph = self.shapes.brute_force(&bounded).or(tri);
        let bounded = Ray { tfar: sph.map_or(ray.tfar, |h| h.t), ..*ray };
        self.solid_tree.brute_force(&bounded).or(sph)
    }

    pub(crate) fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// The sphere tree (empty without spheres).
    pub(crate) fn sphere_tree(&self) -> &SphereBvh {
        &self.shapes
    }

    /// Whether this scene's walks prefetch the children they enter (see [`Bvh::prefetch`]).
    pub(crate) fn set_prefetch(&mut self, on: bool) {
        self.bvh.prefetch = on;
    }
}

/// Queries of a scene with spheres walk the triangle tree first, then the sphere tree with each
/// ray's interval cut to its triangle hit (or, for any-hit queries, only the rays the triangles
/// left unoccluded). Scenes without spheres pay one branch per query.
impl Query for Scene {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let tri = self.bvh.trace1::<false>(ray).map(|h| self.bvh.hit_record(&h));
        if !self.has_shapes() {
            return tri;
        }
        let bounded = Ray { tfar: tri.map_or(ray.tfar, |h| h.t), ..*ray };
        let sph = self.shapes.trace1::<false>(&bounded).or(tri);
        if self.solid_tree.is_empty() {
            return sph;
        }
        let bounded = Ray { tfar: sph.map_or(ray.tfar, |h| h.t), ..*ray };
        self.solid_tree.trace1::<false>(&bounded).or(sph)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.bvh.trace1::<true>(ray).is_some()
            || (self.has_shapes()
                && (self.shapes.trace1::<true>(ray).is_some() || self.solid_tree.trace1::<true>(ray).is_some()))
    }

    fn intersect_packet_each(&self, rays: &RayPacket, mut f: impl FnMut(usize, &Hit)) {
        let mut hits = HitPacket::default();
        let mut mask = self.bvh.trace_packet::<false>(rays, &mut hits);
        if self.has_shapes() {
            mask |= self.shapes.closer_packet(rays, &mut hits);
            mask |= self.solid_tree.closer_packet(rays, &mut hits);
        }
        each_hit(&hits, mask, |lane, h| f(lane, h));
    }

    fn intersect_packet(&self, rays: &RayPacket, hits: &mut HitPacket) {
        self.bvh.trace_packet::<false>(rays, hits);
        if self.has_shapes() {
            self.shapes.closer_packet(rays, hits);
            self.solid_tree.closer_packet(rays, hits);
        }
    }

    fn occluded_packet(&self, rays: &RayPacket) -> u32 {
        let tri = self.bvh.occluded_packet(rays);
        if !self.has_shapes() || tri == rays.active & crate::simd::low_bits(PACKET_WIDTH) {
            return tri;
        }
        // The lanes still open; the packet itself while none is closed (no 512-byte copy).
        fn open<'a>(rays: &'a RayPacket, closed: u32, rest: &'a mut Option<RayPacket>) -> &'a RayPacket {
            if closed == 0 { rays } else { rest.insert(RayPacket { active: rays.active & !closed, ..*rays }) }
        }
        let sph = tri | self.shapes.occluded_packet(open(rays, tri, &mut None));
        if self.solid_tree.is_empty() || sph == rays.active & crate::simd::low_bits(PACKET_WIDTH) {
            return sph;
        }
        sph | self.solid_tree.trace_packet::<true>(open(rays, sph, &mut None), &mut HitPacket::default())
    }

    /// Trees of more than 32 MiB. Below that, nodes come from the cache, and packets of 16 (with
    /// their frustum) and single rays beat the occlusion groups' per-ray node tests: shadow rays,
    /// 2 threads, Sponza 73 against 40 Mrays/s, igea 29 against 25. Above it the groups fetch
    /// each node once for all their rays and prefetch the children they push: on the
    /// 11M-triangle sphereflake 12.4 against 8.3 Mrays/s (PERFORMANCE.md). The walks of such
    /// trees also prefetch the children they enter.
    fn out_of_cache(&self) -> bool {
        self.bvh.out_of_cache()
    }

    fn occluded_octant_rays(&self, rays: &RayStream, base: usize, ids: &[u16], octant: u32) -> u32 {
        let mut bits = self.bvh.occluded_octant(rays, base, ids, octant);
        if self.has_shapes() {
            for (i, &id) in ids.iter().enumerate().take(32) {
                let ray = rays.get(base + id as usize);
                if bits & (1 << i) == 0
                    && (self.shapes.trace1::<true>(&ray).is_some() || self.solid_tree.trace1::<true>(&ray).is_some())
                {
                    bits |= 1 << i;
                }
            }
        }
        bits
    }

    fn intersect_group(&self, rays: &[RayPacket; GROUP], hits: &mut [HitPacket; GROUP]) {
        self.bvh.trace_group(rays, hits);
        if self.has_shapes() {
            for (p, h) in rays.iter().zip(hits.iter_mut()) {
                self.shapes.closer_packet(p, h);
                self.solid_tree.closer_packet(p, h);
            }
        }
    }

    fn intersect_group_each(&self, rays: &[RayPacket; GROUP], mut f: impl FnMut(usize, usize, &Hit)) {
        let mut hits = [HitPacket::default(); GROUP];
        self.intersect_group(rays, &mut hits);
        for (i, h) in hits.iter().enumerate() {
            each_hit(h, u32::MAX, |lane, h| f(i, lane, h));
        }
    }
}

/// Calls `f(lane, hit)` for the lanes of `mask` that hit in `hits`.
#[inline(always)]
pub(crate) fn each_hit(hits: &HitPacket, mask: u32, mut f: impl FnMut(usize, &Hit)) {
    let mut bits = mask & crate::simd::low_bits(PACKET_WIDTH);
    while bits != 0 {
        let lane = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        if let Some(h) = hits.get(lane) {
            f(lane, &h);
        }
    }
}

/// The queries every scene answers: closest hit (`intersect*`) and any hit (`occluded*`) for
/// single rays, packets and streams, serially or in parallel. Implemented by the flat [`Scene`]
/// and the two-level [`InstancedScene`](crate::InstancedScene); stream queries are written once,
/// here, on top of the single-ray and packet queries.
pub trait Query: Sync {
    /// The closest hit of `ray` in `(tnear, tfar]`, or `None`. Invalid rays (see
    /// [`Ray::is_valid`]) miss.
    fn intersect(&self, ray: &Ray) -> Option<Hit>;

    /// Whether anything lies on `ray` in `(tnear, tfar]`. Invalid rays are not occluded.
    fn occluded(&self, ray: &Ray) -> bool;

    /// Whether incoherent streams are traced as packets of consecutive rays instead of packets
    /// of rays sorted by direction octant (closest hit) or single rays in octant order (any
    /// hit): true for two-level scenes, whose instance level is then walked once per packet and
    /// whose instance transforms are computed 16 lanes at once (Embree's stream does the same
    /// with its packets of 16); the objects are still walked one ray at a time. (Octant-sorted
    /// packets measured no faster there: forest 3.61 against 3.65, big world 2.91 against 3.17
    /// Mrays/s, 1 thread.)
    const INCOHERENT_PACKETS: bool = false;

    /// Whether the scene's tree outgrows the cache (a measured 32 MiB), which changes how incoherent
    /// occlusion streams are traced: in groups of up to 32 rays of one direction octant through
    /// [`occluded_octant_rays`](Self::occluded_octant_rays) instead of packets and single rays.
    /// True for flat scenes above 32 MiB of nodes and blocks (see [`Scene`]'s implementation).
    fn out_of_cache(&self) -> bool {
        false
    }

    /// Occlusion of the rays `base + ids[i]` of `rays`: bit `i` set where ray `i` is occluded. At
    /// most 32 rays: those beyond are not traced and read as not occluded. The rays should share
    /// the direction octant `octant` (bit `a` set where the sign bit of direction component `a`
    /// is, `-0.0` included); a ray outside it is answered alone. Every `base + id` must lie in
    /// the stream (else this panics, like slice indexing). Flat scenes walk the rays
    /// together (Embree's occlusion stream); the default asks one ray at a time.
    fn occluded_octant_rays(&self, rays: &RayStream, base: usize, ids: &[u16], octant: u32) -> u32 {
        let _ = octant;
        ids.iter()
            .take(32)
            .enumerate()
            .fold(0, |m, (i, &id)| m | (self.occluded(&rays.get(base + id as usize)) as u32) << i)
    }

    /// Calls `f(lane, hit)` for every active lane of `rays` that hits something (closest hit).
    fn intersect_packet_each(&self, rays: &RayPacket, f: impl FnMut(usize, &Hit));

    /// Bit mask of the active lanes of `rays` that are occluded.
    fn occluded_packet(&self, rays: &RayPacket) -> u32;

    /// Calls `f(packet, lane, hit)` for every active lane of [`GROUP`] packets that hits something
    /// (closest hit). The packets of one camera's 8×8 pixel block (four 4×4 tiles, one origin)
    /// are traced together by flat scenes, with fewer node tests per ray than packet by packet;
    /// other packets are traced one by one.
    fn intersect_group_each(&self, rays: &[RayPacket; GROUP], mut f: impl FnMut(usize, usize, &Hit)) {
        for (i, p) in rays.iter().enumerate() {
            self.intersect_packet_each(p, |lane, h| f(i, lane, h));
        }
    }

    /// Closest hits of [`GROUP`] packets (see
    /// [`intersect_group_each`](Self::intersect_group_each)); lanes without a hit are written as
    /// misses.
    fn intersect_group(&self, rays: &[RayPacket; GROUP], hits: &mut [HitPacket; GROUP]) {
        for (p, h) in rays.iter().zip(hits.iter_mut()) {
            self.intersect_packet(p, h);
        }
    }

    /// Closest hits of the active lanes of `rays`; inactive lanes are written as misses.
    fn intersect_packet(&self, rays: &RayPacket, hits: &mut HitPacket) {
        *hits = HitPacket::default();
        self.intersect_packet_each(rays, |lane, h| hits.set(lane, Some(*h)));
    }

    /// Closest hits of every ray of a stream; `hits` is resized to the stream's length.
    fn intersect_stream(&self, rays: &RayStream, hits: &mut HitStream, coherence: Coherence) {
        hits.resize_uncleared(rays.len());
        intersect_range(self, rays, 0, hits.as_slice_mut(), coherence);
    }

    /// Occlusion of every ray of a stream; `occluded` is resized to the stream's length.
    fn occluded_stream(&self, rays: &RayStream, occluded: &mut Vec<bool>, coherence: Coherence) {
        occluded.clear();
        occluded.resize(rays.len(), false);
        occluded_range(self, rays, 0, occluded, coherence);
    }

    /// [`intersect_stream`](Self::intersect_stream) spread over the current rayon pool in chunks
    /// of [`STREAM_CHUNK`] rays.
    fn intersect_stream_par(&self, rays: &RayStream, hits: &mut HitStream, coherence: Coherence) {
        hits.resize_uncleared(rays.len());
        hits.par_chunks_mut(STREAM_CHUNK)
            .enumerate()
            .with_max_len(1)
            .for_each(|(i, out)| intersect_range(self, rays, i * STREAM_CHUNK, out, coherence));
    }

    /// [`occluded_stream`](Self::occluded_stream) spread over the current rayon pool.
    fn occluded_stream_par(&self, rays: &RayStream, occluded: &mut Vec<bool>, coherence: Coherence) {
        occluded.clear();
        occluded.resize(rays.len(), false);
        occluded
            .par_chunks_mut(STREAM_CHUNK)
            .enumerate()
            .with_max_len(1)
            .for_each(|(i, out)| occluded_range(self, rays, i * STREAM_CHUNK, out, coherence));
    }
}

/// Rays `start..start + out.len()` of `rays` into `out`. (Compiled for the kernels' level, as
/// [`occluded_range`] is, the diffuse streams of a dependency build ran 3% slower; not done.)
fn intersect_range<Q: Query + ?Sized>(
    q: &Q,
    rays: &RayStream,
    start: usize,
    mut out: HitSlice<'_>,
    coherence: Coherence,
) {
    let n = out.len();
    if coherence == Coherence::Coherent || Q::INCOHERENT_PACKETS {
        const G: usize = GROUP * PACKET_WIDTH;
        let whole = n / G * G;
        // Whole groups write every entry.
        out.clear(whole);
        let mut ps = [RayPacket::default(); GROUP];
        let mut hs = [HitPacket::default(); GROUP];
        for k in (0..whole).step_by(G) {
            for (i, p) in ps.iter_mut().enumerate() {
                rays.whole_packet_into(start + k + i * PACKET_WIDTH, p);
            }
            q.intersect_group(&ps, &mut hs);
            for (i, h) in hs.iter().enumerate() {
                out.set_packet(k + i * PACKET_WIDTH, h);
            }
        }
        for k in (whole..n).step_by(PACKET_WIDTH) {
            let p = rays.packet(start + k, (n - k).min(PACKET_WIDTH));
            q.intersect_packet_each(&p, |lane, h| out.set(k + lane, h));
        }
    } else {
        // Incoherent rays of a flat scene: in groups of `OCTANT_GROUP` ordered by direction
        // octant, 16 at a time as a packet (walked per lane: they share no origin).
        out.clear(0);
        let mut p = RayPacket::default();
        each_octant_group(rays, start, n, |g, _, order| {
            for ids in order.chunks(PACKET_WIDTH) {
                rays.gather_packet_into(start + g, ids, &mut p);
                q.intersect_packet_each(&p, |lane, h| out.set(g + ids[lane] as usize, h));
            }
        });
    }
}

/// Rays per octant-sorting group of an incoherent stream.
const OCTANT_GROUP: usize = 4096;

/// The direction octant of rays `base..base + oct.len()`: one bit per component whose sign bit is
/// set (`-0.0` included, as the slab tests see it; see [`octant_of_dir`]).
#[inline(always)]
fn octants(rays: &RayStream, base: usize, oct: &mut [u8]) {
    let n = oct.len();
    let (dx, dy, dz) = (&rays.dx[base..base + n], &rays.dy[base..base + n], &rays.dz[base..base + n]);
    for (i, o) in oct.iter_mut().enumerate() {
        *o = octant_of_dir(dx[i], dy[i], dz[i]) as u8;
    }
}

/// Rays `start..start + n` in groups of [`OCTANT_GROUP`]: `f(g, oct, order)` for each group, where
/// `g` is the group's first ray (from `start`), `oct` its rays' octants and `order` their indices
/// (from `g`) sorted by octant, stably.
#[inline(always)]
fn each_octant_group(rays: &RayStream, start: usize, n: usize, mut f: impl FnMut(usize, &[u8], &[u16])) {
    let mut oct = [0u8; OCTANT_GROUP];
    let mut order = [0u16; OCTANT_GROUP];
    for g in (0..n).step_by(OCTANT_GROUP) {
        let m = (n - g).min(OCTANT_GROUP);
        octants(rays, start + g, &mut oct[..m]);
        sort_by_octant(0..m as u16, &oct, &mut order[..m]);
        f(g, &oct[..m], &order[..m]);
    }
}

/// `ids` into `order` by their octant `oct[id]`: a stable counting sort.
#[inline(always)]
fn sort_by_octant(ids: impl Iterator<Item = u16> + Clone, oct: &[u8], order: &mut [u16]) {
    let mut count = [0u16; 9];
    for id in ids.clone() {
        count[oct[id as usize] as usize + 1] += 1;
    }
    for o in 0..8 {
        count[o + 1] += count[o];
    }
    for id in ids {
        let o = oct[id as usize] as usize;
        order[count[o] as usize] = id;
        count[o] += 1;
    }
}

/// Occlusion of rays `start..start + out.len()` of `rays` into `out`. The stream's own work (rays
/// copied into packets, answers out of them, the octant sort) is compiled for the kernels'
/// level, as the walks are; a dependency build did it at SSE2 (shadow streams 2–4% slower).
fn occluded_range<Q: Query + ?Sized>(q: &Q, rays: &RayStream, start: usize, out: &mut [bool], coherence: Coherence) {
    with_level!(|L| L::call(
        #[inline(always)]
        || occluded_range_in(q, rays, start, out, coherence)
    ))
}

/// [`occluded_range`]'s body.
#[inline(always)]
fn occluded_range_in<Q: Query + ?Sized>(q: &Q, rays: &RayStream, start: usize, out: &mut [bool], coherence: Coherence) {
    let n = out.len();
    let packet = |k: usize, m: usize, out: &mut [bool]| {
        let bits = q.occluded_packet(&rays.packet(start + k, m));
        for (lane, o) in out[k..k + m].iter_mut().enumerate() {
            *o = bits & (1 << lane) != 0;
        }
    };
    if coherence == Coherence::Coherent || Q::INCOHERENT_PACKETS {
        for k in (0..n).step_by(PACKET_WIDTH) {
            packet(k, (n - k).min(PACKET_WIDTH), out);
        }
        return;
    }
    if q.out_of_cache() {
        occluded_in_octant_groups(q, rays, start, out);
        return;
    }
    // Incoherent rays of a flat scene: 16 consecutive rays in one direction octant (shadow rays
    // towards one light, mostly) still go as a packet, tested per lane (they share no origin, so
    // no frustum); the others one at a time, in octant order.
    let mut oct = [0u8; OCTANT_GROUP];
    let mut rest = [0u16; OCTANT_GROUP];
    let mut order = [0u16; OCTANT_GROUP];
    for g in (0..n).step_by(OCTANT_GROUP) {
        let m = (n - g).min(OCTANT_GROUP);
        octants(rays, start + g, &mut oct[..m]);
        let mut r = 0;
        for k in (0..m).step_by(PACKET_WIDTH) {
            let lanes = &oct[k..m.min(k + PACKET_WIDTH)];
            if lanes.iter().all(|&o| o == lanes[0]) {
                packet(g + k, lanes.len(), out);
            } else {
                for i in k..k + lanes.len() {
                    rest[r] = i as u16;
                    r += 1;
                }
            }
        }
        sort_by_octant(rest[..r].iter().copied(), &oct, &mut order[..r]);
        for &i in &order[..r] {
            let k = g + i as usize;
            out[k] = q.occluded(&rays.get(start + k));
        }
    }
}

/// Incoherent occlusion rays `start..start + out.len()` in groups of up to [`STREAM_RAYS`] rays of
/// one direction octant, in stream order within each octant (Embree's octant-sorted occlusion
/// stream), each group walked together by [`Query::occluded_octant_rays`].
#[inline(always)]
fn occluded_in_octant_groups<Q: Query + ?Sized>(q: &Q, rays: &RayStream, start: usize, out: &mut [bool]) {
    each_octant_group(rays, start, out.len(), |g, oct, order| {
        let m = order.len();
        let mut k = 0;
        while k < m {
            let o = oct[order[k] as usize];
            let mut e = k + 1;
            while e < m && e - k < STREAM_RAYS && oct[order[e] as usize] == o {
                e += 1;
            }
            let ids = &order[k..e];
            let bits = q.occluded_octant_rays(rays, start + g, ids, o as u32);
            for (i, &id) in ids.iter().enumerate() {
                out[g + id as usize] = bits & (1 << i) != 0;
            }
            k = e;
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raygen::Pcg32;

    /// The octant-group path that large flat scenes take for incoherent occlusion streams gives
    /// the single-ray answers, with signed-zero direction components (whose clamped reciprocals
    /// take the sign) and invalid rays among the rays, across more than one sorting group.
    #[test]
    fn octant_groups_answer_as_single_rays() {
        let scene = Scene::build(vec![crate::procedural::sphereflake(2, 6, 12)], &BuildConfig::default()).unwrap();
        let mut rng = Pcg32::new(3, 5);
        let mut v = |s: f32| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 * s - Vec3::splat(s);
        let mut rays = RayStream::default();
        for i in 0..OCTANT_GROUP + 777 {
            let o = v(2.5);
            let mut d = v(1.0) - o;
            match i % 11 {
                0 => d.x = -0.0,
                1 => d.y = 0.0,
                2 => (d.y, d.z) = (-0.0, -0.0),
                3 => d = Vec3::ZERO,
                4 => d.z = f32::NAN,
                _ => {}
            }
            let tfar = if i % 5 == 0 { 2.0 } else { f32::INFINITY };
            rays.push(&Ray::segment(o, d, 0.0, tfar));
        }
        let mut out = vec![false; rays.len()];
        occluded_in_octant_groups(&scene, &rays, 0, &mut out);
        let mut hits = 0;
        for (i, &o) in out.iter().enumerate() {
            let expect = scene.occluded(&rays.get(i));
            assert_eq!(o, expect, "ray {i}");
            hits += expect as usize;
        }
        assert!(hits > rays.len() / 10 && hits < rays.len() * 9 / 10, "{hits} of {} occluded", rays.len());
    }

    /// A scene taken for out of the cache (its size faked) answers every query as it did before:
    /// the walks that prefetch, the occlusion groups and the ray-by-ray closest-hit streams.
    #[test]
    fn out_of_cache_paths_answer_as_before() {
        let small = Scene::build(vec![crate::procedural::sphereflake(2, 6, 12)], &BuildConfig::default()).unwrap();
        let mut big = small.clone();
        big.bvh.stats.bytes = usize::MAX;
        big.bvh.prefetch = true;
        assert!(big.out_of_cache() && !small.out_of_cache());
        let mut rng = Pcg32::new(9, 2);
        let mut v = |s: f32| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 * s - Vec3::splat(s);
        let rays: RayStream = (0..3000)
            .map(|_| {
                let o = v(2.5);
                Ray::new(o, v(1.0) - o)
            })
            .collect();
        let cam = crate::Camera::look_at(Vec3::new(0.0, 1.2, 4.5), Vec3::new(0.0, 0.3, 0.0), Vec3::Y, 60.0);
        let (primary, _) = crate::raygen::primary(&cam, 64, 48);
        for (rays, what) in [(&rays, "random"), (&primary, "primary")] {
            for c in [Coherence::Coherent, Coherence::Incoherent] {
                let (mut a, mut b) = (HitStream::default(), HitStream::default());
                small.intersect_stream(rays, &mut a, c);
                big.intersect_stream(rays, &mut b, c);
                let (mut oa, mut ob) = (Vec::new(), Vec::new());
                small.occluded_stream(rays, &mut oa, c);
                big.occluded_stream(rays, &mut ob, c);
                for i in 0..rays.len() {
                    let single = small.intersect(&rays.get(i));
                    assert_eq!(big.intersect(&rays.get(i)), single, "{what} {c:?} single ray {i}");
                    assert_eq!(b.get(i), a.get(i), "{what} {c:?} stream ray {i}");
                    assert_eq!(a.get(i).map(|h| h.t), single.map(|h| h.t), "{what} {c:?} ray {i}");
                    assert_eq!(ob[i], oa[i], "{what} {c:?} occlusion ray {i}");
                    assert_eq!(oa[i], single.is_some(), "{what} {c:?} occlusion ray {i}");
                }
            }
        }
    }
}
