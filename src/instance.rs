//! Two-level scenes: instancing by ray transformation (the seeds' instancing slides; Embree's
//! `RTC_GEOMETRY_TYPE_INSTANCE`).
//!
//! Each object (a [`Scene`] of meshes) is built once in its own space. An [`Instance`] places an
//! object in the world with an affine transform; a top-level BVH over the instances' world boxes
//! finds the instances a ray may hit. At an instance the ray is moved into the object's space with
//! the inverse transform, origin and direction, and the direction is *not* renormalized: `t` then
//! measures the same point in both spaces, so the object BVH can be walked with the ray's current
//! `tfar` and its hit compared with hits in other instances as is. The geometric normal is brought
//! back to world space with the inverse transpose of the linear part (times its determinant, so
//! it stays the cross product of the placed triangle's edges).
//!
//! Memory grows with the number of distinct objects, not with the number of placed triangles: a
//! world of 10,000 instances of a 433k-triangle object stores the object once plus 10,000 small
//! records and a top-level BVH over them.

use std::time::Instant;

use glam::{Affine3A, Mat3A, Vec3, Vec3A};
use rayon::prelude::*;

use crate::bvh::build::{self, Aabb, PrimRef};
use crate::bvh::node::{EMPTY, MAX_BLOCK_INDEX, Node, leaf_blocks};
use crate::bvh::traverse::{
    BoxRay, LaneSlabs, LeafHit, PacketBoxes, PacketHits, SlabTerms, Stack, Tree, dispatch, each_lane_alone, or_scratch,
    walk_packet, walk1, with_stack,
};
use crate::bvh::{BoxTest, BuildConfig, INSTANCED_FAR_MEMORY_BYTES};
use crate::error::{Error, Result};
use crate::geometry::TriangleTest;
use crate::geometry::badouel::Badouel;
use crate::geometry::moeller::Moller;
use crate::geometry::triangle::Kernel;
use crate::geometry::watertight::Watertight;
use crate::ray::{Hit, HitPacket, Ray, RayPacket};
use crate::scene::{Query, Scene, each_hit};
use crate::shapes::SphereSet;
use crate::simd::{Level, Packet, SimdF, hot, with_level};

/// One placement of an object: `object` indexes the objects of the [`InstancedScene`], and
/// `transform` maps object space to world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// Index of the placed object in the objects the scene was built from.
    pub object: usize,
    /// Object-to-world transform: finite and invertible.
    pub transform: Affine3A,
}

impl Instance {
    /// Places `object` by `transform`.
    pub fn new(object: usize, transform: Affine3A) -> Self {
        Self { object, transform }
    }
}

/// What the top-level leaves hold, in leaf order: everything traversal needs at an instance.
#[derive(Clone, Copy, Debug)]
struct Placed {
    /// World to object space.
    to_object: Affine3A,
    /// Object-space geometric normals to world space: the cofactor matrix of the linear part,
    /// `det(M)·M⁻ᵀ`, which maps `e1 × e2` to the cross product of the moved edges, so a mirroring
    /// transform flips the normal with the winding, as flattening would.
    normal_to_world: Mat3A,
    /// Whether the transform mirrors (`det < 0`). Sphere normals stay outward (`p − centre`), so
    /// the walks negate a sphere hit's object normal here before the cofactor flips it back.
    mirror: bool,
    object: u32,
    /// Index in the list the scene was built from (the hit's `inst_id`).
    id: u32,
    /// World box, for the per-lane test of packets.
    lo: [f32; 3],
    hi: [f32; 3],
}

impl Placed {
    /// An object-space sphere hit made ready for `normal_to_world` (see [`Placed::mirror`]).
    #[inline]
    fn sphere_hit(&self, h: Hit) -> Hit {
        if self.mirror { Hit { ng: -h.ng, ..h } } else { h }
    }
}

/// Figures of a two-level build.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InstancedStats {
    /// Wall time of the top-level build (objects are built before, see their own stats).
    pub top_build_ms: f64,
    /// Wall time of the object builds.
    pub objects_build_ms: f64,
    /// Instances in the scene.
    pub instances: usize,
    /// Triangles over all instances, counted once per instance (what the world shows).
    pub instanced_triangles: u64,
    /// Triangles stored: each object's once.
    pub unique_triangles: usize,
    /// Bytes of the objects' BVHs and blocks, the top-level nodes and the instance records.
    pub bytes: usize,
    /// Bytes a flat BVH over every placed triangle would need, estimated from each object's own
    /// bytes per triangle times the triangles it places.
    pub flattened_bytes: u64,
}

/// Objects placed by instances, with a BVH over the instances.
#[derive(Clone, Debug)]
pub struct InstancedScene {
    objects: Vec<Scene>,
    instances: Vec<Instance>,
    nodes: Vec<Node>,
    root: u32,
    placed: Vec<Placed>,
    bounds: Option<(Vec3, Vec3)>,
    /// The tests every object was built for.
    test: TriangleTest,
    box_test: BoxTest,
    stats: InstancedStats,
}

