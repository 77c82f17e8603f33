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
use crate::bvh::traverse::{BoxRay, SlabTerms, Stack, Tree, walk1, with_stack};
use crate::bvh::{BoxTest, BuildConfig, BuildStats, PlacedTree, place_tree};
use crate::error::{Error, Result};
use crate::geometry::triangle::BLOCK;
use crate::ray::{Hit, HitPacket, INVALID_ID, PACKET_WIDTH, Ray, RayPacket};
use crate::simd::{Level, with_level};

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
                let base = stack.push_root(self.root);
                let br = BoxRay::<L>::with_terms(SlabTerms::of(ray), ray.tnear);
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
                best.map(|(s, t, b)| self.hit_record(s, t, &b, ray))
            },
        )
    }

    /// Closest hits (`ANY = false`) or occlusion (`ANY = true`) of the active lanes of a packet,
    /// lane by lane, into `hit` (every lane rewritten); returns the lanes that hit.
    pub fn trace_packet<const ANY: bool>(&self, p: &RayPacket, hit: &mut HitPacket) -> u32 {
        *hit = HitPacket::default();
        let mut mask = 0;
        let mut bits = p.active & crate::simd::low_bits(PACKET_WIDTH);
        while bits != 0 {
            let l = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            if let Some(h) = self.trace1::<ANY>(&p.get(l)) {
                mask |= 1 << l;
                hit.set(l, Some(h));
            }
        }
        mask
    }

    /// [`trace_packet`](Self::trace_packet) on `stack` above its entries, the box test chosen
    /// by the caller: an instance's object walk. Lanes whose object-space rays are not valid
    /// miss.
    pub(crate) fn trace_packet_on<const ANY: bool, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        hit: &mut HitPacket,
        stack: &mut Stack,
    ) -> u32 {
        *hit = HitPacket::default();
        let mut mask = 0;
        let mut bits = p.active & crate::simd::low_bits(PACKET_WIDTH);
        while bits != 0 {
            let l = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let ray = p.get(l);
            if !ray.is_valid() {
                continue;
            }
            if let Some(h) = self.trace1_on::<ANY, CONS, L>(&ray.clamped_to_zero(), stack) {
                mask |= 1 << l;
                hit.set(l, Some(h));
            }
        }
        mask
    }

    /// The closest hits of a packet nearer than those already in `hits`, written over them;
    /// returns the lanes this walk hit.
    pub fn closer_packet(&self, p: &RayPacket, hits: &mut HitPacket) -> u32 {
        if self.is_empty() {
            return 0;
        }
        let mut mask = 0;
        let mut bits = p.active & crate::simd::low_bits(PACKET_WIDTH);
        while bits != 0 {
            let l = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let mut r = p.get(l);
            r.tfar = r.tfar.min(hits.t[l]);
            if let Some(h) = self.trace1::<false>(&r) {
                mask |= 1 << l;
                hits.set(l, Some(h));
            }
        }
        mask
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
