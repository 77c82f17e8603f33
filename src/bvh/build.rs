//! Binned SAH builder producing wide nodes directly.
//!
//! The builder sees only boxes and centroids (madmann91/bvh's rule), never triangles. It follows
//! Embree's `BVHBuilderBinnedSAH` (`kernels/builders/bvh_builder_sah.h`): per node, bin centroids
//! into [`BuildConfig::bins`] bins on all three axes and sweep for the split of least SAH cost
//! (Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies", RT 2007), counting
//! primitives in whole leaf blocks; then fill a wide node by repeatedly splitting the child with the
//! largest surface area until it has `WIDTH` (8) children; then recurse, in parallel with rayon
//! above [`BuildConfig::parallel_threshold`] primitives.

use glam::{BVec3A, UVec4, Vec3A, Vec4};
use rayon::prelude::*;

use super::node::{EMPTY, MAX_LEAF_BLOCKS, Node, WIDTH, is_leaf, leaf_blocks, leaf_ref};
use super::traverse::BoxTest;
use crate::geometry::TriangleMesh;
use crate::geometry::triangle::{BLOCK, TriangleTest};
use crate::shapes::{QuarticSolver, SphereTest};
use crate::simd::{Level, trunc4, with_level};

/// Builder settings. Costs are per node visit and per block test, as in Embree's statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildConfig {
    /// Centroid bins per axis.
    pub bins: usize,
    /// Sets of at most this many primitives are never split.
    pub min_leaf: usize,
    /// Sets of more primitives are always split (at most `MAX_LEAF_BLOCKS` (15) blocks of 4).
    pub max_leaf: usize,
    /// Cost of visiting a node, relative to one block test.
    pub traversal_cost: f32,
    /// Cost of testing one block of triangles.
    pub intersection_cost: f32,
    /// Subtrees with more primitives are built in parallel.
    pub parallel_threshold: usize,
    /// The ray–triangle test the leaves are laid out for.
    pub triangle_test: TriangleTest,
    /// The ray–box test traversal uses.
    pub box_test: BoxTest,
    /// The ray–sphere test for a scene's spheres ([`SphereSet`](crate::SphereSet)).
    pub sphere_test: SphereTest,
    /// The quartic solver for a scene's tori ([`Primitive::Torus`](crate::shapes::Primitive::Torus)).
    pub quartic_solver: QuarticSolver,
    /// References per triangle that spatial splits may create, at most (1.0: no spatial splits,
    /// the default; [`high`](Self::high): 1.2, Embree HIGH's default).
    pub split_factor: f32,
}

impl Default for BuildConfig {
    /// Embree MEDIUM's choices for triangle BVHs: 32 bins, leaves of up to a few blocks of 4.
    fn default() -> Self {
        Self {
            bins: 32,
            min_leaf: BLOCK,
            max_leaf: 8 * BLOCK,
            traversal_cost: 1.0,
            intersection_cost: 1.0,
            parallel_threshold: 1024,
            triangle_test: TriangleTest::MollerTrumbore,
            box_test: BoxTest::Conservative,
            sphere_test: SphereTest::Robust,
            quartic_solver: QuarticSolver::Bracketed,
            split_factor: 1.0,
        }
    }
}

impl BuildConfig {
    /// Fewer bins: a faster build of a slightly worse tree.
    pub fn fast() -> Self {
        Self { bins: 16, ..Self::default() }
    }

    /// Embree HIGH's choices: spatial splits (Stich et al. 2009) with up to 20% more references,
    /// for trees that trace faster at a slower build.
    pub fn high() -> Self {
        Self { split_factor: 1.2, ..Self::default() }
    }

    /// Watertight triangles and conservative boxes: no ray leaks through a closed mesh.
    pub fn watertight() -> Self {
        Self { triangle_test: TriangleTest::Watertight, box_test: BoxTest::Conservative, ..Self::default() }
    }

    /// This configuration with another triangle and box test.
    pub fn with_tests(&self, triangle_test: TriangleTest, box_test: BoxTest) -> Self {
        Self { triangle_test, box_test, ..self.clone() }
    }

    pub(super) fn clamped(&self) -> Self {
        let max_leaf = self.max_leaf.clamp(1, MAX_LEAF_BLOCKS * BLOCK);
        Self {
            bins: self.bins.clamp(2, MAX_BINS),
            min_leaf: self.min_leaf.clamp(1, max_leaf),
            max_leaf,
            traversal_cost: self.traversal_cost.max(0.0),
            intersection_cost: self.intersection_cost.max(1e-6),
            parallel_threshold: self.parallel_threshold.max(64),
            split_factor: if self.split_factor.is_finite() { self.split_factor.clamp(1.0, 4.0) } else { 1.0 },
            ..*self
        }
    }
}

/// Most bins per axis (fixed-size bin arrays on the stack).
pub const MAX_BINS: usize = 32;
const _: () = assert!(MAX_BINS.is_power_of_two(), "bin indices are masked with MAX_BINS − 1");

/// How many bins a set of `n` references is binned into (at most [`BuildConfig::bins`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum BinRule {
    /// `n/2` up to 16 bins, then `4 + n/8` (all 32 from 224 references): the default.
    Fine,
    /// Embree's `4 + n/20`, with its bin mapping: the second tree of small builds
    /// ([`SMALL_BUILD`]).
    Coarse,
    /// The fine rule's bin count with Embree's bin mapping, which moves every bin boundary: the
    /// second tree of small HIGH builds (`spatial::TWO_HIGH_TREES`).
    Shifted,
}

impl BinRule {
    fn bins(self, n: usize, max: usize) -> usize {
        match self {
            BinRule::Fine | BinRule::Shifted => (4 + n / 8).max((n / 2).min(16)),
            BinRule::Coarse => 4 + n / 20,
        }
        .min(max.max(4))
    }

    /// The bin mapping's scale, `bins / extent` times this: slightly less than 1 so that the
    /// largest centroid lands in the last bin (Embree's 0.99 for the coarse rule).
    fn mapping(self) -> f32 {
        match self {
            BinRule::Fine => 0.99999,
            BinRule::Coarse | BinRule::Shifted => 0.99,
        }
    }
}

/// What a build runs with: the caller's configuration (clamped) and the bin rule of this tree.
/// Reads as a [`BuildConfig`] through `Deref`.
#[derive(Clone, Debug)]
pub(super) struct Settings {
    pub cfg: BuildConfig,
    pub rule: BinRule,
}

impl Settings {
    pub fn new(cfg: &BuildConfig, rule: BinRule) -> Self {
        Self { cfg: cfg.clamped(), rule }
    }
}

impl std::ops::Deref for Settings {
    type Target = BuildConfig;
    fn deref(&self) -> &BuildConfig {
        &self.cfg
    }
}

/// Builds of at most this many references are made twice, with the [`BinRule::Fine`] and the
/// [`BinRule::Coarse`] rule, and the tree of lower SAH cost is kept. Trees this small are a node
/// or two deep, so the few splits that fill the root decide the whole tree, and which bin
/// boundaries they can choose from is a lottery neither rule wins everywhere: the shared
/// 34-triangle Cornell box costs 4.32 with the fine rule and 4.04 with the coarse one (Embree
/// MEDIUM's tree), the 32-triangle measured one 3.93 with the fine rule. The second tree adds
/// 2–3 µs to a build of 4–6 (PERFORMANCE.md).
pub(super) const SMALL_BUILD: usize = 64;

/// Past this many wide levels, sets are split at the object median so that depth (and the
/// traversal stack) stays bounded whatever the input.
pub(crate) const MEDIAN_DEPTH: usize = 40;

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Aabb {
    pub lo: Vec3A,
    pub hi: Vec3A,
}

