//! Scene description files: meshes (OBJ files or generated shapes), instances with transforms, a
//! camera and lights, in TOML. The format is documented in `data/README.md`; in short:
//!
//! ```toml
//! [camera]
//! eye = [0.0, 3.0, -10.0]
//! look_at = [0.0, 0.0, 0.0]
//! up = [0.0, 1.0, 0.0]        # optional, +y by default
//! fov = 60.0                  # degrees, optional
//!
//! [[light]]
//! position = [10.0, 20.0, -10.0]
//! color = [1.0, 1.0, 1.0]     # optional
//!
//! [mesh.flake]
//! sphereflake = { levels = 2, stacks = 8, slices = 16 }
//! [mesh.bunny]
//! obj = "bunny.obj"           # relative to this file
//! [mesh.ball]
//! sphere = { radius = 1.0, stacks = 16, slices = 32 }
//!
//! [[instance]]
//! mesh = "flake"
//! translate = [0.0, 1.0, 0.0] # optional; then rotate (degrees about x, y, z) and scale
//! rotate = [0.0, 45.0, 0.0]
//! scale = 2.0                 # or [x, y, z]
//! # matrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]  instead: rows of the 3×4 matrix
//! #                                (a fourth row, if given, must be [0, 0, 0, 1])
//!
//! [[grid]]                    # count[0]·count[1]·count[2] instances on a lattice
//! mesh = "ball"
//! count = [10, 1, 10]
//! spacing = [3.0, 0.0, 3.0]
//! origin = [0.0, 0.0, 0.0]    # optional: the centre of the lattice
//! random_yaw = true           # optional: a seeded random turn about +y per instance
//! scale = [0.5, 1.5]          # optional: a seeded random uniform scale in this range
//! seed = 1
//! ```
//!
//! Unknown keys, unknown mesh names, a mesh with no or two sources, a malformed entry, a
//! non-finite light, and sizes beyond the limits below are [`Error::SceneFile`]s naming the file,
//! the entry and the numbers, found before anything is allocated for them; a missing OBJ file is
//! the loader's error. Limits: [`MAX_SCENE_INSTANCES`] instances in all (instances and grids
//! together), [`MAX_GENERATED_TRIANGLES`] triangles per generated mesh, sphere radii up to half
//! [`MAX_COORDINATE`](crate::MAX_COORDINATE), files up to [`MAX_SCENE_FILE_BYTES`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{Affine3A, EulerRot, Mat3, Quat, Vec3};
use serde::Deserialize;

mod solid;

use crate::bvh::BuildConfig;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::geometry::{TriangleMesh, load_obj};
use crate::instance::{Instance, InstancedScene};
use crate::procedural;
use crate::raygen::Pcg32;
use crate::render::{
    FresnelMode, Light, LightKind, Material, Projection, RenderCamera, Settings, Surfaces, Texture, World,
};
use crate::scene::Scene;
use crate::shapes::SphereSet;

/// Largest scene file read, in bytes.
pub const MAX_SCENE_FILE_BYTES: u64 = 64 << 20;

/// Most instances one scene file may place, counting every `[[instance]]` and every grid cell
/// (2^24; the two-level build needs about 256 bytes per instance, so this is about 4 GiB).
pub const MAX_SCENE_INSTANCES: u64 = 1 << 24;

/// Most triangles of one generated mesh (`sphere`, `sphereflake`): 2^26, a few GiB to build.
pub const MAX_GENERATED_TRIANGLES: u64 = 1 << 26;

/// Triangles of [`procedural::uv_sphere`] with these counts (after its own clamps).
fn sphere_triangles(stacks: u32, slices: u32) -> u64 {
    2 * slices.max(3) as u64 * (stacks.max(2) as u64 - 1)
}

/// The camera of a scene file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraSpec {
    /// Where the camera sits.
    pub eye: Vec3,
    /// The point it looks at.
    pub look_at: Vec3,
    /// Its up direction.
    pub up: Vec3,
    /// The benchmark camera's field of view (both ways) and the pinhole's horizontal one.
    pub fov_deg: f32,
    /// The renderer's projection.
    pub projection: Projection,
}

impl CameraSpec {
    /// The benchmark's square pinhole camera (`../shared/BENCHMARKING.md`).
    pub fn camera(&self) -> Camera {
        Camera::look_at(self.eye, self.look_at, self.up, self.fov_deg)
    }

    /// The renderer's camera (checked when the file was read).
    pub fn render_camera(&self) -> Option<RenderCamera> {
        RenderCamera::look_at(self.eye, self.look_at, self.up, self.projection)
    }
}

/// How a mesh is shaded.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshShading {
    /// Material index of the mesh's geometries.
    pub material: u32,
    /// Smooth shading by interpolated vertex normals (spheres by default) or flat.
    pub smooth: bool,
    /// Materials of single geometries by OBJ object/group name, overriding `material`.
    pub groups: Vec<(String, u32)>,
    /// A solid's materials, one per primitive in leaf order (its `prim_id`s): the nearest
    /// `material` on the way down its tree, else `material`. Empty for other sources.
    pub leaf_materials: Vec<u32>,
}

/// The `[render]` table: image size, sampling, recursion and environment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSpec {
    /// Image size, sampling and recursion limits.
    pub settings: Settings,
    /// Ambient light.
    pub ambient: Vec3,
    /// Radiance of rays that leave the scene.
    pub background: Vec3,
}

impl Default for RenderSpec {
    fn default() -> Self {
        Self { settings: Settings::default(), ambient: Vec3::ONE, background: Vec3::ZERO }
    }
}

