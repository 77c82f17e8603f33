//! The bounding volume hierarchy: built from boxes and centroids ([`build`]), flattened into wide
//! nodes (`node`) whose leaves reference SoA triangle blocks, traversed by single rays, packets and
//! streams (`traverse`, `stream`).

pub mod build;
pub(crate) mod group;
pub(crate) mod node;
mod spatial;
pub(crate) mod stream;
pub(crate) mod traverse;

use std::time::Instant;

use glam::{Vec3, Vec3A};
use rayon::prelude::*;

pub use build::BuildConfig;
use build::{Aabb, Chunk, PrimRef, SubtreeCost, rebase};
use node::{EMPTY, MAX_BLOCK_INDEX, Node};
pub use traverse::BoxTest;

use crate::error::{Error, Result};
use crate::geometry::TriangleMesh;
use crate::geometry::triangle::{BADOUEL_MAX_GEOMETRIES, BLOCK, TriBlock, TriangleTest};

/// Figures the builder reports.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildStats {
    /// Wall time of the build, from meshes to the flat node and block arrays, its statistics and
    /// the release of its temporaries included.
    pub build_ms: f64,
    /// Triangles in the BVH (the hittable ones).
    pub triangles: usize,
    /// Analytic shapes (spheres) in the tree: a sphere tree's count (its `triangles` are 0).
    pub shapes: usize,
    /// Triangles left out: NaN/infinite corners or zero area. They can never be hit.
    pub skipped_triangles: usize,
    /// Inner nodes of the tree.
    pub inner_nodes: usize,
    /// Leaves of the tree.
    pub leaves: usize,
    /// Triangle blocks (of 4 lanes) in the leaves.
    pub blocks: usize,
    /// Triangle references in leaves: `triangles`, plus the copies spatial splits made.
    pub references: usize,
    /// SAH cost computed as Embree's `BVHNStatistics` does: every inner node costs its half area,
    /// every leaf block its leaf's half area, all relative to the root's half area.
    pub sah: f64,
    /// Bytes of nodes plus triangle blocks.
    pub bytes: usize,
    /// `bytes` per hittable triangle.
    pub bytes_per_triangle: f64,
    /// Wide levels from the root to the deepest leaf.
    pub depth: usize,
}

/// Tree size (nodes and blocks) above which a tree counts as out of the cache: 32 MiB. This is a
/// measured crossover, between the sphereflake's 295k triangles (18 MB) and 1M (62 MB), on a
/// 2-core VM with 4 MiB of L2 per core and an L3 it reports as 480 MiB (PERFORMANCE.md); it is
/// also the L3 size of the Zen 5 part the project targets. Such trees prefetch the children their walks
/// enter, and their incoherent streams are traced differently (see
/// [`Query::out_of_cache`](crate::Query::out_of_cache)).
pub(crate) const FAR_MEMORY_BYTES: usize = 32 << 20;

/// The same threshold for the objects of a two-level scene, over all objects together: each
/// instance enters its object from another side, so the rays of one view touch the whole object
/// where a flat tree of that size is touched only where the view sees it. Measured on the big
/// world (one 27 MB object), one thread: prefetching walks gained 5–10% on shadow rays and 5–12% on
/// camera packets and diffuse rays (PERFORMANCE.md); the flat 27 MB sphereflake gained 2–3% on streams and lost
/// 3% on single rays, so flat trees keep [`FAR_MEMORY_BYTES`].
pub(crate) const INSTANCED_FAR_MEMORY_BYTES: usize = 16 << 20;

/// A built BVH over triangle meshes.
#[derive(Clone, Debug)]
pub(crate) struct Bvh {
    pub nodes: Vec<Node>,
    pub blocks: Vec<TriBlock>,
    pub root: u32,
    pub bounds: Option<(Vec3, Vec3)>,
    pub test: TriangleTest,
    pub box_test: BoxTest,
    pub stats: BuildStats,
    /// Whether the walks prefetch the inner children they enter: trees out of the cache
    /// ([`FAR_MEMORY_BYTES`]; a two-level scene sets it for its objects).
    pub prefetch: bool,
}

