//! Typed errors of the library. Queries never fail: bad rays get a defined answer (a miss).

use std::path::PathBuf;

/// What can go wrong when loading meshes or building a scene.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The cause is part of the message (and not also a `source()`, which would print it twice
    /// in an error chain).
    #[error("cannot read OBJ file {path}: {cause}")]
    Obj { path: PathBuf, cause: tobj::LoadError },
    #[error("{path}, line {line}: {message}")]
    ObjRecord { path: PathBuf, line: usize, message: String },
    #[error("cannot read {path}: {cause}")]
    Io { path: PathBuf, cause: std::io::Error },
    #[error("position buffer of length {len} is not a whole number of xyz triples")]
    RaggedPositions { len: usize },
    #[error("index buffer of length {len} is not a whole number of triangles")]
    RaggedIndices { len: usize },
    #[error("triangle {triangle} refers to vertex {index}, but the mesh has {vertex_count} vertices")]
    IndexOutOfRange { triangle: usize, index: u32, vertex_count: usize },
    #[error("vertex {vertex} has a coordinate of magnitude {value:e}; at most {max:e} (2^40) is supported")]
    CoordinateOutOfRange { vertex: usize, value: f32, max: f32 },
    #[error("mesh has {0} triangles; at most 2^32 - 1 are supported")]
    TooManyTriangles(usize),
    #[error("scene file {path}: {message}")]
    SceneFile { path: PathBuf, message: String },
    #[error("instance {instance} places object {object}, but there are only {objects} objects")]
    UnknownObject { instance: usize, object: usize, objects: usize },
    #[error("scene has {0} instances; at most 2^27 - 1 are supported")]
    TooManyInstances(usize),
    #[error("the objects of an instanced scene must share one triangle test and one box test")]
    MixedTests,
    #[error("instance {instance} has a transform that is not finite and invertible")]
    BadTransform { instance: usize },
    #[error("render settings: {0}")]
    RenderSettings(String),
    #[error("cannot read texture {path}: {message}")]
    Texture { path: PathBuf, message: String },
    #[error("cannot write image {path}: {message}")]
    ImageWrite { path: PathBuf, message: String },
    #[error("scene has {0} geometries; at most 2^32 - 1 are supported (2^29 with the Badouel test)")]
    TooManyGeometries(usize),
    #[error("serialized scene: {0}")]
    Serialized(String),
}

pub type Result<T> = std::result::Result<T, Error>;
