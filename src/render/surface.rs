//! What the renderer needs to know about a hit beyond the query's answer: the hit point, the
//! geometric and shading normals in world space, and the material. Built from the same meshes and
//! instances as the query backend, so any backend's [`Hit`] (strahl's or Embree's: the same ids
//! and barycentric convention) can be shaded.

use glam::{Affine3A, Mat3, Vec2, Vec3};

use crate::geometry::TriangleMesh;
use crate::instance::Instance;
use crate::ray::{Hit, INVALID_ID, Ray};

/// One mesh as the shader sees it.
#[derive(Clone, Debug)]
struct Geometry {
    positions: Vec<Vec3>,
    indices: Vec<[u32; 3]>,
    /// Per-vertex unit normals for smooth shading, or `None` for flat shading.
    normals: Option<Vec<Vec3>>,
    /// Texture coordinates of each triangle's corners.
    uvs: Option<Vec<[Vec2; 3]>>,
    material: u32,
    /// For an analytic sphere set (no triangles): its number of spheres.
    spheres: usize,
    /// For a solid (no triangles): the material of each primitive (by `prim_id`).
    solid: Option<Vec<u32>>,
}

#[derive(Clone, Copy, Debug)]
struct Placement {
    object: u32,
    material: Option<u32>,
    transform: Affine3A,
    /// Inverse transpose of the linear part, for shading normals.
    normal: Mat3,
}

/// Per-object meshes with their materials and normals, and per-instance placements.
#[derive(Clone, Debug, Default)]
pub struct Surfaces {
    objects: Vec<Vec<Geometry>>,
    placements: Vec<Placement>,
}

/// A hit resolved for shading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// World-space hit point, from the barycentric coordinates (not `o + t·d`).
    pub p: Vec3,
    /// Unit geometric normal (the triangle's winding).
    pub ng: Vec3,
    /// Unit shading normal on the same side as `ng`.
    pub ns: Vec3,
    /// Texture coordinates, where the mesh has them.
    pub uv: Option<Vec2>,
    /// Index of the surface's material.
    pub material: u32,
}

/// Area-weighted vertex normals: each triangle's unnormalized cross product summed into its
/// vertices, normalized (zero-area triangles add nothing; a vertex of only such triangles gets 0).
pub fn vertex_normals(mesh: &TriangleMesh) -> Vec<Vec3> {
    let p = mesh.positions();
    let mut n = vec![Vec3::ZERO; p.len()];
    for tri in mesh.indices() {
        let [a, b, c] = tri.map(|i| i as usize);
        let f = (p[b] - p[a]).cross(p[c] - p[a]);
        if f.is_finite() {
            n[a] += f;
            n[b] += f;
            n[c] += f;
        }
    }
    n.iter().map(|v| v.normalize_or_zero()).collect()
}

impl Surfaces {
    /// `objects[o][g]`: the meshes of each object with `(material index, smooth)` per mesh;
    /// `instances` place the objects (empty for a flat scene, whose hits carry no instance id),
    /// with an optional material overriding the meshes'.
    pub fn new(objects: &[Vec<(&TriangleMesh, u32, bool)>], instances: &[(Instance, Option<u32>)]) -> Self {
        let objects = objects
            .iter()
            .map(|meshes| {
                meshes
                    .iter()
                    .map(|&(m, material, smooth)| Geometry {
                        positions: m.positions().to_vec(),
                        indices: m.indices().to_vec(),
                        normals: smooth.then(|| vertex_normals(m)),
                        uvs: None,
                        material,
                        spheres: 0,
                        solid: None,
                    })
                    .collect()
            })
            .collect();
        let placements = instances
            .iter()
            .map(|&(inst, material)| Placement {
                object: inst.object as u32,
                material,
                transform: inst.transform,
                normal: Mat3::from(inst.transform.matrix3).inverse().transpose(),
            })
            .collect();
        Self { objects, placements }
    }

    /// Appends an analytic sphere set of `count` spheres with `material` as the next geometry of
    /// object `object` (after its meshes, as scenes number them); `false` if there is no such
    /// object.
    pub fn add_spheres(&mut self, object: usize, count: usize, material: u32) -> bool {
        let Some(o) = self.objects.get_mut(object) else { return false };
        o.push(Geometry {
            positions: Vec::new(),
            indices: Vec::new(),
            normals: None,
            uvs: None,
            material,
            spheres: count,
            solid: None,
        });
        true
    }

    /// Appends a solid whose primitives have `leaf_materials` (by `prim_id`) as the next
    /// geometry of object `object` (after its meshes and sphere sets, as scenes number them);
    /// `false` if there is no such object or the list is empty.
    pub fn add_solid(&mut self, object: usize, leaf_materials: Vec<u32>) -> bool {
        let Some(o) = self.objects.get_mut(object) else { return false };
        let Some(&material) = leaf_materials.first() else { return false };
        o.push(Geometry {
            positions: Vec::new(),
            indices: Vec::new(),
            normals: None,
            uvs: None,
            material,
            spheres: 0,
            solid: Some(leaf_materials),
        });
        true
    }

    /// Gives geometry `geom` of object `object` texture coordinates per triangle corner; `false`
    /// (and nothing set) if there is no such geometry or the count is not its triangle count.
    pub fn set_uvs(&mut self, object: usize, geom: usize, uvs: Vec<[Vec2; 3]>) -> bool {
        match self.objects.get_mut(object).and_then(|o| o.get_mut(geom)) {
            Some(g) if g.indices.len() == uvs.len() => {
                g.uvs = Some(uvs);
                true
            }
            _ => false,
        }
    }