/// Instances per top-level leaf: one, as Embree's instance BVH has. An instance costs a whole
/// object traversal, so the builder should never merge two into a leaf to save a node.
const INSTANCES_PER_LEAF: usize = 1;

impl InstancedScene {
    /// The instance level as the walks read it: its leaves are instances (no triangle blocks),
    /// and it is not prefetched: an instance tree stays in the cache.
    #[inline(always)]
    fn instance_tree(&self) -> Tree<'_> {
        Tree { nodes: &self.nodes, blocks: &[], far_memory: false }
    }

    /// Builds one BVH per object (each a list of meshes), then the top level over `instances`,
    /// all with `config` on the current rayon pool. Geometry ids in hits are indices into the
    /// object's meshes; instance ids are indices into `instances`.
    ///
    /// Errors: an instance naming no object ([`Error::UnknownObject`]), or a transform that is not
    /// finite and invertible ([`Error::BadTransform`]).
    pub fn build(
        objects: Vec<Vec<crate::geometry::TriangleMesh>>,
        instances: Vec<Instance>,
        config: &BuildConfig,
    ) -> Result<Self> {
        crate::bvh::on_pool(|| Self::build_in_pool(objects, instances, config))
    }

    /// [`build`](Self::build) on a thread of the pool.
    fn build_in_pool(
        objects: Vec<Vec<crate::geometry::TriangleMesh>>,
        instances: Vec<Instance>,
        config: &BuildConfig,
    ) -> Result<Self> {
        let start = Instant::now();
        // Objects side by side: most are too small to keep two threads busy on their own.
        let objects =
            objects.into_par_iter().map(|meshes| Scene::build(meshes, config)).collect::<Result<Vec<Scene>>>()?;
        let objects_build_ms = start.elapsed().as_secs_f64() * 1e3;
        Self::from_objects(objects, instances, (config.triangle_test, config.box_test), objects_build_ms)
    }

    /// Places already built objects; see [`build`](Self::build). The objects must share their
    /// triangle and box tests ([`Error::MixedTests`] otherwise); an empty list takes the defaults.
    pub fn from_scenes(objects: Vec<Scene>, instances: Vec<Instance>) -> Result<Self> {
        let tests = objects.first().map_or((TriangleTest::default(), BoxTest::default()), |o| o.tests());
        Self::from_objects(objects, instances, tests, 0.0)
    }

    fn from_objects(
        mut objects: Vec<Scene>,
        instances: Vec<Instance>,
        (test, box_test): (TriangleTest, BoxTest),
        objects_build_ms: f64,
    ) -> Result<Self> {
        let start = Instant::now();
        if objects.iter().any(|o| o.tests() != (test, box_test)) {
            return Err(Error::MixedTests);
        }

        if instances.len() > MAX_BLOCK_INDEX {
            return Err(Error::TooManyInstances(instances.len()));
        }
        for (i, inst) in instances.iter().enumerate() {
            if inst.object >= objects.len() {
                return Err(Error::UnknownObject { instance: i, object: inst.object, objects: objects.len() });
            }
            if !is_invertible(&inst.transform) {
                return Err(Error::BadTransform { instance: i });
            }
            if !objects[inst.object].spheres().is_empty() && uniform_scale(&inst.transform).is_none() {
                return Err(Error::SphereInstanceNotSimilar { instance: i });
            }
        }
        // In parallel: up to 64 boxes of eight corners each per instance.
        let mut prims: Vec<PrimRef> = instances
            .par_iter()
            .enumerate()
            .filter_map(|(i, inst)| {
                placed_box(&objects[inst.object], &inst.transform).map(|b| PrimRef::new(b, i as u32))
            })
            .collect();
        let cfg = BuildConfig {
            min_leaf: INSTANCES_PER_LEAF,
            max_leaf: INSTANCES_PER_LEAF,
            parallel_threshold: 4096,
            ..BuildConfig::default()
        };
        let tree = build::build(&mut prims, &cfg);
        let mut nodes = Vec::new();
        let (root, bounds) = match tree {
            None => (EMPTY, None),
            Some(t) => {
                // One instance per leaf and one "block" per leaf, numbered in leaf order: the leaf
                // references name entries of the reordered instance list.
                nodes.resize(t.chunk.size.nodes, Node::default());
                let mut leaves = vec![(0, 0); t.chunk.size.leaves];
                crate::bvh::place(t.chunk, &mut nodes, &mut leaves, 0, 0);
                debug_assert!(leaves.iter().enumerate().all(|(i, &l)| l == (i, 1)));
                (t.root, Some((Vec3::from(t.bounds.lo), Vec3::from(t.bounds.hi))))
            }
        };
        // Leaf entries in the builder's order, so neighbouring leaves sit side by side in memory.
        let placed: Vec<Placed> = prims
            .iter()
            .map(|p| {
                let id = p.id();
                let b = p.bounds();
                let inst = &instances[id as usize];
                let to_object = inst.transform.inverse();
                Placed {
                    to_object,
                    normal_to_world: to_object.matrix3.transpose() * inst.transform.matrix3.determinant(),
                    mirror: inst.transform.matrix3.determinant() < 0.0,
                    object: inst.object as u32,
                    id,
                    lo: b.lo.to_array(),
                    hi: b.hi.to_array(),
                }
            })
            .collect();
        let object_bytes: usize =
            objects.iter().map(|o| o.stats().bytes + o.sphere_stats().bytes + o.solid_stats().bytes).sum();
        // Objects out of the cache together prefetch in their walks (see the constant).
        for o in &mut objects {
            o.set_prefetch(object_bytes > INSTANCED_FAR_MEMORY_BYTES);
        }
        let bytes = object_bytes
            + nodes.len() * size_of::<Node>()
            + placed.len() * size_of::<Placed>()
            + instances.len() * size_of::<Instance>();
        let mut instanced_triangles = 0u64;
        let mut flattened_bytes = 0u64;
        for inst in &instances {
            let s = objects[inst.object].stats();
            instanced_triangles += objects[inst.object].triangle_count() as u64;
            flattened_bytes += s.bytes as u64;
        }
        let stats = InstancedStats {
            top_build_ms: start.elapsed().as_secs_f64() * 1e3,
            objects_build_ms,
            instances: instances.len(),
            instanced_triangles,
            unique_triangles: objects.iter().map(|o| o.triangle_count()).sum(),
            bytes,
            flattened_bytes,
        };
        Ok(Self { objects, instances, nodes, root, placed, bounds, test, box_test, stats })
    }

    /// The objects, each a flat scene in its own space.
    pub fn objects(&self) -> &[Scene] {
        &self.objects
    }

    /// The instances, in the order given (their index is `Hit::inst_id`).
    pub fn instances(&self) -> &[Instance] {
        &self.instances
    }

    /// Build statistics: times, sizes, counts.
    pub fn stats(&self) -> &InstancedStats {
        &self.stats
    }

    /// World bounds of all instances, or `None` if nothing can be hit.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        self.bounds
    }

    /// The same world as one flat [`Scene`]: every instance's meshes transformed into world space
    /// (geometry ids numbered instance by instance, object mesh by object mesh), then every
    /// instance's sphere sets moved likewise (geometry ids after all the meshes). For comparison
    /// and for small worlds; memory grows with the placed triangles.
    pub fn flatten(&self, config: &BuildConfig) -> Result<Scene> {
        let mut meshes = Vec::new();
        let mut spheres = Vec::new();
        let mut solids = Vec::new();
        for (i, inst) in self.instances.iter().enumerate() {
            for m in self.objects[inst.object].meshes() {
                meshes.push(m.transformed(&inst.transform));
            }
            for s in self.objects[inst.object].solids() {
                solids.push(s.clone().transformed(inst.transform));
            }
            // Instances of objects with spheres are similarities (checked when built).
            let s = uniform_scale(&inst.transform).unwrap_or(1.0);
            for set in self.objects[inst.object].spheres() {
                let moved: Vec<(Vec3, f32)> = (0..set.len())
                    .map(|j| {
                        let (c, r) = set.sphere(j);
                        (inst.transform.transform_point3(c), r * s)
                    })
                    .collect();
                spheres.push(SphereSet::from_pairs(format!("{}@{i}", set.name()), &moved)?);
            }
        }
        Scene::build_with_solids(meshes, spheres, solids, config)
    }

    /// The closest hit among every instance by testing every object triangle of every instance
    /// (O(instances × triangles)): the reference the two levels are tested against.
    pub fn intersect_brute_force(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let ray = &ray.clamped_to_zero();
        let mut best: Option<Hit> = None;
        for (i, inst) in self.instances.iter().enumerate() {
            let to_object = inst.transform.inverse();
            let tfar = best.map_or(ray.tfar, |h| h.t);
            let r = object_ray(&to_object, ray, tfar);
            if let Some(h) = self.objects[inst.object].intersect_brute_force(&r) {
                // Sphere normals stay outward under mirrors (see `Placed::mirror`).
                let det = inst.transform.matrix3.determinant();
                let sphere = h.geom_id as usize >= self.objects[inst.object].meshes().len();
                best = Some(Hit {
                    ng: to_object.matrix3.transpose() * h.ng * if sphere { det.abs() } else { det },
                    inst_id: i as u32,
                    ..h
                });
            }
        }
        best
    }

    fn trace1<const ANY: bool>(&self, ray: &Ray) -> Option<(u32, ObjHit)> {
        if self.root == EMPTY {
            return None;
        }
        with_stack(|stack| {
            dispatch!(self.test, self.box_test, |K, C| with_level!(|L| self.trace1_with::<ANY, K, C, L>(ray, stack)))
        })
    }

    /// The instance level's walk; at each instance the object's walk continues on the same stack
    /// with the same kernel, so entering an instance costs one transform and no dispatch.
    /// Invalid rays miss.
    #[inline(never)]
    fn trace1_with<const ANY: bool, K: Kernel, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        stack: &mut Stack,
    ) -> Option<(u32, ObjHit)> {
        L::call(
            #[inline(always)]
            || {
                // Read field by field, as the object walks do (see `Ray::read_fields`), once for
                // both the validity check and the walk.
                let ray = ray.read_fields();
                if !ray.is_valid() {
                    return None;
                }
                self.trace1_from::<ANY, K, CONS, L>(&ray.clamped_to_zero(), self.root, stack)
            },
        )
    }

    /// [`trace1_with`](Self::trace1_with) over the instance subtree at `root`.
    #[inline(always)]
    fn trace1_from<const ANY: bool, K: Kernel, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        root: u32,
        stack: &mut Stack,
    ) -> Option<(u32, ObjHit)> {
        self.trace1_from_terms::<ANY, K, CONS, L>(ray, SlabTerms::of(ray), root, stack)
    }

    /// [`trace1_from`](Self::trace1_from) with the ray's slab terms already computed (a packet's
    /// lane).
    #[inline(always)]
    fn trace1_from_terms<const ANY: bool, K: Kernel, const CONS: bool, L: Level>(
        &self,
        ray: &Ray,
        terms: SlabTerms,
        root: u32,
        stack: &mut Stack,
    ) -> Option<(u32, ObjHit)> {
        let br = BoxRay::<L>::with_terms(terms, ray.tnear);
        let mut tfar = ray.tfar;
        let mut best = None;
        let base = stack.push_root(root);
        walk1::<ANY, CONS, L>(
            self.instance_tree(),
            &br,
            stack,
            base,
            &mut tfar,
            #[inline(always)]
            |leaf, tfar, stack| {
                let (start, count) = leaf_blocks(leaf);
                for k in start..start + count {
                    let p = &self.placed[k];
                    let r = object_ray(&p.to_object, ray, *tfar);
                    // Finite in, finite out, except where a huge scale overflows: such rays miss.
                    if !(r.origin.is_finite() && r.dir.is_finite()) {
                        continue;
                    }
                    let object = &self.objects[p.object as usize];
                    if let Some(h) = object.bvh().trace1_with::<ANY, false, K, CONS, L>(&r, stack) {
                        *tfar = h.t;
                        best = Some((k as u32, ObjHit::Tri(h)));
                        if ANY {
                            return true;
                        }
                    }
                    let spheres = object.sphere_tree();
                    if !spheres.is_empty()
                        && let Some(h) = spheres.trace1_on::<ANY, CONS, L>(&Ray { tfar: *tfar, ..r }, stack)
                    {
                        *tfar = h.t;
                        best = Some((k as u32, ObjHit::Sphere(p.sphere_hit(h))));
                        if ANY {
                            return true;
                        }
                    }
                    let solids = object.solid_tree();
                    if !solids.is_empty()
                        && let Some(h) = solids.trace1_on::<ANY, CONS, L>(&Ray { tfar: *tfar, ..r }, stack)
                    {
                        *tfar = h.t;
                        best = Some((k as u32, ObjHit::Sphere(p.sphere_hit(h))));
                        if ANY {
                            return true;
                        }
                    }
                }
                false
            },
        );
        best
    }

    /// Closest hits (into `hit`, in world space) or occlusion of a packet; returns the lanes
    /// that hit (are occluded).
    /// Without `hit` (occlusion), into a scratch record made at the kernels' level (see
    /// `Bvh::trace_packet_with`).
    fn trace_packet<const ANY: bool>(&self, p: &RayPacket, hit: Option<&mut HitPacket>) -> u32 {
        with_stack(|stack| {
            dispatch!(self.test, self.box_test, |K, C| with_level!(
                |L| self.trace_packet_with::<ANY, K, C, L>(p, hit, stack)
            ))
        })
    }

    #[inline(never)]
    fn trace_packet_with<const ANY: bool, K: Kernel, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        hit: Option<&mut HitPacket>,
        stack: &mut Stack,
    ) -> u32 {
        L::call(
            #[inline(always)]
            || {
                let mut scratch = None;
                self.trace_packet_in::<ANY, K, CONS, L>(p, or_scratch(hit, &mut scratch), stack)
            },
        )
    }

    /// [`trace_packet_with`](Self::trace_packet_with)'s body, compiled for the level.
    #[inline(always)]
    fn trace_packet_in<const ANY: bool, K: Kernel, const CONS: bool, L: Level>(
        &self,
        p: &RayPacket,
        hit: &mut HitPacket,
        stack: &mut Stack,
    ) -> u32 {
        let mut out = PacketHits::new(hit);
        if self.root == EMPTY {
            return 0;
        }
        let Some((pb, mut tfar)) = PacketBoxes::<L>::new(p) else {
            return 0;
        };
        let base = stack.push_root(self.root);
        // Incoherent closest-hit packets: how far apart their origins lie (see
        // `OBJECT_PACKET_SPREAD`).
        let spread = if !ANY && pb.frustum.is_none() { pb.origin_extent() } else { 0.0 };
        // One object's hits, before they are turned to world space.
        let mut r = HitPacket::default();
        walk_packet::<ANY, CONS, L>(
            self.instance_tree(),
            &pb,
            stack,
            base,
            &mut tfar,
            #[inline(always)]
            |leaf, lanes, tfar, stack| {
                if lanes != 0 {
                    // A few lanes walk this part of the instance tree one at a time.
                    out.mask |= each_lane_alone::<ANY, _, L>(
                        p,
                        lanes,
                        tfar,
                        #[inline(always)]
                        |l, ray| {
                            let (k, h) =
                                self.trace1_from_terms::<ANY, K, CONS, L>(ray, pb.slabs.lane(l), leaf, stack)?;
                            Some((h.t(), (k, h)))
                        },
                        |l, (k, h)| out.set(l, &self.world_hit(k, &self.object_hit(k, &h))),
                    );
                    return ANY && out.mask == pb.live;
                }
                let (start, count) = leaf_blocks(leaf);
                for k in start..start + count {
                    let pl = &self.placed[k];
                    // Only the lanes that enter this instance's box go into the object.
                    let active = pb.lanes_in_box::<CONS>(pl.lo, pl.hi, *tfar) & pb.live;
                    if active == 0 {
                        continue;
                    }
                    let (q, [qo, qd]) = object_packet::<L>(&pl.to_object, &pb, *tfar, active);
                    let bvh = self.objects[pl.object as usize].bvh();
                    let spheres = self.objects[pl.object as usize].sphere_tree();
                    let solids = self.objects[pl.object as usize].solid_tree();
                    if !ANY && pb.frustum.is_none() && !packet_walks_object(active, spread, pl) {
                        // Incoherent closest-hit rays: each lane that enters the instance walks the
                        // object alone, as Embree's instances hand their lanes to the object's hybrid
                        // walk, which takes single rays for so few lanes. Diffuse packets run 10–15%
                        // faster this way than through the object's packet walk; occlusion packets lost
                        // 13% on the forest, so they keep it (PERFORMANCE.md). Many lanes from nearby
                        // origins take the object's packet walk instead (`packet_walks_object`). The
                        // lanes' slab terms are computed here, 16 at a time.
                        let qs = LaneSlabs::<L>::of(&qo, &qd);
                        out.mask |= each_lane_alone::<false, _, L>(
                            &q,
                            active,
                            tfar,
                            #[inline(always)]
                            |l, ray| {
                                let tri = bvh.trace1_from_terms::<false, K, CONS, L>(ray, qs.lane(l), bvh.root, stack);
                                let tri = tri.map(|h| bvh.hit_record(&h));
                                if spheres.is_empty() && solids.is_empty() {
                                    return tri.map(|h| (h.t, h));
                                }
                                let bounded = Ray { tfar: tri.map_or(ray.tfar, |h| h.t), ..*ray };
                                let sphere =
                                    spheres.trace1_on::<false, CONS, L>(&bounded, stack).map(|h| pl.sphere_hit(h));
                                let near = sphere.or(tri);
                                let bounded = Ray { tfar: near.map_or(ray.tfar, |h| h.t), ..*ray };
                                let solid =
                                    solids.trace1_on::<false, CONS, L>(&bounded, stack).map(|h| pl.sphere_hit(h));
                                solid.or(near).map(|h| (h.t, h))
                            },
                            |l, h| out.set(l, &self.world_hit(k as u32, &h)),
                        );
                        continue;
                    }
                    // The object's triangles, then its spheres and its solids, each bounded by the
                    // hits before.
                    for part in 0..3 {
                        let mask = if part == 0 {
                            bvh.trace_packet_with::<ANY, K, CONS, L>(&q, Some(&mut r), stack)
                        } else if (part == 1 && spheres.is_empty()) || (part == 2 && solids.is_empty()) {
                            0
                        } else {
                            let bounded = RayPacket { tfar: tfar.to_array(), ..q };
                            let m = if part == 1 {
                                spheres.trace_packet_on::<ANY, CONS, L>(&bounded, &mut r, stack)
                            } else {
                                solids.trace_packet_on::<ANY, CONS, L>(&bounded, &mut r, stack)
                            };
                            if pl.mirror {
                                for l in 0..r.t.len() {
                                    (r.ng_x[l], r.ng_y[l], r.ng_z[l]) = (-r.ng_x[l], -r.ng_y[l], -r.ng_z[l]);
                                }
                            }
                            m
                        };
                        if mask == 0 {
                            continue;
                        }
                        let valid = L::Pf::lane_mask(mask);
                        out.mask |= mask;
                        if ANY {
                            *tfar = valid.select(L::Pf::splat(f32::NEG_INFINITY), *tfar);
                            if out.mask == pb.live {
                                return true;
                            }
                        } else {
                            *tfar = valid.select(L::Pf::new(r.t), *tfar);
                            out.take_instanced::<L>(valid, &r, &pl.normal_to_world, pl.id);
                        }
                    }
                }
                false
            },
        );
        out.mask
    }

    /// The hit record, in object space, of an object hit in placed instance `k`.
    #[inline]
    fn object_hit(&self, k: u32, h: &ObjHit) -> Hit {
        match h {
            ObjHit::Tri(h) => self.objects[self.placed[k as usize].object as usize].bvh().hit_record(h),
            ObjHit::Sphere(h) => *h,
        }
    }

    /// The public hit record of an object-space hit in placed instance `k`.
    #[inline]
    fn world_hit(&self, k: u32, hit: &Hit) -> Hit {
        let p = &self.placed[k as usize];
        Hit { ng: Vec3::from(p.normal_to_world * Vec3A::from(hit.ng)), inst_id: p.id, ..*hit }
    }

    /// The triangle and box tests every object was built for.
    pub fn tests(&self) -> (TriangleTest, BoxTest) {
        (self.test, self.box_test)
    }

    /// The top level's root, if any instance is placed (for the walks of `crate::query`).
    pub(crate) fn top_root(&self) -> Option<u32> {
        (self.root != EMPTY).then_some(self.root)
    }

    /// The instance level as a tree for [`walk1`] (for the walks of `crate::query`).
    pub(crate) fn top_tree(&self) -> Tree<'_> {
        self.instance_tree()
    }

    /// The object of placed instance `k` and `ray` moved into its space (same `t`).
    pub(crate) fn object_ray_of(&self, k: usize, ray: &Ray) -> (u32, Ray) {
        let p = &self.placed[k];
        (p.object, object_ray(&p.to_object, ray, ray.tfar))
    }

    /// Placed instance `k`'s object, object-to-world transform and instance id.
    pub(crate) fn placed_of(&self, k: usize) -> (u32, Affine3A, u32) {
        let p = &self.placed[k];
        (p.object, self.instances[p.id as usize].transform, p.id)
    }

    /// [`world_hit`](Self::world_hit) of an object-space sphere hit (normal kept outward under
    /// mirrors), for the walks of `crate::query`.
    pub(crate) fn world_sphere_hit_of(&self, k: u32, hit: &Hit) -> Hit {
        self.world_hit(k, &self.placed[k as usize].sphere_hit(*hit))
    }

    /// [`world_hit`](Self::world_hit) for the walks of `crate::query`.
    pub(crate) fn world_hit_of(&self, k: u32, hit: &Hit) -> Hit {
        self.world_hit(k, hit)
    }
}

