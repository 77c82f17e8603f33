//! Occlusion streams: up to [`STREAM_RAYS`] rays of one direction octant walk the tree together
//! (Embree's `BVHNIntersectorStream::occludedIncoherent`). Each node is loaded once for every ray
//! that entered it and tested against them one after another with the single-ray slab test; its
//! children carry the mask of rays that entered them; a leaf is tested by each of its rays alone,
//! and a ray leaves the walk once it is occluded. Per ray and node this costs a short run of
//! independent vector operations instead of a single-ray walk's chain of dependent loads and
//! branches, and one fetch of a node serves all rays that reach it.

use glam::Vec3;

use super::Bvh;
use super::node::{EMPTY, WIDTH, is_leaf, leaf_blocks};
use super::traverse::{BoxTest, FAR_WIDEN, SlabTerms, Stack, dispatch, with_stack};
use crate::geometry::badouel::Badouel;
use crate::geometry::moeller::Moller;
use crate::geometry::triangle::TriangleTest;
use crate::geometry::triangle::{Kernel, Ray4};
use crate::geometry::watertight::Watertight;
use crate::ray::{Ray, RayStream};
use crate::simd::*;

/// Rays per occlusion stream: one bit each in the child masks (Embree's `MAX_INTERNAL_STREAM_SIZE`).
pub(crate) const STREAM_RAYS: usize = 32;

/// The slab-test terms of a stream's rays, one array per term, indexed by ray.
struct StreamRays {
    rd: [[f32; STREAM_RAYS]; 3],
    od: [[f32; STREAM_RAYS]; 3],
    /// The conservative test's pad (see [`SlabTerms`]).
    pad: [f32; STREAM_RAYS],
    tnear: [f32; STREAM_RAYS],
    /// The far distance the slab test compares with (widened for the conservative test).
    tfar_box: [f32; STREAM_RAYS],
}

impl Bvh {
    /// [`occluded_stream`](Self::occluded_stream) with this tree's kernels, on this thread's stack.
    pub(crate) fn occluded_octant(&self, rays: &RayStream, base: usize, ids: &[u16], octant: u32) -> u32 {
        with_stack(|stack| {
            dispatch!(self.test, self.box_test, |K, C| with_level!(
                |L| self.occluded_stream::<K, C, L>(rays, base, ids, octant, stack)
            ))
        })
    }

    /// Occlusion of the rays `base + ids[i]` of `rays` (the first [`STREAM_RAYS`] of `ids`; any
    /// beyond are not traced and their bits stay clear), which should share
    /// the direction octant `octant` (bit `a` set: the sign bit of component `a` is set, as in
    /// [`octant_of`]); a ray outside it is walked alone. Returns bit `i` set where ray `i` is
    /// occluded. Invalid rays are not occluded.
    #[inline(never)]
    pub(crate) fn occluded_stream<K: Kernel, const CONS: bool, L: Level>(
        &self,
        rays: &RayStream,
        base: usize,
        ids: &[u16],
        octant: u32,
        stack: &mut Stack,
    ) -> u32 {
        L::call(
            #[inline(always)]
            || self.occluded_stream_in::<K, CONS, L>(rays, base, ids, octant, stack),
        )
    }

