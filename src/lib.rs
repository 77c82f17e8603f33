//! # strahl
//!
//! A data-oriented packet/SIMD CPU ray tracer. Triangle meshes are built into a wide BVH
//! (binned SAH, 8 children per node, SoA child bounds, leaves of 4-triangle SoA blocks) and
//! queried by single rays, 16-ray packets and streams, for the closest hit or any hit.
//!
//! ```
//! use strahl::{BuildConfig, Query, Ray, Scene, TriangleMesh};
//! use glam::Vec3;
//!
//! // One triangle in the plane z = 0.
//! let mesh = TriangleMesh::from_slices("tri", &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], &[0, 1, 2])?;
//! let scene = Scene::build(vec![mesh], &BuildConfig::default())?;
//!
//! let ray = Ray::new(Vec3::new(0.25, 0.25, 1.0), Vec3::new(0.0, 0.0, -1.0));
//! let hit = scene.intersect(&ray).expect("the ray points at the triangle");
//! assert_eq!((hit.geom_id, hit.prim_id), (0, 0));
//! assert!((hit.t - 1.0).abs() < 1e-6);
//! assert!(scene.occluded(&ray));
//!
//! // Bad rays get a defined answer, not a panic.
//! assert!(scene.intersect(&Ray::new(Vec3::ZERO, Vec3::ZERO)).is_none());
//! # Ok::<(), strahl::Error>(())
//! ```
//!
//! See `ARCHITECTURE.md` for the data flow and where each part lives.
#![deny(unsafe_code)]
#![warn(missing_docs)]
// SoA kernels index several parallel arrays by one lane or axis index; iterators would obscure that.
#![allow(clippy::needless_range_loop)]

pub mod bvh;
pub mod camera;
pub mod error;
pub mod geometry;
pub mod instance;
mod persist;
pub mod procedural;
pub mod query;
pub mod ray;
pub mod raygen;
pub mod render;
pub mod scene;
pub mod scene_file;
pub mod shapes;
pub mod simd;
mod sys;

pub use bvh::group::GROUP;
pub use bvh::{BoxTest, BuildConfig, BuildStats};
pub use camera::Camera;
pub use error::{Error, Result};
pub use geometry::{MAX_COORDINATE, TriangleMesh, TriangleTest, exact_hit, intersect_triangle, load_obj, parse_obj};
pub use instance::{Instance, InstancedScene, InstancedStats};
pub use query::{ClosestPoint, SpatialQuery};
pub use ray::{
    Hit, HitPacket, HitSlice, HitStream, INVALID_ID, PACKET_WIDTH, Ray, RayPacket, RayStream, offset_ray_origin,
};
pub use render::Light;
pub use scene::{Coherence, Query, STREAM_CHUNK, Scene};
pub use scene_file::SceneFile;
pub use shapes::{
    Blob, BlobComponent, CsgOp, Implicit, MeshSolid, Potential, Primitive, QuarticSolver, Solid, SphereSet, SphereTest,
};
pub use simd::{Isa, isa, set_isa};

/// The README's code examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