/// Entering lanes from which an incoherent closest-hit packet walks an object as a packet (with
/// its own switch to single rays below), if their origins are close (see
/// [`OBJECT_PACKET_SPREAD`]).
const OBJECT_PACKET_LANES: u32 = 8;

/// How many times the packet's origin extent an instance's world box must span for its
/// entering lanes to walk the object as a packet. Rays leaving nearby points of a surface pass the
/// same nodes around their origins, whatever their directions, so the per-lane tests of a packet
/// walk serve many of them at once there; origins spread over much of the object share few nodes.
/// One instance of a 433k-triangle sphereflake seen from close by: diffuse rays 3.7 → 4.4 Mrays/s
/// (1 thread); the forest and the big world, whose packets spread over many instances: unchanged
/// (PERFORMANCE.md).
const OBJECT_PACKET_SPREAD: f32 = 16.0;

/// Whether the lanes `active` of an incoherent closest-hit packet whose origins lie within
/// `spread` of each other walk the object of instance entry `pl` as a packet.
#[inline(always)]
fn packet_walks_object(active: u32, spread: f32, pl: &Placed) -> bool {
    let extent = (pl.hi[0] - pl.lo[0]).max(pl.hi[1] - pl.lo[1]).max(pl.hi[2] - pl.lo[2]);
    active.count_ones() >= OBJECT_PACKET_LANES && spread * OBJECT_PACKET_SPREAD <= extent
}

