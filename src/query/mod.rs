//! Queries beyond the closest and any hit, for the people who ask a scene more than "what does
//! this ray hit first": every hit along a ray, the crossings of a surface counted once each, the
//! nearest surface point, inside/outside and signed distance. Implemented by the flat
//! [`Scene`] and the two-level [`InstancedScene`]; the
//! parallel batch forms over slices are in [`batch`].
//!
//! ```
//! use glam::Vec3;
//! use strahl::query::SpatialQuery;
//! use strahl::{BuildConfig, Ray, Scene, procedural};
//!
//! // A closed unit cube, built for the watertight test.
//! let scene = Scene::build(vec![procedural::cuboid(Vec3::ZERO, Vec3::ONE)], &BuildConfig::watertight())?;
//! // A ray through the cube crosses its surface twice.
//! let ray = Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z);
//! assert_eq!(scene.count_crossings(&ray), 2);
//! assert!(scene.contains(Vec3::splat(0.5)));
//! assert!((scene.signed_distance(Vec3::new(0.5, 0.5, 0.25)) + 0.25).abs() < 1e-6);
//! # Ok::<(), strahl::Error>(())
//! ```

mod all_hits;
pub mod batch;
mod closest;

use glam::Vec3;

pub use closest::ClosestPoint;

use crate::instance::InstancedScene;
use crate::ray::{Hit, Ray};
use crate::scene::{Query, Scene};

/// Directions of the rays [`SpatialQuery::contains_votes`] casts, the first `rays` of them: unit
/// vectors along no axis or diagonal, so that none runs along the faces, edges or diagonals of
/// axis-aligned geometry.
pub const INSIDE_DIRECTIONS: [Vec3; 7] = [
    Vec3::new(0.486_164_1, 0.699_861_4, 0.523_461_36),
    Vec3::new(-0.597_017_2, 0.298_508_63, -0.744_649_9),
    Vec3::new(0.254_628_85, -0.890_008_2, 0.378_188_4),
    Vec3::new(-0.878_836_2, 0.416_927_6, 0.231_987_6),
    Vec3::new(-0.609_615_4, 0.732_779, 0.302_330_8),
    Vec3::new(-0.598_727_2, 0.711_324_4, -0.368_162_1),
    Vec3::new(-0.159_409_3, 0.480_261_8, -0.862_518),
];

/// Rays [`SpatialQuery::contains`] and [`SpatialQuery::signed_distance`] vote with.
pub const DEFAULT_VOTES: usize = 3;

/// Queries that need more than the first hit. Every query gives a defined answer for any input:
/// invalid rays (see [`Ray::is_valid`]) hit nothing, non-finite query points have no closest
/// point and a NaN signed distance, an empty scene has no hits and no surface (infinite
/// distance, never inside).
pub trait SpatialQuery: Query {
    /// Calls `f` for every triangle `ray` hits in `(tnear, tfar]`, in no particular order, in
    /// one walk of the BVH. A triangle that spatial splits stored in several leaves may come
    /// more than once; [`all_hits`](Self::all_hits) removes such repeats.
    fn for_each_hit(&self, ray: &Ray, f: impl FnMut(&Hit));

    /// The surface point nearest to `p` no farther than `max_distance` (`f32::INFINITY` for
    /// any), or `None`. Triangles and spheres only: a scene's [`Solid`](crate::Solid)s are not
    /// searched (their distance fields are not yet written).
    fn closest_point(&self, p: Vec3, max_distance: f32) -> Option<ClosestPoint>;

    /// Every triangle `ray` hits in `(tnear, tfar]`, nearest first, each once, into `out`
    /// (cleared first). Hits at the same `t` are ordered by instance, geometry and triangle id.
    fn all_hits(&self, ray: &Ray, out: &mut Vec<Hit>) {
        out.clear();
        self.for_each_hit(ray, |h| out.push(*h));
        out.sort_unstable_by(|a, b| {
            a.t.total_cmp(&b.t)
                .then(a.inst_id.cmp(&b.inst_id))
                .then(a.geom_id.cmp(&b.geom_id))
                .then(a.prim_id.cmp(&b.prim_id))
        });
        out.dedup_by(|a, b| (a.inst_id, a.geom_id, a.prim_id) == (b.inst_id, b.geom_id, b.prim_id) && a.t == b.t);
    }

    /// The surface crossings of `ray` in `(tnear, tfar]`, nearest first, into `out`: its
    /// [`all_hits`](Self::all_hits) with the hits of one crossing merged (see
    /// [`merge_crossings`]). On a closed mesh built with [`BuildConfig::watertight`] this is
    /// the list whose length's parity says inside or outside.
    ///
    /// [`BuildConfig::watertight`]: crate::BuildConfig::watertight
    fn crossings(&self, ray: &Ray, out: &mut Vec<Hit>) {
        self.all_hits(ray, out);
        merge_crossings(ray, out);
    }

    /// How many times `ray` crosses the surface in `(tnear, tfar]` (see
    /// [`crossings`](Self::crossings)).
    fn count_crossings(&self, ray: &Ray) -> usize {
        let mut hits = Vec::new();
        self.crossings(ray, &mut hits);
        hits.len()
    }

