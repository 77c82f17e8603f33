//! Bindings to the subset of Embree 3's C API the harness uses, and a safe wrapper around them.
//!
//! Layouts and constants are transcribed from Debian's `libembree-dev` 3.13.5 headers
//! (`/usr/include/embree3/rtcore_*.h`, `RTC_MAX_INSTANCE_LEVEL_COUNT = 1`, `RTC_MIN_WIDTH = 0`) and
//! checked by the size tests at the end. This is the only file of the harness with `unsafe` code.
#![allow(unsafe_code, non_camel_case_types, non_snake_case, dead_code)]

use std::ffi::{CString, c_char, c_uint, c_void};
use std::time::Instant;

use strahl::TriangleMesh;

type RTCDevice = *mut c_void;
type RTCScene = *mut c_void;
type RTCGeometry = *mut c_void;

pub const RTC_INVALID_GEOMETRY_ID: u32 = u32::MAX;
const RTC_GEOMETRY_TYPE_TRIANGLE: c_uint = 0;
const RTC_GEOMETRY_TYPE_INSTANCE: c_uint = 121;
const RTC_GEOMETRY_TYPE_SPHERE_POINT: c_uint = 50;
const RTC_GEOMETRY_TYPE_USER: c_uint = 120;
const RTC_BUFFER_TYPE_INDEX: c_uint = 0;
const RTC_BUFFER_TYPE_VERTEX: c_uint = 1;
const RTC_FORMAT_UINT3: c_uint = 0x5003;
const RTC_FORMAT_FLOAT3: c_uint = 0x9003;
const RTC_FORMAT_FLOAT4: c_uint = 0x9004;
const RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR: c_uint = 0x9234;
const RTC_SCENE_FLAG_ROBUST: c_uint = 1 << 2;
const RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT: c_uint = 0;
const RTC_INTERSECT_CONTEXT_FLAG_COHERENT: c_uint = 1;

#[repr(C, align(16))]
#[derive(Clone, Copy, Default, Debug)]
pub struct RTCRay {
    pub org_x: f32,
    pub org_y: f32,
    pub org_z: f32,
    pub tnear: f32,
    pub dir_x: f32,
    pub dir_y: f32,
    pub dir_z: f32,
    pub time: f32,
    pub tfar: f32,
    pub mask: u32,
    pub id: u32,
    pub flags: u32,
}

#[repr(C, align(16))]
#[derive(Clone, Copy, Default, Debug)]
pub struct RTCHit {
    pub Ng_x: f32,
    pub Ng_y: f32,
    pub Ng_z: f32,
    pub u: f32,
    pub v: f32,
    pub primID: u32,
    pub geomID: u32,
    pub instID: [u32; 1],
}

#[repr(C)]
#[derive(Clone, Copy, Default, Debug)]
pub struct RTCRayHit {
    pub ray: RTCRay,
    pub hit: RTCHit,
}

#[repr(C, align(64))]
#[derive(Clone, Copy, Debug)]
pub struct RTCRay16 {
    pub org_x: [f32; 16],
    pub org_y: [f32; 16],
    pub org_z: [f32; 16],
    pub tnear: [f32; 16],
    pub dir_x: [f32; 16],
    pub dir_y: [f32; 16],
    pub dir_z: [f32; 16],
    pub time: [f32; 16],
    pub tfar: [f32; 16],
    pub mask: [u32; 16],
    pub id: [u32; 16],
    pub flags: [u32; 16],
}

#[repr(C, align(64))]
#[derive(Clone, Copy, Debug)]
pub struct RTCHit16 {
    pub Ng_x: [f32; 16],
    pub Ng_y: [f32; 16],
    pub Ng_z: [f32; 16],
    pub u: [f32; 16],
    pub v: [f32; 16],
    pub primID: [u32; 16],
    pub geomID: [u32; 16],
    pub instID: [[u32; 16]; 1],
}

#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RTCRayHit16 {
    pub ray: RTCRay16,
    pub hit: RTCHit16,
}

