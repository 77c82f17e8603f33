//! The renderer's cameras. The seeds: "mit Ray-Tracing sind andere Projektionen sehr einfach — z.B.
//! Fischauge, Omnimax, Panorama". Each maps a continuous image point `(x, y)` (pixels, `(0, 0)` the
//! top-left corner, `(w, h)` the bottom-right) to a ray, or to nothing where the projection has no
//! ray (outside a fisheye's circle): such pixels get the background colour.

use glam::Vec3;

use crate::ray::Ray;

/// How image points map to directions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// The lecture's ideal pinhole camera: an image plane at distance 1 whose width spans
    /// `fov_deg` horizontally (POV-Ray's `angle`); the height follows from the aspect ratio.
    Pinhole {
        /// Field of view in degrees.
        fov_deg: f32,
    },
    /// Parallel rays along the view direction from a window `width` scene units wide.
    Orthographic {
        /// Window width in scene units.
        width: f32,
    },
    /// Equidistant fisheye: the angle from the view axis grows linearly with the distance from
    /// the image centre, reaching `fov_deg / 2` on the inscribed circle (up to 360°).
    Fisheye {
        /// Field of view in degrees.
        fov_deg: f32,
    },
    /// POV-Ray's `omnimax`: a 180° dome projection, its axis shifted towards the bottom for wide
    /// images, nothing more than 45° below the axis (POV-Ray 3.7 `tracepixel.cpp`).
    Omnimax,
    /// Equirectangular panorama: longitude across the width (360°), latitude down the height
    /// (180°), the view direction in the image centre.
    Panorama,
}

/// A camera: position, orthonormal frame and projection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderCamera {
    /// Where the camera sits.
    pub eye: Vec3,
    /// Unit view direction, right and up vectors (right-handed: `right = forward × up`).
    pub forward: Vec3,
    /// Unit right vector.
    pub right: Vec3,
    /// Unit up vector.
    pub up: Vec3,
    /// How pixels map to directions.
    pub projection: Projection,
}

impl RenderCamera {
    /// A camera at `eye` looking at `at`, `up` roughly up. `None` if the three do not span a view
    /// or the projection's parameters are out of range (pinhole `fov` in (0, 180), fisheye in
    /// (0, 360], orthographic width positive, all finite).
    pub fn look_at(eye: Vec3, at: Vec3, up: Vec3, projection: Projection) -> Option<Self> {
        let forward = (at - eye).normalize_or_zero();
        let right = forward.cross(up).normalize_or_zero();
        let ok = match projection {
            Projection::Pinhole { fov_deg } => fov_deg > 0.0 && fov_deg < 180.0,
            Projection::Orthographic { width } => width > 0.0 && width.is_finite(),
            Projection::Fisheye { fov_deg } => fov_deg > 0.0 && fov_deg <= 360.0,
            Projection::Omnimax | Projection::Panorama => true,
        };
        if !ok || !eye.is_finite() || forward == Vec3::ZERO || right == Vec3::ZERO {
            return None;
        }
        Some(Self { eye, forward, right, up: right.cross(forward), projection })
    }