/// Whether `m` is finite with a finite inverse: what an instance's transform must be.
pub(crate) fn is_invertible(m: &Affine3A) -> bool {
    let det = m.matrix3.determinant();
    m.is_finite() && det != 0.0 && det.is_finite() && m.inverse().is_finite()
}

/// `ray` in object space over `(tnear, tfar]`; the direction keeps the transform's scale.
#[inline(always)]
fn object_ray(to_object: &Affine3A, ray: &Ray, tfar: f32) -> Ray {
    Ray {
        origin: to_object.transform_point3(ray.origin),
        dir: to_object.transform_vector3(ray.dir),
        tnear: ray.tnear,
        tfar,
    }
}

/// The lanes `active` of a packet in object space, with their current `tfar`, and the moved
/// origins and directions as vectors.
#[inline(always)]
fn object_packet<L: Level>(
    to_object: &Affine3A,
    pb: &PacketBoxes<L>,
    tfar: L::Pf,
    active: u32,
) -> (RayPacket, [[L::Pf; 3]; 2]) {
    let m = to_object.matrix3;
    let tr = to_object.translation;
    // The operations and their order of glam's `transform_point3` / `transform_vector3` (no fused
    // multiply-add), so a lane is moved exactly as the single-ray query moves it.
    let row = hot!(|a: usize, v: &[L::Pf; 3], with_t: bool| {
        let x = v[0] * L::Pf::splat(m.x_axis[a]) + v[1] * L::Pf::splat(m.y_axis[a]) + v[2] * L::Pf::splat(m.z_axis[a]);
        if with_t { x + L::Pf::splat(tr[a]) } else { x }
    });
    let o = [row(0, &pb.o, true), row(1, &pb.o, true), row(2, &pb.o, true)];
    let d = [row(0, &pb.d, false), row(1, &pb.d, false), row(2, &pb.d, false)];
    let q = RayPacket {
        ox: o[0].to_array(),
        oy: o[1].to_array(),
        oz: o[2].to_array(),
        dx: d[0].to_array(),
        dy: d[1].to_array(),
        dz: d[2].to_array(),
        tnear: pb.tnear.to_array(),
        tfar: tfar.to_array(),
        active,
    };
    (q, [o, d])
}

