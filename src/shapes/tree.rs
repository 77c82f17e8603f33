//! The BVH over a scene's spheres: built by the same binned SAH builder as the triangle BVH (from
//! boxes and centroids), placed in the same wide nodes, walked by the same single-ray and packet
//! walks (`bvh::traverse`), with sphere blocks of [`BLOCK`] at the leaves.

use std::time::Instant;

use glam::{Vec3, Vec3A};
use rayon::prelude::*;

use super::SphereSet;
use super::sphere::{self, RayLanes, SphereBlock, SphereTest};
use crate::bvh::build::{self, Aabb, PrimRef};
use crate::bvh::node::{EMPTY, MAX_BLOCK_INDEX, Node, leaf_blocks};
use crate::bvh::traverse::{
    BoxRay, LeafHit, PacketBoxes, PacketHits, SlabTerms, Stack, Tree, closer_packet_by, each_lane_alone, walk_packet,
    walk1, with_stack,
};
use crate::bvh::{BoxTest, BuildConfig, BuildStats, FAR_MEMORY_BYTES, PlacedTree, on_pool, place_tree};
use crate::error::{Error, Result};
use crate::geometry::triangle::BLOCK;
use crate::ray::{Hit, HitPacket, INVALID_ID, Ray, RayPacket};
use crate::simd::*;

/// One sphere test chosen at compile time, so that each walk is compiled for one form.
pub(crate) trait SphereKernel {
    const TEST: SphereTest;
}
pub(crate) struct GeometricK;
pub(crate) struct AlgebraicK;
pub(crate) struct RobustK;
impl SphereKernel for GeometricK {
    const TEST: SphereTest = SphereTest::Geometric;
}
impl SphereKernel for AlgebraicK {
    const TEST: SphereTest = SphereTest::Algebraic;
}
impl SphereKernel for RobustK {
    const TEST: SphereTest = SphereTest::Robust;
}

/// Evaluates `$body` with `$k` bound to the sphere kernel and `$c` to the box-test flag.
macro_rules! dispatch_spheres {
    ($test:expr, $boxes:expr, |$k:ident, $c:ident| $body:expr) => {
        match ($test, $boxes) {
            (SphereTest::Geometric, BoxTest::Conservative) => dispatch_spheres!(@arm GeometricK, true, $k, $c, $body),
            (SphereTest::Geometric, BoxTest::Fast) => dispatch_spheres!(@arm GeometricK, false, $k, $c, $body),
            (SphereTest::Algebraic, BoxTest::Conservative) => dispatch_spheres!(@arm AlgebraicK, true, $k, $c, $body),
            (SphereTest::Algebraic, BoxTest::Fast) => dispatch_spheres!(@arm AlgebraicK, false, $k, $c, $body),
            (SphereTest::Robust, BoxTest::Conservative) => dispatch_spheres!(@arm RobustK, true, $k, $c, $body),
            (SphereTest::Robust, BoxTest::Fast) => dispatch_spheres!(@arm RobustK, false, $k, $c, $body),
        }
    };
    (@arm $kernel:ty, $cons:expr, $k:ident, $c:ident, $body:expr) => {{
        type $k = $kernel;
        const $c: bool = $cons;
        $body
    }};
}

/// Open lanes at or below which a packet without a frustum tests a leaf lane by lane.
const LEAF_SWITCH: u32 = 4;

/// A built BVH over spheres.
#[derive(Clone, Debug)]
pub(crate) struct SphereBvh {
    pub nodes: Vec<Node>,
    pub blocks: Vec<SphereBlock>,
    pub root: u32,
    pub bounds: Option<(Vec3, Vec3)>,
    pub test: SphereTest,
    pub box_test: BoxTest,
    pub stats: BuildStats,
    pub prefetch: bool,
}