impl Aabb {
    pub const EMPTY: Self = Self { lo: Vec3A::INFINITY, hi: Vec3A::NEG_INFINITY };

    #[inline(always)]
    pub fn grow(&mut self, o: &Aabb) {
        self.lo = self.lo.min(o.lo);
        self.hi = self.hi.max(o.hi);
    }

    #[inline]
    pub fn grow_point(&mut self, p: Vec3A) {
        self.lo = self.lo.min(p);
        self.hi = self.hi.max(p);
    }

    /// Half the surface area; 0 for an empty box.
    #[inline]
    pub fn half_area(&self) -> f32 {
        let d = (self.hi - self.lo).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// A primitive as the builder sees it: its box, with its index in the spare fourth lane of the
/// lower corner (Embree's `PrimRef` layout), 32 bytes, so partitioning moves half a cache line.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PrimRef {
    lo: Vec4,
    hi: Vec4,
}

impl PrimRef {
    pub fn new(bounds: Aabb, id: u32) -> Self {
        Self { lo: bounds.lo.extend(f32::from_bits(id)), hi: bounds.hi.extend(0.0) }
    }

    #[inline]
    pub fn id(&self) -> u32 {
        self.lo.w.to_bits()
    }

    #[inline(always)]
    pub fn bounds(&self) -> Aabb {
        Aabb { lo: Vec3A::from_vec4(self.lo), hi: Vec3A::from_vec4(self.hi) }
    }

    /// Twice the centroid (saves a multiply; only ratios of it are used).
    #[inline(always)]
    fn center2(&self) -> Vec3A {
        Vec3A::from_vec4(self.lo) + Vec3A::from_vec4(self.hi)
    }
}

/// The builder's output: a subtree already in the final node layout (depth-first preorder), so
/// that nothing but a copy remains to be done once all subtrees are built. Subtrees built in
/// parallel are chunks of their own, placed after their parent's chunk in order.
///
/// Child references in `nodes` are relative to the chunk: an inner child's node index from the
/// chunk's first node, a leaf's first block from the chunk's first block ([`rebase`] makes them
/// absolute).
#[derive(Debug, Default)]
pub(crate) struct Chunk {
    /// Inner nodes, depth-first preorder.
    pub nodes: Vec<Node>,
    /// Primitive ranges `(start, count)` of the chunk's own leaves, in order: each leaf's blocks
    /// follow the previous leaf's.
    pub leaves: Vec<(usize, usize)>,
    /// Blocks of the chunk's own leaves.
    pub own_blocks: usize,
    /// Subtrees built in parallel (a chunk with kids holds one node, their parent), laid out
    /// after the chunk's own nodes and blocks, in order.
    pub kids: Vec<Chunk>,
    /// Totals of the chunk and its kids.
    pub size: Size,
}

/// Sizes of a subtree: inner nodes, leaves, and triangle blocks of its leaves.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Size {
    pub nodes: usize,
    pub leaves: usize,
    pub blocks: usize,
}

impl std::ops::Add for Size {
    type Output = Size;
    fn add(self, o: Size) -> Size {
        Size { nodes: self.nodes + o.nodes, leaves: self.leaves + o.leaves, blocks: self.blocks + o.blocks }
    }
}

/// A subtree's share of the SAH cost as Embree's `BVHNStatistics` counts it (the half area of
/// every inner node, the half area of every leaf times its blocks; not yet relative to the
/// root's), and its depth in wide levels.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct SubtreeCost {
    pub sah: f64,
    pub depth: usize,
}

impl SubtreeCost {
    /// Adds a child with box `b`, reference `r` and the cost `below` it.
    pub fn add_child(&mut self, b: &Aabb, r: u32, below: SubtreeCost) {
        self.sah += node_cost(b, r) + below.sah;
        self.depth = self.depth.max(below.depth + 1);
    }
}

/// The cost of the node that `r` names itself, whose box is `b`.
pub(crate) fn node_cost(b: &Aabb, r: u32) -> f64 {
    let area = b.half_area() as f64;
    if is_leaf(r) { area * leaf_blocks(r).1 as f64 } else { area }
}

/// `r`, relative to a chunk, made relative to a place `nodes` nodes and `blocks` blocks further.
#[inline]
pub(crate) fn rebase(r: u32, nodes: usize, blocks: usize) -> u32 {
    if r == EMPTY {
        r
    } else if is_leaf(r) {
        // The block index is the low field; the total stays below MAX_BLOCK_INDEX (checked
        // before the chunks are placed).
        r + blocks as u32
    } else {
        r + nodes as u32
    }
}

impl Chunk {
    /// Appends a leaf over primitives `start..start + count`; returns its reference.
    pub fn leaf(&mut self, start: usize, count: usize) -> u32 {
        let blocks = count.div_ceil(BLOCK);
        let r = leaf_ref(self.own_blocks, blocks);
        self.leaves.push((start, count));
        self.own_blocks += blocks;
        self.size.leaves += 1;
        self.size.blocks += blocks;
        r
    }

    /// Reserves the slot of an inner node whose subtree follows; [`close`](Self::close) fills it.
    pub fn open(&mut self) -> usize {
        self.nodes.push(Node::default());
        self.size.nodes += 1;
        self.nodes.len() - 1
    }

    /// Fills slot `index` with `node`; returns its reference.
    pub fn close(&mut self, index: usize, node: Node) -> u32 {
        self.nodes[index] = node;
        index as u32
    }

    /// Attaches `kid`, built in parallel, after the kids already attached; returns `r` (relative
    /// to `kid`) relative to this chunk.
    pub fn attach(&mut self, kid: Chunk, r: u32) -> u32 {
        let before = self.kids.iter().fold(Size::default(), |a, k| a + k.size);
        let r = rebase(r, self.nodes.len() + before.nodes, self.own_blocks + before.blocks);
        self.size = self.size + kid.size;
        self.kids.push(kid);
        r
    }
}

#[derive(Clone, Copy, Debug)]
pub(super) struct Split {
    axis: usize,
    /// Primitives in bins `< pos` go left.
    pos: usize,
    /// `A_left · blocks_left + A_right · blocks_right` (half areas).
    pub(super) cost: f32,
    scale: f32,
    offset: f32,
}

/// A set of primitives under construction: a range of the reference array with its bounds.
#[derive(Clone, Copy, Debug)]
struct Set {
    start: usize,
    count: usize,
    bounds: Aabb,
    centroids: Aabb,
}

#[inline]
pub(super) fn blocks(n: usize) -> f32 {
    n.div_ceil(BLOCK) as f32
}

/// Centroid bins of one set on all three axes, in two copies that alternate between consecutive
/// references (see [`bin_into`]); [`settle`](Bins::settle) folds the second into the first.
#[derive(Clone)]
struct Bins {
    boxes: [BinBoxes; 2],
    /// Per bin, the count on each axis (the fourth lane stays 0, for vector loads in `sweep`).
    counts: [BinCounts; 2],
    n: usize,
}

impl Bins {
    fn new(n: usize) -> Self {
        Self { boxes: [[[Aabb::EMPTY; 3]; MAX_BINS]; 2], counts: [[[0; 4]; MAX_BINS]; 2], n }
    }

    #[inline(always)]
    fn reset(&mut self, n: usize) {
        self.n = n;
        for c in 0..2 {
            for i in 0..n {
                self.boxes[c][i] = [Aabb::EMPTY; 3];
                self.counts[c][i] = [0; 4];
            }
        }
    }

