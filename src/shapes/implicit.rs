//! A general implicit surface from a user's function with a Lipschitz bound: the seeds'
//! implicit surfaces for fields no interval form is written for, found by sphere tracing (Hart
//! 1996; Kalra & Barr 1989 bound the field the same way).
//!
//! If `|f(p) − f(q)| ≤ L |p − q|` for all `p, q` in the bounds, then no crossing lies within
//! `|f(p)| / L` of `p`: the trace steps that far, and every step is safe. Crossings are
//! bracketed where the field changes sign between two steps and closed by bisection.
//!
//! **Guarantee**: with a true bound `L`, every crossing is found except pairs closer together
//! than the minimum step (1e-6 of the bounds' diagonal, the CSG's own tolerance) and tangent
//! touches; the trace stops after [`MAX_TRACE_STEPS`] steps (the rest of the chord is taken as
//! not crossed: a documented miss). A bound that is too small voids the guarantee (steps may
//! jump a thin feature); one too large only costs steps. A field that is NaN counts as
//! outside.

use std::fmt;
use std::sync::Arc;

use glam::{DVec3, Vec3};

/// Steps one chord may take before the trace gives up on the rest of it.
pub const MAX_TRACE_STEPS: usize = 100_000;

/// The user's field.
type Field = dyn Fn(DVec3) -> f64 + Send + Sync;
/// The user's gradient, if given.
type Gradient = dyn Fn(DVec3) -> DVec3 + Send + Sync;

/// An implicit solid `{p : f(p) ≤ 0}` inside an axis-aligned box, from a Rust closure and a
/// Lipschitz bound of it over that box (for a signed distance function, 1). Placed and combined
/// like any [`Primitive`](super::Primitive) (as `Primitive::Implicit`); normals by the given
/// gradient, or by the seeds' central differences of `f`.
///
/// ```
/// use glam::{DVec3, Vec3};
/// use strahl::{Implicit, Primitive, Solid};
/// // A rounded box: its signed distance (Lipschitz bound 1).
/// let rounded = Implicit::new(
///     |p: DVec3| (p.abs() - DVec3::splat(0.6)).max(DVec3::ZERO).length() - 0.3,
///     1.0,
///     Vec3::splat(-1.0),
///     Vec3::splat(1.0),
/// );
/// let solid = Solid::new(Primitive::Implicit(std::sync::Arc::new(rounded)));
/// assert!(solid.check().is_ok());
/// ```
#[derive(Clone)]
pub struct Implicit {
    f: Arc<Field>,
    gradient: Option<Arc<Gradient>>,
    lipschitz: f64,
    min: Vec3,
    max: Vec3,
}

impl Implicit {
    /// The solid where `f ≤ 0` inside `[min, max]`, where `lipschitz` bounds `|∇f|`.
    /// [`check`](Self::check) (through [`Solid::check`](super::Solid::check) and the scene
    /// builders) refuses a bound that is not a positive finite number and a box that is not
    /// finite with `min < max`.
    pub fn new(f: impl Fn(DVec3) -> f64 + Send + Sync + 'static, lipschitz: f64, min: Vec3, max: Vec3) -> Self {
        Implicit { f: Arc::new(f), gradient: None, lipschitz, min, max }
    }

    /// The same solid with an analytic gradient for its normals (instead of central
    /// differences).
    pub fn with_gradient(mut self, gradient: impl Fn(DVec3) -> DVec3 + Send + Sync + 'static) -> Self {
        self.gradient = Some(Arc::new(gradient));
        self
    }

    /// The Lipschitz bound.
    pub fn lipschitz(&self) -> f64 {
        self.lipschitz
    }

