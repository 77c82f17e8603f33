//! Traversal kernels: one ray (SIMD over a node's children and a leaf block's triangles) and one
//! packet (SIMD over rays). Closest-hit and any-hit share each kernel through `const ANY: bool`.
//!
//! Both follow Embree's `BVHNIntersector1` / `BVHNIntersectorKHybrid` (`kernels/bvh/`): an ordered
//! depth-first walk with an explicit stack of `(child, entry distance)`, popping entries that lie
//! beyond the current closest hit. Slab tests use `(box − org) · rdir` written as one fused
//! multiply-subtract, with direction components below 1e-18 in magnitude replaced by ±1e-18 before
//! the reciprocal, as Embree's `rcp_safe` does, so that no slab test meets `0 · ∞ = NaN`
//! (an origin on a box plane with a zero direction component).
//!
//! The FMA form rounds `org · rdir` once per ray, an absolute error of up to
//! `ε·|org · rdir|` in every plane distance, which far from the origin exceeds the size of small
//! boxes: rays then slip between boxes that the triangle test would hit (ACCURACY.md; Ize, "Robust
//! BVH Ray Traversal", JCGT 2013). The interval test is therefore `tn <= tf·(1 + 2⁻²⁰) + pad`, with
//! `pad = 2⁻²⁰·max|org · rdir|` per ray: a bound on both roundings, at one fused multiply-add per
//! node. Without it, 1 in 2,000 random rays at an offset of 1e5 missed a triangle brute force hit.

use std::cell::RefCell;

use glam::{Mat3A, Vec3};

use super::Bvh;
use super::build::MEDIAN_DEPTH;
use super::node::{EMPTY, Node, WIDTH, is_leaf, leaf_blocks};
use crate::geometry::badouel::Badouel;
use crate::geometry::moeller::Moller;
use crate::geometry::triangle::{BLOCK, Kernel, Ray4, RayK, TriBlock, TriangleTest};
use crate::geometry::watertight::Watertight;
use crate::ray::{Hit, HitPacket, INVALID_ID, MIN_DIRECTION, PACKET_WIDTH, Ray, RayPacket};
use crate::simd::*;

/// The ray–box test used by traversal.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BoxTest {
    /// Embree's default slab test `(box·rdir − org·rdir)` compared as is: one instruction cheaper
    /// per node, but far from the origin rounding can let a ray slip between boxes.
    Fast,
    /// The slab test with the far distance widened by the rounding bound of the FMA form (after
    /// Ize, "Robust BVH Ray Traversal", JCGT 2013, adapted to precomputed `org·rdir`): the BVH never
    /// loses a hit the triangle test would find.
    #[default]
    Conservative,
}

impl BoxTest {
    /// Every box test.
    pub const ALL: [BoxTest; 2] = [BoxTest::Fast, BoxTest::Conservative];

    /// The test's name, as the harness and scene files spell it.
    pub fn name(self) -> &'static str {
        match self {
            BoxTest::Fast => "fast",
            BoxTest::Conservative => "conservative",
        }
    }
}

/// Direction components smaller than this in magnitude are clamped before taking reciprocals.
const MIN_RCP_INPUT: f32 = 1e-18;

/// Largest magnitude of a ray's `origin · rd` term. Beyond it (origins far out with small
/// direction components: `|o| · |1/d|` past `f32::MAX` would overflow to infinity, and `inf − inf`
/// in a slab test is NaN, which let rays enter empty child slots) the term saturates: the slab
/// distances of boxes near the scene, whatever their sign, are then beyond `1e37` in magnitude,
/// where no hit of a ray this far out can lie anyway (RELIABILITY.md). Finite terms keep every
/// node test free of NaN.
const MAX_OD: f32 = 1e37;

/// Relative widening of the far plane distance: 16 ulps, well above the 2–3 roundings involved.
pub(super) const WIDEN: f32 = 1.0 / (1u32 << 20) as f32;

/// The conservative test's factor on far distances, `1 + w` (with `w` = [`WIDEN`]).
pub(super) const FAR_WIDEN: f32 = 1.0 + WIDEN;

/// Stack entries: at most `WIDTH − 1` pushes per wide level; SAH levels are capped at
/// `MEDIAN_DEPTH` and median levels below halve the set (at most 32 binary, so 32 wide levels).
/// Twice that: an instance level and an object level share one stack. Rounded up to a power of
/// two, so that an index masked with `STACK − 1` needs no bounds check (the bound above keeps it
/// from ever wrapping).
const STACK: usize = (2 * ((MEDIAN_DEPTH + 33) * (WIDTH - 1) + 1)).next_power_of_two();

#[inline(always)]
fn safe_rcp(d: f32) -> f32 {
    let d = if d.abs() < MIN_RCP_INPUT { MIN_RCP_INPUT.copysign(d) } else { d };
    1.0 / d
}

/// Where a ray hit: block, lane within it, and the hit parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct LeafHit {
    pub block: u32,
    pub lane: u32,
    pub t: f32,
    pub u: f32,
    pub v: f32,
}

/// Per-lane results of a packet query, written straight into the caller's [`HitPacket`]: the
/// leaf tests select each hit triangle's fields into its lanes with vector operations. Building a
/// hit record per lane after the walk (a gather and a cross product each) took 14–19% of
/// Cornell's camera packets, and copying a returned 576-byte record twice another 10%.
pub(crate) struct PacketHits<'a> {
    /// Closest hits; the lanes outside `mask` keep what [`PacketHits::new`] wrote (misses).
    pub hit: &'a mut HitPacket,
    /// Bit `i`: lane `i` hit something (closest hit) or is occluded (any hit).
    pub mask: u32,
}

impl<'a> PacketHits<'a> {
    /// Marks every lane of `hit` a miss and views it as an empty result.
    #[inline(always)]
    pub fn new(hit: &'a mut HitPacket) -> Self {
        hit.t = [f32::INFINITY; PACKET_WIDTH];
        hit.prim_id = [INVALID_ID; PACKET_WIDTH];
        hit.geom_id = [INVALID_ID; PACKET_WIDTH];
        hit.inst_id = [INVALID_ID; PACKET_WIDTH];
        Self { hit, mask: 0 }
    }

    /// Records `h` as lane `l`'s hit.
    #[inline(always)]
    pub fn set(&mut self, l: usize, h: &Hit) {
        self.hit.set(l, Some(*h));
        self.mask |= 1 << l;
    }

    /// Takes the hits of `from` in the lanes of `valid`, found in an instance: normals turned
    /// to world space by `normal_to_world` (the arithmetic of glam's `Mat3A * Vec3A`, so that
    /// packets and single rays give the same normals), instance id `inst_id`.
    #[inline(always)]
    pub fn take_instanced<L: Level>(&mut self, valid: L::Pf, from: &HitPacket, normal_to_world: &Mat3A, inst_id: u32) {
        let h = &mut *self.hit;
        sel(&mut h.t, valid, L::Pf::new(from.t));
        sel(&mut h.u, valid, L::Pf::new(from.u));
        sel(&mut h.v, valid, L::Pf::new(from.v));
        let n = [L::Pf::new(from.ng_x), L::Pf::new(from.ng_y), L::Pf::new(from.ng_z)];
        let (x, y, z) = (normal_to_world.x_axis, normal_to_world.y_axis, normal_to_world.z_axis);
        let row =
            hot!(|a: f32, b: f32, c: f32| L::Pf::splat(a) * n[0] + L::Pf::splat(b) * n[1] + L::Pf::splat(c) * n[2]);
        sel(&mut h.ng_x, valid, row(x.x, y.x, z.x));
        sel(&mut h.ng_y, valid, row(x.y, y.y, z.y));
        sel(&mut h.ng_z, valid, row(x.z, y.z, z.z));
        sel_ids(&mut h.prim_id, valid, L::Pf::new(from.prim_id.map(f32::from_bits)));
        sel_ids(&mut h.geom_id, valid, L::Pf::new(from.geom_id.map(f32::from_bits)));
        sel_id(&mut h.inst_id, valid, inst_id);
    }

    /// Writes the hit of triangle `lane` of block `b` into the lanes of `valid`.
    #[inline(always)]
    fn select<L: Level>(
        &mut self,
        valid: L::Pf,
        b: &TriBlock,
        test: TriangleTest,
        lane: usize,
        tuv: (L::Pf, L::Pf, L::Pf),
    ) {
        let ng = b.ng(test, lane);
        let ng = [L::Pf::splat(ng.x), L::Pf::splat(ng.y), L::Pf::splat(ng.z)];
        self.select_hit::<L>(valid, tuv, ng, b.prim[lane], b.geom_id(test, lane));
    }