    fn merge(mut self, o: Bins) -> Bins {
        for c in 0..2 {
            fold(self.n, (&mut self.boxes[c], &mut self.counts[c]), (&o.boxes[c], &o.counts[c]));
        }
        self
    }

    /// Folds the second copy into the first, which then holds the whole set.
    #[inline(always)]
    fn settle(&mut self) {
        let ([first, second], [first_n, second_n]) = (&mut self.boxes, &mut self.counts);
        fold(self.n, (first, first_n), (second, second_n));
    }
}

type BinBoxes = [[Aabb; 3]; MAX_BINS];
type BinCounts = [[u32; 4]; MAX_BINS];

/// Grows the first `n` bins of `to` by those of `from`.
#[inline(always)]
fn fold(n: usize, to: (&mut BinBoxes, &mut BinCounts), from: (&BinBoxes, &BinCounts)) {
    for (a, b) in to.0.iter_mut().zip(from.0).take(n) {
        for k in 0..3 {
            a[k].grow(&b[k]);
        }
    }
    for (a, b) in to.1.iter_mut().zip(from.1).take(n) {
        for k in 0..3 {
            a[k] += b[k];
        }
    }
}

/// The three bin indices of a reference's centroid; the clamp keeps the truncation in range
/// (NaN-free input).
///
/// The fourth lanes are cleared first: a reference keeps its index there, which as a float is a
/// denormal (below 2²³), and a multiply with a denormal operand costs a microcode assist on x86
/// without denormals-are-zero, as a user's thread runs (PERFORMANCE.md, session 58). Clearing
/// `offset`'s and `scale`'s lanes is loop-invariant and leaves the loop.
#[inline(always)]
fn bin_of(p: &PrimRef, offset: Vec3A, scale: Vec3A, last: Vec3A) -> [i32; 4] {
    let c = xyz0(p.center2()) - xyz0(offset);
    trunc4((c * xyz0(scale)).clamp(Vec3A::ZERO, last).extend(0.0).to_array())
}

/// `v` with its fourth lane zero (one `andps`), for arithmetic on a [`PrimRef`]'s box or anything
/// grown from it: that lane holds a reference's index, a denormal as a float, and a multiply or
/// divide with a denormal operand costs a microcode assist (see [`bin_of`]).
#[inline(always)]
pub(super) fn xyz0(v: Vec3A) -> Vec3A {
    Vec3A::select(BVec3A::new(true, true, true), v, Vec3A::ZERO)
}

/// A bin index from [`bin_of`] (in `0..bins`), masked into `0..MAX_BINS` so that indexing needs
/// no bounds check.
#[inline(always)]
fn bin_index(b: i32) -> usize {
    b as usize & (MAX_BINS - 1)
}

/// Writes the references of mesh `m`'s hittable triangles in `range` (global ids from `offset`)
/// to the front of `out` (room for the whole range); returns how many. Each triangle's corners
/// are fetched once, for the hittability test and the box. Runs at the active level, as
/// [`bin_into`] does (in a dependency build the crate's level is SSE2; PERFORMANCE.md has what
/// this gained: little).
pub(super) fn write_refs(m: &TriangleMesh, offset: usize, range: std::ops::Range<usize>, out: &mut [PrimRef]) -> usize {
    with_level!(|L| L::call(
        #[inline(always)]
        || {
            let mut n = 0;
            for i in range {
                if let Some([a, b, c]) = m.hittable_corners(i) {
                    let (a, b, c) = (Vec3A::from(a), Vec3A::from(b), Vec3A::from(c));
                    out[n] = PrimRef::new(Aabb { lo: a.min(b).min(c), hi: a.max(b).max(c) }, (offset + i) as u32);
                    n += 1;
                }
            }
            n
        }
    ))
}

/// Sets of at least this many references are binned in runs ([`bin_runs`]) when their first
/// [`RUN_SAMPLE`] references change bins fewer than [`RUN_CHANGES`] times over the three axes.
const RUN_MIN: usize = 4096;
const RUN_SAMPLE: usize = 64;
const RUN_CHANGES: u32 = 20;

/// Adds `prims` to `bins`. Neighbouring references of a mesh tend to fall in the same bins, and
/// then each bin update waits for the previous one's store: one copy of the bins took
/// 8.3–9.6 ns per reference on the sphereflake, igea and conference in mesh order against
/// 4.8–5.2 shuffled. Consecutive references therefore go to alternate copies (4.8–5.0 ns in
/// mesh order), and large sets whose order is that coherent keep each axis's current bin in
/// registers instead (2.5–3.0 ns; 5.5–10 ns on shuffled input, hence the sample). PERFORMANCE.md
/// has the figures.
///
/// Runs at the active instruction-set level (`simd::with_level!`): its code, glam's included, is
/// inlined into the level's `#[target_feature]` function, as the walks are.
fn bin_into(bins: &mut Bins, prims: &[PrimRef], offset: Vec3A, scale: Vec3A) {
    with_level!(|L| L::call(
        #[inline(always)]
        || bin_into_in(bins, prims, offset, scale)
    ))
}

#[inline(always)]
fn bin_into_in(bins: &mut Bins, prims: &[PrimRef], offset: Vec3A, scale: Vec3A) {
    let last = Vec3A::splat((bins.n - 1) as f32);
    if prims.len() >= RUN_MIN {
        let mut prev = [-1i32; 4];
        let mut changes = 0u32;
        for p in &prims[..RUN_SAMPLE] {
            let b = bin_of(p, offset, scale, last);
            for a in 0..3 {
                changes += u32::from(b[a] != prev[a]);
            }
            prev = b;
        }
        if changes < RUN_CHANGES {
            return bin_runs(bins, prims, offset, scale, last);
        }
    }
    let mut pairs = prims.chunks_exact(2);
    for pair in &mut pairs {
        let (b0, b1) = (bin_of(&pair[0], offset, scale, last), bin_of(&pair[1], offset, scale, last));
        let (p0, p1) = (pair[0].bounds(), pair[1].bounds());
        for a in 0..3 {
            let (i, j) = (bin_index(b0[a]), bin_index(b1[a]));
            bins.boxes[0][i][a].grow(&p0);
            bins.counts[0][i][a] += 1;
            bins.boxes[1][j][a].grow(&p1);
            bins.counts[1][j][a] += 1;
        }
    }
    for p in pairs.remainder() {
        let b = bin_of(p, offset, scale, last);
        let pb = p.bounds();
        for a in 0..3 {
            let i = bin_index(b[a]);
            bins.boxes[0][i][a].grow(&pb);
            bins.counts[0][i][a] += 1;
        }
    }
}

/// [`bin_into`] for references in coherent order: each axis grows a box and a count for its
/// current bin in registers and adds them to the bins only when the bin changes.
#[inline(always)]
fn bin_runs(bins: &mut Bins, prims: &[PrimRef], offset: Vec3A, scale: Vec3A, last: Vec3A) {
    let Some(first) = prims.first() else { return };
    let b = bin_of(first, offset, scale, last);
    let mut cur = [bin_index(b[0]), bin_index(b[1]), bin_index(b[2])];
    let mut acc = [Aabb::EMPTY; 3];
    let mut cnt = [0u32; 3];
    for p in prims {
        let b = bin_of(p, offset, scale, last);
        let pb = p.bounds();
        for a in 0..3 {
            let i = bin_index(b[a]);
            if i == cur[a] {
                acc[a].grow(&pb);
                cnt[a] += 1;
            } else {
                bins.boxes[0][cur[a]][a].grow(&acc[a]);
                bins.counts[0][cur[a]][a] += cnt[a];
                (cur[a], acc[a], cnt[a]) = (i, pb, 1);
            }
        }
    }
    for a in 0..3 {
        bins.boxes[0][cur[a]][a].grow(&acc[a]);
        bins.counts[0][cur[a]][a] += cnt[a];
    }
}

