//! Blobs (metaballs, "soft objects") on point skeletons: the seeds' potentials summed with
//! weights (negative strengths carve), the surface where the sum equals a threshold. Max and min
//! blends of blobs are CSG union and intersection of them (`{min Fᵢ ≤ 0}` is the union of the
//! `{Fᵢ ≤ 0}`), so a BlobTree is a [`Solid`](super::Solid) tree with blobs at its leaves.
//! Crossings are found by interval root isolation ([`super::interval`]), with each
//! component's squared distance bounded exactly over a piece of the ray.

use std::cell::RefCell;

use glam::{DVec3, Vec3};

use super::csg::dvec;
use super::interval::{Dual, Iv, Real};
use crate::geometry::MAX_COORDINATE;

/// A potential `f(q)` of the squared distance to a component's centre over its squared
/// radius, `q = r²/R²`; each is 1 at the centre and falls to 0 at `q = 1` with a zero slope
/// (the inverse square excepted).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Potential {
    /// POV-Ray's blob density `(1 − q)²` (Wyvill's "soft objects" family).
    Pov,
    /// Wyvill, McPheeters & Wyvill 1986: `1 − 22/9 q + 17/9 q² − 4/9 q³`.
    Wyvill,
    /// The seeds' rational family `(r⁴ − 2r² + 1)/(1 + d·r²) = (1 − q)²/(1 + d q)` (`d > −1`;
    /// `d = 0` is [`Pov`](Self::Pov)).
    Rational {
        /// The shape parameter `d`: larger makes the ball's falloff steeper near the centre.
        d: f32,
    },
    /// Blinn's inverse square `1/q` (infinite support, so every component is summed everywhere).
    InverseSquare,
}

impl Potential {
    /// `f(q)`, written once for points, bounds and derivatives.
    #[inline(always)]
    fn eval<T: Real>(self, q: Dual<T>) -> Dual<T> {
        let one = Dual::c(1.0);
        match self {
            Potential::Pov => {
                let m = one - q.min_c(1.0);
                m * m
            }
            Potential::Wyvill => {
                let q = q.min_c(1.0);
                one + q * (Dual::c(-22.0 / 9.0) + q * (Dual::c(17.0 / 9.0) - Dual::c(4.0 / 9.0) * q))
            }
            Potential::Rational { d } => {
                let q = q.min_c(1.0);
                let m = one - q;
                m * m * (one + Dual::c(d as f64) * q).recip()
            }
            Potential::InverseSquare => q.recip(),
        }
    }

    fn compact(self) -> bool {
        self != Potential::InverseSquare
    }
}

/// One ball of a blob.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlobComponent {
    /// Centre (blob space).
    pub center: Vec3,
    /// Radius of influence `R` (> 0).
    pub radius: f32,
    /// Weight of the potential (non-zero; negative carves).
    pub strength: f32,
}

/// A blob: `Σ sᵢ f(|p − cᵢ|²/Rᵢ²) ≥ threshold` inside (POV-Ray's `blob` with the
/// [`Potential::Pov`] potential). A scene checks it ([`Error::BadSolid`](crate::Error::BadSolid)):
/// a positive finite threshold, finite centres, positive radii, non-zero strengths, at least one
/// positive.
#[derive(Clone, Debug, PartialEq)]
pub struct Blob {
    threshold: f32,
    potential: Potential,
    components: Vec<BlobComponent>,
    /// Object-space bounds, kept (every ray needs them).
    bounds: (DVec3, DVec3),
}

/// Most components one blob may have.
pub const MAX_BLOB_COMPONENTS: usize = 1 << 20;

/// A component seen from one ray: `q(t) = (w2 + 2 t wu + t²)·inv_r2` along a unit direction.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Active {
    w2: f64,
    wu: f64,
    inv_r2: f64,
    strength: f64,
    /// Where the ray is within the component's support.
    t0: f64,
    t1: f64,
}

thread_local! {
    /// The components a ray passes, reused (no allocation per ray once warm).
    pub(crate) static ACTIVE: RefCell<Vec<Active>> = const { RefCell::new(Vec::new()) };
}

impl Blob {
    /// A blob of `components` whose potentials sum to `threshold` on the surface.
    pub fn new(threshold: f32, potential: Potential, components: Vec<BlobComponent>) -> Self {
        let mut b = Blob { threshold, potential, components, bounds: (DVec3::ZERO, DVec3::ZERO) };
        b.bounds = b.compute_bounds();
        b
    }

    /// The level of the surface.
    pub fn threshold(&self) -> f32 {
        self.threshold
    }

    /// The potential every component uses.
    pub fn potential(&self) -> Potential {
        self.potential
    }

    /// The balls.
    pub fn components(&self) -> &[BlobComponent] {
        &self.components
    }

    /// Why this blob describes no shape, if it does not.
    pub(crate) fn check(&self) -> Option<String> {
        if !(self.threshold > 0.0 && self.threshold.is_finite()) {
            return Some(format!("blob threshold {}: must be a positive finite number", self.threshold));
        }
        if let Potential::Rational { d } = self.potential
            && !(d > -1.0 && d.is_finite())
        {
            return Some(format!("blob potential parameter d = {d}: must be finite and > −1"));
        }
        if self.components.len() > MAX_BLOB_COMPONENTS {
            return Some(format!("more than {MAX_BLOB_COMPONENTS} blob components"));
        }
        for (i, c) in self.components.iter().enumerate() {
            if !c.center.is_finite() || c.center.abs().max_element() > MAX_COORDINATE {
                return Some(format!("blob component {i}: centre {} not finite or too far", c.center));
            }
            if !(c.radius > 0.0 && c.radius <= MAX_COORDINATE) {
                return Some(format!("blob component {i}: radius {} must be positive and finite", c.radius));
            }
            if !(c.strength != 0.0 && c.strength.is_finite()) {
                return Some(format!("blob component {i}: strength {} must be finite and non-zero", c.strength));
            }
        }
        if !self.components.iter().any(|c| c.strength > 0.0) {
            return Some("a blob needs a component of positive strength (else it is empty)".into());
        }
        None
    }

