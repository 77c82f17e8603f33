//! `strahl._strahl`: the extension module under the Python package `strahl` (python/strahl).
//!
//! One class, [`Core`]: a built scene (flat or two-level) with its own rayon pool, queried with
//! C-contiguous float32 numpy arrays that the Python side has checked and converted. Every query
//! releases the GIL and runs on the scene's pool; a `Core` is immutable once built (a frozen
//! class), so any number of Python threads may query it at once. Shapes are checked here again:
//! a wrong one is a `ValueError`, never a panic.

use std::borrow::Cow;

use glam::{Affine3A, Mat3A, Vec3, Vec3A};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use rayon::prelude::*;
use strahl::query::batch;
use strahl::{
    BuildConfig, Coherence, Hit, HitStream, INVALID_ID, Instance, InstancedScene, Query, Ray, RayStream, Scene,
    SphereSet, TriangleMesh,
};

/// Rays per parallel job of `cast_rays` and `test_occlusions`: converted, traced and written back
/// by one thread (strahl's own stream chunk).
const CHUNK: usize = strahl::STREAM_CHUNK;

/// A built scene: flat when no geometry is instanced, else every geometry is an object of a
/// two-level scene. One per Python `Scene` object, so the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
enum World {
    /// A flat scene, and the user's geometry id of each of its geometries (strahl numbers meshes,
    /// then sphere sets, then solids; users number geometries in the order they added them).
    /// Empty: the same numbers.
    Flat(Scene, Vec<u32>),
    Instanced {
        scene: InstancedScene,
        /// Per placed instance: the geometry id it shows and the instance id users see
        /// (`INVALID_ID` for a geometry shown as added).
        ids: Vec<(u32, u32)>,
    },
}

/// Runs `$body` with `$q` bound to the world's scene, whatever its kind.
macro_rules! on_world {
    ($world:expr, $q:ident => $body:expr) => {
        match $world {
            World::Flat($q, _) => $body,
            World::Instanced { scene: $q, .. } => $body,
        }
    };
}

#[pyclass(frozen, module = "strahl._strahl")]
struct Core {
    world: World,
    pool: rayon::ThreadPool,
    /// The diagonal of the scene's box (0 for an empty scene).
    size: f32,
}

impl Core {
    /// A `NotImplementedError` for point queries on scenes with solids: strahl's closest-point
    /// search covers triangles and spheres only, and would answer as if the solids were not
    /// there.
    fn no_solids(&self, query: &str) -> PyResult<()> {
        let has = |s: &Scene| !s.solids().is_empty();
        let any = match &self.world {
            World::Flat(s, _) => has(s),
            World::Instanced { scene, .. } => scene.objects().iter().any(has),
        };
        if any {
            return Err(pyo3::exceptions::PyNotImplementedError::new_err(format!(
                "{query}: the scene has solids, and closest points are found on triangles and spheres only \
                 (ray queries and compute_occupancy cover solids)"
            )));
        }
        Ok(())
    }

    fn of(world: World, pool: rayon::ThreadPool) -> Self {
        let bounds = match &world {
            World::Flat(s, _) => s.bounds(),
            World::Instanced { scene, .. } => scene.bounds(),
        };
        let size = bounds.map_or(0.0, |(lo, hi)| (hi - lo).length());
        Self { world, pool, size }
    }
}

/// The build configuration of a quality preset (Embree's names), with the watertight triangle
/// test and conservative boxes if asked.
fn build_config(watertight: bool, quality: &str) -> PyResult<BuildConfig> {
    let preset = match quality {
        "fast" => BuildConfig::fast(),
        "medium" => BuildConfig::default(),
        "high" => BuildConfig::high(),
        q => return Err(value_error(format!("quality must be \"fast\", \"medium\" or \"high\", got {q:?}"))),
    };
    Ok(if watertight {
        preset.with_tests(strahl::TriangleTest::Watertight, strahl::BoxTest::Conservative)
    } else {
        preset
    })
}

/// An error reading `path`: `OSError` (errno, message, file name) if it could not be read,
/// `ValueError` otherwise.
fn file_error(e: strahl::Error, path: &std::path::Path) -> PyErr {
    match e {
        strahl::Error::Io { cause, .. } => pyo3::exceptions::PyOSError::new_err((
            cause.raw_os_error().unwrap_or(0),
            cause.to_string(),
            path.display().to_string(),
        )),
        e => value_error(e),
    }
}

/// A pool of `threads` threads (0: one per core).
fn make_pool(threads: usize) -> PyResult<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("strahl-{i}"))
        // Denormals flushed to zero on the pool's own threads (not the interpreter's), as the
        // harness does for both engines: see `strahl::simd::set_flush_denormals`.
        .start_handler(|_| {
            strahl::simd::set_flush_denormals();
        })
        .build()
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start the thread pool: {e}")))
}

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// The rows of a C-contiguous `(n, width)` float32 array as one slice.
fn rows<'a>(a: &'a PyReadonlyArray2<'_, f32>, width: usize, what: &str) -> PyResult<&'a [f32]> {
    if a.shape()[1] != width {
        return Err(value_error(format!("{what} must have shape (n, {width}), got {:?}", a.shape())));
    }
    a.as_slice().map_err(|_| value_error(format!("{what} must be C-contiguous")))
}

