//! Solids: [`Primitive`]s placed by affine transforms and combined by CSG, intersected by the
//! seeds' interval method — every leaf yields the spans of the ray inside it, and union,
//! intersection and difference merge those lists along the ray. Spans and gaps thinner than a
//! scale-aware tolerance are dropped (the seeds' warning about numerical stability), and
//! disjoint results are kept.

use std::cell::RefCell;

use glam::{Affine3A, DAffine3, DMat3, DVec3, Vec3};

use super::primitive::{Bound, Primitive, Span};
use super::solve::QuarticSolver;
use crate::geometry::MAX_COORDINATE;
use crate::simd::{Level, with_level};

/// A CSG operation over two or more operands (POV-Ray's `union`, `intersection`,
/// `difference`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CsgOp {
    /// Inside any operand.
    Union,
    /// Inside every operand.
    Intersection,
    /// Inside the first operand and none of the others.
    Difference,
}

/// A solid: a primitive, a transformed solid, or a CSG combination. Build one with
/// [`Solid::new`], [`transformed`](Self::transformed), [`union`](Self::union),
/// [`intersection`](Self::intersection) and [`difference`](Self::difference); a scene
/// ([`Scene::build_with_solids`](crate::Scene::build_with_solids)) checks it.
#[derive(Clone, Debug, PartialEq)]
pub enum Solid {
    /// A canonical shape in its object space.
    Primitive(Primitive),
    /// A solid placed by an affine map from its space to the enclosing one.
    Transformed(Affine3A, Box<Solid>),
    /// A CSG operation over operands (at least one).
    Csg(CsgOp, Vec<Solid>),
}

impl Solid {
    /// A primitive, unplaced.
    pub fn new(primitive: Primitive) -> Self {
        Solid::Primitive(primitive)
    }

    /// This solid placed by `m` (applied after any transform it already has).
    pub fn transformed(self, m: Affine3A) -> Self {
        match self {
            Solid::Transformed(inner, s) => Solid::Transformed(m * inner, s),
            s => Solid::Transformed(m, Box::new(s)),
        }
    }

    /// The union of `operands`.
    pub fn union(operands: Vec<Solid>) -> Self {
        Solid::Csg(CsgOp::Union, operands)
    }

    /// The intersection of `operands`.
    pub fn intersection(operands: Vec<Solid>) -> Self {
        Solid::Csg(CsgOp::Intersection, operands)
    }

    /// The first operand minus the others.
    pub fn difference(operands: Vec<Solid>) -> Self {
        Solid::Csg(CsgOp::Difference, operands)
    }

    /// Checks the solid as a scene would when building it: `Err` says what is wrong (see
    /// [`Error::BadSolid`](crate::Error::BadSolid)).
    pub fn check(&self) -> Result<(), String> {
        CompiledSolid::new(self, QuarticSolver::default()).map(|_| ())
    }

    /// Whether the world point `p` lies inside (boundaries included): point membership,
    /// evaluated on the tree directly, in float64 (the reference the interval method is tested
    /// against). A disc contains nothing; so does a tree deeper than [`MAX_SOLID_DEPTH`], which
    /// no scene accepts.
    pub fn contains(&self, p: Vec3) -> bool {
        self.contains_f64(DVec3::from(p.to_array().map(f64::from)), 0)
    }

    fn contains_f64(&self, p: DVec3, depth: usize) -> bool {
        if depth > MAX_SOLID_DEPTH {
            return false;
        }
        let inside = |s: &Solid| s.contains_f64(p, depth + 1);
        match self {
            Solid::Primitive(prim) => prim.contains(p),
            Solid::Transformed(m, s) => s.contains_f64(to_f64(m).inverse().transform_point3(p), depth + 1),
            Solid::Csg(op, ops) => match op {
                CsgOp::Union => ops.iter().any(inside),
                CsgOp::Intersection => ops.iter().all(inside),
                CsgOp::Difference => ops.first().is_some_and(inside) && !ops[1..].iter().any(inside),
            },
        }
    }
}

/// An `Affine3A` in float64.
pub(crate) fn to_f64(m: &Affine3A) -> DAffine3 {
    DAffine3::from_cols_array(&m.to_cols_array().map(f64::from))
}