    /// Writes a hit on primitive `prim` of geometry `geom` into the lanes of `valid`.
    #[inline(always)]
    pub fn select_hit<L: Level>(
        &mut self,
        valid: L::Pf,
        (t, u, v): (L::Pf, L::Pf, L::Pf),
        ng: [L::Pf; 3],
        prim: u32,
        geom: u32,
    ) {
        let h = &mut *self.hit;
        sel(&mut h.t, valid, t);
        sel(&mut h.u, valid, u);
        sel(&mut h.v, valid, v);
        sel(&mut h.ng_x, valid, ng[0]);
        sel(&mut h.ng_y, valid, ng[1]);
        sel(&mut h.ng_z, valid, ng[2]);
        sel_id(&mut h.prim_id, valid, prim);
        sel_id(&mut h.geom_id, valid, geom);
    }
}

/// Writes `x` into the lanes of `valid`.
#[inline(always)]
fn sel<V: Packet>(dst: &mut [f32; PACKET_WIDTH], valid: V, x: V) {
    *dst = valid.select(x, V::new(*dst)).to_array();
}

/// Writes the ids `ids` (as float bits) into the lanes of `valid`.
#[inline(always)]
fn sel_ids<V: Packet>(dst: &mut [u32; PACKET_WIDTH], valid: V, ids: V) {
    let old = V::new(dst.map(f32::from_bits));
    *dst = valid.select(ids, old).to_array().map(f32::to_bits);
}

/// Writes the id `id` into the lanes of `valid`.
#[inline(always)]
fn sel_id<V: Packet>(dst: &mut [u32; PACKET_WIDTH], valid: V, id: u32) {
    sel_ids(dst, valid, V::splat(f32::from_bits(id)));
}

/// Fixed-size traversal stack; no kernel allocates. Each thread keeps one (see [`with_stack`]):
/// zero-filling 4 KB on every ray cost more than a tenth of a primary ray's traversal.
pub(crate) struct Stack {
    /// [`WIDTH`] entries beyond `STACK`: [`put_ordered`](Self::put_ordered) writes a whole node's
    /// children at once from any masked index.
    node: [u32; STACK + WIDTH],
    dist: [f32; STACK + WIDTH],
    /// Packet walks without a frustum only: the lanes that entered the entry's node (0: the whole
    /// packet). Single-ray walks and camera packets leave it stale and never read it; each walk
    /// pops only the entries it pushed.
    lanes: [u16; STACK],
    /// Packet walks without a frustum only: each lane's entry distance into the entry's node
    /// (`+inf` in lanes that did not enter it), so that a popped entry counts only the lanes
    /// whose closest hit so far lies beyond it (Embree's hybrid walk keeps the same vector).
    lane_dist: [LaneDist; STACK],
    pub(super) len: usize,
}

/// One stack entry's per-lane entry distances, aligned for one 16-wide load.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct LaneDist([f32; PACKET_WIDTH]);

/// The walks keep the stack's length in a local `sp` (a register) and store it back only around
/// leaf calls, which may walk an object on the same stack: with the length in the struct, every
/// push reloaded and stored it (measured below in PERFORMANCE.md).
impl Stack {
    const EMPTY: Stack = Stack {
        node: [0; STACK + WIDTH],
        dist: [0.0; STACK + WIDTH],
        lanes: [0; STACK],
        lane_dist: [LaneDist([0.0; PACKET_WIDTH]); STACK],
        len: 0,
    };

    /// Pushes `root` and returns the length to walk back down to.
    #[inline(always)]
    pub(crate) fn push_root(&mut self, root: u32) -> usize {
        let base = self.len;
        let mut sp = self.len;
        self.put_lanes(&mut sp, root, f32::NEG_INFINITY, 0);
        self.len = sp;
        base
    }

    #[inline(always)]
    fn put(&mut self, sp: &mut usize, node: u32, dist: f32) {
        debug_assert!(*sp < STACK);
        let i = *sp & (STACK - 1);
        self.node[i] = node;
        self.dist[i] = dist;
        *sp += 1;
    }

    /// [`put`](Self::put) for a packet walk, with the lanes that entered `node` (0: all).
    #[inline(always)]
    pub(super) fn put_lanes(&mut self, sp: &mut usize, node: u32, dist: f32, lanes: u32) {
        self.lanes[*sp & (STACK - 1)] = lanes as u16;
        self.put(sp, node, dist);
    }

    /// The lanes of the entry below `sp` (see [`put_lanes`](Self::put_lanes)).
    #[inline(always)]
    pub(super) fn lanes_at(&self, sp: usize) -> u32 {
        self.lanes[sp & (STACK - 1)] as u32
    }

    /// [`put_lanes`](Self::put_lanes) with each lane's entry distance (`+inf` where it did not
    /// enter).
    #[inline(always)]
    fn put_lane_dist<V: Packet>(&mut self, sp: &mut usize, node: u32, dist: f32, lanes: u32, tn: V) {
        self.lane_dist[*sp & (STACK - 1)].0 = tn.to_array();
        self.put_lanes(sp, node, dist, lanes);
    }

    /// The per-lane entry distances of the entry below `sp` (see
    /// [`put_lane_dist`](Self::put_lane_dist)).
    #[inline(always)]
    fn lane_dist_at<V: Packet>(&self, sp: usize) -> V {
        V::new(self.lane_dist[sp & (STACK - 1)].0)
    }

    /// Pushes `node` with a mask of stream rays (an occlusion stream's entry; see
    /// [`occluded_stream`](Bvh::occluded_stream)). The mask goes in the distance slot, which
    /// such walks never compare.
    #[inline(always)]
    pub(super) fn put_mask(&mut self, sp: &mut usize, node: u32, mask: u32) {
        self.put(sp, node, f32::from_bits(mask));
    }

    /// Pops an entry pushed by [`put_mask`](Self::put_mask); `sp` must be above zero.
    #[inline(always)]
    pub(super) fn take_mask(&self, sp: &mut usize) -> (u32, u32) {
        let (node, mask) = self.take(sp);
        (node, mask.to_bits())
    }

    /// Pops the top entry; `sp` must be above zero.
    #[inline(always)]
    pub(super) fn take(&self, sp: &mut usize) -> (u32, f32) {
        *sp -= 1;
        let i = *sp & (STACK - 1);
        (self.node[i], self.dist[i])
    }

    /// Sorts the entries `base..sp` so that the nearest is on top (with their lane masks if
    /// `LANES`).
    #[inline(always)]
    pub(super) fn sort_from<const LANES: bool>(&mut self, base: usize, sp: usize) {
        const M: usize = STACK - 1;
        for i in base + 1..sp {
            let (n, d, l) = (self.node[i & M], self.dist[i & M], if LANES { self.lanes[i & M] } else { 0 });
            let mut j = i;
            while j > base && self.dist[(j - 1) & M] < d {
                self.node[j & M] = self.node[(j - 1) & M];
                self.dist[j & M] = self.dist[(j - 1) & M];
                if LANES {
                    self.lanes[j & M] = self.lanes[(j - 1) & M];
                }
                j -= 1;
            }
            self.node[j & M] = n;
            self.dist[j & M] = d;
            if LANES {
                self.lanes[j & M] = l;
            }
        }
    }
}

thread_local! {
    static STACK_TLS: RefCell<Stack> = const { RefCell::new(Stack::EMPTY) };
    /// Stacks for nested walks, kept for reuse.
    static NESTED_STACKS: RefCell<Vec<Box<Stack>>> = const { RefCell::new(Vec::new()) };
}

/// Runs `f` with this thread's traversal stack, emptied. An instance level and the objects below
/// it share the one stack: each walk pushes its root and pops back to where it started. A walk
/// started while the thread's stack is in use — a solid's closed mesh walked from a leaf of the
/// solid tree ([`MeshSolid`](crate::MeshSolid)) — takes one of this thread's spare stacks (made
/// once, then reused: a fresh stack per call zeroed 25% of a frame's time in memset).
#[inline(always)]
pub(crate) fn with_stack<R>(f: impl FnOnce(&mut Stack) -> R) -> R {
    STACK_TLS.with(|cell| match cell.try_borrow_mut() {
        Ok(mut s) => {
            s.len = 0;
            f(&mut s)
        }
        Err(_) => {
            let mut s = NESTED_STACKS.with(|p| p.borrow_mut().pop()).unwrap_or_else(|| Box::new(Stack::EMPTY));
            s.len = 0;
            let r = f(&mut s);
            NESTED_STACKS.with(|p| p.borrow_mut().push(s));
            r
        }
    })
}

/// Evaluates `$body` with `$k` bound to the kernel type and `$c` to the box-test flag of a
/// `(TriangleTest, BoxTest)` pair: the one place the six monomorphized kernels are chosen.
macro_rules! dispatch {
    ($test:expr, $boxes:expr, |$k:ident, $c:ident| $body:expr) => {
        match ($test, $boxes) {
            (TriangleTest::MollerTrumbore, BoxTest::Conservative) => dispatch!(@arm Moller, true, $k, $c, $body),
            (TriangleTest::MollerTrumbore, BoxTest::Fast) => dispatch!(@arm Moller, false, $k, $c, $body),
            (TriangleTest::Badouel, BoxTest::Conservative) => dispatch!(@arm Badouel, true, $k, $c, $body),
            (TriangleTest::Badouel, BoxTest::Fast) => dispatch!(@arm Badouel, false, $k, $c, $body),
            (TriangleTest::Watertight, BoxTest::Conservative) => dispatch!(@arm Watertight, true, $k, $c, $body),
            (TriangleTest::Watertight, BoxTest::Fast) => dispatch!(@arm Watertight, false, $k, $c, $body),
        }
    };
    (@arm $kernel:ty, $cons:expr, $k:ident, $c:ident, $body:expr) => {{
        type $k = $kernel;
        const $c: bool = $cons;
        $body
    }};
}
pub(crate) use dispatch;

