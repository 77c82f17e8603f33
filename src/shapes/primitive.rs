//! The canonical shapes a [`Solid`](super::Solid) is built from, each in its own object space:
//! where a line crosses it (the spans of the line inside it, for CSG), its outward normal, and
//! point membership. Everything here is float64: the canonical shape is intersected with the
//! object-space ray, which is not renormalized, so `t` is the world ray's parameter (the seeds'
//! ellipsoid example).

use std::sync::Arc;

use glam::DVec3;

use super::blob::{self, Blob};
use super::implicit::Implicit;
use super::interval::{self, Isolation};
use super::mesh_solid::MeshSolid;
use super::solve::{self, QuarticSolver};
use super::superquadric::Super;

/// A canonical shape in its object space (placed in the world by a [`Solid`](super::Solid)'s
/// transform). Solids are closed: a point is inside or outside; the disc alone is a surface.
#[derive(Clone, Debug, PartialEq)]
pub enum Primitive {
    /// The unit sphere about the origin (an ellipsoid under a non-uniform scale).
    Sphere,
    /// The cube `[−1, 1]³` (any box under a scale and translation): the slab test.
    Box,
    /// The capped cylinder `x² + y² ≤ 1`, `0 ≤ z ≤ 1`.
    Cylinder,
    /// The capped cone `x² + y² ≤ r(z)²`, `0 ≤ z ≤ 1`, its radius running linearly from `r0` at
    /// `z = 0` to `r1` at `z = 1` (both `≥ 0`, not both 0).
    Cone {
        /// Radius at `z = 0`.
        r0: f32,
        /// Radius at `z = 1`.
        r1: f32,
    },
    /// The disc `z = 0`, `x² + y² ≤ 1`: a surface, not a solid, so not a CSG operand. Its
    /// normal is `+z`.
    Disc,
    /// The half-space `z ≤ 0`, normal `+z`: unbounded, so only a CSG operand of a bounded solid
    /// (cut a box with it, for instance).
    Plane,
    /// The ring torus about the y axis (POV-Ray's orientation): the points at distance `minor`
    /// from the circle of radius `major` in the xz plane (`0 < minor < major`). Its quartic is
    /// solved by the scene's [`QuarticSolver`].
    Torus {
        /// Radius of the tube's centre circle.
        major: f32,
        /// Radius of the tube.
        minor: f32,
    },
    /// The general quadric `A x² + B y² + C z² + D xy + E xz + F yz + G x + H y + I z + J ≤ 0`
    /// (coefficients in that order, as POV-Ray's `quadric`): paraboloids, hyperboloids of one
    /// and two sheets, cones, cylinders. Unbounded in general, so only a CSG operand, clipped by
    /// intersecting it with a bounded solid.
    Quadric {
        /// `[A, B, C, D, E, F, G, H, I, J]`.
        coeffs: [f32; 10],
    },
    /// The superellipsoid `(|x|^(2/e) + |y|^(2/e))^(e/n) + |z|^(2/n) ≤ 1` in `[−1, 1]³`
    /// (POV-Ray's `superellipsoid { <e, n> }`): `e` shapes the cross-sections in xy, `n` the
    /// profile along z; 1 and 1 give the sphere, small values a rounded box, 2 an octahedron,
    /// larger ones pinched stars. Both in `[0.001, 1000]`. Crossings by interval root isolation.
    Superellipsoid {
        /// East–west exponent (the xy cross-sections).
        e: f32,
        /// North–south exponent (the profile along z).
        n: f32,
    },
    /// Barr's super-toroid about the y axis (the torus's orientation): the points whose
    /// distance-like `((|x|^(2/e) + |z|^(2/e))^(e/2) − major, y)` measured in the `2/n` norm is
    /// at most `minor`; `e = n = 1` is the ring torus, small exponents square the tube and the
    /// ring. `0 < minor < major`; exponents in `[0.01, 100]`. Crossings by interval root
    /// isolation.
    Supertoroid {
        /// Radius of the tube's centre line.
        major: f32,
        /// Radius of the tube.
        minor: f32,
        /// Exponent of the ring's shape in xz.
        e: f32,
        /// Exponent of the tube's cross-section.
        n: f32,
    },
    /// Barr's super-hyperboloid about the z axis, cut to `|z| ≤ height` (so it is a bounded
    /// solid): one sheet `ρ^(2/n) ≤ 1 + |z|^(2/n)` (a waisted tower), or two sheets
    /// `|z|^(2/n) ≥ 1 + ρ^(2/n)` (two caps, `height > 1`), where `ρ = (|x|^(2/e) +
    /// |y|^(2/e))^(e/2)`; `e = n = 1` gives the quadric hyperboloids. Exponents in
    /// `[0.01, 100]`. Crossings by interval root isolation.
    Superhyperboloid {
        /// Exponent of the cross-sections in xy.
        e: f32,
        /// Exponent of the profile along z.
        n: f32,
        /// 1 or 2.
        sheets: u8,
        /// Half the height the shape is cut to.
        height: f32,
    },
    /// Blanc & Schlick's (1996) ratioquadric `g_p(x²) + g_q(y²) + g_r(z²) ≤ 1` in `[−1, 1]³`,
    /// with the seeds' pseudo-power `g_p(u) = u / (p + (1 − p) u)` standing in for `|x|^p`
    /// (`g_p(0) = 0`, `g_p(1) = 1`, below the diagonal for `p > 1`, above it for `p < 1`):
    /// rational, so cheaper than powers, and smooth where `|x|^p` has cusps. 1 gives the
    /// sphere, large values a rounded box, small ones pinched stars (with rounded tips). Each in
    /// `[0.001, 1000]`. POV-Ray has no ratioquadric; its export is an isosurface.
    Ratioquadric {
        /// Exponent along x.
        p: f32,
        /// Exponent along y.
        q: f32,
        /// Exponent along z.
        r: f32,
    },
    /// A blob (metaballs) in its own space: see [`Blob`].
    Blob(Arc<Blob>),
    /// A user's implicit surface (a Rust closure with a Lipschitz bound), found by sphere
    /// tracing: see [`Implicit`]. Scene files cannot hold one, and
    /// [`Scene::to_bytes`](crate::Scene::to_bytes) writes only a marker that reading refuses.
    Implicit(Arc<Implicit>),
    /// A closed triangle mesh as a solid (inside by crossing parity): see [`MeshSolid`].
    Mesh(Arc<MeshSolid>),
}