/// `struct RTCIntersectContext` for `RTC_MAX_INSTANCE_LEVEL_COUNT == 1` and `RTC_MIN_WIDTH == 0`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct RTCIntersectContext {
    flags: c_uint,
    filter: Option<unsafe extern "C" fn(*const c_void)>,
    instID: [c_uint; 1],
}

impl RTCIntersectContext {
    /// `rtcInitIntersectContext`, an inline function of the header, reimplemented.
    fn new(coherent: bool) -> Self {
        Self {
            flags: if coherent { RTC_INTERSECT_CONTEXT_FLAG_COHERENT } else { RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT },
            filter: None,
            instID: [RTC_INVALID_GEOMETRY_ID],
        }
    }
}

/// `struct RTCBounds`.
#[repr(C, align(16))]
struct RTCBounds {
    lower: [f32; 3],
    align0: f32,
    upper: [f32; 3],
    align1: f32,
}

/// `struct RTCBoundsFunctionArguments`.
#[repr(C)]
struct RTCBoundsFunctionArguments {
    geometryUserPtr: *mut c_void,
    primID: c_uint,
    timeStep: c_uint,
    bounds_o: *mut RTCBounds,
}

/// `struct RTCIntersectFunctionNArguments`; `rayhit` is an `RTCRayHitN`: `N` lanes of each ray
/// field, then of each hit field (`rtcore_ray.h`'s `RTCRayN_*`/`RTCHitN_*` accessors).
#[repr(C)]
struct RTCIntersectFunctionNArguments {
    valid: *mut i32,
    geometryUserPtr: *mut c_void,
    primID: c_uint,
    context: *mut RTCIntersectContext,
    rayhit: *mut f32,
    N: c_uint,
    geomID: c_uint,
}

/// `struct RTCOccludedFunctionNArguments`; `ray` is an `RTCRayN`.
#[repr(C)]
struct RTCOccludedFunctionNArguments {
    valid: *mut i32,
    geometryUserPtr: *mut c_void,
    primID: c_uint,
    context: *mut RTCIntersectContext,
    ray: *mut f32,
    N: c_uint,
    geomID: c_uint,
}

#[link(name = "embree3")]
unsafe extern "C" {
    fn rtcNewDevice(config: *const c_char) -> RTCDevice;
    fn rtcReleaseDevice(device: RTCDevice);
    fn rtcGetDeviceError(device: RTCDevice) -> c_uint;
    fn rtcNewScene(device: RTCDevice) -> RTCScene;
    fn rtcReleaseScene(scene: RTCScene);
    fn rtcSetSceneBuildQuality(scene: RTCScene, quality: c_uint);
    fn rtcSetSceneFlags(scene: RTCScene, flags: c_uint);
    fn rtcCommitScene(scene: RTCScene);
    fn rtcNewGeometry(device: RTCDevice, kind: c_uint) -> RTCGeometry;
    fn rtcReleaseGeometry(geometry: RTCGeometry);
    fn rtcCommitGeometry(geometry: RTCGeometry);
    fn rtcAttachGeometryByID(scene: RTCScene, geometry: RTCGeometry, id: c_uint);
    fn rtcSetGeometryInstancedScene(geometry: RTCGeometry, scene: RTCScene);
    fn rtcSetGeometryTransform(geometry: RTCGeometry, time_step: c_uint, format: c_uint, xfm: *const c_void);
    fn rtcSetNewGeometryBuffer(
        geometry: RTCGeometry,
        kind: c_uint,
        slot: c_uint,
        format: c_uint,
        byte_stride: usize,
        item_count: usize,
    ) -> *mut c_void;
    fn rtcSetGeometryUserPrimitiveCount(geometry: RTCGeometry, count: c_uint);
    fn rtcSetGeometryUserData(geometry: RTCGeometry, ptr: *mut c_void);
    fn rtcSetGeometryBoundsFunction(
        geometry: RTCGeometry,
        bounds: unsafe extern "C" fn(*const RTCBoundsFunctionArguments),
        user: *mut c_void,
    );
    fn rtcSetGeometryIntersectFunction(
        geometry: RTCGeometry,
        f: unsafe extern "C" fn(*const RTCIntersectFunctionNArguments),
    );
    fn rtcSetGeometryOccludedFunction(
        geometry: RTCGeometry,
        f: unsafe extern "C" fn(*const RTCOccludedFunctionNArguments),
    );
    fn rtcIntersect1(scene: RTCScene, context: *mut RTCIntersectContext, rayhit: *mut RTCRayHit);
    fn rtcOccluded1(scene: RTCScene, context: *mut RTCIntersectContext, ray: *mut RTCRay);
    fn rtcIntersect16(valid: *const i32, scene: RTCScene, context: *mut RTCIntersectContext, rayhit: *mut RTCRayHit16);
    fn rtcOccluded16(valid: *const i32, scene: RTCScene, context: *mut RTCIntersectContext, ray: *mut RTCRay16);
    fn rtcIntersect1M(
        scene: RTCScene,
        context: *mut RTCIntersectContext,
        rayhit: *mut RTCRayHit,
        m: c_uint,
        byte_stride: usize,
    );
    fn rtcOccluded1M(
        scene: RTCScene,
        context: *mut RTCIntersectContext,
        ray: *mut RTCRay,
        m: c_uint,
        byte_stride: usize,
    );
}