/// Descends into the nearest of the children in `mask` (distances `d`) and pushes the others,
/// nearest on top (in any order for any-hit queries). Returns the child to visit next.
///
/// Three or more entered children are ordered by an insertion sort on the stack. A branch-free
/// sorting network in registers was faster for single-ray diffuse streams but slower for the
/// single-ray API; it went when incoherent streams became octant-sorted packets (PERFORMANCE.md).
#[inline(always)]
pub(super) fn order_children<const ANY: bool, V: SimdF<Arr = [f32; WIDTH]>>(
    stack: &mut Stack,
    sp: &mut usize,
    child: &[u32; WIDTH],
    mut mask: u32,
    d: V,
) -> u32 {
    let i0 = mask.trailing_zeros() as usize;
    let rest = mask & mask.wrapping_sub(1);
    // One child hit: descend without touching the stack.
    if rest == 0 {
        return child[i0];
    }
    if ANY {
        // Any hit: push all but the last in slot order and descend into the last, as Embree's
        // any-hit walk and the per-lane packet walks here do (PERFORMANCE.md: shadow rays).
        let d = d.to_array();
        let last = 31 - mask.leading_zeros() as usize;
        mask &= !(1 << last);
        while mask != 0 {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            stack.put(sp, child[i], d[i]);
        }
        return child[last];
    }
    let dd = d.to_array();
    // Two: descend into the nearer, push the farther.
    if rest & (rest - 1) == 0 {
        let i1 = rest.trailing_zeros() as usize;
        let (n, f) = if dd[i0] <= dd[i1] { (i0, i1) } else { (i1, i0) };
        stack.put(sp, child[f], dd[f]);
        return child[n];
    }
    // Push all, order them nearest on top, pop one.
    let base = *sp;
    while mask != 0 {
        let i = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        stack.put(sp, child[i], dd[i]);
    }
    stack.sort_from::<false>(base, *sp);
    stack.take(sp).0
}

/// Bounds on the ray parameters of a whole packet whose rays share a direction octant: per axis,
/// the extreme origins and reciprocal directions. A node's children are then tested for the packet
/// at once, 8 wide, with interval arithmetic: the lowest entry and highest exit any ray can have
/// (Embree's coherent packet traversal with a frustum, `node_intersector_frustum.h`; Reshetov et
/// al., "Multi-Level Ray Tracing Algorithm", SIGGRAPH 2005).
#[derive(Clone, Copy)]
pub(crate) struct Frustum<L: Level> {
    near: [usize; 3],
    far: [usize; 3],
    /// The shared origin, per axis.
    o: [L::Nf; 3],
    rmin: [L::Nf; 3],
    rmax: [L::Nf; 3],
    tnear: L::Nf,
    /// How far apart the rays get per unit of `t`: the largest spread of any direction component.
    spread: L::Nf,
    /// Whether the packet's `tnear` is non-negative: integer minima and maxima (see [`BitOrder`]).
    int_ok: bool,
    /// The conservative test's absolute widening: `w · max |o · r|` over the axes. `(b − o)·r`
    /// cancels where the origin lies near a box plane, so a relative widening alone missed hits
    /// there (a ray starting on a triangle, found by the differential fuzz target).
    pub(super) pad: f32,
}

/// Inner nodes reached below a node smaller than the packet's footprint carry this bit on the
/// stack and are tested per lane: the frustum bounds the packet as a whole, so once boxes are
/// smaller than the gaps between its rays it accepts most of them while few rays enter each.
/// Measured on 10,000 instances seen from 900 units, a frustum-only walk visited 196 million
/// nodes where per-lane tests visited 5 million.
const LANE_MODE: u32 = 1 << 30;

impl<L: Level> Default for Frustum<L> {
    fn default() -> Self {
        let z = L::Nf::splat(0.0);
        Frustum {
            near: [0; 3],
            far: [0; 3],
            o: [z; 3],
            rmin: [z; 3],
            rmax: [z; 3],
            tnear: z,
            spread: z,
            int_ok: false,
            pad: 0.0,
        }
    }
}

impl<L: Level> Frustum<L> {
    /// `None` unless the live lanes share one origin and one direction octant (camera packets).
    /// `tnear` holds `+inf` in the lanes out of the query; `live_mask` selects the live lanes.
    #[inline(always)]
    fn new(o: &[L::Pf; 3], rdir: &[L::Pf; 3], tnear: L::Pf, live: u32, live_mask: L::Pf) -> Option<Self> {
        let zero = L::Pf::splat(0.0);
        let inf = L::Pf::splat(f32::INFINITY);
        // The cheap rejections first (shadow packets fail on the first axis): one octant, one
        // origin.
        let first = live.trailing_zeros() as usize;
        for a in 0..3 {
            let neg = rdir[a].simd_lt(zero).to_bitmask() & live;
            if neg != 0 && neg != live {
                return None;
            }
            // Packets from many origins (shadow rays from hit points) make loose frustums:
            // measured on Sponza, shadow packets ran at 28.6 Mrays/s with the frustum and 70.5
            // without. One comparison against the first live lane replaces two reductions.
            if o[a].simd_eq(L::Pf::splat(o[a].to_array()[first])).to_bitmask() & live != live {
                return None;
            }
        }
        let mut f = Self {
            near: [0; 3],
            far: [0; 3],
            o: [L::Nf::splat(0.0); 3],
            rmin: [L::Nf::splat(0.0); 3],
            rmax: [L::Nf::splat(0.0); 3],
            tnear: L::Nf::splat(tnear.hmin()),
            spread: L::Nf::splat(0.0),
            int_ok: false,
            pad: 0.0,
        };
        // `-0.0 + 0.0` is `+0.0`, which orders right as bits.
        let t0 = f.tnear.to_array()[0];
        f.int_ok = t0 >= 0.0;
        if f.int_ok {
            f.tnear = L::Nf::splat(t0 + 0.0);
        }
        let mut spread = 0.0f32;
        for a in 0..3 {
            let negative = rdir[a].simd_lt(zero).to_bitmask() & live != 0;
            let o0 = o[a].to_array()[first];
            let rmin = live_mask.select(rdir[a], inf).hmin();
            let rmax = -live_mask.select(-rdir[a], inf).hmin();
            // One octant: the directions span [1/rmax, 1/rmin] on this axis.
            spread = spread.max((1.0 / rmin - 1.0 / rmax).abs());
            // Near plane: the box minimum for positive directions, mirrored for negative ones.
            f.near[a] = 2 * a + negative as usize;
            f.far[a] = 2 * a + 1 - negative as usize;
            f.o[a] = L::Nf::splat(o0);
            f.rmin[a] = L::Nf::splat(rmin);
            f.rmax[a] = L::Nf::splat(rmax);
        }
        f.spread = L::Nf::splat(spread * FOOTPRINT_FACTOR);
        f.pad = Self::pad_of(&f.o, &f.rmin, &f.rmax);
        Some(f)
    }

    /// [`pad`](Self::pad) for origin `o` and reciprocal ranges `rmin..rmax` (finite: the
    /// reciprocals are clamped, and a saturated product stays below `f32::MAX`).
    #[inline(always)]
    fn pad_of(o: &[L::Nf; 3], rmin: &[L::Nf; 3], rmax: &[L::Nf; 3]) -> f32 {
        let mut pad = 0.0f32;
        for a in 0..3 {
            let o = o[a].to_array()[0].abs();
            pad = pad.max((o * rmin[a].to_array()[0].abs().max(rmax[a].to_array()[0].abs())).min(MAX_OD));
        }
        pad * WIDEN
    }

    /// Children that some ray of the packet may enter before `tfar_max`, and the lowest entry of each.
    #[inline(always)]
    pub(super) fn test<const CONS: bool>(&self, b: &[[f32; WIDTH]; 6], tfar_max: f32) -> (u32, [f32; WIDTH]) {
        let (mask, tn) = self.test_vec::<CONS>(b, tfar_max);
        (mask.to_bitmask(), tn.to_array())
    }

