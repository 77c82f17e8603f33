//! Triangle leaf storage and the Möller–Trumbore test in SIMD form.
//!
//! Storage follows Embree's `Triangle4` (`kernels/geometry/triangle.h`): blocks of [`BLOCK`]
//! triangles in SoA form holding `v0`, `e1 = v0 − v1` and `e2 = v2 − v0`, so the test needs no
//! vertex gathers. The test is Embree's `MoellerTrumboreIntersector`
//! (`triangle_intersector_moeller.h`) — Möller & Trumbore, "Fast, Minimum Storage Ray/Triangle
//! Intersection", JGT 1997; the seeds' slides on ray–triangle tests — with no epsilon on the
//! barycentric test and the depth test `tnear < t <= tfar`, so that hits agree with Embree's default
//! scenes. Two forms: one ray against the [`BLOCK`] triangles of a block (`intersect1`), and one
//! triangle against the lanes of a packet (`intersect_packet`).

use glam::Vec3;

use crate::simd::*;

/// Triangles per leaf block (M in Embree's naming).
pub(crate) const BLOCK: usize = 4;

/// [`BLOCK`] triangles in SoA form. Unused lanes hold NaN corners, which fail every comparison
/// and so are never hit.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub(crate) struct TriBlock {
    pub v0: [[f32; BLOCK]; 3],
    pub e1: [[f32; BLOCK]; 3],
    pub e2: [[f32; BLOCK]; 3],
    pub geom: [u32; BLOCK],
    pub prim: [u32; BLOCK],
}

impl TriBlock {
    /// Packs up to [`BLOCK`] triangles `(geom_id, prim_id, corners)`.
    pub fn new(tris: &[(u32, u32, [Vec3; 3])]) -> Self {
        let mut b = TriBlock {
            v0: [[f32::NAN; BLOCK]; 3],
            e1: [[f32::NAN; BLOCK]; 3],
            e2: [[f32::NAN; BLOCK]; 3],
            geom: [u32::MAX; BLOCK],
            prim: [u32::MAX; BLOCK],
        };
        for (lane, &(g, p, [a, bb, c])) in tris.iter().take(BLOCK).enumerate() {
            let e1 = a - bb;
            let e2 = c - a;
            for k in 0..3 {
                b.v0[k][lane] = a[k];
                b.e1[k][lane] = e1[k];
                b.e2[k][lane] = e2[k];
            }
            b.geom[lane] = g;
            b.prim[lane] = p;
        }
        b
    }

    /// Geometric normal `(v1 − v0) × (v2 − v0)` of lane `lane`, computed as Embree does.
    #[inline]
    pub fn ng(&self, lane: usize) -> Vec3 {
        let e1 = Vec3::new(self.e1[0][lane], self.e1[1][lane], self.e1[2][lane]);
        let e2 = Vec3::new(self.e2[0][lane], self.e2[1][lane], self.e2[2][lane]);
        e2.cross(e1)
    }
}

/// A ray's origin and direction splatted across [`BLOCK`] lanes, made once per ray.
#[derive(Clone, Copy)]
pub(crate) struct Ray4 {
    pub o: [f32x4; 3],
    pub d: [f32x4; 3],
}

impl Ray4 {
    #[inline]
    pub fn new(o: Vec3, d: Vec3) -> Self {
        Self {
            o: [f32x4::splat(o.x), f32x4::splat(o.y), f32x4::splat(o.z)],
            d: [f32x4::splat(d.x), f32x4::splat(d.y), f32x4::splat(d.z)],
        }
    }
}