    /// The ray through image point `(x, y)` of a `w × h` image (pixel centres at `i + 0.5`).
    /// Directions are not normalized for the pinhole (the lecture's `O + s·x + t·y − A`) and are
    /// unit vectors otherwise.
    pub fn ray(&self, x: f32, y: f32, w: u32, h: u32) -> Option<Ray> {
        let (w, h) = (w as f32, h as f32);
        let aspect = h / w;
        // Image coordinates in [-1, 1] across the width; the height scaled by the aspect ratio.
        let sx = 2.0 * x / w - 1.0;
        let sy = (1.0 - 2.0 * y / h) * aspect;
        let (f, r, u) = (self.forward, self.right, self.up);
        match self.projection {
            Projection::Pinhole { fov_deg } => {
                let t = (fov_deg.to_radians() * 0.5).tan();
                Some(Ray::new(self.eye, f + r * (sx * t) + u * (sy * t)))
            }
            Projection::Orthographic { width } => {
                let half = 0.5 * width;
                Some(Ray::new(self.eye + r * (sx * half) + u * (sy * half), f))
            }
            Projection::Fisheye { fov_deg } => {
                // The circle inscribed in the image's smaller side.
                let k = aspect.min(1.0);
                let (nx, ny) = (sx / k, sy / k);
                let rad = (nx * nx + ny * ny).sqrt();
                if rad > 1.0 {
                    return None;
                }
                Some(Ray::new(self.eye, polar(self, nx, ny, rad, rad * fov_deg.to_radians() * 0.5)))
            }
            Projection::Omnimax => {
                // POV-Ray's mapping: coordinates in [-1, 1] both ways, the dome's centre moved
                // down for images wider than 1.283458 : 1, then a polynomial from radius to angle.
                let inv = 1.0 / aspect; // width / height
                let mut nx = sx;
                let mut ny = sy / aspect;
                if inv > 1.0 {
                    if inv > 1.283_458 {
                        nx *= inv / 1.283_458;
                        ny = (ny - 1.0) / 1.283_458 + 1.0;
                    } else {
                        ny = (ny - 1.0) / inv + 1.0;
                    }
                } else {
                    ny /= inv;
                }
                let rad = (nx * nx + ny * ny).sqrt();
                if rad > 1.0 {
                    return None;
                }
                let theta = 1.411_269 * rad - 0.094_39 * rad.powi(3) + 0.256_74 * rad.powi(5);
                let d = polar(self, nx, ny, rad, theta);
                // Nothing more than 45° below the projection axis.
                if d.dot(u) + d.dot(f) < 0.0 {
                    return None;
                }
                Some(Ray::new(self.eye, d))
            }
            Projection::Panorama => {
                let lon = sx * std::f32::consts::PI;
                let lat = (1.0 - 2.0 * y / h) * std::f32::consts::FRAC_PI_2;
                let d = (f * lon.cos() + r * lon.sin()) * lat.cos() + u * lat.sin();
                Some(Ray::new(self.eye, d))
            }
        }
    }
}