impl Bvh {
    /// Whether the tree is larger than [`FAR_MEMORY_BYTES`].
    #[inline]
    pub(crate) fn out_of_cache(&self) -> bool {
        self.stats.bytes > FAR_MEMORY_BYTES
    }

    /// Builds over every hittable triangle of `meshes` on the current rayon pool.
    pub fn build(meshes: &[TriangleMesh], cfg: &BuildConfig) -> Result<Bvh> {
        // Timed around the whole build, its statistics and the release of its temporaries (the
        // builder's chunks and reference array): all of it is the caller's wait, as Embree's
        // `rtcCommitScene` includes its own clean-up.
        let start = Instant::now();
        // A build too small to run in parallel stays on the calling thread: handing it to the
        // pool from outside would cost two thread switches, more than the whole build.
        let total: usize = meshes.iter().map(|m| m.triangle_count()).sum();
        let mut bvh = if total < cfg.parallel_threshold {
            Self::build_untimed(meshes, cfg)?
        } else {
            on_pool(|| Self::build_untimed(meshes, cfg))?
        };
        bvh.stats.build_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(bvh)
    }

    /// [`build`](Self::build) without its `build_ms`.
    fn build_untimed(meshes: &[TriangleMesh], cfg: &BuildConfig) -> Result<Bvh> {
        let max_geometries =
            if cfg.triangle_test == TriangleTest::Badouel { BADOUEL_MAX_GEOMETRIES } else { u32::MAX as usize };
        if meshes.len() >= max_geometries {
            return Err(Error::TooManyGeometries(meshes.len()));
        }
        // Primitive references: (geometry, triangle) pairs packed into one global id.
        let offsets: Vec<usize> = meshes
            .iter()
            .scan(0usize, |acc, m| {
                let o = *acc;
                *acc += m.triangle_count();
                Some(o)
            })
            .collect();
        let total: usize = meshes.iter().map(|m| m.triangle_count()).sum();
        if total >= u32::MAX as usize {
            return Err(Error::TooManyTriangles(total));
        }
        // Work items of at most 16k triangles, so that single-mesh scenes are spread over threads
        // too; small scenes stay on the calling thread (waking the pool costs more than they do).
        const PRIM_CHUNK: usize = 16 * 1024;
        let items: Vec<(usize, usize, usize)> = meshes
            .iter()
            .enumerate()
            .flat_map(|(g, m)| {
                (0..m.triangle_count())
                    .step_by(PRIM_CHUNK)
                    .map(move |s| (g, s, (s + PRIM_CHUNK).min(m.triangle_count())))
            })
            .collect();
        // One slot per triangle: each item fills its own range (its hittable triangles'
        // references first), in parallel for large scenes, and the gaps are closed after. A
        // `flat_map_iter` collect grew a vector per job and then copied them all into one: more
        // memory churn, after which repeated builds of the forest's objects faulted in 858 fresh
        // pages per build instead of 29 (PERFORMANCE.md).
        let parallel = total >= cfg.parallel_threshold;
        let empty = PrimRef::new(Aabb::EMPTY, 0);
        let mut slots: Vec<PrimRef> = Vec::with_capacity(total);
        if parallel {
            slots.par_extend((0..total).into_par_iter().map(|_| empty));
        } else {
            slots.resize(total, empty);
        }
        let mut rest = slots.as_mut_slice();
        let mut jobs = Vec::with_capacity(items.len());
        for item in &items {
            let (mine, tail) = std::mem::take(&mut rest).split_at_mut(item.2 - item.1);
            jobs.push((item, mine));
            rest = tail;
        }
        let fill = |(&(g, s, e), out): (&(usize, usize, usize), &mut [PrimRef])| {
            build::write_refs(&meshes[g], offsets[g], s..e, out)
        };
        let counts: Vec<usize> =
            if parallel { jobs.into_par_iter().map(fill).collect() } else { jobs.into_iter().map(fill).collect() };
        let mut end = 0;
        let mut start = 0;
        for (item, n) in items.iter().zip(&counts) {
            if start != end {
                slots.copy_within(start..start + n, end);
            }
            end += n;
            start += item.2 - item.1;
        }
        slots.truncate(end);
        let mut prims = slots;
        let skipped = total - prims.len();
        if prims.len().div_ceil(BLOCK) > MAX_BLOCK_INDEX {
            return Err(Error::TooManyTriangles(total));
        }
        let unique = prims.len();
        // A global primitive id as (mesh, triangle within it).
        let locate = |id: usize| {
            let g = offsets.partition_point(|&o| o <= id) - 1;
            (g, id - offsets[g])
        };
        let tree = if cfg.split_factor > 1.0 {
            // Spatial splits need the corners, and return their own reference array.
            let corners = |id: u32| {
                let (g, local) = locate(id as usize);
                meshes[g].triangle(local).map(Vec3A::from)
            };
            spatial::build(std::mem::take(&mut prims), &corners, cfg).map(|(built, refs)| {
                prims = refs;
                built
            })
        } else {
            build::build(&mut prims, cfg)
        };

        // The builder laid its tree out in chunks (one per subtree built in parallel): copy them
        // into arrays of the tree's final size, large ones in parallel; then the triangle blocks of
        // all leaves in parallel (each gathers scattered vertices, the costly part). An indexed
        // collect writes the blocks straight into their vector: igea's blocks took 7–12 ms
        // through per-leaf iterators and 3–5 ms this way.
        let size = tree.as_ref().map(|t| t.chunk.size).unwrap_or_default();
        // At least one block per four references, spatial splits' extra references included.
        if size.blocks > MAX_BLOCK_INDEX {
            return Err(Error::TooManyTriangles(total));
        }
        let PlacedTree { nodes, leaves, root, bounds, cost } = place_tree(tree, parallel);
        // One entry per block, `(first primitive, primitives)`, so that the blocks are filled by an
        // indexed parallel collect straight into their final vector.
        let sources: Vec<(usize, usize)> = leaves
            .iter()
            .flat_map(|&(start, count)| {
                (start..start + count).step_by(BLOCK).map(move |s| (s, (start + count - s).min(BLOCK)))
            })
            .collect();
        // Each triangle's corners sit behind its index triple, both scattered: with the loads of
        // one block waiting on each other, the fill ran at memory latency. So the blocks ahead
        // are asked for early: the index triples two blocks ahead, the corners one block ahead
        // (whose triples the previous block asked for). Bunny on a Zen 4: the fill took 1.73
        // instead of 2.33 ms at SSE2, 1.50 instead of 1.64 ms at AVX-512 (PERFORMANCE.md).
        let make_block = |i: usize| {
            let (start, n) = sources[i];
            if let Some(&(s, n)) = sources.get(i + 2) {
                for p in &prims[s..s + n] {
                    let (g, local) = locate(p.id() as usize);
                    crate::simd::prefetch(&meshes[g].indices()[local]);
                }
            }
            if let Some(&(s, n)) = sources.get(i + 1) {
                for p in &prims[s..s + n] {
                    let (g, local) = locate(p.id() as usize);
                    let (mesh, [a, b, c]) = (&meshes[g], meshes[g].indices()[local]);
                    for v in [a, b, c] {
                        crate::simd::prefetch(&mesh.positions()[v as usize]);
                    }
                }
            }
            let mut block = TriBlock::EMPTY;
            for (lane, p) in prims[start..start + n].iter().enumerate() {
                let (g, local) = locate(p.id() as usize);
                block.set_lane(cfg.triangle_test, lane, g as u32, local as u32, meshes[g].triangle(local));
            }
            block
        };
        let mut blocks: Vec<TriBlock> = crate::sys::huge_vec(sources.len());
        if parallel {
            blocks.par_extend((0..sources.len()).into_par_iter().with_min_len(256).map(make_block));
        } else {
            blocks.extend((0..sources.len()).map(make_block));
        }
        let mut bvh = Bvh {
            nodes,
            blocks,
            root,
            bounds,
            test: cfg.triangle_test,
            box_test: cfg.box_test,
            stats: BuildStats::default(),
            prefetch: false,
        };
        bvh.stats = bvh.compute_stats(cost, leaves.len(), unique, skipped);
        bvh.stats.references = prims.len();
        bvh.prefetch = bvh.out_of_cache();
        Ok(bvh)
    }