    /// [`test`](Self::test) with the mask as a select mask and the distances as a vector.
    #[inline(always)]
    pub(super) fn test_vec<const CONS: bool>(&self, b: &[[f32; WIDTH]; 6], tfar_max: f32) -> (L::Nf, L::Nf) {
        let pn = hot!(|a: usize| L::Nf::new(b[self.near[a]]) - self.o[a]);
        let pf = hot!(|a: usize| L::Nf::new(b[self.far[a]]) - self.o[a]);
        let (pn, pf) = ([pn(0), pn(1), pn(2)], [pf(0), pf(1), pf(2)]);
        let tfar = L::Nf::splat(tfar_max);
        // Exit distances stay float. A product `+0 · r` with `r < 0` is `-0.0`, the smallest value
        // as bits: an integer minimum would return it over the true (negative) exit, and every box
        // with a plane through the packet's origin would be entered (Sibenik's camera sits on such
        // planes; its primary packets ran at half speed). Entry distances are safe: `-0.0` loses
        // every integer maximum, and `tnear ≥ +0` enters last.
        let f = hot!(|a: usize| (pf[a] * self.rmin[a]).fast_max(pf[a] * self.rmax[a]));
        let tf = f(0).fast_min(f(1)).fast_min(f(2).fast_min(tfar));
        let tn = if self.int_ok {
            let n = hot!(|a: usize| (pn[a] * self.rmin[a]).min_bits(pn[a] * self.rmax[a]));
            n(0).max_bits(n(1)).max_bits(n(2).max_bits(self.tnear))
        } else {
            let n = hot!(|a: usize| (pn[a] * self.rmin[a]).fast_min(pn[a] * self.rmax[a]));
            n(0).fast_max(n(1)).fast_max(n(2).fast_max(self.tnear))
        };
        // Widen by the rounding of the subtraction and product (relative), as in the per-ray test.
        let tf = if CONS { tf + (tn.abs() + tf.abs()) * L::Nf::splat(WIDEN) + L::Nf::splat(self.pad) } else { tf };
        let mask = if self.int_ok { tn.le_mask(tf) } else { tn.simd_le(tf) };
        (mask, tn)
    }

    /// The frustum bounding both `self` and `other`, if they share the origin and octant.
    #[inline(always)]
    pub(crate) fn merge(&self, other: &Self) -> Option<Self> {
        if self.near != other.near {
            return None;
        }
        let mut spread = 0.0f32;
        let mut f = Self {
            near: self.near,
            far: self.far,
            o: self.o,
            rmin: self.rmin,
            rmax: self.rmax,
            tnear: self.tnear.fast_min(other.tnear),
            spread: self.spread,
            int_ok: self.int_ok && other.int_ok,
            pad: 0.0,
        };
        for a in 0..3 {
            if self.o[a].to_array()[0] != other.o[a].to_array()[0] {
                return None;
            }
            f.rmin[a] = self.rmin[a].fast_min(other.rmin[a]);
            f.rmax[a] = self.rmax[a].fast_max(other.rmax[a]);
            let (rmin, rmax) = (f.rmin[a].to_array()[0], f.rmax[a].to_array()[0]);
            spread = spread.max((1.0 / rmin - 1.0 / rmax).abs());
        }
        f.spread = L::Nf::splat(spread * FOOTPRINT_FACTOR);
        f.pad = Self::pad_of(&f.o, &f.rmin, &f.rmax);
        Some(f)
    }

    /// The children whose largest extent is below the packet's footprint at their entry
    /// distance `d`.
    #[inline(always)]
    pub(super) fn small(&self, b: &[[f32; WIDTH]; 6], d: &[f32; WIDTH]) -> u32 {
        let ext = hot!(|a: usize| L::Nf::new(b[2 * a + 1]) - L::Nf::new(b[2 * a]));
        let e = ext(0).fast_max(ext(1)).fast_max(ext(2));
        e.simd_lt(L::Nf::new(*d).abs() * self.spread).to_bitmask()
    }
}

/// Footprint scale: a node counts as small when its extent is below this many times the rays'
/// spread at its distance (tuned by measurement, see PERFORMANCE.md).
const FOOTPRINT_FACTOR: f32 = 4.0;

impl Bvh {
    /// Turns a leaf hit into the public hit record. Inlined: called once per hit lane, and as a call
    /// it cost 10% of Sponza's primary packets.
    #[inline(always)]
    pub fn hit_record(&self, h: &LeafHit) -> Hit {
        let b = &self.blocks[h.block as usize];
        let lane = h.lane as usize;
        Hit {
            t: h.t,
            u: h.u,
            v: h.v,
            ng: b.ng(self.test, lane),
            prim_id: b.prim[lane],
            geom_id: b.geom_id(self.test, lane),
            inst_id: crate::ray::INVALID_ID,
        }
    }

    /// The closest hit by testing every block, with this BVH's triangle test.
    pub fn brute_force(&self, ray: &Ray) -> Option<LeafHit> {
        match self.test {
            TriangleTest::MollerTrumbore => with_level!(|L| L::call(
                #[inline(always)]
                || self.brute_force_k::<Moller, L>(ray)
            )),
            TriangleTest::Badouel => with_level!(|L| L::call(
                #[inline(always)]
                || self.brute_force_k::<Badouel, L>(ray)
            )),
            TriangleTest::Watertight => with_level!(|L| L::call(
                #[inline(always)]
                || self.brute_force_k::<Watertight, L>(ray)
            )),
        }
    }

    #[inline(always)]
    fn brute_force_k<K: Kernel, L: Level>(&self, ray: &Ray) -> Option<LeafHit> {
        if !ray.is_valid() {
            return None;
        }
        let ray = &ray.clamped_to_zero();
        let r4 = Ray4::<L>::new(ray.origin, ray.dir);
        let pre = K::pre(&r4);
        let mut tfar = ray.tfar;
        let mut best = None;
        for (bi, b) in self.blocks.iter().enumerate() {
            if let Some((lane, t, u, v)) = K::intersect1(b, &r4, &pre, ray.tnear, tfar) {
                tfar = t;
                best = Some(LeafHit { block: bi as u32, lane: lane as u32, t, u, v });
            }
        }
        best
    }

    /// Closest hit (`ANY = false`) or first hit found (`ANY = true`) of one ray.
    #[inline(always)]
    pub fn trace1<const ANY: bool>(&self, ray: &Ray) -> Option<LeafHit> {
        if self.root == EMPTY {
            return None;
        }
        with_stack(|stack| {
            dispatch!(self.test, self.box_test, |K, C| with_level!(
                |L| self.trace1_with::<ANY, true, K, C, L>(ray, stack)
            ))
        })
    }

