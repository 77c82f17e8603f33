//! The superellipsoid (Barr 1981; POV-Ray's `superellipsoid { <e, n> }`): the seeds'
//! superquadric with `|x|^p` terms, whose crossings no closed form gives. Found by interval root
//! isolation ([`super::interval`]), which cannot skip a thin feature (the guarantee there).

use glam::DVec3;

use super::interval::{Dual, Iv, Real};

/// The field of `(|x|^(2/e) + |y|^(2/e))^(e/n) + |z|^(2/n) ≤ 1`, negative inside, written once
/// for points, bounds and derivatives: in the homogeneous form POV-Ray evaluates,
/// `((|x|^a + |y|^a)^(c/a) + |z|^c)^(1/c) − 1` with `a = 2/e`, `c = 2/n`, which grows like
/// distance along a ray (a norm, for `e, n ≤ 2`), so Newton converges in a few steps even for
/// the large exponents of a rounded box: measured on 2,000 rays at e = n = 0.2, 7.7 point
/// evaluations a root (split points and Newton steps) against 18.6 on the plain form.
#[inline(always)]
pub(crate) fn field<T: Real>(e: f64, n: f64, [x, y, z]: [T; 3]) -> T {
    let (a, c) = (2.0 / e, 2.0 / n);
    ((x.abs().powf(a) + y.abs().powf(a)).powf(c / a) + z.abs().powf(c)).powf(1.0 / c) - T::c(1.0)
}

/// Bounds of the field and its derivative along `o + t u` over `t ∈ [a, b]`.
pub(crate) fn range(e: f64, n: f64, o: DVec3, u: DVec3, a: f64, b: f64) -> Dual<Iv> {
    let c = |k: usize| Dual::var(Iv::new(o[k] + a * u[k], o[k] + b * u[k]), Iv::point(u[k]));
    field(e, n, [c(0), c(1), c(2)])
}

/// The field and its derivative along `u` at `o + t u`.
pub(crate) fn point(e: f64, n: f64, o: DVec3, u: DVec3, t: f64) -> Dual<f64> {
    let c = |k: usize| Dual::var(o[k] + t * u[k], u[k]);
    field(e, n, [c(0), c(1), c(2)])
}

/// The analytic gradient at `p` (three forward passes); where it is not finite (on an axis of a
/// pinched superellipsoid, `e` or `n > 2`) central differences stand in.
pub(crate) fn gradient(e: f64, n: f64, p: DVec3) -> DVec3 {
    let g = DVec3::from_array(std::array::from_fn(|k| {
        let c = |j: usize| Dual::var(p[j], if j == k { 1.0 } else { 0.0 });
        field(e, n, [c(0), c(1), c(2)]).d
    }));
    if g.is_finite() && g != DVec3::ZERO { g } else { central_difference(|q| field(e, n, q.to_array()), p) }
}

/// The seeds' normal by central differences of the field (step 1e-6 of the unit shape).
pub(crate) fn central_difference(f: impl Fn(DVec3) -> f64, p: DVec3) -> DVec3 {
    const H: f64 = 1e-6;
    DVec3::from_array(std::array::from_fn(|k| {
        let mut dp = DVec3::ZERO;
        dp[k] = H;
        (f(p + dp) - f(p - dp)) / (2.0 * H)
    }))
}