    fn compute_stats(&self, cost: SubtreeCost, leaves: usize, triangles: usize, skipped: usize) -> BuildStats {
        let bytes = self.nodes.len() * size_of::<Node>() + self.blocks.len() * size_of::<TriBlock>();
        let root_area = self.bounds.map_or(0.0, |(lo, hi)| Aabb { lo: lo.into(), hi: hi.into() }.half_area() as f64);
        BuildStats {
            triangles,
            skipped_triangles: skipped,
            inner_nodes: self.nodes.len(),
            leaves,
            blocks: self.blocks.len(),
            sah: if root_area > 0.0 { cost.sah / root_area } else { cost.sah },
            bytes,
            bytes_per_triangle: if triangles > 0 { bytes as f64 / triangles as f64 } else { 0.0 },
            depth: cost.depth,
            ..Default::default()
        }
    }
}

/// A built tree copied into its final node array: the nodes, each leaf's `(first reference,
/// references)` in leaf order (leaf `i` references blocks numbered from the blocks of the leaves
/// before it), the root, its bounds and the tree's cost.
pub(crate) struct PlacedTree {
    pub nodes: Vec<Node>,
    pub leaves: Vec<(usize, usize)>,
    pub root: u32,
    pub bounds: Option<(Vec3, Vec3)>,
    pub cost: SubtreeCost,
}