/// Where a mesh's triangles come from.
#[derive(Clone, Debug, PartialEq)]
pub enum MeshSource {
    /// An OBJ file (resolved against the scene file's folder); one geometry per object/group.
    Obj(PathBuf),
    /// [`procedural::sphereflake`].
    Sphereflake {
        /// Recursion levels.
        levels: u32,
        /// Stacks per sphere.
        stacks: u32,
        /// Slices per sphere.
        slices: u32,
    },
    /// [`procedural::uv_sphere`] at the origin.
    Sphere {
        /// Radius.
        radius: f32,
        /// Stacks.
        stacks: u32,
        /// Slices.
        slices: u32,
    },
    /// An OBJ file read with its material libraries and texture coordinates (`mtl = true`): one
    /// geometry per object/group and material.
    ObjWithMaterials(PathBuf),
    /// [`procedural::cuboid`]: an axis-aligned box, 12 triangles.
    Box {
        /// Lowest corner.
        min: Vec3,
        /// Highest corner.
        max: Vec3,
    },
    /// [`procedural::quad`]: a rectangle in the plane y = 0 facing +y, centred on the origin.
    Quad {
        /// Extent along x and z.
        size: [f32; 2],
    },
    /// An analytic sphere at the origin (`analytic = true`): one [`SphereSet`] of one sphere.
    AnalyticSphere {
        /// Radius.
        radius: f32,
    },
    /// The analytic sphereflake (`analytic = true`): [`procedural::sphereflake_spheres`] as one
    /// [`SphereSet`].
    AnalyticSphereflake {
        /// Recursion levels (at most [`MAX_ANALYTIC_FLAKE_LEVELS`]).
        levels: u32,
    },
    /// A solid (`solid = { … }`): primitives placed and combined by CSG (see
    /// [`Solid`](crate::Solid)), one geometry.
    Solid(crate::Solid),
}

/// Deepest analytic sphereflake a scene file may ask for: 4.8 million spheres.
pub const MAX_ANALYTIC_FLAKE_LEVELS: u32 = 7;

impl MeshSource {
    /// Loads or generates the meshes.
    pub fn load(&self) -> Result<Vec<TriangleMesh>> {
        Ok(match *self {
            MeshSource::Obj(ref p) => load_obj(p)?,
            MeshSource::ObjWithMaterials(ref p) => crate::geometry::load_obj_with_materials(p)?.meshes,
            MeshSource::Sphereflake { levels, stacks, slices } => {
                vec![procedural::sphereflake(levels, stacks, slices)]
            }
            MeshSource::Sphere { radius, stacks, slices } => {
                vec![procedural::uv_sphere(Vec3::ZERO, radius, stacks, slices)]
            }
            MeshSource::Box { min, max } => vec![procedural::cuboid(min, max)],
            MeshSource::Quad { size } => vec![procedural::quad(size[0], size[1])],
            MeshSource::AnalyticSphere { .. } | MeshSource::AnalyticSphereflake { .. } | MeshSource::Solid(_) => {
                Vec::new()
            }
        })
    }

    /// The solids of this source (one for a `solid` mesh, none otherwise).
    pub fn solids(&self) -> Vec<crate::Solid> {
        match self {
            MeshSource::Solid(s) => vec![s.clone()],
            _ => Vec::new(),
        }
    }

    /// The analytic spheres of this source (none for the triangle sources).
    pub fn sphere_sets(&self) -> Result<Vec<SphereSet>> {
        Ok(match *self {
            MeshSource::AnalyticSphere { radius } => vec![SphereSet::new("sphere", vec![Vec3::ZERO], vec![radius])?],
            MeshSource::AnalyticSphereflake { levels } => {
                vec![SphereSet::from_pairs("sphereflake", &procedural::sphereflake_spheres(levels))?]
            }
            _ => Vec::new(),
        })
    }
}

/// A parsed and checked scene file: named meshes, instances of them, camera and lights.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneFile {
    /// The file the scene was read from.
    pub path: PathBuf,
    /// Mesh names and sources, in name order; instances refer to them by index.
    pub meshes: Vec<(String, MeshSource)>,
    /// Placements of the meshes.
    pub instances: Vec<Instance>,
    /// The camera, if the file has one.
    pub camera: Option<CameraSpec>,
    /// The lights.
    pub lights: Vec<Light>,
    /// Materials: index 0 is the default [`Material`], then the `[material.*]` tables in name
    /// order.
    pub materials: Vec<(String, Material)>,
    /// Per mesh (in `meshes` order): materials and normals.
    pub mesh_shading: Vec<MeshShading>,
    /// Per instance: the material overriding its mesh's, if any.
    pub instance_materials: Vec<Option<u32>>,
    /// Render settings.
    pub render: RenderSpec,
}

/// A solid from the scene-file notation of one (`data/README.md`): the inline table that follows
/// `solid =` in a `[mesh.*]` table, for example
/// `{ difference = [{ box = {} }, { sphere = { radius = 1.3 } }], rotate = [0, 45, 0] }`.
/// Relative OBJ paths resolve against `base`; `material` keys are accepted and ignored (a scene
/// without a renderer has no materials). Bad notation or a bad solid is an [`Error::SceneFile`]
/// whose path is `base` and whose message names the node.
///
/// ```
/// let die = strahl::scene_file::parse_solid(
///     "{ difference = [{ box = {} }, { sphere = { center = [0, 0, 1], radius = 0.3 } }] }",
///     std::path::Path::new("."),
/// )?;
/// assert!(die.contains(glam::Vec3::new(0.0, 0.0, -0.5)) && !die.contains(glam::Vec3::new(0.0, 0.0, 0.9)));
/// # Ok::<(), strahl::Error>(())
/// ```
pub fn parse_solid(text: &str, base: &Path) -> Result<crate::Solid> {
    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct One {
        solid: solid::RawSolid,
    }
    let err = |message: String| Error::SceneFile { path: base.to_path_buf(), message };
    if text.len() as u64 > MAX_SCENE_FILE_BYTES {
        return Err(err(format!("a solid of {} bytes; at most {MAX_SCENE_FILE_BYTES}", text.len())));
    }
    let one: One = toml::from_str(&format!("solid = {text}")).map_err(|e| err(e.to_string()))?;
    let (solid, _) = solid::build(&one.solid, base).map_err(err)?;
    solid.check().map_err(|e| err(format!("the solid: {e}")))?;
    Ok(solid)
}