/// A 4×4 row-major homogeneous matrix as an affine map, if its last row is `0 0 0 1`.
fn affine_of(m: &[f32]) -> Option<Affine3A> {
    if m[12..16] != [0.0, 0.0, 0.0, 1.0] {
        return None;
    }
    let col = |c: usize| Vec3A::new(m[c], m[4 + c], m[8 + c]);
    Some(Affine3A { matrix3: Mat3A::from_cols(col(0), col(1), col(2)), translation: col(3) })
}

impl World {
    /// The geometry id and user-facing instance id of a hit.
    #[inline]
    fn ids(&self, h: &Hit) -> (u32, u32) {
        match self {
            World::Flat(_, map) if map.is_empty() => (h.geom_id, INVALID_ID),
            World::Flat(_, map) => (map.get(h.geom_id as usize).copied().unwrap_or(INVALID_ID), INVALID_ID),
            World::Instanced { ids, .. } => ids.get(h.inst_id as usize).copied().unwrap_or((INVALID_ID, INVALID_ID)),
        }
    }
}

/// One geometry handed to [`Core::new`], before the build.
enum Part {
    Mesh(TriangleMesh),
    Spheres(SphereSet),
    Solid(strahl::Solid),
}

/// The rays of an `(n, 6)` array (origin, direction) over `(tnear, tfar]`.
fn ray_of(r: &[f32], tnear: f32, tfar: f32) -> Ray {
    Ray::segment(Vec3::new(r[0], r[1], r[2]), Vec3::new(r[3], r[4], r[5]), tnear, tfar)
}

/// How `cast_rays` and `test_occlusions` cut their rays into parallel jobs, and order each job's
/// rays for strahl's streams.
///
/// Rays of an image (`width > 0`) go in strips of 8 rows; a strip whose rays share one origin (a
/// pinhole camera's) is traced in 4×4-tile order (`strahl::camera::tile_order`), so that each
/// packet of 16 is a 4×4 tile and each group of four an 8×8 block walked under one frustum, and
/// its answers are put back in row order. Open3D's `create_rays_pinhole` lists rays row by row:
/// traced in that order, a packet would be a 16×1 strip with a frustum 16 times as wide as high.
/// Other rays go in jobs of [`CHUNK`] in their own order, coherent when they share one origin.
struct Jobs {
    size: usize,
    width: usize,
    /// Tile order of a whole strip, as indices into the strip's rows.
    strip_order: Vec<u32>,
}

impl Jobs {
    fn of(n: usize, width: usize) -> Self {
        if width >= 8 && n.is_multiple_of(width) && n > 0 {
            let strip_order =
                strahl::camera::tile_order(width as u32, 8).iter().map(|&(x, y)| y * width as u32 + x).collect();
            Self { size: 8 * width, width, strip_order }
        } else {
            Self { size: CHUNK, width: 0, strip_order: Vec::new() }
        }
    }

    /// One job's rays as a stream, the row index of each stream entry (if reordered), and how
    /// coherent the rays are; `None` where the rays are better traced one by one: rays whose
    /// origins scatter (see [`scattered`]).
    fn stream(&self, r: &[f32], tnear: f32, tfar: f32, scene_size: f32) -> Option<JobStream<'_>> {
        let n = r.len() / 6;
        let camera = one_origin(r);
        if !camera && scattered(r, scene_size) {
            return None;
        }
        let mut stream = RayStream::with_capacity(n);
        let coherence = if camera { Coherence::Coherent } else { Coherence::Incoherent };
        if camera && self.width > 0 {
            // Whole strips share one order; only the image's last, shorter strip makes its own.
            let order: Cow<'_, [u32]> = if n == self.size {
                Cow::Borrowed(&self.strip_order)
            } else {
                let w = self.width as u32;
                Cow::Owned(
                    strahl::camera::tile_order(w, (n / self.width) as u32).iter().map(|&(x, y)| y * w + x).collect(),
                )
            };
            for &i in order.iter() {
                stream.push(&ray_of(&r[6 * i as usize..6 * i as usize + 6], tnear, tfar));
            }
            return Some((stream, Some(order), coherence));
        }
        for ray in r.chunks_exact(6) {
            stream.push(&ray_of(ray, tnear, tfar));
        }
        Some((stream, None, coherence))
    }
}

/// Whether the origins of runs of 16 consecutive rays spread, on average, over more than 2% of
/// the scene's diagonal. strahl's incoherent streams trace rays as packets of 16 of one direction
/// octant, which pays where neighbours start near each other (bounces off one patch of surface);
/// for rays from anywhere in the scene in any direction, packets cost more than they share.
/// Measured on one thread, 500,000 rays from uniform points in the scene's box in uniform
/// directions (AMD EPYC Zen 3): Sponza 2.20 Mrays/s as a stream, 3.21 one by one; the bunny 4.30
/// and 5.59 (`compare/examples/ray_file_speed.rs`).
fn scattered(r: &[f32], scene_size: f32) -> bool {
    let (mut sum, mut runs) = (0.0f32, 0usize);
    for run in r.chunks(6 * 16) {
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for ray in run.chunks_exact(6) {
            let o = Vec3::new(ray[0], ray[1], ray[2]);
            if o.is_finite() {
                (lo, hi) = (lo.min(o), hi.max(o));
            }
        }
        if lo.cmple(hi).all() {
            sum += (hi - lo).length();
            runs += 1;
        }
    }
    runs > 0 && sum / runs as f32 > 0.02 * scene_size
}

