//! The high-quality build: binned SAH with spatial splits (Stich, Friedrich and Dietrich,
//! "Spatial Splits in Bounding Volume Hierarchies", HPG 2009), the counterpart of Embree's HIGH
//! preset (`BVH8Triangle4SceneBuilderFastSpatialSAH`).
//!
//! Besides the object splits of the default build, a set may be cut by a plane: a triangle that
//! crosses it is referenced on both sides, each reference bounded by the part of the triangle on
//! its side. Long thin triangles (architecture: Sponza's columns, Sibenik's floor) then stop
//! inflating every box they cross. References grow by at most `split_factor` of the triangle
//! count (Embree's default: 1.2).
//!
//! Sets are vectors here, not ranges of one array: a spatial split adds references, so the
//! in-place partition of the default build does not apply. Building is slower for it, as
//! Embree's HIGH is slower than its MEDIUM.

use std::sync::atomic::{AtomicIsize, Ordering};

use crate::simd::{Level, SimdF, trunc4, with_level};

use glam::{BVec3A, Vec3A};
use rayon::prelude::*;

use super::build::{
    Aabb, BinRule, BuildConfig, Built, Chunk, MEDIAN_DEPTH, PrimRef, SMALL_BUILD, Settings, Split, SubtreeCost, blocks,
    find_split, partition, xyz0,
};
use super::node::Node;
use super::node::WIDTH;

/// Bins per axis for spatial splits. 32 bins measured Sponza SAH 18.18 against 18.22 with 16, in
/// 69 against 54 ms (Sibenik 14.20 / 14.31 in 74 / 49 ms, igea equal in 160 / 131 ms).
const SPATIAL_BINS: usize = 16;

/// Spatial splits are tried only where the best object split's children overlap by more than
/// this fraction of the root's area (Stich et al.'s α). Their 1e-5 let deep nodes spend the
/// reference budget on small gains and cost most of the build: measured with a budget of 1.2,
/// α = 1e-5 / 1e-3 / 3e-3 gave Sponza SAH 19.18 / 18.22 / 18.38 in 89 / 51 / 41 ms, igea
/// 13.711 / 13.724 / 13.728 in 508 / 125 / 113 ms.
const OVERLAP_ALPHA: f32 = 1e-3;

/// Spatial splits also need the object split's sides to overlap in at least this fraction of the
/// set's own area: Embree's `SPATIAL_ASPLIT_OVERLAP_THRESHOLD`. Without it, small sets deep in the tree were binned
/// spatially for nothing: with a budget of 1.2 it cut the build by 12–37% (teapot 5.1 → 3.2 ms,
/// Sponza 74 → 63 ms, conference 155 → 136 ms, the Cornell box 81 → 53 µs)
/// at an SAH within ±1% (Sponza 18.23 → 18.27, Sibenik 14.29 → 14.15, sphereflake 13.84 → 13.75;
/// 2 threads, best of 10 builds, alternated runs).
const SET_OVERLAP: f32 = 0.2;

/// Relative padding of a clipped reference's box across the split axis, above the rounding of
/// the computed crossing points, so that the two sides' boxes cover the whole triangle.
const CLIP_PAD: f32 = 1.0 / (1u32 << 20) as f32;

/// The triangle's corners, by primitive id.
pub(crate) type Corners<'a> = dyn Fn(u32) -> [Vec3A; 3] + Sync + 'a;

struct Ctx<'a> {
    cfg: &'a Settings,
    corners: &'a Corners<'a>,
    /// References that spatial splits may still add.
    budget: AtomicIsize,
    root_area: f32,
}

/// A set under construction.
struct Set {
    prims: Vec<PrimRef>,
    bounds: Aabb,
    centroids: Aabb,
}

impl Set {
    fn of(prims: Vec<PrimRef>) -> Self {
        let mut bounds = Aabb::EMPTY;
        let mut centroids = Aabb::EMPTY;
        for p in &prims {
            let b = p.bounds();
            bounds.grow(&b);
            centroids.grow_point(b.lo + b.hi);
        }
        Set { prims, bounds, centroids }
    }
}

/// Where a set is cut.
#[derive(Clone, Copy)]
enum Cut {
    Object(Split),
    /// References left of `plane` on `axis` go left, right of it right, across it both ways.
    Spatial {
        axis: usize,
        plane: f32,
        cost: f32,
    },
    /// No usable split: halve the set in its order.
    Median,
}

impl Cut {
    fn cost(&self) -> f32 {
        match self {
            Cut::Object(s) => s.cost,
            Cut::Spatial { cost, .. } => *cost,
            Cut::Median => f32::INFINITY,
        }
    }
}

