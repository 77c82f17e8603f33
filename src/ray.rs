//! Rays and hits: one ray, an SoA packet of [`PACKET_WIDTH`] rays with an active-lane mask, and a
//! stream of any length in SoA form.
//!
//! A ray is the segment `origin + t·dir` for `max(tnear, 0) < t <= tfar` (the depth test of
//! Embree's default triangle test). A negative `tnear` counts as 0 in every query and in brute
//! force alike: no query reaches behind a ray's origin (Embree's valid rays start at `tnear ≥ 0`
//! too; a half-supported negative range lost hits, RELIABILITY.md). `dir` need not be normalized: `t` is measured in units of `dir`, so it
//! stays the same when a ray is transformed into another space (the seeds' instancing slides).

use glam::Vec3;
use rayon::prelude::*;

pub use crate::simd::PACKET_WIDTH;

/// One ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Where the ray starts.
    pub origin: Vec3,
    /// Its direction: any length (hit distances are in its units), not zero.
    pub dir: Vec3,
    /// Start of the segment (exclusive); negative values count as 0.
    pub tnear: f32,
    /// End of the segment (inclusive); `f32::INFINITY` for an unbounded ray.
    pub tfar: f32,
}

impl Ray {
    /// A ray over `(0, +inf]`.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self { origin, dir, tnear: 0.0, tfar: f32::INFINITY }
    }

    /// A ray over `(tnear, tfar]`.
    pub fn segment(origin: Vec3, dir: Vec3, tnear: f32, tfar: f32) -> Self {
        Self { origin, dir, tnear, tfar }
    }

    /// The point at parameter `t`.
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// This ray read field by field (see [`load_f32`](crate::simd::load_f32)): the copy a
    /// walk works on, so that it never reads its caller's freshly written fields in wider loads.
    #[inline(always)]
    pub(crate) fn read_fields(&self) -> Ray {
        use crate::simd::load_f32 as ld;
        let (o, d) = (&self.origin, &self.dir);
        Ray {
            origin: Vec3::new(ld(&o.x), ld(&o.y), ld(&o.z)),
            dir: Vec3::new(ld(&d.x), ld(&d.y), ld(&d.z)),
            tnear: ld(&self.tnear),
            tfar: ld(&self.tfar),
        }
    }

    /// This ray with a negative `tnear` raised to `+0.0`: the interval every query traces (call
    /// after [`is_valid`](Self::is_valid), which rejects a NaN `tnear`).
    #[inline(always)]
    pub(crate) fn clamped_to_zero(mut self) -> Ray {
        self.tnear = self.tnear.max(0.0) + 0.0;
        self
    }

    /// Whether the ray can hit anything. Rays with a NaN or infinite origin or direction, a zero
    /// direction, a NaN bound, or `tnear > tfar` are invalid; every query answers them with a miss
    /// (and "not occluded") instead of an error, so that one bad ray cannot spoil a batch. A
    /// direction with no component of magnitude 1e-18 or more counts as zero: traversal clamps
    /// reciprocals there (as Embree does), and hit distances beyond 1e18 would overflow.
    #[inline]
    pub fn is_valid(&self) -> bool {
        // Without branches (every single-ray query pays for this check): `0·x` is NaN exactly
        // where `x` is infinite or NaN, and a NaN sum is not 0; a NaN bound fails `tnear <= tfar`.
        let finite = (self.origin * 0.0 + self.dir * 0.0).element_sum() == 0.0;
        finite & (self.dir.abs().max_element() >= MIN_DIRECTION) & (self.tnear <= self.tfar)
    }
}