/// Copies the builder's chunks into arrays of the tree's final size, large trees in parallel
/// (`parallel` and at least [`PLACE_PARALLEL_NODES`] nodes), so that the blocks of all leaves can
/// be filled after, by whatever primitive the leaves hold.
pub(crate) fn place_tree(tree: Option<build::Built>, parallel: bool) -> PlacedTree {
    let size = tree.as_ref().map(|t| t.chunk.size).unwrap_or_default();
    // Nodes and blocks on transparent huge pages where the OS grants them (`crate::sys`).
    let mut nodes: Vec<Node> = crate::sys::huge_vec(size.nodes);
    // Small trees are appended in one pass; large ones copied in parallel into arrays of
    // default values (their freshly mapped pages fault on both threads).
    let big = parallel && size.nodes >= PLACE_PARALLEL_NODES;
    let mut leaves: Vec<(usize, usize)> = if big {
        rayon::join(
            || nodes.par_extend((0..size.nodes).into_par_iter().map(|_| Node::default())),
            || (0..size.leaves).into_par_iter().map(|_| (0, 0)).collect(),
        )
        .1
    } else {
        Vec::with_capacity(size.leaves)
    };
    let (root, bounds, cost) = match tree {
        None => (EMPTY, None, SubtreeCost::default()),
        Some(t) => {
            if big {
                place(t.chunk, &mut nodes, &mut leaves, 0, 0);
            } else {
                append(t.chunk, &mut nodes, &mut leaves, 0);
            }
            (t.root, Some((Vec3::from(t.bounds.lo), Vec3::from(t.bounds.hi))), t.cost)
        }
    };
    PlacedTree { nodes, leaves, root, bounds, cost }
}

/// Runs `f` on a thread of the current rayon pool. A build has several parallel stages; each one
/// entered from a thread outside the pool is a job handed to the pool and a sleep until it is
/// done (two thread switches each; the 6k-triangle teapot built from the main thread spent 13% of
/// its time in the kernel's wake-ups), while inside the pool the stages are plain work-stealing
/// jobs. So the whole build enters the pool once.
pub(crate) fn on_pool<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    if rayon::current_thread_index().is_some() { f() } else { rayon::scope(|_| f()) }
}

/// Trees of at least this many nodes are placed in parallel ([`place`]), smaller ones appended
/// ([`append`]): bunny (5k nodes), 2 threads: appended 0.15 ms against 0.6 before chunks (a
/// parallel layout of the builder's node tree); igea (20k) and the sphereflake (36k) the same
/// either way.
const PLACE_PARALLEL_NODES: usize = 16 * 1024;

/// `n` from a chunk placed `node_base` nodes and `block_base` blocks into the arrays.
fn rebased(n: &Node, node_base: usize, block_base: usize) -> Node {
    Node { child: n.child.map(|c| rebase(c, node_base, block_base)), ..*n }
}