/// An SBVH node before its references are laid out in one array.
enum Tree {
    Leaf(Vec<PrimRef>),
    Inner(Vec<(Aabb, Tree)>),
}

/// Builds over `prims` with spatial splits; returns the root bounds, the tree with leaf ranges
/// into the returned reference array (which may name a triangle more than once).
pub(crate) fn build(prims: Vec<PrimRef>, corners: &Corners<'_>, cfg: &BuildConfig) -> Option<(Built, Vec<PrimRef>)> {
    if prims.is_empty() {
        return None;
    }
    // Small builds: also the object-split tree of the coarse bin rule (see `SMALL_BUILD`), kept
    // if cheaper. A coarse tree with spatial splits would double the build; this one adds a
    // tenth. Larger builds of up to `TWO_HIGH_TREES` references: the spatial tree of the shifted
    // bin mapping instead.
    let n = prims.len();
    let coarse = (n <= SMALL_BUILD).then(|| {
        let mut refs = prims.clone();
        (super::build::build_with_rule(&mut refs, cfg, BinRule::Coarse), refs)
    });
    // The two spatial trees side by side: a build this small keeps two threads busy badly.
    let (fine, shifted) = if SMALL_BUILD < n && n <= TWO_HIGH_TREES {
        let copy = prims.clone();
        let (f, s) = rayon::join(
            || build_with(prims, corners, &Settings::new(cfg, BinRule::Fine)),
            || build_with(copy, corners, &Settings::new(cfg, BinRule::Shifted)),
        );
        (f, Some(s))
    } else {
        (build_with(prims, corners, &Settings::new(cfg, BinRule::Fine)), None)
    };
    Some(
        [coarse, shifted]
            .into_iter()
            .flatten()
            .fold(fine, |best, t| if t.0.cost.sah < best.0.cost.sah { t } else { best }),
    )
}

/// HIGH builds of at most this many references build a second spatial-split tree with the bin
/// boundaries shifted ([`BinRule::Shifted`]) and keep the cheaper one. At this size a HIGH build
/// takes a few milliseconds (the teapot's 6,320 triangles: 3.4 ms against Embree HIGH's 9.8), and
/// where the top splits' bin boundaries fall decides the tree: the teapot's SAH is 7.874 with one
/// mapping and 7.804 with the other (Embree HIGH: 7.868), and neither wins everywhere
/// (PERFORMANCE.md).
const TWO_HIGH_TREES: usize = 16 * 1024;

/// [`build`] of a non-empty set with one bin rule.
fn build_with(prims: Vec<PrimRef>, corners: &Corners<'_>, cfg: &Settings) -> (Built, Vec<PrimRef>) {
    let extra = ((cfg.split_factor - 1.0).max(0.0) as f64 * prims.len() as f64) as isize;
    let root = Set::of(prims);
    let ctx = Ctx {
        cfg,
        corners,
        budget: AtomicIsize::new(extra),
        root_area: root.bounds.half_area().max(f32::MIN_POSITIVE),
    };
    let bounds = root.bounds;
    let tree = recurse(root, &ctx, 0);
    let (mut refs, mut chunk) = (Vec::new(), Chunk::default());
    let (r, below) = flatten(tree, &mut refs, &mut chunk);
    (Built::new(bounds, chunk, r, below), refs)
}

/// Lays `tree` out into `out` (one chunk), its leaves' references appended to `refs`; returns
/// the reference naming it and the cost below it.
fn flatten(tree: Tree, refs: &mut Vec<PrimRef>, out: &mut Chunk) -> (u32, SubtreeCost) {
    match tree {
        Tree::Leaf(p) => {
            let start = refs.len();
            refs.extend_from_slice(&p);
            (out.leaf(start, p.len()), SubtreeCost::default())
        }
        Tree::Inner(children) => {
            let index = out.open();
            let (mut node, mut cost) = (Node::default(), SubtreeCost::default());
            for (i, (b, c)) in children.into_iter().enumerate() {
                let (r, below) = flatten(c, refs, out);
                node.set(i, r, b.lo.into(), b.hi.into());
                cost.add_child(&b, r, below);
            }
            (out.close(index, node), cost)
        }
    }
}