/// Embree's build quality levels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quality {
    Low = 0,
    Medium = 1,
    High = 2,
}

/// An Embree device.
pub struct Device {
    raw: RTCDevice,
}

// SAFETY: Embree devices are documented as thread-safe; the handle is only used through Embree.
unsafe impl Send for Device {}
// SAFETY: as above; all Embree calls taking a device are thread-safe.
unsafe impl Sync for Device {}

impl Device {
    /// A device with Embree's configuration string, e.g. `"threads=2"`. The environment variable
    /// `EMBREE_ISA` (`sse2`, `sse4.2`, `avx`, `avx2`, `avx512`) adds Embree's `isa=` setting, so
    /// that Embree can be held to the instruction set strahl is forced to (`STRAHL_ISA`).
    pub fn new(config: &str) -> anyhow::Result<Self> {
        let config = match std::env::var("EMBREE_ISA") {
            Ok(isa) if !isa.trim().is_empty() => format!("{config},isa={}", isa.trim()),
            _ => config.to_string(),
        };
        let c = CString::new(config.as_str())?;
        // SAFETY: `c` is a valid NUL-terminated string that outlives the call.
        let raw = unsafe { rtcNewDevice(c.as_ptr()) };
        if raw.is_null() {
            anyhow::bail!("rtcNewDevice({config:?}) failed");
        }
        Ok(Self { raw })
    }

    fn check(&self, what: &str) -> anyhow::Result<()> {
        // SAFETY: `self.raw` is a live device.
        let e = unsafe { rtcGetDeviceError(self.raw) };
        if e != 0 {
            anyhow::bail!("Embree error {e} in {what}");
        }
        Ok(())
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: the device was created by rtcNewDevice and is released once; scenes hold their
        // own reference (Embree reference-counts devices).
        unsafe { rtcReleaseDevice(self.raw) }
    }
}

/// A committed Embree scene of triangle meshes, geometry ids equal to mesh indices; or of
/// instances (geometry ids equal to instance indices) of the object scenes it keeps alive.
pub struct Scene {
    raw: RTCScene,
    /// Wall time of the commit (the BVH build); for instances, of all commits.
    pub build_ms: f64,
    objects: Vec<Scene>,
    /// The solids its user geometries point to, kept alive with the scene (the vector is never
    /// resized after they are attached, so its elements stay where Embree was told they are).
    solids: Vec<strahl::shapes::PreparedSolid>,
}