impl SceneFile {
    /// Reads and checks a scene file; meshes are not loaded yet.
    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let bytes = crate::geometry::obj::read_regular(path, MAX_SCENE_FILE_BYTES)?;
        let text = String::from_utf8(bytes).map_err(|e| Error::Io {
            path: path.to_path_buf(),
            cause: std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()),
        })?;
        Self::parse(&text, path)
    }

    /// Parses `text` as the file at `path` (relative OBJ paths resolve against its folder).
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let err = |message: String| Error::SceneFile { path: path.to_path_buf(), message };
        let raw: RawFile = toml::from_str(text).map_err(|e| err(e.to_string()))?;
        let base = path.parent().unwrap_or(Path::new("."));
        let mut materials = vec![("default".to_string(), Material::default())];
        for (name, m) in &raw.material {
            let mat = m.material().map_err(|e| err(format!("material `{name}`: {e}")))?;
            materials.push((name.clone(), mat));
        }
        let material =
            |name: &Option<String>, what: &str| -> Result<Option<u32>> {
                match name {
                    None => Ok(None),
                    Some(n) => materials.iter().position(|(m, _)| m == n).map(|i| Some(i as u32)).ok_or_else(|| {
                        err(format!("{what} names material `{n}`, which no [material.{n}] table defines"))
                    }),
                }
            };
        let mut meshes = Vec::new();
        let mut mesh_shading = Vec::new();
        for (name, m) in &raw.mesh {
            let sources = m.obj.is_some() as u32
                + m.sphereflake.is_some() as u32
                + m.sphere.is_some() as u32
                + m.cuboid.is_some() as u32
                + m.quad.is_some() as u32
                + m.solid.is_some() as u32;
            if sources != 1 {
                return Err(err(format!(
                    "mesh `{name}` needs exactly one of `obj`, `sphereflake`, `sphere`, `box`, `quad`, `solid`"
                )));
            }
            let too_many = |tris: f64| {
                err(format!(
                    "mesh `{name}`: {tris:.3e} triangles; at most {MAX_GENERATED_TRIANGLES} (2^26) per generated mesh"
                ))
            };
            if m.mtl.is_some() && m.obj.is_none() {
                return Err(err(format!("mesh `{name}`: `mtl` applies to `obj` meshes only")));
            }
            let analytic = m.analytic == Some(true);
            if analytic && m.sphere.is_none() && m.sphereflake.is_none() {
                return Err(err(format!(
                    "mesh `{name}`: `analytic` applies to `sphere` and `sphereflake` meshes only"
                )));
            }
            // Tessellation sizes: required for triangle spheres, meaningless for analytic ones.
            let tessellation = |stacks: Option<u32>, slices: Option<u32>| match (analytic, stacks, slices) {
                (false, Some(a), Some(b)) => Ok((a, b)),
                (false, _, _) => Err(err(format!("mesh `{name}` needs `stacks` and `slices` (or `analytic = true`)"))),
                (true, None, None) => Ok((0, 0)),
                (true, _, _) => {
                    Err(err(format!("mesh `{name}`: `stacks` and `slices` do not apply to analytic spheres")))
                }
            };
            let mut leaf_materials = Vec::new();
            let source = if let Some(raw) = &m.solid {
                let (solid, names) = solid::build(raw, base).map_err(|e| err(format!("mesh `{name}`: {e}")))?;
                solid.check().map_err(|e| err(format!("mesh `{name}`: the solid: {e}")))?;
                for n in &names {
                    leaf_materials.push(material(n, &format!("mesh `{name}`, a solid's node,"))?);
                }
                MeshSource::Solid(solid)
            } else if let Some(p) = &m.obj {
                if m.mtl == Some(true) {
                    MeshSource::ObjWithMaterials(base.join(p))
                } else {
                    MeshSource::Obj(base.join(p))
                }
            } else if let Some(s) = &m.sphereflake {
                let (stacks, slices) = tessellation(s.stacks, s.slices)?;
                if analytic {
                    if s.levels > MAX_ANALYTIC_FLAKE_LEVELS {
                        return Err(err(format!(
                            "mesh `{name}`: analytic sphereflake levels {}; at most {MAX_ANALYTIC_FLAKE_LEVELS}",
                            s.levels
                        )));
                    }
                    MeshSource::AnalyticSphereflake { levels: s.levels }
                } else {
                    // 1 + 9 + … + 9^levels spheres.
                    let spheres = (9f64.powi(s.levels.min(1000) as i32 + 1) - 1.0) / 8.0;
                    let tris = spheres * sphere_triangles(stacks, slices) as f64;
                    if tris > MAX_GENERATED_TRIANGLES as f64 {
                        return Err(too_many(tris));
                    }
                    MeshSource::Sphereflake { levels: s.levels, stacks, slices }
                }
            } else if let Some(b) = &m.cuboid {
                let (min, max) = (Vec3::from(b.min), Vec3::from(b.max));
                let lim = crate::MAX_COORDINATE;
                if !(min.cmplt(max).all() && min.abs().max_element() <= lim && max.abs().max_element() <= lim) {
                    return Err(err(format!("mesh `{name}`: box min {min} must lie below max {max}, within ±{lim:e}")));
                }
                MeshSource::Box { min, max }
            } else if let Some(q) = &m.quad {
                let lim = crate::MAX_COORDINATE;
                if !q.size.iter().all(|&v| v > 0.0 && v <= lim) {
                    return Err(err(format!(
                        "mesh `{name}`: quad size {:?} must be positive, at most {lim:e}",
                        q.size
                    )));
                }
                MeshSource::Quad { size: q.size }
            } else {
                let s = m.sphere.as_ref().expect("counted above");
                if !(s.radius.is_finite() && s.radius > 0.0 && s.radius <= 0.5 * crate::MAX_COORDINATE) {
                    return Err(err(format!(
                        "mesh `{name}`: sphere radius {} must be positive and at most {:e}",
                        s.radius,
                        0.5 * crate::MAX_COORDINATE
                    )));
                }
                let (stacks, slices) = tessellation(s.stacks, s.slices)?;
                if analytic {
                    MeshSource::AnalyticSphere { radius: s.radius }
                } else {
                    let tris = sphere_triangles(stacks, slices);
                    if tris > MAX_GENERATED_TRIANGLES {
                        return Err(too_many(tris as f64));
                    }
                    MeshSource::Sphere { radius: s.radius, stacks, slices }
                }
            };
            let smooth =
                m.smooth.unwrap_or(matches!(source, MeshSource::Sphere { .. } | MeshSource::Sphereflake { .. }));
            let what = format!("mesh `{name}`");
            let mut groups = Vec::new();
            for (group, mat) in &m.groups {
                let i = material(&Some(mat.clone()), &format!("{what}, group `{group}`,"))?.expect("named");
                groups.push((group.clone(), i));
            }
            let mesh_material = material(&m.material, &what)?.unwrap_or(0);
            let leaf_materials = leaf_materials.into_iter().map(|l| l.unwrap_or(mesh_material)).collect();
            mesh_shading.push(MeshShading { material: mesh_material, smooth, groups, leaf_materials });
            meshes.push((name.clone(), source));
        }
        let index = |mesh: &str, what: &str| {
            meshes
                .iter()
                .position(|(n, _)| n == mesh)
                .ok_or_else(|| err(format!("{what} places mesh `{mesh}`, which no [mesh.{mesh}] table defines")))
        };
        // Every instance counted before any is made.
        let mut total = raw.instance.len() as u64;
        for (g, grid) in raw.grid.iter().enumerate() {
            let cells = grid.count.iter().map(|&c| c as u64).product::<u64>();
            if cells == 0 {
                return Err(err(format!("grid {g}: count {:?} places no instance", grid.count)));
            }
            total = total.saturating_add(cells);
        }
        if total > MAX_SCENE_INSTANCES {
            return Err(err(format!(
                "{total} instances in all (instances and grid cells); at most {MAX_SCENE_INSTANCES} (2^24)"
            )));
        }
        let mut instances = Vec::new();
        instances.try_reserve_exact(total as usize).map_err(|e| err(format!("{total} instances: {e}")))?;
        let mut instance_materials = Vec::new();
        instance_materials.try_reserve_exact(total as usize).map_err(|e| err(format!("{total} instances: {e}")))?;
        for (i, inst) in raw.instance.iter().enumerate() {
            let what = format!("instance {i}");
            let object = index(&inst.mesh, &what)?;
            instance_materials.push(material(&inst.material, &what)?);
            let transform = placement(inst.translate, inst.rotate, inst.scale, &inst.matrix)
                .map_err(|m| err(format!("{what}: {m}")))?
                .unwrap_or(Affine3A::IDENTITY);
            check_transform(&transform).map_err(|m| err(format!("{what}: {m}")))?;
            instances.push(Instance::new(object, transform));
        }
        for (g, grid) in raw.grid.iter().enumerate() {
            let what = format!("grid {g}");
            let object = index(&grid.mesh, &what)?;
            let grid_material = material(&grid.material, &what)?;
            let n = grid.count;
            let spacing = Vec3::from(grid.spacing);
            let origin = grid.origin.map_or(Vec3::ZERO, Vec3::from);
            let (lo_s, hi_s) = match grid.scale {
                None => (1.0, 1.0),
                Some(Range::Fixed(s)) => (s, s),
                Some(Range::Between([a, b])) => (a, b),
            };
            let mut rng = Pcg32::new(grid.seed, g as u64);
            let half = Vec3::new(n[0] as f32 - 1.0, n[1] as f32 - 1.0, n[2] as f32 - 1.0) * 0.5;
            for z in 0..n[2] {
                for y in 0..n[1] {
                    for x in 0..n[0] {
                        let cell = (Vec3::new(x as f32, y as f32, z as f32) - half) * spacing + origin;
                        let yaw = if grid.random_yaw { rng.next_f32() * 360.0 } else { 0.0 };
                        let s = lo_s + (hi_s - lo_s) * rng.next_f32();
                        let transform = trs(cell, Vec3::new(0.0, yaw, 0.0), Vec3::splat(s));
                        check_transform(&transform).map_err(|m| err(format!("{what}: {m}")))?;
                        instances.push(Instance::new(object, transform));
                        instance_materials.push(grid_material);
                    }
                }
            }
        }
        let camera = match raw.camera {
            None => None,
            Some(c) => {
                let fov_deg = c.fov.unwrap_or(60.0);
                let projection = match c.projection.as_deref().unwrap_or("pinhole") {
                    "pinhole" => Projection::Pinhole { fov_deg },
                    "orthographic" => Projection::Orthographic { width: c.width.unwrap_or(1.0) },
                    "fisheye" => Projection::Fisheye { fov_deg: c.fov.unwrap_or(180.0) },
                    "omnimax" => Projection::Omnimax,
                    "panorama" => Projection::Panorama,
                    other => {
                        return Err(err(format!(
                            "camera: projection `{other}` is none of pinhole, orthographic, fisheye, omnimax, panorama"
                        )));
                    }
                };
                let spec = CameraSpec {
                    eye: c.eye.into(),
                    look_at: c.look_at.into(),
                    up: c.up.map_or(Vec3::Y, Vec3::from),
                    fov_deg,
                    projection,
                };
                let f = spec.look_at - spec.eye;
                if !(f.is_finite() && spec.up.is_finite())
                    || f.cross(spec.up).length_squared() == 0.0
                    || !(fov_deg > 0.0 && fov_deg < 180.0 || matches!(projection, Projection::Fisheye { .. }))
                    || spec.render_camera().is_none()
                {
                    return Err(err(
                        "camera: eye, look_at and up must span a view, and fov lie in (0, 180) (fisheye: (0, 360]; orthographic width > 0)".into(),
                    ));
                }
                Some(spec)
            }
        };
        let mut lights = Vec::with_capacity(raw.light.len());
        for (i, l) in raw.light.iter().enumerate() {
            let light = l.light().map_err(|m| err(format!("light {i}: {m}")))?;
            light.check().map_err(|m| err(format!("light {i}: {m}")))?;
            lights.push(light);
        }
        let render = match raw.render {
            None => RenderSpec::default(),
            Some(r) => {
                let d = RenderSpec::default();
                let spec = RenderSpec {
                    settings: Settings {
                        width: r.width.unwrap_or(d.settings.width),
                        height: r.height.unwrap_or(d.settings.height),
                        spp: r.spp.unwrap_or(d.settings.spp),
                        max_depth: r.max_depth.unwrap_or(d.settings.max_depth),
                        bailout: r.bailout.unwrap_or(d.settings.bailout),
                        seed: r.seed.unwrap_or(d.settings.seed),
                        filtered_shadows: match r.shadows.as_deref().unwrap_or("opaque") {
                            "opaque" => false,
                            "filtered" => true,
                            other => {
                                return Err(err(format!("[render]: shadows `{other}` is neither opaque nor filtered")));
                            }
                        },
                    },
                    ambient: r.ambient.map_or(d.ambient, Rgb::vec),
                    background: r.background.map_or(d.background, Rgb::vec),
                };
                spec.settings.check().map_err(|e| err(format!("[render]: {e}")))?;
                for (name, c) in [("ambient", spec.ambient), ("background", spec.background)] {
                    if !(c.is_finite() && c.min_element() >= 0.0) {
                        return Err(err(format!("[render]: {name} {c} must be finite and not negative")));
                    }
                }
                spec
            }
        };
        Ok(Self {
            path: path.to_path_buf(),
            meshes,
            instances,
            camera,
            lights,
            materials,
            mesh_shading,
            instance_materials,
            render,
        })
    }

    /// Loads or generates every mesh (one object per `[mesh.*]` table, in name order).
    pub fn load_objects(&self) -> Result<Vec<Vec<TriangleMesh>>> {
        self.meshes.iter().map(|(_, s)| s.load()).collect()
    }

    /// The analytic spheres of every object (one list per `[mesh.*]` table, in name order; empty
    /// for triangle sources).
    pub fn load_spheres(&self) -> Result<Vec<Vec<SphereSet>>> {
        self.meshes.iter().map(|(_, s)| s.sphere_sets()).collect()
    }

    /// The solids of every object (one list per `[mesh.*]` table, in name order; empty for other
    /// sources).
    pub fn load_solids(&self) -> Vec<Vec<crate::Solid>> {
        self.meshes.iter().map(|(_, s)| s.solids()).collect()
    }

    /// Loads the meshes and spheres and builds the two-level scene.
    pub fn build(&self, config: &BuildConfig) -> Result<InstancedScene> {
        self.build_from(self.load_objects()?, config)
    }

    /// Builds the two-level scene from the meshes [`load_objects`](Self::load_objects) returned
    /// and this file's analytic spheres and solids: each object's meshes, spheres and solids in
    /// one object scene (geometry ids: meshes, then sphere sets, then solids), objects in
    /// parallel.
    pub fn build_from(&self, objects: Vec<Vec<TriangleMesh>>, config: &BuildConfig) -> Result<InstancedScene> {
        use rayon::prelude::*;
        let spheres = self.load_spheres()?;
        let solids = self.load_solids();
        if spheres.iter().all(|s| s.is_empty()) && solids.iter().all(|s| s.is_empty()) {
            return InstancedScene::build(objects, self.instances.clone(), config);
        }
        let scenes = objects
            .into_par_iter()
            .zip(spheres)
            .zip(solids)
            .map(|((meshes, sets), solids)| Scene::build_with_solids(meshes, sets, solids, config))
            .collect::<Result<Vec<Scene>>>()?;
        InstancedScene::from_scenes(scenes, self.instances.clone())
    }

    /// The renderer's view of the scene, from the objects [`load_objects`](Self::load_objects)
    /// returned: materials per mesh and instance, normals, lights and environment.
    pub fn world(&self, objects: &[Vec<TriangleMesh>]) -> Result<World> {
        let err = |message: String| Error::SceneFile { path: self.path.clone(), message };
        let mut materials: Vec<Material> = self.materials.iter().map(|(_, m)| *m).collect();
        let mut textures = Vec::new();
        let mut texture_paths: Vec<PathBuf> = Vec::new();
        // Per object and geometry: material and corner texture coordinates.
        let mut per_geom: Vec<Vec<GeomShading>> = Vec::with_capacity(objects.len());
        for ((meshes, sh), (name, source)) in objects.iter().zip(&self.mesh_shading).zip(&self.meshes) {
            for (group, _) in &sh.groups {
                if !meshes.iter().any(|g| &g.name == group) {
                    let names: Vec<&str> = meshes.iter().map(|g| g.name.as_str()).collect();
                    return Err(err(format!("mesh `{name}` has no object or group `{group}` (it has {names:?})")));
                }
            }
            let group = |g: &TriangleMesh| sh.groups.iter().find(|(n, _)| *n == g.name).map(|x| x.1);
            let mut geoms: Vec<GeomShading> = meshes.iter().map(|g| (group(g).unwrap_or(sh.material), None)).collect();
            if let MeshSource::ObjWithMaterials(path) = source {
                // Read again for the materials and coordinates; the same parse gives the same
                // geometries as the ones the scene was built from.
                let obj = crate::geometry::load_obj_with_materials(path)?;
                let same = obj.meshes.len() == meshes.len()
                    && obj.meshes.iter().zip(meshes).all(|(a, b)| a.triangle_count() == b.triangle_count());
                if !same {
                    return Err(err(format!("mesh `{name}`: {} changed while it was read", path.display())));
                }
                let first = materials.len() as u32;
                let base = path.parent().unwrap_or(Path::new("."));
                for m in &obj.materials {
                    let texture = match &m.diffuse_texture {
                        None => None,
                        Some(t) => {
                            let p = base.join(t.trim());
                            let i = match texture_paths.iter().position(|q| *q == p) {
                                Some(i) => i,
                                None => {
                                    textures.push(crate::render::texture::ImageTexture::load(&p)?);
                                    texture_paths.push(p);
                                    textures.len() - 1
                                }
                            };
                            Some(i as u32)
                        }
                    };
                    let mat = material_from_mtl(m, texture)
                        .map_err(|e| err(format!("mesh `{name}`: MTL material `{}`: {e}", m.name)))?;
                    materials.push(mat);
                }
                for (k, g) in meshes.iter().enumerate() {
                    if let (None, Some(m)) = (group(g), obj.mesh_material[k]) {
                        geoms[k].0 = first + m as u32;
                    }
                    geoms[k].1 =
                        obj.corner_uvs[k].as_ref().map(|c| c.iter().map(|t| t.map(glam::Vec2::from)).collect());
                }
            }
            per_geom.push(geoms);
        }
        let objs: Vec<Vec<(&TriangleMesh, u32, bool)>> = objects
            .iter()
            .zip(&per_geom)
            .zip(&self.mesh_shading)
            .map(|((meshes, geoms), sh)| meshes.iter().zip(geoms).map(|(g, (m, _))| (g, *m, sh.smooth)).collect())
            .collect();
        let placed: Vec<_> = self.instances.iter().copied().zip(self.instance_materials.iter().copied()).collect();
        let mut surfaces = Surfaces::new(&objs, &placed);
        for (o, ((_, source), sh)) in self.meshes.iter().zip(&self.mesh_shading).enumerate() {
            for set in source.sphere_sets()? {
                surfaces.add_spheres(o, set.len(), sh.material);
            }
            if matches!(source, MeshSource::Solid(_)) {
                surfaces.add_solid(o, sh.leaf_materials.clone());
            }
        }
        for (o, geoms) in per_geom.into_iter().enumerate() {
            for (g, (_, uvs)) in geoms.into_iter().enumerate() {
                if let Some(uvs) = uvs {
                    surfaces.set_uvs(o, g, uvs);
                }
            }
        }
        let world = World {
            surfaces,
            materials,
            textures,
            lights: self.lights.clone(),
            ambient: self.render.ambient,
            background: self.render.background,
        };
        world.check().map_err(|e| err(e.to_string()))?;
        Ok(world)
    }
}

