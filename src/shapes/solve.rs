//! Root finders for the shapes' polynomials, in float64: the stable quadratic formula, and two
//! quartic solvers for the torus — Ferrari's closed form, and Yuksel's bracketed solver, which
//! isolates every real root in an interval between the critical points (the roots of the
//! derivative, found the same way one degree down) and cannot skip one.
//!
//! Coefficients are given lowest degree first: `c[k]` multiplies `x^k`.

/// How a torus's quartic is solved (see [`Primitive::Torus`](super::Primitive::Torus)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum QuarticSolver {
    /// Ferrari's closed form through the resolvent cubic (Cardano), each root then polished by
    /// one Newton step on the quartic — POV-Ray's `solve_quartic` practice. Fast; loses roots
    /// where the resolvent's cancellation is severe (grazing rays, thin tubes).
    Ferrari,
    /// Yuksel's bracketed solver (C. Yuksel, "High-Performance Polynomial Root Finding for
    /// Graphics", HPG 2022): the roots of the derivatives split the interval into monotone
    /// pieces, and each piece whose ends differ in sign holds exactly one root, found by Newton
    /// steps kept inside the bracket (bisection where a step leaves it). Every simple root in the
    /// interval is found; a double root (a tangent ray) reads as none.
    #[default]
    Bracketed,
    /// The seeds' Laguerre iteration in complex arithmetic, each root deflated out of the
    /// polynomial before the next is sought, then every near-real root polished by Newton steps
    /// on the undeflated quartic (Numerical Recipes' `zroots`). Converges from anywhere, but a
    /// root close to another may come out complex and be dropped.
    Laguerre,
}

impl QuarticSolver {
    /// Every solver.
    pub const ALL: [QuarticSolver; 3] = [QuarticSolver::Ferrari, QuarticSolver::Bracketed, QuarticSolver::Laguerre];

    /// The solver's name, as the harness and scene files spell it.
    pub fn name(self) -> &'static str {
        match self {
            QuarticSolver::Ferrari => "ferrari",
            QuarticSolver::Bracketed => "bracketed",
            QuarticSolver::Laguerre => "laguerre",
        }
    }
}

/// Maximum Newton or bisection steps per bracketed root: 64 halvings of an f64 bracket reach its
/// last bit, so no input can loop longer.
const MAX_STEPS: usize = 64;

/// `p(x)` and `p'(x)` by Horner's rule.
#[inline(always)]
fn eval<const N: usize>(c: &[f64; N], x: f64) -> (f64, f64) {
    let mut p = c[N - 1];
    let mut dp = 0.0;
    for k in (0..N - 1).rev() {
        dp = dp * x + p;
        p = p * x + c[k];
    }
    (p, dp)
}

/// The real roots of `c[2] x² + c[1] x + c[0]` in ascending order (the form that does not cancel:
/// `q = −(b + sign(b)·√Δ)/2`, roots `q/a` and `c/q`); a linear or constant polynomial gives its
/// one root or none. A double root is returned twice.
#[inline(always)]
pub fn quadratic(c: [f64; 3]) -> ([f64; 2], usize) {
    let [c0, b, a] = c;
    if a == 0.0 {
        return if b != 0.0 { ([-c0 / b, 0.0], 1) } else { ([0.0; 2], 0) };
    }
    let disc = b * b - 4.0 * a * c0;
    if disc < 0.0 || disc.is_nan() {
        return ([0.0; 2], 0);
    }
    let q = -0.5 * (b + disc.sqrt().copysign(b));
    let (r0, r1) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c0 / q) };
    ([r0.min(r1), r0.max(r1)], 2)
}