/// A leaf of a compiled solid: its primitive and the map from world to its object space.
#[derive(Clone, Debug)]
pub(crate) struct Leaf {
    pub prim: Primitive,
    pub to_object: DAffine3,
    /// The inverse transpose of the object-to-world map's linear part: object normals to world.
    pub normal_to_world: DMat3,
}

/// One step of a compiled solid's postfix program.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Step {
    /// Push the spans of leaf `i`.
    Leaf(u16),
    /// Combine the top `n` span lists by `op`.
    Op(CsgOp, u16),
}

/// A solid flattened for intersection: leaves with their world-to-object maps, and the CSG tree
/// as a postfix program over span lists.
#[derive(Clone, Debug)]
pub(crate) struct CompiledSolid {
    pub leaves: Vec<Leaf>,
    program: Vec<Step>,
    /// World bounds.
    pub bounds: (Vec3, Vec3),
    /// Spans and gaps thinner than this (world length) are dropped: 1e-6 of the bounds'
    /// diagonal (float32 transforms place coincident faces of different leaves this far apart).
    tolerance: f64,
    pub solver: QuarticSolver,
}

/// Most leaves one solid may have (leaf indices are 16-bit).
pub const MAX_LEAVES: usize = u16::MAX as usize;

/// Deepest solid tree a scene accepts (levels of transforms and CSG operations): the recursive
/// checks stay far from the stack's end.
pub const MAX_SOLID_DEPTH: usize = 256;

/// Relative thickness below which CSG spans and gaps are dropped (of the solid's diagonal).
pub const CSG_TOLERANCE: f64 = 1e-6;

type Bounds = Option<(DVec3, DVec3)>;

impl CompiledSolid {
    /// Flattens and checks `solid`; `Err` says what is wrong with which part.
    pub fn new(solid: &Solid, solver: QuarticSolver) -> Result<Self, String> {
        let mut c = CompiledSolid {
            leaves: Vec::new(),
            program: Vec::new(),
            bounds: (Vec3::ZERO, Vec3::ZERO),
            tolerance: 0.0,
            solver,
        };
        let b = c.flatten(solid, DAffine3::IDENTITY, false, 0)?;
        let Some((lo, hi)) = b else {
            return Err("the solid is unbounded: intersect its plane or quadric with a bounded solid".into());
        };
        let (lo, hi) = if lo.cmple(hi).all() { (lo, hi) } else { (lo.min(hi), lo.min(hi)) };
        if lo.abs().max_element() > MAX_COORDINATE as f64 || hi.abs().max_element() > MAX_COORDINATE as f64 {
            return Err(format!("its bounds {lo}..{hi} reach beyond {MAX_COORDINATE:e}"));
        }
        let f = |v: DVec3| Vec3::new(v.x as f32, v.y as f32, v.z as f32);
        // Rounded outwards to float32.
        let (lo32, hi32) = (f(lo), f(hi));
        let down = |x: f32, want: f64| if (x as f64) > want { x.next_down() } else { x };
        let up = |x: f32, want: f64| if (x as f64) < want { x.next_up() } else { x };
        c.bounds = (
            Vec3::new(down(lo32.x, lo.x), down(lo32.y, lo.y), down(lo32.z, lo.z)),
            Vec3::new(up(hi32.x, hi.x), up(hi32.y, hi.y), up(hi32.z, hi.z)),
        );
        c.tolerance = CSG_TOLERANCE * (hi - lo).length();
        Ok(c)
    }