// SAFETY: a committed scene is immutable; Embree documents rtcIntersect*/rtcOccluded* on a committed
// scene as safe to call from many threads at once.
unsafe impl Send for Scene {}
// SAFETY: as above.
unsafe impl Sync for Scene {}

impl Scene {
    /// Builds `meshes` with the given quality; `robust` sets `RTC_SCENE_FLAG_ROBUST`.
    pub fn build(device: &Device, meshes: &[TriangleMesh], quality: Quality, robust: bool) -> anyhow::Result<Self> {
        Self::build_mixed(device, meshes, &[], &[], quality, robust)
    }

    /// Builds `meshes`, then sphere sets (`RTC_GEOMETRY_TYPE_SPHERE_POINT`), then solids
    /// (`RTC_GEOMETRY_TYPE_USER`, one primitive each, whose callbacks run strahl's own solid
    /// intersection, [`strahl::shapes::PreparedSolid`]) into one scene, geometry ids numbered as
    /// strahl numbers them.
    pub fn build_mixed(
        device: &Device,
        meshes: &[TriangleMesh],
        spheres: &[strahl::SphereSet],
        solids: &[strahl::shapes::PreparedSolid],
        quality: Quality,
        robust: bool,
    ) -> anyhow::Result<Self> {
        Self::build_all(device, meshes, spheres, solids, quality, robust, false)
    }

    /// Builds `solids` alone as the primitives of one `RTC_GEOMETRY_TYPE_USER` geometry (id 0;
    /// hits report the solid's index as their geometry id, as [`build_mixed`](Self::build_mixed)'s
    /// one geometry per solid does): the other layout a user of Embree might choose.
    pub fn build_solid_set(
        device: &Device,
        solids: &[strahl::shapes::PreparedSolid],
        quality: Quality,
    ) -> anyhow::Result<Self> {
        Self::build_all(device, &[], &[], solids, quality, false, true)
    }

