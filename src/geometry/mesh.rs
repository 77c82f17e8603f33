//! Indexed triangle meshes, validated on construction.

use glam::{Affine3A, Vec3};

use crate::error::{Error, Result};

/// Largest magnitude of a finite vertex coordinate, 2^40 (about 1.1e12). The triangle tests'
/// products are of third degree in coordinates (Möller–Trumbore's `t·det` is `(e2 × e1) · (v0 − o)`),
/// so triangles of size 1e13 and up overflow float32 (`f32::MAX` ≈ 3.4e38) for any ray and are
/// never hit — by Embree's test too. Below this bound every product stays finite for ray origins
/// within the same bound and directions up to about 1e12 in length (RELIABILITY.md).
pub const MAX_COORDINATE: f32 = (1u64 << 40) as f32;

/// An indexed triangle mesh: one geometry of a scene.
///
/// Indices are checked against the vertex count when the mesh is made, and finite coordinates
/// against [`MAX_COORDINATE`]. Vertices may hold NaN or infinity, and triangles may be degenerate:
/// such triangles are kept (so primitive ids match the input) but the BVH builder leaves them out,
/// and they are never hit — the same answer Embree gives. So are triangles moved beyond
/// [`MAX_COORDINATE`] later ([`map_positions`](Self::map_positions)).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleMesh {
    /// The mesh's name (the OBJ object or group, or the caller's).
    pub name: String,
    positions: Vec<Vec3>,
    indices: Vec<[u32; 3]>,
}

/// Whether a vertex is accepted by [`TriangleMesh::new`]: each coordinate NaN, infinite, or finite
/// within [`MAX_COORDINATE`].
fn in_range(p: Vec3) -> bool {
    p.to_array().iter().all(|x| !x.is_finite() || x.abs() <= MAX_COORDINATE)
}

impl TriangleMesh {
    /// Makes a mesh, checking that every index refers to a vertex and that no finite coordinate
    /// exceeds [`MAX_COORDINATE`] in magnitude.
    pub fn new(name: impl Into<String>, positions: Vec<Vec3>, indices: Vec<[u32; 3]>) -> Result<Self> {
        if indices.len() >= u32::MAX as usize {
            return Err(Error::TooManyTriangles(indices.len()));
        }
        if let Some((vertex, p)) = positions.iter().enumerate().find(|(_, p)| !in_range(**p)) {
            let value = p.to_array().into_iter().filter(|x| x.is_finite()).fold(0.0f32, |a, x| a.max(x.abs()));
            return Err(Error::CoordinateOutOfRange { vertex, value, max: MAX_COORDINATE });
        }
        for (triangle, tri) in indices.iter().enumerate() {
            for &index in tri {
                if index as usize >= positions.len() {
                    return Err(Error::IndexOutOfRange { triangle, index, vertex_count: positions.len() });
                }
            }
        }
        Ok(Self { name: name.into(), positions, indices })
    }

    /// Makes a mesh from flat slices: `positions` as x, y, z triples and `indices` as triples.
    pub fn from_slices(name: impl Into<String>, positions: &[f32], indices: &[u32]) -> Result<Self> {
        if !positions.len().is_multiple_of(3) {
            return Err(Error::RaggedPositions { len: positions.len() });
        }
        if !indices.len().is_multiple_of(3) {
            return Err(Error::RaggedIndices { len: indices.len() });
        }
        let p = positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        let i = indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        Self::new(name, p, i)
    }

    /// The vertex positions.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// The triangles, as three vertex indices each.
    pub fn indices(&self) -> &[[u32; 3]] {
        &self.indices
    }

    /// The number of triangles (hittable or not).
    pub fn triangle_count(&self) -> usize {
        self.indices.len()
    }

    /// The three corners of triangle `i`.
    #[inline]
    pub fn triangle(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.indices[i];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }

    /// Whether triangle `i` can ever be hit: finite corners within [`MAX_COORDINATE`] and a
    /// non-zero geometric normal.
    pub fn is_hittable(&self, i: usize) -> bool {
        self.hittable_corners(i).is_some()
    }

    /// Triangle `i`'s corners if it [is hittable](Self::is_hittable): one fetch for the test and
    /// the corners (the builder makes every reference from this).
    #[inline(always)]
    pub(crate) fn hittable_corners(&self, i: usize) -> Option<[Vec3; 3]> {
        let [a, b, c] = self.triangle(i);
        let inside = |p: Vec3| p.is_finite() && p.abs().max_element() <= MAX_COORDINATE;
        (inside(a) && inside(b) && inside(c) && (b - a).cross(c - a) != Vec3::ZERO).then_some([a, b, c])
    }

    /// Applies `f` to every vertex (used to move or scale a mesh in tests and generated scenes).
    pub fn map_positions(&mut self, f: impl Fn(Vec3) -> Vec3) {
        for p in &mut self.positions {
            *p = f(*p);
        }
    }

    /// A copy with every vertex moved by `m` (an instance flattened into world space).
    pub fn transformed(&self, m: &Affine3A) -> TriangleMesh {
        let mut t = self.clone();
        t.map_positions(|p| m.transform_point3(p));
        t
    }

    /// Axis-aligned bounds of the finite vertices, or `None` if there are none.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut lo = Vec3::INFINITY;
        let mut hi = Vec3::NEG_INFINITY;
        for p in self.positions.iter().filter(|p| p.is_finite()) {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        (lo.x <= hi.x).then_some((lo, hi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_indices() {
        let e = TriangleMesh::from_slices("m", &[0.0; 9], &[0, 1, 3]).unwrap_err();
        assert!(matches!(e, Error::IndexOutOfRange { triangle: 0, index: 3, vertex_count: 3 }));
        assert!(matches!(
            TriangleMesh::from_slices("m", &[0.0; 8], &[0, 1, 2]),
            Err(Error::RaggedPositions { len: 8 })
        ));
        assert!(matches!(TriangleMesh::from_slices("m", &[0.0; 9], &[0, 1]), Err(Error::RaggedIndices { len: 2 })));
    }

    #[test]
    fn hittable() {
        let p = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 2.0, 0.0, 0.0, f32::NAN, 0.0, 0.0];
        let m = TriangleMesh::from_slices("m", &p, &[0, 1, 2, 0, 1, 3, 0, 1, 4]).unwrap();
        assert!(m.is_hittable(0));
        assert!(!m.is_hittable(1), "collinear");
        assert!(!m.is_hittable(2), "NaN vertex");
    }
}