    /// Appends `s`'s program (placed by `m`, object to world); returns its world bounds.
    fn flatten(&mut self, s: &Solid, m: DAffine3, in_csg: bool, depth: usize) -> Result<Bounds, String> {
        if depth > MAX_SOLID_DEPTH {
            return Err(format!("the tree is deeper than {MAX_SOLID_DEPTH} levels"));
        }
        match s {
            Solid::Primitive(p) => {
                if let Some(why) = p.check() {
                    return Err(why);
                }
                if in_csg && *p == Primitive::Disc {
                    return Err("a disc is a surface, not a solid: it cannot be a CSG operand".into());
                }
                if self.leaves.len() >= MAX_LEAVES {
                    return Err(format!("more than {MAX_LEAVES} primitives in one solid"));
                }
                self.program.push(Step::Leaf(self.leaves.len() as u16));
                self.leaves.push(Leaf {
                    prim: p.clone(),
                    to_object: m.inverse(),
                    normal_to_world: m.matrix3.inverse().transpose(),
                });
                Ok(p.bounds().map(|(lo, hi)| transform_box(&m, lo, hi)))
            }
            Solid::Transformed(t, inner) => {
                let t = to_f64(t);
                let det = t.matrix3.determinant();
                if !t.is_finite() || !det.is_normal() || !t.inverse().is_finite() {
                    return Err(format!("transform {t:?} is not finite and invertible"));
                }
                self.flatten(inner, m * t, in_csg, depth + 1)
            }
            Solid::Csg(op, operands) => {
                if operands.is_empty() {
                    return Err(format!("{op:?} of no operands"));
                }
                if operands.len() > u16::MAX as usize {
                    return Err(format!("{op:?} of more than {} operands", u16::MAX));
                }
                let mut acc: Option<Bounds> = None;
                for o in operands {
                    let b = self.flatten(o, m, true, depth + 1)?;
                    acc = Some(match (acc, op) {
                        (None, _) => b,
                        (Some(a), CsgOp::Union) => a.zip(b).map(|(a, b)| (a.0.min(b.0), a.1.max(b.1))),
                        (Some(a), CsgOp::Intersection) => match (a, b) {
                            (Some(a), Some(b)) => Some((a.0.max(b.0), a.1.min(b.1))),
                            (a, b) => a.or(b),
                        },
                        (Some(a), CsgOp::Difference) => a,
                    });
                }
                if operands.len() > 1 {
                    self.program.push(Step::Op(*op, operands.len() as u16));
                }
                Ok(acc.flatten())
            }
        }
    }

    /// The spans of the world line `o + t d` inside the solid, ascending, into `out` (cleared
    /// first): all of them, also behind `t = 0`.
    #[inline(always)]
    pub fn spans(&self, o: DVec3, d: DVec3, out: &mut Vec<Span>) {
        out.clear();
        // Postfix evaluation: each list is a segment at the end of `out`, `starts` its start.
        SCRATCH.with(|s| {
            let mut s = s.borrow_mut();
            let Scratch { starts, acc, tmp } = &mut *s;
            starts.clear();
            let tol = self.tolerance / d.length();
            for step in &self.program {
                match *step {
                    Step::Leaf(i) => {
                        let leaf = &self.leaves[i as usize];
                        let (lo, ld) = (leaf.to_object.transform_point3(o), leaf.to_object.transform_vector3(d));
                        starts.push(out.len());
                        leaf.prim.spans(lo, ld, self.solver, i, out);
                    }
                    Step::Op(op, n) => {
                        // Left to right: ((A op B) op C) …, as a difference needs.
                        let base = starts.len() - n as usize;
                        let end = |k: usize| if k + 1 < starts.len() { starts[k + 1] } else { out.len() };
                        acc.clear();
                        acc.extend_from_slice(&out[starts[base]..end(base)]);
                        for k in base + 1..starts.len() {
                            if acc.is_empty() && op != CsgOp::Union {
                                break;
                            }
                            tmp.clear();
                            combine(op, acc, &out[starts[k]..end(k)], tol, tmp);
                            std::mem::swap(acc, tmp);
                        }
                        out.truncate(starts[base]);
                        out.extend_from_slice(acc);
                        starts.truncate(base + 1);
                    }
                }
            }
        });
        // A lone primitive's spans are exact; CSG results were cleaned as they were merged.
    }

    /// [`first_hit`](Self::first_hit) compiled for the level `L`: the spans, the primitives'
    /// span functions and the quartic solvers are inlined into it, so that a dependency build
    /// runs them with the level's instructions (VEX encoding, AVX registers) instead of the
    /// crate's baseline.
    #[inline(never)]
    pub fn first_hit_at<L: Level>(&self, o: Vec3, d: Vec3, tnear: f32, tfar: f32) -> Option<(f32, Bound)> {
        L::call(
            #[inline(always)]
            || self.first_hit(o, d, tnear, tfar),
        )
    }

    /// The first surface crossing in `(tnear, tfar]` of the world ray: `(t, bound)`.
    #[inline(always)]
    pub fn first_hit(&self, o: Vec3, d: Vec3, tnear: f32, tfar: f32) -> Option<(f32, Bound)> {
        let (o, d) = (dvec(o), dvec(d));
        SPANS.with(|buf| {
            let mut buf = buf.borrow_mut();
            self.spans(o, d, &mut buf);
            for sp in buf.iter() {
                for b in [sp.enter, sp.exit] {
                    // The crossing in float32, as the queries' intervals are.
                    let t = b.t as f32;
                    if t > tnear && t.is_finite() {
                        return (t <= tfar).then_some((t, b));
                    }
                }
            }
            None
        })
    }