    /// Whether `p` lies inside the closed surface: the parity of the crossings of rays from `p`
    /// in the first three [`INSIDE_DIRECTIONS`], by majority. With the watertight triangle test and
    /// the conservative box test ([`BuildConfig::watertight`]) no ray slips between the
    /// triangles of a closed mesh and [`merge_crossings`] counts a ray through a shared edge or
    /// vertex once, so one ray already answers right; the vote outvotes a ray that meets a hole
    /// of a mesh that is not quite closed, or grazes a silhouette edge where the
    /// two faces' `t` differ by more than the merge tolerance. A point on the surface may come
    /// out either way. Points that are not finite are outside.
    ///
    /// [`BuildConfig::watertight`]: crate::BuildConfig::watertight
    fn contains(&self, p: Vec3) -> bool {
        self.contains_votes(p, DEFAULT_VOTES)
    }

    /// [`contains`](Self::contains) by the majority of the first `rays` of the
    /// [`INSIDE_DIRECTIONS`] (clamped to 1..=7; with an even number a tie counts as outside).
    /// One ray is what Open3D casts by default: right on a closed mesh built watertight, wrong
    /// wherever it meets a hole.
    fn contains_votes(&self, p: Vec3, rays: usize) -> bool {
        if !p.is_finite() {
            return false;
        }
        let rays = rays.clamp(1, INSIDE_DIRECTIONS.len());
        let mut hits = Vec::new();
        let odd = INSIDE_DIRECTIONS[..rays]
            .iter()
            .filter(|&&d| {
                self.crossings(&Ray::new(p, d), &mut hits);
                hits.len() % 2 == 1
            })
            .count();
        2 * odd > rays
    }

    /// Distance from `p` to the surface, negative inside (see [`contains`](Self::contains)),
    /// as Open3D's `compute_signed_distance`. `+∞` in an empty scene; NaN for a point that is
    /// not finite.
    fn signed_distance(&self, p: Vec3) -> f32 {
        self.signed_distance_votes(p, DEFAULT_VOTES)
    }

    /// [`signed_distance`](Self::signed_distance) with the inside test of
    /// [`contains_votes`](Self::contains_votes).
    fn signed_distance_votes(&self, p: Vec3, rays: usize) -> f32 {
        if !p.is_finite() {
            return f32::NAN;
        }
        let Some(c) = self.closest_point(p, f32::INFINITY) else {
            return f32::INFINITY;
        };
        if self.contains_votes(p, rays) { -c.distance } else { c.distance }
    }
}

/// Merges the hits of one surface crossing in a list sorted by `t` (as
/// [`SpatialQuery::all_hits`] gives it): a ray through an edge or a vertex shared by several
/// triangles hits each of them (the watertight test guarantees at least one, and reports all),
/// at the same point up to rounding. Hits within a tolerance of the run's first hit
/// (`64·ε` times the largest coordinate of the ray's origin or hit point, over the direction's
/// length: the rounding of the hit point, in units of `t`) that face the same way (the sign of
/// `ng · dir`) are one crossing, and the first of them stands for it. Hits there that face
/// opposite ways — a ray grazing a silhouette edge, entering and leaving at once — stay two, so
/// the parity of the count is still right. The price: two distinct surfaces closer than the
/// tolerance along the ray and facing the same way count as one.
pub fn merge_crossings(ray: &Ray, hits: &mut Vec<Hit>) {
    let len = ray.dir.length();
    if hits.len() < 2 || len == 0.0 {
        return;
    }
    let tol = |t: f32| 64.0 * f32::EPSILON * ray.origin.abs().max_element().max(ray.at(t).abs().max_element()) / len;
    let facing = |h: &Hit| h.ng.dot(ray.dir) > 0.0;
    // In place: `hits[..kept]` are the hits kept so far; `run` starts the current run of
    // coincident hits among them (no allocation: this runs once per ray of every count).
    let (mut kept, mut run) = (0, 0);
    for i in 0..hits.len() {
        let h = hits[i];
        if run < kept && h.t - hits[run].t <= tol(h.t) {
            if hits[run..kept].iter().any(|k| facing(k) == facing(&h)) {
                continue;
            }
        } else {
            run = kept;
        }
        hits[kept] = h;
        kept += 1;
    }
    hits.truncate(kept);
}

impl SpatialQuery for Scene {
    fn for_each_hit(&self, ray: &Ray, mut f: impl FnMut(&Hit)) {
        let bvh = self.bvh();
        bvh.each_hit(ray, |h| f(&bvh.hit_record(h)));
        self.sphere_tree().each_hit(ray, &mut f);
        self.solid_tree().each_hit(ray, f);
    }

    fn closest_point(&self, p: Vec3, max_distance: f32) -> Option<ClosestPoint> {
        self.closest_point_impl(p, max_distance)
    }
}

impl SpatialQuery for InstancedScene {
    fn for_each_hit(&self, ray: &Ray, f: impl FnMut(&Hit)) {
        self.each_hit(ray, f);
    }

    fn closest_point(&self, p: Vec3, max_distance: f32) -> Option<ClosestPoint> {
        self.closest_point_impl(p, max_distance)
    }
}