#[inline(always)]
fn cross<T: Copy + core::ops::Mul<Output = T> + core::ops::Sub<Output = T>>(a: [T; 3], b: [T; 3]) -> [T; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[inline(always)]
fn dot<T: Copy + core::ops::Mul<Output = T> + core::ops::Add<Output = T>>(a: [T; 3], b: [T; 3]) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The nearest hit of one ray among the triangles of a block, as `(lane, t, u, v)`.
#[inline(always)]
pub(crate) fn intersect1(b: &TriBlock, r: &Ray4, tnear: f32, tfar: f32) -> Option<(usize, f32, f32, f32)> {
    let ld = |a: &[[f32; BLOCK]; 3]| [f32x4::new(a[0]), f32x4::new(a[1]), f32x4::new(a[2])];
    let (v0, e1, e2) = (ld(&b.v0), ld(&b.e1), ld(&b.e2));
    // Edge tests: the signs of U and V decide the hit, made independent of the winding by
    // flipping with the sign of the determinant.
    let c = [v0[0] - r.o[0], v0[1] - r.o[1], v0[2] - r.o[2]];
    let rr = cross(c, r.d);
    let ng = cross(e2, e1);
    let den = dot(ng, r.d);
    let abs_den = den.abs();
    let sgn = den & f32x4::splat(-0.0);
    let u = dot(rr, e2) ^ sgn;
    let v = dot(rr, e1) ^ sgn;
    let zero = f32x4::splat(0.0);
    let valid = den.simd_ne(zero) & u.simd_ge(zero) & v.simd_ge(zero) & (u + v).simd_le(abs_den);
    if valid.to_bitmask() == 0 {
        return None;
    }
    // Depth test, scaled by |den| to avoid the division for rejected lanes.
    let tt = dot(ng, c) ^ sgn;
    let valid = valid & (abs_den * f32x4::splat(tnear)).simd_lt(tt) & tt.simd_le(abs_den * f32x4::splat(tfar));
    let bits = valid.to_bitmask();
    if bits == 0 {
        return None;
    }
    let inv = f32x4::splat(1.0) / abs_den;
    let t = valid.select(tt * inv, f32x4::splat(f32::INFINITY)).to_array();
    // The nearest lane; among equal distances the lowest lane wins, as in Embree's select_min.
    let mut best = bits.trailing_zeros() as usize;
    for (lane, &tl) in t.iter().enumerate().skip(best + 1) {
        if tl < t[best] {
            best = lane;
        }
    }
    let (u, v) = ((u * inv).to_array(), (v * inv).to_array());
    Some((best, t[best], u[best], v[best]))
}

/// Packet lanes in SoA form for the broadcast test.
#[derive(Clone, Copy)]
pub(crate) struct RayK {
    pub o: [Pf; 3],
    pub d: [Pf; 3],
    pub tnear: Pf,
}

/// Lanes of a packet that hit triangle `lane` of block `b` within `(tnear, tfar]`, with their
/// `t`, `u` and `v`. Only lanes in `active` are reported.
#[inline(always)]
pub(crate) fn intersect_packet(b: &TriBlock, lane: usize, r: &RayK, tfar: Pf, active: Pf) -> (Pf, Pf, Pf, Pf) {
    let s = |a: &[[f32; BLOCK]; 3]| [Pf::splat(a[0][lane]), Pf::splat(a[1][lane]), Pf::splat(a[2][lane])];
    let (v0, e1, e2) = (s(&b.v0), s(&b.e1), s(&b.e2));
    let c = [v0[0] - r.o[0], v0[1] - r.o[1], v0[2] - r.o[2]];
    let rr = cross(c, r.d);
    let ng = cross(e2, e1);
    let den = dot(ng, r.d);
    let abs_den = den.abs();
    let sgn = den & Pf::splat(-0.0);
    let u = dot(rr, e2) ^ sgn;
    let v = dot(rr, e1) ^ sgn;
    let zero = Pf::splat(0.0);
    let valid = active & den.simd_ne(zero) & u.simd_ge(zero) & v.simd_ge(zero) & (u + v).simd_le(abs_den);
    if valid.to_bitmask() == 0 {
        return (valid, zero, zero, zero);
    }
    let tt = dot(ng, c) ^ sgn;
    let valid = valid & (abs_den * r.tnear).simd_lt(tt) & tt.simd_le(abs_den * tfar);
    let inv = Pf::splat(1.0) / abs_den;
    (valid, tt * inv, u * inv, v * inv)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block1(a: Vec3, b: Vec3, c: Vec3) -> TriBlock {
        TriBlock::new(&[(0, 7, [a, b, c])])
    }

    #[test]
    fn barycentrics_and_normal_match_the_definition() {
        let (a, b, c) = (Vec3::new(0.0, 0.0, 0.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0));
        let blk = block1(a, b, c);
        let o = Vec3::new(0.5, 0.25, 3.0);
        let d = Vec3::new(0.0, 0.0, -1.5);
        let (lane, t, u, v) = intersect1(&blk, &Ray4::new(o, d), 0.0, f32::INFINITY).unwrap();
        assert_eq!(lane, 0);
        assert!((t - 2.0).abs() < 1e-6);
        let p = a * (1.0 - u - v) + b * u + c * v;
        assert!((p - (o + d * t)).length() < 1e-6, "{p}");
        assert_eq!(blk.ng(0), (b - a).cross(c - a));
    }

    #[test]
    fn depth_test_is_half_open() {
        let blk = block1(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(0.0, 1.0, 0.0));
        let r = Ray4::new(Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.0, 0.0, -1.0));
        assert!(intersect1(&blk, &r, 0.0, 1.0).is_some(), "t == tfar hits");
        assert!(intersect1(&blk, &r, 1.0, 2.0).is_none(), "t == tnear misses");
        assert!(intersect1(&blk, &r, 0.0, 0.999).is_none());
        // Both windings hit.
        let back = Ray4::new(Vec3::new(0.0, 0.0, -1.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(intersect1(&blk, &back, 0.0, 5.0).is_some());
    }

    #[test]
    fn padding_lanes_never_hit() {
        let blk = TriBlock::new(&[]);
        let r = Ray4::new(Vec3::ZERO, Vec3::X);
        assert!(intersect1(&blk, &r, f32::NEG_INFINITY, f32::INFINITY).is_none());
    }

    #[test]
    fn packet_form_matches_single_form() {
        let blk = block1(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(0.0, 1.0, 0.0));
        let mut o = [[0.0f32; PACKET_WIDTH]; 3];
        let mut d = [[0.0f32; PACKET_WIDTH]; 3];
        for i in 0..PACKET_WIDTH {
            o[0][i] = -1.2 + 0.16 * i as f32;
            o[1][i] = 0.3 - 0.1 * i as f32;
            o[2][i] = 2.0;
            d[2][i] = -1.0;
            d[0][i] = 0.01 * i as f32;
        }
        let rk = RayK {
            o: [Pf::new(o[0]), Pf::new(o[1]), Pf::new(o[2])],
            d: [Pf::new(d[0]), Pf::new(d[1]), Pf::new(d[2])],
            tnear: Pf::splat(0.0),
        };
        let all = Pf::splat(0.0).simd_eq(Pf::splat(0.0));
        let (valid, t, _, _) = intersect_packet(&blk, 0, &rk, Pf::splat(f32::INFINITY), all);
        let (bits, t) = (valid.to_bitmask(), t.to_array());
        let mut hits = 0;
        for i in 0..PACKET_WIDTH {
            let single = Ray4::new(Vec3::new(o[0][i], o[1][i], o[2][i]), Vec3::new(d[0][i], d[1][i], d[2][i]));
            let s = intersect1(&blk, &single, 0.0, f32::INFINITY);
            assert_eq!(s.is_some(), bits & (1 << i) != 0, "lane {i}");
            if let Some((_, ts, _, _)) = s {
                assert_eq!(ts, t[i]);
                hits += 1;
            }
        }
        assert!(hits > 3 && hits < PACKET_WIDTH, "the test rays should both hit and miss: {hits}");
    }
}
