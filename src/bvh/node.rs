//! Wide BVH node layout: [`WIDTH`] children per node with their bounds in SoA form, so one node is
//! tested against a ray with one SIMD slab test (Embree's `AABBNode_t` with N = 8).

/// Children per node (N in Embree's naming).
pub(crate) const WIDTH: usize = 8;

/// A child slot that holds nothing; its bounds are inverted so that no ray ever enters it.
pub(crate) const EMPTY: u32 = u32::MAX;
const LEAF_BIT: u32 = 1 << 31;
const COUNT_SHIFT: u32 = 27;
/// Largest number of triangle blocks one leaf can reference.
pub(crate) const MAX_LEAF_BLOCKS: usize = 15;
/// Largest triangle block index a leaf can reference.
pub(crate) const MAX_BLOCK_INDEX: usize = (1 << COUNT_SHIFT) - 1;

/// One node: bounds of its children as `[lo_x, hi_x, lo_y, hi_y, lo_z, hi_z]` rows of [`WIDTH`]
/// lanes, and a child reference per lane. Used slots come first; the rest are [`EMPTY`].
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(crate) struct Node {
    pub bounds: [[f32; WIDTH]; 6],
    pub child: [u32; WIDTH],
}

impl Default for Node {
    fn default() -> Self {
        let inv = [f32::INFINITY; WIDTH];
        let neg = [f32::NEG_INFINITY; WIDTH];
        Self { bounds: [inv, neg, inv, neg, inv, neg], child: [EMPTY; WIDTH] }
    }
}

impl Node {
    /// Sets slot `i` to `child` with bounds `lo..hi`.
    pub fn set(&mut self, i: usize, child: u32, lo: [f32; 3], hi: [f32; 3]) {
        // `-0.0` becomes `+0.0` (`x + 0.0`): the single-ray slab test's integer minimum treats
        // `-0.0` as the smallest value, and a `-0.0` bound (an OBJ's "-0.000000") could make it
        // one (see `BitOrder`).
        for a in 0..3 {
            self.bounds[2 * a][i] = lo[a] + 0.0;
            self.bounds[2 * a + 1][i] = hi[a] + 0.0;
        }
        self.child[i] = child;
    }
}

/// A child reference to a leaf: `count` blocks (1..=[`MAX_LEAF_BLOCKS`]) starting at `start`.
#[inline]
pub(crate) fn leaf_ref(start: usize, count: usize) -> u32 {
    debug_assert!((1..=MAX_LEAF_BLOCKS).contains(&count) && start <= MAX_BLOCK_INDEX);
    LEAF_BIT | ((count as u32 - 1) << COUNT_SHIFT) | start as u32
}

/// Whether a (non-empty) child reference names a leaf.
#[inline(always)]
pub(crate) fn is_leaf(r: u32) -> bool {
    r & LEAF_BIT != 0
}

/// The block range `start..start + count` of a leaf reference.
#[inline(always)]
pub(crate) fn leaf_blocks(r: u32) -> (usize, usize) {
    let start = (r & ((1 << COUNT_SHIFT) - 1)) as usize;
    let count = ((r >> COUNT_SHIFT) & 0xf) as usize + 1;
    (start, count)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leaf_refs_round_trip() {
        for (s, c) in [(0, 1), (12345, 15), (MAX_BLOCK_INDEX, 7)] {
            let r = leaf_ref(s, c);
            assert!(is_leaf(r) && r != EMPTY);
            assert_eq!(leaf_blocks(r), (s, c));
        }
        assert!(!is_leaf(42));
    }
}