fn recurse(set: Set, ctx: &Ctx<'_>, depth: usize) -> Tree {
    let cfg = ctx.cfg;
    let n = set.prims.len();
    if n <= cfg.min_leaf {
        return Tree::Leaf(set.prims);
    }
    let median = depth >= MEDIAN_DEPTH;
    let own = if median { Cut::Median } else { best_cut(&set, ctx) };
    if n <= cfg.max_leaf {
        let area = set.bounds.half_area();
        let leaf_cost = cfg.intersection_cost * blocks(n) * area;
        let split_cost = cfg.traversal_cost * area + cfg.intersection_cost * own.cost();
        if leaf_cost <= split_cost {
            return Tree::Leaf(set.prims);
        }
    }
    // Fill a wide node: cut the child of largest area until there are WIDTH children.
    let mut children: Vec<(Set, Option<Cut>)> = vec![(set, Some(own))];
    while children.len() < WIDTH {
        let pick = children
            .iter()
            .enumerate()
            .filter(|(_, (s, _))| s.prims.len() > cfg.min_leaf)
            .max_by(|a, b| a.1.0.bounds.half_area().total_cmp(&b.1.0.bounds.half_area()))
            .map(|(i, _)| i);
        let Some(i) = pick else { break };
        let (s, known) = children.swap_remove(i);
        let cut = match known {
            Some(c) => c,
            None if median => Cut::Median,
            None => best_cut(&s, ctx),
        };
        let (l, r) = apply(s, cut, ctx);
        children.push((l, None));
        children.push((r, None));
    }
    let build_child = |(s, _): (Set, Option<Cut>)| (s.bounds, recurse(s, ctx, depth + 1));
    let parallel = children.iter().map(|(s, _)| s.prims.len()).sum::<usize>() >= cfg.parallel_threshold;
    let built = if parallel {
        children.into_par_iter().map(build_child).collect()
    } else {
        children.into_iter().map(build_child).collect()
    };
    Tree::Inner(built)
}

/// The better of the best object split and, where that one's children overlap, the best
/// spatial split the budget allows.
fn best_cut(set: &Set, ctx: &Ctx<'_>) -> Cut {
    let object = find_split(&set.prims, &set.centroids, ctx.cfg);
    let Some(o) = object else {
        return Cut::Median;
    };
    if ctx.budget.load(Ordering::Relaxed) <= 0 {
        return Cut::Object(o);
    }
    // Overlap of the object split's two sides.
    let (mut l, mut r) = (Aabb::EMPTY, Aabb::EMPTY);
    for p in &set.prims {
        let b = p.bounds();
        let c = b.lo + b.hi;
        if super::build::goes_left(c, &o) {
            l.grow(&b);
        } else {
            r.grow(&b);
        }
    }
    let overlap = Aabb { lo: l.lo.max(r.lo), hi: l.hi.min(r.hi) };
    let overlaps = (overlap.hi - overlap.lo).cmpgt(Vec3A::ZERO).all();
    if !overlaps
        || overlap.half_area() < OVERLAP_ALPHA * ctx.root_area
        || overlap.half_area() < SET_OVERLAP * set.bounds.half_area()
    {
        return Cut::Object(o);
    }
    match find_spatial(set, ctx) {
        Some(s) if s.cost() < o.cost => s,
        _ => Cut::Object(o),
    }
}

/// The parts of triangle `v` on either side of the plane `x[axis] = plane`, each bounded and
/// intersected with `within` (the box of the reference being cut); `None` for a side the
/// triangle does not reach. One pass over the edges (Embree's `splitPrimitive`): every corner
/// goes to its side, every crossing point to both.
#[inline]
fn split_tri(v: &[Vec3A; 3], axis: usize, plane: f32, within: &Aabb) -> (Option<Aabb>, Option<Aabb>) {
    split_tri_with::<true>(v, axis, plane, within)
}

/// [`split_tri`], padded (`PAD`, for references) or not: the unpadded cut is what spatial
/// binning computes for all planes at once ([`PlaneCuts`]), and its tests' reference.
#[inline(always)]
fn split_tri_with<const PAD: bool>(
    v: &[Vec3A; 3],
    axis: usize,
    plane: f32,
    within: &Aabb,
) -> (Option<Aabb>, Option<Aabb>) {
    let (mut l, mut r) = (Aabb::EMPTY, Aabb::EMPTY);
    for i in 0..3 {
        let (p, q) = (v[i], v[(i + 1) % 3]);
        if p[axis] <= plane {
            l.grow_point(p);
        }
        if p[axis] >= plane {
            r.grow_point(p);
        }
        if (p[axis] < plane && q[axis] > plane) || (p[axis] > plane && q[axis] < plane) {
            let t = (plane - p[axis]) / (q[axis] - p[axis]);
            let mut x = p + (q - p) * t;
            x[axis] = plane;
            l.grow_point(x);
            r.grow_point(x);
        }
    }
    // Pad across the axis for the rounding of the crossing points (relative to the corners,
    // whose magnitude bounds the error of `p + (q − p)·t`), then keep within the reference.
    let mut pad = Vec3A::ZERO;
    if PAD {
        let m = v[0].abs().max(v[1].abs()).max(v[2].abs());
        pad = (m * CLIP_PAD).max(Vec3A::splat(f32::MIN_POSITIVE));
        pad[axis] = 0.0;
    }
    (fit_within(l, pad, within), fit_within(r, pad, within))
}

