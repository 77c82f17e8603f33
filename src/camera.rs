//! The pinhole camera of the seeds (pixel-centre rays through an image plane) in the exact form
//! `../shared/BENCHMARKING.md` prescribes, so that strahl and Embree trace bit-identical rays.

use glam::Vec3;

use crate::ray::Ray;

/// A pinhole camera with a square field of view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Where the camera sits.
    pub eye: Vec3,
    /// Unit forward, right and up vectors.
    pub forward: Vec3,
    /// Unit right vector.
    pub right: Vec3,
    /// Unit up vector.
    pub up: Vec3,
    /// `tan(fov / 2)`.
    pub tan_half_fov: f32,
}

impl Camera {
    /// A camera at `eye` looking at `at`, with `up` roughly up and a field of view of `fov_deg`
    /// degrees both ways. `f = normalize(at − eye)`, `r = normalize(f × up)`, `u = r × f`.
    pub fn look_at(eye: Vec3, at: Vec3, up: Vec3, fov_deg: f32) -> Self {
        let forward = (at - eye).normalize();
        let right = forward.cross(up).normalize();
        let up = right.cross(forward);
        Self { eye, forward, right, up, tan_half_fov: (fov_deg.to_radians() * 0.5).tan() }
    }

    /// The ray through the centre of pixel `(px, py)` of a `w × h` image: direction
    /// `f + sx·r + sy·u`, not normalized, over `(0, +inf]`.
    pub fn ray(&self, px: u32, py: u32, w: u32, h: u32) -> Ray {
        let sx = ((px as f32 + 0.5) / w as f32 * 2.0 - 1.0) * self.tan_half_fov;
        let sy = (1.0 - (py as f32 + 0.5) / h as f32 * 2.0) * self.tan_half_fov;
        Ray::new(self.eye, self.forward + self.right * sx + self.up * sy)
    }
}

/// Pixel coordinates of a `w × h` image in 4×4-tile order: 8×8 blocks row by row, the four 4×4
/// tiles of a block row by row, pixels within a tile row by row. Sixteen consecutive entries form
/// one packet, and 64 one block (a [`GROUP`](crate::GROUP) of packets). Pixels of partial
/// tiles at the right and bottom edges are listed too, so every pixel appears exactly once.
pub fn tile_order(w: u32, h: u32) -> Vec<(u32, u32)> {
    let mut out = Vec::with_capacity(w as usize * h as usize);
    for by in (0..h).step_by(8) {
        for bx in (0..w).step_by(8) {
            for ty in (by..(by + 8).min(h)).step_by(4) {
                for tx in (bx..(bx + 8).min(w)).step_by(4) {
                    for y in ty..(ty + 4).min(h) {
                        for x in tx..(tx + 4).min(w) {
                            out.push((x, y));
                        }
                    }
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_looks_forward() {
        let c = Camera::look_at(Vec3::ZERO, Vec3::new(0.0, 0.0, -5.0), Vec3::Y, 60.0);
        let r = c.ray(512, 512, 1025, 1025);
        assert!((r.dir - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        // Corners span tan(30°) both ways; the top-left pixel looks up and left.
        let tl = c.ray(0, 0, 2, 2);
        assert!(tl.dir.x < 0.0 && tl.dir.y > 0.0);
    }

    #[test]
    fn tile_order_covers_every_pixel_once() {
        let mut o = tile_order(10, 7);
        assert_eq!(o.len(), 70);
        assert_eq!(&o[..4], &[(0, 0), (1, 0), (2, 0), (3, 0)]);
        // The second tile is the one to the right, the third the one below the first.
        assert_eq!((o[16], o[32]), ((4, 0), (0, 4)));
        o.sort_unstable();
        o.dedup();
        assert_eq!(o.len(), 70);
    }
}