/// The roots of a polynomial in `[lo, hi]` whose critical points are `crit` (ascending; those
/// not strictly inside the interval add nothing and are skipped): each monotone piece whose ends
/// differ in sign holds one root.
#[inline(always)]
fn between<const N: usize>(c: &[f64; N], crit: &[f64], lo: f64, hi: f64, out: &mut [f64]) -> usize {
    let mut n = 0;
    let mut a = lo;
    let mut fa = eval(c, a).0;
    let inside = crit.iter().filter(|&&x| x > lo && x < hi);
    for &b in inside.chain(std::iter::once(&hi)) {
        let fb = eval(c, b).0;
        if fa == 0.0 {
            if n == 0 || out[n - 1] != a {
                out[n] = a;
                n += 1;
            }
        } else if fa.signum() != fb.signum() && fb != 0.0 {
            out[n] = root_in(c, a, b, fa);
            n += 1;
        }
        a = b;
        fa = fb;
    }
    if fa == 0.0 && (n == 0 || out[n - 1] != hi) {
        out[n] = hi;
        n += 1;
    }
    n
}

/// The one root in `[a, b]`, where `p(a) = fa` and `p(b)` differ in sign and `p` is monotone:
/// Newton from the bracket's middle, bisecting where a step would leave the bracket.
#[inline(always)]
fn root_in<const N: usize>(c: &[f64; N], mut a: f64, mut b: f64, fa: f64) -> f64 {
    let neg_at_a = fa < 0.0;
    let mut x = 0.5 * (a + b);
    for _ in 0..MAX_STEPS {
        let (f, df) = eval(c, x);
        if f == 0.0 {
            return x;
        }
        // Shrink the bracket to the side holding the sign change.
        if (f < 0.0) == neg_at_a {
            a = x;
        } else {
            b = x;
        }
        let step = f / df;
        let next = x - step;
        // Converged: the step is below the last bit (`x` itself may be an end of the bracket
        // now, so `next` may fall on or just outside it).
        if step.abs() <= f64::EPSILON * x.abs() {
            return if next >= a && next <= b { next } else { x };
        }
        x = if next > a && next < b { next } else { 0.5 * (a + b) };
        if (b - a) <= 4.0 * f64::EPSILON * x.abs().max(f64::MIN_POSITIVE) {
            break;
        }
    }
    x
}

/// The real roots of the cubic `c` in `[lo, hi]`, ascending, each simple root once.
#[inline(always)]
pub fn cubic_in(c: [f64; 4], lo: f64, hi: f64, out: &mut [f64; 3]) -> usize {
    if c[3] == 0.0 {
        let (r, n) = quadratic([c[0], c[1], c[2]]);
        let mut k = 0;
        for &x in &r[..n] {
            if x >= lo && x <= hi && (k == 0 || out[k - 1] != x) {
                out[k] = x;
                k += 1;
            }
        }
        return k;
    }
    let (crit, nc) = quadratic([c[1], 2.0 * c[2], 3.0 * c[3]]);
    between(&c, &crit[..nc], lo, hi, out)
}

/// The real roots of the quartic `c` in `[lo, hi]`, ascending, by [`QuarticSolver::Bracketed`].
#[inline(always)]
pub fn quartic_in(c: [f64; 5], lo: f64, hi: f64, out: &mut [f64; 4]) -> usize {
    if c[4] == 0.0 {
        let mut r = [0.0; 3];
        let n = cubic_in([c[0], c[1], c[2], c[3]], lo, hi, &mut r);
        out[..n].copy_from_slice(&r[..n]);
        return n;
    }
    let mut crit = [0.0; 3];
    let nc = cubic_in([c[1], 2.0 * c[2], 3.0 * c[3], 4.0 * c[4]], lo, hi, &mut crit);
    between(&c, &crit[..nc], lo, hi, out)
}

/// The largest real root of the monic cubic `x³ + a x² + b x + c` (Cardano, or the
/// trigonometric form where there are three real roots).
fn cubic_largest(a: f64, b: f64, c: f64) -> f64 {
    let q = (a * a - 3.0 * b) / 9.0;
    let r = (2.0 * a * a * a - 9.0 * a * b + 27.0 * c) / 54.0;
    let shift = a / 3.0;
    if r * r < q * q * q {
        let theta = (r / (q * q * q).sqrt()).clamp(-1.0, 1.0).acos();
        -2.0 * q.sqrt() * (theta / 3.0).cos() - shift
    } else {
        let big = -(r.abs() + (r * r - q * q * q).sqrt()).cbrt().copysign(r);
        let small = if big != 0.0 { q / big } else { 0.0 };
        big + small - shift
    }
}

