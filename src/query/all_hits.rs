//! Every hit along a ray in one walk: the BVH walk of the closest-hit query with a leaf test that
//! reports every triangle it hits and never shortens the ray.
//!
//! trimesh's `intersects_location(multiple_hits=True)` finds all hits by asking Embree for the
//! closest hit again and again from just beyond the last one; a step too short finds the same
//! triangle again, a step too long skips a close second surface. One walk over the whole interval
//! `(tnear, tfar]` has neither problem.

use crate::bvh::node::{EMPTY, leaf_blocks};
use crate::bvh::traverse::{BoxRay, LeafHit, SlabTerms, Stack, dispatch, walk1, with_stack};
use crate::bvh::{BoxTest, Bvh};
use crate::geometry::TriangleTest;
use crate::geometry::badouel::Badouel;
use crate::geometry::moeller::Moller;
use crate::geometry::triangle::{Kernel, Ray4};
use crate::geometry::watertight::Watertight;
use crate::instance::InstancedScene;
use crate::ray::{Hit, Ray};
use crate::simd::{Level, SimdF, with_level};

impl Bvh {
    /// Calls `f` for every triangle `ray` hits in `(tnear, tfar]`, in no particular order (a
    /// triangle split by spatial splits may come more than once). Invalid rays hit nothing.
    pub(crate) fn each_hit(&self, ray: &Ray, mut f: impl FnMut(&LeafHit)) {
        if self.root == EMPTY || !ray.is_valid() {
            return;
        }
        let ray = ray.clamped_to_zero();
        with_stack(|stack| {
            dispatch!(self.test, self.box_test, |K, C| with_level!(|L| L::call(
                #[inline(always)]
                || self.each_hit_with::<K, C, L>(&ray, stack, &mut f)
            )))
        })
    }

    /// [`each_hit`](Self::each_hit) with a chosen kernel, on `stack` above its current entries,
    /// for a valid ray with `tnear >= 0`.
    #[inline(always)]
    pub(crate) fn each_hit_with<K: Kernel, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        stack: &mut Stack,
        f: &mut impl FnMut(&LeafHit),
    ) {
        if self.root == EMPTY {
            return;
        }
        let base = stack.push_root(self.root);
        let r4 = Ray4::<L>::new(ray.origin, ray.dir);
        let pre = K::pre(&r4);
        let br = BoxRay::<L>::with_terms(SlabTerms::of(ray), ray.tnear);
        // The walk's `tfar` stays the ray's: every subtree the ray enters is visited.
        let mut tfar = ray.tfar;
        walk1::<false, CONS, L>(
            self.tree(),
            &br,
            stack,
            base,
            &mut tfar,
            #[inline(always)]
            |leaf, tfar, _| {
                let (start, count) = leaf_blocks(leaf);
                for bi in start..start + count {
                    let Some((valid, t, u, v)) = K::lanes1(&self.blocks[bi], &r4, &pre, ray.tnear, *tfar) else {
                        continue;
                    };
                    let (t, u, v) = (t.to_array(), u.to_array(), v.to_array());
                    let mut bits = valid.to_bitmask();
                    while bits != 0 {
                        let lane = bits.trailing_zeros() as usize;
                        bits &= bits - 1;
                        f(&LeafHit { block: bi as u32, lane: lane as u32, t: t[lane], u: u[lane], v: v[lane] });
                    }
                }
                false
            },
        );
    }
}

impl InstancedScene {
    /// Calls `f` for every triangle of every instance `ray` hits in `(tnear, tfar]` (world-space
    /// hits), in no particular order. Invalid rays hit nothing.
    pub(crate) fn each_hit(&self, ray: &Ray, mut f: impl FnMut(&Hit)) {
        if !ray.is_valid() {
            return;
        }
        let ray = ray.clamped_to_zero();
        let (test, box_test) = self.tests();
        with_stack(|stack| {
            dispatch!(test, box_test, |K, C| with_level!(|L| L::call(
                #[inline(always)]
                || self.each_hit_with::<K, C, L>(&ray, stack, &mut f)
            )))
        })
    }

    #[inline(always)]
    fn each_hit_with<K: Kernel, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        stack: &mut Stack,
        f: &mut impl FnMut(&Hit),
    ) {
        let Some(root) = self.top_root() else { return };
        let br = BoxRay::<L>::with_terms(SlabTerms::of(ray), ray.tnear);
        let mut tfar = ray.tfar;
        let base = stack.push_root(root);
        walk1::<false, CONS, L>(
            self.top_tree(),
            &br,
            stack,
            base,
            &mut tfar,
            #[inline(always)]
            |leaf, _, stack| {
                let (start, count) = leaf_blocks(leaf);
                for k in start..start + count {
                    let (object, r) = self.object_ray_of(k, ray);
                    // Finite in, finite out, except where a huge scale overflows: such rays miss.
                    if !(r.origin.is_finite() && r.dir.is_finite()) {
                        continue;
                    }
                    let bvh = self.objects()[object as usize].bvh();
                    bvh.each_hit_with::<K, CONS, L>(&r, stack, &mut |h| {
                        f(&self.world_hit_of(k as u32, &bvh.hit_record(h)));
                    });
                    self.objects()[object as usize].sphere_tree().each_hit_on::<CONS, L>(&r, stack, &mut |h| {
                        f(&self.world_sphere_hit_of(k as u32, h));
                    });
                    self.objects()[object as usize].solid_tree().each_hit_on::<CONS, L>(&r, stack, &mut |h| {
                        f(&self.world_sphere_hit_of(k as u32, h));
                    });
                }
                false
            },
        );
    }
}
