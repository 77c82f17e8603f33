//! Coherent groups: [`GROUP`] camera packets (an 8×8 pixel block of 4×4 tiles) traced as one.
//!
//! A 16-ray packet pays one frustum test, one stack entry and one child ordering per node for
//! 16 rays. Near the root every packet of a camera makes the same choices, so a group walks the
//! upper tree once under the frustum bounding all its packets, and splits only where it must:
//! below a node smaller than the group's footprint, and at leaves, each packet's own frustum
//! decides which packets go on (the "packet" bit mask kept on the stack entry, as the hybrid walk
//! keeps lane masks). Leaves are tested per packet, 16 lanes at a time, with the packet leaf test
//! of [`Bvh::leaf_packet`]. Below a node smaller than half of a packet's own footprint, where
//! even a packet's frustum accepts nodes few of its rays enter, each packet continues with its
//! own walk and that walk's per-lane mode. This is the large-packet, multi-frustum walk of
//! Reshetov et al. ("Multi-Level Ray Tracing Algorithm", SIGGRAPH 2005) and of Wald et al.'s BVH
//! packets ("Ray Tracing Deformable Scenes Using Dynamic Bounding Volume Hierarchies", TOG 2007),
//! on Embree's frustum node test.

use super::Bvh;
use super::node::{EMPTY, Node, WIDTH, is_leaf};
use super::traverse::{BoxTest, Frustum, PacketBoxes, PacketHits, Stack, WIDEN, dispatch, with_stack};
use crate::geometry::badouel::Badouel;
use crate::geometry::moeller::Moller;
use crate::geometry::triangle::{Kernel, RayK, TriangleTest};
use crate::geometry::watertight::Watertight;
use crate::ray::{HitPacket, RayPacket};
use crate::simd::*;

/// Packets per coherent group: four 4×4 tiles, an 8×8 pixel block.
pub const GROUP: usize = 4;

/// A stack entry of a group walk with this bit in its lane field is tested per packet; the low
/// bits name the packets that entered it. Without it, the entry is tested with the group's
/// frustum for every packet.
const PER_PACKET: u32 = 1 << 15;

/// With [`PER_PACKET`]: the entry is smaller than the footprint of a packet that enters it, and
/// each of its packets walks it alone, with the packet walk's per-lane mode (the frusta accept
/// most such nodes although few rays enter them). Without it, a flattened forest of 13.5 million
/// triangles ran at 3.8 Mrays/s in groups against 7.4 packet by packet.
const SOLO: u32 = 1 << 14;

/// A child goes [`SOLO`] when smaller than this fraction of the footprint `Frustum::small` uses.
/// Measured (1 thread) with the fraction 1 / 0.5 / 0.25: flattened forest 6.0–6.3 / 5.7–5.8 /
/// 5.1–5.2 Mrays/s, sphereflake 29.3 / 31.2–31.8 / 32.2–32.6 (31.3–32.1 without handing off).
const SOLO_SCALE: f32 = 0.5;

/// The children of `node` that are leaves.
#[inline(always)]
fn leaf_children(node: &Node) -> u32 {
    let c: Ni = bytemuck::cast(node.child);
    (c.is_negative() & !c.simd_eq(Ni::splat(EMPTY as i32))).to_bitmask()
}

impl Bvh {
    /// Closest hits of [`GROUP`] packets traced together (see the module comment). Packets that
    /// do not share one origin and direction octant are traced one by one.
    /// The hits go to `hits` (without instance ids; an out-parameter: returned by value, the
    /// results were copied twice per group).
    pub(crate) fn trace_group(&self, ps: &[RayPacket; GROUP], hits: &mut [HitPacket; GROUP]) {
        if self.root == EMPTY {
            // No triangles: every lane misses.
            for h in hits.iter_mut() {
                PacketHits::new(h);
            }
            return;
        }
        with_stack(|stack| {
            dispatch!(self.test, self.box_test, |K, C| {
                let mut out = hits.each_mut().map(PacketHits::new);
                with_level!(|L| self.trace_group_with::<K, C, L>(ps, &mut out, stack))
            })
        })
    }

