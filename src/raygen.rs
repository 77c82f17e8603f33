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

/// How secondary rays avoid re-hitting the surface they start on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Offset {
    /// Origin on the surface, `tnear = epsilon` (BENCHMARKING.md uses 1e-4 × the scene diagonal):
    /// simple, but the right epsilon depends on the scene's scale.
    Epsilon(f32),
    /// Origin moved off the surface by [`offset_ray_origin`](crate::ray::offset_ray_origin) to the
    /// side the ray leaves from, `tnear = 0`: independent of the scene's scale.
    Normal,
}

impl Offset {
    /// Origin and tnear for a ray leaving point `p` of a surface with normal `n` in direction `d`.
    pub fn apply(self, p: Vec3, n: Vec3, d: Vec3) -> (Vec3, f32) {
        match self {
            Offset::Epsilon(e) => (p, e),
            Offset::Normal => (crate::ray::offset_ray_origin(p, if n.dot(d) >= 0.0 { n } else { -n }), 0.0),
        }
    }
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
    shadow_with(rays, hits, light, Offset::Epsilon(epsilon))
}

/// [`shadow`] with a choice of [`Offset`]. With [`Offset::Normal`] the direction is still
/// `light − p` from the surface point, so `tfar = 0.9999` still ends just before the light.
pub fn shadow_with(rays: &RayStream, hits: &HitStream, light: Vec3, offset: Offset) -> (RayStream, Vec<u32>) {
    let mut out = RayStream::default();
    let mut src = Vec::new();
    for (i, p, _) in hit_points(rays, hits) {
        let n = Vec3::new(hits.ng_x[i], hits.ng_y[i], hits.ng_z[i]);
        let (o, tnear) = offset.apply(p, n, light - p);
        out.push(&Ray::segment(o, light - o, tnear, 0.9999));
        src.push(i as u32);
    }
    (out, src)
}

/// A diffuse ray from every hit: cosine-distributed about the geometric normal turned to face the
/// incoming ray, `tnear = epsilon`, `tfar = +inf`. The random numbers of ray `i` depend only on
/// `seed` and `i`.
pub fn diffuse(rays: &RayStream, hits: &HitStream, seed: u64, epsilon: f32) -> (RayStream, Vec<u32>) {
    diffuse_with(rays, hits, seed, Offset::Epsilon(epsilon))
}

/// [`diffuse`] with a choice of [`Offset`].
pub fn diffuse_with(rays: &RayStream, hits: &HitStream, seed: u64, offset: Offset) -> (RayStream, Vec<u32>) {
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
        let (o, tnear) = offset.apply(p, n, d);
        out.push(&Ray::segment(o, d, tnear, f32::INFINITY));
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

    /// The next 32 random bits.
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

/// A uniform random unit vector.
pub fn uniform_direction(rng: &mut Pcg32) -> Vec3 {
    let z = 1.0 - 2.0 * rng.next_f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * rng.next_f32();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// `n` rays from random points within `radius` of `center`, in random directions: from inside a
/// closed mesh around them every ray must hit (Embree's verify `WatertightTest`).
pub fn inside_rays(center: Vec3, radius: f32, n: usize, seed: u64) -> RayStream {
    let mut rng = Pcg32::new(seed, 31);
    (0..n)
        .map(|_| {
            let o = center + uniform_direction(&mut rng) * radius * rng.next_f32().cbrt();
            Ray::new(o, uniform_direction(&mut rng))
        })
        .collect()
}

/// Rays aimed from outside at points on interior edges of a closed mesh (edges shared by exactly
/// two triangles), each with the indices of those two triangles. The origin lies along the mean of
/// the two normals, at twice the edge's length, jittered sideways so that rays are not all
/// perpendicular to the surface.
pub fn edge_aimed_rays(mesh: &crate::TriangleMesh, n: usize, seed: u64) -> Vec<(Ray, [u32; 2])> {
    use std::collections::HashMap;
    let mut faces: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for (t, idx) in mesh.indices().iter().enumerate() {
        if !mesh.is_hittable(t) {
            continue;
        }
        for k in 0..3 {
            let (a, b) = (idx[k], idx[(k + 1) % 3]);
            faces.entry((a.min(b), a.max(b))).or_default().push(t as u32);
        }
    }
    let mut edges: Vec<((u32, u32), [u32; 2])> =
        faces.into_iter().filter(|(_, f)| f.len() == 2).map(|(e, f)| (e, [f[0], f[1]])).collect();
    edges.sort_unstable();
    if edges.is_empty() {
        return Vec::new();
    }
    let mut rng = Pcg32::new(seed, 32);
    let normal = |t: u32| {
        let [a, b, c] = mesh.triangle(t as usize);
        (b - a).cross(c - a).normalize_or_zero()
    };
    let p = mesh.positions();
    (0..n)
        .map(|_| {
            let ((a, b), tris) = edges[(rng.next_u32() as usize) % edges.len()];
            let (pa, pb) = (p[a as usize], p[b as usize]);
            let target = pa.lerp(pb, 0.05 + 0.9 * rng.next_f32());
            let len = (pb - pa).length();
            let n = (normal(tris[0]) + normal(tris[1])).normalize_or_zero();
            let jitter = uniform_direction(&mut rng) * 0.5;
            let o = target + (n + jitter - n * jitter.dot(n)).normalize_or_zero() * 2.0 * len;
            (Ray::new(o, target - o), tris)
        })
        .collect()
}

/// Rays aimed from outside at vertices of a mesh, each with the triangles around the vertex.
pub fn vertex_aimed_rays(mesh: &crate::TriangleMesh, n: usize, seed: u64) -> Vec<(Ray, Vec<u32>)> {
    let mut fan: Vec<Vec<u32>> = vec![Vec::new(); mesh.positions().len()];
    for (t, idx) in mesh.indices().iter().enumerate() {
        if mesh.is_hittable(t) {
            for &v in idx {
                fan[v as usize].push(t as u32);
            }
        }
    }
    let verts: Vec<usize> = (0..fan.len()).filter(|&v| fan[v].len() >= 3).collect();
    if verts.is_empty() {
        return Vec::new();
    }
    let mut rng = Pcg32::new(seed, 33);
    (0..n)
        .map(|_| {
            let v = verts[(rng.next_u32() as usize) % verts.len()];
            let target = mesh.positions()[v];
            let mut nrm = Vec3::ZERO;
            let mut size = 0.0f32;
            for &t in &fan[v] {
                let [a, b, c] = mesh.triangle(t as usize);
                nrm += (b - a).cross(c - a).normalize_or_zero();
                size = size.max((b - a).length()).max((c - a).length());
            }
            let nrm = nrm.normalize_or_zero();
            let jitter = uniform_direction(&mut rng) * 0.5;
            let o = target + (nrm + jitter - nrm * jitter.dot(nrm)).normalize_or_zero() * 2.0 * size;
            (Ray::new(o, target - o), fan[v].clone())
        })
        .collect()
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
