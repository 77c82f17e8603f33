//! Spheres: storage in SoA leaf blocks of [`BLOCK`] and the three ray–sphere tests of the seeds
//! and their successors, written once over [`Lanes`] so that one ray against a block of four and
//! a packet of sixteen against one sphere run the same arithmetic, at every instruction-set
//! level (`simd::Level`).
//!
//! - **Geometric** (the seeds' slides; Haines, "Essential Ray Tracing Algorithms", 1989): the
//!   centre's projection on the ray, early outs for rays pointing away and for lines passing
//!   outside; the squared distance of the line from the centre is `|L|² − t_ca²`, a difference of
//!   two large numbers for spheres far from the origin.
//! - **Algebraic** (the seeds' slides): the quadratic `a t² + 2b t + c = 0`, discriminant
//!   `b² − a c`, with the same cancellation, and a second one in `−b ± √disc` for the near root.
//! - **Robust** (Haines, Günther, Akenine-Möller, "Precision Improvements for Ray/Sphere
//!   Intersection", Ray Tracing Gems, 2019, ch. 7): the discriminant from the perpendicular
//!   `f − (f·d/d·d) d` (what Embree's `SphereIntersector` computes), and the root of smaller
//!   magnitude as `c/q` with `q = b' + sign(b')√(a·Δ)`, which keeps rays starting near the
//!   surface (shadow and secondary rays) from cancelling.
//!
//! Directions are not assumed to be unit vectors (instancing does not renormalize), so `a = d·d`
//! enters every form. Hits lie in `(tnear, tfar]`: the nearer root where it lies there, else the
//! farther (a ray starting inside leaves through it).

use glam::{DVec3, Vec3};

use crate::geometry::triangle::BLOCK;
use crate::simd::*;

/// The ray–sphere test a scene's spheres are intersected with (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SphereTest {
    /// The seeds' geometric test: projection of the centre, early outs ("the geometric is
    /// faster"). Loses accuracy for spheres far from the ray's origin relative to their radius.
    Geometric,
    /// The seeds' algebraic test: the quadratic's discriminant `b² − ac`. Loses accuracy as the
    /// geometric one does, and for rays starting near the surface.
    Algebraic,
    /// Ray Tracing Gems ch. 7: perpendicular discriminant and the `c/q` near root. The default.
    #[default]
    Robust,
}

impl SphereTest {
    /// Every sphere test.
    pub const ALL: [SphereTest; 3] = [SphereTest::Geometric, SphereTest::Algebraic, SphereTest::Robust];

    /// The test's name, as the harness and scene files spell it.
    pub fn name(self) -> &'static str {
        match self {
            SphereTest::Geometric => "geometric",
            SphereTest::Algebraic => "algebraic",
            SphereTest::Robust => "robust",
        }
    }
}

/// [`BLOCK`] spheres in SoA form: centre `x, y, z` and radius rows. Unused lanes hold NaN, which
/// fails every test, and `prim = u32::MAX`.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub(crate) struct SphereBlock {
    pub rows: [[f32; BLOCK]; 4],
    pub geom: [u32; BLOCK],
    pub prim: [u32; BLOCK],
}

impl SphereBlock {
    /// Packs up to [`BLOCK`] spheres `(geom_id, prim_id, centre, radius)`.
    pub fn new(spheres: &[(u32, u32, Vec3, f32)]) -> Self {
        let mut b = SphereBlock { rows: [[f32::NAN; BLOCK]; 4], geom: [u32::MAX; BLOCK], prim: [u32::MAX; BLOCK] };
        for (lane, &(g, p, c, r)) in spheres.iter().take(BLOCK).enumerate() {
            for (row, v) in b.rows.iter_mut().zip([c.x, c.y, c.z, r]) {
                row[lane] = v;
            }
            b.geom[lane] = g;
            b.prim[lane] = p;
        }
        b
    }

    /// The centre of lane `lane`.
    #[inline(always)]
    pub fn center(&self, lane: usize) -> Vec3 {
        Vec3::new(self.rows[0][lane], self.rows[1][lane], self.rows[2][lane])
    }
}

/// Rays in lanes, with what every sphere test needs of them alone: `a = d·d` and its reciprocal,
/// computed once per ray (or packet) instead of once per block.
#[derive(Clone, Copy)]
pub(crate) struct RayLanes<V> {
    pub o: [V; 3],
    pub d: [V; 3],
    pub a: V,
    pub inv_a: V,
}

impl<V: Lanes> RayLanes<V> {
    #[inline(always)]
    pub fn new(o: [V; 3], d: [V; 3]) -> Self {
        let a = dot(d, d);
        Self { o, d, a, inv_a: V::splat(1.0) / a }
    }
}

