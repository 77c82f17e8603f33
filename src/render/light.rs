//! Light sources of the local illumination model: point, directional and spot lights, each with a
//! colour (intensity folded in) and an optional distance fade.

use glam::Vec3;

/// What kind of light, with its shape parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    /// Radiates equally in all directions from `Light::position`.
    Point,
    /// Parallel light travelling along the unit `direction` (the sun); `position` unused.
    Directional { direction: Vec3 },
    /// A point light limited to a cone about the unit `direction`: full intensity within
    /// `cos_inner` of the axis, none beyond `cos_outer`, a smoothstep between (POV-Ray's
    /// `radius` and `falloff`).
    Spot { direction: Vec3, cos_inner: f32, cos_outer: f32 },
}

/// A light source.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Where a point or spot light sits (`Vec3::ZERO` for directional lights).
    pub position: Vec3,
    /// Colour times intensity.
    pub color: Vec3,
    pub kind: LightKind,
    /// POV-Ray's `fade_distance` with `fade_power 2`: intensity `2 / (1 + (d / fade)²)` at distance
    /// `d`; `None`: no fall-off with distance.
    pub fade: Option<f32>,
}

/// The light arriving at a point from one light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Incident {
    /// Unit direction from the point towards the light.
    pub dir: Vec3,
    /// Distance to the light (infinite for directional lights).
    pub dist: f32,
    /// Light arriving (colour, after the cone and the fade).
    pub color: Vec3,
}

impl Light {
    /// A white point light.
    pub fn point(position: Vec3, color: Vec3) -> Self {
        Self { position, color, kind: LightKind::Point, fade: None }
    }

    /// The light's contribution arriving at `p`, or `None` where it sends none (outside a spot's
    /// cone, at the light's own position).
    pub fn incident(&self, p: Vec3) -> Option<Incident> {
        let (dir, dist) = match self.kind {
            LightKind::Directional { direction } => (-direction, f32::INFINITY),
            LightKind::Point | LightKind::Spot { .. } => {
                let v = self.position - p;
                let d = v.length();
                if !(d > 0.0 && d.is_finite()) {
                    return None;
                }
                (v / d, d)
            }
        };
        let mut k = 1.0;
        if let LightKind::Spot { direction, cos_inner, cos_outer } = self.kind {
            let c = (-dir).dot(direction);
            if c <= cos_outer {
                return None;
            }
            if c < cos_inner {
                let x = (c - cos_outer) / (cos_inner - cos_outer);
                k = x * x * (3.0 - 2.0 * x);
            }
        }
        if let (Some(fade), true) = (self.fade, dist.is_finite()) {
            k *= 2.0 / (1.0 + (dist / fade).powi(2));
        }
        Some(Incident { dir, dist, color: self.color * k })
    }

    /// What is wrong with the light, if anything.
    pub fn check(&self) -> Result<(), String> {
        if !(self.position.is_finite() && self.position.abs().max_element() <= crate::MAX_COORDINATE) {
            return Err(format!("position {} must be finite and within ±{:e}", self.position, crate::MAX_COORDINATE));
        }
        if !(self.color.is_finite() && self.color.min_element() >= 0.0) {
            return Err(format!("color {} must be finite and not negative", self.color));
        }
        if let Some(f) = self.fade
            && !(f.is_finite() && f > 0.0)
        {
            return Err(format!("fade distance {f} must be finite and positive"));
        }
        match self.kind {
            LightKind::Point => Ok(()),
            LightKind::Directional { direction } | LightKind::Spot { direction, .. }
                if !(direction.is_finite() && (direction.length() - 1.0).abs() < 1e-4) =>
            {
                Err(format!("direction {direction} must be a finite non-zero vector"))
            }
            LightKind::Spot { cos_inner, cos_outer, .. } if !(cos_inner >= cos_outer && cos_outer > -1.0) => {
                Err("a spot's radius must not exceed its falloff, and the falloff be under 180°".into())
            }
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_light_points_at_itself() {
        let l = Light::point(Vec3::new(0.0, 4.0, 0.0), Vec3::ONE);
        let i = l.incident(Vec3::ZERO).unwrap();
        assert_eq!((i.dir, i.dist, i.color), (Vec3::Y, 4.0, Vec3::ONE));
        assert!(l.incident(l.position).is_none());
        let faded = Light { fade: Some(4.0), ..l }.incident(Vec3::ZERO).unwrap();
        assert!((faded.color.x - 1.0).abs() < 1e-6, "2 / (1 + 1) at the fade distance");
    }

    #[test]
    fn spot_cone() {
        let l = Light {
            position: Vec3::new(0.0, 1.0, 0.0),
            color: Vec3::ONE,
            kind: LightKind::Spot {
                direction: Vec3::NEG_Y,
                cos_inner: 30f32.to_radians().cos(),
                cos_outer: 45f32.to_radians().cos(),
            },
            fade: None,
        };
        assert_eq!(l.incident(Vec3::ZERO).unwrap().color, Vec3::ONE);
        assert!(l.incident(Vec3::new(2.0, 0.0, 0.0)).is_none());
        let mid = l.incident(Vec3::new(0.8, 0.0, 0.0)).unwrap().color.x;
        assert!(mid > 0.0 && mid < 1.0, "{mid}");
    }

    #[test]
    fn directional_is_everywhere() {
        let l = Light {
            position: Vec3::ZERO,
            color: Vec3::ONE,
            kind: LightKind::Directional { direction: Vec3::NEG_Y },
            fade: Some(1.0),
        };
        let i = l.incident(Vec3::splat(1e6)).unwrap();
        assert_eq!((i.dir, i.dist, i.color), (Vec3::Y, f32::INFINITY, Vec3::ONE));
    }
}