/// One side `b` of a cut triangle, widened by `pad` and cut to `within`; `None` if the triangle
/// does not reach that side (`b` empty) or the result is empty.
#[inline(always)]
fn fit_within(b: Aabb, pad: Vec3A, within: &Aabb) -> Option<Aabb> {
    if b.lo.cmpgt(b.hi).any() {
        return None;
    }
    intersect(&Aabb { lo: b.lo - pad, hi: b.hi + pad }, within)
}

/// Both sides of a triangle at every inner bin plane of an axis at once, one plane per vector
/// lane (`lo + k·w` in lane `k − 1`), by the operations [`split_tri_with`] makes for one plane,
/// lane by lane, so that the boxes are the same to the bit: per side, the box of the corners on
/// that side and of the edges' crossing points. For a wall spanning all 16 bins, 15 cuts of 3
/// edges with a branch each became some 90 vector operations.
struct PlaneCuts {
    /// Per side (left, right): low and high corner, by coordinate and lane.
    lo: [[[f32; 16]; 3]; 2],
    hi: [[[f32; 16]; 3]; 2],
}

impl PlaneCuts {
    /// The cuts, with the active instruction-set level's sixteen-lane vectors (one instruction
    /// each at AVX-512, two at AVX2). Only this part of the spatial binning is entered at the
    /// level: inlining all of `SpatialBins::add` into the level's function made the native
    /// build's spatial-split builds 15–20% slower (PERFORMANCE.md).
    fn new(v: &[Vec3A; 3], axis: usize, lo: f32, w: f32) -> Self {
        with_level!(|L| L::call(
            #[inline(always)]
            || Self::new_in::<L>(v, axis, lo, w)
        ))
    }

    #[inline(always)]
    fn new_in<L: Level>(v: &[Vec3A; 3], axis: usize, lo: f32, w: f32) -> Self {
        const _: () = assert!(SPATIAL_BINS <= 17, "one lane per inner plane");
        type P<L> = <L as Level>::Pf;
        const K: [f32; 16] = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0, 16.0];
        let plane = P::<L>::splat(lo) + P::<L>::new(K) * P::<L>::splat(w);
        let mut blo = [[P::<L>::splat(f32::INFINITY); 3]; 2];
        let mut bhi = [[P::<L>::splat(f32::NEG_INFINITY); 3]; 2];
        #[inline(always)]
        fn grow<V: SimdF>(blo: &mut [[V; 3]; 2], bhi: &mut [[V; 3]; 2], side: usize, mask: V, x: [V; 3]) {
            for c in 0..3 {
                blo[side][c] = mask.select(blo[side][c].fast_min(x[c]), blo[side][c]);
                bhi[side][c] = mask.select(bhi[side][c].fast_max(x[c]), bhi[side][c]);
            }
        }
        for i in 0..3 {
            let (p, q) = (v[i], v[(i + 1) % 3]);
            let (pa, qa) = (P::<L>::splat(p[axis]), P::<L>::splat(q[axis]));
            let ps = [P::<L>::splat(p.x), P::<L>::splat(p.y), P::<L>::splat(p.z)];
            grow(&mut blo, &mut bhi, 0, pa.simd_le(plane), ps);
            grow(&mut blo, &mut bhi, 1, pa.simd_ge(plane), ps);
            let cross = (pa.simd_lt(plane) & qa.simd_gt(plane)) | (pa.simd_gt(plane) & qa.simd_lt(plane));
            if cross.to_bitmask() == 0 {
                continue;
            }
            // Lanes without a crossing may divide by zero; their results are never taken.
            let t = (plane - pa) / (qa - pa);
            let mut x = ps;
            for c in 0..3 {
                x[c] = ps[c] + (P::<L>::splat(q[c]) - ps[c]) * t;
            }
            x[axis] = plane;
            grow(&mut blo, &mut bhi, 0, cross, x);
            grow(&mut blo, &mut bhi, 1, cross, x);
        }
        let mut cuts = PlaneCuts { lo: [[[0.0; 16]; 3]; 2], hi: [[[0.0; 16]; 3]; 2] };
        for s in 0..2 {
            for c in 0..3 {
                cuts.lo[s][c] = blo[s][c].to_array();
                cuts.hi[s][c] = bhi[s][c].to_array();
            }
        }
        cuts
    }

    /// The left and right sides' boxes at lane `k` (possibly empty).
    fn sides(&self, k: usize) -> (Aabb, Aabb) {
        let side = |s: usize| Aabb {
            lo: Vec3A::new(self.lo[s][0][k], self.lo[s][1][k], self.lo[s][2][k]),
            hi: Vec3A::new(self.hi[s][0][k], self.hi[s][1][k], self.hi[s][2][k]),
        };
        (side(0), side(1))
    }
}