    /// [`trace1`](Self::trace1) with a chosen kernel, on `stack` above its current entries. With
    /// `CHECK` (the single-ray API) an invalid ray misses; without (an instance's object walk,
    /// a stream's lone ray), the caller has checked the ray.
    #[inline(never)]
    pub(crate) fn trace1_with<const ANY: bool, const CHECK: bool, K: Kernel, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        stack: &mut Stack,
    ) -> Option<LeafHit> {
        // The walk's own copy, read field by field: this call's callers (the single-ray API, an
        // instance's object walk) have just written the ray (see `Ray::read_fields`). The API's
        // validity check reads the same copy.
        L::call(
            #[inline(always)]
            || {
                let ray = ray.read_fields();
                if CHECK && !ray.is_valid() {
                    return None;
                }
                self.trace1_from::<ANY, K, CONS, L>(&ray.clamped_to_zero(), self.root, stack)
            },
        )
    }

    /// [`trace1_with`](Self::trace1_with) over the subtree at `root` (a node or a leaf): the
    /// whole tree, or the part a packet hands to its few lanes that enter it.
    #[inline(always)]
    pub(crate) fn trace1_from<const ANY: bool, K: Kernel, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        root: u32,
        stack: &mut Stack,
    ) -> Option<LeafHit> {
        self.trace1_from_terms::<ANY, K, CONS, L>(ray, SlabTerms::of(ray), root, stack)
    }

    /// [`trace1_from`](Self::trace1_from) with the ray's slab terms already computed (a packet's
    /// lane, see [`LaneSlabs`]).
    #[inline(always)]
    pub(crate) fn trace1_from_terms<const ANY: bool, K: Kernel, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        terms: SlabTerms,
        root: u32,
        stack: &mut Stack,
    ) -> Option<LeafHit> {
        if root == EMPTY {
            return None;
        }
        let base = stack.push_root(root);
        let r4 = Ray4::<L>::new(ray.origin, ray.dir);
        let pre = K::pre(&r4);
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
                    if let Some((lane, t, u, v)) = K::intersect1(&self.blocks[bi], &r4, &pre, ray.tnear, *tfar) {
                        *tfar = t;
                        best = Some(LeafHit { block: bi as u32, lane: lane as u32, t, u, v });
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

    /// Closest hits (`ANY = false`) or occlusion (`ANY = true`) of the active lanes of a packet.
    /// Invalid rays in active lanes are answered with a miss.
    /// The closest hits go to `hit` (without instance ids); returns the lanes that hit (are
    /// occluded).
    pub fn trace_packet<const ANY: bool>(&self, p: &RayPacket, hit: &mut HitPacket) -> u32 {
        if self.root == EMPTY {
            // No triangles (a scene of spheres or solids): every lane misses, without the walk's
            // set-up.
            return PacketHits::new(hit).mask;
        }
        with_stack(|stack| {
            dispatch!(self.test, self.box_test, |K, C| with_level!(|L| self.trace_packet_with::<ANY, K, C, L>(
                p,
                Some(hit),
                stack
            )))
        })
    }

    /// The occluded lanes of a packet: [`trace_packet`](Self::trace_packet) with `ANY`, its
    /// record of hits a scratch one made at the kernels' level.
    pub fn occluded_packet(&self, p: &RayPacket) -> u32 {
        if self.root == EMPTY {
            return 0;
        }
        with_stack(|stack| {
            dispatch!(self.test, self.box_test, |K, C| with_level!(
                |L| self.trace_packet_with::<true, K, C, L>(p, None, stack)
            ))
        })
    }

    /// [`trace_packet`](Self::trace_packet) with a chosen kernel, on `stack` above its current
    /// entries. Without `hit` (occlusion), the hits go to a scratch record made here: 640
    /// bytes, whose stores outside the level cost a dependency build's (SSE2) occlusion packets
    /// some 6% of their time.
    #[inline(never)]
    pub(crate) fn trace_packet_with<const ANY: bool, K: Kernel, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        hit: Option<&mut HitPacket>,
        stack: &mut Stack,
    ) -> u32 {
        L::call(
            #[inline(always)]
            || {
                let mut scratch = None;
                let mut out = PacketHits::new(or_scratch(hit, &mut scratch));
                self.trace_packet_from::<ANY, K, CONS, L>(p, self.root, &mut out, stack);
                out.mask
            },
        )
    }

    /// [`trace_packet_with`](Self::trace_packet_with) over the subtree at `root` (a node or a
    /// leaf), recording in `out` the hits closer than the lanes' `tfar`: the whole tree, or the
    /// part a coherent group hands to one packet.
    #[inline(always)]
    pub(crate) fn trace_packet_from<const ANY: bool, K: Kernel, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        root: u32,
        out: &mut PacketHits<'_>,
        stack: &mut Stack,
    ) {
        if root == EMPTY {
            return;
        }
        let Some((pb, mut tfar)) = PacketBoxes::<L>::new(p) else {
            return;
        };
        let base = stack.push_root(root);
        let rk = RayK::<L> { o: pb.o, d: pb.d, tnear: pb.tnear };
        walk_packet::<ANY, CONS, L>(
            self.tree(),
            &pb,
            stack,
            base,
            &mut tfar,
            #[inline(always)]
            |leaf, lanes, tfar, stack| {
                if lanes != 0 {
                    // A few lanes walk this subtree one at a time.
                    out.mask |= each_lane_alone::<ANY, _, L>(
                        p,
                        lanes,
                        tfar,
                        #[inline(always)]
                        |l, ray| {
                            let h = self.trace1_from_terms::<ANY, K, CONS, L>(ray, pb.slabs.lane(l), leaf, stack)?;
                            Some((h.t, h))
                        },
                        |l, h| out.set(l, &self.hit_record(&h)),
                    );
                    return ANY && out.mask == pb.live;
                }
                self.leaf_packet::<ANY, K, L>(leaf, &rk, pb.tnear, pb.live, tfar, out)
            },
        );
    }

    /// Tests the blocks of `leaf` against the open lanes of a packet (`tnear ≤ tfar`): lowers the
    /// lanes' `tfar` to their hits (closes them, `ANY`) and records the hits in `out`. Returns
    /// true once every `live` lane is occluded (`ANY`).
    #[inline(always)]
    pub(super) fn leaf_packet<const ANY: bool, K: Kernel, L: Level>(
        &self,
        leaf: u32,
        rk: &RayK<L>,
        tnear: L::Pf,
        live: u32,
        tfar: &mut L::Pf,
        out: &mut PacketHits<'_>,
    ) -> bool {
        let (start, count) = leaf_blocks(leaf);
        let active = tnear.simd_le(*tfar);
        for bi in start..start + count {
            let blk = &self.blocks[bi];
            if ANY {
                // Over the filled lanes' bits: a loop whose trip count the compiler does not
                // know, so it is not unrolled four times. It was at the AVX-512 level, whose walk
                // then spilled in its node loop: 3% on occlusion (PERFORMANCE.md, session 55).
                // Closest-hit packets measured 1–2% faster unrolled, so they keep the plain loop.
                let mut lanes = blk.filled();
                while lanes != 0 {
                    let lane = lanes.trailing_zeros() as usize & (BLOCK - 1);
                    lanes &= lanes - 1;
                    let valid = K::intersect_packet(blk, lane, rk, *tfar, active).0;
                    let bits = valid.to_bitmask();
                    if bits != 0 {
                        // Occluded lanes are finished: close their interval.
                        out.mask |= bits;
                        *tfar = valid.select(L::Pf::splat(f32::NEG_INFINITY), *tfar);
                        if out.mask == live {
                            return true;
                        }
                    }
                }
                continue;
            }
            for lane in 0..BLOCK {
                if blk.prim[lane] == u32::MAX {
                    break;
                }
                let (valid, t, u, v) = K::intersect_packet(blk, lane, rk, *tfar, active);
                let bits = valid.to_bitmask();
                if bits == 0 {
                    continue;
                }
                *tfar = valid.select(t, *tfar);
                out.mask |= bits;
                out.select::<L>(valid, blk, self.test, lane, (t, u, v));
            }
        }
        false
    }
}

/// One ray's slab-test terms, for the 8 children of a node at a time.
pub(crate) struct BoxRay<L: Level> {
    rd: [L::Nf; 3],
    od: [L::Nf; 3],
    /// The far planes' terms: for the conservative test, `rd·(1 + w)` and `od·(1 + w) − pad`, so
    /// that `fmsub(box, rdf, odf)` is the widened far distance `(box·rd − od)·(1 + w) + pad`
    /// without a multiply-add after the minimum (the same bound, one step shorter).
    rdf: [L::Nf; 3],
    odf: [L::Nf; 3],
    /// Row of the near plane per axis: the box minimum where the direction is positive.
    near: [usize; 3],
    far: [usize; 3],
    tnear: L::Nf,
    /// The conservative test's pad for the ray's own `tfar` (widened by [`FAR_WIDEN`]).
    far_pad: f32,
    /// Whether `tnear ≥ 0`: then the minima and maxima run as integer operations (see
    /// [`BitOrder`]), else as float ones.
    int_ok: bool,
}

/// One ray's slab-test terms as scalars: what [`BoxRay`] splats over a node's children, and what
/// the occlusion streams (`stream.rs`) keep per ray.
pub(crate) struct SlabTerms {
    /// Clamped reciprocal direction.
    pub rd: Vec3,
    /// `origin · rd`.
    pub od: Vec3,
    /// The conservative test's far-plane terms: `rd·(1 + w)` and `od·(1 + w) − pad`.
    pub rdf: Vec3,
    pub odf: Vec3,
    /// The conservative test's absolute pad (its relative widening is [`FAR_WIDEN`]).
    pub pad: f32,
}

impl SlabTerms {
    #[inline(always)]
    pub(crate) fn of(ray: &Ray) -> Self {
        let rd = Vec3::new(safe_rcp(ray.dir.x), safe_rcp(ray.dir.y), safe_rcp(ray.dir.z));
        let od = (ray.origin * rd).clamp(Vec3::splat(-MAX_OD), Vec3::splat(MAX_OD));
        Self::from_parts(rd, od, WIDEN * od.abs().max_element())
    }

    /// The terms from the clamped reciprocal direction, `origin · rd` and the pad.
    #[inline(always)]
    fn from_parts(rd: Vec3, od: Vec3, pad: f32) -> Self {
        Self { rd, od, rdf: rd * FAR_WIDEN, odf: od * FAR_WIDEN - Vec3::splat(pad), pad }
    }

    /// The far distance a slab test compares with for a closest hit so far at `tfar`: widened by
    /// the rounding bound for the conservative test.
    #[inline(always)]
    pub(super) fn far_limit<const CONS: bool>(&self, tfar: f32) -> f32 {
        if CONS { tfar.mul_add(FAR_WIDEN, self.pad) } else { tfar }
    }
}

impl<L: Level> BoxRay<L> {
    /// The node-test form of a ray's slab terms, for the interval from `tnear`.
    #[inline(always)]
    pub(crate) fn with_terms(terms: SlabTerms, tnear: f32) -> Self {
        let SlabTerms { rd: rdir, od: ordir, rdf, odf, pad } = terms;
        let near = [(rdir.x < 0.0) as usize, 2 + (rdir.y < 0.0) as usize, 4 + (rdir.z < 0.0) as usize];
        // `-0.0 + 0.0` is `+0.0`, whose bits order correctly against positive distances.
        let int_ok = tnear >= 0.0;
        let tnear = if int_ok { tnear + 0.0 } else { tnear };
        Self {
            rd: [L::Nf::splat(rdir.x), L::Nf::splat(rdir.y), L::Nf::splat(rdir.z)],
            od: [L::Nf::splat(ordir.x), L::Nf::splat(ordir.y), L::Nf::splat(ordir.z)],
            rdf: [L::Nf::splat(rdf.x), L::Nf::splat(rdf.y), L::Nf::splat(rdf.z)],
            odf: [L::Nf::splat(odf.x), L::Nf::splat(odf.y), L::Nf::splat(odf.z)],
            near,
            far: [near[0] ^ 1, near[1] ^ 1, near[2] ^ 1],
            tnear: L::Nf::splat(tnear),
            far_pad: pad,
            int_ok,
        }
    }