/// One end of a span: where the line crosses a leaf's surface, which leaf (its index in the
/// solid), which face of it (box faces `2·axis + side`; cone and cylinder: 0 the side, 1 the
/// base, 2 the cap; 0 otherwise), and whether the normal is flipped (the leaf was subtracted).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Bound {
    pub t: f64,
    pub leaf: u16,
    pub face: u8,
    pub flip: bool,
}

/// A piece of the line inside a solid, `enter.t ≤ exit.t`; ends may be infinite.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Span {
    pub enter: Bound,
    pub exit: Bound,
}

impl Span {
    fn new(t0: f64, f0: u8, t1: f64, f1: u8, leaf: u16) -> Self {
        Span { enter: Bound { t: t0, leaf, face: f0, flip: false }, exit: Bound { t: t1, leaf, face: f1, flip: false } }
    }
}

/// Up to two spans of one primitive (every primitive here crosses a line at most four times).
pub(crate) type Spans = ([Span; 2], usize);

const NONE: Spans = ([Span { enter: B0, exit: B0 }; 2], 0);
const B0: Bound = Bound { t: 0.0, leaf: 0, face: 0, flip: false };

/// The spans of the line `o + t d` inside `{a t² + b t + c ≤ 0}`, faces `face`.
#[inline(always)]
fn quadratic_spans(a: f64, b: f64, c: f64, leaf: u16, face: u8) -> Spans {
    const INF: f64 = f64::INFINITY;
    let one = |t0, t1| ([Span::new(t0, face, t1, face, leaf), Span::new(0.0, 0, 0.0, 0, 0)], 1);
    if a == 0.0 {
        // Linear: b t + c ≤ 0.
        return if b > 0.0 {
            one(-INF, -c / b)
        } else if b < 0.0 {
            one(-c / b, INF)
        } else if c <= 0.0 {
            one(-INF, INF)
        } else {
            NONE
        };
    }
    let (r, n) = solve::quadratic([c, b, a]);
    match (n, a > 0.0) {
        (2, true) => one(r[0], r[1]),
        (2, false) => ([Span::new(-INF, face, r[0], face, leaf), Span::new(r[1], face, INF, face, leaf)], 2),
        (_, true) => NONE,
        (_, false) => one(-INF, INF),
    }
}

/// The spans of `s` (ascending, disjoint) cut to `[lo, hi]` with faces `flo`, `fhi`.
fn clip(s: Spans, lo: f64, flo: u8, hi: f64, fhi: u8, leaf: u16) -> Spans {
    let mut out = NONE;
    for sp in &s.0[..s.1] {
        let mut sp = *sp;
        if sp.enter.t < lo {
            sp.enter = Bound { t: lo, leaf, face: flo, flip: false };
        }
        if sp.exit.t > hi {
            sp.exit = Bound { t: hi, leaf, face: fhi, flip: false };
        }
        if sp.enter.t <= sp.exit.t {
            out.0[out.1] = sp;
            out.1 += 1;
        }
    }
    out
}

/// `[−1, 1]` along one axis: the slab's span of the line with faces `2·axis + side`, or
/// `None` (no crossing) / the whole line (parallel, inside).
#[inline(always)]
fn slab(o: f64, d: f64, lo: f64, hi: f64, axis: u8) -> Option<(f64, u8, f64, u8)> {
    if d == 0.0 {
        return (o >= lo && o <= hi).then_some((f64::NEG_INFINITY, 2 * axis, f64::INFINITY, 2 * axis + 1));
    }
    let (ta, tb) = ((lo - o) / d, (hi - o) / d);
    Some(if d > 0.0 { (ta, 2 * axis, tb, 2 * axis + 1) } else { (tb, 2 * axis + 1, ta, 2 * axis) })
}

impl Primitive {
    /// The radii of a cone or cylinder.
    fn cone_radii(&self) -> Option<(f64, f64)> {
        match *self {
            Primitive::Cylinder => Some((1.0, 1.0)),
            Primitive::Cone { r0, r1 } => Some((r0 as f64, r1 as f64)),
            _ => None,
        }
    }

    /// The spans of the line `o + t d` (object space, any `d ≠ 0`) inside this primitive, over
    /// all `t` (also behind the ray's start: a ray may start inside). The disc gives its one
    /// crossing as a span of zero width.
    #[inline(always)]
    pub(crate) fn spans(&self, o: DVec3, d: DVec3, solver: QuarticSolver, leaf: u16, out: &mut Vec<Span>) {
        match self {
            Primitive::Superellipsoid { .. }
            | Primitive::Supertoroid { .. }
            | Primitive::Superhyperboloid { .. }
            | Primitive::Ratioquadric { .. } => {
                let Some(sq) = Super::of(self) else { return };
                let Some(ch) = Chord::new(o, d, sq.bounds()) else { return };
                let (p, u) = (ch.p, ch.u);
                ch.spans(|a, b| sq.range(p, u, a, b), |t| sq.point(p, u, t), leaf, out);
            }
            Primitive::Implicit(im) => {
                let Some(ch) = Chord::new(o, d, im.bounds_f64()) else { return };
                TRACE.with(|roots| {
                    let mut roots = roots.borrow_mut();
                    let _complete: bool = im.trace(ch.p, ch.u, ch.length, IMPLICIT_MIN_STEP * ch.size, &mut roots);
                    ch.push_spans(&roots, im.field(ch.p) <= 0.0, leaf, out);
                });
            }
            Primitive::Mesh(m) => {
                let Some(ch) = Chord::new(o, d, m.bounds()) else { return };
                TRACE.with(|roots| {
                    let mut roots = roots.borrow_mut();
                    m.crossings(ch.p, ch.u, ch.length, &mut roots);
                    // The chord starts outside the bounds, so outside the mesh.
                    ch.push_spans(&roots, false, leaf, out);
                });
            }
            Primitive::Blob(b) => blob::ACTIVE.with(|active| {
                let Some(ch) = Chord::new(o, d, b.bounds()) else { return };
                let mut active = active.borrow_mut();
                b.activate(ch.p, ch.u, &mut active);
                let active = &*active;
                ch.spans(|lo, hi| b.range(active, lo, hi), |t| b.point(active, t), leaf, out);
            }),
            _ => {
                let (s, k) = self.spans_fixed(o, d, solver, leaf);
                out.extend_from_slice(&s[..k]);
            }
        }
    }