/// The unit direction at angle `theta` from the view axis, towards image direction `(nx, ny)` at
/// image radius `rad`.
fn polar(c: &RenderCamera, nx: f32, ny: f32, rad: f32, theta: f32) -> Vec3 {
    let (cos_phi, sin_phi) = if rad > 0.0 { (nx / rad, ny / rad) } else { (1.0, 0.0) };
    let (s, co) = theta.sin_cos();
    c.right * (cos_phi * s) + c.up * (sin_phi * s) + c.forward * co
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(p: Projection) -> RenderCamera {
        RenderCamera::look_at(Vec3::ZERO, Vec3::new(0.0, 0.0, -1.0), Vec3::Y, p).unwrap()
    }

    fn dir(c: &RenderCamera, x: f32, y: f32, w: u32, h: u32) -> Option<Vec3> {
        c.ray(x, y, w, h).map(|r| r.dir.normalize())
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    #[test]
    fn pinhole_centre_edges_and_aspect() {
        let c = cam(Projection::Pinhole { fov_deg: 90.0 });
        assert!(close(dir(&c, 100.0, 50.0, 200, 100).unwrap(), Vec3::NEG_Z));
        // The left edge's middle is 45° to the left (horizontal field of view).
        let l = dir(&c, 0.0, 50.0, 200, 100).unwrap();
        assert!(close(l, Vec3::new(-1.0, 0.0, -1.0).normalize()), "{l}");
        // The top edge's middle: tan = 0.5 (half the width's extent at aspect 1:2).
        let t = dir(&c, 100.0, 0.0, 200, 100).unwrap();
        assert!(close(t, Vec3::new(0.0, 0.5, -1.0).normalize()), "{t}");
    }

    #[test]
    fn orthographic_rays_are_parallel() {
        let c = cam(Projection::Orthographic { width: 4.0 });
        let a = c.ray(0.0, 0.0, 100, 100).unwrap();
        let b = c.ray(100.0, 100.0, 100, 100).unwrap();
        assert_eq!(a.dir, b.dir);
        assert!(close(a.origin, Vec3::new(-2.0, 2.0, 0.0)) && close(b.origin, Vec3::new(2.0, -2.0, 0.0)));
    }

    #[test]
    fn fisheye_is_equidistant_up_to_360() {
        let c = cam(Projection::Fisheye { fov_deg: 180.0 });
        assert!(close(dir(&c, 50.0, 50.0, 100, 100).unwrap(), Vec3::NEG_Z));
        // On the circle: 90° off axis; halfway: 45°.
        assert!(close(dir(&c, 100.0, 50.0, 100, 100).unwrap(), Vec3::X));
        assert!(close(dir(&c, 50.0, 25.0, 100, 100).unwrap(), Vec3::new(0.0, 1.0, -1.0).normalize()));
        // Corners lie outside the circle.
        assert!(c.ray(0.0, 0.0, 100, 100).is_none());
        // 360°: the circle's edge looks backwards.
        let c = cam(Projection::Fisheye { fov_deg: 360.0 });
        assert!(close(dir(&c, 0.0, 50.0, 100, 100).unwrap(), Vec3::Z));
    }

    #[test]
    fn omnimax_follows_povray() {
        let c = cam(Projection::Omnimax);
        // Square image: the centre looks along the axis; the right edge's middle at POV-Ray's
        // polynomial of the radius (at radius 1 it exceeds 90° and, like POV-Ray, has no ray).
        assert!(close(dir(&c, 50.0, 50.0, 100, 100).unwrap(), Vec3::NEG_Z));
        let e = dir(&c, 99.0, 50.0, 100, 100).unwrap();
        let rad = 0.98f32;
        let theta = 1.411_269 * rad - 0.094_39 * rad.powi(3) + 0.256_74 * rad.powi(5);
        assert!(close(e, Vec3::new(theta.sin(), 0.0, -theta.cos())), "{e}");
        assert!(c.ray(100.0, 50.0, 100, 100).is_none());
        // More than 45° below the axis: no ray.
        assert!(c.ray(50.0, 100.0, 100, 100).is_none());
    }

    #[test]
    fn panorama_covers_the_sphere() {
        let c = cam(Projection::Panorama);
        assert!(close(dir(&c, 100.0, 50.0, 200, 100).unwrap(), Vec3::NEG_Z));
        assert!(close(dir(&c, 150.0, 50.0, 200, 100).unwrap(), Vec3::X));
        assert!(close(dir(&c, 0.0, 50.0, 200, 100).unwrap(), Vec3::Z));
        assert!(close(dir(&c, 100.0, 0.0, 200, 100).unwrap(), Vec3::Y));
    }

    #[test]
    fn bad_cameras_are_refused() {
        let p = Projection::Pinhole { fov_deg: 60.0 };
        assert!(RenderCamera::look_at(Vec3::ZERO, Vec3::ZERO, Vec3::Y, p).is_none());
        assert!(RenderCamera::look_at(Vec3::ZERO, Vec3::Y, Vec3::Y, p).is_none());
        assert!(RenderCamera::look_at(Vec3::ZERO, Vec3::X, Vec3::Y, Projection::Pinhole { fov_deg: 180.0 }).is_none());
        assert!(RenderCamera::look_at(Vec3::NAN, Vec3::X, Vec3::Y, p).is_none());
        assert!(
            RenderCamera::look_at(Vec3::ZERO, Vec3::X, Vec3::Y, Projection::Fisheye { fov_deg: f32::NAN }).is_none()
        );
    }
}
