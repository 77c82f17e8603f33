//! Root isolation by interval arithmetic, for implicit shapes no closed form solves
//! (superellipsoids, blobs): the seeds' implicit surfaces, found with a guarantee instead of
//! Laguerre's starting-point luck (Mitchell 1990, "Robust ray intersection with interval
//! arithmetic"; Kalra & Barr 1989 use a Lipschitz bound for the same end).
//!
//! A shape writes its field once, generically over [`Real`]; evaluated on [`Iv`] intervals it
//! bounds the field over a piece of the ray, on [`Dual`] numbers it also gives the derivative
//! along the ray, and on `f64` it gives point values. [`isolate`] splits the ray's chord until
//! every piece either cannot hold a crossing (the field's bounds exclude 0), is monotone (the
//! derivative's bounds exclude 0: at most one crossing, refined by safeguarded Newton), or is
//! thinner than the resolution `eps`.
//!
//! **Guarantee**: every crossing is found except pairs of crossings closer together than `eps`
//! (a feature thinner than `eps` along the ray, which the CSG's tolerance drops anyway) and
//! tangent touches — up to float64 rounding in the bounds (no directed rounding), and unless the
//! budget of interval evaluations runs out, which [`isolate`] reports.

use std::ops::{Add, Mul, Neg, Sub};

/// A closed interval `[lo, hi]` of float64 (rounded to nearest, not outwards).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Iv {
    pub lo: f64,
    pub hi: f64,
}

impl Iv {
    /// The interval between `a` and `b`, in either order.
    pub fn new(a: f64, b: f64) -> Self {
        Iv { lo: a.min(b), hi: a.max(b) }
    }

    pub fn point(x: f64) -> Self {
        Iv { lo: x, hi: x }
    }

    const ALL: Iv = Iv { lo: f64::NEG_INFINITY, hi: f64::INFINITY };

    /// Whether 0 lies inside (or a bound is NaN: nothing is known).
    pub fn holds_zero(self) -> bool {
        !(self.lo > 0.0 || self.hi < 0.0)
    }
}

/// The arithmetic a field is written in: `f64` for points, [`Iv`] for bounds over a piece of
/// the ray, [`Dual`] for a derivative alongside.
pub(crate) trait Real:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Neg<Output = Self>
{
    fn c(x: f64) -> Self;
    fn abs(self) -> Self;
    /// The sign, −1, 0 or 1 (for an interval, the hull of its values' signs).
    fn sign(self) -> Self;
    /// `self^p` for `self ≥ 0` (negative parts are taken as 0).
    fn powf(self, p: f64) -> Self {
        self.pow_d(p).0
    }
    /// `self^p` and its derivative `p·self^(p−1)`, for `self ≥ 0`, together (one `powf`).
    fn pow_d(self, p: f64) -> (Self, Self);
    /// `min(self, c)`, with the derivative of a [`Dual`] (0 where the constant is taken).
    fn min_dual(v: Self, d: Self, c: f64) -> (Self, Self);
    fn recip(self) -> Self;
    /// The hull with 0 (for the derivative of `min` where both sides are taken).
    fn with_zero(self) -> Self;
    /// `max(a, b)` of two (value, derivative) pairs: the larger one's derivative, the hull of
    /// both where an interval cannot tell which is larger.
    fn max_dual(a: (Self, Self), b: (Self, Self)) -> (Self, Self);
    /// `max(self, o)`.
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        Self::max_dual((self, self), (o, o)).0
    }
}

impl Real for f64 {
    #[inline(always)]
    fn c(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline(always)]
    fn sign(self) -> Self {
        if self > 0.0 {
            1.0
        } else if self < 0.0 {
            -1.0
        } else {
            0.0
        }
    }
    #[inline(always)]
    fn pow_d(self, p: f64) -> (Self, Self) {
        let x = self.max(0.0);
        if x == 0.0 {
            return (pow(0.0, p), p * pow(0.0, p - 1.0));
        }
        let w = pow(x, p - 1.0);
        (w * x, p * w)
    }
    #[inline(always)]
    fn min_dual(v: Self, d: Self, c: f64) -> (Self, Self) {
        if v < c { (v, d) } else { (c, 0.0) }
    }
    #[inline(always)]
    fn recip(self) -> Self {
        1.0 / self
    }
    #[inline(always)]
    fn with_zero(self) -> Self {
        self
    }
    #[inline(always)]
    fn max_dual(a: (Self, Self), b: (Self, Self)) -> (Self, Self) {
        if a.0 >= b.0 || b.0.is_nan() { a } else { b }
    }
}

impl Add for Iv {
    type Output = Iv;
    #[inline(always)]
    fn add(self, o: Iv) -> Iv {
        Iv { lo: self.lo + o.lo, hi: self.hi + o.hi }
    }
}