    /// The spans of the primitives with at most two of them.
    #[inline(always)]
    fn spans_fixed(&self, o: DVec3, d: DVec3, solver: QuarticSolver, leaf: u16) -> Spans {
        match *self {
            Primitive::Sphere => {
                // Ray Tracing Gems ch. 7: the discriminant from the distance of the line to the
                // centre, `1 − |o − (o·d / d·d) d|²`, which does not cancel for far rays.
                let a = d.dot(d);
                let b = o.dot(d);
                let f = o - (b / a) * d;
                let disc = 1.0 - f.dot(f);
                if disc < 0.0 {
                    return NONE;
                }
                let q = -b - (a * disc).sqrt().copysign(b);
                let c = o.dot(o) - 1.0;
                let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (c / q, q / a) };
                ([Span::new(t0.min(t1), 0, t0.max(t1), 0, leaf), NONE.0[0]], 1)
            }
            Primitive::Box => {
                let mut span = (f64::NEG_INFINITY, 0u8, f64::INFINITY, 1u8);
                for axis in 0..3 {
                    let Some((t0, f0, t1, f1)) = slab(o[axis], d[axis], -1.0, 1.0, axis as u8) else {
                        return NONE;
                    };
                    if t0 > span.0 {
                        span.0 = t0;
                        span.1 = f0;
                    }
                    if t1 < span.2 {
                        span.2 = t1;
                        span.3 = f1;
                    }
                }
                if span.0 > span.2 {
                    return NONE;
                }
                ([Span::new(span.0, span.1, span.2, span.3, leaf), NONE.0[0]], 1)
            }
            Primitive::Cylinder | Primitive::Cone { .. } => {
                let (r0, r1) = self.cone_radii().unwrap_or((1.0, 1.0));
                let k = r1 - r0;
                let rz = r0 + k * o.z;
                let a = d.x * d.x + d.y * d.y - k * k * d.z * d.z;
                let b = 2.0 * (o.x * d.x + o.y * d.y - k * d.z * rz);
                let c = o.x * o.x + o.y * o.y - rz * rz;
                let side = quadratic_spans(a, b, c, leaf, 0);
                // The caps: faces 1 (z = 0) and 2 (z = 1).
                let Some((t0, f0, t1, f1)) = slab(o.z, d.z, 0.0, 1.0, 2) else {
                    return NONE;
                };
                let (f0, f1) = (f0 - 3, f1 - 3);
                clip(side, t0, f0, t1, f1, leaf)
            }
            Primitive::Disc => {
                if d.z == 0.0 {
                    return NONE;
                }
                let t = -o.z / d.z;
                let p = o + t * d;
                if p.x * p.x + p.y * p.y > 1.0 {
                    return NONE;
                }
                ([Span::new(t, 0, t, 0, leaf), NONE.0[0]], 1)
            }
            Primitive::Plane => quadratic_spans(0.0, d.z, o.z, leaf, 0),
            Primitive::Quadric { coeffs } => {
                let [qa, qb, qc, qd, qe, qf, qg, qh, qi, _] = coeffs.map(|x| x as f64);
                let a =
                    qa * d.x * d.x + qb * d.y * d.y + qc * d.z * d.z + qd * d.x * d.y + qe * d.x * d.z + qf * d.y * d.z;
                let b = 2.0 * (qa * o.x * d.x + qb * o.y * d.y + qc * o.z * d.z)
                    + qd * (o.x * d.y + o.y * d.x)
                    + qe * (o.x * d.z + o.z * d.x)
                    + qf * (o.y * d.z + o.z * d.y)
                    + qg * d.x
                    + qh * d.y
                    + qi * d.z;
                quadratic_spans(a, b, self.field(o), leaf, 0)
            }
            Primitive::Torus { major, minor } => torus_spans(major as f64, minor as f64, o, d, solver, leaf),
            Primitive::Superellipsoid { .. }
            | Primitive::Supertoroid { .. }
            | Primitive::Superhyperboloid { .. }
            | Primitive::Ratioquadric { .. }
            | Primitive::Blob(_)
            | Primitive::Implicit(_)
            | Primitive::Mesh(_) => NONE,
        }
    }

    /// The implicit function at the object-space point `p`: negative inside, positive outside,
    /// 0 on the surface (not a distance; for the disc, 1 everywhere). For other root finders
    /// to be compared with strahl's (the harness's sampling marcher).
    pub fn field(&self, p: DVec3) -> f64 {
        match *self {
            Primitive::Sphere => p.dot(p) - 1.0,
            Primitive::Box => p.abs().max_element() - 1.0,
            Primitive::Cylinder | Primitive::Cone { .. } => {
                let (r0, r1) = self.cone_radii().unwrap_or((1.0, 1.0));
                let r = r0 + (r1 - r0) * p.z;
                let lateral = p.x * p.x + p.y * p.y - r * r;
                lateral.max(-p.z).max(p.z - 1.0)
            }
            Primitive::Disc => 1.0,
            Primitive::Plane => p.z,
            Primitive::Torus { major, minor } => {
                let (big, small) = (major as f64, minor as f64);
                let g = p.dot(p) + big * big - small * small;
                g * g - 4.0 * big * big * (p.x * p.x + p.z * p.z)
            }
            Primitive::Quadric { coeffs } => {
                let [a, b, c, d, e, f, g, h, i, j] = coeffs.map(|x| x as f64);
                a * p.x * p.x
                    + b * p.y * p.y
                    + c * p.z * p.z
                    + d * p.x * p.y
                    + e * p.x * p.z
                    + f * p.y * p.z
                    + g * p.x
                    + h * p.y
                    + i * p.z
                    + j
            }
            Primitive::Superellipsoid { .. }
            | Primitive::Supertoroid { .. }
            | Primitive::Superhyperboloid { .. }
            | Primitive::Ratioquadric { .. } => Super::of(self).map_or(1.0, |s| s.field(p.to_array())),
            Primitive::Blob(ref b) => b.field(p),
            Primitive::Implicit(ref im) => {
                let (lo, hi) = im.bounds_f64();
                // Clipped to its box (a field that is not positive on the box's faces leaves
                // the solid open there).
                let outside = p.cmplt(lo).any() || p.cmpgt(hi).any();
                if outside { f64::INFINITY } else { im.field(p) }
            }
            Primitive::Mesh(ref m) => m.field(p),
        }
    }

    /// Whether the object-space point `p` lies inside (boundary included); the disc contains
    /// nothing.
    pub fn contains(&self, p: DVec3) -> bool {
        self.field(p) <= 0.0
    }

    /// The outward normal (not normalized) at the object-space surface point `p` on `face`.
    pub(crate) fn normal(&self, p: DVec3, face: u8) -> DVec3 {
        match *self {
            Primitive::Sphere => p,
            Primitive::Box => {
                let mut n = DVec3::ZERO;
                n[(face / 2) as usize] = if face % 2 == 1 { 1.0 } else { -1.0 };
                n
            }
            Primitive::Cylinder | Primitive::Cone { .. } => match face {
                1 => DVec3::NEG_Z,
                2 => DVec3::Z,
                _ => {
                    let (r0, r1) = self.cone_radii().unwrap_or((1.0, 1.0));
                    let k = r1 - r0;
                    DVec3::new(p.x, p.y, -(r0 + k * p.z) * k)
                }
            },
            Primitive::Disc | Primitive::Plane => DVec3::Z,
            Primitive::Torus { major, minor } => {
                let (big, small) = (major as f64, minor as f64);
                let g = p.dot(p) + big * big - small * small;
                g * p - 2.0 * big * big * DVec3::new(p.x, 0.0, p.z)
            }
            Primitive::Quadric { coeffs } => {
                let [a, b, c, d, e, f, g, h, i, _] = coeffs.map(|x| x as f64);
                DVec3::new(
                    2.0 * a * p.x + d * p.y + e * p.z + g,
                    2.0 * b * p.y + d * p.x + f * p.z + h,
                    2.0 * c * p.z + e * p.x + f * p.y + i,
                )
            }
            Primitive::Superellipsoid { .. }
            | Primitive::Supertoroid { .. }
            | Primitive::Superhyperboloid { .. }
            | Primitive::Ratioquadric { .. } => Super::of(self).map_or(DVec3::Z, |s| s.gradient(p)),
            Primitive::Blob(ref b) => b.gradient(p),
            Primitive::Implicit(ref im) => im.gradient(p),
            Primitive::Mesh(ref m) => m.normal(p),
        }
    }

    /// Object-space bounds, or `None` for the unbounded plane and quadric.
    pub(crate) fn bounds(&self) -> Option<(DVec3, DVec3)> {
        match *self {
            Primitive::Sphere | Primitive::Box => Some((DVec3::splat(-1.0), DVec3::ONE)),
            Primitive::Superellipsoid { .. }
            | Primitive::Supertoroid { .. }
            | Primitive::Superhyperboloid { .. }
            | Primitive::Ratioquadric { .. } => Super::of(self).map(|s| s.bounds()),
            Primitive::Blob(ref b) => Some(b.bounds()),
            Primitive::Implicit(ref im) => Some(im.bounds_f64()),
            Primitive::Mesh(ref m) => Some(m.bounds()),
            Primitive::Cylinder | Primitive::Cone { .. } => {
                let (r0, r1) = self.cone_radii().unwrap_or((1.0, 1.0));
                let r = r0.max(r1);
                Some((DVec3::new(-r, -r, 0.0), DVec3::new(r, r, 1.0)))
            }
            Primitive::Disc => Some((DVec3::new(-1.0, -1.0, 0.0), DVec3::new(1.0, 1.0, 0.0))),
            Primitive::Torus { major, minor } => {
                let (big, small) = (major as f64, minor as f64);
                let e = DVec3::new(big + small, small, big + small);
                Some((-e, e))
            }
            Primitive::Plane | Primitive::Quadric { .. } => None,
        }
    }

    /// Why these parameters describe no shape, if they do not.
    pub(crate) fn check(&self) -> Option<String> {
        match *self {
            Primitive::Cone { r0, r1 } if !(r0 >= 0.0 && r1 >= 0.0 && r0.max(r1) > 0.0 && r0.max(r1).is_finite()) => {
                Some(format!("cone radii {r0} and {r1}: both must be finite and ≥ 0, not both 0"))
            }
            Primitive::Torus { major, minor } if !(minor > 0.0 && minor < major && major.is_finite()) => {
                Some(format!("torus radii {major} and {minor}: need 0 < minor < major, finite"))
            }
            Primitive::Quadric { coeffs } if coeffs.iter().any(|c| !c.is_finite()) => {
                Some(format!("quadric coefficients {coeffs:?} are not all finite"))
            }
            Primitive::Quadric { coeffs } if coeffs[..9].iter().all(|&c| c == 0.0) => {
                Some("quadric coefficients A to I are all zero: no surface".into())
            }
            Primitive::Superellipsoid { e, n } if !((1e-3..=1e3).contains(&e) && (1e-3..=1e3).contains(&n)) => {
                Some(format!("superellipsoid exponents {e} and {n}: both must lie in [0.001, 1000]"))
            }
            Primitive::Supertoroid { major, minor, e, n } => {
                let ok = minor > 0.0 && minor < major && major.is_finite() && exponents_ok([e, n], 0.01, 100.0);
                (!ok || !powers_fit(self, [e, n])).then(|| {
                    format!(
                        "supertoroid radii {major}, {minor} and exponents {e}, {n}: need 0 < minor < major, \
                         exponents in [0.01, 100], and (major + minor)^(2/min(e, n)) below 1e200"
                    )
                })
            }
            Primitive::Superhyperboloid { e, n, sheets, height } => {
                let ok = exponents_ok([e, n], 0.01, 100.0)
                    && (sheets == 1 && height > 0.0 || sheets == 2 && height > 1.0)
                    && height.is_finite();
                (!ok || !powers_fit(self, [e, n])).then(|| {
                    format!(
                        "superhyperboloid exponents {e}, {n}, {sheets} sheets, height {height}: need exponents in \
                         [0.01, 100], 1 or 2 sheets, height > 0 (> 1 for two sheets) and the bounds' coordinates \
                         to the power 2/min(e, n) below 1e200"
                    )
                })
            }
            Primitive::Ratioquadric { p, q, r } if !exponents_ok([p, q, r], 1e-3, 1e3) => {
                Some(format!("ratioquadric exponents {p}, {q}, {r}: each must lie in [0.001, 1000]"))
            }
            Primitive::Blob(ref b) => b.check(),
            Primitive::Implicit(ref im) => im.check(),
            _ => None,
        }
    }
}