    /// Geometry `geom` of object `object`: its material and, where it has them, its texture
    /// coordinates per triangle corner (for exporters; a hit's answer is [`resolve`](Self::resolve)).
    pub fn geometry_shading(&self, object: usize, geom: usize) -> Option<(u32, Option<&[[Vec2; 3]]>)> {
        let g = self.objects.get(object)?.get(geom)?;
        Some((g.material, g.uvs.as_deref()))
    }

    /// Materials referenced, for checking against the material table.
    pub fn max_material(&self) -> Option<u32> {
        let meshes = self.objects.iter().flatten().flat_map(|g| g.solid.iter().flatten().copied().chain([g.material]));
        meshes.chain(self.placements.iter().filter_map(|p| p.material)).max()
    }

    /// Resolves a hit of `ray`; `None` if the hit's ids name nothing here (a backend built from
    /// other meshes).
    #[inline(always)]
    pub fn resolve(&self, ray: &Ray, hit: &Hit) -> Option<SurfacePoint> {
        let (object, placement) = if hit.inst_id == INVALID_ID {
            (0, None)
        } else {
            let p = self.placements.get(hit.inst_id as usize)?;
            (p.object as usize, Some(p))
        };
        let g = self.objects.get(object)?.get(hit.geom_id as usize)?;
        if g.spheres > 0 || g.solid.is_some() {
            // A sphere or a solid: the point along the ray, the query's outward normal (already
            // in world space) for both normals, no texture coordinates.
            let leaf_material = match &g.solid {
                Some(m) => *m.get(hit.prim_id as usize)?,
                None if hit.prim_id as usize >= g.spheres => return None,
                None => g.material,
            };
            let mut ng = hit.ng.normalize_or_zero();
            if ng == Vec3::ZERO || !ng.is_finite() {
                ng = -ray.dir.normalize_or_zero();
            }
            let material = placement.and_then(|p| p.material).unwrap_or(leaf_material);
            return Some(SurfacePoint { p: ray.at(hit.t), ng, ns: ng, uv: None, material });
        }
        let tri = g.indices.get(hit.prim_id as usize)?;
        let [a, b, c] = tri.map(|i| i as usize);
        let w = 1.0 - hit.u - hit.v;
        let mut p = g.positions[a] * w + g.positions[b] * hit.u + g.positions[c] * hit.v;
        let mut ng = hit.ng.normalize_or_zero();
        if ng == Vec3::ZERO {
            ng = -ray.dir.normalize_or_zero();
        }
        let mut material = g.material;
        if let Some(pl) = placement {
            p = pl.transform.transform_point3(p);
            material = pl.material.unwrap_or(material);
        }
        // Flat shading: the geometric normal, already of unit length.
        let ns = match &g.normals {
            None => ng,
            Some(n) => {
                let mut ns = n[a] * w + n[b] * hit.u + n[c] * hit.v;
                if let Some(pl) = placement {
                    ns = pl.normal * ns;
                }
                ns = ns.normalize_or_zero();
                // Vertex normals follow the winding in object space; a mirroring transform flips
                // the winding's normal but not the inverse transpose's. Keep both on one side.
                if ns.dot(ng) < 0.0 {
                    ns = -ns;
                }
                if ns == Vec3::ZERO || !ns.is_finite() { ng } else { ns }
            }
        };
        if !p.is_finite() {
            p = ray.at(hit.t);
        }
        let uv = g.uvs.as_ref().map(|t| {
            let [a, b, c] = t[hit.prim_id as usize];
            a * w + b * hit.u + c * hit.v
        });
        Some(SurfacePoint { p, ng, ns, uv, material })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_vertex_normals_point_outwards() {
        let s = crate::procedural::uv_sphere(Vec3::ZERO, 2.0, 16, 32);
        for (p, n) in s.positions().iter().zip(vertex_normals(&s)) {
            assert!((n - p.normalize()).length() < 0.05, "{p} {n}");
        }
    }

    #[test]
    fn instanced_hit_resolves_in_world_space() {
        let m = TriangleMesh::new("t", vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]).unwrap();
        let t = Affine3A::from_translation(Vec3::new(0.0, 0.0, 5.0)) * Affine3A::from_scale(Vec3::new(2.0, 2.0, 1.0));
        let s = Surfaces::new(&[vec![(&m, 3, true)]], &[(Instance::new(0, t), Some(7)), (Instance::new(0, t), None)]);
        let hit = Hit { t: 1.0, u: 0.25, v: 0.25, ng: Vec3::Z * 4.0, prim_id: 0, geom_id: 0, inst_id: 0 };
        let ray = Ray::new(Vec3::new(0.5, 0.5, 6.0), Vec3::NEG_Z);
        let sp = s.resolve(&ray, &hit).unwrap();
        assert!((sp.p - Vec3::new(0.5, 0.5, 5.0)).length() < 1e-6);
        assert_eq!((sp.ng, sp.ns, sp.material), (Vec3::Z, Vec3::Z, 7));
        assert_eq!(s.resolve(&ray, &Hit { inst_id: 1, ..hit }).unwrap().material, 3);
        assert!(s.resolve(&ray, &Hit { inst_id: 2, ..hit }).is_none());
        assert!(s.resolve(&ray, &Hit { prim_id: 1, ..hit }).is_none());
        assert_eq!(s.max_material(), Some(7));
    }
}