impl Sub for Iv {
    type Output = Iv;
    #[inline(always)]
    fn sub(self, o: Iv) -> Iv {
        Iv { lo: self.lo - o.hi, hi: self.hi - o.lo }
    }
}

impl Neg for Iv {
    type Output = Iv;
    #[inline(always)]
    fn neg(self) -> Iv {
        Iv { lo: -self.hi, hi: -self.lo }
    }
}

impl Mul for Iv {
    type Output = Iv;
    #[inline(always)]
    fn mul(self, o: Iv) -> Iv {
        let p = [self.lo * o.lo, self.lo * o.hi, self.hi * o.lo, self.hi * o.hi];
        if p.iter().any(|x| x.is_nan()) {
            // 0 · ∞: nothing is known.
            return Iv::ALL;
        }
        Iv { lo: p[0].min(p[1]).min(p[2]).min(p[3]), hi: p[0].max(p[1]).max(p[2]).max(p[3]) }
    }
}

impl Real for Iv {
    #[inline(always)]
    fn c(x: f64) -> Self {
        Iv::point(x)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        if self.lo >= 0.0 {
            self
        } else if self.hi <= 0.0 {
            -self
        } else {
            Iv { lo: 0.0, hi: (-self.lo).max(self.hi) }
        }
    }
    #[inline(always)]
    fn sign(self) -> Self {
        Iv { lo: self.lo.sign(), hi: self.hi.sign() }
    }
    #[inline(always)]
    fn pow_d(self, p: f64) -> (Self, Self) {
        // x^p and p·x^(p−1) are monotone on x ≥ 0: the ends bound them.
        let (a, da) = self.lo.pow_d(p);
        let (b, db) = self.hi.pow_d(p);
        (Iv::new(a, b), Iv::new(da, db))
    }
    #[inline(always)]
    fn min_dual(v: Self, d: Self, c: f64) -> (Self, Self) {
        if v.hi <= c {
            (v, d)
        } else if v.lo >= c {
            (Iv::point(c), Iv::point(0.0))
        } else {
            (Iv { lo: v.lo, hi: c }, d.with_zero())
        }
    }
    #[inline(always)]
    fn recip(self) -> Self {
        if self.lo > 0.0 || self.hi < 0.0 {
            Iv { lo: 1.0 / self.hi, hi: 1.0 / self.lo }
        } else if self.lo == 0.0 && self.hi > 0.0 {
            Iv { lo: 1.0 / self.hi, hi: f64::INFINITY }
        } else {
            Iv::ALL
        }
    }
    #[inline(always)]
    fn with_zero(self) -> Self {
        Iv { lo: self.lo.min(0.0), hi: self.hi.max(0.0) }
    }
    #[inline(always)]
    fn max_dual(a: (Self, Self), b: (Self, Self)) -> (Self, Self) {
        if a.0.lo >= b.0.hi {
            a
        } else if b.0.lo >= a.0.hi {
            b
        } else {
            let v = Iv { lo: a.0.lo.max(b.0.lo), hi: a.0.hi.max(b.0.hi) };
            (v, Iv { lo: a.1.lo.min(b.1.lo), hi: a.1.hi.max(b.1.hi) })
        }
    }
}

/// A value and its derivative along one direction (forward-mode automatic differentiation):
/// the analytic gradient of a field written once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Dual<T> {
    pub v: T,
    pub d: T,
}

impl<T: Real> Dual<T> {
    /// A variable with derivative `d`.
    pub fn var(v: T, d: T) -> Self {
        Dual { v, d }
    }
}

impl<T: Real> Add for Dual<T> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Dual { v: self.v + o.v, d: self.d + o.d }
    }
}

impl<T: Real> Sub for Dual<T> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Dual { v: self.v - o.v, d: self.d - o.d }
    }
}

impl<T: Real> Neg for Dual<T> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Dual { v: -self.v, d: -self.d }
    }
}

impl<T: Real> Mul for Dual<T> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        Dual { v: self.v * o.v, d: self.d * o.v + self.v * o.d }
    }
}