/// The real roots of the quartic `c` in `[lo, hi]`, ascending, by Ferrari's method (see
/// [`QuarticSolver::Ferrari`]).
pub fn quartic_ferrari(c: [f64; 5], lo: f64, hi: f64, out: &mut [f64; 4]) -> usize {
    if c[4] == 0.0 {
        let mut r = [0.0; 3];
        let n = cubic_in([c[0], c[1], c[2], c[3]], lo, hi, &mut r);
        out[..n].copy_from_slice(&r[..n]);
        return n;
    }
    // Monic x⁴ + a x³ + b x² + cc x + d, then depressed by x = y − a/4: y⁴ + p y² + q y + r.
    let (a, b, cc, d) = (c[3] / c[4], c[2] / c[4], c[1] / c[4], c[0] / c[4]);
    let a2 = a * a;
    let p = b - 0.375 * a2;
    let q = cc - 0.5 * a * b + 0.125 * a2 * a;
    let r = d - 0.25 * a * cc + 0.0625 * a2 * b - 3.0 / 256.0 * a2 * a2;
    let mut ys = [0.0; 4];
    let mut n = 0;
    let push_quadratic = |qc: [f64; 3], ys: &mut [f64; 4], n: &mut usize| {
        let (rr, k) = quadratic(qc);
        for &y in &rr[..k] {
            ys[*n] = y;
            *n += 1;
        }
    };
    // The resolvent 8m³ + 8p m² + (2p² − 8r) m − q² = 0 has a root m ≥ 0; with it,
    // (y² + p/2 + m)² = 2m (y − q/(4m))², two quadratics.
    let m = cubic_largest(p, 0.25 * p * p - r, -0.125 * q * q);
    if m > 1e-14 * (p.abs() + r.abs().sqrt() + 1e-300) {
        let s = (2.0 * m).sqrt();
        let t = q / (2.0 * s);
        // y² + p/2 + m = ±(s y − t), s = √(2m), t = q / (2s).
        push_quadratic([0.5 * p + m + t, -s, 1.0], &mut ys, &mut n);
        push_quadratic([0.5 * p + m - t, s, 1.0], &mut ys, &mut n);
    } else {
        // q ≈ 0: a biquadratic, y² = z with z² + p z + r = 0.
        let (zs, k) = quadratic([r, p, 1.0]);
        for &z in &zs[..k] {
            if z >= 0.0 {
                let y = z.sqrt();
                ys[n] = -y;
                ys[n + 1] = y;
                n += 2;
            }
        }
    }
    let mut k = 0;
    for &y in &ys[..n] {
        let mut x = y - 0.25 * a;
        // One Newton step on the undepressed quartic (POV-Ray polishes its roots likewise).
        let (f, df) = eval(&c, x);
        if df != 0.0 {
            x -= f / df;
        }
        if x >= lo && x <= hi {
            out[k] = x;
            k += 1;
        }
    }
    // A double root found twice (from both quadratics) counts once.
    sorted_distinct(out, k)
}

/// Sorts `out[..n]` and keeps each value once; returns how many remain.
fn sorted_distinct(out: &mut [f64; 4], n: usize) -> usize {
    out[..n].sort_unstable_by(f64::total_cmp);
    let mut m = 0;
    for i in 0..n {
        if m == 0 || out[i] != out[m - 1] {
            out[m] = out[i];
            m += 1;
        }
    }
    m
}