/// Moves a surface point `p` off the surface along its geometric normal `ng` (either side; pass
/// `-ng` for the other), so that a secondary ray from the result with `tnear = 0` does not hit the
/// surface it starts on, at any scene scale.
///
/// After Wächter & Binder, "A Fast and Robust Method for Avoiding Self-Intersection" (Ray Tracing
/// Gems, ch. 6, 2019), with one change: every coordinate moves by 256 units in the last place of
/// the *largest* coordinate (scaled by the normal's component), not of its own. Their per-coordinate
/// step assumes each coordinate's error scales with that coordinate alone; a hit point computed as
/// `o + t·d`, and above all one moved into an instance's object space, carries errors of the
/// size of its largest coordinate in every axis. At (3.7, 0.46, −157) with a normal along y, the
/// per-coordinate step was 1.5e-5 units, as small as the transform's rounding, and 3 in 12,000
/// outward rays hit their own instance again (`tests/instancing.rs`). Near the origin, where ulps
/// become tiny, a fixed `1/65536` step along the normal is used instead.
pub fn offset_ray_origin(p: Vec3, ng: Vec3) -> Vec3 {
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    if !p.is_finite() {
        return p;
    }
    let n = ng.normalize_or_zero();
    let m = p.abs().max_element();
    let step = (INT_SCALE * (m.next_up() - m)).max(FLOAT_SCALE);
    p + n * step
}

/// A ray–surface intersection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit point, in units of the ray's direction.
    pub t: f32,
    /// Barycentric coordinates: the hit point is `(1 − u − v)·v0 + u·v1 + v·v2`.
    pub u: f32,
    /// Barycentric `v` per ray (see [`Hit::v`]).
    pub v: f32,
    /// Unnormalized geometric normal `(v1 − v0) × (v2 − v0)` in world space.
    pub ng: Vec3,
    /// Index of the triangle within its geometry.
    pub prim_id: u32,
    /// Index of the geometry (mesh) within the scene, or within the instanced object.
    pub geom_id: u32,
    /// Index of the instance that was hit in an [`InstancedScene`](crate::InstancedScene);
    /// [`INVALID_ID`] in a flat [`Scene`](crate::Scene) (Embree's `instID`).
    pub inst_id: u32,
}

/// The smallest largest-component magnitude of a valid ray direction (see [`Ray::is_valid`]).
pub const MIN_DIRECTION: f32 = 1e-18;

/// Marks a miss in the SoA hit containers.
pub const INVALID_ID: u32 = u32::MAX;

/// Up to [`PACKET_WIDTH`] rays in SoA form, with a bit mask of the active lanes.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct RayPacket {
    /// Origin x per ray.
    pub ox: [f32; PACKET_WIDTH],
    /// Origin y per ray.
    pub oy: [f32; PACKET_WIDTH],
    /// Origin z per ray.
    pub oz: [f32; PACKET_WIDTH],
    /// Direction x per ray (not necessarily normalized).
    pub dx: [f32; PACKET_WIDTH],
    /// Direction y per ray.
    pub dy: [f32; PACKET_WIDTH],
    /// Direction z per ray.
    pub dz: [f32; PACKET_WIDTH],
    /// Start of each segment (exclusive); negative values count as 0.
    pub tnear: [f32; PACKET_WIDTH],
    /// End of each segment (inclusive).
    pub tfar: [f32; PACKET_WIDTH],
    /// Bit `i` set: lane `i` takes part in the query.
    pub active: u32,
}

impl Default for RayPacket {
    fn default() -> Self {
        Self {
            ox: [0.0; PACKET_WIDTH],
            oy: [0.0; PACKET_WIDTH],
            oz: [0.0; PACKET_WIDTH],
            dx: [0.0; PACKET_WIDTH],
            dy: [0.0; PACKET_WIDTH],
            dz: [0.0; PACKET_WIDTH],
            tnear: [0.0; PACKET_WIDTH],
            tfar: [0.0; PACKET_WIDTH],
            active: 0,
        }
    }
}

impl RayPacket {
    /// Packs up to [`PACKET_WIDTH`] rays; lanes past `rays.len()` are inactive. Extra rays are
    /// ignored.
    pub fn from_rays(rays: &[Ray]) -> Self {
        let mut p = Self::default();
        for (i, r) in rays.iter().take(PACKET_WIDTH).enumerate() {
            p.set(i, r);
        }
        p
    }

