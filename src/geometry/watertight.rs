//! Woop, Benthin & Wald, "Watertight Ray/Triangle Intersection" (JCGT 2(1), 2013).
//!
//! Per ray: the dominant direction axis becomes z, and a shear maps the direction onto +z. Per
//! triangle: the corners, relative to the origin, are sheared; the signed 2D edge functions U, V,
//! W decide the hit. Shared edges compute bit-identical edge functions from the same corners (with
//! opposite signs), so no ray passes between two triangles; edge functions that are exactly zero
//! are recomputed in float64, as the paper prescribes. The traversal must be conservative too
//! (`BoxTest::Conservative`) for the whole query to be watertight.

use glam::Vec3;

use super::triangle::{BlockHits, Kernel, Ray4, RayK, TriBlock, sane};
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

/// The float64 fallback of the paper: the edge functions `[U, V, W]` of the lanes in `zeros`
/// recomputed from the sheared corners `[ax, ay, bx, by, cx, cy]` in double precision.
#[inline(never)]
fn edges_f64<const N: usize>(zeros: u32, e: [[f32; N]; 3], c: [[f32; N]; 6]) -> ([f32; N], [f32; N], [f32; N]) {
    let [mut u, mut v, mut w] = e;
    for l in 0..N {
        if zeros & (1 << l) != 0 {
            let [ax, ay, bx, by, cx, cy] = c.map(|x| x[l] as f64);
            u[l] = (cx * by - cy * bx) as f32;
            v[l] = (ax * cy - ay * cx) as f32;
            w[l] = (bx * ay - by * ax) as f32;
        }
    }
    (u, v, w)
}

pub(crate) struct Watertight;

impl Kernel for Watertight {
    type Pre = Shear;

    #[inline(always)]
    fn pre<L: Level>(r: &Ray4<L>) -> Shear {
        Shear::new(r.ds)
    }

    #[inline(always)]
    fn lanes1<L: Level>(b: &TriBlock, r: &Ray4<L>, sh: &Shear, tnear: f32, tfar: f32) -> Option<BlockHits<L::F4>> {
        let [kx, ky, kz] = sh.k;
        let rel = hot!(|first: usize| -> [L::F4; 3] {
            let p = hot!(|a: usize| L::F4::new(b.rows[first + a]) - r.o[a]);
            [p(0), p(1), p(2)]
        });
        let (a, bb, c) = (rel(0), rel(3), rel(6));
        let (sx, sy, sz) = (L::F4::splat(sh.s[0]), L::F4::splat(sh.s[1]), L::F4::splat(sh.s[2]));
        let shear = hot!(|p: &[L::F4; 3]| (p[kx] - sx * p[kz], p[ky] - sy * p[kz]));
        let ((ax, ay), (bx, by), (cx, cy)) = (shear(&a), shear(&bb), shear(&c));
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        let zero = L::F4::splat(0.0);
        // Exactly-zero edge functions: recompute those lanes in float64.
        let zeros = (u.simd_eq(zero) | v.simd_eq(zero) | w.simd_eq(zero)).to_bitmask();
        if zeros != 0 {
            let g = hot!(|x: L::F4| x.to_array());
            let (ua, va, wa) = edges_f64(zeros, [g(u), g(v), g(w)], [g(ax), g(ay), g(bx), g(by), g(cx), g(cy)]);
            (u, v, w) = (L::F4::new(ua), L::F4::new(va), L::F4::new(wa));
        }
        let neg = u.simd_lt(zero) | v.simd_lt(zero) | w.simd_lt(zero);
        let pos = u.simd_gt(zero) | v.simd_gt(zero) | w.simd_gt(zero);
        let det = u + v + w;
        let valid = !(neg & pos) & det.simd_ne(zero);
        if valid.to_bitmask() == 0 {
            return None;
        }
        let t_scaled = u * (sz * a[kz]) + v * (sz * bb[kz]) + w * (sz * c[kz]);
        let sgn = det & L::F4::splat(-0.0);
        let t_s = t_scaled ^ sgn;
        let abs_det = det.abs();
        let valid = valid & (abs_det * L::F4::splat(tnear)).simd_lt(t_s) & t_s.simd_le(abs_det * L::F4::splat(tfar));
        if valid.to_bitmask() == 0 {
            return None;
        }
        let inv = L::F4::splat(1.0) / det;
        let t = t_s / abs_det;
        Some((valid & sane(inv, t, L::F4::splat(tnear), L::F4::splat(tfar)), t, v * inv, w * inv))
    }