/// `a ∩ b`, or `None` if empty.
fn intersect(a: &Aabb, b: &Aabb) -> Option<Aabb> {
    let r = Aabb { lo: a.lo.max(b.lo), hi: a.hi.min(b.hi) };
    (!r.lo.cmpgt(r.hi).any()).then_some(r)
}

/// Per axis: the parts of the references falling in each of [`SPATIAL_BINS`] equal slabs of a
/// set's box, and how many references enter and leave in each.
#[derive(Clone)]
struct SpatialBins {
    boxes: [[Aabb; SPATIAL_BINS]; 3],
    enter: [[u32; SPATIAL_BINS]; 3],
    exit: [[u32; SPATIAL_BINS]; 3],
}

impl SpatialBins {
    fn new() -> Self {
        Self { boxes: [[Aabb::EMPTY; SPATIAL_BINS]; 3], enter: [[0; SPATIAL_BINS]; 3], exit: [[0; SPATIAL_BINS]; 3] }
    }

    fn merge(mut self, o: Self) -> Self {
        for a in 0..3 {
            for i in 0..SPATIAL_BINS {
                self.boxes[a][i].grow(&o.boxes[a][i]);
                self.enter[a][i] += o.enter[a][i];
                self.exit[a][i] += o.exit[a][i];
            }
        }
        self
    }

    /// Bins `prims` into slabs of width `w` from `lo` (per axis; axes of zero width skipped).
    fn add(&mut self, prims: &[PrimRef], lo: Vec3A, w: Vec3A, corners: &Corners<'_>) {
        // All three axes' bins at once: one vector division and truncation per corner instead of
        // three scalar ones, lane by lane the same numbers. The fourth lanes, where a reference
        // keeps its index (as a float, a denormal), are cleared (`andps`): a division by or of a
        // denormal costs a microcode assist (PERFORMANCE.md, session 58). A zero-width axis
        // divides by 1, and is skipped.
        const _: () = assert!(SPATIAL_BINS.is_power_of_two(), "a mask keeps the index in range");
        let last = Vec3A::splat((SPATIAL_BINS - 1) as f32);
        let (lo3, w3) = (xyz0(lo), Vec3A::select(BVec3A::new(true, true, true) & w.cmpgt(Vec3A::ZERO), w, Vec3A::ONE));
        let bins = |x: Vec3A| trunc4(((xyz0(x) - lo3) / w3).clamp(Vec3A::ZERO, last).extend(0.0).to_array());
        for p in prims {
            let pb = p.bounds();
            let (lo_bins, hi_bins) = (bins(pb.lo), bins(pb.hi));
            let mut v = None;
            for axis in 0..3 {
                if w[axis] <= 0.0 {
                    continue;
                }
                // In `0..SPATIAL_BINS` by the clamp; the mask lets indexing go unchecked.
                let b0 = lo_bins[axis] as usize & (SPATIAL_BINS - 1);
                let b1 = (hi_bins[axis] as usize & (SPATIAL_BINS - 1)).max(b0);
                self.enter[axis][b0] += 1;
                self.exit[axis][b1] += 1;
                if b0 == b1 {
                    self.boxes[axis][b0].grow(&pb);
                    continue;
                }
                let v = v.get_or_insert_with(|| corners(p.id()));
                self.add_cut(axis, b0, b1, &PlaneCuts::new(v, axis, lo[axis], w[axis]), &pb);
            }
        }
    }

    /// Grows bins `b0..=b1` of `axis` by the parts of a reference with box `pb` that `cuts`
    /// give, cutting off one bin after another from the left: each bin gets the part left of its
    /// right plane within what is left of the reference.
    fn add_cut(&mut self, axis: usize, b0: usize, b1: usize, cuts: &PlaneCuts, pb: &Aabb) {
        let mut rest = *pb;
        for b in b0..b1 {
            // Plane `b + 1` is lane `b`.
            let (l, r) = cuts.sides(b);
            if let Some(l) = fit_within(l, Vec3A::ZERO, &rest) {
                self.boxes[axis][b].grow(&l);
            }
            match fit_within(r, Vec3A::ZERO, &rest) {
                Some(r) => rest = r,
                None => return,
            }
        }
        self.boxes[axis][b1].grow(&rest);
    }
}