/// Sets of at least four times this many primitives are binned in parallel, in chunks of this
/// size (each chunk fills its own bins, which are then merged).
pub(super) const BIN_CHUNK: usize = 4096;

/// The best binned SAH split of `prims` (whose doubled centroids lie in `cb`), if any axis has
/// extent.
pub(super) fn find_split(prims: &[PrimRef], cb: &Aabb, cfg: &Settings) -> Option<Split> {
    // Small sets get fewer bins: the bins are cleared and swept on every call, and a set of 10
    // primitives gains nothing from 32 of them. The fine rule lies between `n/2` and Embree's
    // `4 + n/20` (PERFORMANCE.md has the SAH and times of each).
    let nb = cfg.rule.bins(prims.len(), cfg.bins);
    let ext = cb.hi - cb.lo;
    let scale = Vec3A::select(ext.cmpgt(Vec3A::ZERO), Vec3A::splat(nb as f32 * cfg.rule.mapping()) / ext, Vec3A::ZERO);
    if prims.len() >= 4 * BIN_CHUNK {
        return find_split_parallel(prims, cb, nb, scale);
    }
    // Small and medium sets bin into this thread's scratch bins, clearing only the bins in use:
    // clearing all 32 on every call cost about a quarter of a 6k-triangle build.
    SCRATCH.with(|cell| match cell.try_borrow_mut() {
        Ok(mut b) => bin_and_sweep(&mut b, nb, prims, cb, scale),
        Err(_) => find_split_fresh(prims, cb, nb, scale),
    })
}

/// Clears `nb` of `bins`, bins `prims` into them and sweeps them: the whole of a small or medium
/// set's split search in one call at the active level, clearing and folding the bins included
/// (at the crate's level in a dependency build those ran at SSE2).
fn bin_and_sweep(bins: &mut Bins, nb: usize, prims: &[PrimRef], cb: &Aabb, scale: Vec3A) -> Option<Split> {
    with_level!(|L| L::call(
        #[inline(always)]
        || {
            bins.reset(nb);
            bin_into_in(bins, prims, cb.lo, scale);
            bins.settle();
            sweep_in(bins, cb, scale)
        }
    ))
}

/// [`find_split`] for large sets: chunks binned in parallel, each fold into its own bins. Out of
/// line, so that the common path's frame does not hold these 6 KB values.
#[inline(never)]
fn find_split_parallel(prims: &[PrimRef], cb: &Aabb, nb: usize, scale: Vec3A) -> Option<Split> {
    let mut bins = prims
        .par_chunks(BIN_CHUNK)
        .fold(
            || Bins::new(nb),
            |mut b, c| {
                bin_into(&mut b, c, cb.lo, scale);
                b
            },
        )
        .reduce(|| Bins::new(nb), Bins::merge);
    bins.settle();
    sweep(&bins, cb, scale)
}

/// [`find_split`] with fresh bins, should this thread's scratch bins be in use (never in the
/// current builder: binning does not re-enter it).
#[cold]
#[inline(never)]
fn find_split_fresh(prims: &[PrimRef], cb: &Aabb, nb: usize, scale: Vec3A) -> Option<Split> {
    bin_and_sweep(&mut Bins::new(nb), nb, prims, cb, scale)
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Bins> = std::cell::RefCell::new(Bins::new(MAX_BINS));
}

/// The split of least SAH cost over filled and settled bins: all three axes at once, one per
/// vector lane. Runs at the active level, as [`bin_into`] does.
fn sweep(bins: &Bins, cb: &Aabb, scale: Vec3A) -> Option<Split> {
    with_level!(|L| L::call(
        #[inline(always)]
        || sweep_in(bins, cb, scale)
    ))
}

#[inline(always)]
fn sweep_in(bins: &Bins, cb: &Aabb, scale: Vec3A) -> Option<Split> {
    let nb = bins.n;
    // Per bin i: the cost of the right side `A · blocks` of bins >= i (infinite if empty).
    let mut right_cost = [Vec4::ZERO; MAX_BINS];
    let mut acc = [Aabb::EMPTY; 3];
    let mut cnt = UVec4::ZERO;
    for i in (1..nb).rev() {
        for (a, b) in acc.iter_mut().zip(&bins.boxes[0][i]) {
            a.grow(b);
        }
        cnt += UVec4::from_array(bins.counts[0][i]);
        right_cost[i] = side_costs(&acc, cnt);
    }
    // Sweep from the left, evaluating the split before bin i; no branch on the data, the first
    // of equal costs wins.
    let mut acc = [Aabb::EMPTY; 3];
    let mut cnt = UVec4::ZERO;
    // Positions as floats (exact below 2^24) so that one mask selects both.
    let (mut best_cost, mut best_pos) = (Vec4::INFINITY, Vec4::ZERO);
    for i in 1..nb {
        for (a, b) in acc.iter_mut().zip(&bins.boxes[0][i - 1]) {
            a.grow(b);
        }
        cnt += UVec4::from_array(bins.counts[0][i - 1]);
        let cost = side_costs(&acc, cnt) + right_cost[i];
        let better = cost.cmplt(best_cost);
        best_cost = Vec4::select(better, cost, best_cost);
        best_pos = Vec4::select(better, Vec4::splat(i as f32), best_pos);
    }
    // The axis of least cost; of equal costs the first.
    let mut best: Option<Split> = None;
    for axis in 0..3 {
        let (cost, pos) = (best_cost[axis], best_pos[axis] as usize);
        if scale[axis] != 0.0 && pos != 0 && best.is_none_or(|b| cost < b.cost) {
            best = Some(Split { axis, pos, cost, scale: scale[axis], offset: cb.lo[axis] });
        }
    }
    best
}

/// `half area · blocks` of the three axes' boxes `acc` holding `cnt` references, one per lane
/// (infinite where empty), in the same operations as [`Aabb::half_area`] and [`blocks`].
#[inline(always)]
fn side_costs(acc: &[Aabb; 3], cnt: UVec4) -> Vec4 {
    let d = acc.map(|b| (b.hi - b.lo).max(Vec3A::ZERO));
    let x = Vec4::new(d[0].x, d[1].x, d[2].x, 0.0);
    let y = Vec4::new(d[0].y, d[1].y, d[2].y, 0.0);
    let z = Vec4::new(d[0].z, d[1].z, d[2].z, 0.0);
    let area = x * y + y * z + z * x;
    let blocks = ((cnt + UVec4::splat(BLOCK as u32 - 1)) >> UVec4::splat(BLOCK.trailing_zeros())).as_vec4();
    Vec4::select(blocks.cmpeq(Vec4::ZERO), Vec4::INFINITY, area * blocks)
}

/// Whether a doubled centroid `c` falls on the left of `split`.
#[inline]
pub(super) fn goes_left(c: Vec3A, split: &Split) -> bool {
    // The bin is `trunc(x)` (clamped to the last) of `x = (c − offset) · scale ≥ 0`, and
    // `trunc(x) < pos` exactly when `x < pos` for a whole `pos` below the bin count: one float
    // comparison of the same rounded `x` the binning computed.
    (c[split.axis] - split.offset) * split.scale < split.pos as f32
}

