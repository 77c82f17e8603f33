//! Geometry: triangle meshes (storage and loading) apart from the SIMD triangle tests that run on
//! the BVH's leaf blocks.

pub mod mesh;
pub mod obj;
pub(crate) mod triangle;

pub use mesh::TriangleMesh;
pub use obj::load_obj;