    /// The node test's far limit, and the bound a popped entry's distance is held to: the far limit of the node test that
    /// pushed it (widened by the rounding bound for the conservative test). Comparing with `tfar`
    /// itself dropped children the widened test had entered, whose hits lay within `tfar` (found
    /// by the differential fuzz target: occlusion found a hit closest hit missed).
    #[inline(always)]
    pub(crate) fn pop_limit<const CONS: bool>(&self, tfar: f32) -> f32 {
        if CONS { tfar.mul_add(FAR_WIDEN, self.far_pad) } else { tfar }
    }

    /// The children of `node` the ray enters before `tfar`, and the entry distance of each.
    #[inline(always)]
    fn test<const CONS: bool>(&self, node: &Node, tfar: f32) -> (u32, L::Nf) {
        let b = &node.bounds;
        let near = hot!(|a: usize| L::Nf::new(b[self.near[a]]).mul_sub(self.rd[a], self.od[a]));
        let (n0, n1, n2) = (near(0), near(1), near(2));
        let (f0, f1, f2, tf) = if CONS {
            let far = hot!(|a: usize| L::Nf::new(b[self.far[a]]).mul_sub(self.rdf[a], self.odf[a]));
            (far(0), far(1), far(2), L::Nf::splat(self.pop_limit::<CONS>(tfar)))
        } else {
            let far = hot!(|a: usize| L::Nf::new(b[self.far[a]]).mul_sub(self.rd[a], self.od[a]));
            (far(0), far(1), far(2), L::Nf::splat(tfar))
        };
        if self.int_ok {
            // Integer minima and maxima: exact here because `tnear ≥ +0` enters the maximum.
            let tn = n0.max_bits(n1).max_bits(n2.max_bits(self.tnear));
            let tf = f0.min_bits(f1).min_bits(f2.min_bits(tf));
            (tn.le_bits(tf), tn)
        } else {
            let tn = n0.fast_max(n1).fast_max(n2.fast_max(self.tnear));
            let tf = f0.fast_min(f1).fast_min(f2.fast_min(tf));
            (tn.simd_le(tf).to_bitmask(), tn)
        }
    }
}

/// What a walk reads: the nodes, the triangle blocks their leaves reference (empty for the
/// instance level, whose leaves are instances), and whether the tree is out of the cache
/// (`far_memory`: the walk then prefetches the children it enters).
#[derive(Clone, Copy)]
pub(crate) struct Tree<'a> {
    pub nodes: &'a [Node],
    pub blocks: &'a [TriBlock],
    pub far_memory: bool,
}

impl Bvh {
    /// This tree as the walks read it.
    #[inline(always)]
    pub(crate) fn tree(&self) -> Tree<'_> {
        Tree { nodes: &self.nodes, blocks: &self.blocks, far_memory: self.prefetch }
    }
}

/// The ordered depth-first walk of one ray over `nodes`, from the entries on `stack`; with
/// `far_memory` (a tree out of the cache) it prefetches the children it enters: nodes, and the
/// first triangle block of leaves (`blocks`; empty for the instance level).
/// `leaf(reference, tfar)` tests one leaf, may lower `tfar`, and returns true to end the walk (an
/// any-hit query found its hit). Shared by triangle BVHs and the instance level above them.
#[inline(always)]
pub(crate) fn walk1<const ANY: bool, const CONS: bool, L: Level>(
    tree: Tree<'_>,
    br: &BoxRay<L>,
    stack: &mut Stack,
    base: usize,
    tfar: &mut f32,
    mut leaf: impl FnMut(u32, &mut f32, &mut Stack) -> bool,
) {
    let Tree { nodes, blocks, far_memory } = tree;
    let mut sp = stack.len;
    'pop: while sp > base {
        let (mut cur, dist) = stack.take(&mut sp);
        // Skip subtrees entered beyond the closest hit so far (by the node test's own bound).
        if dist > br.pop_limit::<CONS>(*tfar) {
            continue;
        }
        loop {
            if is_leaf(cur) {
                stack.len = sp;
                let done = leaf(cur, tfar, stack);
                sp = stack.len;
                if done {
                    break 'pop;
                }
                continue 'pop;
            }
            let node = &nodes[cur as usize];
            let (mask, tn) = br.test::<CONS>(node, *tfar);
            if mask == 0 {
                continue 'pop;
            }
            if far_memory {
                prefetch_children(nodes, blocks, &node.child, mask);
            }
            cur = order_children::<ANY, _>(stack, &mut sp, &node.child, mask, tn);
        }
    }
    stack.len = base;
}

/// Prefetches the children in `mask`: the node of an inner child, the first block of a leaf
/// (from `blocks`, if it holds it). What the walks do on trees that outgrow the cache
/// (`far_memory`), as Embree's walks always do. On trees in the cache it cost 3%
/// (PERFORMANCE.md).
#[inline(always)]
fn prefetch_children(nodes: &[Node], blocks: &[TriBlock], child: &[u32; WIDTH], mut mask: u32) {
    while mask != 0 {
        let i = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        if !is_leaf(child[i]) {
            if let Some(n) = nodes.get(child[i] as usize) {
                prefetch(n);
            }
        } else if let Some(b) = blocks.get(leaf_blocks(child[i]).0) {
            prefetch(b);
        }
    }
}

/// A packet's slab-test terms: per-lane reciprocals, and the frustum if the packet has one.
pub(crate) struct PacketBoxes<L: Level> {
    pub o: [L::Pf; 3],
    pub d: [L::Pf; 3],
    /// Every lane's slab terms, also what the lanes handed to single-ray walks start from.
    pub slabs: LaneSlabs<L>,
    /// Per lane; `+inf` in lanes out of the query, so no node or triangle test passes them.
    pub tnear: L::Pf,
    /// The active lanes with valid rays.
    pub live: u32,
    /// Whether every live lane's `tnear` is non-negative: integer minima and maxima in the per-lane
    /// tests (see [`BitOrder`]).
    int_ok: bool,
    pub(crate) frustum: Option<Frustum<L>>,
}

impl<L: Level> PacketBoxes<L> {
    /// The terms and the lanes' initial `tfar` (`−inf` out of the query), or `None` if no active
    /// lane holds a valid ray.
    #[inline(always)]
    pub fn new(p: &RayPacket) -> Option<(Self, L::Pf)> {
        let o = [L::Pf::new(p.ox), L::Pf::new(p.oy), L::Pf::new(p.oz)];
        let d = [L::Pf::new(p.dx), L::Pf::new(p.dy), L::Pf::new(p.dz)];
        // `Ray::is_valid` for all lanes at once: comparisons with NaN are false.
        let inf = L::Pf::splat(f32::INFINITY);
        let finite = hot!(|x: L::Pf| x.abs().simd_lt(inf));
        let (ad, tn, tf) = ([d[0].abs(), d[1].abs(), d[2].abs()], L::Pf::new(p.tnear), L::Pf::new(p.tfar));
        let valid = finite(o[0])
            & finite(o[1])
            & finite(o[2])
            & finite(d[0])
            & finite(d[1])
            & finite(d[2])
            & ad[0].fast_max(ad[1]).fast_max(ad[2]).simd_ge(L::Pf::splat(MIN_DIRECTION))
            & tn.simd_le(tf);
        let live = valid.to_bitmask() & p.active & ((1u64 << PACKET_WIDTH) - 1) as u32;
        if live == 0 {
            return None;
        }
        let slabs = LaneSlabs::of(&o, &d);
        let live_mask = L::Pf::lane_mask(live);
        // No query reaches behind a ray's origin (`Ray::clamped_to_zero`).
        let tnear = live_mask.select(tn.fast_max(L::Pf::splat(0.0)), inf);
        let tfar = live_mask.select(tf, L::Pf::splat(f32::NEG_INFINITY));
        // `-0.0 + 0.0` is `+0.0`; lanes out of the query hold `+inf`.
        let int_ok = tnear.simd_ge(L::Pf::splat(0.0)).to_bitmask() == low_bits(PACKET_WIDTH);
        let tnear = if int_ok { tnear + L::Pf::splat(0.0) } else { tnear };
        let frustum = Frustum::new(&o, &slabs.rd, tnear, live, live_mask);
        Some((Self { o, d, slabs, tnear, live, int_ok, frustum }, tfar))
    }
}

