//! Wavefront OBJ loading through `tobj`: polygons fan-triangulated, one geometry per OBJ object or
//! group, materials ignored.

use std::path::Path;

use glam::Vec3;

use super::mesh::TriangleMesh;
use crate::error::{Error, Result};

/// Loads every object/group of an OBJ file with at least one face as its own mesh, in file order.
///
/// A missing file, a malformed record or an out-of-range index is an [`Error`]; a file with no
/// faces gives an empty list (an empty scene, which every ray misses).
pub fn load_obj(path: impl AsRef<Path>) -> Result<Vec<TriangleMesh>> {
    let path = path.as_ref();
    let opts = tobj::LoadOptions { triangulate: true, single_index: false, ignore_points: true, ignore_lines: true };
    // Material libraries are not needed for ray queries; a missing .mtl is not an error.
    let (models, _materials) =
        tobj::load_obj(path, &opts).map_err(|source| Error::Obj { path: path.to_owned(), source })?;
    let mut meshes = Vec::with_capacity(models.len());
    for model in models {
        let m = model.mesh;
        if m.indices.is_empty() {
            continue;
        }
        if !m.positions.len().is_multiple_of(3) {
            return Err(Error::RaggedPositions { len: m.positions.len() });
        }
        let positions: Vec<Vec3> = m.positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        if !m.indices.len().is_multiple_of(3) {
            return Err(Error::RaggedIndices { len: m.indices.len() });
        }
        let indices = m.indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        meshes.push(TriangleMesh::new(model.name, positions, indices)?);
    }
    Ok(meshes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_tmp(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("strahl-obj-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn quads_are_fan_triangulated_per_group() {
        let p = write_tmp("quads.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\ng a\nf 1 2 3 4\ng b\nf 1 2 5\n");
        let meshes = load_obj(&p).unwrap();
        assert_eq!(meshes.len(), 2);
        assert_eq!(meshes[0].triangle_count(), 2);
        assert_eq!(meshes[1].triangle_count(), 1);
    }

    #[test]
    fn missing_file_is_an_error() {
        let e = load_obj("/nonexistent/strahl/none.obj").unwrap_err();
        assert!(matches!(e, Error::Obj { .. }), "{e}");
        assert!(e.to_string().contains("none.obj"));
    }

    #[test]
    fn malformed_and_out_of_range_are_errors() {
        let p = write_tmp("bad.obj", "v 0 0 zero\nf 1 2 3\n");
        assert!(load_obj(&p).is_err());
        let p = write_tmp("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
        assert!(load_obj(&p).is_err());
    }

    #[test]
    fn no_faces_is_empty() {
        let p = write_tmp("empty.obj", "# nothing\nv 0 0 0\n");
        assert!(load_obj(&p).unwrap().is_empty());
    }
}