    /// Writes lane `lane` and marks it active.
    pub fn set(&mut self, lane: usize, r: &Ray) {
        self.ox[lane] = r.origin.x;
        self.oy[lane] = r.origin.y;
        self.oz[lane] = r.origin.z;
        self.dx[lane] = r.dir.x;
        self.dy[lane] = r.dir.y;
        self.dz[lane] = r.dir.z;
        self.tnear[lane] = r.tnear;
        self.tfar[lane] = r.tfar;
        self.active |= 1 << lane;
    }

    /// Reads lane `lane`.
    pub fn get(&self, lane: usize) -> Ray {
        Ray {
            origin: Vec3::new(self.ox[lane], self.oy[lane], self.oz[lane]),
            dir: Vec3::new(self.dx[lane], self.dy[lane], self.dz[lane]),
            tnear: self.tnear[lane],
            tfar: self.tfar[lane],
        }
    }

    /// Whether lane `lane` is active.
    pub fn is_active(&self, lane: usize) -> bool {
        lane < PACKET_WIDTH && self.active & (1 << lane) != 0
    }
}

/// Closest hits of a [`RayPacket`] in SoA form; a missed or inactive lane has `t = +inf` and
/// `prim_id = geom_id = inst_id = INVALID_ID` (its other fields are unspecified: the queries
/// leave them as they were).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct HitPacket {
    /// Hit distance per ray, in units of its direction; `+inf` for a miss.
    pub t: [f32; PACKET_WIDTH],
    /// Barycentric `u` per ray (see [`Hit::u`]).
    pub u: [f32; PACKET_WIDTH],
    /// Barycentric `v` per ray (see [`Hit::v`]).
    pub v: [f32; PACKET_WIDTH],
    /// Unnormalized geometric normal, x, per ray.
    pub ng_x: [f32; PACKET_WIDTH],
    /// Unnormalized geometric normal, y, per ray.
    pub ng_y: [f32; PACKET_WIDTH],
    /// Unnormalized geometric normal, z, per ray.
    pub ng_z: [f32; PACKET_WIDTH],
    /// Triangle index per ray, [`INVALID_ID`] for a miss.
    pub prim_id: [u32; PACKET_WIDTH],
    /// Geometry index per ray, [`INVALID_ID`] for a miss.
    pub geom_id: [u32; PACKET_WIDTH],
    /// Instance index per ray, [`INVALID_ID`] for a miss or a flat scene.
    pub inst_id: [u32; PACKET_WIDTH],
}

impl Default for HitPacket {
    fn default() -> Self {
        Self {
            t: [f32::INFINITY; PACKET_WIDTH],
            u: [0.0; PACKET_WIDTH],
            v: [0.0; PACKET_WIDTH],
            ng_x: [0.0; PACKET_WIDTH],
            ng_y: [0.0; PACKET_WIDTH],
            ng_z: [0.0; PACKET_WIDTH],
            prim_id: [INVALID_ID; PACKET_WIDTH],
            geom_id: [INVALID_ID; PACKET_WIDTH],
            inst_id: [INVALID_ID; PACKET_WIDTH],
        }
    }
}

impl HitPacket {
    /// The hit of lane `lane`, if it hit anything.
    pub fn get(&self, lane: usize) -> Option<Hit> {
        (self.prim_id[lane] != INVALID_ID).then(|| Hit {
            t: self.t[lane],
            u: self.u[lane],
            v: self.v[lane],
            ng: Vec3::new(self.ng_x[lane], self.ng_y[lane], self.ng_z[lane]),
            prim_id: self.prim_id[lane],
            geom_id: self.geom_id[lane],
            inst_id: self.inst_id[lane],
        })
    }

    /// Writes lane `lane` (a miss for `None`).
    pub fn set(&mut self, lane: usize, hit: Option<Hit>) {
        match hit {
            Some(h) => {
                self.t[lane] = h.t;
                self.u[lane] = h.u;
                self.v[lane] = h.v;
                self.ng_x[lane] = h.ng.x;
                self.ng_y[lane] = h.ng.y;
                self.ng_z[lane] = h.ng.z;
                self.prim_id[lane] = h.prim_id;
                self.geom_id[lane] = h.geom_id;
                self.inst_id[lane] = h.inst_id;
            }
            None => {
                self.t[lane] = f32::INFINITY;
                self.prim_id[lane] = INVALID_ID;
                self.geom_id[lane] = INVALID_ID;
                self.inst_id[lane] = INVALID_ID;
            }
        }
    }
}