/// Appends `chunk` and its kids to `nodes` and `leaves`, the chunk's first block being block
/// `block_base`.
fn append(chunk: Chunk, nodes: &mut Vec<Node>, leaves: &mut Vec<(usize, usize)>, block_base: usize) {
    let node_base = nodes.len();
    nodes.extend(chunk.nodes.iter().map(|n| rebased(n, node_base, block_base)));
    leaves.extend_from_slice(&chunk.leaves);
    let mut bb = block_base + chunk.own_blocks;
    for kid in chunk.kids {
        let blocks = kid.size.blocks;
        append(kid, nodes, leaves, bb);
        bb += blocks;
    }
}

/// Copies `chunk` and its kids into `nodes` and `leaves` (exactly their size), the chunk's
/// first node being node `node_base` of the whole array and its first block `block_base`: its
/// own nodes and leaves first, then each kid's, kids in parallel (they were built in parallel, so
/// each is large).
pub(crate) fn place(
    chunk: Chunk,
    nodes: &mut [Node],
    leaves: &mut [(usize, usize)],
    node_base: usize,
    block_base: usize,
) {
    let (own, rest) = nodes.split_at_mut(chunk.nodes.len());
    for (dst, src) in own.iter_mut().zip(&chunk.nodes) {
        *dst = rebased(src, node_base, block_base);
    }
    let (own_leaves, rest_leaves) = leaves.split_at_mut(chunk.leaves.len());
    own_leaves.copy_from_slice(&chunk.leaves);
    if chunk.kids.is_empty() {
        return;
    }
    let (mut rest, mut rest_leaves) = (rest, rest_leaves);
    let (mut nb, mut bb) = (node_base + chunk.nodes.len(), block_base + chunk.own_blocks);
    let jobs: Vec<_> = chunk
        .kids
        .into_iter()
        .map(|kid| {
            let (n, tail) = std::mem::take(&mut rest).split_at_mut(kid.size.nodes);
            let (l, ltail) = std::mem::take(&mut rest_leaves).split_at_mut(kid.size.leaves);
            (rest, rest_leaves) = (tail, ltail);
            let job = (n, l, nb, bb);
            (nb, bb) = (nb + kid.size.nodes, bb + kid.size.blocks);
            (kid, job)
        })
        .collect();
    jobs.into_par_iter().for_each(|(kid, (n, l, nb, bb))| place(kid, n, l, nb, bb));
}

#[cfg(test)]
mod tests {
    use super::node::{is_leaf, leaf_blocks};
    use super::*;
    use crate::procedural;

    /// Walks the flat tree from the root: returns, in depth-first order, the inner nodes reached
    /// and the block ranges of the leaves.
    fn walk(bvh: &Bvh) -> (Vec<u32>, Vec<(usize, usize)>) {
        let (mut inner, mut blocks) = (Vec::new(), Vec::new());
        let mut stack = vec![bvh.root];
        while let Some(r) = stack.pop() {
            if is_leaf(r) {
                blocks.push(leaf_blocks(r));
                continue;
            }
            inner.push(r);
            let n = &bvh.nodes[r as usize];
            stack.extend(n.child.iter().rev().copied().filter(|&c| c != EMPTY));
        }
        (inner, blocks)
    }

