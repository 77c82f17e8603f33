//! The point of a scene nearest to a query point: a best-first walk of the BVH pruned by box
//! distance, with Ericson's point–triangle test (Real-Time Collision Detection, §5.1.5) in float64
//! at the leaves.

use glam::{Affine3A, DVec3, Vec3};

use crate::bvh::Bvh;
use crate::bvh::node::{EMPTY, Node, is_leaf, leaf_blocks};
use crate::geometry::TriangleMesh;
use crate::instance::InstancedScene;
use crate::ray::INVALID_ID;
use crate::scene::Scene;
use crate::shapes::tree::SphereBvh;

/// The point of a scene nearest to a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClosestPoint {
    /// The nearest surface point, in world space.
    pub point: Vec3,
    /// Its distance from the query point.
    pub distance: f32,
    /// Barycentric coordinates of `point` on its triangle (as [`Hit`](crate::Hit)'s `u`, `v`);
    /// 0 on a sphere.
    pub u: f32,
    /// Barycentric coordinate of `v2`.
    pub v: f32,
    /// The triangle's unnormalized geometric normal `(v1 − v0) × (v2 − v0)` in world space; on a
    /// sphere, `point − centre`.
    pub ng: Vec3,
    /// The triangle's (or sphere's) index within its geometry.
    pub prim_id: u32,
    /// The geometry's index.
    pub geom_id: u32,
    /// The instance, or [`INVALID_ID`] in a flat scene.
    pub inst_id: u32,
}

/// The best candidate so far: squared world distance and its record.
struct Best {
    d2: f64,
    found: Option<ClosestPoint>,
}

impl Best {
    /// Takes the surface point `q` (squared distance `d2`) if it is nearer than the best so far,
    /// or the first within the bound; `record` fills in the rest of its record.
    #[inline]
    fn offer(&mut self, q: DVec3, d2: f64, record: impl FnOnce(ClosestPoint) -> ClosestPoint) {
        if d2 < self.d2 || (self.found.is_none() && d2 <= self.d2) {
            self.d2 = d2;
            let base = ClosestPoint {
                point: q.as_vec3(),
                distance: d2.sqrt() as f32,
                u: 0.0,
                v: 0.0,
                ng: Vec3::ZERO,
                prim_id: INVALID_ID,
                geom_id: INVALID_ID,
                inst_id: INVALID_ID,
            };
            self.found = Some(record(base));
        }
    }
}

/// Where an object sits: its meshes, the query point in object space, the world query point, and
/// how the object maps to the world.
struct Placement<'a> {
    meshes: &'a [TriangleMesh],
    /// The query point in the object's space (the BVH's space).
    p_obj: Vec3,
    p_world: DVec3,
    /// Object to world; `None` for a flat scene (the identity).
    to_world: Option<Affine3A>,
    /// A lower bound on how much the transform shrinks lengths (its smallest singular value, or
    /// less): a box `d` away in object space is at least `scale·d` away in the world.
    scale: f32,
    inst_id: u32,
}

impl Scene {
    /// See [`SpatialQuery::closest_point`](super::SpatialQuery::closest_point).
    pub(crate) fn closest_point_impl(&self, p: Vec3, max_distance: f32) -> Option<ClosestPoint> {
        if !p.is_finite() || max_distance.is_nan() || max_distance < 0.0 {
            return None;
        }
        let mut best = Best { d2: (max_distance as f64).powi(2), found: None };
        let at = Placement {
            meshes: self.meshes(),
            p_obj: p,
            p_world: p.as_dvec3(),
            to_world: None,
            scale: 1.0,
            inst_id: INVALID_ID,
        };
        closest_in(self.bvh(), &at, &mut best);
        closest_sphere_in(self.sphere_tree(), &at, &mut best);
        best.found
    }
}

impl InstancedScene {
    /// See [`SpatialQuery::closest_point`](super::SpatialQuery::closest_point).
    pub(crate) fn closest_point_impl(&self, p: Vec3, max_distance: f32) -> Option<ClosestPoint> {
        if !p.is_finite() || max_distance.is_nan() || max_distance < 0.0 {
            return None;
        }
        let root = self.top_root()?;
        let mut best = Best { d2: (max_distance as f64).powi(2), found: None };
        let nodes = self.top_tree().nodes;
        // The instance level: world boxes, one instance per leaf.
        walk_boxes(nodes, root, p, 1.0, &mut best, |leaf, best| {
            let (start, count) = leaf_blocks(leaf);
            for k in start..start + count {
                let (object, to_world, inst_id) = self.placed_of(k);
                let inv = to_world.inverse();
                let at = Placement {
                    meshes: self.objects()[object as usize].meshes(),
                    p_obj: inv.transform_point3(p),
                    p_world: p.as_dvec3(),
                    to_world: Some(to_world),
                    // ‖M⁻¹‖_F ≥ ‖M⁻¹‖₂ = 1/σ_min(M).
                    scale: 1.0 / frobenius(&inv),
                    inst_id,
                };
                closest_in(self.objects()[object as usize].bvh(), &at, best);
                closest_sphere_in(self.objects()[object as usize].sphere_tree(), &at, best);
            }
        });
        best.found
    }
}

/// The Frobenius norm of an affine map's linear part.
fn frobenius(m: &Affine3A) -> f32 {
    let c = m.matrix3;
    (c.x_axis.length_squared() + c.y_axis.length_squared() + c.z_axis.length_squared()).sqrt()
}