/// Whether every exponent lies in `[lo, hi]` (NaN does not).
fn exponents_ok<const N: usize>(x: [f32; N], lo: f32, hi: f32) -> bool {
    x.iter().all(|x| (lo..=hi).contains(x))
}

/// Whether the largest coordinate of a superquadric's bounds, raised to the largest power its
/// field takes (`2 / min(exponents)`), stays far from overflow, so no bound of the field is
/// `∞ − ∞`.
fn powers_fit(p: &Primitive, exponents: [f32; 2]) -> bool {
    let Some((_, hi)) = Super::of(p).map(|s| s.bounds()) else { return false };
    let power = 2.0 / exponents[0].min(exponents[1]) as f64;
    let top = hi.max_element().max(1.0).powf(power);
    hi.is_finite() && top < 1e200
}

/// The chord of a line through a shape's bounds, for root isolation: the origin moved to where
/// the line enters (POV-Ray's practice), the direction made unit, so `t` is arc length there.
struct Chord {
    p: DVec3,
    u: DVec3,
    /// Arc length from `o` along `u` to where the chord starts, and the chord's length.
    t0: f64,
    length: f64,
    /// `|d|`: arc length per unit of the ray's parameter.
    scale: f64,
    /// The bounds' diagonal.
    size: f64,
}