    #[test]
    fn parallel_references_skip_unhittable_triangles_in_every_work_item() {
        // Three meshes, one of them 40,000 triangles long (three work items), with degenerate
        // and NaN triangles scattered, first and last included, so that gaps open in every item
        // and are closed across them.
        let big = procedural::uv_sphere(Vec3::ZERO, 1.0, 100, 201);
        let small = procedural::sphereflake(1, 6, 12);
        let mut meshes = Vec::new();
        let mut unhittable = std::collections::HashSet::new();
        for (g, m) in [&small, &big, &small].into_iter().enumerate() {
            let mut positions = m.positions().to_vec();
            positions.push(Vec3::NAN);
            let nan = positions.len() as u32 - 1;
            let mut indices = m.indices().to_vec();
            let n = indices.len();
            for i in (0..n).step_by(997).chain([n - 1]) {
                indices[i] = if i % 2 == 0 { [indices[i][0]; 3] } else { [indices[i][0], indices[i][1], nan] };
                unhittable.insert((g as u32, i as u32));
            }
            meshes.push(TriangleMesh::new(format!("m{g}"), positions, indices).unwrap());
        }
        let total: usize = meshes.iter().map(|m| m.triangle_count()).sum();
        assert!(big.triangle_count() > 2 * 16 * 1024);
        let bvh = Bvh::build(&meshes, &BuildConfig::default()).unwrap();
        assert_eq!(bvh.stats.skipped_triangles, unhittable.len());
        let mut found: Vec<(u32, u32)> = bvh
            .blocks
            .iter()
            .flat_map(|b| b.geom.iter().zip(&b.prim).map(|(&g, &p)| (g, p)).filter(|&(_, p)| p != u32::MAX))
            .collect();
        found.sort_unstable();
        let mut want: Vec<(u32, u32)> = meshes
            .iter()
            .enumerate()
            .flat_map(|(g, m)| (0..m.triangle_count() as u32).map(move |p| (g as u32, p)))
            .filter(|k| !unhittable.contains(k))
            .collect();
        want.sort_unstable();
        assert_eq!(found.len(), total - unhittable.len());
        assert_eq!(found, want);
    }

    #[test]
    fn chunks_placed_in_parallel_and_appended_give_the_same_arrays() {
        let mesh = procedural::sphereflake(2, 6, 12);
        let mut prims: Vec<PrimRef> = (0..mesh.triangle_count())
            .map(|i| {
                let [a, b, c] = mesh.triangle(i).map(Vec3A::from);
                PrimRef::new(Aabb { lo: a.min(b).min(c), hi: a.max(b).max(c) }, i as u32)
            })
            .collect();
        let cfg = BuildConfig { parallel_threshold: 256, ..BuildConfig::default() };
        let mut same = prims.clone();
        let built = build::build(&mut prims, &cfg).unwrap();
        assert!(!built.chunk.kids.is_empty() && built.chunk.kids.iter().any(|k| !k.kids.is_empty()));
        let again = build::build(&mut same, &cfg).unwrap();
        let size = built.chunk.size;
        let (mut nodes, mut leaves) = (vec![Node::default(); size.nodes], vec![(0, 0); size.leaves]);
        place(built.chunk, &mut nodes, &mut leaves, 0, 0);
        let (mut appended, mut appended_leaves) = (Vec::new(), Vec::new());
        append(again.chunk, &mut appended, &mut appended_leaves, 0);
        assert_eq!(leaves, appended_leaves);
        assert!(nodes.iter().zip(&appended).all(|(x, y)| x.bounds == y.bounds && x.child == y.child));
        assert_eq!(nodes.len(), appended.len());
    }

    #[test]
    fn flat_layout_is_depth_first_and_complete_in_parallel_and_serially() {
        // 10,920 triangles: above the parallel threshold, so that the builder's chunks have kids.
        let mesh = procedural::sphereflake(2, 6, 12);
        for parallel_threshold in [1024, usize::MAX / 2] {
            let cfg = BuildConfig { parallel_threshold, ..BuildConfig::default() };
            let bvh = Bvh::build(std::slice::from_ref(&mesh), &cfg).unwrap();
            let (inner, blocks) = walk(&bvh);
            // Depth-first preorder: the walk meets node i as the i-th inner node.
            assert_eq!(inner, (0..bvh.nodes.len() as u32).collect::<Vec<_>>(), "threshold {parallel_threshold}");
            // Leaves take consecutive block ranges in the same order, covering every block once.
            let mut next = 0;
            for (start, count) in blocks {
                assert_eq!(start, next);
                next += count;
            }
            assert_eq!(next, bvh.blocks.len());
            let mut prims: Vec<u32> =
                bvh.blocks.iter().flat_map(|b| b.prim.iter().copied().filter(|&p| p != u32::MAX)).collect();
            prims.sort_unstable();
            assert_eq!(prims, (0..mesh.triangle_count() as u32).collect::<Vec<_>>());
        }
    }
}