/// The slab terms of all lanes of a packet, computed 16 at a time: what the per-lane box tests
/// use, and what a lane handed to a single-ray walk takes as its own ([`lane`](Self::lane)), as
/// Embree's hybrid walk hands its lanes the packet's reciprocals, so that no lane's walk waits
/// for three scalar divisions before its first node test.
pub(crate) struct LaneSlabs<L: Level> {
    rd: [L::Pf; 3],
    od: [L::Pf; 3],
    pad: L::Pf,
}

impl<L: Level> LaneSlabs<L> {
    /// The terms of the rays with origins `o` and directions `d`, lane by lane the values
    /// [`SlabTerms::of`] computes for one ray.
    #[inline(always)]
    pub fn of(o: &[L::Pf; 3], d: &[L::Pf; 3]) -> Self {
        let rcp = hot!(|x: L::Pf| {
            let small = x.abs().simd_lt(L::Pf::splat(MIN_RCP_INPUT));
            L::Pf::splat(1.0) / small.select(L::Pf::splat(MIN_RCP_INPUT).copysign(x), x)
        });
        let rd = [rcp(d[0]), rcp(d[1]), rcp(d[2])];
        let sat = hot!(|x: L::Pf| x.fast_max(L::Pf::splat(-MAX_OD)).fast_min(L::Pf::splat(MAX_OD)));
        let od = [sat(o[0] * rd[0]), sat(o[1] * rd[1]), sat(o[2] * rd[2])];
        let pad = od[0].abs().fast_max(od[1].abs()).fast_max(od[2].abs()) * L::Pf::splat(WIDEN);
        Self { rd, od, pad }
    }

    /// Lane `l`'s terms.
    #[inline(always)]
    pub fn lane(&self, l: usize) -> SlabTerms {
        let at = hot!(|v: &[L::Pf; 3]| Vec3::new(v[0].to_array()[l], v[1].to_array()[l], v[2].to_array()[l]));
        SlabTerms::from_parts(at(&self.rd), at(&self.od), self.pad.to_array()[l])
    }
}

impl<L: Level> PacketBoxes<L> {
    /// The largest extent, over the three axes, of the live lanes' origins.
    #[inline(always)]
    pub fn origin_extent(&self) -> f32 {
        let live = L::Pf::lane_mask(self.live);
        let mut e = 0.0f32;
        for o in &self.o {
            let hi = live.select(*o, L::Pf::splat(f32::NEG_INFINITY)).hmax();
            let lo = live.select(*o, L::Pf::splat(f32::INFINITY)).hmin();
            e = e.max(hi - lo);
        }
        e
    }

    /// The lanes that enter the box `lo..hi` before their `tfar` (the per-lane slab test, with the
    /// conservative widening if `CONS`).
    #[inline(always)]
    pub fn lanes_in_box<const CONS: bool>(&self, lo: [f32; 3], hi: [f32; 3], tfar: L::Pf) -> u32 {
        self.enter::<CONS>(lo, hi, tfar).0
    }

    /// The lanes that enter the box `lo..hi` before their `tfar`, and each lane's entry distance
    /// (`+inf` in the others).
    #[inline(always)]
    fn enter<const CONS: bool>(&self, lo: [f32; 3], hi: [f32; 3], tfar: L::Pf) -> (u32, L::Pf) {
        let slab = hot!(|a: usize| {
            let t0 = L::Pf::splat(lo[a]).mul_sub(self.slabs.rd[a], self.slabs.od[a]);
            let t1 = L::Pf::splat(hi[a]).mul_sub(self.slabs.rd[a], self.slabs.od[a]);
            (t0, t1)
        });
        let ((x0, x1), (y0, y1), (z0, z1)) = (slab(0), slab(1), slab(2));
        // Exit distances stay float: an integer minimum may return `-0.0` or a negative value
        // nearer to zero than the true exit, which the widening below could lift above zero (a
        // box behind the ray entered: no wrong answer, only wasted work).
        let tf = x0.fast_max(x1).fast_min(y0.fast_max(y1)).fast_min(z0.fast_max(z1).fast_min(tfar));
        let tn = if self.int_ok {
            x0.min_bits(x1).max_bits(y0.min_bits(y1)).max_bits(z0.min_bits(z1).max_bits(self.tnear))
        } else {
            x0.fast_min(x1).fast_max(y0.fast_min(y1)).fast_max(z0.fast_min(z1).fast_max(self.tnear))
        };
        let tf = if CONS { tf.mul_add(L::Pf::splat(FAR_WIDEN), self.slabs.pad) } else { tf };
        let mask = if self.int_ok { tn.le_mask(tf) } else { tn.simd_le(tf) };
        (mask.to_bitmask(), mask.select(tn, L::Pf::splat(f32::INFINITY)))
    }
}