/// One job's rays as a stream, the row of each stream entry where they were reordered, and how
/// coherent they are.
type JobStream<'a> = (RayStream, Option<Cow<'a, [u32]>>, Coherence);

/// Whether a chunk of rays is a camera's: one origin for all.
fn one_origin(rays: &[f32]) -> bool {
    rays.chunks_exact(6).all(|r| r[..3] == rays[..3])
}

fn points_of(p: &[f32]) -> Vec<Vec3> {
    p.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect()
}

type Arr1<'py, T> = Bound<'py, PyArray1<T>>;
type Arr2<'py, T> = Bound<'py, PyArray2<T>>;

/// Per-query hit arrays: t, geometry ids, primitive ids, uvs (n, 2), unit normals (n, 3), instance
/// ids.
type HitArrays<'py> = (Arr1<'py, f32>, Arr1<'py, u32>, Arr1<'py, u32>, Arr2<'py, f32>, Arr2<'py, f32>, Arr1<'py, u32>);

/// Hit fields in flat vectors, before they become numpy arrays.
struct HitColumns {
    t: Vec<f32>,
    geom: Vec<u32>,
    prim: Vec<u32>,
    uv: Vec<f32>,
    normal: Vec<f32>,
    inst: Vec<u32>,
}

impl HitColumns {
    fn misses(n: usize) -> Self {
        Self {
            t: vec![f32::INFINITY; n],
            geom: vec![INVALID_ID; n],
            prim: vec![INVALID_ID; n],
            uv: vec![0.0; 2 * n],
            normal: vec![0.0; 3 * n],
            inst: vec![INVALID_ID; n],
        }
    }

