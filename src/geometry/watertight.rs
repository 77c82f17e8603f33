//! Woop, Benthin & Wald, "Watertight Ray/Triangle Intersection" (JCGT 2(1), 2013).
//!
//! Per ray: the dominant direction axis becomes z, and a shear maps the direction onto +z. Per
//! triangle: the corners, relative to the origin, are sheared; the signed 2D edge functions U, V,
//! W decide the hit. Shared edges compute bit-identical edge functions from the same corners (with
//! opposite signs), so no ray passes between two triangles; edge functions that are exactly zero
//! are recomputed in float64, as the paper prescribes. The traversal must be conservative too
//! (`BoxTest::Conservative`) for the whole query to be watertight.

use glam::Vec3;

use super::triangle::{BLOCK, Kernel, Ray4, RayK, TriBlock, nearest};
use crate::ray::RayPacket;
use crate::simd::*;

/// Per-ray shear: axis permutation `(kx, ky, kz)` and `(Sx, Sy, Sz)`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Shear {
    pub k: [usize; 3],
    pub s: [f32; 3],
}

impl Shear {
    #[inline(always)]
    pub fn new(d: Vec3) -> Self {
        let a = d.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding: swap when the dominant component is negative.
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Self { k: [kx, ky, kz], s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]] }
    }
}

/// One triangle against one ray in scalar form (used per lane by the packet form, and as the
/// float64 fallback): `(t, u, v)`.
#[inline(always)]
fn scalar(v: [Vec3; 3], o: Vec3, sh: &Shear, tnear: f32, tfar: f32) -> Option<(f32, f32, f32)> {
    let [kx, ky, kz] = sh.k;
    let [sx, sy, sz] = sh.s;
    let rel = v.map(|p| p - o);
    let xy = rel.map(|p| (p[kx] - sx * p[kz], p[ky] - sy * p[kz]));
    let (a, b, c) = (xy[0], xy[1], xy[2]);
    let mut e = [c.0 * b.1 - c.1 * b.0, a.0 * c.1 - a.1 * c.0, b.0 * a.1 - b.1 * a.0];
    if e.contains(&0.0) {
        let d = |p: (f32, f32)| (p.0 as f64, p.1 as f64);
        let (a, b, c) = (d(a), d(b), d(c));
        e = [(c.0 * b.1 - c.1 * b.0) as f32, (a.0 * c.1 - a.1 * c.0) as f32, (b.0 * a.1 - b.1 * a.0) as f32];
    }
    finish(e, rel.map(|p| sz * p[kz]), tnear, tfar)
}

#[inline(always)]
fn finish(e: [f32; 3], z: [f32; 3], tnear: f32, tfar: f32) -> Option<(f32, f32, f32)> {
    let [u, v, w] = e;
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || det.is_nan() {
        return None;
    }
    let t_scaled = u * z[0] + v * z[1] + w * z[2];
    let (t_s, abs_det) = if det < 0.0 { (-t_scaled, -det) } else { (t_scaled, det) };
    if !(abs_det * tnear < t_s && t_s <= abs_det * tfar) {
        return None;
    }
    let inv = 1.0 / det;
    let t = t_s / abs_det;
    (t < f32::INFINITY).then_some((t, v * inv, w * inv))
}

pub(crate) struct Watertight;

impl Kernel for Watertight {
    type Pre = Shear;

    #[inline(always)]
    fn pre(r: &Ray4) -> Shear {
        Shear::new(r.ds)
    }