/// The best spatial split of `set`: per axis, the set's box cut into equal bins, every reference
/// clipped into the bins it spans; the cost counts a reference on every side it reaches.
fn find_spatial(set: &Set, ctx: &Ctx<'_>) -> Option<Cut> {
    let nb = SPATIAL_BINS;
    let lo = set.bounds.lo;
    let ext = set.bounds.hi - lo;
    let w = Vec3A::select(ext.cmpgt(Vec3A::ZERO), ext / nb as f32, Vec3A::ZERO);
    let chunk = super::build::BIN_CHUNK;
    let bins = if set.prims.len() >= 4 * chunk {
        set.prims
            .par_chunks(chunk)
            .fold(SpatialBins::new, |mut b, c| {
                b.add(c, lo, w, ctx.corners);
                b
            })
            .reduce(SpatialBins::new, SpatialBins::merge)
    } else {
        let mut b = SpatialBins::new();
        b.add(&set.prims, lo, w, ctx.corners);
        b
    };
    let mut best: Option<Cut> = None;
    for axis in 0..3 {
        if w[axis] <= 0.0 {
            continue;
        }
        let (boxes, enter, exit) = (&bins.boxes[axis], &bins.enter[axis], &bins.exit[axis]);
        // Sweep: right side area and count (exits) from the right, left side from the left.
        let mut right_area = [0.0f32; SPATIAL_BINS];
        let mut right_count = [0usize; SPATIAL_BINS];
        let (mut acc, mut cnt) = (Aabb::EMPTY, 0usize);
        for i in (1..nb).rev() {
            acc.grow(&boxes[i]);
            cnt += exit[i] as usize;
            right_area[i] = acc.half_area();
            right_count[i] = cnt;
        }
        let (mut acc, mut cnt) = (Aabb::EMPTY, 0usize);
        for i in 1..nb {
            acc.grow(&boxes[i - 1]);
            cnt += enter[i - 1] as usize;
            if cnt == 0 || right_count[i] == 0 {
                continue;
            }
            let cost = acc.half_area() * blocks(cnt) + right_area[i] * blocks(right_count[i]);
            if best.is_none_or(|b| cost < b.cost()) {
                best = Some(Cut::Spatial { axis, plane: lo[axis] + i as f32 * w[axis], cost });
            }
        }
    }
    best
}

/// Cuts `set` in two.
fn apply(set: Set, cut: Cut, ctx: &Ctx<'_>) -> (Set, Set) {
    match cut {
        Cut::Object(s) => {
            let mut prims = set.prims;
            // The partition bounds both sides (and their centroids) as it goes.
            let (mid, [(lb, lc), (rb, rc)]) = partition(&mut prims, &s);
            if mid > 0 && mid < prims.len() {
                let right = prims.split_off(mid);
                return (Set { prims, bounds: lb, centroids: lc }, Set { prims: right, bounds: rb, centroids: rc });
            }
            halve(prims)
        }
        Cut::Spatial { axis, plane, .. } => {
            let (mut left, mut right) = (Vec::with_capacity(set.prims.len()), Vec::with_capacity(set.prims.len()));
            let mut added = 0isize;
            for p in &set.prims {
                let pb = p.bounds();
                if pb.hi[axis] <= plane {
                    left.push(*p);
                } else if pb.lo[axis] >= plane {
                    right.push(*p);
                } else {
                    match split_tri(&(ctx.corners)(p.id()), axis, plane, &pb) {
                        (Some(l), Some(r)) => {
                            left.push(PrimRef::new(l, p.id()));
                            right.push(PrimRef::new(r, p.id()));
                            added += 1;
                        }
                        // Touching the plane only: keep it whole on its side.
                        (Some(_), None) => left.push(*p),
                        _ => right.push(*p),
                    }
                }
            }
            ctx.budget.fetch_sub(added, Ordering::Relaxed);
            if left.is_empty() || right.is_empty() {
                let mut all = left;
                all.append(&mut right);
                return halve(all);
            }
            (Set::of(left), Set::of(right))
        }
        Cut::Median => halve(set.prims),
    }
}