impl<V: Lanes> RayLanes<V> {
    /// One ray in all lanes.
    #[inline(always)]
    pub fn splat(o: Vec3, d: Vec3) -> Self {
        let s = |v: Vec3| [V::splat(v.x), V::splat(v.y), V::splat(v.z)];
        Self::new(s(o), s(d))
    }
}

/// Both roots `t0 ≤ t1` of the rays `ray` against spheres `c, r` (lane by lane), and the lanes
/// where the line meets the sphere at all (all bits set). Other lanes hold anything.
#[inline(always)]
pub(crate) fn roots<V: Lanes>(test: SphereTest, c: [V; 3], r: V, ray: &RayLanes<V>) -> (V, V, V) {
    let zero = V::splat(0.0);
    let RayLanes { o, d, a, inv_a } = *ray;
    let r2 = r * r;
    match test {
        SphereTest::Geometric => {
            // L = c − o; t_ca·|d|² = L·d; the line's squared distance from the centre is
            // |L|² − (L·d)²/|d|².
            let l = [c[0] - o[0], c[1] - o[1], c[2] - o[2]];
            let tca = dot(l, d);
            let l2 = dot(l, l);
            // Early out (the seeds): an origin outside the sphere with the centre behind it.
            let away = r2.lt(l2) & tca.lt(zero);
            let d2 = l2 - tca * tca * inv_a;
            let meet = d2.le(r2) & !away;
            let thc = ((r2 - d2) * inv_a).sqrt();
            let mid = tca * inv_a;
            (mid - thc, mid + thc, meet)
        }
        SphereTest::Algebraic => {
            let f = [o[0] - c[0], o[1] - c[1], o[2] - c[2]];
            let b = dot(f, d);
            let cc = dot(f, f) - r2;
            let disc = b * b - a * cc;
            let s = disc.sqrt();
            ((-b - s) * inv_a, (-b + s) * inv_a, zero.le(disc))
        }
        SphereTest::Robust => {
            let f = [o[0] - c[0], o[1] - c[1], o[2] - c[2]];
            // b' = −f·d; the perpendicular from the centre to the line is f + (b'/a) d.
            let b = -dot(f, d);
            let k = b * inv_a;
            let p = [k.madd(d[0], f[0]), k.madd(d[1], f[1]), k.madd(d[2], f[2])];
            let disc = r2 - dot(p, p);
            let q = b + (a * disc).sqrt().copysign(b);
            let cc = dot(f, f) - r2;
            let (t0, t1) = (cc / q, q * inv_a);
            (t0.min(t1), t0.max(t1), zero.le(disc))
        }
    }
}

/// The first hit of each lane's ray in `(tnear, tfar]`: the lanes that hit (all bits set) and
/// their distance.
#[inline(always)]
pub(crate) fn first_hit<V: Lanes>(test: SphereTest, c: [V; 3], r: V, ray: &RayLanes<V>, tnear: V, tfar: V) -> (V, V) {
    let (t0, t1, meet) = roots(test, c, r, ray);
    let h0 = tnear.lt(t0) & t0.le(tfar);
    let h1 = tnear.lt(t1) & t1.le(tfar);
    (meet & (h0 | h1), h0.sel(t0, t1))
}

/// `a · b`, fused as the triangle tests fuse it.
#[inline(always)]
fn dot<V: Lanes>(a: [V; 3], b: [V; 3]) -> V {
    a[0].madd(b[0], a[1].madd(b[1], a[2] * b[2]))
}

/// The nearest hit of one ray among the spheres of a block in `(tnear, tfar]`, as `(lane, t)`;
/// among equal distances the lowest lane wins.
#[inline(always)]
pub(crate) fn intersect1<F: Four>(
    test: SphereTest,
    b: &SphereBlock,
    ray: &RayLanes<F>,
    tnear: f32,
    tfar: f32,
) -> Option<(usize, f32)> {
    let row = |k: usize| F::new(b.rows[k]);
    let (valid, t) = first_hit(test, [row(0), row(1), row(2)], row(3), ray, F::splat(tnear), F::splat(tfar));
    let zero = F::splat(0.0);
    crate::geometry::triangle::nearest(valid, t, zero, zero).map(|(lane, t, _, _)| (lane, t))
}

/// The lanes of a packet hitting sphere `lane` of `b` in `(tnear, tfar]`, with their distance.
#[inline(always)]
pub(crate) fn intersect_packet<P: SimdF>(
    test: SphereTest,
    b: &SphereBlock,
    lane: usize,
    ray: &RayLanes<P>,
    tnear: P,
    tfar: P,
) -> (P, P) {
    let s = |k: usize| P::splat(b.rows[k][lane]);
    first_hit(test, [s(0), s(1), s(2)], s(3), ray, tnear, tfar)
}