/// Root isolation stops splitting pieces of the chord thinner than this share of the shape's
/// bounding diagonal (the CSG drops spans below 1e-6 of a solid's diagonal anyway).
const ISOLATION_EPS: f64 = 1e-9;

impl Chord {
    fn new(o: DVec3, d: DVec3, (lo, hi): (DVec3, DVec3)) -> Option<Chord> {
        // The box a little larger, so the chord's ends lie outside the shape.
        let pad = 1e-9 * (hi - lo).max_element();
        let (lo, hi) = (lo - pad, hi + pad);
        let scale = d.length();
        let u = d / scale;
        let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
        for k in 0..3 {
            let (a, _, b, _) = slab(o[k], u[k], lo[k], hi[k], 0)?;
            t0 = t0.max(a);
            t1 = t1.min(b);
        }
        let size = (hi - lo).length();
        (t0 < t1 && t0.is_finite() && t1.is_finite()).then(|| Chord {
            p: o + t0 * u,
            u,
            t0,
            length: t1 - t0,
            scale,
            size,
        })
    }

    /// Appends the spans of the line inside the shape whose field (along the chord, from its
    /// start) `range` bounds and `point` evaluates. A budget-exhausted isolation keeps what it
    /// found: the chord keeps the side of its last crossing found to its end.
    fn spans(
        &self,
        range: impl Fn(f64, f64) -> interval::Dual<interval::Iv>,
        point: impl Fn(f64) -> interval::Dual<f64>,
        leaf: u16,
        out: &mut Vec<Span>,
    ) {
        ISOLATION.with(|scratch| {
            let mut scratch = scratch.borrow_mut();
            let eps = ISOLATION_EPS * self.size;
            let _: Isolation = interval::isolate(&range, &point, 0.0, self.length, eps, &mut scratch);
            self.push_spans(&scratch.roots, point(0.0).v <= 0.0, leaf, out);
        });
    }

    /// Appends the spans between `roots` (arc lengths along the chord, ascending, each a change
    /// of sign), the first piece inside if `inside`: the pieces alternate from the start's side.
    fn push_spans(&self, roots: &[f64], mut inside: bool, leaf: u16, out: &mut Vec<Span>) {
        let mut prev = 0.0;
        let to_ray = |s: f64| (self.t0 + s) / self.scale;
        for &r in roots.iter().chain(std::iter::once(&self.length)) {
            if inside {
                out.push(Span::new(to_ray(prev), 0, to_ray(r), 0, leaf));
            }
            inside = !inside;
            prev = r;
        }
    }
}

/// The smallest step of the sphere trace of an [`Implicit`], as a share of its bounding
/// diagonal: crossings closer together than this may be missed (the CSG drops spans thinner
/// than 1e-6 of a solid's diagonal anyway).
const IMPLICIT_MIN_STEP: f64 = 1e-6;

