//! Diffing two engines' answers on the same rays, with every disagreement decided by a float64
//! recomputation from the same f32 inputs (ACCURACY.md, "Metrics").

use glam::Vec3;
use serde::Serialize;
use strahl::{Ray, RayStream, TriangleMesh};

use crate::harness::Answers;

/// Barycentric distance from an edge below which a disagreement counts as an edge or vertex tie:
/// f32 Möller–Trumbore decides such rays by rounding, so either answer is legitimate. This is the
/// floor; [`edge_tolerance`] raises it where the coordinates are large against the triangle.
pub const EDGE_TOL: f64 = 1e-5;

/// The barycentric tie tolerance for `ray` against `tri`: the f32 edge functions carry absolute
/// errors of a few ulps of the coordinates involved (origin and corners), which in barycentric
/// terms is that error over the triangle's size, and over the cosine between ray and plane (a
/// grazing ray moves its hit point along the plane by the error over that cosine). 64 ulps,
/// never below [`EDGE_TOL`].
pub fn edge_tolerance(ray: &Ray, tri: [Vec3; 3]) -> f64 {
    let (err, size, cos) = conditioning(ray, tri);
    if size <= 0.0 || !size.is_finite() {
        return EDGE_TOL;
    }
    (err / (size * cos)).max(EDGE_TOL)
}

/// The absolute tie tolerance on `t` for `ray` against `tri`: the same coordinate error, along the
/// ray, over the cosine between ray and plane and the direction's length.
pub fn depth_tolerance(ray: &Ray, tri: [Vec3; 3]) -> f64 {
    let (err, _, cos) = conditioning(ray, tri);
    err / (cos * (ray.dir.length() as f64).max(1e-30))
}

/// `(64 ulps of the largest coordinate, sqrt of twice the area, |cos| between ray and plane)`,
/// the cosine floored at 1e-6.
fn conditioning(ray: &Ray, tri: [Vec3; 3]) -> (f64, f64, f64) {
    let mag = tri.iter().map(|p| p.abs().max_element()).fold(ray.origin.abs().max_element(), f32::max) as f64;
    let n = (tri[1] - tri[0]).as_dvec3().cross((tri[2] - tri[0]).as_dvec3());
    let size = n.length().sqrt();
    let cos = (n.normalize_or_zero().dot(ray.dir.as_dvec3().normalize_or_zero())).abs().max(1e-6);
    (64.0 * f32::EPSILON as f64 * mag, size, cos)
}

/// Relative distance between two candidate hits, or from a ray bound, below which they tie.
pub const DEPTH_TOL: f64 = 1e-5;
/// Occlusion disagreements decided by a float64 brute-force pass over all triangles, at most.
const MAX_BRUTE_FORCE: usize = 64;