/// The real roots of the quartic `c` in `[lo, hi]` by `solver`, ascending.
#[inline(always)]
pub fn quartic(solver: QuarticSolver, c: [f64; 5], lo: f64, hi: f64, out: &mut [f64; 4]) -> usize {
    match solver {
        QuarticSolver::Ferrari => quartic_ferrari(c, lo, hi, out),
        QuarticSolver::Bracketed => quartic_in(c, lo, hi, out),
        QuarticSolver::Laguerre => quartic_laguerre(c, lo, hi, out),
    }
}

/// A complex number, for Laguerre's iteration.
#[derive(Clone, Copy, Debug, PartialEq)]
struct C(f64, f64);

impl C {
    fn add(self, o: C) -> C {
        C(self.0 + o.0, self.1 + o.1)
    }
    fn sub(self, o: C) -> C {
        C(self.0 - o.0, self.1 - o.1)
    }
    fn mul(self, o: C) -> C {
        C(self.0 * o.0 - self.1 * o.1, self.0 * o.1 + self.1 * o.0)
    }
    fn div(self, o: C) -> C {
        let d = o.0 * o.0 + o.1 * o.1;
        C((self.0 * o.0 + self.1 * o.1) / d, (self.1 * o.0 - self.0 * o.1) / d)
    }
    fn scale(self, k: f64) -> C {
        C(self.0 * k, self.1 * k)
    }
    fn abs(self) -> f64 {
        self.0.hypot(self.1)
    }
    fn sqrt(self) -> C {
        let r = self.abs();
        let re = (0.5 * (r + self.0)).max(0.0).sqrt();
        let im = (0.5 * (r - self.0)).max(0.0).sqrt().copysign(self.1);
        C(re, im)
    }
}

/// Laguerre's iteration for one root of the complex polynomial `a` (lowest degree first) from
/// `x` (Numerical Recipes' `laguer`, its fractional steps against limit cycles); at most 80
/// steps.
fn laguerre(a: &[C], mut x: C) -> C {
    const FRAC: [f64; 8] = [0.5, 0.25, 0.75, 0.13, 0.38, 0.62, 0.88, 1.0];
    let m = a.len() - 1;
    for iter in 1..=80 {
        let mut b = a[m];
        let mut err = b.abs();
        let (mut d, mut f) = (C(0.0, 0.0), C(0.0, 0.0));
        let ax = x.abs();
        for j in (0..m).rev() {
            f = x.mul(f).add(d);
            d = x.mul(d).add(b);
            b = x.mul(b).add(a[j]);
            err = b.abs() + ax * err;
        }
        if b.abs() <= err * f64::EPSILON {
            return x;
        }
        let g = d.div(b);
        let g2 = g.mul(g);
        let h = g2.sub(f.div(b).scale(2.0));
        let sq = h.scale(m as f64).sub(g2).scale((m - 1) as f64).sqrt();
        let (gp, gm) = (g.add(sq), g.sub(sq));
        let big = if gp.abs() >= gm.abs() { gp } else { gm };
        let dx = if big.abs() > 0.0 {
            C(m as f64, 0.0).div(big)
        } else {
            let r = 1.0 + ax;
            C(r * (iter as f64).cos(), r * (iter as f64).sin())
        };
        let x1 = x.sub(dx);
        if x1 == x || !(x1.0.is_finite() && x1.1.is_finite()) {
            return x;
        }
        x = if iter % 10 != 0 { x1 } else { x.sub(dx.scale(FRAC[(iter / 10) % 8])) };
    }
    x
}