/// The closest hits of packet `p` nearer than those already in `hits` (an earlier walk's over
/// another tree of the scene), found by `walk(q, out)` on the packet with each lane's `tfar`
/// lowered to its hit so far, and written over `hits`; returns the lanes `walk` hit. The sphere
/// and solid trees answer a scene's packets after the triangles with it. All of it runs inside
/// the level's function (`L::call`): outside it, in a dependency build, the packet's copy and
/// the merge ran at SSE2.
#[inline(always)]
pub(crate) fn closer_packet_by<L: Level>(
    p: &RayPacket,
    hits: &mut HitPacket,
    walk: impl FnOnce(&RayPacket, &mut PacketHits<'_>),
) -> u32 {
    L::call(
        #[inline(always)]
        || {
            let mut q = *p;
            for l in 0..PACKET_WIDTH {
                q.tfar[l] = q.tfar[l].min(hits.t[l]);
            }
            let mut mine = HitPacket::default();
            let mut out = PacketHits::new(&mut mine);
            walk(&q, &mut out);
            let mask = out.mask;
            let mut bits = mask;
            while bits != 0 {
                let l = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                hits.set(l, mine.get(l));
            }
            mask
        },
    )
}

/// Walks the `lanes` of packet `p` one ray at a time: `walk(ray)` with the lane's current `tfar`
/// returns a hit and its `t`. A hit closes the lane's interval (`ANY`) or lowers its `tfar` to
/// `t`, and is handed to `record(lane, hit)` (closest hit only). Returns the lanes that hit. The
/// packet walks' leaf closures use it for the subtrees they hand to single rays.
#[inline(always)]
pub(crate) fn each_lane_alone<const ANY: bool, H, L: Level>(
    p: &RayPacket,
    lanes: u32,
    tfar: &mut L::Pf,
    mut walk: impl FnMut(usize, &Ray) -> Option<(f32, H)>,
    mut record: impl FnMut(usize, H),
) -> u32 {
    let mut t = tfar.to_array();
    let (mut bits, mut hits) = (lanes, 0);
    while bits != 0 {
        let l = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        if let Some((th, h)) = walk(l, &Ray { tfar: t[l], ..p.get(l) }.clamped_to_zero()) {
            hits |= 1 << l;
            if ANY {
                t[l] = f32::NEG_INFINITY;
            } else {
                t[l] = th;
                record(l, h);
            }
        }
    }
    *tfar = L::Pf::new(t);
    hits
}

/// An inner node entered by this many open lanes or fewer, in a packet without a frustum, is
/// walked by each lane alone (Embree's single-ray switch in `BVHNIntersectorKHybrid`): a per-lane
/// node test costs as much for 2 lanes as for 16. Measured on shadow packets (1 thread): big world
/// 1.9 → 2.8, forest 6.3 → 7.0, Sponza 33 → 30, conference 34 → 33 Mrays/s; thresholds 2 and 8
/// did no better. Camera packets (with a frustum) and leaves keep the packet form: both lost
/// 5–10% with the switch.
const SINGLE_SWITCH: u32 = 4;

/// The ordered depth-first walk of a packet over `nodes`: children tested with the frustum if
/// the packet has one, per lane otherwise, and entered if any lane enters them; with
/// `far_memory`, the children entered are prefetched (nodes, and the first block of leaves).
/// `leaf(reference, lanes, tfar, stack)` is called with `lanes == 0` to test a leaf for the whole
/// packet, and with the few `lanes` that entered a subtree (a node or a leaf) to walk it one ray
/// at a time; it may lower the lanes' `tfar` and returns true to end the walk.
#[inline(always)]
pub(crate) fn walk_packet<const ANY: bool, const CONS: bool, L: Level>(
    tree: Tree<'_>,
    pb: &PacketBoxes<L>,
    stack: &mut Stack,
    base: usize,
    tfar: &mut L::Pf,
    mut leaf: impl FnMut(u32, u32, &mut L::Pf, &mut Stack) -> bool,
) {
    let Tree { nodes, blocks, far_memory } = tree;
    let mut tfar_max = tfar.hmax();
    // Popped entries are held to the node tests' own widened bounds (see `BoxRay::pop_limit`):
    // per lane `tfar·(1 + w) + pad`, and for the packet's lowest entry the largest of those (the
    // frustum test's relative widening, `(|tn| + |tf|)·w`, lies within twice that).
    let max_pad = if CONS { pb.slabs.pad.hmax().max(pb.frustum.as_ref().map_or(0.0, |f| f.pad)) } else { 0.0 };
    let pop_limit = hot!(|tfar_max: f32, dist: f32| {
        if CONS { tfar_max + (tfar_max.abs() + dist.abs()) * (2.0 * WIDEN) + max_pad } else { tfar_max }
    });
    let lane_limit = hot!(|tfar: L::Pf| if CONS { tfar.mul_add(L::Pf::splat(FAR_WIDEN), pb.slabs.pad) } else { tfar });
    // Camera packets (with a frustum) never switch to single rays; their entries' lane masks are
    // not kept.
    let switch = pb.frustum.is_none();
    let mut sp = stack.len;
    'pop: while sp > base {
        let mut lanes = stack.lanes_at(sp - 1);
        // Stale for the root and for entries of frustum packets, which `switch` leaves unread.
        // Any-hit walks keep no distances: a lane's `tfar` only ever drops to `-inf` there, so
        // `tnear` decides as well (and the 64-byte copies cost shadow packets 3–8%).
        let mut lane_tn = if ANY { pb.tnear } else { stack.lane_dist_at(sp - 1) };
        let (mut cur, dist) = stack.take(&mut sp);
        if dist > pop_limit(tfar_max, dist) {
            continue;
        }
        loop {
            // A lane is open if it entered the node before its closest hit so far (an occluded
            // lane's interval is closed). Entries no lane is open for are dropped; an inner node
            // few open lanes entered goes to single rays; a leaf is tested for the whole packet
            // (single rays at leaves lost 2–6% on Sponza and igea).
            let mut single = 0;
            if switch && lanes != 0 {
                let open = lanes & lane_tn.simd_le(lane_limit(*tfar)).to_bitmask();
                if open == 0 {
                    continue 'pop;
                }
                if !is_leaf(cur) && open.count_ones() <= SINGLE_SWITCH {
                    single = open;
                }
            }
            if single != 0 || is_leaf(cur) {
                // Leaf references use bit 30 for their block count; only nodes carry `LANE_MODE`.
                let r = if is_leaf(cur) { cur } else { cur & !LANE_MODE };
                stack.len = sp;
                let done = leaf(r, single, tfar, stack);
                sp = stack.len;
                if done {
                    break 'pop;
                }
                tfar_max = tfar.hmax();
                continue 'pop;
            }
            let lane_mode = cur & LANE_MODE != 0;
            let node = &nodes[(cur & !LANE_MODE) as usize];
            let b = &node.bounds;
            if let (Some(f), false) = (&pb.frustum, lane_mode) {
                let (mut mask, d) = f.test::<CONS>(b, tfar_max);
                if mask == 0 {
                    continue 'pop;
                }
                // Children smaller than the packet's footprint: the frustum accepts them although
                // few rays may enter. A leaf no lane enters is dropped here, before its costly
                // test; an inner node continues per lane. (Large children skip both: there the
                // frustum is tight, and the extra test only cost time.)
                let mut child = node.child;
                let mut small = f.small(b, &d) & mask;
                while small != 0 {
                    let i = small.trailing_zeros() as usize;
                    small &= small - 1;
                    if !is_leaf(child[i]) {
                        child[i] |= LANE_MODE;
                    } else if pb.lanes_in_box::<CONS>([b[0][i], b[2][i], b[4][i]], [b[1][i], b[3][i], b[5][i]], *tfar)
                        == 0
                    {
                        mask &= !(1 << i);
                    }
                }
                if mask == 0 {
                    continue 'pop;
                }
                if far_memory {
                    prefetch_children(nodes, blocks, &node.child, mask);
                }
                cur = order_children::<ANY, _>(stack, &mut sp, &child, mask, L::Nf::new(d));
                lanes = 0;
                continue;
            }
            let mut hit_child = [0u32; WIDTH];
            let mut hit_dist = [0f32; WIDTH];
            let mut hit_lanes = [0u32; WIDTH];
            let mut hit_tn = [L::Pf::splat(0.0); WIDTH];
            let mut n = 0;
            for i in 0..WIDTH {
                let c = node.child[i];
                if c == EMPTY {
                    break;
                }
                let (m, tn) = pb.enter::<CONS>([b[0][i], b[2][i], b[4][i]], [b[1][i], b[3][i], b[5][i]], *tfar);
                if m != 0 {
                    if far_memory {
                        if !is_leaf(c) {
                            prefetch(&nodes[c as usize]);
                        } else if let Some(b) = blocks.get(leaf_blocks(c).0) {
                            prefetch(b);
                        }
                    }
                    hit_child[n] = if is_leaf(c) { c } else { c | LANE_MODE };
                    // An any-hit walk that keeps lane masks needs no entry distance: a popped
                    // entry's open lanes decide (its lanes entered before their `tfar`, which
                    // only ever drops to `-inf`), and the pop check passes the 0 pushed here.
                    // Skipping the 16-lane minimum made shadow packets 2–8% faster.
                    hit_dist[n] = if ANY && switch { 0.0 } else { tn.hmin() };
                    hit_lanes[n] = m;
                    hit_tn[n] = tn;
                    n += 1;
                }
            }
            if n == 0 {
                continue 'pop;
            }
            // Push all but the nearest, farthest first, and descend into the nearest (any hit:
            // in slot order, descending into the last). The order is sorted here, on indices,
            // so that the 64-byte lane distances are written once. (Descending into the first
            // slot instead cost igea's shadow packets a third.)
            let mut order: [u8; WIDTH] = std::array::from_fn(|i| i as u8);
            if !ANY {
                for i in 1..n {
                    let k = order[i];
                    let mut j = i;
                    while j > 0 && hit_dist[order[j - 1] as usize] < hit_dist[k as usize] {
                        order[j] = order[j - 1];
                        j -= 1;
                    }
                    order[j] = k;
                }
            }
            let (last, rest) = (n - 1, &order[..n - 1]);
            for &k in rest {
                let k = k as usize;
                if ANY {
                    stack.put_lanes(&mut sp, hit_child[k], hit_dist[k], hit_lanes[k]);
                } else {
                    stack.put_lane_dist(&mut sp, hit_child[k], hit_dist[k], hit_lanes[k], hit_tn[k]);
                }
            }
            let k = order[last] as usize;
            (cur, lanes) = (hit_child[k], hit_lanes[k]);
            if !ANY {
                lane_tn = hit_tn[k];
            }
        }
    }
    stack.len = base;
}

/// `hit`, or else a default record made in `scratch`: the occlusion walks' throw-away record of
/// hits. Called inside [`Level::call`] so that the 640-byte record is written at the level.
#[inline(always)]
pub(crate) fn or_scratch<'a>(hit: Option<&'a mut HitPacket>, scratch: &'a mut Option<HitPacket>) -> &'a mut HitPacket {
    match hit {
        Some(h) => h,
        None => scratch.insert(HitPacket::default()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lane handed to a single-ray walk must see exactly the terms the single-ray API computes
    /// for the same ray, or the two could disagree at box edges.
    #[test]
    fn lane_slab_terms_equal_the_single_ray_terms_bit_for_bit() {
        let dirs = [
            Vec3::new(0.3, -0.8, 0.52),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(-0.0, -1.0, 1e-30),
            Vec3::new(1e-19, -1e-17, 2.0),
            Vec3::new(-3.0e5, 7.0e-3, -0.25),
            Vec3::new(1.0, 1.0, -1.0),
        ];
        let origins = [
            Vec3::ZERO,
            Vec3::new(1e6, -3.5e4, 0.125),
            Vec3::new(-2.0, 7.5, -1e-20),
            Vec3::new(3e30, -1.0, 4.0),
            Vec3::new(0.0, 0.0, -1e21),
        ];
        let rays: Vec<Ray> = dirs.iter().flat_map(|&d| origins.iter().map(move |&o| Ray::new(o, d))).collect();
        for chunk in rays.chunks(PACKET_WIDTH) {
            let lane = |f: fn(&Ray) -> f32| Pf::new(std::array::from_fn(|l| chunk.get(l).map_or(1.0, f)));
            let o = [lane(|r| r.origin.x), lane(|r| r.origin.y), lane(|r| r.origin.z)];
            let d = [lane(|r| r.dir.x), lane(|r| r.dir.y), lane(|r| r.dir.z)];
            let slabs = LaneSlabs::<Native>::of(&o, &d);
            for (l, ray) in chunk.iter().enumerate() {
                let (a, b) = (slabs.lane(l), SlabTerms::of(ray));
                let bits = |t: &SlabTerms| {
                    [t.rd, t.od, t.rdf, t.odf]
                        .map(|v| v.to_array().map(f32::to_bits))
                        .concat()
                        .into_iter()
                        .chain([t.pad.to_bits()])
                        .collect::<Vec<u32>>()
                };
                assert_eq!(bits(&a), bits(&b), "{ray:?}");
            }
        }
    }
}