#[derive(Clone, Debug, Default, Serialize)]
pub struct Disagreements {
    /// The ray passes within rounding of a triangle edge or vertex.
    pub edge_or_vertex_tie: usize,
    /// Two surfaces at the same distance, or a hit at the ray's tnear/tfar bound.
    pub depth_tie: usize,
    /// The float64 reference says strahl is wrong.
    pub strahl_error: usize,
    /// The float64 reference says Embree is wrong.
    pub embree_error: usize,
    /// Not decided (occlusion disagreements beyond the brute-force budget).
    pub undecided: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct Case {
    pub ray: usize,
    pub kind: &'static str,
    pub verdict: &'static str,
    pub strahl: (f32, u32, u32),
    pub embree: (f32, u32, u32),
    /// Smallest barycentric coordinate of the deciding triangle in float64.
    pub min_barycentric: f64,
    pub t64: f64,
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct Accuracy {
    pub hit_miss_agreement: f64,
    /// Among rays both engines hit: same geometry and primitive.
    pub prim_agreement: f64,
    /// Relative t difference among rays hitting the same primitive.
    pub t_rel_median: f64,
    pub t_rel_p999: f64,
    pub t_rel_max: f64,
    pub hit_miss_disagreements: usize,
    pub prim_disagreements: usize,
    pub classified: Disagreements,
    pub worst: Vec<Case>,
}

/// Float64 Möller–Trumbore without range checks (strahl's reference, [`strahl::exact_hit`]).
pub fn exact(ray: &Ray, tri: [Vec3; 3]) -> Option<(f64, [f64; 3])> {
    strahl::exact_hit(ray.origin, ray.dir, tri)
}

fn min3(b: [f64; 3]) -> f64 {
    b[0].min(b[1]).min(b[2])
}

/// Whether the float64 hit `(t, b)` is inside the triangle and the ray interval, with a margin:
/// `Some(true)` clearly a hit, `Some(false)` clearly not, `None` within tolerance of a boundary.
fn decide(ray: &Ray, tri: [Vec3; 3], h: Option<(f64, [f64; 3])>) -> (Option<bool>, &'static str) {
    let Some((t, b)) = h else {
        return (Some(false), "parallel");
    };
    let m = min3(b);
    let (tn, tf) = (ray.tnear as f64, ray.tfar as f64);
    let scale = t.abs().max(1e-30);
    if m.abs() <= edge_tolerance(ray, tri) {
        return (None, "edge_or_vertex");
    }
    let tol = (DEPTH_TOL * scale).max(depth_tolerance(ray, tri));
    if (t - tn).abs() <= tol || (tf.is_finite() && (t - tf).abs() <= tol) {
        return (None, "depth");
    }
    (Some(m > 0.0 && t > tn && t <= tf), "clear")
}

/// The triangles answers can name, in world space, for float64 decisions.
pub trait World: Sync {
    /// The corners of triangle (instance, geometry, primitive), if it exists.
    fn tri(&self, key: (u32, u32, u32)) -> Option<[Vec3; 3]>;
    /// Calls `f` with every hittable triangle that `ray` might meet (all of them, or those of
    /// the instances whose world box the ray crosses); `f` returns true to stop.
    fn for_each_near(&self, ray: &Ray, f: &mut dyn FnMut([Vec3; 3]) -> bool);
}

/// The meshes of a flat scene.
pub struct Flat<'a>(pub &'a [TriangleMesh]);

impl World for Flat<'_> {
    fn tri(&self, (_, geom, prim): (u32, u32, u32)) -> Option<[Vec3; 3]> {
        let m = self.0.get(geom as usize)?;
        ((prim as usize) < m.triangle_count()).then(|| m.triangle(prim as usize))
    }

    fn for_each_near(&self, _ray: &Ray, f: &mut dyn FnMut([Vec3; 3]) -> bool) {
        for m in self.0 {
            for i in (0..m.triangle_count()).filter(|&i| m.is_hittable(i)) {
                if f(m.triangle(i)) {
                    return;
                }
            }
        }
    }
}

/// Objects placed by instances: triangles moved into world space in float64, then rounded.
pub struct InstancedWorld<'a> {
    pub objects: &'a [Vec<TriangleMesh>],
    pub instances: &'a [strahl::Instance],
    boxes: Vec<Option<(Vec3, Vec3)>>,
}

impl<'a> InstancedWorld<'a> {
    pub fn new(objects: &'a [Vec<TriangleMesh>], instances: &'a [strahl::Instance]) -> Self {
        let boxes = instances
            .iter()
            .map(|inst| {
                let mut b: Option<(Vec3, Vec3)> = None;
                for m in &objects[inst.object] {
                    for p in m.positions().iter().filter(|p| p.is_finite()) {
                        let w = inst.transform.transform_point3(*p);
                        b = Some(b.map_or((w, w), |(lo, hi)| (lo.min(w), hi.max(w))));
                    }
                }
                b
            })
            .collect();
        Self { objects, instances, boxes }
    }

    fn world(&self, inst: usize, tri: [Vec3; 3]) -> [Vec3; 3] {
        let t = self.instances[inst].transform;
        let m = glam::DAffine3::from_mat3_translation(t.matrix3.as_dmat3(), t.translation.as_dvec3());
        tri.map(|p| m.transform_point3(p.as_dvec3()).as_vec3())
    }
}

impl World for InstancedWorld<'_> {
    fn tri(&self, (inst, geom, prim): (u32, u32, u32)) -> Option<[Vec3; 3]> {
        let i = self.instances.get(inst as usize)?;
        let m = self.objects[i.object].get(geom as usize)?;
        ((prim as usize) < m.triangle_count()).then(|| self.world(inst as usize, m.triangle(prim as usize)))
    }

    fn for_each_near(&self, ray: &Ray, f: &mut dyn FnMut([Vec3; 3]) -> bool) {
        for (k, inst) in self.instances.iter().enumerate() {
            let Some((lo, hi)) = self.boxes[k] else { continue };
            // A slab test in float64 on the box widened by a thousandth of its size.
            let pad = (hi - lo).as_dvec3() * 1e-3 + glam::DVec3::splat(1e-9);
            let (lo, hi) = (lo.as_dvec3() - pad, hi.as_dvec3() + pad);
            let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
            let (mut tn, mut tf) = (ray.tnear as f64, ray.tfar as f64);
            for a in 0..3 {
                let (t0, t1) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
                let (t0, t1) = if t0.is_nan() || t1.is_nan() { (f64::NEG_INFINITY, f64::INFINITY) } else { (t0, t1) };
                tn = tn.max(t0.min(t1));
                tf = tf.min(t0.max(t1));
            }
            if tn > tf {
                continue;
            }
            for m in &self.objects[inst.object] {
                for i in (0..m.triangle_count()).filter(|&i| m.is_hittable(i)) {
                    if f(self.world(k, m.triangle(i))) {
                        return;
                    }
                }
            }
        }
    }
}