    fn into_arrays(self, py: Python<'_>) -> PyResult<HitArrays<'_>> {
        let n = self.t.len();
        let two = |v: Vec<f32>, w: usize| Array2::from_shape_vec((n, w), v).map_err(value_error);
        Ok((
            Array1::from(self.t).into_pyarray(py),
            Array1::from(self.geom).into_pyarray(py),
            Array1::from(self.prim).into_pyarray(py),
            two(self.uv, 2)?.into_pyarray(py),
            two(self.normal, 3)?.into_pyarray(py),
            Array1::from(self.inst).into_pyarray(py),
        ))
    }
}

#[pymethods]
impl Core {
    /// Builds the scene. `geometries`, geometry ids in list order: `("triangles", vertices (n, 3)
    /// float32, triangles (m, 3) uint32)`, `("spheres", centres (n, 3) float32, radii (n,)
    /// float32)` or `("solid", anything, notation)` with a solid in the scene-file notation
    /// (`strahl::scene_file::parse_solid`, relative OBJ paths from the working directory).
    /// `placements`: `(geometry id, 4×4 row-major transform, instance id)` triples, or an empty
    /// list for a flat scene. `threads`: the pool's size (0: one per core). `watertight`:
    /// the watertight triangle test with the conservative box test, else Möller–Trumbore with the
    /// fast box test. `quality`: the build preset, by Embree's names (`fast`, `medium`, `high`:
    /// spatial splits).
    #[new]
    #[pyo3(signature = (geometries, placements, threads, watertight, quality))]
    fn new(
        py: Python<'_>,
        geometries: Vec<(String, Bound<'_, PyAny>, Bound<'_, PyAny>)>,
        placements: Vec<(u32, PyReadonlyArray2<'_, f32>, u32)>,
        threads: usize,
        watertight: bool,
        quality: &str,
    ) -> PyResult<Self> {
        let mut parts = Vec::with_capacity(geometries.len());
        for (g, (kind, a, b)) in geometries.iter().enumerate() {
            parts.push(match kind.as_str() {
                "triangles" => {
                    let a: PyReadonlyArray2<'_, f32> = a.extract()?;
                    let v = rows(&a, 3, "vertices")?;
                    let f: PyReadonlyArray2<'_, u32> = b.extract()?;
                    if f.shape()[1] != 3 {
                        return Err(value_error(format!("triangles must have shape (m, 3), got {:?}", f.shape())));
                    }
                    let f = f.as_slice().map_err(|_| value_error("triangles must be C-contiguous"))?;
                    Part::Mesh(TriangleMesh::from_slices(format!("geometry {g}"), v, f).map_err(value_error)?)
                }
                "spheres" => {
                    let a: PyReadonlyArray2<'_, f32> = a.extract()?;
                    let c = points_of(rows(&a, 3, "centers")?);
                    let r: PyReadonlyArray1<'_, f32> = b.extract()?;
                    let r = r.as_slice().map_err(|_| value_error("radii must be C-contiguous"))?.to_vec();
                    Part::Spheres(SphereSet::new(format!("geometry {g}"), c, r).map_err(value_error)?)
                }
                "solid" => {
                    let text: String = b.extract()?;
                    Part::Solid(parse_solid(&text).map_err(|e| value_error(format!("geometry {g}: {e}")))?)
                }
                k => return Err(value_error(format!("geometry {g}: unknown kind {k:?}"))),
            });
        }
        let mut instances = Vec::with_capacity(placements.len());
        let mut ids = Vec::with_capacity(placements.len());
        for (g, m, id) in &placements {
            if *g as usize >= parts.len() {
                return Err(value_error(format!("no geometry {g}")));
            }
            let m = m.as_slice().map_err(|_| value_error("transforms must be C-contiguous"))?;
            let t = (m.len() == 16).then(|| affine_of(m)).flatten().ok_or_else(|| {
                value_error(format!("the transform of instance {id} is not a 4×4 affine matrix (last row 0 0 0 1)"))
            })?;
            instances.push(Instance::new(*g as usize, t));
            ids.push((*g, *id));
        }
        let pool = make_pool(threads)?;
        let cfg = build_config(watertight, quality)?;
        let flat = placements.is_empty();
        let world = py.detach(|| {
            pool.install(|| -> strahl::Result<World> {
                if flat {
                    // strahl numbers a scene's meshes first, then its sphere sets, then its solids.
                    let (mut meshes, mut spheres, mut solids) = (vec![], vec![], vec![]);
                    let mut ids: [Vec<u32>; 3] = Default::default();
                    for (g, p) in parts.into_iter().enumerate() {
                        let g = g as u32;
                        match p {
                            Part::Mesh(m) => {
                                meshes.push(m);
                                ids[0].push(g);
                            }
                            Part::Spheres(s) => {
                                spheres.push(s);
                                ids[1].push(g);
                            }
                            Part::Solid(s) => {
                                solids.push(s);
                                ids[2].push(g);
                            }
                        }
                    }
                    let map = ids.concat();
                    let in_order = map.iter().enumerate().all(|(i, &g)| i as u32 == g);
                    let map = if in_order { Vec::new() } else { map };
                    Ok(World::Flat(Scene::build_with_solids(meshes, spheres, solids, &cfg)?, map))
                } else {
                    let objects = parts
                        .into_par_iter()
                        .map(|p| match p {
                            Part::Mesh(m) => Scene::build(vec![m], &cfg),
                            Part::Spheres(s) => Scene::build_with_spheres(Vec::new(), vec![s], &cfg),
                            Part::Solid(s) => Scene::build_with_solids(Vec::new(), Vec::new(), vec![s], &cfg),
                        })
                        .collect::<strahl::Result<Vec<Scene>>>()?;
                    Ok(World::Instanced { scene: InstancedScene::from_scenes(objects, instances)?, ids })
                }
            })
        });
        Ok(Self::of(world.map_err(value_error)?, pool))
    }

    /// The scene of a scene file (`data/README.md`): its meshes, analytic spheres and solids
    /// (CSG, superquadrics, blobs, closed meshes), placed by its instances. A hit reports as
    /// geometry id the index of its instance's `[mesh.*]` table (in name order) and as instance
    /// id the index of its `[[instance]]`. A file that cannot be read is an `OSError`; one that
    /// is malformed or describes bad geometry a `ValueError` naming the entry.
    #[staticmethod]
    #[pyo3(signature = (path, threads, watertight, quality))]
    fn from_scene_file(
        py: Python<'_>,
        path: std::path::PathBuf,
        threads: usize,
        watertight: bool,
        quality: &str,
    ) -> PyResult<Self> {
        let pool = make_pool(threads)?;
        let cfg = build_config(watertight, quality)?;
        let built = py.detach(|| {
            pool.install(|| -> strahl::Result<(InstancedScene, Vec<(u32, u32)>)> {
                let file = strahl::SceneFile::read(&path)?;
                let scene = file.build(&cfg)?;
                let ids = file.instances.iter().enumerate().map(|(i, inst)| (inst.object as u32, i as u32)).collect();
                Ok((scene, ids))
            })
        });
        let (scene, ids) = built.map_err(|e| file_error(e, &path))?;
        Ok(Self::of(World::Instanced { scene, ids }, pool))
    }

    /// The built scene as bytes, for pickling: `(instanced, bytes, instance ids)`; see
    /// `strahl::Scene::to_bytes`.
    fn serialize<'py>(&self, py: Python<'py>) -> (bool, Bound<'py, pyo3::types::PyBytes>, Vec<(u32, u32)>) {
        match &self.world {
            World::Flat(s, map) => {
                (false, pyo3::types::PyBytes::new(py, &s.to_bytes()), map.iter().map(|&g| (g, INVALID_ID)).collect())
            }
            World::Instanced { scene, ids } => (true, pyo3::types::PyBytes::new(py, &scene.to_bytes()), ids.clone()),
        }
    }