    fn build_all(
        device: &Device,
        meshes: &[TriangleMesh],
        spheres: &[strahl::SphereSet],
        solids: &[strahl::shapes::PreparedSolid],
        quality: Quality,
        robust: bool,
        one_solid_geometry: bool,
    ) -> anyhow::Result<Self> {
        // SAFETY: `device.raw` is live; every pointer returned by rtcSetNewGeometryBuffer is checked
        // for null and points to a buffer of exactly `item_count × byte_stride` bytes (plus Embree's
        // own padding), which the copies below fill without overrunning.
        unsafe {
            let raw = rtcNewScene(device.raw);
            if raw.is_null() {
                device.check("rtcNewScene")?;
                anyhow::bail!("rtcNewScene failed");
            }
            let mut scene = Self { raw, build_ms: 0.0, objects: Vec::new(), solids: Vec::new() };
            rtcSetSceneBuildQuality(raw, quality as c_uint);
            if robust {
                rtcSetSceneFlags(raw, RTC_SCENE_FLAG_ROBUST);
            }
            for (id, m) in meshes.iter().enumerate() {
                if m.triangle_count() == 0 || m.positions().is_empty() {
                    continue;
                }
                let g = rtcNewGeometry(device.raw, RTC_GEOMETRY_TYPE_TRIANGLE);
                if g.is_null() {
                    device.check("rtcNewGeometry")?;
                    anyhow::bail!("rtcNewGeometry failed");
                }
                let nv = m.positions().len();
                let vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, nv) as *mut f32;
                let nt = m.triangle_count();
                let ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, nt) as *mut u32;
                if vb.is_null() || ib.is_null() {
                    rtcReleaseGeometry(g);
                    device.check("rtcSetNewGeometryBuffer")?;
                    anyhow::bail!("rtcSetNewGeometryBuffer failed");
                }
                let vs = std::slice::from_raw_parts_mut(vb, 3 * nv);
                for (i, p) in m.positions().iter().enumerate() {
                    vs[3 * i..3 * i + 3].copy_from_slice(&p.to_array());
                }
                let is = std::slice::from_raw_parts_mut(ib, 3 * nt);
                for (i, t) in m.indices().iter().enumerate() {
                    is[3 * i..3 * i + 3].copy_from_slice(t);
                }
                rtcCommitGeometry(g);
                rtcAttachGeometryByID(raw, g, id as c_uint);
                rtcReleaseGeometry(g);
            }
            attach_spheres(device, raw, spheres, meshes.len())?;
            scene.solids = solids.to_vec();
            attach_solids(device, raw, &scene.solids, meshes.len() + spheres.len(), one_solid_geometry)?;
            let start = Instant::now();
            rtcCommitScene(raw);
            scene.build_ms = start.elapsed().as_secs_f64() * 1e3;
            device.check("rtcCommitScene")?;
            Ok(scene)
        }
    }

    /// Builds sphere sets as `RTC_GEOMETRY_TYPE_SPHERE_POINT` geometries (geometry id = set
    /// index), each from one `RTC_FORMAT_FLOAT4` vertex buffer of `(x, y, z, radius)`: Embree's
    /// own layout for spheres, filled before the build and never touched by a timed query.
    pub fn build_spheres(device: &Device, sets: &[strahl::SphereSet], quality: Quality) -> anyhow::Result<Self> {
        Self::build_mixed(device, &[], sets, &[], quality, false)
    }

    /// Builds each object (a list of meshes) as its own scene, then a scene of instances of them:
    /// `(object, column-major 3×4 object-to-world matrix)`, as `RTC_GEOMETRY_TYPE_INSTANCE` with
    /// `RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR`. Hits report the instance index in `instID[0]`.
    pub fn build_instanced(
        device: &Device,
        objects: &[Vec<TriangleMesh>],
        instances: &[(usize, [f32; 12])],
        quality: Quality,
    ) -> anyhow::Result<Self> {
        Self::build_instanced_mixed(device, objects, &[], &[], instances, quality)
    }

    /// [`build_instanced`](Self::build_instanced) with each object's sphere sets and then its
    /// solids after its meshes (`spheres[o]`, `solids[o]`; a missing entry is none).
    pub fn build_instanced_mixed(
        device: &Device,
        objects: &[Vec<TriangleMesh>],
        spheres: &[Vec<strahl::SphereSet>],
        solids: &[Vec<strahl::shapes::PreparedSolid>],
        instances: &[(usize, [f32; 12])],
        quality: Quality,
    ) -> anyhow::Result<Self> {
        let objects = objects
            .iter()
            .enumerate()
            .map(|(o, m)| {
                let sp = spheres.get(o).map_or(&[][..], |s| s);
                Self::build_mixed(device, m, sp, solids.get(o).map_or(&[][..], |s| s), quality, false)
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        if let Some((i, (o, _))) = instances.iter().enumerate().find(|(_, (o, _))| *o >= objects.len()) {
            anyhow::bail!("instance {i} places object {o} of {}", objects.len());
        }
        // SAFETY: `device.raw` and every object scene are live and committed; each geometry is
        // checked for null; the transform pointer refers to 12 floats that outlive the call (Embree
        // copies them); the object scenes are kept in `objects` for as long as the top scene lives.
        unsafe {
            let raw = rtcNewScene(device.raw);
            if raw.is_null() {
                device.check("rtcNewScene")?;
                anyhow::bail!("rtcNewScene failed");
            }
            let mut scene = Self { raw, build_ms: 0.0, objects: Vec::new(), solids: Vec::new() };
            rtcSetSceneBuildQuality(raw, quality as c_uint);
            for (id, (o, xfm)) in instances.iter().enumerate() {
                let g = rtcNewGeometry(device.raw, RTC_GEOMETRY_TYPE_INSTANCE);
                if g.is_null() {
                    device.check("rtcNewGeometry")?;
                    anyhow::bail!("rtcNewGeometry(INSTANCE) failed");
                }
                rtcSetGeometryInstancedScene(g, objects[*o].raw);
                rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, xfm.as_ptr() as *const c_void);
                rtcCommitGeometry(g);
                rtcAttachGeometryByID(raw, g, id as c_uint);
                rtcReleaseGeometry(g);
            }
            device.check("instance geometries")?;
            let start = Instant::now();
            rtcCommitScene(raw);
            scene.build_ms = start.elapsed().as_secs_f64() * 1e3 + objects.iter().map(|s| s.build_ms).sum::<f64>();
            device.check("rtcCommitScene")?;
            scene.objects = objects;
            Ok(scene)
        }
    }

    /// `rtcIntersect1` on one ray/hit record.
    #[inline]
    pub fn intersect1(&self, rh: &mut RTCRayHit, coherent: bool) {
        let mut ctx = RTCIntersectContext::new(coherent);
        // SAFETY: the scene is committed; `ctx` and `rh` are valid, aligned, exclusive references.
        unsafe { rtcIntersect1(self.raw, &mut ctx, rh) }
    }

    /// `rtcOccluded1`; afterwards `ray.tfar == -inf` marks an occluded ray.
    #[inline]
    pub fn occluded1(&self, ray: &mut RTCRay, coherent: bool) {
        let mut ctx = RTCIntersectContext::new(coherent);
        // SAFETY: as for intersect1.
        unsafe { rtcOccluded1(self.raw, &mut ctx, ray) }
    }

    /// `rtcIntersect16` with a valid mask (−1 = active lane).
    #[inline]
    pub fn intersect16(&self, valid: &[i32; 16], rh: &mut RTCRayHit16, coherent: bool) {
        let mut ctx = RTCIntersectContext::new(coherent);
        // SAFETY: `valid` points to 16 ints and `rh` is a 64-byte-aligned RTCRayHit16, as required.
        unsafe { rtcIntersect16(valid.as_ptr(), self.raw, &mut ctx, rh) }
    }

    /// `rtcOccluded16` with a valid mask.
    #[inline]
    pub fn occluded16(&self, valid: &[i32; 16], ray: &mut RTCRay16, coherent: bool) {
        let mut ctx = RTCIntersectContext::new(coherent);
        // SAFETY: as for intersect16.
        unsafe { rtcOccluded16(valid.as_ptr(), self.raw, &mut ctx, ray) }
    }

    /// `rtcIntersect1M` over a slice of ray/hit records.
    pub fn intersect1m(&self, rh: &mut [RTCRayHit], coherent: bool) {
        if rh.is_empty() {
            return;
        }
        let mut ctx = RTCIntersectContext::new(coherent);
        // SAFETY: the slice holds `len` contiguous, aligned records with the given stride.
        unsafe { rtcIntersect1M(self.raw, &mut ctx, rh.as_mut_ptr(), rh.len() as c_uint, size_of::<RTCRayHit>()) }
    }

    /// `rtcOccluded1M` over a slice of rays.
    pub fn occluded1m(&self, rays: &mut [RTCRay], coherent: bool) {
        if rays.is_empty() {
            return;
        }
        let mut ctx = RTCIntersectContext::new(coherent);
        // SAFETY: as for intersect1m.
        unsafe { rtcOccluded1M(self.raw, &mut ctx, rays.as_mut_ptr(), rays.len() as c_uint, size_of::<RTCRay>()) }
    }
}