impl<T: Real> Real for Dual<T> {
    #[inline(always)]
    fn c(x: f64) -> Self {
        Dual { v: T::c(x), d: T::c(0.0) }
    }
    #[inline(always)]
    fn abs(self) -> Self {
        Dual { v: self.v.abs(), d: self.d * self.v.sign() }
    }
    #[inline(always)]
    fn sign(self) -> Self {
        Dual { v: self.v.sign(), d: T::c(0.0) }
    }
    #[inline(always)]
    fn pow_d(self, p: f64) -> (Self, Self) {
        // Only `powf` uses this: the second result's own derivative is not needed (left 0).
        let (v, dv) = self.v.pow_d(p);
        (Dual { v, d: self.d * dv }, Dual { v: dv, d: T::c(0.0) })
    }
    #[inline(always)]
    fn min_dual(v: Self, _d: Self, c: f64) -> (Self, Self) {
        // Nested duals are not used.
        (v.min_c(c), Dual::c(0.0))
    }
    #[inline(always)]
    fn recip(self) -> Self {
        let r = self.v.recip();
        Dual { v: r, d: -(self.d * r * r) }
    }
    #[inline(always)]
    fn with_zero(self) -> Self {
        Dual { v: self.v.with_zero(), d: self.d.with_zero() }
    }
    #[inline(always)]
    fn max_dual(a: (Self, Self), b: (Self, Self)) -> (Self, Self) {
        // Nested duals are not used: only the value pair is taken through.
        let (v, d) = T::max_dual((a.0.v, a.0.d), (b.0.v, b.0.d));
        (Dual { v, d }, Dual::c(0.0))
    }
}

impl<T: Real> Dual<T> {
    /// `min(self, c)`.
    #[inline(always)]
    pub fn min_c(self, c: f64) -> Self {
        let (v, d) = T::min_dual(self.v, self.d, c);
        Dual { v, d }
    }
}

/// `x^p` for `x ≥ 0`, by multiplication where `p` is a small integer (common exponents: the
/// superellipsoid's `2/e` for `e` = 1, 0.5, 0.2 …), as POV-Ray's `power` does; `powf` else.
#[inline(always)]
fn pow(x: f64, p: f64) -> f64 {
    if p == 1.0 {
        x
    } else if p == 0.0 {
        1.0
    } else if p.fract() == 0.0 && p.abs() <= 64.0 {
        x.powi(p as i32)
    } else {
        x.powf(p)
    }
}

/// How [`isolate`] went.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Isolation {
    /// Every crossing (but those the guarantee excepts) was found.
    Complete,
    /// The budget of interval evaluations ran out; the chord beyond the last piece examined was
    /// taken as not crossed.
    BudgetExhausted,
}

/// Interval evaluations [`isolate`] may spend on one chord.
pub(crate) const ISOLATION_BUDGET: usize = 4096;

/// Reused buffers of [`isolate`]: the crossings found, and the pieces still to examine.
#[derive(Default)]
pub(crate) struct IsolationScratch {
    pub roots: Vec<f64>,
    /// `(a, f(a), b, f(b))`.
    stack: Vec<(f64, f64, f64, f64)>,
}

/// Deepest the splitting goes (with `eps` 1e-9 of the chord, 30 levels suffice).
const MAX_DEPTH: usize = 96;

/// Finds the crossings of the field along the chord `[t0, t1]`, ascending, into
/// `scratch.roots` (cleared first). `range(a, b)` bounds the field and its derivative over
/// `[a, b]`; `point(t)` gives both at `t`. Pieces thinner than `eps` are not split further.
pub(crate) fn isolate(
    range: impl Fn(f64, f64) -> Dual<Iv>,
    point: impl Fn(f64) -> Dual<f64>,
    t0: f64,
    t1: f64,
    eps: f64,
    scratch: &mut IsolationScratch,
) -> Isolation {
    let IsolationScratch { roots, stack } = scratch;
    roots.clear();
    stack.clear();
    // Depth-first, left piece first, so roots come out ascending.
    stack.push((t0, point(t0).v, t1, point(t1).v));
    let mut spent = 0;
    while let Some((a, fa, b, fb)) = stack.pop() {
        spent += 1;
        if spent > ISOLATION_BUDGET {
            return Isolation::BudgetExhausted;
        }
        let r = range(a, b);
        if !r.v.holds_zero() {
            continue;
        }
        let change = (fa <= 0.0) != (fb <= 0.0);
        if !r.d.holds_zero() || b - a < eps {
            // Monotone (or too thin to split): one crossing where the ends' signs differ.
            if change {
                roots.push(refine(&point, a, fa, b));
            }
            continue;
        }
        if stack.len() >= MAX_DEPTH {
            return Isolation::BudgetExhausted;
        }
        let m = 0.5 * (a + b);
        let fm = point(m).v;
        stack.push((m, fm, b, fb));
        stack.push((a, fa, m, fm));
    }
    Isolation::Complete
}

