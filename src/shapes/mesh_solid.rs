//! Closed triangle meshes as solids, so CSG can cut them and cut with them (issue 30: "CSG over
//! closed triangle meshes, inside/outside from the watertight test's hit parity").
//!
//! The mesh gets its own scene, built with the watertight triangle test and conservative boxes
//! ([`BuildConfig::watertight`]), so no line slips between its triangles. A line's crossings are
//! its hits there with the hits of one crossing merged ([`crate::query::merge_crossings`]: a
//! line through a shared edge or vertex hits every triangle there); entering from outside the
//! bounds, the pieces between crossings alternate outside and inside.

use std::collections::HashMap;
use std::fmt;

use glam::{DVec3, Vec3};

use crate::bvh::BuildConfig;
use crate::error::{Error, Result};
use crate::geometry::TriangleMesh;
use crate::query::{SpatialQuery, merge_crossings};
use crate::ray::Ray;
use crate::scene::Scene;

/// A closed, consistently oriented triangle mesh as a solid: a [`Primitive`](super::Primitive)
/// (`Primitive::Mesh`) that CSG combines with the analytic shapes and other meshes, placed by
/// an affine map like any of them.
#[derive(Clone)]
pub struct MeshSolid {
    mesh: TriangleMesh,
    scene: Scene,
    /// The mesh winds clockwise seen from outside: its geometric normals point inwards.
    inward: bool,
    /// The bounds of the mesh (computed once: a mesh's own `bounds` walks every vertex).
    bounds: (DVec3, DVec3),
}

impl MeshSolid {
    /// A solid bounded by `mesh`. Errors ([`Error::BadSolid`], index 0) unless the mesh is
    /// closed: after vertices at the same position are welded and triangles with a repeated
    /// corner dropped, every edge must bound exactly two triangles that run along it in opposite
    /// directions (a consistently oriented 2-manifold; either orientation). A mesh with no
    /// hittable triangle is refused too.
    pub fn new(mesh: TriangleMesh) -> Result<MeshSolid> {
        let bad = |message: String| Error::BadSolid { index: 0, message: format!("mesh \"{}\": {message}", mesh.name) };
        // Weld by position (OBJ files repeat vertices along texture seams).
        let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
        let canon: Vec<u32> = mesh
            .positions()
            .iter()
            .map(|p| {
                let next = ids.len() as u32;
                *ids.entry(p.to_array().map(|x| (x + 0.0).to_bits())).or_insert(next)
            })
            .collect();
        // Directed edges: each must appear once, with its reverse once.
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        let mut used = 0usize;
        for (i, tri) in mesh.indices().iter().enumerate() {
            let [a, b, c] = tri.map(|v| canon[v as usize]);
            if a == b || b == c || a == c || !mesh.is_hittable(i) {
                continue;
            }
            used += 1;
            for e in [(a, b), (b, c), (c, a)] {
                *edges.entry(e).or_insert(0) += 1;
            }
        }
        if used == 0 {
            return Err(bad("no hittable triangle".into()));
        }
        for (&(a, b), &n) in &edges {
            let back = edges.get(&(b, a)).copied().unwrap_or(0);
            if n != 1 || back != 1 {
                return Err(bad(format!(
                    "not closed: the edge between welded vertices {a} and {b} runs {n}× one way and {back}× the \
                     other (a closed, consistently oriented mesh has each edge once each way)"
                )));
            }
        }
        let scene = Scene::build(vec![mesh.clone()], &BuildConfig::watertight())?;
        // The signed volume (divergence theorem) says which way the triangles wind.
        let volume: f64 = (0..mesh.triangle_count())
            .map(|i| {
                let [a, b, c] = mesh.triangle(i).map(|p| p.as_dvec3());
                a.dot(b.cross(c))
            })
            .sum();
        let (lo, hi) = mesh.bounds().unwrap_or((Vec3::ZERO, Vec3::ZERO));
        Ok(MeshSolid { mesh, scene, inward: volume < 0.0, bounds: (lo.as_dvec3(), hi.as_dvec3()) })
    }

    /// The mesh.
    pub fn mesh(&self) -> &TriangleMesh {
        &self.mesh
    }

    pub(crate) fn bounds(&self) -> (DVec3, DVec3) {
        self.bounds
    }

    /// The crossings of the line `p + s u` (`u` unit, `p` outside the bounds) for
    /// `s ∈ [0, length]`, ascending, into `out` (cleared first), in float32 as the mesh is.
    pub(crate) fn crossings(&self, p: DVec3, u: DVec3, length: f64, out: &mut Vec<f64>) {
        out.clear();
        // Start a little farther out: the float32 origin must not round into the bounds.
        let (lo, hi) = self.bounds();
        let margin = 1e-3 * (hi - lo).length().max(1e-30);
        let ray = Ray::segment((p - margin * u).as_vec3(), u.as_vec3(), 0.0, (length + 2.0 * margin) as f32);
        HITS.with(|hits| {
            let mut hits = hits.borrow_mut();
            self.scene.all_hits(&ray, &mut hits);
            merge_crossings(&ray, &mut hits);
            out.extend(hits.iter().map(|h| h.t as f64 - margin));
        });
    }

    /// The outward normal (not normalized) of the triangle nearest to `p`.
    pub(crate) fn normal(&self, p: DVec3) -> DVec3 {
        let n = self.scene.closest_point(p.as_vec3(), f32::INFINITY).map_or(Vec3::Z, |c| c.ng).as_dvec3();
        if self.inward { -n } else { n }
    }

    /// The signed distance to the mesh, negative inside (by crossing parity, by a vote of
    /// three rays).
    pub(crate) fn field(&self, p: DVec3) -> f64 {
        let d = self.scene.signed_distance(p.as_vec3()) as f64;
        if d.is_nan() { f64::INFINITY } else { d }
    }
}

thread_local! {
    static HITS: std::cell::RefCell<Vec<crate::Hit>> = const { std::cell::RefCell::new(Vec::new()) };
}

impl fmt::Debug for MeshSolid {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("MeshSolid")
            .field("name", &self.mesh.name)
            .field("triangles", &self.mesh.triangle_count())
            .field("inward", &self.inward)
            .finish_non_exhaustive()
    }
}

/// Meshes are equal when their vertices and triangles are.
impl PartialEq for MeshSolid {
    fn eq(&self, o: &Self) -> bool {
        self.mesh == o.mesh
    }
}