/// Any number of rays in SoA form: one vector per component.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RayStream {
    /// Origin x per ray.
    pub ox: Vec<f32>,
    /// Origin y per ray.
    pub oy: Vec<f32>,
    /// Origin z per ray.
    pub oz: Vec<f32>,
    /// Direction x per ray (not necessarily normalized).
    pub dx: Vec<f32>,
    /// Direction y per ray.
    pub dy: Vec<f32>,
    /// Direction z per ray.
    pub dz: Vec<f32>,
    /// Start of each segment (exclusive); negative values count as 0.
    pub tnear: Vec<f32>,
    /// End of each segment (inclusive).
    pub tfar: Vec<f32>,
}

impl RayStream {
    /// An empty stream with room for `n` rays.
    pub fn with_capacity(n: usize) -> Self {
        let v = || Vec::with_capacity(n);
        Self { ox: v(), oy: v(), oz: v(), dx: v(), dy: v(), dz: v(), tnear: v(), tfar: v() }
    }

    /// Number of rays. The component vectors are expected to have equal lengths; if they do not,
    /// the shortest one counts.
    pub fn len(&self) -> usize {
        [
            self.ox.len(),
            self.oy.len(),
            self.oz.len(),
            self.dx.len(),
            self.dy.len(),
            self.dz.len(),
            self.tnear.len(),
            self.tfar.len(),
        ]
        .into_iter()
        .min()
        .unwrap_or(0)
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Removes every ray, keeping the allocations.
    pub fn clear(&mut self) {
        for v in [&mut self.ox, &mut self.oy, &mut self.oz, &mut self.dx, &mut self.dy, &mut self.dz] {
            v.clear();
        }
        self.tnear.clear();
        self.tfar.clear();
    }

    /// Appends `r`.
    pub fn push(&mut self, r: &Ray) {
        self.ox.push(r.origin.x);
        self.oy.push(r.origin.y);
        self.oz.push(r.origin.z);
        self.dx.push(r.dir.x);
        self.dy.push(r.dir.y);
        self.dz.push(r.dir.z);
        self.tnear.push(r.tnear);
        self.tfar.push(r.tfar);
    }

    /// Appends rays from the common `origin` along the directions `dir` (by component, equally
    /// long; the shortest counts), each the segment `[tnear, tfar]`.
    pub fn extend_lanes(&mut self, origin: Vec3, dir: [&[f32]; 3], tnear: f32, tfar: f32) {
        let n = dir.iter().map(|d| d.len()).min().unwrap_or(0);
        self.ox.extend(std::iter::repeat_n(origin.x, n));
        self.oy.extend(std::iter::repeat_n(origin.y, n));
        self.oz.extend(std::iter::repeat_n(origin.z, n));
        self.dx.extend_from_slice(&dir[0][..n]);
        self.dy.extend_from_slice(&dir[1][..n]);
        self.dz.extend_from_slice(&dir[2][..n]);
        self.tnear.extend(std::iter::repeat_n(tnear, n));
        self.tfar.extend(std::iter::repeat_n(tfar, n));
    }

    /// Ray `i`. Panics if `i >= len()`, like slice indexing.
    #[inline]
    pub fn get(&self, i: usize) -> Ray {
        Ray {
            origin: Vec3::new(self.ox[i], self.oy[i], self.oz[i]),
            dir: Vec3::new(self.dx[i], self.dy[i], self.dz[i]),
            tnear: self.tnear[i],
            tfar: self.tfar[i],
        }
    }

    /// Writes the rays `start..start + PACKET_WIDTH` into `p`, all lanes active (in place: a
    /// packet returned by value is copied on its way). The rays must exist.
    pub(crate) fn whole_packet_into(&self, start: usize, p: &mut RayPacket) {
        let w = |dst: &mut [f32; PACKET_WIDTH], a: &[f32]| dst.copy_from_slice(&a[start..start + PACKET_WIDTH]);
        w(&mut p.ox, &self.ox);
        w(&mut p.oy, &self.oy);
        w(&mut p.oz, &self.oz);
        w(&mut p.dx, &self.dx);
        w(&mut p.dy, &self.dy);
        w(&mut p.dz, &self.dz);
        w(&mut p.tnear, &self.tnear);
        w(&mut p.tfar, &self.tfar);
        p.active = crate::simd::low_bits(PACKET_WIDTH);
    }

    /// The rays `base + ids[lane]` as the lanes of `p` (at most [`PACKET_WIDTH`]; the lanes
    /// past `ids.len()` inactive). The indices must lie in the stream.
    pub(crate) fn gather_packet_into(&self, base: usize, ids: &[u16], p: &mut RayPacket) {
        let n = ids.len().min(PACKET_WIDTH);
        let g = |dst: &mut [f32; PACKET_WIDTH], a: &[f32]| {
            let a = &a[base..];
            for (d, &i) in dst.iter_mut().zip(&ids[..n]) {
                *d = a[i as usize];
            }
        };
        g(&mut p.ox, &self.ox);
        g(&mut p.oy, &self.oy);
        g(&mut p.oz, &self.oz);
        g(&mut p.dx, &self.dx);
        g(&mut p.dy, &self.dy);
        g(&mut p.dz, &self.dz);
        g(&mut p.tnear, &self.tnear);
        g(&mut p.tfar, &self.tfar);
        p.active = crate::simd::low_bits(n);
    }

    /// The rays `start..start + n` (clamped to the stream) as a packet.
    pub fn packet(&self, start: usize, n: usize) -> RayPacket {
        let n = n.min(PACKET_WIDTH).min(self.len().saturating_sub(start));
        if n == PACKET_WIDTH {
            // Whole packets as fixed-size copies (vector moves; slices of run-time length went
            // through `memcpy` calls, a tenth of Cornell's primary stream).
            let w =
                |a: &[f32]| -> [f32; PACKET_WIDTH] { a[start..start + PACKET_WIDTH].try_into().unwrap_or_default() };
            return RayPacket {
                ox: w(&self.ox),
                oy: w(&self.oy),
                oz: w(&self.oz),
                dx: w(&self.dx),
                dy: w(&self.dy),
                dz: w(&self.dz),
                tnear: w(&self.tnear),
                tfar: w(&self.tfar),
                active: crate::simd::low_bits(PACKET_WIDTH),
            };
        }
        let mut p = RayPacket { active: 0, ..RayPacket::default() };
        if n == 0 {
            // `start` at or past the end: an empty packet (slicing from there would panic).
            return p;
        }
        p.ox[..n].copy_from_slice(&self.ox[start..start + n]);
        p.oy[..n].copy_from_slice(&self.oy[start..start + n]);
        p.oz[..n].copy_from_slice(&self.oz[start..start + n]);
        p.dx[..n].copy_from_slice(&self.dx[start..start + n]);
        p.dy[..n].copy_from_slice(&self.dy[start..start + n]);
        p.dz[..n].copy_from_slice(&self.dz[start..start + n]);
        p.tnear[..n].copy_from_slice(&self.tnear[start..start + n]);
        p.tfar[..n].copy_from_slice(&self.tfar[start..start + n]);
        p.active = crate::simd::low_bits(n);
        p
    }
}

impl FromIterator<Ray> for RayStream {
    fn from_iter<I: IntoIterator<Item = Ray>>(iter: I) -> Self {
        let mut s = Self::default();
        for r in iter {
            s.push(&r);
        }
        s
    }
}

/// Closest hits of a [`RayStream`] in SoA form (misses as in [`HitPacket`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HitStream {
    /// Hit distance per ray, in units of its direction; `+inf` for a miss.
    pub t: Vec<f32>,
    /// Barycentric `u` per ray (see [`Hit::u`]).
    pub u: Vec<f32>,
    /// Barycentric `v` per ray (see [`Hit::v`]).
    pub v: Vec<f32>,
    /// Unnormalized geometric normal, x, per ray.
    pub ng_x: Vec<f32>,
    /// Unnormalized geometric normal, y, per ray.
    pub ng_y: Vec<f32>,
    /// Unnormalized geometric normal, z, per ray.
    pub ng_z: Vec<f32>,
    /// Triangle index per ray, [`INVALID_ID`] for a miss.
    pub prim_id: Vec<u32>,
    /// Geometry index per ray, [`INVALID_ID`] for a miss.
    pub geom_id: Vec<u32>,
    /// Instance index per ray, [`INVALID_ID`] for a miss or a flat scene.
    pub inst_id: Vec<u32>,
}