    /// A scene from [`serialize`](Self::serialize)'s parts, without rebuilding its BVHs (a
    /// two-level scene rebuilds its top level); bytes that are not such a scene are a
    /// `ValueError`.
    #[staticmethod]
    fn deserialize(
        py: Python<'_>,
        instanced: bool,
        bytes: &[u8],
        ids: Vec<(u32, u32)>,
        threads: usize,
    ) -> PyResult<Self> {
        let pool = make_pool(threads)?;
        let world = py.detach(|| {
            pool.install(|| -> strahl::Result<World> {
                Ok(if instanced {
                    World::Instanced { scene: InstancedScene::from_bytes(bytes)?, ids }
                } else {
                    // A flat scene's ids are the user's geometry id of each of its geometries.
                    World::Flat(Scene::from_bytes(bytes)?, ids.iter().map(|&(g, _)| g).collect())
                })
            })
        });
        let world = world.map_err(value_error)?;
        match &world {
            World::Instanced { scene, ids } if scene.instances().len() != ids.len() => {
                return Err(value_error(format!(
                    "{} instance ids for {} instances",
                    ids.len(),
                    scene.instances().len()
                )));
            }
            World::Flat(scene, map)
                if !map.is_empty()
                    && map.len() != scene.meshes().len() + scene.spheres().len() + scene.solids().len() =>
            {
                let n = scene.meshes().len() + scene.spheres().len() + scene.solids().len();
                return Err(value_error(format!("{} geometry ids for {n} geometries", map.len())));
            }
            _ => {}
        }
        Ok(Self::of(world, pool))
    }

    /// Threads of the scene's pool.
    #[getter]
    fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }

    /// Triangles in the BVH (the hittable ones; an instanced geometry counts once).
    #[getter]
    fn triangles(&self) -> usize {
        match &self.world {
            World::Flat(s, _) => s.stats().triangles,
            World::Instanced { scene, .. } => scene.stats().unique_triangles,
        }
    }

    /// Analytic spheres (an instanced geometry counts once).
    #[getter]
    fn spheres(&self) -> usize {
        let count = |s: &Scene| s.spheres().iter().map(SphereSet::len).sum::<usize>();
        match &self.world {
            World::Flat(s, _) => count(s),
            World::Instanced { scene, .. } => scene.objects().iter().map(count).sum(),
        }
    }

