//! Möller–Trumbore ("Fast, Minimum Storage Ray/Triangle Intersection", JGT 1997; the seeds'
//! slides) in the form of Embree's `MoellerTrumboreIntersector` (`triangle_intersector_moeller.h`):
//! edges precomputed, no epsilon on the barycentric test, depth test `tnear < t <= tfar`, cross and
//! dot products fused as Embree's `vec3.h` writes them, so that hits agree with Embree's default
//! scenes.

use super::triangle::{BLOCK, BlockHits, Kernel, Ray4, RayK, TriBlock, cross, dot, sane};
use crate::simd::*;

pub(crate) struct Moller;

impl Kernel for Moller {
    type Pre = ();

    #[inline(always)]
    fn pre<L: Level>(_: &Ray4<L>) {}

    #[inline(always)]
    fn lanes1<L: Level>(b: &TriBlock, r: &Ray4<L>, _: &(), tnear: f32, tfar: f32) -> Option<BlockHits<L::F4>> {
        let ld = hot!(|k: usize| [L::F4::new(b.rows[k]), L::F4::new(b.rows[k + 1]), L::F4::new(b.rows[k + 2])]);
        let (v0, e1, e2) = (ld(0), ld(3), ld(6));
        // Edge tests: the signs of U and V decide the hit, made independent of the winding by
        // flipping with the sign of the determinant.
        let c = [v0[0] - r.o[0], v0[1] - r.o[1], v0[2] - r.o[2]];
        let rr = cross(c, r.d);
        let ng = cross(e2, e1);
        let den = dot(ng, r.d);
        let abs_den = den.abs();
        let sgn = den & L::F4::splat(-0.0);
        let u = dot(rr, e2) ^ sgn;
        let v = dot(rr, e1) ^ sgn;
        let zero = L::F4::splat(0.0);
        let valid = den.simd_ne(zero) & u.simd_ge(zero) & v.simd_ge(zero) & (u + v).simd_le(abs_den);
        if valid.to_bitmask() == 0 {
            return None;
        }
        // Depth test, scaled by |den| to avoid the division for rejected lanes.
        let tt = dot(ng, c) ^ sgn;
        let valid = valid & (abs_den * L::F4::splat(tnear)).simd_lt(tt) & tt.simd_le(abs_den * L::F4::splat(tfar));
        if valid.to_bitmask() == 0 {
            return None;
        }
        let inv = L::F4::splat(1.0) / abs_den;
        let t = tt * inv;
        Some((valid & sane(inv, t, L::F4::splat(tnear), L::F4::splat(tfar)), t, u * inv, v * inv))
    }

    #[inline(always)]
    fn intersect_packet<L: Level>(
        b: &TriBlock,
        lane: usize,
        r: &RayK<L>,
        tfar: L::Pf,
        active: L::Pf,
    ) -> (L::Pf, L::Pf, L::Pf, L::Pf) {
        debug_assert!(lane < BLOCK);
        let s = hot!(|k: usize| {
            [L::Pf::splat(b.rows[k][lane]), L::Pf::splat(b.rows[k + 1][lane]), L::Pf::splat(b.rows[k + 2][lane])]
        });
        let (v0, e1, e2) = (s(0), s(3), s(6));
        let c = [v0[0] - r.o[0], v0[1] - r.o[1], v0[2] - r.o[2]];
        let rr = cross(c, r.d);
        let ng = cross(e2, e1);
        let den = dot(ng, r.d);
        let abs_den = den.abs();
        let sgn = den & L::Pf::splat(-0.0);
        let u = dot(rr, e2) ^ sgn;
        let v = dot(rr, e1) ^ sgn;
        let zero = L::Pf::splat(0.0);
        let valid = active & den.simd_ne(zero) & u.simd_ge(zero) & v.simd_ge(zero) & (u + v).simd_le(abs_den);
        if valid.to_bitmask() == 0 {
            return (valid, zero, zero, zero);
        }
        let tt = dot(ng, c) ^ sgn;
        let valid = valid & (abs_den * r.tnear).simd_lt(tt) & tt.simd_le(abs_den * tfar);
        let inv = L::Pf::splat(1.0) / abs_den;
        let t = tt * inv;
        (valid & sane(inv, t, r.tnear, tfar), t, u * inv, v * inv)
    }
}