/// Compares strahl's answers `s` with Embree's `e` on `rays`.
pub fn compare(world: &dyn World, rays: &RayStream, occlusion: bool, s: &Answers, e: &Answers) -> Accuracy {
    let n = rays.len();
    let mut acc = Accuracy::default();
    let mut rel = Vec::new();
    let mut both = 0usize;
    let mut same_prim = 0usize;
    let mut cases: Vec<(u8, f64, Case)> = Vec::new();
    let mut brute_left = MAX_BRUTE_FORCE;
    for i in 0..n {
        let (sh, eh) = (s.hit(i), e.hit(i));
        let ray = rays.get(i);
        let sa = (s.t[i], s.geom[i], s.prim[i]);
        let ea = (e.t[i], e.geom[i], e.prim[i]);
        if sh != eh {
            acc.hit_miss_disagreements += 1;
            // Decide by the triangle the hitting engine reported, or by brute force for occlusion.
            let (verdict, minb, t64) = if occlusion {
                if brute_left == 0 {
                    ("undecided", f64::NAN, f64::NAN)
                } else {
                    brute_left -= 1;
                    let (any_clear, any_tie, t64, mb) = brute_force_occlusion(world, &ray);
                    if any_clear {
                        (if sh { "embree_error" } else { "strahl_error" }, mb, t64)
                    } else if let Some(kind) = any_tie {
                        (kind, mb, t64)
                    } else {
                        (if sh { "strahl_error" } else { "embree_error" }, mb, t64)
                    }
                }
            } else {
                let key = if sh { s.key(i) } else { e.key(i) };
                match world.tri(key).map(|t| (t, exact(&ray, t))) {
                    Some((tri, h)) => {
                        let (clear, kind) = decide(&ray, tri, h);
                        let (t64, mb) = h.map(|(t, b)| (t, min3(b))).unwrap_or((f64::NAN, f64::NAN));
                        match clear {
                            None => (if kind == "depth" { "depth_tie" } else { "edge_or_vertex_tie" }, mb, t64),
                            // The reported hit is real: the engine that missed erred.
                            Some(true) => (if sh { "embree_error" } else { "strahl_error" }, mb, t64),
                            Some(false) => (if sh { "strahl_error" } else { "embree_error" }, mb, t64),
                        }
                    }
                    None => (if sh { "strahl_error" } else { "embree_error" }, f64::NAN, f64::NAN),
                }
            };
            record(
                &mut acc.classified,
                &mut cases,
                Case { ray: i, kind: "hit_miss", verdict, strahl: sa, embree: ea, min_barycentric: minb, t64 },
            );
            continue;
        }
        if !sh || occlusion {
            continue;
        }
        both += 1;
        if s.key(i) == e.key(i) {
            same_prim += 1;
            let r = ((sa.0 as f64 - ea.0 as f64) / (ea.0 as f64).abs().max(1e-30)).abs();
            rel.push(r);
            continue;
        }
        acc.prim_disagreements += 1;
        let (ts3, te3) = (world.tri(s.key(i)), world.tri(e.key(i)));
        let hs = ts3.and_then(|t| exact(&ray, t));
        let he = te3.and_then(|t| exact(&ray, t));
        let (verdict, minb, t64) = match (hs, he, ts3, te3) {
            (Some((ts, bs)), Some((te, be)), Some(tri_s), Some(tri_e)) => {
                let scale = ts.abs().max(te.abs()).max(1e-30);
                let mb = min3(bs).min(min3(be));
                if min3(bs).abs() <= edge_tolerance(&ray, tri_s) || min3(be).abs() <= edge_tolerance(&ray, tri_e) {
                    ("edge_or_vertex_tie", mb, ts.min(te))
                } else if (ts - te).abs()
                    <= (DEPTH_TOL * scale).max(depth_tolerance(&ray, tri_s)).max(depth_tolerance(&ray, tri_e))
                {
                    ("depth_tie", mb, ts.min(te))
                } else if ts < te {
                    // strahl's triangle is nearer; Embree's answer is wrong unless strahl's is not a hit.
                    if min3(bs) > 0.0 { ("embree_error", mb, ts) } else { ("strahl_error", mb, te) }
                } else if min3(be) > 0.0 {
                    ("strahl_error", mb, te)
                } else {
                    ("embree_error", mb, ts)
                }
            }
            _ => ("undecided", f64::NAN, f64::NAN),
        };
        record(
            &mut acc.classified,
            &mut cases,
            Case { ray: i, kind: "primitive", verdict, strahl: sa, embree: ea, min_barycentric: minb, t64 },
        );
    }
    acc.hit_miss_agreement = if n == 0 { 1.0 } else { 1.0 - acc.hit_miss_disagreements as f64 / n as f64 };
    acc.prim_agreement = if both == 0 { 1.0 } else { same_prim as f64 / both as f64 };
    rel.sort_by(f64::total_cmp);
    if !rel.is_empty() {
        let q = |f: f64| rel[((rel.len() - 1) as f64 * f).round() as usize];
        acc.t_rel_median = q(0.5);
        acc.t_rel_p999 = q(0.999);
        acc.t_rel_max = *rel.last().expect("non-empty");
    }
    cases.sort_by(|a, b| a.0.cmp(&b.0).then(b.1.total_cmp(&a.1)));
    acc.worst = cases.into_iter().take(5).map(|c| c.2).collect();
    acc
}