    /// Closest hits of `(n, 6)` rays over `(tnear, tfar]`. `width`: the image width when the
    /// rays are an image's rows (row-major, `n` a multiple of it), else 0 (see [`Jobs`]).
    fn cast_rays<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        tnear: f32,
        tfar: f32,
        width: usize,
    ) -> PyResult<HitArrays<'py>> {
        let r = rows(&rays, 6, "rays")?;
        let n = r.len() / 6;
        let jobs = Jobs::of(n, width);
        let mut out = HitColumns::misses(n);
        py.detach(|| {
            self.pool.install(|| {
                let HitColumns { t, geom, prim, uv, normal, inst } = &mut out;
                let c = jobs.size;
                (
                    r.par_chunks(6 * c),
                    (t.par_chunks_mut(c), geom.par_chunks_mut(c), prim.par_chunks_mut(c)),
                    (uv.par_chunks_mut(2 * c), normal.par_chunks_mut(3 * c), inst.par_chunks_mut(c)),
                )
                    .into_par_iter()
                    .with_max_len(1)
                    .for_each(|(r, (t, geom, prim), (uv, normal, inst))| {
                        let mut hits = HitStream::misses(0);
                        let order = match jobs.stream(r, tnear, tfar, self.size) {
                            Some((stream, order, coherence)) => {
                                on_world!(&self.world, q => q.intersect_stream(&stream, &mut hits, coherence));
                                order
                            }
                            None => {
                                hits.reset(t.len());
                                for (k, ray) in r.chunks_exact(6).enumerate() {
                                    hits.set(k, on_world!(&self.world, q => q.intersect(&ray_of(ray, tnear, tfar))));
                                }
                                None
                            }
                        };
                        for k in 0..t.len() {
                            let i = order.as_ref().map_or(k, |o| o[k] as usize);
                            if let Some(h) = hits.get(k) {
                                let (g, k) = self.world.ids(&h);
                                t[i] = h.t;
                                (geom[i], prim[i], inst[i]) = (g, h.prim_id, k);
                                uv[2 * i..2 * i + 2].copy_from_slice(&[h.u, h.v]);
                                normal[3 * i..3 * i + 3].copy_from_slice(&h.ng.normalize_or_zero().to_array());
                            }
                        }
                    });
            })
        });
        out.into_arrays(py)
    }

    /// Whether anything lies on each of `(n, 6)` rays in `(tnear, tfar]` (`width` as for
    /// [`cast_rays`](Self::cast_rays)).
    fn test_occlusions<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        tnear: f32,
        tfar: f32,
        width: usize,
    ) -> PyResult<Arr1<'py, bool>> {
        let r = rows(&rays, 6, "rays")?;
        let jobs = Jobs::of(r.len() / 6, width);
        let mut out = vec![false; r.len() / 6];
        py.detach(|| {
            self.pool.install(|| {
                let c = jobs.size;
                out.par_chunks_mut(c).zip(r.par_chunks(6 * c)).with_max_len(1).for_each(|(o, r)| {
                    let Some((stream, order, coherence)) = jobs.stream(r, tnear, tfar, self.size) else {
                        for (o, ray) in o.iter_mut().zip(r.chunks_exact(6)) {
                            *o = on_world!(&self.world, q => q.occluded(&ray_of(ray, tnear, tfar)));
                        }
                        return;
                    };
                    let mut occ = Vec::new();
                    on_world!(&self.world, q => q.occluded_stream(&stream, &mut occ, coherence));
                    match &order {
                        Some(order) => order.iter().zip(&occ).for_each(|(&i, &b)| o[i as usize] = b),
                        None => o.copy_from_slice(&occ),
                    }
                });
            })
        });
        Ok(Array1::from(out).into_pyarray(py))
    }

    /// Surface crossings of each of `(n, 6)` rays in `(tnear, tfar]` (shared edges and vertices
    /// counted once).
    fn count_intersections<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        tnear: f32,
        tfar: f32,
    ) -> PyResult<Arr1<'py, u32>> {
        let r = rows(&rays, 6, "rays")?;
        let rays: Vec<Ray> = r.chunks_exact(6).map(|x| ray_of(x, tnear, tfar)).collect();
        let mut out = vec![0u32; rays.len()];
        py.detach(|| self.pool.install(|| on_world!(&self.world, q => batch::count_hits(q, &rays, true, &mut out))));
        Ok(Array1::from(out).into_pyarray(py))
    }

    /// Every crossing of each of `(n, 6)` rays, nearest first: `(ray_splits (n + 1), ray_ids,
    /// t_hit, geometry_ids, primitive_ids, primitive_uvs, instance_ids)`.
    #[allow(clippy::type_complexity)]
    fn list_intersections<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        tnear: f32,
        tfar: f32,
    ) -> PyResult<(
        Arr1<'py, u64>,
        Arr1<'py, u32>,
        Arr1<'py, f32>,
        Arr1<'py, u32>,
        Arr1<'py, u32>,
        Arr2<'py, f32>,
        Arr1<'py, u32>,
    )> {
        let r = rows(&rays, 6, "rays")?;
        let rays: Vec<Ray> = r.chunks_exact(6).map(|x| ray_of(x, tnear, tfar)).collect();
        let lists = py.detach(|| self.pool.install(|| on_world!(&self.world, q => batch::hit_lists(q, &rays, true))));
        let m = lists.hits.len();
        let mut ray_ids = Vec::with_capacity(m);
        for (i, w) in lists.splits.windows(2).enumerate() {
            ray_ids.extend(std::iter::repeat_n(i as u32, w[1] - w[0]));
        }
        let ids: Vec<(u32, u32)> = lists.hits.iter().map(|h| self.world.ids(h)).collect();
        let uv: Vec<f32> = lists.hits.iter().flat_map(|h| [h.u, h.v]).collect();
        Ok((
            Array1::from_iter(lists.splits.iter().map(|&s| s as u64)).into_pyarray(py),
            Array1::from(ray_ids).into_pyarray(py),
            Array1::from_iter(lists.hits.iter().map(|h| h.t)).into_pyarray(py),
            Array1::from_iter(ids.iter().map(|i| i.0)).into_pyarray(py),
            Array1::from_iter(lists.hits.iter().map(|h| h.prim_id)).into_pyarray(py),
            Array2::from_shape_vec((m, 2), uv).map_err(value_error)?.into_pyarray(py),
            Array1::from_iter(ids.iter().map(|i| i.1)).into_pyarray(py),
        ))
    }

    /// The surface point nearest to each of `(n, 3)` points: `(points (n, 3), distance,
    /// geometry_ids, primitive_ids, primitive_uvs, primitive_normals, instance_ids)`. Points that
    /// are not finite, and every point of an empty scene, get NaN points, infinite (NaN for
    /// points that are not finite) distances and invalid ids.
    #[allow(clippy::type_complexity)]
    fn compute_closest_points<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<(Arr2<'py, f32>, HitArrays<'py>)> {
        self.no_solids("compute_closest_points")?;
        let p = points_of(rows(&points, 3, "query points")?);
        let found = py.detach(|| self.pool.install(|| on_world!(&self.world, q => batch::closest_points(q, &p))));
        let n = p.len();
        let mut cols = HitColumns::misses(n);
        let mut at = vec![f32::NAN; 3 * n];
        for (i, c) in found.iter().enumerate() {
            let Some(c) = c else {
                cols.t[i] = if p[i].is_finite() { f32::INFINITY } else { f32::NAN };
                continue;
            };
            let (g, k) = self.world.ids(&Hit {
                t: 0.0,
                u: 0.0,
                v: 0.0,
                ng: c.ng,
                prim_id: c.prim_id,
                geom_id: c.geom_id,
                inst_id: c.inst_id,
            });
            at[3 * i..3 * i + 3].copy_from_slice(&c.point.to_array());
            cols.t[i] = c.distance;
            (cols.geom[i], cols.prim[i], cols.inst[i]) = (g, c.prim_id, k);
            cols.uv[2 * i..2 * i + 2].copy_from_slice(&[c.u, c.v]);
            cols.normal[3 * i..3 * i + 3].copy_from_slice(&c.ng.normalize_or_zero().to_array());
        }
        Ok((Array2::from_shape_vec((n, 3), at).map_err(value_error)?.into_pyarray(py), cols.into_arrays(py)?))
    }

    /// Signed distance of each of `(n, 3)` points: negative inside, by the majority of `votes`
    /// rays' crossing parities.
    fn compute_signed_distance<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        votes: usize,
    ) -> PyResult<Arr1<'py, f32>> {
        self.no_solids("compute_signed_distance")?;
        let p = points_of(rows(&points, 3, "query points")?);
        let d = py.detach(|| self.pool.install(|| on_world!(&self.world, q => batch::signed_distances(q, &p, votes))));
        Ok(Array1::from(d).into_pyarray(py))
    }

    /// Whether each of `(n, 3)` points lies inside the closed surface (`votes` as for
    /// [`compute_signed_distance`](Self::compute_signed_distance)).
    fn compute_occupancy<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        votes: usize,
    ) -> PyResult<Arr1<'py, bool>> {
        let p = points_of(rows(&points, 3, "query points")?);
        let d = py.detach(|| self.pool.install(|| on_world!(&self.world, q => batch::contains(q, &p, votes))));
        Ok(Array1::from(d).into_pyarray(py))
    }
}