impl HitStream {
    /// `n` misses.
    pub fn misses(n: usize) -> Self {
        Self {
            t: vec![f32::INFINITY; n],
            u: vec![0.0; n],
            v: vec![0.0; n],
            ng_x: vec![0.0; n],
            ng_y: vec![0.0; n],
            ng_z: vec![0.0; n],
            prim_id: vec![INVALID_ID; n],
            geom_id: vec![INVALID_ID; n],
            inst_id: vec![INVALID_ID; n],
        }
    }

    /// The number of rays (or hits).
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Resizes to `n` entries, all misses, reusing the allocations.
    pub fn reset(&mut self, n: usize) {
        let fill = |v: &mut Vec<f32>, x: f32| {
            v.clear();
            v.resize(n, x);
        };
        fill(&mut self.t, f32::INFINITY);
        fill(&mut self.u, 0.0);
        fill(&mut self.v, 0.0);
        fill(&mut self.ng_x, 0.0);
        fill(&mut self.ng_y, 0.0);
        fill(&mut self.ng_z, 0.0);
        for ids in [&mut self.prim_id, &mut self.geom_id, &mut self.inst_id] {
            ids.clear();
            ids.resize(n, INVALID_ID);
        }
    }

    /// Resizes to `n` entries, keeping what the first `n` held: the stream queries clear each
    /// chunk as they trace it (in parallel and while it is in cache; a serial fill of all nine
    /// arrays was a tenth of a primary stream's time).
    pub(crate) fn resize_uncleared(&mut self, n: usize) {
        for v in [&mut self.t, &mut self.u, &mut self.v, &mut self.ng_x, &mut self.ng_y, &mut self.ng_z] {
            v.resize(n, 0.0);
        }
        for ids in [&mut self.prim_id, &mut self.geom_id, &mut self.inst_id] {
            ids.resize(n, INVALID_ID);
        }
    }