/// A geometry's material and the texture coordinates of its triangles' corners.
type GeomShading = (u32, Option<Vec<[glam::Vec2; 3]>>);

/// An MTL material as the renderer's: `Kd` (1 under a `map_Kd`, else 0.7 when absent), `Ka` as
/// the ambient factor, `Ks`/`Ns` Phong, `Ni` the index, `d` (or `Tr`) and `Tf` the transmission,
/// and the illumination model: 3 and 5 reflect by `Ks`, 4, 6 and 7 refract (glass).
fn material_from_mtl(m: &tobj::Material, texture: Option<u32>) -> std::result::Result<Material, String> {
    let d = Material::default();
    let rgb = |c: Option<[f32; 3]>| c.map(Vec3::from);
    let param = |k: &str| {
        m.unknown_param.get(k).and_then(|v| {
            let n: Vec<f32> = v.split_whitespace().filter_map(|x| x.parse().ok()).collect();
            match n[..] {
                [g] => Some(Vec3::splat(g)),
                [r, g, b, ..] => Some(Vec3::new(r, g, b)),
                _ => None,
            }
        })
    };
    let dissolve = m.dissolve.or_else(|| param("Tr").map(|t| 1.0 - t.x)).unwrap_or(1.0);
    let illum = m.illumination_model.unwrap_or(2);
    let specular = if illum >= 2 { rgb(m.specular).unwrap_or(Vec3::ZERO) } else { Vec3::ZERO };
    let filter = param("Tf").unwrap_or(Vec3::ONE);
    let glass = matches!(illum, 4 | 6 | 7);
    let transmit =
        if dissolve < 1.0 || glass { filter * (1.0 - dissolve).max(if glass { 1.0 } else { 0.0 }) } else { Vec3::ZERO };
    let mat = Material {
        ambient: rgb(m.ambient).unwrap_or(d.ambient),
        diffuse: rgb(m.diffuse).unwrap_or(if texture.is_some() { Vec3::ONE } else { d.diffuse }),
        specular,
        shininess: m.shininess.unwrap_or(d.shininess),
        reflect: if matches!(illum, 3 | 5) { specular } else { Vec3::ZERO },
        transmit,
        ior: m.optical_density.unwrap_or(if transmit != Vec3::ZERO { 1.5 } else { 1.0 }),
        absorption: Vec3::ZERO,
        fresnel: FresnelMode::Exact,
        texture: texture.map(|index| Texture::Image { index }),
    };
    mat.check()?;
    Ok(mat)
}