fn halve(mut prims: Vec<PrimRef>) -> (Set, Set) {
    let right = prims.split_off(prims.len() / 2);
    (Set::of(prims), Set::of(right))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn high_builds_up_to_the_limit_keep_the_cheaper_of_two_spatial_trees() {
        // Random triangle soups above `SMALL_BUILD`: the build's SAH is the lower of the two
        // mappings' trees, and each mapping gives the cheaper tree on some of them.
        let mut rng = crate::raygen::Pcg32::new(21, 5);
        let mut r = || rng.next_f32();
        let cfg = BuildConfig::high();
        let (mut shifted_won, mut fine_won) = (0, 0);
        for set in 0..40 {
            let n = SMALL_BUILD + 1 + set * 7;
            let tris: Vec<[Vec3A; 3]> = (0..n)
                .map(|_| {
                    let a = Vec3A::new(r(), r(), r()) * 10.0;
                    let long = Vec3A::new(r(), r(), r()) * if r() < 0.2 { 8.0 } else { 1.0 };
                    [a, a + long, a + Vec3A::new(r(), r(), r())]
                })
                .collect();
            let prims: Vec<PrimRef> = tris
                .iter()
                .enumerate()
                .map(|(i, [a, b, c])| PrimRef::new(Aabb { lo: a.min(*b).min(*c), hi: a.max(*b).max(*c) }, i as u32))
                .collect();
            let corners = |id: u32| tris[id as usize];
            let fine = build_with(prims.clone(), &corners, &Settings::new(&cfg, BinRule::Fine)).0.cost.sah;
            let shifted = build_with(prims.clone(), &corners, &Settings::new(&cfg, BinRule::Shifted)).0.cost.sah;
            let (kept, refs) = build(prims, &corners, &cfg).unwrap();
            assert_eq!(kept.cost.sah, fine.min(shifted), "set {set}");
            assert!(refs.len() >= n, "set {set}");
            shifted_won += usize::from(shifted < fine);
            fine_won += usize::from(fine < shifted);
        }
        assert!(shifted_won > 0 && fine_won > 0, "shifted cheaper {shifted_won} times, fine {fine_won}");
    }

    #[test]
    fn all_planes_at_once_bin_like_one_plane_after_another() {
        // Triangles with corners anywhere or on bin planes, whole or already clipped references,
        // sets flat along an axis (width 0: not binned on it), any reference index: every bin
        // box equal to the bit to cutting off one bin after another with `split_tri_with`, and
        // every reference entering and leaving where the scalar bin index says.
        let mut rng = crate::raygen::Pcg32::new(11, 4);
        let mut r = || rng.next_f32();
        for case in 0..3000 {
            // Planes at whole numbers (cases 0..1000) or anywhere, a flat axis in every fifth.
            let (lo, mut w) = if case < 1000 {
                (Vec3A::ZERO, Vec3A::ONE)
            } else {
                (Vec3A::new(-3.5, 0.25, 70.0), Vec3A::new(0.75, 1.0, 2.5))
            };
            if case % 5 == 4 {
                w[case % 3] = 0.0;
            }
            let corner = |r: &mut dyn FnMut() -> f32| {
                let c = Vec3A::new(r(), r(), r()) * SPATIAL_BINS as f32;
                lo + w * if case % 3 == 0 { c.floor() } else { c }
            };
            let v = [corner(&mut r), corner(&mut r), corner(&mut r)];
            let full = Aabb { lo: v[0].min(v[1]).min(v[2]), hi: v[0].max(v[1]).max(v[2]) };
            let shrink = if case % 2 == 0 { 0.0 } else { 0.3 * r() };
            let pb = Aabb { lo: full.lo + (full.hi - full.lo) * shrink, hi: full.hi - (full.hi - full.lo) * shrink };
            let id = (r() * u32::MAX as f32) as u32 >> (case % 32);
            let mut bins = SpatialBins::new();
            bins.add(&[PrimRef::new(pb, id)], lo, w, &|_| v);
            for axis in 0..3 {
                let mut want = [Aabb::EMPTY; SPATIAL_BINS];
                let (mut enter, mut exit) = ([0u32; SPATIAL_BINS], [0u32; SPATIAL_BINS]);
                let bin = |x: f32| (((x - lo[axis]) / w[axis]) as usize).min(SPATIAL_BINS - 1);
                let (b0, b1) = (bin(pb.lo[axis]), bin(pb.hi[axis]).max(bin(pb.lo[axis])));
                if w[axis] > 0.0 {
                    (enter[b0], exit[b1]) = (1, 1);
                }
                assert_eq!((bins.enter[axis], bins.exit[axis]), (enter, exit), "case {case}, axis {axis}");
                // A flat axis (no width) bins nothing: `want` stays empty.
                if w[axis] > 0.0 && b0 == b1 {
                    want[b0] = pb;
                } else if w[axis] > 0.0 {
                    let mut rest = Some(pb);
                    for b in b0..b1 {
                        let Some(cur) = rest else { break };
                        let (l, r) = split_tri_with::<false>(&v, axis, lo[axis] + (b + 1) as f32 * w[axis], &cur);
                        if let Some(l) = l {
                            want[b] = l;
                        }
                        rest = r;
                    }
                    if let Some(r) = rest {
                        want[b1] = r;
                    }
                }
                let bits = |b: &Aabb| (b.lo.to_array().map(f32::to_bits), b.hi.to_array().map(f32::to_bits));
                for b in 0..SPATIAL_BINS {
                    assert_eq!(bits(&bins.boxes[axis][b]), bits(&want[b]), "case {case}, axis {axis}, bin {b}");
                }
            }
        }
    }

    #[test]
    fn split_parts_cover_the_triangle() {
        // Every point of the triangle lies in the part of its side, near the origin and far
        // from it (where the crossing points round), for planes through and beside it.
        let mut rng = crate::raygen::Pcg32::new(3, 9);
        let mut r = || rng.next_f32();
        for offset in [0.0f32, 1e3, 1e6] {
            for _ in 0..200 {
                let c = |r: &mut dyn FnMut() -> f32| {
                    Vec3A::new(r() * 2.0 - 1.0, r() * 2.0 - 1.0, r() * 2.0 - 1.0) + Vec3A::splat(offset)
                };
                let v = [c(&mut r), c(&mut r), c(&mut r)];
                let b = Aabb { lo: v[0].min(v[1]).min(v[2]), hi: v[0].max(v[1]).max(v[2]) };
                let axis = (r() * 3.0) as usize % 3;
                let plane = b.lo[axis] + (b.hi[axis] - b.lo[axis]) * (r() * 1.2 - 0.1);
                let (lp, rp) = split_tri(&v, axis, plane, &b);
                for _ in 0..200 {
                    let (mut u, mut w) = (r(), r());
                    if u + w > 1.0 {
                        (u, w) = (1.0 - u, 1.0 - w);
                    }
                    let p = v[0] + (v[1] - v[0]) * u + (v[2] - v[0]) * w;
                    let inside = |a: &Option<Aabb>| a.is_some_and(|a| a.lo.cmple(p).all() && p.cmple(a.hi).all());
                    assert!(inside(&lp) || inside(&rp), "{p:?} of {v:?} split at {plane} on {axis}");
                    if p[axis] < plane {
                        assert!(inside(&lp), "{p:?} left of {plane} on {axis}: {lp:?}");
                    }
                    if p[axis] > plane {
                        assert!(inside(&rp), "{p:?} right of {plane} on {axis}: {rp:?}");
                    }
                }
            }
        }
    }

    /// Two clusters of small triangles along x, `width` wide at either end of `[0, 10]`, and one
    /// long triangle across the whole box, and what `best_cut` makes of them.
    fn cut_of_clusters(width: f32) -> Cut {
        let mut tris = vec![[Vec3A::ZERO, Vec3A::new(10.0, 1.0, 0.0), Vec3A::new(10.0, 0.0, 1.0)]];
        for k in 0..8 {
            for x0 in [k as f32 * (width - 0.1) / 8.0, 10.0 - 0.1 - k as f32 * (width - 0.1) / 8.0] {
                tris.push([Vec3A::new(x0, 0.0, 0.0), Vec3A::new(x0 + 0.1, 1.0, 0.0), Vec3A::new(x0, 0.0, 1.0)]);
            }
        }
        let prims = tris
            .iter()
            .enumerate()
            .map(|(i, [a, b, c])| PrimRef::new(Aabb { lo: a.min(*b).min(*c), hi: a.max(*b).max(*c) }, i as u32))
            .collect();
        let set = Set::of(prims);
        let corners = |id: u32| tris[id as usize];
        let cfg = Settings::new(&BuildConfig::high(), BinRule::Fine);
        let ctx =
            Ctx { cfg: &cfg, corners: &corners, budget: AtomicIsize::new(100), root_area: set.bounds.half_area() };
        best_cut(&set, &ctx)
    }

    #[test]
    fn spatial_splits_only_where_the_object_split_overlaps_much_of_the_set() {
        // Clusters 3 wide: the object split's sides overlap in a third of the set's area, and
        // cutting the long triangle at the middle is cheaper.
        assert!(matches!(cut_of_clusters(3.0), Cut::Spatial { axis: 0, .. }));
        // Clusters 1 wide: the overlap is a seventh of the set's area, below `SET_OVERLAP`, though
        // a spatial split would still be cheaper than the object split here.
        assert!(matches!(cut_of_clusters(1.0), Cut::Object(_)));
    }
}
