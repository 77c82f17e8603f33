//! The BVH over a scene's solids: the same binned SAH builder and wide nodes as the triangles
//! and spheres, one solid per primitive reference, each leaf block naming up to [`BLOCK`]
//! solids. Solids are tested one ray at a time in float64 ([`CompiledSolid`]); packets and
//! streams are answered lane by lane.

use std::time::Instant;

use glam::{Vec3, Vec3A};

use super::Solid;
use super::csg::CompiledSolid;
use super::primitive::Bound;
use super::solve::QuarticSolver;
use crate::bvh::build::{self, Aabb, PrimRef};
use crate::bvh::node::{EMPTY, Node, leaf_blocks};
use crate::bvh::traverse::{
    BoxRay, PacketBoxes, PacketHits, SlabTerms, Stack, Tree, closer_packet_by, walk_packet, walk1, with_stack,
};
use crate::bvh::{BoxTest, BuildConfig, BuildStats, PlacedTree, place_tree};
use crate::error::{Error, Result};
use crate::geometry::triangle::BLOCK;
use crate::ray::{Hit, HitPacket, INVALID_ID, PACKET_WIDTH, Ray, RayPacket};
use crate::simd::*;

/// A built BVH over solids.
#[derive(Clone, Debug)]
pub(crate) struct SolidBvh {
    pub nodes: Vec<Node>,
    /// Solid indices per leaf block, `u32::MAX` past the end.
    blocks: Vec<[u32; BLOCK]>,
    pub solids: Vec<CompiledSolid>,
    pub root: u32,
    pub bounds: Option<(Vec3, Vec3)>,
    box_test: BoxTest,
    geom_base: u32,
    pub solver: QuarticSolver,
    pub stats: BuildStats,
}

impl SolidBvh {
    /// An empty tree.
    pub fn empty() -> Self {
        SolidBvh {
            nodes: Vec::new(),
            blocks: Vec::new(),
            solids: Vec::new(),
            root: EMPTY,
            bounds: None,
            box_test: BoxTest::default(),
            geom_base: 0,
            solver: QuarticSolver::default(),
            stats: BuildStats::default(),
        }
    }

