//! Typed errors of the library. Queries never fail: bad rays get a defined answer (a miss).

use std::path::PathBuf;

/// What can go wrong when loading meshes or building a scene.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An OBJ file could not be read or parsed by tobj.
    ///
    /// The cause is part of the message (and not also a `source()`, which would print it twice
    /// in an error chain).
    #[error("cannot read OBJ file {path}: {cause}")]
    Obj {
        /// The file.
        path: PathBuf,
        /// tobj's error.
        cause: tobj::LoadError,
    },
    /// A record of an OBJ file is malformed or out of range.
    #[error("{path}, line {line}: {message}")]
    ObjRecord {
        /// The file.
        path: PathBuf,
        /// The line, counted from 1.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// A file could not be read.
    #[error("cannot read {path}: {cause}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        cause: std::io::Error,
    },
    /// A position buffer's length is not a multiple of 3.
    #[error("position buffer of length {len} is not a whole number of xyz triples")]
    RaggedPositions {
        /// The buffer's length.
        len: usize,
    },
    /// An index buffer's length is not a multiple of 3.
    #[error("index buffer of length {len} is not a whole number of triangles")]
    RaggedIndices {
        /// The buffer's length.
        len: usize,
    },
    /// A triangle names a vertex the mesh does not have.
    #[error("triangle {triangle} refers to vertex {index}, but the mesh has {vertex_count} vertices")]
    IndexOutOfRange {
        /// The triangle's index.
        triangle: usize,
        /// The vertex index it holds.
        index: u32,
        /// The mesh's vertex count.
        vertex_count: usize,
    },
    /// A vertex coordinate is beyond [`MAX_COORDINATE`](crate::MAX_COORDINATE) (or NaN).
    #[error("vertex {vertex} has a coordinate of magnitude {value:e}; at most {max:e} (2^40) is supported")]
    CoordinateOutOfRange {
        /// The vertex's index.
        vertex: usize,
        /// The offending coordinate.
        value: f32,
        /// The largest magnitude supported.
        max: f32,
    },
    /// A mesh has more triangles than 32-bit ids can name.
    #[error("mesh has {0} triangles; at most 2^32 - 1 are supported")]
    TooManyTriangles(usize),
    /// A scene file is malformed or names something that does not exist.
    #[error("scene file {path}: {message}")]
    SceneFile {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the entry and value.
        message: String,
    },
    /// An instance places an object that does not exist.
    #[error("instance {instance} places object {object}, but there are only {objects} objects")]
    UnknownObject {
        /// The instance's index.
        instance: usize,
        /// The object it names.
        object: usize,
        /// How many objects there are.
        objects: usize,
    },
    /// A scene has more instances than instance ids can name.
    #[error("scene has {0} instances; at most 2^27 - 1 are supported")]
    TooManyInstances(usize),
    /// The objects of an instanced scene were built with different tests.
    #[error("the objects of an instanced scene must share one triangle test and one box test")]
    MixedTests,
    /// An instance's transform is not finite and invertible.
    #[error("instance {instance} has a transform that is not finite and invertible")]
    BadTransform {
        /// The instance's index.
        instance: usize,
    },
    /// Impossible render settings (sizes, sample or depth counts, colours, indices of refraction).
    #[error("render settings: {0}")]
    RenderSettings(String),
    /// A texture could not be read or decoded.
    #[error("cannot read texture {path}: {message}")]
    Texture {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// An image could not be written.
    #[error("cannot write image {path}: {message}")]
    ImageWrite {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// [`set_isa`](crate::simd::set_isa) asked for an instruction-set level this processor
    /// cannot run.
    #[error("this processor cannot run strahl's {0} kernels")]
    UnsupportedIsa(&'static str),
    /// A scene has more geometries than geometry ids can name.
    #[error("scene has {0} geometries; at most 2^32 - 1 are supported (2^29 with the Badouel test)")]
    TooManyGeometries(usize),
    /// A sphere with a non-finite or out-of-range centre, or a radius that is not a positive
    /// finite number, or a sphere set whose centre and radius lists differ in length.
    #[error("sphere set {set:?}, sphere {index}: {message}")]
    BadSphere {
        /// The set's name.
        set: String,
        /// The sphere's index in the set.
        index: usize,
        /// What is wrong, with the value.
        message: String,
    },
    /// An instance places an object holding spheres by a transform that is not a similarity
    /// (rotation or mirror, uniform scale, translation): its spheres would become ellipsoids.
    #[error("instance {instance} places spheres by a transform that is not a rotation, uniform scale and translation")]
    SphereInstanceNotSimilar {
        /// The instance's index.
        instance: usize,
    },
    /// A solid that cannot be built: bad primitive parameters (radii, NaN coefficients), a
    /// transform that is not finite and invertible, an empty CSG operation, a disc as a CSG
    /// operand, or a solid without bounds (a plane or quadric not intersected with a bounded
    /// solid).
    #[error("solid {index}: {message}")]
    BadSolid {
        /// The solid's index in the list given to the scene.
        index: usize,
        /// What is wrong.
        message: String,
    },
    /// Bytes given to `Scene::from_bytes` or `InstancedScene::from_bytes` are not a scene this
    /// version wrote, or were damaged.
    #[error("serialized scene: {0}")]
    Serialized(String),
}

/// The library's result type.
pub type Result<T> = std::result::Result<T, Error>;