/// Attaches each sphere set as an `RTC_GEOMETRY_TYPE_SPHERE_POINT` geometry of `raw` with id
/// `first_id + index`, from one `RTC_FORMAT_FLOAT4` vertex buffer of `(x, y, z, radius)`:
/// Embree's own layout for spheres, filled before the build.
fn attach_spheres(device: &Device, raw: RTCScene, sets: &[strahl::SphereSet], first_id: usize) -> anyhow::Result<()> {
    // SAFETY: `device.raw` and `raw` are live (the caller's); each buffer pointer is checked for
    // null and points to `n × 16` bytes (plus Embree's padding), which the copy below fills
    // without overrunning.
    unsafe {
        for (k, set) in sets.iter().enumerate() {
            if set.is_empty() {
                continue;
            }
            let g = rtcNewGeometry(device.raw, RTC_GEOMETRY_TYPE_SPHERE_POINT);
            if g.is_null() {
                device.check("rtcNewGeometry")?;
                anyhow::bail!("rtcNewGeometry(SPHERE_POINT) failed");
            }
            let n = set.len();
            let vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, 16, n) as *mut f32;
            if vb.is_null() {
                rtcReleaseGeometry(g);
                device.check("rtcSetNewGeometryBuffer")?;
                anyhow::bail!("rtcSetNewGeometryBuffer failed");
            }
            let vs = std::slice::from_raw_parts_mut(vb, 4 * n);
            for (i, (c, &r)) in set.centers().iter().zip(set.radii()).enumerate() {
                vs[4 * i..4 * i + 4].copy_from_slice(&[c.x, c.y, c.z, r]);
            }
            rtcCommitGeometry(g);
            rtcAttachGeometryByID(raw, g, (first_id + k) as c_uint);
            rtcReleaseGeometry(g);
        }
    }
    Ok(())
}