    #[inline(never)]
    pub(crate) fn trace_group_with<K: Kernel, const CONS: bool, L: Level>(
        &self,
        ps: &[RayPacket; GROUP],
        out: &mut [PacketHits<'_>; GROUP],
        stack: &mut Stack,
    ) {
        L::call(
            #[inline(always)]
            || self.trace_group_in::<K, CONS, L>(ps, out, stack),
        )
    }

    /// [`trace_group_with`](Self::trace_group_with)'s body, compiled for the level.
    #[inline(always)]
    fn trace_group_in<K: Kernel, const CONS: bool, L: Level>(
        &self,
        ps: &[RayPacket; GROUP],
        out: &mut [PacketHits<'_>; GROUP],
        stack: &mut Stack,
    ) {
        if self.root == EMPTY {
            return;
        }
        // Per packet with a live lane: its frustum, triangle-test terms and `tfar`; and the
        // frustum bounding them all (`None` unless all share one origin and octant).
        let mut subs = 0u32;
        let mut sf: [Frustum<L>; GROUP] = Default::default();
        let none = RayK { o: [L::Pf::splat(0.0); 3], d: [L::Pf::splat(0.0); 3], tnear: L::Pf::splat(f32::INFINITY) };
        let mut rk: [RayK<L>; GROUP] = [none; GROUP];
        let mut live = [0u32; GROUP];
        let mut tfar = [L::Pf::splat(f32::NEG_INFINITY); GROUP];
        let mut group: Option<Frustum<L>> = None;
        let mut shared = true;
        for (i, p) in ps.iter().enumerate() {
            let Some((pb, t)) = PacketBoxes::<L>::new(p) else { continue };
            subs |= 1 << i;
            group = match (&pb.frustum, &group) {
                (Some(f), None) => Some(*f),
                (Some(f), Some(g)) => g.merge(f),
                (None, _) => None,
            };
            shared &= group.is_some();
            if !shared {
                break;
            }
            sf[i] = pb.frustum.unwrap_or_default();
            rk[i] = RayK { o: pb.o, d: pb.d, tnear: pb.tnear };
            live[i] = pb.live;
            tfar[i] = t;
        }
        let (Some(gf), true) = (group, shared) else {
            for (p, o) in ps.iter().zip(out.iter_mut()) {
                self.trace_packet_from::<false, K, CONS, L>(p, self.root, o, stack);
            }
            return;
        };
        walk_group::<CONS, L>(
            &self.nodes,
            self.root,
            &gf,
            &sf,
            subs,
            &mut tfar,
            stack,
            #[inline(always)]
            |r, m, solo, tfar, stack| {
                let mut m = m;
                while m != 0 {
                    let s = m.trailing_zeros() as usize;
                    m &= m - 1;
                    if solo {
                        // The packet's own walk, with its per-lane mode below its footprint.
                        let p = RayPacket { tfar: tfar[s].to_array(), active: live[s], ..ps[s] };
                        self.trace_packet_from::<false, K, CONS, L>(&p, r, &mut out[s], stack);
                        let hit = out[s].mask;
                        tfar[s] = L::Pf::lane_mask(hit).select(L::Pf::new(out[s].hit.t), L::Pf::new(p.tfar));
                    } else {
                        self.leaf_packet::<false, K, L>(r, &rk[s], rk[s].tnear, live[s], &mut tfar[s], &mut out[s]);
                    }
                }
            },
        );
    }
}

/// The group walk over `nodes` from `root`: the group's frustum `gf` above the leaves, the
/// packets' own frusta `sf` at leaves and below nodes smaller than the group's footprint (see the
/// module comment). `leaf(reference, packets, solo, tfar, stack)` tests a leaf for the packets in
/// the mask, lowering their lanes' `tfar`, or with `solo` walks the subtree at `reference` (a node
/// or leaf smaller than a packet's footprint) for each packet alone; it may use the same stack.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn walk_group<const CONS: bool, L: Level>(
    nodes: &[Node],
    root: u32,
    gf: &Frustum<L>,
    sf: &[Frustum<L>; GROUP],
    subs: u32,
    tfar: &mut [L::Pf; GROUP],
    stack: &mut Stack,
    mut leaf: impl FnMut(u32, u32, bool, &mut [L::Pf; GROUP], &mut Stack),
) {
    let mut tmax = [0.0f32; GROUP];
    for (m, t) in tmax.iter_mut().zip(tfar.iter()) {
        *m = t.hmax();
    }
    let mut tfar_max = tmax.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));

    let base = stack.push_root(root);
    let mut sp = stack.len;
    'pop: while sp > base {
        let mut lanes = stack.lanes_at(sp - 1);
        let (mut cur, dist) = stack.take(&mut sp);
        // Held to the frustum test's own widened bound (`Frustum::test_vec`), as the other walks'
        // pops are (`BoxRay::pop_limit`).
        let limit = if CONS { tfar_max + (tfar_max.abs() + dist.abs()) * WIDEN + gf.pad } else { tfar_max };
        if dist > limit {
            continue;
        }
        loop {
            let solo = lanes & SOLO != 0;
            if is_leaf(cur) || solo {
                let m = if lanes & PER_PACKET != 0 { lanes & subs } else { subs };
                stack.len = sp;
                leaf(cur, m, solo, tfar, stack);
                sp = stack.len;
                let mut b = m;
                while b != 0 {
                    let s = b.trailing_zeros() as usize;
                    b &= b - 1;
                    tmax[s] = tfar[s].hmax();
                }
                tfar_max = tmax.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
                continue 'pop;
            }
            let node = &nodes[cur as usize];
            let b = &node.bounds;
            let (mut mask, mut d, mut cl);
            if lanes & PER_PACKET == 0 {
                let (gm, gd) = gf.test::<CONS>(b, tfar_max);
                if gm == 0 {
                    continue 'pop;
                }
                // Leaves, and children smaller than the group's footprint, go per packet.
                // (Testing a node with leaves per packet only, without the group's test,
                // measured 6% slower on Sponza: the group test rejects whole nodes.)
                let fine = (gf.small(b, &gd) | leaf_children(node)) & gm;
                mask = gm;
                d = gd;
                cl = [0u32; WIDTH];
                if fine != 0 {
                    let (pm, pd, pl, tiny) = per_packet::<CONS, L>(sf, &tmax, subs, b);
                    // Leaves stay with the group: each packet tests them anyway.
                    let tiny = tiny & !leaf_children(node);
                    mask &= !fine | pm;
                    let mut f = fine & pm;
                    while f != 0 {
                        let i = f.trailing_zeros() as usize;
                        f &= f - 1;
                        d[i] = pd[i];
                        cl[i] = pl[i] as u32 | PER_PACKET | if tiny & (1 << i) != 0 { SOLO } else { 0 };
                    }
                }
            } else {
                let (pm, pd, pl, tiny) = per_packet::<CONS, L>(sf, &tmax, lanes & subs, b);
                let tiny = tiny & !leaf_children(node);
                mask = pm;
                d = pd;
                cl = std::array::from_fn(|i| pl[i] as u32 | PER_PACKET | if tiny & (1 << i) != 0 { SOLO } else { 0 });
            }
            if mask == 0 {
                continue 'pop;
            }
            if mask & (mask - 1) == 0 {
                let i = mask.trailing_zeros() as usize;
                (cur, lanes) = (node.child[i], cl[i]);
                continue;
            }
            // Descend into the nearest child, push the others nearest on top (with the
            // packets that enter each: entries pushed without it would read stale bits).
            let first = sp;
            while mask != 0 {
                let i = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                stack.put_lanes(&mut sp, node.child[i], d[i], cl[i]);
            }
            stack.sort_from::<true>(first, sp);
            lanes = stack.lanes_at(sp - 1);
            cur = stack.take(&mut sp).0;
        }
    }
    stack.len = base;
}