/// Both roots of the ray `o + t d` against the sphere `c, r` in float64 with the robust form, or
/// `None` where the line misses: the reference the tests are measured against.
pub fn roots_f64(c: DVec3, r: f64, o: DVec3, d: DVec3) -> Option<(f64, f64)> {
    let f = o - c;
    let a = d.dot(d);
    let b = -f.dot(d);
    let p = f + d * (b / a);
    let disc = r * r - p.dot(p);
    if disc.is_nan() || disc < 0.0 || a == 0.0 {
        return None;
    }
    let q = b + (a * disc).sqrt().copysign(b);
    let cc = f.dot(f) - r * r;
    let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (cc / q, q / a) };
    Some((t0.min(t1), t0.max(t1)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(test: SphereTest, c: Vec3, r: f32, o: Vec3, d: Vec3) -> Option<(f32, f32)> {
        let s = |x: f32| f32x4::splat(x);
        let (t0, t1, meet) = roots(test, [s(c.x), s(c.y), s(c.z)], s(r), &RayLanes::<f32x4>::splat(o, d));
        (meet.to_bitmask() & 1 != 0).then(|| (t0.to_array()[0], t1.to_array()[0]))
    }

    /// A unit sphere at distance 5 along the ray: roots 4 and 6 with every test, for unit and
    /// scaled directions (t is in units of the direction's length).
    #[test]
    fn roots_of_a_centred_ray() {
        for test in SphereTest::ALL {
            for scale in [1.0f32, 0.5, 3.0] {
                let (t0, t1) = one(test, Vec3::new(0.0, 0.0, 5.0), 1.0, Vec3::ZERO, Vec3::Z * scale).unwrap();
                assert!((t0 * scale - 4.0).abs() < 1e-5 && (t1 * scale - 6.0).abs() < 1e-5, "{test:?} {t0} {t1}");
            }
        }
    }

    /// A line passing outside misses, a ray pointing away from a sphere ahead of nothing misses,
    /// and a ray from inside leaves through the far root.
    #[test]
    fn misses_and_inside() {
        let c = Vec3::new(0.0, 0.0, 5.0);
        for test in SphereTest::ALL {
            assert!(one(test, c, 1.0, Vec3::new(1.01, 0.0, 0.0), Vec3::Z).is_none(), "{test:?}");
            let s = |x: f32| f32x4::splat(x);
            let v = |p: Vec3| [s(p.x), s(p.y), s(p.z)];
            let (ok, _) =
                first_hit(test, v(c), s(1.0), &RayLanes::splat(Vec3::ZERO, -Vec3::Z), s(0.0), s(f32::INFINITY));
            assert_eq!(ok.to_bitmask() & 1, 0, "{test:?}: the sphere lies behind the ray");
            let (ok, t) = first_hit(test, v(c), s(1.0), &RayLanes::splat(c, Vec3::X), s(0.0), s(f32::INFINITY));
            assert_eq!(ok.to_bitmask() & 1, 1, "{test:?}");
            assert!((t.to_array()[0] - 1.0).abs() < 1e-6, "{test:?}");
        }
    }

    /// Far from the origin relative to its radius, the robust test stays within a few ulps of
    /// the float64 roots where the seeds' two forms do not: the measured gap the chart shows.
    #[test]
    fn robust_keeps_accuracy_far_away() {
        let (c, r) = (Vec3::new(0.3, -0.2, 4000.0), 0.5f32);
        let o = Vec3::new(0.0, 0.0, 0.0);
        let mut worst = [0.0f64; 3];
        for i in 0..200 {
            let a = i as f32 / 200.0 * std::f32::consts::TAU;
            let target = c + Vec3::new(a.cos(), a.sin(), 0.0) * (r * 0.7);
            let d = (target - o).normalize();
            let (e0, _) = roots_f64(c.as_dvec3(), r as f64, o.as_dvec3(), d.as_dvec3()).unwrap();
            for (k, test) in SphereTest::ALL.into_iter().enumerate() {
                let (t0, _) = one(test, c, r, o, d).unwrap_or((f32::NAN, f32::NAN));
                let err = ((t0 as f64 - e0) / e0).abs();
                worst[k] = worst[k].max(if err.is_nan() { 1.0 } else { err });
            }
        }
        assert!(worst[2] < 4.0 * f32::EPSILON as f64, "robust {:e}", worst[2]);
        assert!(worst[0] > worst[2] && worst[1] > worst[2], "{worst:?}");
    }
}