/// Attaches the solids as `RTC_GEOMETRY_TYPE_USER` geometry: each as a geometry of one primitive
/// with id `first_id + index` (`one_geometry` false), or all as the primitives of one geometry
/// with id `first_id` (`one_geometry` true, the layout of Embree's own user-geometry tutorial).
/// The user pointer is the first solid of the group, which `Scene::solids` keeps alive and in
/// place for the scene's life; a callback finds its solid at `primID` from there and reports
/// `geomID + primID` as the hit's geometry id, so both layouts number hits as strahl does.
fn attach_solids(
    device: &Device,
    raw: RTCScene,
    solids: &[strahl::shapes::PreparedSolid],
    first_id: usize,
    one_geometry: bool,
) -> anyhow::Result<()> {
    let groups: Vec<&[strahl::shapes::PreparedSolid]> = if one_geometry {
        vec![solids].into_iter().filter(|g| !g.is_empty()).collect()
    } else {
        solids.chunks(1).collect()
    };
    // SAFETY: `device.raw` and `raw` are live; each geometry is checked for null; the user
    // pointer is the first of `group.len()` consecutive `PreparedSolid`s owned by the scene being
    // built, never moved or freed before the scene is released, only read (shared) by the
    // callbacks, which index it by a `primID` below the primitive count set here.
    unsafe {
        for (k, group) in groups.iter().enumerate() {
            let g = rtcNewGeometry(device.raw, RTC_GEOMETRY_TYPE_USER);
            if g.is_null() {
                device.check("rtcNewGeometry")?;
                anyhow::bail!("rtcNewGeometry(USER) failed");
            }
            let ptr = group.as_ptr() as *mut c_void;
            rtcSetGeometryUserPrimitiveCount(g, group.len() as c_uint);
            rtcSetGeometryUserData(g, ptr);
            rtcSetGeometryBoundsFunction(g, solid_bounds, std::ptr::null_mut());
            rtcSetGeometryIntersectFunction(g, solid_intersect);
            rtcSetGeometryOccludedFunction(g, solid_occluded);
            rtcCommitGeometry(g);
            rtcAttachGeometryByID(raw, g, (first_id + k) as c_uint);
            rtcReleaseGeometry(g);
        }
    }
    device.check("user geometries")
}

/// The bounds callback of a solid's user geometry.
unsafe extern "C" fn solid_bounds(args: *const RTCBoundsFunctionArguments) {
    // SAFETY: Embree passes valid arguments whose user pointer is the first of the
    // `PreparedSolid`s set in `attach_solids`, `primID` below their count, and whose `bounds_o`
    // points to one writable `RTCBounds`.
    unsafe {
        let a = &*args;
        let solid = &*(a.geometryUserPtr as *const strahl::shapes::PreparedSolid).add(a.primID as usize);
        let (lo, hi) = solid.bounds();
        *a.bounds_o = RTCBounds { lower: lo.to_array(), align0: 0.0, upper: hi.to_array(), align1: 0.0 };
    }
}