/// The nearest triangle of one BVH to the placement's query point, improving `best`.
fn closest_in(bvh: &Bvh, at: &Placement<'_>, best: &mut Best) {
    if bvh.root == EMPTY {
        return;
    }
    walk_boxes(&bvh.nodes, bvh.root, at.p_obj, at.scale, best, |leaf, best| {
        let (start, count) = leaf_blocks(leaf);
        for b in &bvh.blocks[start..start + count] {
            for lane in 0..b.prim.len() {
                if b.prim[lane] == u32::MAX {
                    continue;
                }
                let (geom, prim) = (b.geom_id(bvh.test, lane), b.prim[lane]);
                let mut tri = at.meshes[geom as usize].triangle(prim as usize);
                if let Some(m) = &at.to_world {
                    tri = tri.map(|v| m.transform_point3(v));
                }
                let [a, bb, c] = tri.map(|v| v.as_dvec3());
                let (q, u, v) = closest_on_triangle(at.p_world, a, bb, c);
                let d2 = (q - at.p_world).length_squared();
                best.offer(q, d2, |cp| ClosestPoint {
                    u: u as f32,
                    v: v as f32,
                    ng: (tri[1] - tri[0]).cross(tri[2] - tri[0]),
                    prim_id: prim,
                    geom_id: geom,
                    inst_id: at.inst_id,
                    ..cp
                });
            }
        }
    });
}

/// The nearest sphere surface point of one sphere tree to the placement's query point, improving
/// `best`: in object space the centre's direction scaled to the radius (from the centre itself,
/// the point above it in +y), moved to the world, distances in float64. Exact in the world
/// because instances of spheres are similarities. `u = v = 0`, `ng = point − centre` (world).
fn closest_sphere_in(tree: &SphereBvh, at: &Placement<'_>, best: &mut Best) {
    if tree.is_empty() {
        return;
    }
    let po = at.p_obj.as_dvec3();
    walk_boxes(&tree.nodes, tree.root, at.p_obj, at.scale, best, |leaf, best| {
        let (start, count) = leaf_blocks(leaf);
        for b in &tree.blocks[start..start + count] {
            for lane in 0..b.prim.len() {
                if b.prim[lane] == u32::MAX {
                    continue;
                }
                let (c, r) = (b.center(lane).as_dvec3(), b.rows[3][lane] as f64);
                let dir = (po - c).try_normalize().unwrap_or(DVec3::Y);
                let (mut q, mut c_w) = (c + dir * r, c);
                if let Some(m) = &at.to_world {
                    let m = glam::DAffine3::from_cols_array(&m.to_cols_array().map(|x| x as f64));
                    q = m.transform_point3(q);
                    c_w = m.transform_point3(c);
                }
                let d2 = (q - at.p_world).length_squared();
                best.offer(q, d2, |cp| ClosestPoint {
                    ng: (q - c_w).as_vec3(),
                    prim_id: b.prim[lane],
                    geom_id: b.geom[lane],
                    inst_id: at.inst_id,
                    ..cp
                });
            }
        }
    });
}

/// Best-first walk over wide nodes from `root`: children nearer (squared box distance from `p`,
/// times `scale²`) than the best so far are visited nearest first; `leaf` tests a leaf.
fn walk_boxes(nodes: &[Node], root: u32, p: Vec3, scale: f32, best: &mut Best, mut leaf: impl FnMut(u32, &mut Best)) {
    let s2 = (scale as f64) * (scale as f64);
    let mut stack: Vec<(u32, f64)> = Vec::with_capacity(64);
    stack.push((root, 0.0));
    while let Some((r, d2)) = stack.pop() {
        if d2 * s2 > best.d2 {
            continue;
        }
        if is_leaf(r) {
            leaf(r, best);
            continue;
        }
        let node = &nodes[r as usize];
        let first = stack.len();
        for i in 0..node.child.len() {
            if node.child[i] == EMPTY {
                continue;
            }
            let b = &node.bounds;
            let gap = |a: usize, x: f32| ((b[2 * a][i] - x).max(x - b[2 * a + 1][i]).max(0.0)) as f64;
            let d2 = gap(0, p.x).powi(2) + gap(1, p.y).powi(2) + gap(2, p.z).powi(2);
            if d2 * s2 <= best.d2 {
                stack.push((node.child[i], d2));
            }
        }
        // Nearest on top.
        stack[first..].sort_unstable_by(|a, b| b.1.total_cmp(&a.1));
    }
}

/// The point of triangle `abc` nearest to `p`, with its barycentrics `(u, v)` (weights of `b` and
/// `c`), by Ericson's Voronoi-region test (Real-Time Collision Detection, §5.1.5).
pub(crate) fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (DVec3, f64, f64) {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, 0.0, 0.0);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, 1.0, 0.0);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, v, 0.0);
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, 0.0, 1.0);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, 0.0, w);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, 1.0 - w, w);
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (a + ab * v + ac * w, v, w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_on_triangle_regions() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        // Inside the face: straight down.
        let (q, u, v) = closest_on_triangle(DVec3::new(0.25, 0.25, 2.0), a, b, c);
        assert!(
            (q - DVec3::new(0.25, 0.25, 0.0)).length() < 1e-12 && (u - 0.25).abs() < 1e-12 && (v - 0.25).abs() < 1e-12
        );
        // Beyond a corner, beyond an edge.
        assert_eq!(closest_on_triangle(DVec3::new(-1.0, -1.0, 0.0), a, b, c).0, a);
        assert_eq!(closest_on_triangle(DVec3::new(2.0, -0.5, 0.0), a, b, c).0, b);
        let (q, _, _) = closest_on_triangle(DVec3::new(1.0, 1.0, 0.0), a, b, c);
        assert!((q - DVec3::new(0.5, 0.5, 0.0)).length() < 1e-12);
    }
}
