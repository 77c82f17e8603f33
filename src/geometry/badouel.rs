//! Badouel's test ("An Efficient Ray–Polygon Intersection", Graphics Gems 1990; the seeds' slides
//! "Schnitt Strahl—Dreieck [Badouel 1990]"): intersect the plane to get `t` and the hit point,
//! project point and triangle onto the coordinate plane that drops the normal's dominant axis k,
//! and test the 2D barycentric coordinates, which equal the 3D ones.
//!
//! Precomputed in Wald's form (2004, §7.1), nine floats per triangle: with the normal scaled so
//! that `n_k = 1`, the plane is `x_k + n_u·x_u + n_v·x_v = n_d`, and each barycentric coordinate is
//! an affine function of the projected hit point, `β = β_u·h_u + β_v·h_v + β_d`. The coefficients
//! are computed in float64 and rounded once.

use glam::{DVec3, Vec3};

use super::triangle::{BlockHits, Kernel, Ray4, RayK, TriBlock};
use crate::simd::*;

/// The nine rows and the aux bits (axis k, normal sign) of one triangle.
pub(crate) fn precompute(a: Vec3, b: Vec3, c: Vec3) -> ([f32; 9], u8) {
    let (a, b, c): (DVec3, DVec3, DVec3) = (a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
    let (e1, e2) = (b - a, c - a);
    let n = e1.cross(e2);
    let an = n.abs();
    let k = if an.x >= an.y && an.x >= an.z {
        0
    } else if an.y >= an.z {
        1
    } else {
        2
    };
    let (u, v) = ((k + 1) % 3, (k + 2) % 3);
    // n[k] = e1_u·e2_v − e1_v·e2_u is also the determinant of the projected triangle.
    let nk = n[k];
    let (bu, bv) = (e2[v] / nk, -e2[u] / nk);
    let (cu, cv) = (-e1[v] / nk, e1[u] / nk);
    let rows =
        [n[u] / nk, n[v] / nk, n.dot(a) / nk, bu, bv, -(bu * a[u] + bv * a[v]), cu, cv, -(cu * a[u] + cv * a[v])];
    (rows.map(|x| x as f32), k as u8 | (((nk < 0.0) as u8) << 2))
}

/// The geometric normal of lane `lane`, scaled so that its dominant component is ±1.
pub(crate) fn normal(b: &TriBlock, lane: usize) -> Vec3 {
    let k = ((b.aux(lane) & 3) as usize).min(2);
    let sign = if b.aux(lane) & 4 != 0 { -1.0 } else { 1.0 };
    let mut n = Vec3::ZERO;
    n[k] = 1.0;
    n[(k + 1) % 3] = b.rows[0][lane];
    n[(k + 2) % 3] = b.rows[1][lane];
    n * sign
}

pub(crate) struct Badouel;

impl Kernel for Badouel {
    type Pre = ();

    #[inline(always)]
    fn pre<L: Level>(_: &Ray4<L>) {}

    #[inline(always)]
    fn lanes1<L: Level>(b: &TriBlock, r: &Ray4<L>, _: &(), tnear: f32, tfar: f32) -> Option<BlockHits<L::F4>> {
        // Per lane, the ray's components along k, u = k + 1 and v = k + 2.
        let kf = L::F4::new(std::array::from_fn(|l| (b.aux(l) & 3) as f32));
        let (k0, k1) = (kf.simd_eq(L::F4::splat(0.0)), kf.simd_eq(L::F4::splat(1.0)));
        let sel = hot!(|x: L::F4, y: L::F4, z: L::F4| k0.select(x, k1.select(y, z)));
        let (o, d) = (&r.o, &r.d);
        let (ok, ou, ov) = (sel(o[0], o[1], o[2]), sel(o[1], o[2], o[0]), sel(o[2], o[0], o[1]));
        let (dk, du, dv) = (sel(d[0], d[1], d[2]), sel(d[1], d[2], d[0]), sel(d[2], d[0], d[1]));
        let row = hot!(|i: usize| L::F4::new(b.rows[i]));
        let (nu, nv, nd) = (row(0), row(1), row(2));
        // Plane first: t and the projected hit point.
        let den = dk + nu * du + nv * dv;
        let t = (nd - ok - nu * ou - nv * ov) / den;
        let zero = L::F4::splat(0.0);
        let valid = den.simd_ne(zero)
            & L::F4::splat(tnear).simd_lt(t)
            & t.simd_le(L::F4::splat(tfar))
            & t.simd_lt(L::F4::splat(f32::INFINITY));
        if valid.to_bitmask() == 0 {
            return None;
        }
        let (hu, hv) = (ou + t * du, ov + t * dv);
        let beta = row(3) * hu + row(4) * hv + row(5);
        let gamma = row(6) * hu + row(7) * hv + row(8);
        let valid = valid & beta.simd_ge(zero) & gamma.simd_ge(zero) & (beta + gamma).simd_le(L::F4::splat(1.0));
        Some((valid, t, beta, gamma))
    }

    #[inline(always)]
    fn intersect_packet<L: Level>(
        b: &TriBlock,
        lane: usize,
        r: &RayK<L>,
        tfar: L::Pf,
        active: L::Pf,
    ) -> (L::Pf, L::Pf, L::Pf, L::Pf) {
        let k = ((b.aux(lane) & 3) as usize).min(2);
        let (u, v) = ((k + 1) % 3, (k + 2) % 3);
        let s = hot!(|i: usize| L::Pf::splat(b.rows[i][lane]));
        let den = r.d[k] + s(0) * r.d[u] + s(1) * r.d[v];
        let t = (s(2) - r.o[k] - s(0) * r.o[u] - s(1) * r.o[v]) / den;
        let zero = L::Pf::splat(0.0);
        let valid =
            active & den.simd_ne(zero) & r.tnear.simd_lt(t) & t.simd_le(tfar) & t.simd_lt(L::Pf::splat(f32::INFINITY));
        if valid.to_bitmask() == 0 {
            return (valid, zero, zero, zero);
        }
        let (hu, hv) = (r.o[u] + t * r.d[u], r.o[v] + t * r.d[v]);
        let beta = s(3) * hu + s(4) * hv + s(5);
        let gamma = s(6) * hu + s(7) * hv + s(8);
        let valid = valid & beta.simd_ge(zero) & gamma.simd_ge(zero) & (beta + gamma).simd_le(L::Pf::splat(1.0));
        (valid, t, beta, gamma)
    }
}
