//! Analytic shapes (issue 30): primitives other than triangles, traced through the same wide
//! BVH, node tests and walks as the meshes, with their own leaf blocks and tests:
//! - spheres ([`SphereSet`], `sphere.rs` for the tests, `tree.rs` for their BVH), tested four at
//!   a time with SIMD in float32;
//! - solids ([`Solid`]): [`Primitive`]s (box, cylinder, cone, disc, plane, torus, general
//!   quadric, and the sphere as an ellipsoid) placed by affine transforms and combined by CSG
//!   (`primitive.rs`, `csg.rs`, `solve.rs` for the root finders, `solid_tree.rs` for their BVH),
//!   one ray at a time in float64.
//!
//! A [`Scene`](crate::Scene) holding meshes and spheres keeps one BVH per primitive type and
//! answers each query from both, the second walk bounded by the first's hit — as Embree keeps one
//! acceleration structure per geometry type in a scene (`AccelN`).

mod blob;
mod csg;
mod implicit;
mod interval;
mod mesh_solid;
mod primitive;
pub(crate) mod solid_tree;
mod solve;
pub(crate) mod sphere;
mod superquadric;
pub(crate) mod tree;

use glam::Vec3;

use crate::error::{Error, Result};
use crate::geometry::MAX_COORDINATE;
pub use blob::{Blob, BlobComponent, MAX_BLOB_COMPONENTS, Potential};
pub use csg::{CSG_TOLERANCE, CsgOp, MAX_LEAVES, MAX_SOLID_DEPTH, PreparedSolid, Solid};
pub use implicit::{Implicit, MAX_TRACE_STEPS};
pub use mesh_solid::MeshSolid;
pub use primitive::Primitive;
pub use solve::{QuarticSolver, quadratic, quartic};
pub use sphere::SphereTest;
pub use sphere::roots_f64 as sphere_roots_f64;

/// A named set of spheres (one geometry, like a mesh): centres and radii. Hits on sphere `i` of
/// set `s` report `prim_id = i` and `geom_id = meshes + s`, `u = v = 0`, and the unnormalized
/// outward normal `p − centre` (as Embree's `RTC_GEOMETRY_TYPE_SPHERE_POINT` does).
#[derive(Clone, Debug, PartialEq)]
pub struct SphereSet {
    name: String,
    centers: Vec<Vec3>,
    radii: Vec<f32>,
}

impl SphereSet {
    /// A set from centres and radii. Errors ([`Error::BadSphere`]) for lists of different
    /// lengths, centres that are not finite or lie beyond [`MAX_COORDINATE`], and radii that are
    /// not positive finite numbers at most [`MAX_COORDINATE`].
    pub fn new(name: impl Into<String>, centers: Vec<Vec3>, radii: Vec<f32>) -> Result<Self> {
        let name = name.into();
        let bad = |index: usize, message: String| Err(Error::BadSphere { set: name.clone(), index, message });
        if centers.len() != radii.len() {
            return bad(centers.len().min(radii.len()), format!("{} centres but {} radii", centers.len(), radii.len()));
        }
        for (i, (c, &r)) in centers.iter().zip(&radii).enumerate() {
            if !c.is_finite() || c.abs().max_element() > MAX_COORDINATE {
                return bad(i, format!("centre {c} is not finite or beyond {MAX_COORDINATE:e}"));
            }
            if !(r > 0.0 && r <= MAX_COORDINATE) {
                return bad(i, format!("radius {r} is not a positive finite number at most {MAX_COORDINATE:e}"));
            }
        }
        Ok(Self { name, centers, radii })
    }

    /// A set from `(centre, radius)` pairs (see [`new`](Self::new)).
    pub fn from_pairs(name: impl Into<String>, spheres: &[(Vec3, f32)]) -> Result<Self> {
        Self::new(name, spheres.iter().map(|s| s.0).collect(), spheres.iter().map(|s| s.1).collect())
    }

    /// The set's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Number of spheres.
    pub fn len(&self) -> usize {
        self.centers.len()
    }

    /// Whether the set holds no sphere.
    pub fn is_empty(&self) -> bool {
        self.centers.is_empty()
    }

    /// The centres.
    pub fn centers(&self) -> &[Vec3] {
        &self.centers
    }

    /// The radii.
    pub fn radii(&self) -> &[f32] {
        &self.radii
    }

    /// Sphere `i` as `(centre, radius)`.
    pub fn sphere(&self, i: usize) -> (Vec3, f32) {
        (self.centers[i], self.radii[i])
    }

    /// Bytes of the set's own storage (four floats a sphere).
    pub fn bytes(&self) -> usize {
        self.len() * 16
    }
}