/// Levels of an object's tree whose boxes bound its instances: the world box of an instance is the
/// union of the moved boxes of the object's nodes this many levels down (at most 8² boxes), not
/// the moved root box. A turned object's root box moves into a box up to √2 wider on each turned
/// axis, empty at its corners; its children's boxes follow the geometry more closely.
const PLACED_BOX_LEVELS: usize = 2;

/// The world box of an instance of `bvh` under `m` (see [`PLACED_BOX_LEVELS`]), or `None` for an
/// object with nothing to hit.
fn placed_box(object: &Scene, m: &Affine3A) -> Option<Aabb> {
    fn grow(nodes: &[Node], m: &Affine3A, r: u32, lo: Vec3, hi: Vec3, levels: usize, out: &mut Aabb) {
        if levels == 0 || r == EMPTY || crate::bvh::node::is_leaf(r) {
            out.grow(&world_box(m, lo, hi));
            return;
        }
        let n = &nodes[r as usize];
        for i in 0..n.child.len() {
            if n.child[i] != EMPTY {
                let c = |a: usize| Vec3::new(n.bounds[a][i], n.bounds[a + 2][i], n.bounds[a + 4][i]);
                grow(nodes, m, n.child[i], c(0), c(1), levels - 1, out);
            }
        }
    }
    let (bvh, spheres, solids) = (object.bvh(), object.sphere_tree(), object.solid_tree());
    let mut out = Aabb::EMPTY;
    for (nodes, root, bounds) in [
        (&bvh.nodes, bvh.root, bvh.bounds),
        (&spheres.nodes, spheres.root, spheres.bounds),
        (&solids.nodes, solids.root, solids.bounds),
    ] {
        if let Some((lo, hi)) = bounds {
            grow(nodes, m, root, lo, hi, PLACED_BOX_LEVELS, &mut out);
        }
    }
    (out.lo.cmple(out.hi).all()).then_some(out)
}