    /// Hit `i`, if ray `i` hit anything.
    pub fn get(&self, i: usize) -> Option<Hit> {
        (self.prim_id[i] != INVALID_ID).then(|| Hit {
            t: self.t[i],
            u: self.u[i],
            v: self.v[i],
            ng: Vec3::new(self.ng_x[i], self.ng_y[i], self.ng_z[i]),
            prim_id: self.prim_id[i],
            geom_id: self.geom_id[i],
            inst_id: self.inst_id[i],
        })
    }

    /// Writes entry `i` (a miss for `None`).
    pub fn set(&mut self, i: usize, hit: Option<Hit>) {
        match hit {
            Some(h) => self.as_slice_mut().set(i, &h),
            None => {
                self.t[i] = f32::INFINITY;
                self.prim_id[i] = INVALID_ID;
                self.geom_id[i] = INVALID_ID;
                self.inst_id[i] = INVALID_ID;
            }
        }
    }
}

/// A run of a [`HitStream`]'s entries, borrowed mutably: what [`HitStream::par_chunks_mut`]
/// hands each worker, so that a backend writes its answers in place.
pub struct HitSlice<'a> {
    t: &'a mut [f32],
    u: &'a mut [f32],
    v: &'a mut [f32],
    ng_x: &'a mut [f32],
    ng_y: &'a mut [f32],
    ng_z: &'a mut [f32],
    prim_id: &'a mut [u32],
    geom_id: &'a mut [u32],
    inst_id: &'a mut [u32],
}