thread_local! {
    static ISOLATION: std::cell::RefCell<interval::IsolationScratch> = std::cell::RefCell::new(Default::default());
    static TRACE: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// The torus's spans: the quartic `F(t) = G² − 4R²(x² + z²)`, `G = |p|² + R² − r²`, solved on
/// the chord of its bounding sphere, with the origin moved to where the chord starts and the
/// direction normalized (POV-Ray's practice: far origins otherwise cancel away the roots). The
/// pieces between roots are classified by `F` at their middles, so a root the solver loses
/// merges two pieces instead of turning the inside out.
#[inline(always)]
fn torus_spans(big: f64, small: f64, o: DVec3, d: DVec3, solver: QuarticSolver, leaf: u16) -> Spans {
    let len = d.length();
    let u = d / len;
    // The bounding sphere, radius R + r (a little more, so the chord's ends lie outside).
    let rb = (big + small) * (1.0 + 1e-9);
    let b = o.dot(u);
    let f = o - b * u;
    let disc = rb * rb - f.dot(f);
    if disc <= 0.0 {
        return NONE;
    }
    let h = disc.sqrt();
    let (s0, s1) = (-b - h, -b + h);
    let p = o + s0 * u;
    let e = p.dot(p) + big * big - small * small;
    let pu = p.dot(u);
    let r2 = 4.0 * big * big;
    let c = [
        e * e - r2 * (p.x * p.x + p.z * p.z),
        4.0 * pu * e - 2.0 * r2 * (p.x * u.x + p.z * u.z),
        4.0 * pu * pu + 2.0 * e - r2 * (u.x * u.x + u.z * u.z),
        4.0 * pu,
        1.0,
    ];
    let mut roots = [0.0; 4];
    let n = solve::quartic(solver, c, 0.0, s1 - s0, &mut roots);
    let field = |s: f64| {
        let q = p + s * u;
        let g = q.dot(q) + big * big - small * small;
        g * g - r2 * (q.x * q.x + q.z * q.z)
    };
    let mut out = NONE;
    let mut open: Option<f64> = None;
    let mut prev = 0.0;
    for &r in roots[..n].iter().chain(std::iter::once(&(s1 - s0))) {
        let inside = field(0.5 * (prev + r)) < 0.0;
        match (inside, open) {
            (true, None) => open = Some(prev),
            (false, Some(start)) => {
                if out.1 < 2 {
                    out.0[out.1] = Span::new(s0 + start, 0, s0 + prev, 0, leaf);
                    out.1 += 1;
                }
                open = None;
            }
            _ => {}
        }
        prev = r;
    }
    if let Some(start) = open
        && out.1 < 2
    {
        out.0[out.1] = Span::new(s0 + start, 0, s1, 0, leaf);
        out.1 += 1;
    }
    // From arc length along `u` back to the ray's parameter.
    for sp in &mut out.0[..out.1] {
        sp.enter.t /= len;
        sp.exit.t /= len;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{BlobComponent, Potential};

    fn spans_of(p: &Primitive, o: DVec3, d: DVec3) -> Vec<Span> {
        let mut out = Vec::new();
        p.spans(o, d, QuarticSolver::default(), 0, &mut out);
        out
    }

    #[test]
    fn the_unit_superellipsoid_is_the_sphere() {
        let se = Primitive::Superellipsoid { e: 1.0, n: 1.0 };
        for k in 0..2000 {
            let a = k as f64 * 0.37;
            let o = DVec3::new(a.cos() * 3.0, a.sin() * 2.0, (a * 0.7).sin());
            let d = DVec3::new((a * 1.3).sin() * 0.9, (a * 2.1).cos() * 0.8, (a * 0.3).cos() * 0.5) - o;
            let (x, y) = (spans_of(&se, o, d), spans_of(&Primitive::Sphere, o, d));
            assert_eq!(x.len(), y.len(), "{o} {d} {x:?} {y:?}");
            for (x, y) in x.iter().zip(&y) {
                assert!((x.enter.t - y.enter.t).abs() < 1e-9 && (x.exit.t - y.exit.t).abs() < 1e-9, "{x:?} {y:?}");
            }
        }
    }

    /// Rays from a shell of radius 5 through points near the origin.
    fn rays(n: usize) -> impl Iterator<Item = (DVec3, DVec3)> {
        (0..n).map(|k| {
            let a = k as f64 * 0.37;
            let o = DVec3::new(a.cos() * 3.0, a.sin() * 2.0, (a * 0.7).sin() * 2.5);
            let target = DVec3::new((a * 1.3).sin() * 1.2, (a * 2.1).cos() * 0.9, (a * 0.3).cos() * 1.1);
            (o, (target - o) * (1.0 + 0.5 * (a * 0.11).sin()))
        })
    }

    fn same_spans(x: &Primitive, y: &[Span], o: DVec3, d: DVec3) {
        let s = spans_of(x, o, d);
        assert_eq!(s.len(), y.len(), "{x:?} {o} {d} {s:?} {y:?}");
        for (a, b) in s.iter().zip(y) {
            let ok = (a.enter.t - b.enter.t).abs() < 1e-9 && (a.exit.t - b.exit.t).abs() < 1e-9;
            assert!(ok, "{x:?} {o} {d}: {a:?} against {b:?}");
        }
    }

    #[test]
    fn the_round_supertoroid_is_the_torus() {
        let st = Primitive::Supertoroid { major: 1.0, minor: 0.3, e: 1.0, n: 1.0 };
        let torus = Primitive::Torus { major: 1.0, minor: 0.3 };
        for (o, d) in rays(3000) {
            let (s, k) = torus.spans_fixed(o, d, QuarticSolver::default(), 0);
            same_spans(&st, &s[..k], o, d);
        }
    }

    #[test]
    fn the_round_superhyperboloids_are_the_quadric_hyperboloids() {
        // x² + y² − z² − 1 ≤ 0 (one sheet) and x² + y² − z² + 1 ≤ 0 (two), cut to |z| ≤ h by
        // the slab: the quadric's closed form.
        for (sheets, h, j) in [(1u8, 1.5f32, -1.0f32), (2, 1.7, 1.0)] {
            let sh = Primitive::Superhyperboloid { e: 1.0, n: 1.0, sheets, height: h };
            let h = h as f64;
            let q = Primitive::Quadric { coeffs: [1.0, 1.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, j] };
            for (o, d) in rays(3000) {
                let s = q.spans_fixed(o, d, QuarticSolver::default(), 0);
                let expected = match slab(o.z, d.z, -h, h, 2) {
                    Some((t0, f0, t1, f1)) => clip(s, t0, f0, t1, f1, 0),
                    None => NONE,
                };
                // Spans that only touch (a ray through a rim) have no width to compare.
                let expected: Vec<Span> =
                    expected.0[..expected.1].iter().filter(|s| s.exit.t - s.enter.t > 1e-9).copied().collect();
                same_spans(&sh, &expected, o, d);
            }
        }
    }

    #[test]
    fn ratioquadrics_cross_where_the_pseudo_power_inverts() {
        // Along x at height y0: g_p(x²) = 1 − g_q(y0²) = v, so x² = p v / (1 − (1 − p) v).
        let g = |u: f64, p: f64| u / (p + (1.0 - p) * u);
        for (p, q, r) in [(1.0f32, 1.0f32, 1.0f32), (0.1, 0.3, 2.0), (5.0, 0.05, 0.5), (1e-3, 1e3, 1.0)] {
            let rq = Primitive::Ratioquadric { p, q, r };
            assert!(rq.check().is_none());
            let (p, q) = (p as f64, q as f64);
            for k in 0..50 {
                let y0 = -0.98 + 1.96 * k as f64 / 49.0;
                let v = 1.0 - g(y0 * y0, q);
                let x = (p * v / (1.0 - (1.0 - p) * v)).sqrt();
                let (o, d) = (DVec3::new(-3.0, y0, 0.0), DVec3::new(0.5, 0.0, 0.0));
                let expected = [Span::new((3.0 - x) / 0.5, 0, (3.0 + x) / 0.5, 0, 0)];
                same_spans(&rq, if x > 0.0 { &expected } else { &[] }, o, d);
            }
        }
        // p = q = r = 1 is the sphere.
        let unit = Primitive::Ratioquadric { p: 1.0, q: 1.0, r: 1.0 };
        for (o, d) in rays(2000) {
            let (s, k) = Primitive::Sphere.spans_fixed(o, d, QuarticSolver::default(), 0);
            same_spans(&unit, &s[..k], o, d);
        }
    }

    #[test]
    fn superquadric_normals_match_central_differences() {
        // The seeds' normal by differences, against the analytic gradient (automatic
        // differentiation), at surface points of each family.
        let shapes = [
            Primitive::Supertoroid { major: 1.0, minor: 0.4, e: 0.3, n: 0.5 },
            Primitive::Supertoroid { major: 1.0, minor: 0.4, e: 2.0, n: 2.5 },
            Primitive::Superhyperboloid { e: 0.5, n: 1.5, sheets: 1, height: 1.0 },
            Primitive::Superhyperboloid { e: 1.5, n: 0.7, sheets: 2, height: 2.0 },
            Primitive::Ratioquadric { p: 0.1, q: 0.3, r: 1.0 },
            Primitive::Ratioquadric { p: 6.0, q: 6.0, r: 3.0 },
        ];
        for shape in shapes {
            let (mut worst, mut n) = (0.0f64, 0);
            for (o, d) in rays(1000) {
                let Some(s) = spans_of(&shape, o, d).first().copied() else { continue };
                let p = o + s.enter.t * d;
                let g = shape.normal(p, 0).normalize();
                let c = crate::shapes::superquadric::central_difference(|q| shape.field(q), p).normalize();
                // (A point within the difference step of a cap's rim, where the gradient jumps,
                // would differ; rays hit one with a chance of about 1e-6.)
                if g.is_finite() && c.is_finite() {
                    worst = worst.max(g.angle_between(c));
                    n += 1;
                }
            }
            assert!(n > 200 && worst < 1e-3, "{shape:?}: {n} points, worst angle {worst}");
        }
    }

    #[test]
    fn a_lone_blob_ball_has_the_potentials_radius() {
        // s·f(q) = T on the surface: solve f(q) = T/s for q by bisection (f falls on [0, 1]),
        // independently of the interval solver; a ray through the centre spans [−r, r].
        let (t, s, big_r) = (0.3f32 as f64, 1.0f64, 0.8f32 as f64);
        for pot in [Potential::Pov, Potential::Wyvill, Potential::Rational { d: 3.0 }, Potential::InverseSquare] {
            let f = |q: f64| match pot {
                Potential::Pov => (1.0 - q).powi(2),
                Potential::Wyvill => 1.0 - 22.0 / 9.0 * q + 17.0 / 9.0 * q * q - 4.0 / 9.0 * q * q * q,
                Potential::Rational { d } => (1.0 - q).powi(2) / (1.0 + d as f64 * q),
                Potential::InverseSquare => 1.0 / q,
            };
            let (mut lo, mut hi) = (1e-9, if pot == Potential::InverseSquare { 100.0 } else { 1.0 });
            for _ in 0..200 {
                let m = 0.5 * (lo + hi);
                if s * f(m) > t { lo = m } else { hi = m }
            }
            let r = big_r * lo.sqrt();
            let ball = BlobComponent { center: glam::Vec3::ZERO, radius: big_r as f32, strength: s as f32 };
            let blob = Primitive::Blob(Arc::new(Blob::new(t as f32, pot, vec![ball])));
            assert!(blob.check().is_none());
            let sp = spans_of(&blob, DVec3::new(-5.0, 0.0, 0.0), DVec3::new(2.0, 0.0, 0.0));
            assert_eq!(sp.len(), 1, "{pot:?} {sp:?}");
            assert!((sp[0].enter.t - (5.0 - r) / 2.0).abs() < 1e-9, "{pot:?} {sp:?} r = {r}");
            assert!((sp[0].exit.t - (5.0 + r) / 2.0).abs() < 1e-9, "{pot:?} {sp:?} r = {r}");
            // The analytic gradient points outwards, radially.
            let n = blob.normal(DVec3::new(r, 0.0, 0.0), 0);
            assert!(n.x > 0.0 && n.y.abs() < 1e-12 && n.z.abs() < 1e-12, "{n}");
        }
    }

    #[test]
    fn superellipsoid_normals_match_central_differences() {
        // The seeds' normal by differences, against the analytic gradient (automatic
        // differentiation): at surface points of a rounded box and a pinched star.
        for (e, n) in [(0.3, 0.5), (1.0, 1.0), (2.5, 3.0)] {
            let se = Primitive::Superellipsoid { e, n };
            let mut worst = 0.0f64;
            for k in 0..500 {
                let a = k as f64 * 0.731;
                let d = DVec3::new(a.cos() * (a * 0.3).sin(), a.sin() * (a * 0.3).sin(), (a * 0.3).cos()) * 2.0;
                let o = DVec3::new(0.01, -0.02, 0.015) - d;
                let Some(s) = spans_of(&se, o, d).first().copied() else { continue };
                let p = o + s.enter.t * d;
                let g = se.normal(p, 0).normalize();
                let c = crate::shapes::superquadric::central_difference(|q| se.field(q), p).normalize();
                if g.is_finite() && c.is_finite() {
                    worst = worst.max(g.angle_between(c));
                }
            }
            assert!(worst < 1e-3, "e {e} n {n}: worst angle {worst}");
        }
    }

    #[test]
    fn torus_solvers_find_the_same_crossings() {
        let torus = Primitive::Torus { major: 1.0, minor: 0.25 };
        let mut seed = 1u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for _ in 0..20000 {
            let o = DVec3::new(rnd(), rnd(), rnd()).normalize() * 5.0;
            let d = DVec3::new(rnd(), rnd(), rnd()) * 1.3 - o;
            let a = torus.spans_fixed(o, d, QuarticSolver::Ferrari, 0);
            let b = torus.spans_fixed(o, d, QuarticSolver::Bracketed, 0);
            assert_eq!(a.1, b.1, "{o} {d} {a:?} {b:?}");
            for (x, y) in a.0[..a.1].iter().zip(&b.0[..b.1]) {
                for (p, q) in [(x.enter.t, y.enter.t), (x.exit.t, y.exit.t)] {
                    let (fp, fq) = (torus.field(o + p * d), torus.field(o + q * d));
                    assert!((p - q).abs() < 1e-9, "{o} {d} {p} {q} fields {fp} {fq}");
                }
            }
        }
    }
}

#[cfg(test)]
mod implicit_tests {
    use super::*;

    fn spans_of(p: &Primitive, o: DVec3, d: DVec3) -> Vec<Span> {
        let mut out = Vec::new();
        p.spans(o, d, QuarticSolver::default(), 0, &mut out);
        out
    }

    fn implicit(f: impl Fn(DVec3) -> f64 + Send + Sync + 'static, l: f64, half: glam::Vec3) -> Primitive {
        Primitive::Implicit(Arc::new(Implicit::new(f, l, -half, half)))
    }

    /// Lines from a shell of radius 4 through points near the origin.
    fn lines(n: usize) -> impl Iterator<Item = (DVec3, DVec3)> {
        (0..n).map(|k| {
            let a = k as f64 * 0.61;
            let o = DVec3::new(a.cos() * 3.0, (a * 0.9).sin() * 2.0, a.sin() * 2.5);
            let target = DVec3::new((a * 1.7).sin(), (a * 2.3).cos() * 0.4, (a * 0.5).cos());
            (o, (target - o) * 0.7)
        })
    }

    #[test]
    fn a_signed_distance_traces_like_the_closed_forms() {
        // The sphere's and the torus's signed distances (Lipschitz bound 1), against the
        // sphere's quadratic and the torus's quartic: spans wider than the trace's resolution
        // agree to 1e-9.
        let sphere = implicit(|p| p.length() - 1.0, 1.0, glam::Vec3::splat(1.1));
        let (big, small) = (1.0f32, 0.3f32);
        let torus_sdf = implicit(
            move |p| (DVec3::new(p.x, 0.0, p.z).length() - big as f64).hypot(p.y) - small as f64,
            1.0,
            glam::Vec3::new(1.4, 0.4, 1.4),
        );
        let torus = Primitive::Torus { major: big, minor: small };
        for (shape, exact) in [(&sphere, Primitive::Sphere), (&torus_sdf, torus)] {
            let mut compared = 0;
            for (o, d) in lines(3000) {
                let (s, k) = exact.spans_fixed(o, d, QuarticSolver::default(), 0);
                let wide: Vec<Span> =
                    s[..k].iter().filter(|s| (s.exit.t - s.enter.t) * d.length() > 1e-4).copied().collect();
                let got = spans_of(shape, o, d);
                if wide.len() != k {
                    continue;
                }
                assert_eq!(got.len(), wide.len(), "{exact:?} {o} {d}: {got:?} against {wide:?}");
                for (a, b) in got.iter().zip(&wide) {
                    let ok = (a.enter.t - b.enter.t).abs() < 1e-9 && (a.exit.t - b.exit.t).abs() < 1e-9;
                    assert!(ok, "{exact:?} {o} {d}: {a:?} against {b:?}");
                }
                compared += k;
            }
            assert!(compared > 1000, "{exact:?}: {compared}");
        }
    }

    #[test]
    fn a_thin_plate_is_never_skipped() {
        // A plate 2e-5 thick (about 6e-6 of the box's diagonal): steps of |f| / L cannot jump
        // it, where a marcher with even steps of 0.01 would almost always step over it.
        let plate = implicit(|p| p.y.abs() - 1e-5, 1.0, glam::Vec3::ONE);
        for (o, d) in lines(5000) {
            let o = o + DVec3::new(0.0, 0.37, 0.0);
            let t = -o.y / d.y;
            let at = o + t * d;
            if at.abs().max_element() >= 0.999 || !at.is_finite() {
                continue;
            }
            let s = spans_of(&plate, o, d);
            assert_eq!(s.len(), 1, "{o} {d} {s:?}");
            let mid = 0.5 * (s[0].enter.t + s[0].exit.t);
            assert!((mid - t).abs() * d.length() < 1e-9, "{o} {d} {s:?} plane at {t}");
        }
    }

    #[test]
    fn nan_and_unhelpful_fields_end() {
        // A field that is NaN everywhere is outside everywhere; one that hovers at 0 exhausts
        // the step budget and ends (no hang).
        let nan = implicit(|_| f64::NAN, 1.0, glam::Vec3::ONE);
        assert!(spans_of(&nan, DVec3::new(-3.0, 0.1, 0.2), DVec3::X).is_empty());
        let flat = implicit(|_| 1e-12, 1.0, glam::Vec3::ONE);
        assert!(spans_of(&flat, DVec3::new(-3.0, 0.1, 0.2), DVec3::X).is_empty());
        let bad = Implicit::new(|p| p.length() - 1.0, 0.0, glam::Vec3::ONE, -glam::Vec3::ONE);
        assert!(bad.check().is_some());
        let inverted = Implicit::new(|p| p.length() - 1.0, 1.0, glam::Vec3::ONE, -glam::Vec3::ONE);
        assert!(inverted.check().unwrap().contains("min < max"));
    }
}