/// An object-level hit of the instance walks: a triangle's leaf hit, or a sphere's record.
#[derive(Clone, Copy, Debug)]
enum ObjHit {
    Tri(LeafHit),
    Sphere(Hit),
}

impl ObjHit {
    fn t(&self) -> f32 {
        match self {
            ObjHit::Tri(h) => h.t,
            ObjHit::Sphere(h) => h.t,
        }
    }
}

/// The scale factor of a similarity transform (rotation or mirror times a uniform scale, plus a
/// translation): the common length of its three columns, if they are orthogonal and equally long
/// within 1e-5 relative. Spheres stay spheres only under these.
pub(crate) fn uniform_scale(m: &Affine3A) -> Option<f32> {
    let c = [m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis];
    let l = c.map(|v| v.length());
    let s = (l[0] + l[1] + l[2]) / 3.0;
    let tol = 1e-5 * s * s;
    let equal = l.iter().all(|&x| (x - s).abs() <= 1e-5 * s);
    let orthogonal = c[0].dot(c[1]).abs() <= tol && c[1].dot(c[2]).abs() <= tol && c[0].dot(c[2]).abs() <= tol;
    (s > 0.0 && s.is_finite() && equal && orthogonal).then_some(s)
}

/// The world box of an object box `lo..hi` under `m`: the bounds of its eight moved corners.
fn world_box(m: &Affine3A, lo: Vec3, hi: Vec3) -> Aabb {
    let mut b = Aabb::EMPTY;
    for c in 0..8 {
        let p = Vec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        );
        b.grow_point(Vec3A::from(m.transform_point3(p)));
    }
    b
}

