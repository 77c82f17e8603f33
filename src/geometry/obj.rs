//! Wavefront OBJ loading through `tobj`: polygons fan-triangulated, one geometry per OBJ object or
//! group; materials ignored by [`load_obj`], read (with texture coordinates) by
//! [`load_obj_with_materials`] for the renderer.

use std::io::Read;
use std::path::Path;

use glam::Vec3;

use super::mesh::TriangleMesh;
use crate::error::{Error, Result};

/// Largest OBJ file read, in bytes (4 GiB; the largest shared scene is 40 MB).
pub const MAX_OBJ_BYTES: u64 = 4 << 30;

/// Largest magnitude of an index in an `f` record: larger ones name no vertex of any file this
/// loader reads, and tobj's arithmetic on them overflows (a panic in debug builds).
const MAX_OBJ_INDEX: i64 = 1 << 32;

/// Loads every object/group of an OBJ file with at least one face as its own mesh, in file order.
///
/// Only regular files up to [`MAX_OBJ_BYTES`] are read (a FIFO or a device is an error, not a
/// hang); material libraries (`mtllib`) are never opened. A missing or unreadable file is an
/// [`Error::Io`] with the OS's cause; a malformed `v` or `f` record (too few numbers, a face of
/// one or two vertices, a file cut off mid-face, an absurd index) an [`Error::ObjRecord`] naming
/// the line; an out-of-range index an [`Error::IndexOutOfRange`]. A file with no faces gives an
/// empty list (an empty scene, which every ray misses).
pub fn load_obj(path: impl AsRef<Path>) -> Result<Vec<TriangleMesh>> {
    let path = path.as_ref();
    parse_obj(&read_regular(path, MAX_OBJ_BYTES)?, path)
}

/// [`load_obj`] on the bytes of an OBJ file already in memory; `path` names it in errors.
pub fn parse_obj(bytes: &[u8], path: &Path) -> Result<Vec<TriangleMesh>> {
    check_records(path, bytes)?;
    let opts = tobj::LoadOptions { triangulate: true, single_index: false, ignore_points: true, ignore_lines: true };
    // Material libraries are not needed for ray queries: the loader refuses them unread.
    let (models, _materials) = tobj::load_obj_buf(&mut &bytes[..], &opts, |_| Err(tobj::LoadError::OpenFileFailed))
        .map_err(|cause| Error::Obj { path: path.to_owned(), cause })?;
    Ok(meshes_of(models)?.into_iter().map(|(m, _)| m).collect())
}

/// An OBJ file loaded with its material library (see [`load_obj_with_materials`]).
#[derive(Clone, Debug)]
pub struct ObjWithMaterials {
    /// One mesh per object/group and material, in file order.
    pub meshes: Vec<TriangleMesh>,
    /// Per mesh: its material (an index into `materials`), if it has one.
    pub mesh_material: Vec<Option<usize>>,
    /// Per mesh: the texture coordinates of each triangle's three corners, if its faces give them.
    pub corner_uvs: Vec<Option<Vec<[[f32; 2]; 3]>>>,
    /// The materials of every `mtllib` the file names.
    pub materials: Vec<tobj::Material>,
}

/// Largest material library read, in bytes.
pub const MAX_MTL_BYTES: u64 = 64 << 20;

/// Like [`load_obj`], but the material libraries (`mtllib`, relative to the OBJ file's folder,
/// regular files up to [`MAX_MTL_BYTES`]) are read, each object/group is split where its
/// material changes (as tobj does), and texture coordinates are kept. A missing or unreadable
/// library is an [`Error::Io`] naming it; a malformed one an [`Error::Obj`].
pub fn load_obj_with_materials(path: impl AsRef<Path>) -> Result<ObjWithMaterials> {
    let path = path.as_ref();
    let bytes = read_regular(path, MAX_OBJ_BYTES)?;
    check_records(path, &bytes)?;
    let opts = tobj::LoadOptions { triangulate: true, single_index: false, ignore_points: true, ignore_lines: true };
    let base = path.parent().unwrap_or(Path::new("."));
    let failed = std::cell::RefCell::new(None);
    let loaded = tobj::load_obj_buf(&mut &bytes[..], &opts, |mtl| {
        let p = base.join(mtl);
        match read_regular(&p, MAX_MTL_BYTES) {
            Ok(b) => tobj::load_mtl_buf(&mut &b[..]),
            Err(e) => {
                *failed.borrow_mut() = Some(e);
                Err(tobj::LoadError::OpenFileFailed)
            }
        }
    });
    if let Some(e) = failed.into_inner() {
        return Err(e);
    }
    let (models, materials) = loaded.map_err(|cause| Error::Obj { path: path.to_owned(), cause })?;
    let materials = materials.map_err(|cause| Error::Obj { path: path.to_owned(), cause })?;
    let mut out = ObjWithMaterials { meshes: Vec::new(), mesh_material: Vec::new(), corner_uvs: Vec::new(), materials };
    for (mesh, raw) in meshes_of(models)? {
        let uvs = (raw.texcoord_indices.len() == raw.indices.len() && !raw.texcoords.is_empty()).then(|| {
            let uv = |i: u32| {
                let i = i as usize * 2;
                raw.texcoords.get(i..i + 2).map_or([0.0, 0.0], |t| [t[0], t[1]])
            };
            raw.texcoord_indices.chunks_exact(3).map(|c| [uv(c[0]), uv(c[1]), uv(c[2])]).collect()
        });
        let material = raw.material_id.filter(|&m| m < out.materials.len());
        out.meshes.push(mesh);
        out.mesh_material.push(material);
        out.corner_uvs.push(uvs);
    }
    Ok(out)
}