    /// Calls `f(t, bound)` for every surface crossing in `(tnear, tfar]`, ascending (a disc's
    /// crossing once).
    pub fn each_crossing(&self, o: Vec3, d: Vec3, tnear: f32, tfar: f32, mut f: impl FnMut(f32, Bound)) {
        let (o, d) = (dvec(o), dvec(d));
        SPANS.with(|buf| {
            let mut buf = buf.borrow_mut();
            self.spans(o, d, &mut buf);
            for sp in buf.iter() {
                let ends: &[Bound] = if sp.enter.t == sp.exit.t { &[sp.enter] } else { &[sp.enter, sp.exit] };
                for b in ends {
                    let t = b.t as f32;
                    if t > tnear && t <= tfar && t.is_finite() {
                        f(t, *b);
                    }
                }
            }
        });
    }

    /// The outward unit normal (world space) where the world ray `o + t d` crosses `b` (at `b.t`).
    pub fn normal(&self, o: Vec3, d: Vec3, b: &Bound) -> Vec3 {
        let leaf = &self.leaves[b.leaf as usize];
        let p = leaf.to_object.transform_point3(dvec(o) + b.t.clamp(-1e300, 1e300) * dvec(d));
        let n = leaf.normal_to_world * leaf.prim.normal(p, b.face);
        let n = if b.flip { -n } else { n };
        let n = n.normalize_or_zero();
        Vec3::new(n.x as f32, n.y as f32, n.z as f32)
    }
}

/// One solid checked and flattened for intersection on its own, outside a scene: the same code
/// the solid BVH's leaves run, for callers that bring their own acceleration structure (the
/// harness hands it to Embree as user geometry).
#[derive(Clone, Debug)]
pub struct PreparedSolid(CompiledSolid);

impl PreparedSolid {
    /// Checks and flattens `solid` ([`Error::BadSolid`](crate::Error::BadSolid) with index 0
    /// where it cannot be built).
    pub fn new(solid: &Solid, solver: QuarticSolver) -> crate::Result<Self> {
        CompiledSolid::new(solid, solver).map(Self).map_err(|message| crate::Error::BadSolid { index: 0, message })
    }

    /// World bounds (rounded outwards to float32).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.0.bounds
    }

    /// The first surface crossing of `ray` in `(tnear, tfar]`: its `t`, the outward unit normal
    /// there, and the index of the primitive crossed (a hit's `prim_id`). Invalid rays miss.
    pub fn intersect(&self, ray: &crate::Ray) -> Option<(f32, Vec3, u32)> {
        if !ray.is_valid() {
            return None;
        }
        let r = ray.clamped_to_zero();
        let (t, b) = with_level!(|L| self.0.first_hit_at::<L>(r.origin, r.dir, r.tnear, r.tfar))?;
        Some((t, self.0.normal(r.origin, r.dir, &b), b.leaf as u32))
    }
}

/// `v` in float64.
#[inline(always)]
pub(crate) fn dvec(v: Vec3) -> DVec3 {
    DVec3::new(v.x as f64, v.y as f64, v.z as f64)
}

/// The box around `[lo, hi]` mapped by `m`.
fn transform_box(m: &DAffine3, lo: DVec3, hi: DVec3) -> (DVec3, DVec3) {
    let (mut a, mut b) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for k in 0..8 {
        let c = DVec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        let p = m.transform_point3(c);
        a = a.min(p);
        b = b.max(p);
    }
    (a, b)
}

struct Scratch {
    starts: Vec<usize>,
    acc: Vec<Span>,
    tmp: Vec<Span>,
}

thread_local! {
    /// Reused buffers: no query allocates once a thread has traced its largest solid.
    static SCRATCH: RefCell<Scratch> = const { RefCell::new(Scratch { starts: Vec::new(), acc: Vec::new(), tmp: Vec::new() }) };
    static SPANS: RefCell<Vec<Span>> = const { RefCell::new(Vec::new()) };
}