    /// Whether the tree holds no solid.
    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.root == EMPTY
    }

    /// Checks and builds `solids`, solid `i` being geometry `geom_base + i`.
    pub fn build(solids: &[Solid], geom_base: usize, cfg: &BuildConfig) -> Result<Self> {
        let start = Instant::now();
        if solids.is_empty() {
            return Ok(Self { solver: cfg.quartic_solver, ..Self::empty() });
        }
        if geom_base + solids.len() >= u32::MAX as usize {
            return Err(Error::TooManyGeometries(geom_base + solids.len()));
        }
        let compiled = solids
            .iter()
            .enumerate()
            .map(|(i, s)| {
                CompiledSolid::new(s, cfg.quartic_solver).map_err(|message| Error::BadSolid { index: i, message })
            })
            .collect::<Result<Vec<_>>>()?;
        let mut prims: Vec<PrimRef> = compiled
            .iter()
            .enumerate()
            .map(|(i, c)| PrimRef::new(Aabb { lo: Vec3A::from(c.bounds.0), hi: Vec3A::from(c.bounds.1) }, i as u32))
            .collect();
        // Solids cost far more to test than a node: small leaves.
        let cfg = BuildConfig { min_leaf: 1, max_leaf: BLOCK, intersection_cost: 4.0, ..cfg.clone() };
        let tree = build::build(&mut prims, &cfg);
        let PlacedTree { nodes, leaves, root, bounds, cost } = place_tree(tree, false);
        let mut blocks = Vec::new();
        for &(first, count) in &leaves {
            for s in (first..first + count).step_by(BLOCK) {
                let mut b = [u32::MAX; BLOCK];
                for (slot, p) in b.iter_mut().zip(&prims[s..(first + count).min(s + BLOCK)]) {
                    *slot = p.id();
                }
                blocks.push(b);
            }
        }
        let bytes = nodes.len() * size_of::<Node>()
            + blocks.len() * size_of::<[u32; BLOCK]>()
            + compiled.iter().map(|c| c.leaves.len() * size_of::<super::csg::Leaf>()).sum::<usize>();
        let root_area = bounds.map_or(0.0, |(lo, hi)| Aabb { lo: lo.into(), hi: hi.into() }.half_area() as f64);
        let stats = BuildStats {
            shapes: compiled.len(),
            inner_nodes: nodes.len(),
            leaves: leaves.len(),
            blocks: blocks.len(),
            references: compiled.len(),
            sah: if root_area > 0.0 { cost.sah / root_area } else { cost.sah },
            bytes,
            depth: cost.depth,
            build_ms: start.elapsed().as_secs_f64() * 1e3,
            ..Default::default()
        };
        Ok(SolidBvh {
            nodes,
            blocks,
            solids: compiled,
            root,
            bounds,
            box_test: cfg.box_test,
            geom_base: geom_base as u32,
            solver: cfg.quartic_solver,
            stats,
        })
    }

    #[inline(always)]
    fn tree(&self) -> Tree<'_> {
        Tree { nodes: &self.nodes, blocks: &[], far_memory: false }
    }

    /// The public record of a crossing of solid `s`: the outward unit normal, `prim_id` the
    /// leaf primitive's index in the solid.
    fn hit_record(&self, s: u32, t: f32, b: &Bound, ray: &Ray) -> Hit {
        Hit {
            t,
            u: 0.0,
            v: 0.0,
            ng: self.solids[s as usize].normal(ray.origin, ray.dir, b),
            prim_id: b.leaf as u32,
            geom_id: self.geom_base + s,
            inst_id: INVALID_ID,
        }
    }

    /// Closest hit (`ANY = false`) or first hit found (`ANY = true`) of one ray; invalid rays
    /// miss.
    pub fn trace1<const ANY: bool>(&self, ray: &Ray) -> Option<Hit> {
        if self.is_empty() || !ray.is_valid() {
            return None;
        }
        let ray = ray.read_fields().clamped_to_zero();
        with_stack(|stack| {
            with_level!(|L| match self.box_test {
                BoxTest::Conservative => self.trace1_on::<ANY, true, L>(&ray, stack),
                BoxTest::Fast => self.trace1_on::<ANY, false, L>(&ray, stack),
            })
        })
    }

    /// [`trace1`](Self::trace1) of a checked ray (valid, `tnear ≥ 0`) on `stack` above its
    /// entries, the walk at level `L`.
    #[inline(never)]
    pub(crate) fn trace1_on<const ANY: bool, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        stack: &mut Stack,
    ) -> Option<Hit> {
        if self.is_empty() {
            return None;
        }
        L::call(
            #[inline(always)]
            || {
                let best = self.walk_from::<ANY, CONS, L>(ray, SlabTerms::of(ray), self.root, stack);
                best.map(|(s, t, b)| self.hit_record(s, t, &b, ray))
            },
        )
    }

    /// The walk of one checked ray over the subtree at `root`: the solid hit, `t` and the
    /// crossing.
    #[inline(always)]
    fn walk_from<const ANY: bool, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        terms: SlabTerms,
        root: u32,
        stack: &mut Stack,
    ) -> Option<(u32, f32, Bound)> {
        let base = stack.push_root(root);
        let br = BoxRay::<L>::with_terms(terms, ray.tnear);
        let mut tfar = ray.tfar;
        let mut best = None;
        walk1::<ANY, CONS, L>(self.tree(), &br, stack, base, &mut tfar, |leaf, tfar, _| {
            let (start, count) = leaf_blocks(leaf);
            for block in &self.blocks[start..start + count] {
                for &s in block.iter().take_while(|&&s| s != u32::MAX) {
                    let solid = &self.solids[s as usize];
                    if let Some((t, b)) = solid.first_hit_at::<L>(ray.origin, ray.dir, ray.tnear, *tfar) {
                        *tfar = t;
                        best = Some((s, t, b));
                        if ANY {
                            return true;
                        }
                    }
                }
            }
            false
        });
        best
    }

    /// Closest hits (`ANY = false`) or occlusion (`ANY = true`) of the active lanes of a packet
    /// into `hit` (every lane rewritten); returns the lanes that hit. Invalid rays miss.
    ///
    /// The packet walks the tree as a triangle packet does (its frustum, or per-lane node tests
    /// and single rays for subtrees few lanes enter); at a leaf, each solid is tested, one lane
    /// at a time, for the lanes whose rays enter the solid's box (Embree hands a user
    /// geometry's callback a packet's lanes the same way).
    pub fn trace_packet<const ANY: bool>(&self, p: &RayPacket, hit: &mut HitPacket) -> u32 {
        let mut out = PacketHits::new(hit);
        if !self.is_empty() {
            with_stack(|stack| {
                with_level!(|L| match self.box_test {
                    BoxTest::Conservative => self.trace_packet_with::<ANY, true, L>(p, &mut out, stack),
                    BoxTest::Fast => self.trace_packet_with::<ANY, false, L>(p, &mut out, stack),
                })
            });
        }
        out.mask
    }

    #[inline(never)]
    fn trace_packet_with<const ANY: bool, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        out: &mut PacketHits<'_>,
        stack: &mut Stack,
    ) {
        L::call(
            #[inline(always)]
            || self.trace_packet_in::<ANY, CONS, L>(p, out, stack),
        )
    }

    /// [`trace_packet_with`](Self::trace_packet_with)'s body, compiled for the level.
    #[inline(always)]
    fn trace_packet_in<const ANY: bool, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        out: &mut PacketHits<'_>,
        stack: &mut Stack,
    ) {
        let Some((pb, mut tfar)) = PacketBoxes::<L>::new(p) else {
            return;
        };
        // Each lane's checked ray, and its closest crossing so far (normals made once, at the end).
        let rays: [Ray; PACKET_WIDTH] = std::array::from_fn(|l| p.get(l).clamped_to_zero());
        let mut best: [Option<(u32, Bound)>; PACKET_WIDTH] = [None; PACKET_WIDTH];
        let base = stack.push_root(self.root);
        let leaf_walk = hot!(|leaf: u32, lanes: u32, tfar: &mut L::Pf, stack: &mut Stack| {
            let mut t = tfar.to_array();
            let mut bits = lanes;
            while bits != 0 {
                // Few lanes entered this subtree: each walks it alone.
                let l = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let ray = Ray { tfar: t[l], ..rays[l] };
                if let Some((s, th, b)) = self.walk_from::<ANY, CONS, L>(&ray, pb.slabs.lane(l), leaf, stack) {
                    out.mask |= 1 << l;
                    t[l] = if ANY { f32::NEG_INFINITY } else { th };
                    best[l] = Some((s, b));
                }
            }
            if lanes == 0 {
                let (start, count) = leaf_blocks(leaf);
                for block in &self.blocks[start..start + count] {
                    for &s in block.iter().take_while(|&&s| s != u32::MAX) {
                        let solid = &self.solids[s as usize];
                        let (lo, hi) = solid.bounds;
                        let mut bits = pb.lanes_in_box::<CONS>(lo.to_array(), hi.to_array(), L::Pf::new(t));
                        while bits != 0 {
                            let l = bits.trailing_zeros() as usize;
                            bits &= bits - 1;
                            let r = &rays[l];
                            if let Some((th, b)) = solid.first_hit_at::<L>(r.origin, r.dir, r.tnear, t[l]) {
                                out.mask |= 1 << l;
                                t[l] = if ANY { f32::NEG_INFINITY } else { th };
                                best[l] = Some((s, b));
                            }
                        }
                    }
                }
            }
            *tfar = L::Pf::new(t);
            ANY && out.mask == pb.live
        });
        walk_packet::<ANY, CONS, L>(self.tree(), &pb, stack, base, &mut tfar, leaf_walk);
        if !ANY {
            let t = tfar.to_array();
            for (l, b) in best.iter().enumerate() {
                if let Some((s, b)) = b {
                    out.hit.set(l, Some(self.hit_record(*s, t[l], b, &rays[l])));
                }
            }
        }
    }

    /// [`trace_packet`](Self::trace_packet) on `stack` above its entries, the box test and
    /// level chosen by the caller: an instance's object walk. Lanes whose object-space rays are
    /// not valid miss.
    pub(crate) fn trace_packet_on<const ANY: bool, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        hit: &mut HitPacket,
        stack: &mut Stack,
    ) -> u32 {
        let mut out = PacketHits::new(hit);
        if !self.is_empty() {
            self.trace_packet_with::<ANY, CONS, L>(p, &mut out, stack);
        }
        out.mask
    }

    /// The closest hits of a packet nearer than those already in `hits`, written over them;
    /// returns the lanes this walk hit.
    pub fn closer_packet(&self, p: &RayPacket, hits: &mut HitPacket) -> u32 {
        if self.is_empty() {
            return 0;
        }
        with_stack(|stack| {
            with_level!(|L| match self.box_test {
                BoxTest::Conservative => self.closer_packet_with::<true, L>(p, hits, stack),
                BoxTest::Fast => self.closer_packet_with::<false, L>(p, hits, stack),
            })
        })
    }

    /// [`closer_packet`](Self::closer_packet) at a level (see the sphere tree's).
    #[inline(never)]
    fn closer_packet_with<const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        hits: &mut HitPacket,
        stack: &mut Stack,
    ) -> u32 {
        closer_packet_by::<L>(
            p,
            hits,
            #[inline(always)]
            |q, out| self.trace_packet_in::<false, CONS, L>(q, out, stack),
        )
    }

    /// Calls `f` for every surface crossing of `ray` in `(tnear, tfar]` with a solid, in no
    /// particular order (per solid ascending). Invalid rays cross nothing.
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

    /// [`each_hit`](Self::each_hit) of a checked ray on `stack` above its entries, inside the
    /// caller's [`Level::call`].
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
        let base = stack.push_root(self.root);
        let br = BoxRay::<L>::with_terms(SlabTerms::of(ray), ray.tnear);
        let mut tfar = ray.tfar;
        walk1::<false, CONS, L>(self.tree(), &br, stack, base, &mut tfar, |leaf, tfar, _| {
            let (start, count) = leaf_blocks(leaf);
            for block in &self.blocks[start..start + count] {
                for &s in block.iter().take_while(|&&s| s != u32::MAX) {
                    self.solids[s as usize].each_crossing(ray.origin, ray.dir, ray.tnear, *tfar, |t, b| {
                        f(&self.hit_record(s, t, &b, ray));
                    });
                }
            }
            false
        });
    }

    /// The closest hit by testing every solid: the reference the tree is tested against.
    pub fn brute_force(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let ray = ray.clamped_to_zero();
        let mut best: Option<(u32, f32, Bound)> = None;
        for (s, c) in self.solids.iter().enumerate() {
            let tfar = best.map_or(ray.tfar, |b| b.1);
            if let Some((t, b)) = with_level!(|L| c.first_hit_at::<L>(ray.origin, ray.dir, ray.tnear, tfar)) {
                best = Some((s as u32, t, b));
            }
        }
        best.map(|(s, t, b)| self.hit_record(s, t, &b, &ray))
    }
}