/// The children of a node's bounds `b` that the packets in `subs` enter, each packet under its
/// own frustum and `tmax`: the mask, the lowest entry distance per child, the packets that enter
/// each child, and the children smaller than the footprint of a packet that enters them.
#[inline(always)]
fn per_packet<const CONS: bool, L: Level>(
    sf: &[Frustum<L>; GROUP],
    tmax: &[f32; GROUP],
    subs: u32,
    b: &[[f32; WIDTH]; 6],
) -> (u32, [f32; WIDTH], [i32; WIDTH], u32) {
    // Bit `s` of a child's lane: packet `s` enters it. Float bit operations only (a mask
    // compared as a float would be a denormal, zero under DAZ).
    let mut packets = L::Nf::splat(0.0);
    let mut dist = L::Nf::splat(f32::INFINITY);
    let mut tiny = 0u32;
    let mut m = subs;
    while m != 0 {
        let s = m.trailing_zeros() as usize;
        m &= m - 1;
        let (hit, tn) = sf[s].test_vec::<CONS>(b, tmax[s]);
        packets |= hit & L::Nf::splat(f32::from_bits(1 << s));
        dist = hit.select(dist.fast_min(tn), dist);
        tiny |= sf[s].small(b, &(tn * L::Nf::splat(SOLO_SCALE)).to_array()) & hit.to_bitmask();
    }
    let packets = packets.to_array().map(|x| x.to_bits() as i32);
    let mask = (0..WIDTH).fold(0u32, |m, i| m | ((packets[i] != 0) as u32) << i);
    (mask, dist.to_array(), packets, tiny)
}