/// Lane `i` of an `N`-wide SoA ray (`RTCRayN`) starting at `r`, as a strahl ray.
///
/// # Safety
/// `r` must point to an `RTCRayN` of `n` lanes and `i < n`.
unsafe fn lane_ray(r: *const f32, n: usize, i: usize) -> strahl::Ray {
    // SAFETY: the caller's; each field block is `n` floats long, field `k` at `k·n`.
    let f = |k: usize| unsafe { *r.add(k * n + i) };
    strahl::Ray::segment(glam::Vec3::new(f(0), f(1), f(2)), glam::Vec3::new(f(4), f(5), f(6)), f(3), f(8))
}

/// The intersect callback: strahl's solid test per valid lane, closer hits written into the
/// `RTCRayHitN` (`tfar`, normal, `u = v = 0`, the primitive crossed as `primID`, and the
/// instance id from the context, as Embree's own user-geometry tutorial does).
unsafe extern "C" fn solid_intersect(args: *const RTCIntersectFunctionNArguments) {
    // SAFETY: Embree passes valid arguments: `valid` and `rayhit` hold `N` lanes, the user
    // pointer is the first of the `PreparedSolid`s set in `attach_solids` with `primID` below
    // their count, and `context` is live.
    unsafe {
        let a = &*args;
        let n = a.N as usize;
        let solid = &*(a.geometryUserPtr as *const strahl::shapes::PreparedSolid).add(a.primID as usize);
        let rh = a.rayhit;
        let hit = rh.add(12 * n);
        let inst = (*a.context).instID[0];
        for i in 0..n {
            if *a.valid.add(i) == 0 {
                continue;
            }
            if let Some((t, ng, leaf)) = solid.intersect(&lane_ray(rh, n, i)) {
                *rh.add(8 * n + i) = t;
                *hit.add(i) = ng.x;
                *hit.add(n + i) = ng.y;
                *hit.add(2 * n + i) = ng.z;
                *hit.add(3 * n + i) = 0.0;
                *hit.add(4 * n + i) = 0.0;
                let ids = hit as *mut u32;
                *ids.add(5 * n + i) = leaf;
                *ids.add(6 * n + i) = a.geomID + a.primID;
                *ids.add(7 * n + i) = inst;
            }
        }
    }
}

/// The occluded callback: `tfar = −inf` for each valid lane the solid occludes.
unsafe extern "C" fn solid_occluded(args: *const RTCOccludedFunctionNArguments) {
    // SAFETY: as for `solid_intersect`, with an `RTCRayN` of `N` lanes.
    unsafe {
        let a = &*args;
        let n = a.N as usize;
        let solid = &*(a.geometryUserPtr as *const strahl::shapes::PreparedSolid).add(a.primID as usize);
        for i in 0..n {
            if *a.valid.add(i) != 0 && solid.intersect(&lane_ray(a.ray, n, i)).is_some() {
                *a.ray.add(8 * n + i) = f32::NEG_INFINITY;
            }
        }
    }
}

impl Drop for Scene {
    fn drop(&mut self) {
        // SAFETY: the scene was created by rtcNewScene and is released once.
        unsafe { rtcReleaseScene(self.raw) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_match_the_headers() {
        assert_eq!(size_of::<RTCRay>(), 48);
        assert_eq!(size_of::<RTCHit>(), 32);
        assert_eq!(size_of::<RTCRayHit>(), 80);
        assert_eq!(size_of::<RTCRay16>(), 12 * 64);
        assert_eq!(size_of::<RTCHit16>(), 8 * 64);
        assert_eq!(size_of::<RTCRayHit16>(), 20 * 64);
        assert_eq!(align_of::<RTCRayHit16>(), 64);
        assert_eq!(size_of::<RTCIntersectContext>(), 24);
    }
}