impl Query for InstancedScene {
    const INCOHERENT_PACKETS: bool = true;

    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.trace1::<false>(ray).map(|(k, h)| self.world_hit(k, &self.object_hit(k, &h)))
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.trace1::<true>(ray).is_some()
    }

    fn intersect_packet_each(&self, rays: &RayPacket, mut f: impl FnMut(usize, &Hit)) {
        let mut hits = HitPacket::default();
        let mask = self.trace_packet::<false>(rays, Some(&mut hits));
        each_hit(&hits, mask, |lane, h| f(lane, h));
    }

    fn intersect_packet(&self, rays: &RayPacket, hits: &mut HitPacket) {
        self.trace_packet::<false>(rays, Some(hits));
    }

    fn occluded_packet(&self, rays: &RayPacket) -> u32 {
        self.trace_packet::<true>(rays, None)
    }
}

#[cfg(test)]
mod tests {
    use glam::Quat;

    use super::*;
    use crate::procedural::sphereflake;

    #[test]
    fn objects_out_of_the_cache_together_prefetch_in_their_walks() {
        let mesh = sphereflake(3, 8, 16);
        let object = Scene::build(vec![mesh], &BuildConfig::default()).unwrap();
        let bytes = object.stats().bytes;
        // One object between the two thresholds; two of them together above the lower one.
        assert!(bytes < INSTANCED_FAR_MEMORY_BYTES && 2 * bytes > INSTANCED_FAR_MEMORY_BYTES, "{bytes} B");
        assert!(!object.bvh().prefetch);
        let place = |objects: [usize; 2]| {
            objects
                .iter()
                .enumerate()
                .map(|(i, &o)| Instance::new(o, Affine3A::from_translation(Vec3::X * i as f32)))
                .collect()
        };
        let one = InstancedScene::from_scenes(vec![object.clone()], place([0, 0])).unwrap();
        assert!(!one.objects()[0].bvh().prefetch);
        let two = InstancedScene::from_scenes(vec![object.clone(), object], place([0, 1])).unwrap();
        assert!(two.objects().iter().all(|o| o.bvh().prefetch));
        // Prefetching changes no answer.
        let mut hits = 0;
        for k in 0..200 {
            let a = k as f32 * 0.031;
            let ray = Ray::new(
                Vec3::new(0.5, 0.0, 0.0) + 4.0 * Vec3::new(a.cos(), 0.3, a.sin()),
                Vec3::new(-a.cos(), -0.2, -a.sin()),
            );
            assert_eq!(one.intersect(&ray), two.intersect(&ray), "ray {k}");
            assert_eq!(one.occluded(&ray), two.occluded(&ray), "ray {k}");
            hits += one.intersect(&ray).is_some() as usize;
        }
        assert!(hits > 100, "{hits} hits");
    }