impl SphereBvh {
    /// Whether the tree holds no sphere.
    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.root == EMPTY
    }

    /// Builds over every sphere of `sets`, set `s` being geometry `geom_base + s`.
    pub fn build(sets: &[SphereSet], geom_base: usize, cfg: &BuildConfig) -> Result<Self> {
        let start = Instant::now();
        let total: usize = sets.iter().map(|s| s.len()).sum();
        if total.div_ceil(BLOCK) > MAX_BLOCK_INDEX || total >= u32::MAX as usize {
            return Err(Error::TooManyTriangles(total));
        }
        if geom_base + sets.len() >= u32::MAX as usize {
            return Err(Error::TooManyGeometries(geom_base + sets.len()));
        }
        let parallel = total >= cfg.parallel_threshold;
        let mut bvh = if parallel {
            on_pool(|| Self::build_untimed(sets, geom_base, cfg, parallel))
        } else {
            Self::build_untimed(sets, geom_base, cfg, parallel)
        };
        bvh.stats.build_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(bvh)
    }

    fn build_untimed(sets: &[SphereSet], geom_base: usize, cfg: &BuildConfig, parallel: bool) -> Self {
        // One global id per sphere: the sets' spheres numbered one after another.
        let offsets: Vec<usize> = sets
            .iter()
            .scan(0usize, |acc, s| {
                let o = *acc;
                *acc += s.len();
                Some(o)
            })
            .collect();
        let locate = |id: usize| {
            let g = offsets.partition_point(|&o| o <= id) - 1;
            (g, id - offsets[g])
        };
        let prim = |(g, i): (usize, usize), id: usize| {
            let (c, r) = sets[g].sphere(i);
            let (c, r) = (Vec3A::from(c), Vec3A::splat(r));
            PrimRef::new(Aabb { lo: c - r, hi: c + r }, id as u32)
        };
        let mut prims: Vec<PrimRef> = sets
            .iter()
            .enumerate()
            .flat_map(|(g, s)| (0..s.len()).map(move |i| (g, i)))
            .enumerate()
            .map(|(id, gi)| prim(gi, id))
            .collect();
        let tree = build::build(&mut prims, cfg);
        let PlacedTree { nodes, leaves, root, bounds, cost } = place_tree(tree, parallel);
        let sources: Vec<(usize, usize)> = leaves
            .iter()
            .flat_map(|&(start, count)| {
                (start..start + count).step_by(BLOCK).map(move |s| (s, (start + count - s).min(BLOCK)))
            })
            .collect();
        let make_block = |&(start, n): &(usize, usize)| {
            let mut spheres = [(0u32, 0u32, Vec3::ZERO, 0.0f32); BLOCK];
            for (slot, p) in spheres.iter_mut().zip(&prims[start..start + n]) {
                let (g, i) = locate(p.id() as usize);
                let (c, r) = sets[g].sphere(i);
                *slot = ((geom_base + g) as u32, i as u32, c, r);
            }
            SphereBlock::new(&spheres[..n])
        };
        let blocks: Vec<SphereBlock> = if parallel {
            sources.par_iter().with_min_len(256).map(make_block).collect()
        } else {
            sources.iter().map(make_block).collect()
        };
        let bytes = nodes.len() * size_of::<Node>() + blocks.len() * size_of::<SphereBlock>();
        let root_area = bounds.map_or(0.0, |(lo, hi)| Aabb { lo: lo.into(), hi: hi.into() }.half_area() as f64);
        let total = prims.len();
        let stats = BuildStats {
            shapes: total,
            inner_nodes: nodes.len(),
            leaves: leaves.len(),
            blocks: blocks.len(),
            references: total,
            sah: if root_area > 0.0 { cost.sah / root_area } else { cost.sah },
            bytes,
            depth: cost.depth,
            ..Default::default()
        };
        SphereBvh {
            nodes,
            blocks,
            root,
            bounds,
            test: cfg.sphere_test,
            box_test: cfg.box_test,
            stats,
            prefetch: bytes > FAR_MEMORY_BYTES,
        }
    }

    /// The walks' view: nodes only (sphere blocks are not prefetched).
    #[inline(always)]
    fn tree(&self) -> Tree<'_> {
        Tree { nodes: &self.nodes, blocks: &[], far_memory: self.prefetch }
    }

    /// The public record of a leaf hit of the ray `o + t d`: the normal `p − centre`.
    #[inline(always)]
    pub fn hit_record(&self, h: &LeafHit, o: Vec3, d: Vec3) -> Hit {
        let b = &self.blocks[h.block as usize];
        let lane = h.lane as usize;
        Hit {
            t: h.t,
            u: 0.0,
            v: 0.0,
            ng: d.mul_add(Vec3::splat(h.t), o) - b.center(lane),
            prim_id: b.prim[lane],
            geom_id: b.geom[lane],
            inst_id: INVALID_ID,
        }
    }

    /// Closest hit (`ANY = false`) or first hit found (`ANY = true`) of one ray; invalid rays
    /// miss.
    pub fn trace1<const ANY: bool>(&self, ray: &Ray) -> Option<Hit> {
        if self.is_empty() {
            return None;
        }
        let ray = ray.read_fields();
        if !ray.is_valid() {
            return None;
        }
        let ray = ray.clamped_to_zero();
        with_stack(|stack| {
            dispatch_spheres!(self.test, self.box_test, |K, C| with_level!(
                |L| self.trace1_with::<ANY, K, C, L>(&ray, stack)
            ))
        })
        .map(|h| self.hit_record(&h, ray.origin, ray.dir))
    }

    /// [`trace1`](Self::trace1) of a checked ray with a chosen kernel and level.
    #[inline(never)]
    fn trace1_with<const ANY: bool, K: SphereKernel, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        stack: &mut Stack,
    ) -> Option<LeafHit> {
        L::call(
            #[inline(always)]
            || self.trace1_from_terms::<ANY, K, CONS, L>(ray, SlabTerms::of(ray), self.root, stack),
        )
    }

    /// [`trace1`](Self::trace1) of a checked ray (valid, `tnear ≥ 0`) on `stack` above its
    /// entries, the box test and level chosen by the caller: an instance's object walk.
    #[inline(always)]
    pub(crate) fn trace1_on<const ANY: bool, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        stack: &mut Stack,
    ) -> Option<Hit> {
        if self.is_empty() {
            return None;
        }
        let terms = SlabTerms::of(ray);
        let h = match self.test {
            SphereTest::Geometric => self.trace1_from_terms::<ANY, GeometricK, CONS, L>(ray, terms, self.root, stack),
            SphereTest::Algebraic => self.trace1_from_terms::<ANY, AlgebraicK, CONS, L>(ray, terms, self.root, stack),
            SphereTest::Robust => self.trace1_from_terms::<ANY, RobustK, CONS, L>(ray, terms, self.root, stack),
        };
        h.map(|h| self.hit_record(&h, ray.origin, ray.dir))
    }

    /// Closest hits (`ANY = false`) or occlusion (`ANY = true`) of the active lanes of a packet,
    /// into `hit` (every lane rewritten: misses where nothing is hit), on `stack` above its
    /// entries, the box test chosen by the caller, at the caller's level: an instance's object
    /// walk. Returns the lanes that hit; invalid rays miss.
    pub(crate) fn trace_packet_on<const ANY: bool, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        hit: &mut HitPacket,
        stack: &mut Stack,
    ) -> u32 {
        let mut out = PacketHits::new(hit);
        if !self.is_empty() {
            match self.test {
                SphereTest::Geometric => self.trace_packet_with::<ANY, GeometricK, CONS, L>(p, &mut out, stack),
                SphereTest::Algebraic => self.trace_packet_with::<ANY, AlgebraicK, CONS, L>(p, &mut out, stack),
                SphereTest::Robust => self.trace_packet_with::<ANY, RobustK, CONS, L>(p, &mut out, stack),
            }
        }
        out.mask
    }

    /// The walk of one checked ray over the subtree at `root`.
    #[inline(always)]
    fn trace1_from_terms<const ANY: bool, K: SphereKernel, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        terms: SlabTerms,
        root: u32,
        stack: &mut Stack,
    ) -> Option<LeafHit> {
        let base = stack.push_root(root);
        let lanes = RayLanes::<L::F4>::splat(ray.origin, ray.dir);
        let br = BoxRay::<L>::with_terms(terms, ray.tnear);
        let mut tfar = ray.tfar;
        let mut best = None;
        walk1::<ANY, CONS, L>(
            self.tree(),
            &br,
            stack,
            base,
            &mut tfar,
            #[inline(always)]
            |leaf, tfar, _| {
                let (start, count) = leaf_blocks(leaf);
                for bi in start..start + count {
                    if let Some((lane, t)) = sphere::intersect1(K::TEST, &self.blocks[bi], &lanes, ray.tnear, *tfar) {
                        *tfar = t;
                        best = Some(LeafHit { block: bi as u32, lane: lane as u32, t, u: 0.0, v: 0.0 });
                        if ANY {
                            return true;
                        }
                    }
                }
                false
            },
        );
        best
    }

    /// The occluded lanes of a packet, the hits recorded in a scratch record made at the
    /// kernels' level (see `Bvh::trace_packet_with`).
    pub fn occluded_packet(&self, p: &RayPacket) -> u32 {
        if self.is_empty() {
            return 0;
        }
        with_stack(|stack| {
            dispatch_spheres!(self.test, self.box_test, |K, C| with_level!(
                |L| self.occluded_packet_with::<K, C, L>(p, stack)
            ))
        })
    }

    #[inline(never)]
    fn occluded_packet_with<K: SphereKernel, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        stack: &mut Stack,
    ) -> u32 {
        L::call(
            #[inline(always)]
            || {
                let mut hit = HitPacket::default();
                let mut out = PacketHits::new(&mut hit);
                self.trace_packet_in::<true, K, CONS, L>(p, &mut out, stack);
                out.mask
            },
        )
    }

    #[inline(never)]
    fn trace_packet_with<const ANY: bool, K: SphereKernel, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        out: &mut PacketHits<'_>,
        stack: &mut Stack,
    ) {
        L::call(
            #[inline(always)]
            || self.trace_packet_in::<ANY, K, CONS, L>(p, out, stack),
        )
    }

    /// [`trace_packet_with`](Self::trace_packet_with)'s body, compiled for the level.
    #[inline(always)]
    fn trace_packet_in<const ANY: bool, K: SphereKernel, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        out: &mut PacketHits<'_>,
        stack: &mut Stack,
    ) {
        let Some((pb, mut tfar)) = PacketBoxes::<L>::new(p) else {
            return;
        };
        let base = stack.push_root(self.root);
        let rl = RayLanes::<L::Pf>::new(pb.o, pb.d);
        let switch = pb.frustum.is_none();
        let leaf_walk = hot!(|leaf: u32, lanes: u32, tfar: &mut L::Pf, stack: &mut Stack| {
            // Closest hit without a frustum (incoherent packets): a leaf few lanes are still open
            // for goes lane by lane, four spheres per test, instead of sixteen lanes per sphere.
            // Diffuse rays, level-6 flake, 2 threads, best vs best against Embree: 0.98 before,
            // 1.09 and 1.03 after (two runs; the machine's noise is about ±8%). Any-hit packets
            // measured no better (1.18 against 1.25) and keep the packet test.
            let lanes = if lanes == 0 && switch && !ANY {
                let open = pb.live & pb.tnear.simd_le(*tfar).to_bitmask();
                if open.count_ones() <= LEAF_SWITCH { open } else { 0 }
            } else {
                lanes
            };
            if lanes != 0 {
                out.mask |= each_lane_alone::<ANY, _, L>(
                    p,
                    lanes,
                    tfar,
                    #[inline(always)]
                    |l, ray| {
                        let h = self.trace1_from_terms::<ANY, K, CONS, L>(ray, pb.slabs.lane(l), leaf, stack)?;
                        Some((h.t, h))
                    },
                    #[inline(always)]
                    |l, h| {
                        let r = p.get(l);
                        out.set(l, &self.hit_record(&h, r.origin, r.dir))
                    },
                );
                return ANY && out.mask == pb.live;
            }
            self.leaf_packet::<ANY, K, L>(leaf, &pb, &rl, tfar, out)
        });
        walk_packet::<ANY, CONS, L>(self.tree(), &pb, stack, base, &mut tfar, leaf_walk);
    }

    /// Tests the spheres of `leaf` against the open lanes of a packet (see the triangle BVH's
    /// `leaf_packet`).
    #[inline(always)]
    fn leaf_packet<const ANY: bool, K: SphereKernel, L: Level>(
        &self,
        leaf: u32,
        pb: &PacketBoxes<L>,
        lanes: &RayLanes<L::Pf>,
        tfar: &mut L::Pf,
        out: &mut PacketHits<'_>,
    ) -> bool {
        let (start, count) = leaf_blocks(leaf);
        let active = pb.tnear.simd_le(*tfar);
        for bi in start..start + count {
            let blk = &self.blocks[bi];
            for lane in 0..BLOCK {
                if blk.prim[lane] == u32::MAX {
                    break;
                }
                let (valid, t) = sphere::intersect_packet(K::TEST, blk, lane, lanes, pb.tnear, *tfar);
                let valid = valid & active;
                let bits = valid.to_bitmask();
                if bits == 0 {
                    continue;
                }
                out.mask |= bits;
                if ANY {
                    *tfar = valid.select(L::Pf::splat(f32::NEG_INFINITY), *tfar);
                    if out.mask == pb.live {
                        return true;
                    }
                    continue;
                }
                *tfar = valid.select(t, *tfar);
                let c = blk.center(lane);
                let ng = [
                    t.mul_add(pb.d[0], pb.o[0]) - L::Pf::splat(c.x),
                    t.mul_add(pb.d[1], pb.o[1]) - L::Pf::splat(c.y),
                    t.mul_add(pb.d[2], pb.o[2]) - L::Pf::splat(c.z),
                ];
                let zero = L::Pf::splat(0.0);
                out.select_hit::<L>(valid, (t, zero, zero), ng, blk.prim[lane], blk.geom[lane]);
            }
        }
        false
    }

    /// The closest hits of a packet nearer than those already in `hits` (a first walk's, over
    /// the scene's triangles), written over them; returns the lanes this walk hit.
    pub fn closer_packet(&self, p: &RayPacket, hits: &mut HitPacket) -> u32 {
        if self.is_empty() {
            return 0;
        }
        with_stack(|stack| {
            dispatch_spheres!(self.test, self.box_test, |K, C| with_level!(
                |L| self.closer_packet_with::<K, C, L>(p, hits, stack)
            ))
        })
    }

    /// [`closer_packet`](Self::closer_packet) at a level: the packet's `tfar` lowered to the
    /// hits so far and the merge of the walk's hits into them are compiled with the walk (in a
    /// dependency build they ran at SSE2 outside it, copies of 512-byte packets included).
    #[inline(never)]
    fn closer_packet_with<K: SphereKernel, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        hits: &mut HitPacket,
        stack: &mut Stack,
    ) -> u32 {
        closer_packet_by::<L>(
            p,
            hits,
            #[inline(always)]
            |q, out| self.trace_packet_in::<false, K, CONS, L>(q, out, stack),
        )
    }

    /// Calls `f` for every surface crossing of `ray` in `(tnear, tfar]` with a sphere (both roots
    /// where both lie in the interval: entering and leaving), in no particular order; the
    /// crossings a point-in-solid parity counts. Invalid rays cross nothing.
    pub fn each_hit(&self, ray: &Ray, mut f: impl FnMut(&Hit)) {
        if self.is_empty() || !ray.is_valid() {
            return;
        }
        let ray = ray.clamped_to_zero();
        with_stack(|stack| {
            with_level!(|L| L::call(
                #[inline(always)]
                || match self.box_test {
                    BoxTest::Conservative => self.each_hit_on::<true, L>(&ray, stack, &mut f),
                    BoxTest::Fast => self.each_hit_on::<false, L>(&ray, stack, &mut f),
                }
            ))
        });
    }

    /// [`each_hit`](Self::each_hit) of a checked ray (valid, `tnear ≥ 0`) on `stack` above its
    /// entries, the box test and level chosen by the caller.
    #[inline(always)]
    pub(crate) fn each_hit_on<const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        stack: &mut Stack,
        f: &mut impl FnMut(&Hit),
    ) {
        if self.is_empty() {
            return;
        }
        let rl = RayLanes::<L::F4>::splat(ray.origin, ray.dir);
        let test = self.test;
        let base = stack.push_root(self.root);
        let br = BoxRay::<L>::with_terms(SlabTerms::of(ray), ray.tnear);
        // The walk's `tfar` stays the ray's: every subtree the ray enters is visited.
        let mut tfar = ray.tfar;
        let leaf_walk = hot!(|leaf: u32, tfar: &mut f32, _: &mut Stack| {
            let (start, count) = leaf_blocks(leaf);
            for bi in start..start + count {
                let b = &self.blocks[bi];
                let row = hot!(|k: usize| L::F4::new(b.rows[k]));
                let (t0, t1, meet) = sphere::roots(test, [row(0), row(1), row(2)], row(3), &rl);
                let (t0, t1) = (t0.to_array(), t1.to_array());
                let mut bits = meet.to_bitmask();
                while bits != 0 {
                    let lane = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    for t in [t0[lane], t1[lane]] {
                        if t > ray.tnear && t <= *tfar {
                            let h = LeafHit { block: bi as u32, lane: lane as u32, t, u: 0.0, v: 0.0 };
                            f(&self.hit_record(&h, ray.origin, ray.dir));
                        }
                    }
                }
            }
            false
        });
        walk1::<false, CONS, L>(self.tree(), &br, stack, base, &mut tfar, leaf_walk);
    }

    /// The closest hit by testing every block: the reference the tree is tested against (at the
    /// active level, as the walks are).
    pub fn brute_force(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let ray = ray.clamped_to_zero();
        with_level!(|L| L::call(
            #[inline(always)]
            || self.brute_force_with::<L>(&ray)
        ))
    }

    #[inline(always)]
    fn brute_force_with<L: Level>(&self, ray: &Ray) -> Option<Hit> {
        let lanes = RayLanes::<L::F4>::splat(ray.origin, ray.dir);
        let mut tfar = ray.tfar;
        let mut best = None;
        for (bi, b) in self.blocks.iter().enumerate() {
            if let Some((lane, t)) = sphere::intersect1(self.test, b, &lanes, ray.tnear, tfar) {
                tfar = t;
                best = Some(LeafHit { block: bi as u32, lane: lane as u32, t, u: 0.0, v: 0.0 });
            }
        }
        best.map(|h| self.hit_record(&h, ray.origin, ray.dir))
    }
}
