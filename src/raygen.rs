//! The ray classes of `../shared/BENCHMARKING.md`: primary rays from a camera, shadow rays from
//! primary hits towards a point light, and cosine-distributed diffuse rays from primary hits.
//! Deterministic: the same inputs and seed give bit-identical rays on every run and thread count.

use glam::Vec3;

use crate::camera::{Camera, tile_order};
use crate::ray::{HitStream, Ray, RayStream};

/// Primary rays of a `w × h` image in 4×4-tile order, with the pixel index (`y·w + x`) of each.
pub fn primary(camera: &Camera, w: u32, h: u32) -> (RayStream, Vec<u32>) {
    let order = tile_order(w, h);
    let rays = order.iter().map(|&(x, y)| camera.ray(x, y, w, h)).collect();
    let pixels = order.iter().map(|&(x, y)| y * w + x).collect();
    (rays, pixels)
}

/// The hit point `o + t·d` of every ray of `rays` that hit, with its index in the stream.
fn hit_points<'a>(rays: &'a RayStream, hits: &'a HitStream) -> impl Iterator<Item = (usize, Vec3, Ray)> + 'a {
    (0..rays.len().min(hits.len())).filter(move |&i| hits.get(i).is_some()).map(move |i| {
        let r = rays.get(i);
        (i, r.at(hits.t[i]), r)
    })
}

/// A shadow ray from every hit towards `light`: direction `light − p` (not normalized),
/// `tnear = epsilon`, `tfar = 0.9999`. Returns the rays and the index of the primary ray of each.
pub fn shadow(rays: &RayStream, hits: &HitStream, light: Vec3, epsilon: f32) -> (RayStream, Vec<u32>) {
    let mut out = RayStream::default();
    let mut src = Vec::new();
    for (i, p, _) in hit_points(rays, hits) {
        out.push(&Ray::segment(p, light - p, epsilon, 0.9999));
        src.push(i as u32);
    }
    (out, src)
}

/// A diffuse ray from every hit: cosine-distributed about the geometric normal turned to face the
/// incoming ray, `tnear = epsilon`, `tfar = +inf`. The random numbers of ray `i` depend only on
/// `seed` and `i`.
pub fn diffuse(rays: &RayStream, hits: &HitStream, seed: u64, epsilon: f32) -> (RayStream, Vec<u32>) {
    let mut out = RayStream::default();
    let mut src = Vec::new();
    for (i, p, r) in hit_points(rays, hits) {
        let ng = Vec3::new(hits.ng_x[i], hits.ng_y[i], hits.ng_z[i]);
        let mut n = ng.normalize_or_zero();
        if n == Vec3::ZERO {
            continue;
        }
        if n.dot(r.dir) > 0.0 {
            n = -n;
        }
        let mut rng = Pcg32::new(seed, i as u64);
        let d = cosine_direction(n, rng.next_f32(), rng.next_f32());
        out.push(&Ray::segment(p, d, epsilon, f32::INFINITY));
        src.push(i as u32);
    }
    (out, src)
}

/// A unit direction about `n` with density `cos θ / π` (Malley's method), from two uniform numbers.
pub fn cosine_direction(n: Vec3, u1: f32, u2: f32) -> Vec3 {
    let r = u1.sqrt();
    let phi = 2.0 * std::f32::consts::PI * u2;
    let (x, y) = (r * phi.cos(), r * phi.sin());
    let z = (1.0 - u1).max(0.0).sqrt();
    let (t, b) = n.any_orthonormal_pair();
    (t * x + b * y + n * z).normalize()
}

/// PCG32 (O'Neill 2014): a small, well-tested generator for reproducible ray sets, benches and
/// tests.
#[derive(Clone, Debug)]
pub struct Pcg32 {
    state: u64,
    inc: u64,
}

impl Pcg32 {
    /// A generator for stream `stream` of seed `seed`.
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut g = Self { state: 0, inc: (stream << 1) | 1 };
        g.next_u32();
        g.state = g.state.wrapping_add(seed);
        g.next_u32();
        g
    }

    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(6364136223846793005).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        xorshifted.rotate_right((old >> 59) as u32)
    }

    /// Uniform in `[0, 1)`.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_directions_lie_in_the_hemisphere_with_cosine_mean() {
        let n = Vec3::new(0.3, -0.8, 0.52).normalize();
        let mut rng = Pcg32::new(7, 0);
        let mut mean_cos = 0.0;
        let count = 20_000;
        for _ in 0..count {
            let d = cosine_direction(n, rng.next_f32(), rng.next_f32());
            assert!((d.length() - 1.0).abs() < 1e-5);
            let c = d.dot(n);
            assert!(c >= -1e-6);
            mean_cos += c as f64;
        }
        // E[cos θ] under the cosine density is 2/3.
        assert!((mean_cos / count as f64 - 2.0 / 3.0).abs() < 0.01);
    }

    #[test]
    fn generator_is_deterministic_and_spread() {
        let a: Vec<u32> = (0..4)
            .map({
                let mut g = Pcg32::new(1, 2);
                move |_| g.next_u32()
            })
            .collect();
        let b: Vec<u32> = (0..4)
            .map({
                let mut g = Pcg32::new(1, 2);
                move |_| g.next_u32()
            })
            .collect();
        assert_eq!(a, b);
        let c = Pcg32::new(1, 3).next_u32();
        assert_ne!(a[0], c);
    }
}