/// The triangle meshes of an OBJ file (one per object or group, polygons fanned into triangles),
/// as `(vertices (n, 3) float32, triangles (m, 3) uint32)` pairs. A file that cannot be read is an
/// `OSError`; a malformed one (the error names the line) a `ValueError`.
#[pyfunction]
fn load_obj<'py>(py: Python<'py>, path: std::path::PathBuf) -> PyResult<Vec<(Arr2<'py, f32>, Arr2<'py, u32>)>> {
    let meshes = py.detach(|| strahl::load_obj(&path)).map_err(|e| file_error(e, &path))?;
    meshes
        .iter()
        .map(|m| {
            let v: Vec<f32> = m.positions().iter().flat_map(|p| p.to_array()).collect();
            let f: Vec<u32> = m.indices().iter().flatten().copied().collect();
            Ok((
                Array2::from_shape_vec((m.positions().len(), 3), v).map_err(value_error)?.into_pyarray(py),
                Array2::from_shape_vec((m.indices().len(), 3), f).map_err(value_error)?.into_pyarray(py),
            ))
        })
        .collect()
}

/// Checks a solid in the scene-file notation (`strahl::scene_file::parse_solid`, relative OBJ
/// paths from the working directory): a `ValueError` naming the node if it is malformed or
/// describes a bad solid.
#[pyfunction]
fn check_solid(py: Python<'_>, text: &str) -> PyResult<()> {
    py.detach(|| parse_solid(text)).map(|_| ()).map_err(value_error)
}

/// A solid in the scene-file notation, relative OBJ paths from the working directory; the error
/// says what is wrong without naming a scene file (there is none).
fn parse_solid(text: &str) -> Result<strahl::Solid, String> {
    strahl::scene_file::parse_solid(text, std::path::Path::new(".")).map_err(|e| match e {
        strahl::Error::SceneFile { message, .. } => format!("bad solid: {message}"),
        e => e.to_string(),
    })
}

/// A scene file's render set-up: its pool, the file, its camera and its `[render]` settings with
/// the overrides given (`None` keeps the file's), checked.
#[allow(clippy::type_complexity)]
fn render_setup(
    py: Python<'_>,
    path: &std::path::Path,
    overrides: [Option<u32>; 4],
    bailout: Option<f32>,
    threads: usize,
) -> PyResult<(rayon::ThreadPool, strahl::SceneFile, strahl::render::RenderCamera, strahl::render::Settings)> {
    let pool = make_pool(threads)?;
    let file = py.detach(|| strahl::SceneFile::read(path)).map_err(|e| file_error(e, path))?;
    let camera = file
        .camera
        .as_ref()
        .and_then(|c| c.render_camera())
        .ok_or_else(|| value_error(format!("{}: the scene file has no [camera]", path.display())))?;
    let mut settings = file.render.settings;
    let [width, height, spp, max_depth] = overrides;
    settings.width = width.unwrap_or(settings.width);
    settings.height = height.unwrap_or(settings.height);
    settings.spp = spp.unwrap_or(settings.spp);
    settings.max_depth = max_depth.unwrap_or(settings.max_depth);
    settings.bailout = bailout.unwrap_or(settings.bailout);
    settings.check().map_err(value_error)?;
    Ok((pool, file, camera, settings))
}

