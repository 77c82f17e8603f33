//! Geometry: triangle meshes (storage and loading) apart from the SIMD triangle tests that run on
//! the BVH's leaf blocks.

pub(crate) mod badouel;
pub mod mesh;
pub(crate) mod moeller;
pub mod obj;
pub mod triangle;
pub(crate) mod watertight;

pub use mesh::{MAX_COORDINATE, TriangleMesh};
pub use obj::{ObjWithMaterials, load_obj, load_obj_with_materials, parse_obj};
pub use triangle::{TriangleTest, exact_hit, intersect_triangle};