/// Reorders `prims` so that the left side of `split` comes first; returns the left count and both
/// sides' `(bounds, centroid bounds)`.
///
/// Hoare's partition branches on every reference's side: 1.2–1.4 ns per reference where the
/// sides come in long runs (Sponza's, igea's meshes in their order), 3.1 ns in the bunny's
/// order and 5–6 ns shuffled. The block partition does not branch on sides but needs a second
/// pass for the bounds: 2.1 ns in any order. So the first [`PART_SAMPLE`] references choose: a
/// set whose sides change at least [`PART_CHANGES`] times there takes the blocks.
pub(super) fn partition(prims: &mut [PrimRef], split: &Split) -> (usize, [(Aabb, Aabb); 2]) {
    if prims.len() > 2 * PART_BLOCK {
        let mut changes = 0;
        let mut prev = goes_left(prims[0].center2(), split);
        for p in &prims[1..PART_SAMPLE] {
            let side = goes_left(p.center2(), split);
            changes += usize::from(side != prev);
            prev = side;
        }
        if changes >= PART_CHANGES {
            let mid = partition_blocks(prims, split);
            return (mid, [bounds_of(&prims[..mid]), bounds_of(&prims[mid..])]);
        }
    }
    partition_hoare(prims, split)
}

/// References sampled, and side changes among them, that send a set to the block partition.
const PART_SAMPLE: usize = 32;
const PART_CHANGES: usize = 4;

const PART_BLOCK: usize = 64;

/// Block partition (Edelkamp and Weiß, "BlockQuicksort", 2016): each end classifies a block of
/// [`PART_BLOCK`] references without branches, recording the offsets of the misplaced ones, and
/// misplaced pairs are swapped; the last blocks go to Hoare's loop. Returns the left count.
/// The side is [`goes_left`]'s comparison, on the axis's lanes read straight from memory.
fn partition_blocks(prims: &mut [PrimRef], split: &Split) -> usize {
    let (axis, offset, scale, pos) = (split.axis, split.offset, split.scale, split.pos as f32);
    let lane = |v: &Vec4| AsRef::<[f32; 4]>::as_ref(v)[axis];
    let left = |p: &PrimRef| (lane(&p.lo) + lane(&p.hi) - offset) * scale < pos;
    let (mut l, mut r) = (0usize, prims.len());
    let (mut off_l, mut off_r) = ([0u8; PART_BLOCK], [0u8; PART_BLOCK]);
    let (mut start_l, mut num_l, mut start_r, mut num_r) = (0usize, 0usize, 0usize, 0usize);
    while r - l > 2 * PART_BLOCK {
        if num_l == 0 {
            start_l = 0;
            for (k, p) in prims[l..l + PART_BLOCK].iter().enumerate() {
                off_l[num_l] = k as u8;
                num_l += usize::from(!left(p));
            }
        }
        if num_r == 0 {
            start_r = 0;
            for (k, p) in prims[r - PART_BLOCK..r].iter().rev().enumerate() {
                off_r[num_r] = k as u8;
                num_r += usize::from(left(p));
            }
        }
        let num = num_l.min(num_r);
        for k in 0..num {
            prims.swap(l + off_l[start_l + k] as usize, r - 1 - off_r[start_r + k] as usize);
        }
        (num_l, num_r, start_l, start_r) = (num_l - num, num_r - num, start_l + num, start_r + num);
        if num_l == 0 {
            l += PART_BLOCK;
        }
        if num_r == 0 {
            r -= PART_BLOCK;
        }
    }
    l + partition_hoare(&mut prims[l..r], split).0
}

/// `(bounds, centroid bounds)` of `prims`, in four interleaved chains.
fn bounds_of(prims: &[PrimRef]) -> (Aabb, Aabb) {
    let (mut b, mut c) = ([Aabb::EMPTY; 4], [Aabb::EMPTY; 4]);
    let mut quads = prims.chunks_exact(4);
    for q in &mut quads {
        for k in 0..4 {
            b[k].grow(&q[k].bounds());
            c[k].grow_point(q[k].center2());
        }
    }
    for p in quads.remainder() {
        b[0].grow(&p.bounds());
        c[0].grow_point(p.center2());
    }
    let ([mut b, b1, b2, b3], [mut c, c1, c2, c3]) = (b, c);
    for (x, y) in [(b1, c1), (b2, c2), (b3, c3)] {
        b.grow(&x);
        c.grow(&y);
    }
    (b, c)
}

/// [`partition`] by Hoare's scheme.
fn partition_hoare(prims: &mut [PrimRef], split: &Split) -> (usize, [(Aabb, Aabb); 2]) {
    let goes_left = |c: Vec3A| goes_left(c, split);
    let mut sides = [(Aabb::EMPTY, Aabb::EMPTY); 2];
    let grow = |side: &mut (Aabb, Aabb), p: &PrimRef| {
        side.0.grow(&p.bounds());
        side.1.grow_point(p.center2());
    };
    // Hoare's scheme (Embree's `serial_partitioning`): both ends scan past the references already
    // on their side, and only misplaced pairs are swapped.
    let (mut i, mut j) = (0usize, prims.len());
    loop {
        while i < j && goes_left(prims[i].center2()) {
            grow(&mut sides[0], &prims[i]);
            i += 1;
        }
        while i < j && !goes_left(prims[j - 1].center2()) {
            grow(&mut sides[1], &prims[j - 1]);
            j -= 1;
        }
        if i >= j {
            break;
        }
        // prims[i] goes right and prims[j - 1] goes left.
        grow(&mut sides[1], &prims[i]);
        grow(&mut sides[0], &prims[j - 1]);
        prims.swap(i, j - 1);
        i += 1;
        j -= 1;
    }
    (i, sides)
}

fn set_of(prims: &[PrimRef], start: usize) -> Set {
    let (bounds, centroids) = bounds_of(prims);
    Set { start, count: prims.len(), bounds, centroids }
}

/// Splits `set` (whose primitives are `prims`, indexed from `set.start`) in two: by SAH where
/// possible, else at the object median.
fn split_set(set: &Set, prims: &mut [PrimRef], split: Option<Split>) -> (Set, Set) {
    let local = &mut prims[set.start..set.start + set.count];
    if let Some(s) = split {
        let (mid, [(lb, lc), (rb, rc)]) = partition(local, &s);
        if mid > 0 && mid < local.len() {
            return (
                Set { start: set.start, count: mid, bounds: lb, centroids: lc },
                Set { start: set.start + mid, count: local.len() - mid, bounds: rb, centroids: rc },
            );
        }
    }
    // No usable split (all centroids equal, or forced): halve in the current order.
    let mid = local.len() / 2;
    let (l, r) = local.split_at(mid);
    (set_of(l, set.start), set_of(r, set.start + mid))
}

/// Builds the tree over `prims` (reordering them) and returns it with its root bounds.
pub(crate) fn build(prims: &mut [PrimRef], cfg: &BuildConfig) -> Option<Built> {
    if prims.is_empty() {
        return None;
    }
    let fine = build_with_rule(prims, cfg, BinRule::Fine);
    if prims.len() > SMALL_BUILD {
        return Some(fine);
    }
    let mut alt = prims.to_vec();
    let coarse = build_with_rule(&mut alt, cfg, BinRule::Coarse);
    if coarse.cost.sah < fine.cost.sah {
        prims.copy_from_slice(&alt);
        return Some(coarse);
    }
    Some(fine)
}

/// [`build`] of a non-empty set with one bin rule.
pub(super) fn build_with_rule(prims: &mut [PrimRef], cfg: &BuildConfig, rule: BinRule) -> Built {
    build_presplit(prims, &Settings::new(cfg, rule), PRESPLIT_MIN)
}

/// A built tree: its root bounds, its nodes in chunks, the root's reference (absolute: the top
/// chunk comes first) and the cost of the whole tree (the root's own included).
#[derive(Debug)]
pub(crate) struct Built {
    pub bounds: Aabb,
    pub chunk: Chunk,
    pub root: u32,
    pub cost: SubtreeCost,
}