/// Loads a scene file's meshes and builds its scene and shading world, on the current pool;
/// `f` gets the renderer.
fn with_renderer<T>(
    file: &strahl::SceneFile,
    camera: strahl::render::RenderCamera,
    settings: strahl::render::Settings,
    f: impl FnOnce(&strahl::render::Renderer<'_, InstancedScene>) -> strahl::Result<T>,
) -> strahl::Result<T> {
    let objects = file.load_objects()?;
    let world = file.world(&objects)?;
    let scene = file.build_from(objects, &BuildConfig::default())?;
    f(&strahl::render::Renderer { query: &scene, world: &world, camera, settings })
}

/// Renders a scene file with strahl's renderer (the seeds' recursive ray tracer, `strahl
/// render`): its camera, lights and materials, the file's `[render]` settings overridden by the
/// arguments given. Returns the linear RGB image `(height, width, 3)` float32 (rows from the top),
/// its 8-bit sRGB form as `strahl render` writes PNGs, and the statistics. A file that cannot be
/// read is an `OSError`; a malformed one, one without a `[camera]`, or settings out of range a
/// `ValueError`.
#[pyfunction]
#[pyo3(signature = (path, width, height, spp, max_depth, bailout, threads))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn render<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
    width: Option<u32>,
    height: Option<u32>,
    spp: Option<u32>,
    max_depth: Option<u32>,
    bailout: Option<f32>,
    threads: usize,
) -> PyResult<(Bound<'py, PyArray3<f32>>, Bound<'py, PyArray3<u8>>, Bound<'py, pyo3::types::PyDict>)> {
    let (pool, file, camera, settings) = render_setup(py, &path, [width, height, spp, max_depth], bailout, threads)?;
    let started = std::time::Instant::now();
    let rendered = py.detach(|| {
        pool.install(|| {
            with_renderer(&file, camera, settings, |r| {
                let build_seconds = started.elapsed().as_secs_f64();
                let (image, stats) = r.render(&|_| {})?;
                Ok((image, stats, build_seconds))
            })
        })
    });
    let (image, stats, build_seconds) = rendered.map_err(|e| file_error(e, &path))?;
    let (h, w) = (image.height as usize, image.width as usize);
    let linear: Vec<f32> = image.pixels.iter().flat_map(|p| p.to_array()).collect();
    let linear = Array3::from_shape_vec((h, w, 3), linear).map_err(value_error)?.into_pyarray(py);
    let srgb = Array3::from_shape_vec((h, w, 3), image.to_srgb8()).map_err(value_error)?.into_pyarray(py);
    let d = pyo3::types::PyDict::new(py);
    let kinds = ["primary", "shadow", "reflected", "refracted"];
    let rays = pyo3::types::PyDict::new(py);
    for (k, n) in kinds.iter().zip(stats.rays) {
        rays.set_item(k, n)?;
    }
    d.set_item("rays", rays)?;
    d.set_item("seconds", stats.seconds)?;
    d.set_item("build_seconds", build_seconds)?;
    d.set_item("query_share", stats.query_share())?;
    d.set_item("threads", stats.threads)?;
    d.set_item("width", settings.width)?;
    d.set_item("height", settings.height)?;
    d.set_item("spp", settings.spp)?;
    d.set_item("max_depth", settings.max_depth)?;
    d.set_item("cut_by_weight", stats.counts_cut_by_weight)?;
    d.set_item("cut_by_depth", stats.counts_cut_by_depth)?;
    Ok((linear, srgb, d))
}

/// The ray tree of pixel `(x, y)` of a scene file's image (its first sample, traced depth first
/// with the renderer's optics: `strahl render --ray-tree`): one dict per ray, parents first
/// (`parent`, `kind`, `depth`, `origin`, `dir`, `t`, `tfar`, `weight`), and the pixel's colour.
/// Errors as for [`render`], and a `ValueError` for a pixel outside the image.
#[pyfunction]
#[pyo3(signature = (path, x, y, width, height, max_depth, bailout))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn ray_tree<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
    x: u32,
    y: u32,
    width: Option<u32>,
    height: Option<u32>,
    max_depth: Option<u32>,
    bailout: Option<f32>,
) -> PyResult<(Vec<Bound<'py, pyo3::types::PyDict>>, [f32; 3])> {
    let (pool, file, camera, settings) = render_setup(py, &path, [width, height, None, max_depth], bailout, 1)?;
    let traced = py.detach(|| pool.install(|| with_renderer(&file, camera, settings, |r| r.ray_tree(x, y))));
    let (nodes, colour) = traced.map_err(|e| file_error(e, &path))?;
    let kind = |k: strahl::render::RayKind| match k {
        strahl::render::RayKind::Primary => "primary",
        strahl::render::RayKind::Shadow => "shadow",
        strahl::render::RayKind::Reflected => "reflected",
        strahl::render::RayKind::Refracted => "refracted",
    };
    let dicts = nodes
        .iter()
        .map(|n| {
            let d = pyo3::types::PyDict::new(py);
            d.set_item("parent", n.parent)?;
            d.set_item("kind", kind(n.kind))?;
            d.set_item("depth", n.depth)?;
            d.set_item("origin", n.origin)?;
            d.set_item("dir", n.dir)?;
            d.set_item("t", n.t)?;
            d.set_item("tfar", n.tfar)?;
            d.set_item("weight", n.weight)?;
            Ok(d)
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok((dicts, colour.to_array()))
}

/// The `strahl._strahl` module.
#[pymodule]
fn _strahl(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Core>()?;
    m.add_function(wrap_pyfunction!(load_obj, m)?)?;
    m.add_function(wrap_pyfunction!(check_solid, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(ray_tree, m)?)?;
    m.add("INVALID_ID", INVALID_ID)?;
    Ok(())
}