/// The crossing in `[a, b]` where the field's sign changes (`fa` its value at `a`): safeguarded
/// Newton, bisecting whenever a step leaves the bracket. A Newton step shorter than the
/// tolerance is lengthened to it, so that the next value closes the bracket around the root; if
/// it does not (a cusp, where the slope is infinite and the steps vanish far from any root: the
/// pinched superellipsoid's edges), a bisection follows. Returns the middle of a bracket no
/// wider than the tolerance; at most 200 steps.
fn refine(point: &impl Fn(f64) -> Dual<f64>, a: f64, fa: f64, b: f64) -> f64 {
    let inside_a = fa <= 0.0;
    let (mut lo, mut hi) = (a, b);
    let mut t = 0.5 * (a + b);
    let mut bisect = false;
    for _ in 0..200 {
        let f = point(t);
        if f.v == 0.0 {
            return t;
        }
        if (f.v <= 0.0) == inside_a {
            lo = t;
        } else {
            hi = t;
        }
        let tol = 1e-14 * (1.0 + t.abs());
        if hi - lo <= tol {
            break;
        }
        let newton = t - f.v / f.d;
        t = if bisect || !(newton > lo && newton < hi) {
            bisect = false;
            0.5 * (lo + hi)
        } else if (newton - t).abs() < tol {
            bisect = true;
            (t + tol.copysign(newton - t)).clamp(lo, hi)
        } else {
            newton
        };
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intervals_bound_the_values_they_stand_for() {
        let f = |x: Iv| (x * x - Iv::c(0.5)).abs().powf(1.5) + x.recip().min_c_iv(3.0);
        let a = Iv::new(0.2, 0.9);
        let r = f(a);
        for k in 0..=100 {
            let x = 0.2 + 0.7 * k as f64 / 100.0;
            let v = ((x * x - 0.5).abs()).powf(1.5) + (1.0 / x).min(3.0);
            assert!(v >= r.lo - 1e-12 && v <= r.hi + 1e-12, "{x} {v} {r:?}");
        }
    }

    impl Iv {
        fn min_c_iv(self, c: f64) -> Iv {
            Iv::min_dual(self, Iv::c(0.0), c).0
        }
    }

    #[test]
    fn isolation_finds_close_roots_and_no_spurious_ones() {
        // (t − 0.3)(t − 0.3001)(t − 0.7): two crossings 1e-4 apart, which sampling misses.
        let f = |t: Dual<Iv>| (t - Dual::c(0.3)) * (t - Dual::c(0.3001)) * (t - Dual::c(0.7));
        let range = |a: f64, b: f64| f(Dual::var(Iv::new(a, b), Iv::c(1.0)));
        let point = |t: f64| {
            let g = |t: Dual<f64>| (t - Dual::c(0.3)) * (t - Dual::c(0.3001)) * (t - Dual::c(0.7));
            g(Dual::var(t, 1.0))
        };
        let mut scratch = IsolationScratch::default();
        assert_eq!(isolate(range, point, 0.0, 1.0, 1e-9, &mut scratch), Isolation::Complete);
        let roots = &scratch.roots;
        assert_eq!(roots.len(), 3, "{roots:?}");
        for (r, want) in roots.iter().zip([0.3, 0.3001, 0.7]) {
            assert!((r - want).abs() < 1e-12, "{roots:?}");
        }
        // A double root (a tangent touch) is no crossing.
        let range = |a: f64, b: f64| {
            let t = Dual::var(Iv::new(a, b), Iv::c(1.0));
            (t - Dual::c(0.4)) * (t - Dual::c(0.4))
        };
        let point = |t: f64| {
            let t = Dual::var(t, 1.0);
            (t - Dual::c(0.4)) * (t - Dual::c(0.4))
        };
        let done = isolate(range, point, 0.0, 1.0, 1e-9, &mut scratch);
        assert_eq!(done, Isolation::Complete);
        assert!(scratch.roots.is_empty(), "{:?}", scratch.roots);
    }

    #[test]
    fn refinement_crosses_cusps_and_budgets_end_wild_fields() {
        // |t − 0.3|^(1/3)·sign − 1e-6: an infinite slope next to the root, where Newton's steps
        // vanish; the bracket must still close on the root.
        let f = |t: f64| {
            let x = t - 0.3;
            Dual { v: x.abs().powf(1.0 / 3.0).copysign(x) - 1e-6, d: x.abs().powf(-2.0 / 3.0) / 3.0 }
        };
        let r = refine(&f, 0.0, f(0.0).v, 1.0);
        assert!((r - (0.3 + 1e-18)).abs() < 1e-13, "{r}");
        // A field crossing zero 20,000 times: the budget ends the isolation, reported.
        let wild = |t: f64| Dual { v: (t * 4e4 * std::f64::consts::PI).sin(), d: 1.0 };
        let range = |_: f64, _: f64| Dual { v: Iv::new(-1.0, 1.0), d: Iv::new(-1.0, 1.0) };
        let mut scratch = IsolationScratch::default();
        let done = isolate(range, wild, 0.0, 1.0, 1e-12, &mut scratch);
        assert_eq!(done, Isolation::BudgetExhausted);
        assert!(scratch.roots.len() < ISOLATION_BUDGET, "{}", scratch.roots.len());
    }
}