    #[test]
    fn turned_instances_get_boxes_that_bound_their_triangles_closer_than_the_moved_root_box() {
        let mesh = sphereflake(1, 8, 16);
        let object = Scene::build(vec![mesh.clone()], &BuildConfig::default()).unwrap();
        let (lo, hi) = object.bounds().unwrap();
        for (turn, scale) in [(0.7, Vec3::new(1.5, 0.7, 1.5)), (2.3, Vec3::ONE), (0.0, Vec3::splat(2.0))] {
            let m = Affine3A::from_scale_rotation_translation(
                scale,
                Quat::from_rotation_y(turn) * Quat::from_rotation_x(turn * 0.5),
                Vec3::new(3.0, -2.0, 1e3),
            );
            let b = placed_box(&object, &m).unwrap();
            let root = world_box(&m, lo, hi);
            // Every placed vertex inside (up to the rounding of moving a point), and the box
            // inside the moved root box.
            let slack = Vec3A::splat(1e-5) * (root.hi - root.lo).max_element();
            for p in mesh.positions() {
                let q = Vec3A::from(m.transform_point3(*p));
                assert!(q.cmpge(b.lo - slack).all() && q.cmple(b.hi + slack).all(), "{q} outside {b:?}");
            }
            assert!(b.lo.cmpge(root.lo).all() && b.hi.cmple(root.hi).all());
            if turn == 0.0 {
                // An unturned object's children fill its root box on every axis.
                assert_eq!(b, root);
            } else {
                assert!(b.half_area() < 0.9 * root.half_area(), "{} against {}", b.half_area(), root.half_area());
            }
        }
    }
}
