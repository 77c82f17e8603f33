//! The lecture's ray tree ("excellent for debugging") as a picture: the scene rendered from a
//! second viewpoint, with every ray of one pixel's tree drawn over it as a line, coloured by kind,
//! hidden where the scene's surfaces lie in front of it.

use glam::Vec3;

use super::camera::{Projection, RenderCamera};
use super::image::Image;
use super::{RayKind, Renderer, TreeNode};
use crate::error::{Error, Result};
use crate::ray::{HitStream, RayStream};
use crate::scene::{Coherence, Query};

/// Line colours (linear RGB) by ray kind; blocked shadow feelers are drawn dark red.
pub fn kind_colour(kind: RayKind, blocked: bool) -> Vec3 {
    match kind {
        RayKind::Primary => Vec3::new(1.0, 1.0, 1.0),
        RayKind::Shadow if blocked => Vec3::new(0.5, 0.0, 0.0),
        RayKind::Shadow => Vec3::new(1.0, 0.85, 0.0),
        RayKind::Reflected => Vec3::new(0.0, 0.6, 1.0),
        RayKind::Refracted => Vec3::new(1.0, 0.0, 1.0),
    }
}

/// Where a tree node's segment ends: its hit (or blocker), the light for an unblocked feeler, or
/// `miss_length` along the direction for rays that leave the scene.
pub fn segment_end(n: &TreeNode, miss_length: f32) -> Vec3 {
    let o = Vec3::from(n.origin);
    let d = Vec3::from(n.dir);
    match (n.t, n.tfar) {
        (Some(t), _) => o + d * t,
        (None, Some(tfar)) => o + d * tfar,
        (None, None) => o + d.normalize_or_zero() * miss_length,
    }
}

/// The centre and radius of a tree's origins and hit points (rays that leave the scene have no
/// end point and do not count); `None` for an empty tree.
pub fn tree_extent(nodes: &[TreeNode]) -> Option<(Vec3, f32)> {
    let points: Vec<Vec3> = nodes
        .iter()
        .flat_map(|n| {
            let o = Vec3::from(n.origin);
            [Some(o), n.t.map(|t| o + Vec3::from(n.dir) * t)]
        })
        .flatten()
        .filter(|p| p.is_finite())
        .collect();
    if points.is_empty() {
        return None;
    }
    let centre = points.iter().copied().sum::<Vec3>() / points.len() as f32;
    let radius = points.iter().map(|p| (*p - centre).length()).fold(0.0, f32::max);
    Some((centre, radius.max(1e-3)))
}

/// A viewpoint beside `camera` that sees the whole tree from the side: from the tree's centre,
/// towards the camera turned right and up, far enough for the tree to fill most of the view.
/// `None` for an empty tree.
pub fn side_view(camera: &RenderCamera, nodes: &[TreeNode], fov_deg: f32) -> Option<RenderCamera> {
    let (centre, radius) = tree_extent(nodes)?;
    let back = camera.eye - centre;
    let d = back.length().max(1e-3);
    let out = (back + camera.right * (0.9 * d) + camera.up * (0.6 * d)).normalize_or(camera.up);
    let dist = 1.2 * radius / (fov_deg.to_radians() * 0.5).tan();
    RenderCamera::look_at(centre + out * dist, centre, camera.up, Projection::Pinhole { fov_deg })
}

impl<Q: Query> Renderer<'_, Q> {
    /// The picture of a ray tree seen through `view` (a pinhole camera), at this renderer's image
    /// size: the scene rendered from `view`, then each ray's segment drawn two pixels wide, in
    /// full where no surface of the scene lies in front of it and blended at 35% where one does
    /// (rays inside glass stay visible). Rays that leave the scene are drawn `miss_length` long.
    pub fn ray_tree_picture(&self, nodes: &[TreeNode], view: RenderCamera, miss_length: f32) -> Result<Image> {
        let Projection::Pinhole { fov_deg } = view.projection else {
            return Err(Error::RenderSettings("the ray tree's view must be a pinhole camera".into()));
        };
        let seen = Renderer { camera: view, ..*self };
        let (mut image, _) = seen.render(&|_| {})?;
        let (w, h) = (self.settings.width, self.settings.height);
        // Depth buffer: distance from the eye to the first surface through each pixel centre.
        let mut rays = RayStream::with_capacity(w as usize * h as usize);
        for y in 0..h {
            for x in 0..w {
                let r = view.ray(x as f32 + 0.5, y as f32 + 0.5, w, h).expect("a pinhole has a ray everywhere");
                rays.push(&r);
            }
        }
        let mut hits = HitStream::default();
        self.query.intersect_stream_par(&rays, &mut hits, Coherence::Incoherent);
        let depth: Vec<f32> = (0..rays.len())
            .map(|i| hits.get(i).map_or(f32::INFINITY, |hit| hit.t * rays.get(i).dir.length()))
            .collect();
        let tan = (fov_deg.to_radians() * 0.5).tan();
        let aspect = h as f32 / w as f32;
        // Image position and distance of a world point, if in front of the eye.
        let project = |p: Vec3| -> Option<(f32, f32, f32)> {
            let v = p - view.eye;
            let z = v.dot(view.forward);
            if z <= 1e-6 {
                return None;
            }
            let sx = v.dot(view.right) / (z * tan);
            let sy = v.dot(view.up) / (z * tan);
            Some(((sx + 1.0) * 0.5 * w as f32, (1.0 - sy / aspect) * 0.5 * h as f32, v.length()))
        };
        for n in nodes {
            let (a, b) = (Vec3::from(n.origin), segment_end(n, miss_length));
            let colour = kind_colour(n.kind, n.kind == RayKind::Shadow && n.t.is_some());
            let (Some(pa), Some(pb)) = (project(a), project(b)) else { continue };
            let steps = (((pb.0 - pa.0).abs() + (pb.1 - pa.1).abs()) * 2.0).clamp(2.0, 8.0 * (w + h) as f32) as usize;
            for k in 0..=steps {
                let p = a.lerp(b, k as f32 / steps as f32);
                let Some((x, y, dist)) = project(p) else { continue };
                for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                    let (px, py) = ((x - 0.5 + dx).floor(), (y - 0.5 + dy).floor());
                    if px < 0.0 || py < 0.0 || px >= w as f32 || py >= h as f32 {
                        continue;
                    }
                    let i = py as usize * w as usize + px as usize;
                    // Behind a surface (with a margin for the segment's own end on it): blended.
                    if dist <= depth[i] * 1.01 + 1e-4 {
                        image.pixels[i] = colour;
                    } else {
                        image.pixels[i] = image.pixels[i].lerp(colour, 0.35);
                    }
                }
            }
        }
        Ok(image)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_end_at_hits_lights_or_far_away() {
        let n = TreeNode {
            parent: None,
            kind: RayKind::Primary,
            depth: 0,
            origin: [0.0, 0.0, 0.0],
            dir: [0.0, 0.0, 2.0],
            t: Some(1.5),
            tfar: None,
            weight: [1.0; 3],
        };
        assert_eq!(segment_end(&n, 10.0), Vec3::new(0.0, 0.0, 3.0));
        assert_eq!(segment_end(&TreeNode { t: None, ..n.clone() }, 10.0), Vec3::new(0.0, 0.0, 10.0));
        assert_eq!(segment_end(&TreeNode { t: None, tfar: Some(1.0), ..n }, 10.0), Vec3::new(0.0, 0.0, 2.0));
    }
}