    #[inline(always)]
    fn intersect1(b: &TriBlock, r: &Ray4, sh: &Shear, tnear: f32, tfar: f32) -> Option<(usize, f32, f32, f32)> {
        let [kx, ky, kz] = sh.k;
        let rel = |first: usize| -> [f32x4; 3] { std::array::from_fn(|a| f32x4::new(b.rows[first + a]) - r.o[a]) };
        let (a, bb, c) = (rel(0), rel(3), rel(6));
        let (sx, sy, sz) = (f32x4::splat(sh.s[0]), f32x4::splat(sh.s[1]), f32x4::splat(sh.s[2]));
        let shear = |p: &[f32x4; 3]| (p[kx] - sx * p[kz], p[ky] - sy * p[kz]);
        let ((ax, ay), (bx, by), (cx, cy)) = (shear(&a), shear(&bb), shear(&c));
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        let zero = f32x4::splat(0.0);
        // Exactly-zero edge functions: recompute those lanes in float64.
        let zeros = (u.simd_eq(zero) | v.simd_eq(zero) | w.simd_eq(zero)).to_bitmask();
        if zeros != 0 {
            let (mut ua, mut va, mut wa) = (u.to_array(), v.to_array(), w.to_array());
            let g = |x: f32x4| x.to_array();
            let (axa, aya, bxa, bya, cxa, cya) = (g(ax), g(ay), g(bx), g(by), g(cx), g(cy));
            for l in 0..BLOCK {
                if zeros & (1 << l) != 0 {
                    let (ax, ay, bx, by, cx, cy) =
                        (axa[l] as f64, aya[l] as f64, bxa[l] as f64, bya[l] as f64, cxa[l] as f64, cya[l] as f64);
                    ua[l] = (cx * by - cy * bx) as f32;
                    va[l] = (ax * cy - ay * cx) as f32;
                    wa[l] = (bx * ay - by * ax) as f32;
                }
            }
            (u, v, w) = (f32x4::new(ua), f32x4::new(va), f32x4::new(wa));
        }
        let neg = u.simd_lt(zero) | v.simd_lt(zero) | w.simd_lt(zero);
        let pos = u.simd_gt(zero) | v.simd_gt(zero) | w.simd_gt(zero);
        let det = u + v + w;
        let valid = !(neg & pos) & det.simd_ne(zero);
        if valid.to_bitmask() == 0 {
            return None;
        }
        let t_scaled = u * (sz * a[kz]) + v * (sz * bb[kz]) + w * (sz * c[kz]);
        let sgn = det & f32x4::splat(-0.0);
        let t_s = t_scaled ^ sgn;
        let abs_det = det.abs();
        let valid = valid & (abs_det * f32x4::splat(tnear)).simd_lt(t_s) & t_s.simd_le(abs_det * f32x4::splat(tfar));
        if valid.to_bitmask() == 0 {
            return None;
        }
        let inv = f32x4::splat(1.0) / det;
        let t = t_s / abs_det;
        nearest(valid & t.simd_lt(f32x4::splat(f32::INFINITY)), t, v * inv, w * inv)
    }

    /// Per lane: packets rarely share the shear of a single ray, and this test is chosen for
    /// robustness, not packet speed.
    #[inline(always)]
    fn intersect_packet(
        b: &TriBlock,
        lane: usize,
        r: &RayK,
        rays: &RayPacket,
        tfar: Pf,
        active: Pf,
    ) -> (Pf, Pf, Pf, Pf) {
        let mut bits = active.to_bitmask();
        let (tn, tf) = (r.tnear.to_array(), tfar.to_array());
        let tri = [b.row3(0, lane), b.row3(3, lane), b.row3(6, lane)];
        let (mut m, mut t, mut u, mut v) = ([0.0f32; 16], [0.0f32; 16], [0.0f32; 16], [0.0f32; 16]);
        while bits != 0 {
            let l = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let ray = rays.get(l);
            if let Some(h) = scalar(tri, ray.origin, &Shear::new(ray.dir), tn[l], tf[l]) {
                (m[l], t[l], u[l], v[l]) = (f32::from_bits(u32::MAX), h.0, h.1, h.2);
            }
        }
        // `m` holds all-ones (NaN) bits in hit lanes; NaN != 0 makes a full lane mask.
        let valid = Pf::new(m).simd_ne(Pf::splat(0.0));
        (valid, Pf::new(t), Pf::new(u), Pf::new(v))
    }
}