    /// All lanes at once: each lane's axis permutation and shear are selected by mask, so the
    /// arithmetic is the single-ray form's, operation for operation (bit-identical results).
    #[inline(always)]
    fn intersect_packet<L: Level>(
        b: &TriBlock,
        lane: usize,
        r: &RayK<L>,
        tfar: L::Pf,
        active: L::Pf,
    ) -> (L::Pf, L::Pf, L::Pf, L::Pf) {
        let zero = L::Pf::splat(0.0);
        let d = &r.d;
        let ad = [d[0].abs(), d[1].abs(), d[2].abs()];
        // kz = the dominant axis (ties resolved as in `Shear::new`).
        let zx = ad[0].simd_ge(ad[1]) & ad[0].simd_ge(ad[2]);
        let zy = !zx & ad[1].simd_ge(ad[2]);
        // Components along kz, kz + 1 and kz + 2, then kx/ky swapped where d[kz] < 0.
        let perm = hot!(|p: &[L::Pf; 3]| -> [L::Pf; 3] {
            let z = zx.select(p[0], zy.select(p[1], p[2]));
            let x = zx.select(p[1], zy.select(p[2], p[0]));
            let y = zx.select(p[2], zy.select(p[0], p[1]));
            [x, y, z]
        });
        let [dx0, dy0, dz] = perm(d);
        let neg = dz.simd_lt(zero);
        let swap = hot!(|p: [L::Pf; 3]| [neg.select(p[1], p[0]), neg.select(p[0], p[1]), p[2]]);
        let [dx, dy, _] = swap([dx0, dy0, dz]);
        let (sx, sy, sz) = (dx / dz, dy / dz, L::Pf::splat(1.0) / dz);
        let rel = hot!(|first: usize| -> [L::Pf; 3] {
            let p = hot!(|a: usize| L::Pf::splat(b.rows[first + a][lane]) - r.o[a]);
            swap(perm(&[p(0), p(1), p(2)]))
        });
        let (a, bb, c) = (rel(0), rel(3), rel(6));
        let shear = hot!(|p: &[L::Pf; 3]| (p[0] - sx * p[2], p[1] - sy * p[2]));
        let ((ax, ay), (bx, by), (cx, cy)) = (shear(&a), shear(&bb), shear(&c));
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        // Exactly-zero edge functions: recompute those lanes in float64, as the single-ray form.
        let zeros = (active & (u.simd_eq(zero) | v.simd_eq(zero) | w.simd_eq(zero))).to_bitmask();
        if zeros != 0 {
            let g = hot!(|x: L::Pf| x.to_array());
            let (ua, va, wa) = edges_f64(zeros, [g(u), g(v), g(w)], [g(ax), g(ay), g(bx), g(by), g(cx), g(cy)]);
            (u, v, w) = (L::Pf::new(ua), L::Pf::new(va), L::Pf::new(wa));
        }
        let negs = u.simd_lt(zero) | v.simd_lt(zero) | w.simd_lt(zero);
        let poss = u.simd_gt(zero) | v.simd_gt(zero) | w.simd_gt(zero);
        let det = u + v + w;
        let valid = active & !(negs & poss) & det.simd_ne(zero);
        if valid.to_bitmask() == 0 {
            return (valid, zero, zero, zero);
        }
        let t_scaled = u * (sz * a[2]) + v * (sz * bb[2]) + w * (sz * c[2]);
        let t_s = t_scaled ^ (det & L::Pf::splat(-0.0));
        let abs_det = det.abs();
        let valid = valid & (abs_det * r.tnear).simd_lt(t_s) & t_s.simd_le(abs_det * tfar);
        let inv = L::Pf::splat(1.0) / det;
        let t = t_s / abs_det;
        (valid & sane(inv, t, r.tnear, tfar), t, v * inv, w * inv)
    }
}