/// Counts a decided disagreement and keeps it for the worst-case list: errors first, then
/// hit/miss before primitive disagreements, nearest to an edge last.
fn record(d: &mut Disagreements, cases: &mut Vec<(u8, f64, Case)>, case: Case) {
    tally(d, case.verdict);
    let sev = if case.verdict.ends_with("error") {
        0
    } else if case.kind == "hit_miss" {
        1
    } else {
        2
    };
    cases.push((sev, -case.min_barycentric.abs(), case));
}

fn tally(d: &mut Disagreements, verdict: &str) {
    match verdict {
        "edge_or_vertex_tie" | "edge_or_vertex" => d.edge_or_vertex_tie += 1,
        "depth_tie" | "depth" => d.depth_tie += 1,
        "strahl_error" => d.strahl_error += 1,
        "embree_error" => d.embree_error += 1,
        _ => d.undecided += 1,
    }
}

/// Float64 occlusion of `ray` over every triangle: (some triangle clearly occludes, the kind of
/// tie if some triangle is within tolerance, nearest t, its smallest barycentric).
fn brute_force_occlusion(world: &dyn World, ray: &Ray) -> (bool, Option<&'static str>, f64, f64) {
    let mut tie = None;
    let mut best = (f64::INFINITY, f64::NAN);
    let mut clear = None;
    world.for_each_near(ray, &mut |tri| {
        let h = exact(ray, tri);
        match decide(ray, tri, h) {
            (Some(true), _) => {
                clear = h;
                return true;
            }
            (None, kind) => {
                let (t, b) = h.expect("ties exist");
                // A tie at the ray's start (a ray from a vertex: t = 0 within rounding) counts
                // within the same depth tolerance `decide` allows.
                let tol = (DEPTH_TOL * t.abs()).max(depth_tolerance(ray, tri));
                if t >= ray.tnear as f64 - tol && t < best.0 {
                    best = (t, min3(b));
                    tie = Some(if kind == "depth" { "depth_tie" } else { "edge_or_vertex_tie" });
                }
            }
            _ => {}
        }
        false
    });
    if let Some((t, b)) = clear {
        return (true, None, t, min3(b));
    }
    (false, tie, best.0, best.1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_matches_the_definition() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let r = Ray::new(Vec3::new(0.25, 0.5, 2.0), Vec3::new(0.0, 0.0, -1.0));
        let (t, b) = exact(&r, tri).unwrap();
        assert!((t - 2.0).abs() < 1e-12);
        assert!((b[1] - 0.25).abs() < 1e-12 && (b[2] - 0.5).abs() < 1e-12);
        assert_eq!(decide(&r, tri, Some((t, b))).0, Some(true));
        let edge = Ray::new(Vec3::new(0.5, 0.0, 2.0), Vec3::new(0.0, 0.0, -1.0));
        assert_eq!(decide(&edge, tri, exact(&edge, tri)).0, None);
        // Far from the origin the tolerance grows with the coordinates.
        let far = [Vec3::splat(1e4), Vec3::splat(1e4) + Vec3::X, Vec3::splat(1e4) + Vec3::Y];
        assert!(edge_tolerance(&r, far) > 100.0 * edge_tolerance(&r, tri));
    }
}