    /// [`occluded_stream`](Self::occluded_stream)'s body, compiled for the level.
    #[inline(always)]
    fn occluded_stream_in<K: Kernel, const CONS: bool, L: Level>(
        &self,
        rays: &RayStream,
        base: usize,
        ids: &[u16],
        octant: u32,
        stack: &mut Stack,
    ) -> u32 {
        if self.root == EMPTY {
            return 0;
        }
        let n = ids.len().min(STREAM_RAYS);
        let mut sr = StreamRays {
            rd: [[0.0; STREAM_RAYS]; 3],
            od: [[0.0; STREAM_RAYS]; 3],
            pad: [0.0; STREAM_RAYS],
            tnear: [0.0; STREAM_RAYS],
            tfar_box: [0.0; STREAM_RAYS],
        };
        let mut r4 = [Ray4::<L>::new(Vec3::ZERO, Vec3::X); STREAM_RAYS];
        let mut tfar = [0.0f32; STREAM_RAYS];
        let mut active = 0u32;
        // Rays walked alone and found occluded.
        let mut alone = 0u32;
        for (i, &id) in ids[..n].iter().enumerate() {
            let k = base + id as usize;
            let ray = Ray {
                origin: Vec3::new(rays.ox[k], rays.oy[k], rays.oz[k]),
                dir: Vec3::new(rays.dx[k], rays.dy[k], rays.dz[k]),
                tnear: rays.tnear[k],
                tfar: rays.tfar[k],
            };
            if !ray.is_valid() {
                continue;
            }
            let ray = ray.clamped_to_zero();
            if octant_of(&ray) != octant {
                if self.trace1_with::<true, false, K, CONS, L>(&ray, stack).is_some() {
                    alone |= 1 << i;
                }
                continue;
            }
            active |= 1 << i;
            let t = SlabTerms::of(&ray);
            for a in 0..3 {
                sr.rd[a][i] = t.rd[a];
                sr.od[a][i] = t.od[a];
            }
            sr.pad[i] = t.pad;
            sr.tnear[i] = ray.tnear;
            sr.tfar_box[i] = t.far_limit::<CONS>(ray.tfar);
            tfar[i] = ray.tfar;
            r4[i] = Ray4::new(ray.origin, ray.dir);
        }
        if active == 0 {
            return alone;
        }
        let pre: [K::Pre; STREAM_RAYS] = std::array::from_fn(|i| K::pre(&r4[i]));
        // Row of the near plane per axis: the box minimum where the direction is positive.
        let near = [(octant & 1) as usize, 2 + (octant >> 1 & 1) as usize, 4 + (octant >> 2 & 1) as usize];
        let far = [near[0] ^ 1, near[1] ^ 1, near[2] ^ 1];
        let mut occluded = 0u32;
        let mut sp = stack.len;
        let base_sp = sp;
        stack.put_mask(&mut sp, self.root, active);
        'pop: while sp > base_sp {
            let (mut cur, mask) = stack.take_mask(&mut sp);
            let mut mask = mask & !occluded;
            if mask == 0 {
                continue;
            }
            while !is_leaf(cur) {
                let b = &self.nodes[cur as usize].bounds;
                let rows = hot!(|r: [usize; 3]| [L::Nf::new(b[r[0]]), L::Nf::new(b[r[1]]), L::Nf::new(b[r[2]])]);
                let (bn, bf) = (rows(near), rows(far));
                // Bit `i` of a child's lane: ray `i` enters it (float bit operations only: the
                // lanes compared as floats would be denormals, zero under DAZ).
                let mut hits = L::Nf::splat(0.0);
                let mut bits = mask;
                while bits != 0 {
                    let i = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    // Near and far planes share the ray's six terms (one broadcast each); the
                    // conservative test widens the far minimum afterwards, `tf·(1 + w) + pad`,
                    // instead of folding the widening into six more terms as `BoxRay` does: the
                    // same bound, as the widening is increasing, at one fused multiply-add for
                    // six fewer loads.
                    let s = L::Nf::splat;
                    let (r0, r1, r2) = (s(sr.rd[0][i]), s(sr.rd[1][i]), s(sr.rd[2][i]));
                    let (o0, o1, o2) = (s(sr.od[0][i]), s(sr.od[1][i]), s(sr.od[2][i]));
                    let n0 = bn[0].mul_sub(r0, o0);
                    let n1 = bn[1].mul_sub(r1, o1);
                    let n2 = bn[2].mul_sub(r2, o2);
                    let f = bf[0].mul_sub(r0, o0).fast_min(bf[1].mul_sub(r1, o1)).fast_min(bf[2].mul_sub(r2, o2));
                    let f = if CONS { f.mul_add(s(FAR_WIDEN), s(sr.pad[i])) } else { f };
                    let tn = n0.fast_max(n1).fast_max(n2.fast_max(s(sr.tnear[i])));
                    let tf = f.fast_min(s(sr.tfar_box[i]));
                    hits |= tn.simd_le(tf) & s(f32::from_bits(1 << i));
                }
                let lanes = hits.to_array().map(f32::to_bits);
                let mut entered = (0..WIDTH).fold(0u32, |m, c| m | ((lanes[c] != 0) as u32) << c);
                if entered == 0 {
                    continue 'pop;
                }
                let child = &self.nodes[cur as usize].child;
                // Push the children entered in slot order and descend into the last, as Embree's
                // any-hit walks do.
                let last = 31 - entered.leading_zeros() as usize;
                entered &= !(1 << last);
                while entered != 0 {
                    let c = entered.trailing_zeros() as usize;
                    entered &= entered - 1;
                    self.prefetch_child(child[c]);
                    stack.put_mask(&mut sp, child[c], lanes[c]);
                }
                cur = child[last];
                mask = lanes[last];
            }
            let (start, count) = leaf_blocks(cur);
            let mut bits = mask;
            while bits != 0 {
                let i = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                for bi in start..start + count {
                    if K::intersect1(&self.blocks[bi], &r4[i], &pre[i], sr.tnear[i], tfar[i]).is_some() {
                        occluded |= 1 << i;
                        break;
                    }
                }
            }
            if occluded == active {
                break;
            }
        }
        stack.len = base_sp;
        occluded | alone
    }

    /// Prefetches the node or the first block of a leaf that `r` references.
    #[inline(always)]
    fn prefetch_child(&self, r: u32) {
        if is_leaf(r) {
            let (start, _) = leaf_blocks(r);
            if let Some(b) = self.blocks.get(start) {
                prefetch(b);
            }
        } else if let Some(n) = self.nodes.get(r as usize) {
            prefetch(n);
        }
    }
}

/// The direction octant of `ray` as the slab test sees it: bit `a` set where component `a` has its
/// sign bit set (`-0.0` too: its clamped reciprocal is negative).
#[inline(always)]
pub(crate) fn octant_of(ray: &Ray) -> u32 {
    octant_of_dir(ray.dir.x, ray.dir.y, ray.dir.z)
}

/// [`octant_of`] a direction given by its components.
#[inline(always)]
pub(crate) fn octant_of_dir(x: f32, y: f32, z: f32) -> u32 {
    x.to_bits() >> 31 | (y.to_bits() >> 31) << 1 | (z.to_bits() >> 31) << 2
}