    /// How far around its centre a component can reach into the blob: its radius for a compact
    /// potential; for the inverse square, where `sᵢ/q ≥ T/n₊` (some term must reach that
    /// share of the threshold), `R·√(n₊ sᵢ / T)`.
    fn reach(&self, c: &BlobComponent) -> f64 {
        if self.potential.compact() {
            return c.radius as f64;
        }
        let n = self.components.iter().filter(|c| c.strength > 0.0).count() as f64;
        c.radius as f64 * (n * c.strength as f64 / self.threshold as f64).sqrt()
    }

    /// Bounds: the reach of every component of positive strength (outside them all, the sum is
    /// below the threshold).
    pub(crate) fn bounds(&self) -> (DVec3, DVec3) {
        self.bounds
    }

    fn compute_bounds(&self) -> (DVec3, DVec3) {
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for c in self.components.iter().filter(|c| c.strength > 0.0) {
            let p = dvec(c.center);
            let r = self.reach(c);
            lo = lo.min(p - r);
            hi = hi.max(p + r);
        }
        (lo, hi)
    }

    /// The field `T − Σ sᵢ f(qᵢ)`, negative inside, at a point, with its derivative along `dp`.
    pub(crate) fn field_dual(&self, p: DVec3, dp: DVec3) -> Dual<f64> {
        let mut sum = Dual::c(0.0);
        for c in &self.components {
            let w = p - dvec(c.center);
            let inv = 1.0 / (c.radius as f64 * c.radius as f64);
            let q = Dual { v: w.dot(w) * inv, d: 2.0 * w.dot(dp) * inv };
            sum = sum + Dual::c(c.strength as f64) * self.potential.eval(q);
        }
        Dual::c(self.threshold as f64) - sum
    }

    /// The field at a point.
    pub(crate) fn field(&self, p: DVec3) -> f64 {
        self.field_dual(p, DVec3::ZERO).v
    }

    /// The analytic gradient at `p`.
    pub(crate) fn gradient(&self, p: DVec3) -> DVec3 {
        DVec3::new(self.field_dual(p, DVec3::X).d, self.field_dual(p, DVec3::Y).d, self.field_dual(p, DVec3::Z).d)
    }

    /// The components the line `p + t u` (unit `u`) passes within their reach, with the
    /// stretch of `t` where it does, into `out` (cleared first).
    pub(crate) fn activate(&self, p: DVec3, u: DVec3, out: &mut Vec<Active>) {
        out.clear();
        for c in &self.components {
            let w = p - dvec(c.center);
            let (w2, wu) = (w.dot(w), w.dot(u));
            let inv_r2 = 1.0 / (c.radius as f64 * c.radius as f64);
            let strength = c.strength as f64;
            if !self.potential.compact() {
                out.push(Active { w2, wu, inv_r2, strength, t0: f64::NEG_INFINITY, t1: f64::INFINITY });
                continue;
            }
            let r = c.radius as f64;
            let disc = r * r - (w2 - wu * wu);
            if disc > 0.0 {
                let h = disc.sqrt();
                out.push(Active { w2, wu, inv_r2, strength, t0: -wu - h, t1: -wu + h });
            }
        }
    }

    /// Bounds of the field and its derivative along the line over `t ∈ [a, b]`, from the
    /// components active there: each `q` is bounded exactly (a parabola in `t`).
    pub(crate) fn range(&self, active: &[Active], a: f64, b: f64) -> Dual<Iv> {
        let mut sum = Dual::c(0.0);
        for c in active {
            if c.t1 < a || c.t0 > b {
                continue;
            }
            let q = |t: f64| (c.w2 + t * (2.0 * c.wu + t)) * c.inv_r2;
            let (qa, qb) = (q(a), q(b));
            let vertex = -c.wu;
            let lo = if vertex > a && vertex < b { (c.w2 - c.wu * c.wu).max(0.0) * c.inv_r2 } else { qa.min(qb) };
            let qi = Dual {
                v: Iv { lo, hi: qa.max(qb) },
                d: Iv::new(2.0 * (a + c.wu) * c.inv_r2, 2.0 * (b + c.wu) * c.inv_r2),
            };
            sum = sum + Dual::c(c.strength) * self.potential.eval(qi);
        }
        Dual::c(self.threshold as f64) - sum
    }

    /// The field and its derivative along the line at `t`.
    pub(crate) fn point(&self, active: &[Active], t: f64) -> Dual<f64> {
        let mut sum = Dual::c(0.0);
        for c in active {
            if t < c.t0 || t > c.t1 {
                continue;
            }
            let qi = Dual { v: (c.w2 + t * (2.0 * c.wu + t)) * c.inv_r2, d: 2.0 * (t + c.wu) * c.inv_r2 };
            sum = sum + Dual::c(c.strength) * self.potential.eval(qi);
        }
        Dual::c(self.threshold as f64) - sum
    }
}