/// Translation · rotation (degrees about x, then y, then z) · scale.
fn trs(t: Vec3, rot_deg: Vec3, s: Vec3) -> Affine3A {
    let q = Quat::from_euler(EulerRot::XYZ, rot_deg.x.to_radians(), rot_deg.y.to_radians(), rot_deg.z.to_radians());
    Affine3A::from_scale_rotation_translation(s, q, t)
}

/// The placement written as `matrix` (3 rows, or 4 whose last is `[0, 0, 0, 1]`) or as
/// translate · rotate · scale; `None` where neither is given. `Err` says what is malformed.
fn placement(
    translate: Option<[f32; 3]>,
    rotate: Option<[f32; 3]>,
    scale: Option<Scale>,
    matrix: &Option<Vec<[f32; 4]>>,
) -> std::result::Result<Option<Affine3A>, String> {
    let trs_given = translate.is_some() || rotate.is_some() || scale.is_some();
    match matrix {
        Some(rows) => {
            if trs_given {
                return Err("give `matrix` or translate/rotate/scale, not both".into());
            }
            match rows.len() {
                3 => {}
                4 if rows[3] == [0.0, 0.0, 0.0, 1.0] => {}
                4 => {
                    return Err(format!(
                        "the matrix's fourth row is {:?}; an affine transform's is [0, 0, 0, 1]",
                        rows[3]
                    ));
                }
                n => return Err(format!("`matrix` has {n} rows; give 3 (or 4, the last [0, 0, 0, 1])")),
            }
            let c = |k: usize| Vec3::new(rows[0][k], rows[1][k], rows[2][k]);
            Ok(Some(Affine3A::from_mat3_translation(Mat3::from_cols(c(0), c(1), c(2)), c(3))))
        }
        None if trs_given => Ok(Some(trs(
            translate.map_or(Vec3::ZERO, Vec3::from),
            rotate.map_or(Vec3::ZERO, Vec3::from),
            scale.map_or(Vec3::ONE, Scale::vec),
        ))),
        None => Ok(None),
    }
}