impl<'a> HitSlice<'a> {
    pub(crate) fn of(h: &'a mut HitStream) -> Self {
        Self {
            t: &mut h.t,
            u: &mut h.u,
            v: &mut h.v,
            ng_x: &mut h.ng_x,
            ng_y: &mut h.ng_y,
            ng_z: &mut h.ng_z,
            prim_id: &mut h.prim_id,
            geom_id: &mut h.geom_id,
            inst_id: &mut h.inst_id,
        }
    }

    /// The number of entries.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Marks every entry from `from` on a miss: `t = +inf` and invalid ids, as [`HitPacket`] defines a miss
    /// (the other fields of a miss are unspecified; writing them too cost Cornell's and the
    /// teapot's primary streams a tenth of their time).
    pub(crate) fn clear(&mut self, from: usize) {
        self.t[from..].fill(f32::INFINITY);
        for ids in [&mut *self.prim_id, &mut *self.geom_id, &mut *self.inst_id] {
            ids[from..].fill(INVALID_ID);
        }
    }

    /// Writes the whole packet `h` to entries `i..i + PACKET_WIDTH`.
    #[inline(always)]
    pub(crate) fn set_packet(&mut self, i: usize, h: &HitPacket) {
        let r = i..i + PACKET_WIDTH;
        self.t[r.clone()].copy_from_slice(&h.t);
        self.u[r.clone()].copy_from_slice(&h.u);
        self.v[r.clone()].copy_from_slice(&h.v);
        self.ng_x[r.clone()].copy_from_slice(&h.ng_x);
        self.ng_y[r.clone()].copy_from_slice(&h.ng_y);
        self.ng_z[r.clone()].copy_from_slice(&h.ng_z);
        self.prim_id[r.clone()].copy_from_slice(&h.prim_id);
        self.geom_id[r.clone()].copy_from_slice(&h.geom_id);
        self.inst_id[r].copy_from_slice(&h.inst_id);
    }

    /// Writes hit `h` to entry `i` (panics if `i` is out of range, like slice indexing).
    #[inline]
    pub fn set(&mut self, i: usize, h: &Hit) {
        self.t[i] = h.t;
        self.u[i] = h.u;
        self.v[i] = h.v;
        self.ng_x[i] = h.ng.x;
        self.ng_y[i] = h.ng.y;
        self.ng_z[i] = h.ng.z;
        self.prim_id[i] = h.prim_id;
        self.geom_id[i] = h.geom_id;
        self.inst_id[i] = h.inst_id;
    }
}