/// Appends `s` to `out`, merging it into the last span where the gap between them is thinner
/// than `tol`, and leaves out spans thinner than `tol`.
fn push_span(out: &mut Vec<Span>, s: Span, tol: f64) {
    if let Some(last) = out.last_mut()
        && s.enter.t - last.exit.t < tol
    {
        if s.exit.t > last.exit.t {
            last.exit = s.exit;
        }
        return;
    }
    if s.exit.t - s.enter.t >= tol {
        out.push(s);
    }
}

/// `a op b` for ascending disjoint span lists, into `out`.
fn combine(op: CsgOp, a: &[Span], b: &[Span], tol: f64, out: &mut Vec<Span>) {
    match op {
        CsgOp::Union => {
            let (mut i, mut j) = (0, 0);
            while i < a.len() || j < b.len() {
                let take_a = j >= b.len() || (i < a.len() && a[i].enter.t <= b[j].enter.t);
                let s = if take_a {
                    i += 1;
                    a[i - 1]
                } else {
                    j += 1;
                    b[j - 1]
                };
                push_span(out, s, tol);
            }
        }
        CsgOp::Intersection => {
            let (mut i, mut j) = (0, 0);
            while i < a.len() && j < b.len() {
                let enter = if a[i].enter.t >= b[j].enter.t { a[i].enter } else { b[j].enter };
                let exit = if a[i].exit.t <= b[j].exit.t { a[i].exit } else { b[j].exit };
                if exit.t - enter.t >= tol {
                    out.push(Span { enter, exit });
                }
                if a[i].exit.t <= b[j].exit.t {
                    i += 1;
                } else {
                    j += 1;
                }
            }
        }
        CsgOp::Difference => {
            let flip = |b: Bound| Bound { flip: !b.flip, ..b };
            let mut j = 0;
            for s in a {
                let mut enter = s.enter;
                // Skip the cuts wholly before this span.
                while j < b.len() && b[j].exit.t <= enter.t {
                    j += 1;
                }
                let mut k = j;
                while k < b.len() && b[k].enter.t < s.exit.t {
                    let cut = b[k];
                    if cut.enter.t > enter.t {
                        push_span(out, Span { enter, exit: flip(cut.enter) }, tol);
                    }
                    if cut.exit.t > enter.t {
                        enter = flip(cut.exit);
                    }
                    k += 1;
                }
                if enter.t < s.exit.t {
                    push_span(out, Span { enter, exit: s.exit }, tol);
                }
                // The last cut may reach into the next span.
                j = k.saturating_sub(1).max(j);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn span(t0: f64, t1: f64) -> Span {
        Span {
            enter: Bound { t: t0, leaf: 0, face: 0, flip: false },
            exit: Bound { t: t1, leaf: 0, face: 0, flip: false },
        }
    }

    fn ts(s: &[Span]) -> Vec<(f64, f64)> {
        s.iter().map(|s| (s.enter.t, s.exit.t)).collect()
    }

    #[test]
    fn interval_algebra() {
        let a = [span(0.0, 2.0), span(4.0, 6.0)];
        let b = [span(1.0, 5.0)];
        let mut out = Vec::new();
        combine(CsgOp::Union, &a, &b, 1e-9, &mut out);
        assert_eq!(ts(&out), [(0.0, 6.0)]);
        out.clear();
        combine(CsgOp::Intersection, &a, &b, 1e-9, &mut out);
        assert_eq!(ts(&out), [(1.0, 2.0), (4.0, 5.0)]);
        out.clear();
        combine(CsgOp::Difference, &a, &b, 1e-9, &mut out);
        assert_eq!(ts(&out), [(0.0, 1.0), (5.0, 6.0)]);
        assert!(out[0].exit.flip && out[1].enter.flip && !out[0].enter.flip);
        // A cut spanning several spans, and a sliver left by coincident faces is dropped.
        out.clear();
        combine(
            CsgOp::Difference,
            &[span(0.0, 1.0), span(2.0, 3.0), span(4.0, 5.0)],
            &[span(0.5, 4.0 + 1e-12)],
            1e-9,
            &mut out,
        );
        assert_eq!(ts(&out), [(0.0, 0.5), (4.0 + 1e-12, 5.0)]);
        out.clear();
        combine(CsgOp::Difference, &[span(0.0, 1.0)], &[span(-1.0, 1.0 - 1e-12)], 1e-9, &mut out);
        assert!(out.is_empty(), "{:?}", ts(&out));
    }
}