fn check_transform(m: &Affine3A) -> std::result::Result<(), String> {
    if crate::instance::is_invertible(m) { Ok(()) } else { Err("the transform is not finite and invertible".into()) }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    camera: Option<RawCamera>,
    render: Option<RawRender>,
    #[serde(default)]
    material: BTreeMap<String, RawMaterial>,
    #[serde(default)]
    light: Vec<RawLight>,
    #[serde(default)]
    mesh: BTreeMap<String, RawMesh>,
    #[serde(default)]
    instance: Vec<RawInstance>,
    #[serde(default)]
    grid: Vec<RawGrid>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    eye: [f32; 3],
    look_at: [f32; 3],
    up: Option<[f32; 3]>,
    fov: Option<f32>,
    projection: Option<String>,
    width: Option<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRender {
    width: Option<u32>,
    height: Option<u32>,
    spp: Option<u32>,
    max_depth: Option<u32>,
    bailout: Option<f32>,
    seed: Option<u64>,
    ambient: Option<Rgb>,
    background: Option<Rgb>,
    shadows: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLight {
    kind: Option<String>,
    position: Option<[f32; 3]>,
    color: Option<Rgb>,
    intensity: Option<f32>,
    direction: Option<[f32; 3]>,
    /// Spot: full intensity within this half-angle (degrees). Sphere: the radius.
    radius: Option<f32>,
    /// Spot: no light beyond this half-angle (degrees).
    falloff: Option<f32>,
    fade: Option<f32>,
    /// Rect: the edge vectors.
    u: Option<[f32; 3]>,
    v: Option<[f32; 3]>,
    /// Rect: `[n0, n1]` (or one number for both); sphere: one number.
    samples: Option<Samples>,
}

#[derive(Clone, Copy, Deserialize)]
#[serde(untagged)]
enum Samples {
    Both(u32),
    Each([u32; 2]),
}

impl RawLight {
    fn light(&self) -> std::result::Result<Light, String> {
        let color = self.color.map_or(Vec3::ONE, Rgb::vec) * self.intensity.unwrap_or(1.0);
        let dir = || -> std::result::Result<Vec3, String> {
            let d = Vec3::from(self.direction.ok_or("needs a `direction`")?);
            let n = d.normalize_or_zero();
            if n == Vec3::ZERO || !n.is_finite() {
                return Err(format!("direction {d} must be finite and non-zero"));
            }
            Ok(n)
        };
        let position = || self.position.map(Vec3::from).ok_or_else(|| "needs a `position`".to_string());
        let kind = self.kind.as_deref().unwrap_or("point");
        let (position, kind) = match kind {
            "point" => (position()?, LightKind::Point),
            "directional" => (Vec3::ZERO, LightKind::Directional { direction: dir()? }),
            "spot" => {
                let radius = self.radius.unwrap_or(30.0);
                let falloff = self.falloff.unwrap_or(radius.max(45.0));
                if !(radius >= 0.0 && radius <= falloff && falloff < 180.0) {
                    return Err(format!(
                        "spot radius {radius}° and falloff {falloff}° need 0 ≤ radius ≤ falloff < 180"
                    ));
                }
                let kind = LightKind::Spot {
                    direction: dir()?,
                    cos_inner: radius.to_radians().cos(),
                    cos_outer: falloff.to_radians().cos(),
                };
                (position()?, kind)
            }
            "rect" => {
                let edge =
                    |e: Option<[f32; 3]>, k: &str| e.map(Vec3::from).ok_or_else(|| format!("needs an edge `{k}`"));
                let n = match self.samples.unwrap_or(Samples::Both(4)) {
                    Samples::Both(n) => [n, n],
                    Samples::Each(n) => n,
                };
                (position()?, LightKind::Rect { u: edge(self.u, "u")?, v: edge(self.v, "v")?, n })
            }
            "sphere" => {
                let n = match self.samples.unwrap_or(Samples::Both(16)) {
                    Samples::Both(n) => n,
                    Samples::Each(_) => return Err("a sphere light's `samples` is one number".into()),
                };
                (position()?, LightKind::Sphere { radius: self.radius.ok_or("needs a `radius`")?, n })
            }
            other => return Err(format!("kind `{other}` is none of point, directional, spot, rect, sphere")),
        };
        Ok(Light { position, color, kind, fade: self.fade })
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaterial {
    color: Option<Rgb>,
    ambient: Option<Rgb>,
    specular: Option<Rgb>,
    shininess: Option<f32>,
    reflect: Option<Rgb>,
    transmit: Option<Rgb>,
    ior: Option<f32>,
    absorption: Option<Rgb>,
    fresnel: Option<String>,
    checker: Option<RawChecker>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChecker {
    color: Rgb,
    size: f32,
}

impl RawMaterial {
    fn material(&self) -> std::result::Result<Material, String> {
        let d = Material::default();
        let fresnel = match self.fresnel.as_deref().unwrap_or("exact") {
            "exact" => FresnelMode::Exact,
            "schlick" => FresnelMode::Schlick,
            "off" => FresnelMode::Off,
            other => return Err(format!("fresnel `{other}` is none of exact, schlick, off")),
        };
        let m = Material {
            ambient: self.ambient.map_or(d.ambient, Rgb::vec),
            diffuse: self.color.map_or(d.diffuse, Rgb::vec),
            specular: self.specular.map_or(d.specular, Rgb::vec),
            shininess: self.shininess.unwrap_or(d.shininess),
            reflect: self.reflect.map_or(d.reflect, Rgb::vec),
            transmit: self.transmit.map_or(d.transmit, Rgb::vec),
            ior: self.ior.unwrap_or(if self.transmit.is_some() { 1.5 } else { d.ior }),
            absorption: self.absorption.map_or(d.absorption, Rgb::vec),
            fresnel,
            texture: self.checker.as_ref().map(|c| Texture::Checker { other: c.color.vec(), size: c.size }),
        };
        m.check()?;
        Ok(m)
    }
}

/// A colour as one number (grey) or three.
#[derive(Clone, Copy, Deserialize)]
#[serde(untagged)]
enum Rgb {
    Grey(f32),
    Rgb([f32; 3]),
}

impl Rgb {
    fn vec(self) -> Vec3 {
        match self {
            Rgb::Grey(g) => Vec3::splat(g),
            Rgb::Rgb(c) => c.into(),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMesh {
    obj: Option<PathBuf>,
    sphereflake: Option<RawFlake>,
    sphere: Option<RawSphere>,
    #[serde(rename = "box")]
    cuboid: Option<RawBox>,
    quad: Option<RawQuad>,
    material: Option<String>,
    smooth: Option<bool>,
    #[serde(default)]
    groups: BTreeMap<String, String>,
    mtl: Option<bool>,
    analytic: Option<bool>,
    solid: Option<solid::RawSolid>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBox {
    min: [f32; 3],
    max: [f32; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawQuad {
    size: [f32; 2],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFlake {
    levels: u32,
    stacks: Option<u32>,
    slices: Option<u32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSphere {
    radius: f32,
    stacks: Option<u32>,
    slices: Option<u32>,
}

#[derive(Clone, Copy, Deserialize)]
#[serde(untagged)]
enum Scale {
    Uniform(f32),
    Axes([f32; 3]),
}

impl Scale {
    fn vec(self) -> Vec3 {
        match self {
            Scale::Uniform(s) => Vec3::splat(s),
            Scale::Axes(a) => a.into(),
        }
    }
}

#[derive(Clone, Copy, Deserialize)]
#[serde(untagged)]
enum Range {
    Fixed(f32),
    Between([f32; 2]),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInstance {
    mesh: String,
    translate: Option<[f32; 3]>,
    rotate: Option<[f32; 3]>,
    scale: Option<Scale>,
    matrix: Option<Vec<[f32; 4]>>,
    material: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGrid {
    mesh: String,
    count: [u32; 3],
    spacing: [f32; 3],
    origin: Option<[f32; 3]>,
    #[serde(default)]
    random_yaw: bool,
    scale: Option<Range>,
    #[serde(default)]
    seed: u64,
    material: Option<String>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<SceneFile> {
        SceneFile::parse(text, Path::new("/scenes/test.toml"))
    }

    #[test]
    fn parses_the_documented_example() {
        let doc = include_str!("mod.rs");
        let example: String = doc
            .lines()
            .skip_while(|l| !l.starts_with("//! ```toml"))
            .skip(1)
            .take_while(|l| !l.starts_with("//! ```"))
            .map(|l| l.trim_start_matches("//!").trim_start_matches(' '))
            .collect::<Vec<_>>()
            .join("\n");
        let f = parse(&example).unwrap();
        assert_eq!(f.meshes.len(), 3);
        assert_eq!(f.meshes[1].1, MeshSource::Obj(PathBuf::from("/scenes/bunny.obj")));
        assert_eq!(f.instances.len(), 1 + 100);
        assert_eq!(f.lights.len(), 1);
        let c = f.camera.unwrap();
        assert_eq!(c.fov_deg, 60.0);
        // translate · rotate · scale: the origin goes to the translation, x to a turned, scaled x.
        let m = f.instances[0].transform;
        assert!((m.transform_point3(Vec3::ZERO) - Vec3::Y).length() < 1e-6);
        let x = m.transform_vector3(Vec3::X);
        assert!((x - Vec3::new(2.0_f32.sqrt(), 0.0, -(2.0_f32.sqrt()))).length() < 1e-5, "{x}");
        // The lattice is centred on its origin.
        let c: Vec3 =
            f.instances[1..].iter().map(|i| i.transform.translation.into()).fold(Vec3::ZERO, |a, b: Vec3| a + b);
        assert!(c.length() < 1e-3, "{c}");
    }

    #[test]
    fn clear_errors_for_malformed_files() {
        let cases = [
            ("[[instance]]\nmesh = \"nope\"", "no [mesh.nope] table"),
            ("[mesh.a]\nsphere = { radius = 1.0, stacks = 4, slices = 8 }\nobj = \"a.obj\"", "exactly one of"),
            ("[mesh.a]\n", "exactly one of"),
            ("[mesh.a]\nsphere = { radius = -1.0, stacks = 4, slices = 8 }", "radius"),
            ("[mesh.a]\nobj = \"a.obj\"\n[[instance]]\nmesh = \"a\"\nscale = 0.0", "not finite and invertible"),
            ("[mesh.a]\nobj = \"a.obj\"\n[[instance]]\nmesh = \"a\"\nsclae = 2.0", "unknown field"),
            ("[mesh.a]\nobj = \"a.obj\"\n[[grid]]\nmesh = \"a\"\ncount = [0, 1, 1]\nspacing = [1, 1, 1]", "count"),
            ("[camera]\neye = [0, 0, 0]\nlook_at = [0, 0, 0]", "camera"),
            ("[camera\n", "TOML"),
            ("[mesh.a]\nsolid = { box = {}, sphere = {} }", "exactly one of sphere, box"),
            ("[mesh.a]\nsolid = { union = [] }", "union of no operands"),
            ("[mesh.a]\nsolid = { cylinder = { cap = [0, 0, 0] } }", "cylinder needs base"),
            ("[mesh.a]\nsolid = { torus = { major = 1.0, minor = 2.0 } }", "0 < minor < major"),
            ("[mesh.a]\nsolid = { plane = { normal = [0, 1, 0] } }", "unbounded"),
            ("[mesh.a]\nsolid = { box = {}, material = \"nope\" }", "no [material.nope]"),
            ("[mesh.a]\nsolid = { union = [{ box = {} }, { disc = {} }] }", "disc is a surface"),
            ("[mesh.a]\nsolid = { box = {}, scale = [1, 0, 1] }", "not finite and invertible"),
            ("[mesh.a]\nobj = \"a.obj\"\n[[instance]]\nmesh = \"a\"\nmatrix = [[1, 0, 0, 0], [0, 1, 0]]", "line 5"),
        ];
        for (text, needle) in cases {
            let e = parse(text).expect_err(text);
            assert!(matches!(e, Error::SceneFile { .. }), "{text}: {e:?}");
            let msg = e.to_string();
            assert!(msg.contains("/scenes/test.toml"), "{msg}");
            assert!(msg.to_lowercase().contains(&needle.to_lowercase()) || needle == "TOML", "{text}: {msg}");
        }
        // A mesh file that does not exist fails when loading, naming the file.
        let f = parse("[mesh.a]\nobj = \"missing.obj\"\n[[instance]]\nmesh = \"a\"").unwrap();
        let e = f.build(&BuildConfig::default()).unwrap_err();
        assert!(e.to_string().contains("missing.obj"), "{e}");
        assert!(matches!(SceneFile::read("/nonexistent/x.toml"), Err(Error::Io { .. })));
    }
}