impl HitStream {
    /// The whole stream as one [`HitSlice`].
    pub fn as_slice_mut(&mut self) -> HitSlice<'_> {
        HitSlice::of(self)
    }

    /// The stream in runs of `chunk` entries (the last may be shorter; a `chunk` of 0 counts as
    /// 1), for rayon: `hits.par_chunks_mut(n).enumerate()` gives each run with its index.
    pub fn par_chunks_mut(&mut self, chunk: usize) -> impl IndexedParallelIterator<Item = HitSlice<'_>> {
        let c = chunk.max(1);
        let h = self;
        (
            (h.t.par_chunks_mut(c), h.u.par_chunks_mut(c), h.v.par_chunks_mut(c)),
            (h.ng_x.par_chunks_mut(c), h.ng_y.par_chunks_mut(c), h.ng_z.par_chunks_mut(c)),
            (h.prim_id.par_chunks_mut(c), h.geom_id.par_chunks_mut(c), h.inst_id.par_chunks_mut(c)),
        )
            .into_par_iter()
            .map(|((t, u, v), (ng_x, ng_y, ng_z), (prim_id, geom_id, inst_id))| HitSlice {
                t,
                u,
                v,
                ng_x,
                ng_y,
                ng_z,
                prim_id,
                geom_id,
                inst_id,
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hit_stream_chunks_cover_the_stream_and_write_in_place() {
        use rayon::prelude::*;
        let mut hits = HitStream::misses(37);
        for chunk in [0usize, 1, 5, 16, 37, 100] {
            let lens: Vec<usize> = hits.par_chunks_mut(chunk).map(|c| c.len()).collect();
            assert_eq!(lens.iter().sum::<usize>(), 37, "chunk {chunk}");
            assert!(lens.iter().all(|&n| n >= 1 && n <= chunk.max(1)), "chunk {chunk}: {lens:?}");
        }
        hits.par_chunks_mut(5).enumerate().for_each(|(i, mut c)| {
            let h =
                Hit { t: i as f32, u: 0.0, v: 0.0, ng: Vec3::Z, prim_id: i as u32, geom_id: 0, inst_id: INVALID_ID };
            c.set(0, &h);
        });
        for i in 0..37 {
            match hits.get(i) {
                Some(h) => assert_eq!((i % 5, h.prim_id as usize), (0, i / 5)),
                None => assert_ne!(i % 5, 0),
            }
        }
        assert!(hits.as_slice_mut().len() == 37 && !hits.as_slice_mut().is_empty());
    }

    #[test]
    fn validity() {
        let o = Vec3::ZERO;
        assert!(Ray::new(o, Vec3::X).is_valid());
        assert!(!Ray::new(o, Vec3::ZERO).is_valid());
        assert!(!Ray::new(o, Vec3::new(1e-38, -1e-30, 0.0)).is_valid());
        assert!(Ray::new(o, Vec3::new(1e-38, -1e-18, 0.0)).is_valid());
        assert!(!Ray::new(Vec3::NAN, Vec3::X).is_valid());
        assert!(!Ray::new(o, Vec3::new(f32::INFINITY, 0.0, 0.0)).is_valid());
        assert!(!Ray::segment(o, Vec3::X, 2.0, 1.0).is_valid());
        assert!(!Ray::segment(o, Vec3::X, f32::NAN, 1.0).is_valid());
        assert!(Ray::segment(o, Vec3::X, 1.0, 1.0).is_valid());
        // One bad component anywhere, beside large finite ones.
        let big = f32::MAX;
        assert!(Ray::new(Vec3::new(big, -big, big), Vec3::new(big, 1.0, -big)).is_valid());
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            for k in 0..3 {
                let mut v = Vec3::new(big, -1.0, 3.0);
                v[k] = bad;
                assert!(!Ray::new(v, Vec3::X).is_valid(), "origin {v}");
                assert!(!Ray::new(o, v).is_valid(), "direction {v}");
            }
        }
        assert!(!Ray::segment(o, Vec3::X, 0.0, f32::NAN).is_valid());
        assert!(Ray::segment(o, Vec3::X, f32::NEG_INFINITY, f32::INFINITY).is_valid());
    }

    #[test]
    fn offset_moves_to_the_normal_side_at_every_scale() {
        for scale in [1e-3f32, 1.0, 1e3, 1e6] {
            for n in [Vec3::X, Vec3::new(-0.3, 0.9, 0.1).normalize(), Vec3::new(0.0, 0.0, -1.0)] {
                for p in [Vec3::new(0.3, -0.7, 0.01) * scale, Vec3::new(-5.0, 2.0, 9.0) * scale] {
                    let q = offset_ray_origin(p, n);
                    assert!(q.is_finite());
                    assert!((q - p).dot(n) > 0.0, "scale {scale} p {p} n {n}: {q}");
                    // Small relative to the coordinates: at most ~256 ulps per axis.
                    assert!((q - p).length() <= 1e-4 * p.abs().max_element().max(1.0), "{p} -> {q}");
                }
            }
        }
        assert_eq!(offset_ray_origin(Vec3::ONE, Vec3::ZERO), Vec3::ONE);
    }

    #[test]
    fn packet_round_trip() {
        let rays: Vec<Ray> = (0..5).map(|i| Ray::new(Vec3::splat(i as f32), Vec3::new(1.0, i as f32, 2.0))).collect();
        let p = RayPacket::from_rays(&rays);
        assert_eq!(p.active, 0b11111);
        for (i, r) in rays.iter().enumerate() {
            assert_eq!(p.get(i), *r);
        }
        let s: RayStream = rays.iter().copied().collect();
        assert_eq!(s.len(), 5);
        let q = s.packet(3, 16);
        assert_eq!(q.active, 0b11);
        assert_eq!(q.get(1), rays[4]);
    }
}