impl Built {
    /// The tree whose root, with box `bounds`, is `root` in `chunk`, `below` costing the rest.
    pub fn new(bounds: Aabb, chunk: Chunk, root: u32, below: SubtreeCost) -> Self {
        let cost = SubtreeCost { sah: node_cost(&bounds, root) + below.sah, depth: below.depth };
        Built { bounds, chunk, root, cost }
    }
}

/// [`build`] of a non-empty set, splitting sets of `presplit_min` or more ahead.
fn build_presplit(prims: &mut [PrimRef], cfg: &Settings, presplit_min: usize) -> Built {
    let root = set_of(prims, 0);
    let min = presplit_min.max(cfg.max_leaf + 1);
    let pre = presplit(root, prims, 0, cfg, min, 0);
    let mut chunk = Chunk::default();
    let (r, below) = recurse_at(root, prims, 0, cfg, 0, pre, &mut chunk);
    Built::new(root.bounds, chunk, r, below)
}

/// Sets of at least this many references are split ahead of the wide nodes ([`presplit`]).
const PRESPLIT_MIN: usize = 4096;

/// A large set's split and its two halves (with theirs, if large), computed before the wide node
/// that splits it exists.
struct Presplit {
    split: Option<Split>,
    /// The halves, in absolute indices.
    halves: [(Set, Option<Box<Presplit>>); 2],
}

/// Splits `set` (indexed like `recurse_at`'s) and its halves recursively, both halves in parallel,
/// down to sets of `min` (more than `max_leaf`).
///
/// A wide node is filled by splitting its largest child again and again, one split after the
/// other; at the root that serial chain took 1.6–1.8 ms of the bunny's 9.5 ms build on 2 threads,
/// and the pool's second thread, asleep, joined a parallel binning only after the 30–45 µs it takes
/// to wake. But any set of more than `max_leaf` references is split, and always by the same split:
/// in a wide node's fill, or as the first split of its own node. So the splits of the tree's large
/// sets can be made ahead, in parallel, without changing the tree or wasting work: the fills then
/// take them from here.
fn presplit(
    set: Set,
    prims: &mut [PrimRef],
    base: usize,
    cfg: &Settings,
    min: usize,
    depth: usize,
) -> Option<Box<Presplit>> {
    // A set `depth` binary splits down lies at most `depth` wide levels down, so above
    // MEDIAN_DEPTH the wide builder would split it by SAH too.
    if set.count < min || depth >= MEDIAN_DEPTH {
        return None;
    }
    let local = Set { start: set.start - base, ..set };
    let split = find_split(&prims[local.start..local.start + local.count], &set.centroids, cfg);
    let (l, r) = split_set(&local, prims, split);
    let (l, r) = (Set { start: l.start + base, ..l }, Set { start: r.start + base, ..r });
    let (lo, hi) = prims[local.start..local.start + local.count].split_at_mut(l.count);
    let (lp, rp) =
        rayon::join(|| presplit(l, lo, l.start, cfg, min, depth + 1), || presplit(r, hi, r.start, cfg, min, depth + 1));
    Some(Box::new(Presplit { split, halves: [(l, lp), (r, rp)] }))
}

/// A child of a wide node being filled: its set (local indices), its split if known, its
/// presplit if it has one.
type Slot = (Set, Option<Option<Split>>, Option<Box<Presplit>>);