/// The real roots of the quartic `c` in `[lo, hi]`, ascending, by [`QuarticSolver::Laguerre`].
pub fn quartic_laguerre(c: [f64; 5], lo: f64, hi: f64, out: &mut [f64; 4]) -> usize {
    let deg = (0..5).rev().find(|&k| c[k] != 0.0).unwrap_or(0);
    if deg == 0 || c.iter().any(|x| !x.is_finite()) {
        return 0;
    }
    // A fixed array, deflated in place: no allocation per ray.
    let mut a = c.map(|x| C(x, 0.0));
    let mut roots = [C(0.0, 0.0); 4];
    for k in (1..=deg).rev() {
        let x = laguerre(&a[..=k], C(0.0, 0.0));
        roots[deg - k] = x;
        // Deflate: divide by (z − x); the quotient's coefficients replace a[0..k].
        let mut b = a[k];
        for j in (0..k).rev() {
            let t = a[j];
            a[j] = b;
            b = x.mul(b).add(t);
        }
    }
    let mut n = 0;
    for r in &roots[..deg] {
        // Near-real roots, polished on the quartic itself.
        if r.1.abs() > 1e-6 * (1.0 + r.0.abs()) {
            continue;
        }
        let mut x = r.0;
        for _ in 0..4 {
            let (f, df) = eval(&c, x);
            if df == 0.0 {
                break;
            }
            x -= f / df;
        }
        if x >= lo && x <= hi && x.is_finite() {
            out[n] = x;
            n += 1;
        }
    }
    sorted_distinct(out, n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quartic with roots `r` (lowest degree first).
    fn from_roots(r: [f64; 4]) -> [f64; 5] {
        let mut c = [1.0, 0.0, 0.0, 0.0, 0.0];
        for (deg, &x) in r.iter().enumerate() {
            for k in (0..=deg + 1).rev() {
                c[k] = if k > 0 { c[k - 1] } else { 0.0 } - x * c[k];
            }
        }
        c
    }

    #[test]
    fn quadratic_is_stable_for_tiny_roots() {
        // x² − 1e8 x + 1 = 0: the small root 1e-8 cancels in the textbook formula.
        let (r, n) = quadratic([1.0, -1e8, 1.0]);
        assert_eq!(n, 2);
        assert!((r[0] - 1e-8).abs() < 1e-20, "{}", r[0]);
        assert!((r[1] - 1e8).abs() < 1e-6);
        assert_eq!(quadratic([1.0, 0.0, 1.0]).1, 0);
        assert_eq!(quadratic([2.0, 1.0, 0.0]), ([-2.0, 0.0], 1));
    }

    #[test]
    fn both_quartic_solvers_find_well_separated_roots() {
        for roots in [[-3.0, -1.0, 0.5, 2.0], [0.1, 0.2, 0.3, 0.4], [-10.0, 1.0, 1.5, 7.0]] {
            let c = from_roots(roots);
            for solver in QuarticSolver::ALL {
                let mut out = [0.0; 4];
                let n = quartic(solver, c, -100.0, 100.0, &mut out);
                assert_eq!(n, 4, "{solver:?} {roots:?} {out:?}");
                for (a, b) in out.iter().zip(&roots) {
                    assert!((a - b).abs() < 1e-9, "{solver:?} {roots:?} {out:?}");
                }
            }
        }
    }

    #[test]
    fn bracketed_solver_keeps_to_its_interval_and_finds_close_pairs() {
        let c = from_roots([1.0, 1.0 + 1e-6, 3.0, 5.0]);
        let mut out = [0.0; 4];
        let n = quartic_in(c, 0.0, 4.0, &mut out);
        assert_eq!(n, 3, "{out:?}");
        assert!((out[0] - 1.0).abs() < 1e-9 && (out[1] - (1.0 + 1e-6)).abs() < 1e-9);
        // No real roots: x⁴ + 1.
        assert_eq!(quartic_in([1.0, 0.0, 0.0, 0.0, 1.0], -10.0, 10.0, &mut out), 0);
        assert_eq!(quartic_ferrari([1.0, 0.0, 0.0, 0.0, 1.0], -10.0, 10.0, &mut out), 0);
    }

    #[test]
    fn nan_coefficients_end() {
        let mut out = [0.0; 4];
        for solver in QuarticSolver::ALL {
            let n = quartic(solver, [f64::NAN, 1.0, 0.0, 0.0, 1.0], -1.0, 1.0, &mut out);
            assert!(out[..n].iter().all(|x| x.is_finite() || x.is_nan()));
        }
    }
}