/// The meshes of tobj's models with faces, each with tobj's mesh (for its other attributes).
fn meshes_of(models: Vec<tobj::Model>) -> Result<Vec<(TriangleMesh, tobj::Mesh)>> {
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
        meshes.push((TriangleMesh::new(model.name, positions, indices)?, m));
    }
    Ok(meshes)
}

/// The whole of `path` if it is a regular file of at most `cap` bytes.
pub(crate) fn read_regular(path: &Path, cap: u64) -> Result<Vec<u8>> {
    let io = |cause: std::io::Error| Error::Io { path: path.to_owned(), cause };
    let file = std::fs::File::open(path).map_err(io)?;
    let meta = file.metadata().map_err(io)?;
    if !meta.is_file() {
        return Err(io(std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a regular file")));
    }
    if meta.len() > cap {
        let msg = format!("{} bytes, more than the {cap} read", meta.len());
        return Err(io(std::io::Error::new(std::io::ErrorKind::InvalidData, msg)));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    // `take`: a file that grows while it is read still stops at the cap.
    file.take(cap + 1).read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > cap {
        return Err(io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("more than the {cap} bytes read"),
        )));
    }
    Ok(bytes)
}

/// Checks the `v` and `f` records line by line, so that their errors name the line (tobj's do
/// not) and faces tobj would drop silently are errors.
fn check_records(path: &Path, bytes: &[u8]) -> Result<()> {
    let bad = |line: usize, message: String| Error::ObjRecord { path: path.to_owned(), line, message };
    for (k, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let line = k + 1;
        let text = String::from_utf8_lossy(raw);
        let mut words = text.split_whitespace();
        match words.next() {
            Some("v") => {
                let n = words.take(3).filter(|w| w.parse::<f32>().is_ok()).count();
                if n < 3 {
                    return Err(bad(line, format!("a vertex needs three numbers: \"{}\"", text.trim())));
                }
            }
            Some("f") => {
                let refs: Vec<&str> = words.collect();
                if refs.len() < 3 {
                    return Err(bad(line, format!("a face needs three vertices, this has {}", refs.len())));
                }
                for r in refs {
                    for (j, part) in r.split('/').enumerate() {
                        if part.is_empty() && j > 0 {
                            continue;
                        }
                        match part.parse::<i64>() {
                            Ok(i) if i != 0 && i.abs() <= MAX_OBJ_INDEX => {}
                            _ => return Err(bad(line, format!("\"{r}\" is no vertex reference"))),
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
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
        assert!(matches!(e, Error::Io { .. }), "{e}");
        assert!(e.to_string().contains("none.obj") && e.to_string().contains("No such file"), "{e}");
    }

    #[test]
    fn devices_fifos_and_folders_are_not_read() {
        for p in ["/dev/zero", "/dev/null", "/tmp"] {
            let e = load_obj(p).unwrap_err();
            assert!(e.to_string().contains("not a regular file"), "{p}: {e}");
        }
        // A material library naming a device is never opened.
        let p = write_tmp("mtl.obj", "mtllib /dev/zero\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
        assert_eq!(load_obj(&p).unwrap()[0].triangle_count(), 1);
    }

    #[test]
    fn short_faces_and_absurd_indices_name_the_line() {
        for (text, line) in [
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", 4),
            ("v 0 0 0\nv 1 0 0\n\nv 0 1 0\nf 1 2 3\nf 1", 6),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2//1 3//7000000000000000000\n", 4),
            ("v 0 0 0\nv 1 0\n", 2),
        ] {
            let p = write_tmp("short.obj", text);
            match load_obj(&p) {
                Err(Error::ObjRecord { line: l, .. }) => assert_eq!(l, line, "{text:?}"),
                other => panic!("{text:?}: {other:?}"),
            }
        }
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