/// Builds the subtree of `set` into `out`; returns the reference naming it (relative to `out`)
/// and the cost below it. `prims` is the slice that `set` indexes into, starting at index `base`
/// of the whole reference array; leaf ranges are absolute. `pre` is the set's [`presplit`], if
/// it has one.
fn recurse_at(
    set: Set,
    prims: &mut [PrimRef],
    base: usize,
    cfg: &Settings,
    depth: usize,
    pre: Option<Box<Presplit>>,
    out: &mut Chunk,
) -> (u32, SubtreeCost) {
    let local = Set { start: set.start - base, ..set };
    let mut make_leaf = || (out.leaf(set.start, set.count), SubtreeCost::default());
    if set.count <= cfg.min_leaf {
        return make_leaf();
    }
    let median = depth >= MEDIAN_DEPTH;
    let own_split = match &pre {
        Some(p) => p.split,
        None if median => None,
        None => find_split(&prims[local.start..local.start + local.count], &set.centroids, cfg),
    };
    if set.count <= cfg.max_leaf {
        let area = set.bounds.half_area();
        let leaf_cost = cfg.intersection_cost * blocks(set.count) * area;
        let split_cost = match own_split {
            Some(s) => cfg.traversal_cost * area + cfg.intersection_cost * s.cost,
            None => f32::INFINITY,
        };
        if leaf_cost <= split_cost {
            return make_leaf();
        }
    }

    // Fill a wide node: split the child of largest area until there are WIDTH children.
    // Fixed arrays: vectors here cost three allocations per node.
    let mut children: [Slot; WIDTH] = std::array::from_fn(|_| (local, None, None));
    children[0] = (local, Some(own_split), pre);
    let mut n = 1;
    while n < WIDTH {
        let pick = children[..n]
            .iter()
            .enumerate()
            .filter(|(_, (s, _, _))| s.count > cfg.min_leaf)
            .max_by(|a, b| a.1.0.bounds.half_area().total_cmp(&b.1.0.bounds.half_area()))
            .map(|(i, _)| i);
        let Some(i) = pick else { break };
        let (s, known, pre) = (children[i].0, children[i].1, children[i].2.take());
        let [(l, lp), (r, rp)] = match pre {
            Some(p) => p.halves.map(|(h, hp)| (Set { start: h.start - base, ..h }, hp)),
            None => {
                let split = match known {
                    Some(k) => k,
                    None if median => None,
                    None => find_split(&prims[s.start..s.start + s.count], &s.centroids, cfg),
                };
                let (l, r) = split_set(&s, prims, split);
                [(l, None), (r, None)]
            }
        };
        // The last child takes the split one's slot and the two parts go last (`swap_remove`
        // and two pushes: the same trees as with a vector).
        children.swap(i, n - 1);
        children[n - 1] = (l, None, lp);
        children[n] = (r, None, rp);
        n += 1;
    }
    // Children in reference order, so that the slice can be cut into disjoint pieces.
    let mut order = [0usize; WIDTH];
    for (k, o) in order.iter_mut().enumerate() {
        *o = k;
    }
    let order = &mut order[..n];
    order.sort_unstable_by_key(|&k| children[k].0.start);
    let mut node = Node::default();
    let mut cost = SubtreeCost::default();
    if set.count >= cfg.parallel_threshold {
        // Each child a chunk of its own. This node is its chunk's only node: the chunks of
        // parallel subtrees are made for sets at least this large, and the sets below a
        // sequential node are smaller still.
        debug_assert!(out.nodes.is_empty() && out.leaves.is_empty() && out.kids.is_empty());
        let mut pieces = Vec::with_capacity(n);
        let mut rest = prims;
        let mut offset = 0usize;
        for &k in order.iter() {
            let s = children[k].0;
            let (_, tail) = rest.split_at_mut(s.start - offset);
            let (piece, tail) = tail.split_at_mut(s.count);
            pieces.push((Set { start: s.start + base, ..s }, piece, children[k].2.take()));
            rest = tail;
            offset = s.start + s.count;
        }
        let built: Vec<(Aabb, u32, SubtreeCost, Chunk)> = pieces
            .into_par_iter()
            .map(|(s, piece, pre)| {
                let mut kid = Chunk::default();
                let (r, below) = recurse_at(s, piece, s.start, cfg, depth + 1, pre, &mut kid);
                (s.bounds, r, below, kid)
            })
            .collect();
        let index = out.open();
        for (i, (b, r, below, kid)) in built.into_iter().enumerate() {
            let r = out.attach(kid, r);
            node.set(i, r, b.lo.into(), b.hi.into());
            cost.add_child(&b, r, below);
        }
        return (out.close(index, node), cost);
    }
    let index = out.open();
    let mut rest = prims;
    let mut offset = 0usize;
    for (i, &k) in order.iter().enumerate() {
        let s = children[k].0;
        let (_, tail) = rest.split_at_mut(s.start - offset);
        let (piece, tail) = tail.split_at_mut(s.count);
        let abs = Set { start: s.start + base, ..s };
        let (r, below) = recurse_at(abs, piece, abs.start, cfg, depth + 1, children[k].2.take(), out);
        node.set(i, r, s.bounds.lo.into(), s.bounds.hi.into());
        cost.add_child(&s.bounds, r, below);
        rest = tail;
        offset = s.start + s.count;
    }
    (out.close(index, node), cost)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raygen::Pcg32;

    fn prims_on_line(n: usize) -> Vec<PrimRef> {
        (0..n)
            .map(|i| {
                let x = i as f32;
                PrimRef::new(Aabb { lo: Vec3A::new(x, 0.0, 0.0), hi: Vec3A::new(x + 0.5, 1.0, 1.0) }, i as u32)
            })
            .collect()
    }

    /// A built tree placed into arrays: nodes, leaves, root reference.
    fn placed(t: Built) -> (Vec<Node>, Vec<(usize, usize)>, u32) {
        let mut nodes = vec![Node::default(); t.chunk.size.nodes];
        let mut leaves = vec![(0, 0); t.chunk.size.leaves];
        crate::bvh::place(t.chunk, &mut nodes, &mut leaves, 0, 0);
        (nodes, leaves, t.root)
    }

    /// Checks that every primitive lies inside the boxes above it, that leaves hold what their
    /// references say, and records the primitives met; returns the box of all of them.
    fn check(tree: &(Vec<Node>, Vec<(usize, usize)>, u32), prims: &[PrimRef], seen: &mut Vec<u32>) -> Aabb {
        let (nodes, leaves, root) = tree;
        // The first block of each leaf, in leaf order.
        let firsts: Vec<usize> = leaves
            .iter()
            .scan(0, |b, &(_, count)| {
                let first = *b;
                *b += count.div_ceil(BLOCK);
                Some(first)
            })
            .collect();
        let mut stack = vec![(*root, Aabb { lo: Vec3A::NEG_INFINITY, hi: Vec3A::INFINITY })];
        let mut root_box = Aabb::EMPTY;
        while let Some((r, bounds)) = stack.pop() {
            if is_leaf(r) {
                let (first, n) = leaf_blocks(r);
                let (start, count) = leaves[firsts.binary_search(&first).expect("a leaf's first block")];
                assert!((1..=MAX_LEAF_BLOCKS * BLOCK).contains(&count) && n == count.div_ceil(BLOCK));
                for p in &prims[start..start + count] {
                    let pb = p.bounds();
                    assert!(bounds.lo.cmple(pb.lo).all() && pb.hi.cmple(bounds.hi).all());
                    root_box.grow(&pb);
                    seen.push(p.id());
                }
                continue;
            }
            let node = &nodes[r as usize];
            let used = node.child.iter().filter(|&&c| c != EMPTY).count();
            assert!((2..=WIDTH).contains(&used) && node.child[..used].iter().all(|&c| c != EMPTY));
            for i in 0..used {
                let b = |a: usize| node.bounds[a][i];
                let child = Aabb { lo: Vec3A::new(b(0), b(2), b(4)), hi: Vec3A::new(b(1), b(3), b(5)) };
                stack.push((node.child[i], child));
            }
        }
        root_box
    }

    #[test]
    fn every_primitive_in_exactly_one_leaf_inside_its_bounds() {
        for n in [1, 3, 5, 100, 10_000, 50_000] {
            let mut prims = prims_on_line(n);
            let t = build(&mut prims, &BuildConfig::default()).unwrap();
            let b = t.bounds;
            let mut seen = Vec::new();
            assert_eq!(check(&placed(t), &prims, &mut seen), b);
            seen.sort_unstable();
            assert_eq!(seen, (0..n as u32).collect::<Vec<_>>());
        }
    }

    /// Bins filled one reference at a time, the plain way.
    fn reference_bins(prims: &[PrimRef], nb: usize, offset: Vec3A, scale: Vec3A) -> Bins {
        let mut b = Bins::new(nb);
        let last = Vec3A::splat((nb - 1) as f32);
        for p in prims {
            let i = bin_of(p, offset, scale, last);
            for a in 0..3 {
                b.boxes[0][i[a] as usize][a].grow(&p.bounds());
                b.counts[0][i[a] as usize][a] += 1;
            }
        }
        b
    }

    fn same_bins(x: &Bins, y: &Bins) -> bool {
        (0..x.n).all(|i| x.boxes[0][i] == y.boxes[0][i] && x.counts[0][i] == y.counts[0][i])
    }

    #[test]
    fn binning_in_pairs_and_in_runs_fills_the_same_bins() {
        // Coherent order (along a line, as a mesh's neighbours come) takes the runs; shuffled
        // and odd-sized sets take the alternating copies.
        let mut prims = prims_on_line(3 * RUN_MIN + 3);
        for shuffle in [false, true] {
            if shuffle {
                let mut rng = Pcg32::new(7, 0);
                for i in (1..prims.len()).rev() {
                    prims.swap(i, rng.next_u32() as usize % (i + 1));
                }
            }
            for len in [1, 2, 7, 100, RUN_MIN - 1, RUN_MIN, prims.len()] {
                let set = set_of(&prims[..len], 0);
                let nb = 32;
                let ext = set.centroids.hi - set.centroids.lo;
                let scale = Vec3A::select(ext.cmpgt(Vec3A::ZERO), Vec3A::splat(nb as f32 * 0.99999) / ext, Vec3A::ZERO);
                let want = reference_bins(&prims[..len], nb, set.centroids.lo, scale);
                let mut got = Bins::new(nb);
                bin_into(&mut got, &prims[..len], set.centroids.lo, scale);
                got.settle();
                assert!(same_bins(&got, &want), "bin_into, {len} references, shuffled: {shuffle}");
                let mut runs = Bins::new(nb);
                bin_runs(&mut runs, &prims[..len], set.centroids.lo, scale, Vec3A::splat((nb - 1) as f32));
                assert!(same_bins(&runs, &want), "bin_runs, {len} references, shuffled: {shuffle}");
            }
        }
    }

    #[test]
    fn sweep_finds_the_cheapest_split_over_all_axes() {
        // Random boxes; the vector sweep against one split at a time, scalar.
        let mut rng = Pcg32::new(11, 0);
        let mut rnd = || rng.next_f32();
        for n in [2, 5, 40, 300] {
            let prims: Vec<PrimRef> = (0..n)
                .map(|i| {
                    let lo = Vec3A::new(rnd(), rnd() * 0.5, rnd() * 2.0);
                    PrimRef::new(Aabb { lo, hi: lo + Vec3A::new(rnd(), rnd(), rnd()) * 0.1 }, i)
                })
                .collect();
            let set = set_of(&prims, 0);
            let nb = 16;
            let ext = set.centroids.hi - set.centroids.lo;
            let scale = Vec3A::splat(nb as f32 * 0.99999) / ext;
            let mut bins = Bins::new(nb);
            bin_into(&mut bins, &prims, set.centroids.lo, scale);
            bins.settle();
            let got = sweep(&bins, &set.centroids, scale).unwrap();
            let mut want: Option<(f32, usize, usize)> = None;
            for axis in 0..3 {
                for pos in 1..nb {
                    let (mut l, mut r) = (Aabb::EMPTY, Aabb::EMPTY);
                    let (mut nl, mut nr) = (0, 0);
                    for p in &prims {
                        let bin = ((p.center2() - set.centroids.lo) * scale)[axis] as usize;
                        if bin < pos {
                            l.grow(&p.bounds());
                            nl += 1;
                        } else {
                            r.grow(&p.bounds());
                            nr += 1;
                        }
                    }
                    if nl == 0 || nr == 0 {
                        continue;
                    }
                    let cost = l.half_area() * blocks(nl) + r.half_area() * blocks(nr);
                    if want.is_none_or(|w| cost < w.0) {
                        want = Some((cost, axis, pos));
                    }
                }
            }
            let (cost, axis, pos) = want.unwrap();
            assert_eq!((got.axis, got.pos), (axis, pos), "{n} boxes");
            assert_eq!(got.cost, cost);
        }
    }

    fn same_tree(a: &(Vec<Node>, Vec<(usize, usize)>, u32), b: &(Vec<Node>, Vec<(usize, usize)>, u32)) -> bool {
        a.0.len() == b.0.len()
            && a.0.iter().zip(&b.0).all(|(x, y)| x.bounds == y.bounds && x.child == y.child)
            && a.1 == b.1
            && a.2 == b.2
    }

    #[test]
    fn splits_made_ahead_give_the_same_tree() {
        // Shuffled random boxes, then a block of identical ones (median halving, which presplits
        // must reproduce too).
        let mut rng = Pcg32::new(11, 3);
        let mut r = || rng.next_u32() as f32 / u32::MAX as f32;
        let mut prims: Vec<PrimRef> = (0..20_000)
            .map(|i| {
                let lo = Vec3A::new(r(), r(), r()) * 100.0;
                PrimRef::new(Aabb { lo, hi: lo + Vec3A::new(r(), r(), r()) }, i)
            })
            .collect();
        prims.extend((20_000..23_000).map(|i| PrimRef::new(Aabb { lo: Vec3A::splat(5.0), hi: Vec3A::splat(6.0) }, i)));
        let cfg = Settings::new(&BuildConfig::default(), BinRule::Fine);
        let mut plain = prims.clone();
        let plain_tree = build_presplit(&mut plain, &cfg, usize::MAX);
        let (pb, plain_tree) = (plain_tree.bounds, placed(plain_tree));
        for min in [0, 100, 4096] {
            let mut ahead = prims.clone();
            let tree = build_presplit(&mut ahead, &cfg, min);
            let (ab, tree) = (tree.bounds, placed(tree));
            assert_eq!(pb, ab);
            assert!(same_tree(&plain_tree, &tree), "presplit from {min}");
            assert!(plain.iter().zip(&ahead).all(|(x, y)| x.id() == y.id()), "reference order, presplit from {min}");
        }
    }

    #[test]
    fn both_partitions_split_by_the_side_and_bound_both_sides() {
        let mut rng = Pcg32::new(5, 1);
        let mut r = || rng.next_u32() as f32 / u32::MAX as f32;
        let random: Vec<PrimRef> = (0..5000)
            .map(|i| {
                let lo = Vec3A::new(r(), r(), r()) * 10.0;
                PrimRef::new(Aabb { lo, hi: lo + Vec3A::new(r(), r(), r()) }, i)
            })
            .collect();
        // Random sides (the block partition), long runs (Hoare's), and sets on one side only.
        for prims in [random.clone(), prims_on_line(5000)] {
            for len in [1, 2, 100, 129, 200, 1000, 5000] {
                let set = set_of(&prims[..len], 0);
                let cfg = Settings::new(&BuildConfig::default(), BinRule::Fine);
                let Some(split) = find_split(&prims[..len], &set.centroids, &cfg) else { continue };
                for split in [split, Split { pos: 0, ..split }, Split { pos: 1000, ..split }] {
                    for blocks in [false, true] {
                        let mut p = prims[..len].to_vec();
                        let (mid, sides) = if blocks && len > 2 * PART_BLOCK {
                            let mid = partition_blocks(&mut p, &split);
                            (mid, [bounds_of(&p[..mid]), bounds_of(&p[mid..])])
                        } else {
                            partition(&mut p, &split)
                        };
                        assert!(p[..mid].iter().all(|q| goes_left(q.center2(), &split)));
                        assert!(p[mid..].iter().all(|q| !goes_left(q.center2(), &split)));
                        let sorted = |v: &[PrimRef]| {
                            let mut ids: Vec<u32> = v.iter().map(|q| q.id()).collect();
                            ids.sort_unstable();
                            ids
                        };
                        assert_eq!(sorted(&p), sorted(&prims[..len]));
                        for (side, part) in [(sides[0], &p[..mid]), (sides[1], &p[mid..])] {
                            // One reference at a time, the plain way.
                            let (mut b, mut c) = (Aabb::EMPTY, Aabb::EMPTY);
                            for q in part {
                                b.grow(&q.bounds());
                                c.grow_point(q.center2());
                            }
                            assert_eq!(side, (b, c), "len {len}, blocks {blocks}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn identical_centroids_still_split() {
        let mut prims: Vec<PrimRef> =
            (0..1000).map(|i| PrimRef::new(Aabb { lo: Vec3A::ZERO, hi: Vec3A::ONE }, i)).collect();
        let t = build(&mut prims, &BuildConfig::default()).unwrap();
        let mut seen = Vec::new();
        check(&placed(t), &prims, &mut seen);
        assert_eq!(seen.len(), 1000);
    }

    #[test]
    fn small_builds_keep_the_cheaper_of_the_two_bin_rules_trees() {
        // Random boxes, some long and thin as walls: each rule's tree is the cheaper one for some
        // of these sets, and the build keeps that one, whole and in its bounds.
        let mut rng = Pcg32::new(9, 3);
        let mut r = || rng.next_u32() as f32 / u32::MAX as f32;
        let (mut coarse_won, mut fine_won) = (0, 0);
        for set in 0..300 {
            let n = 8 + set % (SMALL_BUILD - 7);
            let prims: Vec<PrimRef> = (0..n as u32)
                .map(|i| {
                    let lo = Vec3A::new(r(), r(), r()) * 10.0;
                    let long = Vec3A::new(r(), r(), r()).cmpgt(Vec3A::splat(0.7));
                    let ext = Vec3A::select(long, Vec3A::splat(10.0 * r()), Vec3A::new(r(), r(), r()));
                    PrimRef::new(Aabb { lo, hi: lo + ext }, i)
                })
                .collect();
            let cfg = BuildConfig::default();
            let fine = build_with_rule(&mut prims.clone(), &cfg, BinRule::Fine).cost.sah;
            let coarse = build_with_rule(&mut prims.clone(), &cfg, BinRule::Coarse).cost.sah;
            let mut kept = prims.clone();
            let t = build(&mut kept, &cfg).unwrap();
            assert_eq!(t.cost.sah, fine.min(coarse), "set {set}");
            coarse_won += usize::from(coarse < fine);
            fine_won += usize::from(fine < coarse);
            let mut seen = Vec::new();
            check(&placed(t), &kept, &mut seen);
            seen.sort_unstable();
            assert_eq!(seen, (0..n as u32).collect::<Vec<_>>(), "set {set}");
        }
        assert!(coarse_won > 0 && fine_won > 0, "coarse cheaper {coarse_won} times, fine {fine_won}");
    }
}
