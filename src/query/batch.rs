//! The [`SpatialQuery`] queries over slices of rays or points, spread over the current rayon pool
//! (what the Python package calls with the GIL released). Results come in input order and do
//! not depend on the number of threads.

use glam::Vec3;
use rayon::prelude::*;

use super::{ClosestPoint, SpatialQuery};
use crate::ray::{Hit, Ray};

/// Rays or points per rayon job: small enough to balance two threads on a few thousand queries,
/// large enough that a job's overhead vanishes beside its walks.
const CHUNK: usize = 256;

/// All hits of many rays: `hits[splits[i]..splits[i + 1]]` are ray `i`'s, nearest first (Open3D's
/// `ray_splits`). With `merge`, each ray's hits are its [`crossings`](SpatialQuery::crossings),
/// otherwise its [`all_hits`](SpatialQuery::all_hits).
pub struct HitLists {
    /// Ray `i`'s hits are `hits[splits[i]..splits[i + 1]]` (length rays + 1).
    pub splits: Vec<usize>,
    /// Every ray's hits, ray after ray, nearest first.
    pub hits: Vec<Hit>,
}

/// [`SpatialQuery::crossings`] (with `merge`) or [`SpatialQuery::all_hits`] of every ray.
pub fn hit_lists<Q: SpatialQuery>(q: &Q, rays: &[Ray], merge: bool) -> HitLists {
    let per_chunk: Vec<(Vec<usize>, Vec<Hit>)> = rays
        .par_chunks(CHUNK)
        .map(|chunk| {
            let (mut counts, mut hits, mut one) = (Vec::with_capacity(chunk.len()), Vec::new(), Vec::new());
            for r in chunk {
                if merge {
                    q.crossings(r, &mut one);
                } else {
                    q.all_hits(r, &mut one);
                }
                counts.push(one.len());
                hits.extend_from_slice(&one);
            }
            (counts, hits)
        })
        .collect();
    let mut splits = Vec::with_capacity(rays.len() + 1);
    splits.push(0);
    let mut hits = Vec::with_capacity(per_chunk.iter().map(|c| c.1.len()).sum());
    for (counts, h) in per_chunk {
        for c in counts {
            splits.push(splits.last().copied().unwrap_or(0) + c);
        }
        hits.extend(h);
    }
    HitLists { splits, hits }
}

/// [`SpatialQuery::count_crossings`] (with `merge`) or the number of
/// [`all_hits`](SpatialQuery::all_hits) of every ray.
pub fn count_hits<Q: SpatialQuery>(q: &Q, rays: &[Ray], merge: bool, out: &mut [u32]) {
    assert_eq!(rays.len(), out.len(), "one count per ray");
    out.par_chunks_mut(CHUNK).zip(rays.par_chunks(CHUNK)).for_each(|(o, r)| {
        let mut one = Vec::new();
        for (o, r) in o.iter_mut().zip(r) {
            if merge {
                q.crossings(r, &mut one);
            } else {
                q.all_hits(r, &mut one);
            }
            *o = one.len() as u32;
        }
    });
}

/// [`SpatialQuery::closest_point`] of every point, unbounded.
pub fn closest_points<Q: SpatialQuery>(q: &Q, points: &[Vec3]) -> Vec<Option<ClosestPoint>> {
    points.par_iter().with_min_len(CHUNK).map(|&p| q.closest_point(p, f32::INFINITY)).collect()
}

/// [`SpatialQuery::signed_distance_votes`] of every point, with `rays` votes each
/// ([`DEFAULT_VOTES`](super::DEFAULT_VOTES) for [`SpatialQuery::signed_distance`]).
pub fn signed_distances<Q: SpatialQuery>(q: &Q, points: &[Vec3], rays: usize) -> Vec<f32> {
    points.par_iter().with_min_len(CHUNK).map(|&p| q.signed_distance_votes(p, rays)).collect()
}

/// [`SpatialQuery::contains_votes`] of every point, with `rays` votes each.
pub fn contains<Q: SpatialQuery>(q: &Q, points: &[Vec3], rays: usize) -> Vec<bool> {
    points.par_iter().with_min_len(CHUNK).map(|&p| q.contains_votes(p, rays)).collect()
}