    /// The box the solid lies in.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        (self.min, self.max)
    }

    /// The field at `p` (object space).
    pub fn field(&self, p: DVec3) -> f64 {
        (self.f)(p)
    }

    /// Why this is no solid, if it is not.
    pub fn check(&self) -> Option<String> {
        if !(self.lipschitz > 0.0 && self.lipschitz.is_finite()) {
            return Some(format!("implicit surface: Lipschitz bound {} must be positive and finite", self.lipschitz));
        }
        if !(self.min.is_finite() && self.max.is_finite() && self.min.cmplt(self.max).all()) {
            return Some(format!(
                "implicit surface: bounds {} to {} must be finite with min < max",
                self.min, self.max
            ));
        }
        None
    }

    pub(crate) fn bounds_f64(&self) -> (DVec3, DVec3) {
        (self.min.as_dvec3(), self.max.as_dvec3())
    }

    /// The outward normal (not normalized) at `p`.
    pub(crate) fn gradient(&self, p: DVec3) -> DVec3 {
        if let Some(g) = &self.gradient {
            let g = g(p);
            if g.is_finite() && g != DVec3::ZERO {
                return g;
            }
        }
        let h = 1e-6 * (self.max - self.min).as_dvec3().length();
        DVec3::from_array(std::array::from_fn(|k| {
            let mut dp = DVec3::ZERO;
            dp[k] = h;
            (self.field(p + dp) - self.field(p - dp)) / (2.0 * h)
        }))
    }

    /// The crossings of the field along `p + s u` (`u` unit) for `s ∈ [0, length]`, ascending,
    /// into `roots` (cleared first); `min_step` is the smallest step. Returns whether the trace
    /// reached the end within [`MAX_TRACE_STEPS`].
    pub(crate) fn trace(&self, p: DVec3, u: DVec3, length: f64, min_step: f64, roots: &mut Vec<f64>) -> bool {
        roots.clear();
        let f = |s: f64| {
            let v = self.field(p + s * u);
            // NaN counts as outside (a positive value that allows no long step).
            if v.is_nan() { min_step * self.lipschitz } else { v }
        };
        let inv_l = 1.0 / self.lipschitz;
        let (mut s, mut fs) = (0.0, f(0.0));
        for _ in 0..MAX_TRACE_STEPS {
            if s >= length {
                return true;
            }
            let next = (s + (fs.abs() * inv_l).max(min_step)).min(length);
            let fn_ = f(next);
            if (fs <= 0.0) != (fn_ <= 0.0) {
                roots.push(bisect(&f, s, fs, next));
            }
            (s, fs) = (next, fn_);
        }
        s >= length
    }
}

/// The crossing in `[a, b]` where the sign changes (`fa` the value at `a`), by bisection to
/// 1e-14 relative (at most 64 halvings).
fn bisect(f: &impl Fn(f64) -> f64, a: f64, fa: f64, b: f64) -> f64 {
    let inside_a = fa <= 0.0;
    let (mut lo, mut hi) = (a, b);
    for _ in 0..64 {
        let m = 0.5 * (lo + hi);
        if hi - lo <= 1e-14 * (1.0 + m.abs()) {
            break;
        }
        if (f(m) <= 0.0) == inside_a {
            lo = m;
        } else {
            hi = m;
        }
    }
    0.5 * (lo + hi)
}

impl fmt::Debug for Implicit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Implicit")
            .field("lipschitz", &self.lipschitz)
            .field("min", &self.min)
            .field("max", &self.max)
            .field("gradient", &self.gradient.is_some())
            .finish_non_exhaustive()
    }
}

/// Two implicit surfaces are equal when they share the same function (the same `Arc`) and
/// parameters: closures cannot be compared.
impl PartialEq for Implicit {
    fn eq(&self, o: &Self) -> bool {
        Arc::ptr_eq(&self.f, &o.f)
            && self.lipschitz == o.lipschitz
            && self.min == o.min
            && self.max == o.max
            && match (&self.gradient, &o.gradient) {
                (Some(a), Some(b)) => Arc::ptr_eq(a, b),
                (None, None) => true,
                _ => false,
            }
    }
}
