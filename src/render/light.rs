//! Light sources of the local illumination model: point, directional and spot lights, and area
//! lights (a rectangle, or a disc facing the lit point: POV-Ray's `area_light … circular orient`)
//! sampled by several shadow feelers for soft shadows; each with a colour (intensity folded in) and
//! an optional distance fade.

use glam::Vec3;

use crate::raygen::Pcg32;

/// Most samples of one area light per lit point.
pub const MAX_LIGHT_SAMPLES: u32 = 1024;

/// What kind of light, with its shape parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    /// Radiates equally in all directions from `Light::position`.
    Point,
    /// Parallel light travelling along the unit `direction` (the sun); `position` unused.
    Directional {
        /// Unit direction the light travels in.
        direction: Vec3,
    },
    /// A point light limited to a cone about the unit `direction`: full intensity within
    /// `cos_inner` of the axis, none beyond `cos_outer`, a smoothstep between (POV-Ray's
    /// `radius` and `falloff`).
    Spot {
        /// Unit direction of the cone's axis.
        direction: Vec3,
        /// Cosine of the full-intensity half angle.
        cos_inner: f32,
        /// Cosine of the cut-off half angle.
        cos_outer: f32,
    },
    /// A rectangle centred on `Light::position` with edge vectors `u` and `v`, sampled on an
    /// `n[0] × n[1]` grid of strata, each jittered; every sample an omnidirectional point light
    /// of `color / (n[0]·n[1])` (POV-Ray's `area_light u, v, n0, n1 jitter`).
    Rect {
        /// First edge vector.
        u: Vec3,
        /// Second edge vector.
        v: Vec3,
        /// Strata along `u` and `v`.
        n: [u32; 2],
    },
    /// A disc of `radius` centred on `Light::position`, turned to face each lit point, sampled on
    /// `n` jittered strata (polar, equal area) (POV-Ray's `area_light … circular orient`).
    Sphere {
        /// Radius.
        radius: f32,
        /// Number of strata.
        n: u32,
    },
}

/// A light source.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Where a point or spot light sits (`Vec3::ZERO` for directional lights).
    pub position: Vec3,
    /// Colour times intensity.
    pub color: Vec3,
    /// Point, directional, spot or area light.
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

    /// Shadow feelers this light needs per lit point: 1, or an area light's sample count.
    pub fn samples(&self) -> u32 {
        match self.kind {
            LightKind::Rect { n, .. } => n[0] * n[1],
            LightKind::Sphere { n, .. } => n,
            _ => 1,
        }
    }

    /// The light's contribution arriving at `p`, or `None` where it sends none (outside a spot's
    /// cone, at the light's own position). Area lights answer as a point light at their centre.
    pub fn incident(&self, p: Vec3) -> Option<Incident> {
        self.arriving(p, self.position)
    }

    /// Where the shadow feeler of a one-sample light (point, spot, directional) must reach: the
    /// light's position, or `None` for directional light (the feeler is unbounded).
    #[inline(always)]
    pub(crate) fn fixed_target(&self) -> Option<Vec3> {
        match self.kind {
            LightKind::Directional { .. } => None,
            _ => Some(self.position),
        }
    }

    /// Sample `s` (of [`samples`](Self::samples)) of the light seen from `p`: what arrives, and
    /// the point the shadow feeler must reach (`None` for directional light). `rng` jitters area
    /// lights' strata.
    #[inline]
    pub fn sample(&self, p: Vec3, s: u32, rng: &mut Pcg32) -> Option<(Incident, Option<Vec3>)> {
        let target = match self.kind {
            // One sample, the whole light, no jitter.
            LightKind::Directional { .. } | LightKind::Point | LightKind::Spot { .. } => {
                return self.incident(p).map(|i| (i, self.fixed_target()));
            }
            // No strata (a light that `check` rejects): no sample, rather than a division by zero.
            LightKind::Rect { n: [0, _] | [_, 0], .. } | LightKind::Sphere { n: 0, .. } => return None,
            LightKind::Rect { u, v, n } => {
                let (a, b) = ((s % n[0]) as f32 + rng.next_f32(), (s / n[0]) as f32 + rng.next_f32());
                let (du, dv) = (u / n[0] as f32, v / n[1] as f32);
                self.position - 0.5 * (u + v) + du * a + dv * b
            }
            LightKind::Sphere { radius, n } => {
                // Equal-area strata of the disc: rings by r², then the angle.
                let rings = (n as f32).sqrt().ceil() as u32;
                let per = n.div_ceil(rings);
                let (ring, k) = (s / per, s % per);
                let r = radius * ((ring as f32 + rng.next_f32()) / rings as f32).sqrt();
                let phi = std::f32::consts::TAU * (k as f32 + rng.next_f32()) / per as f32;
                let w = (p - self.position).normalize_or(Vec3::Y);
                let e1 = w.any_orthonormal_vector();
                let e2 = w.cross(e1);
                self.position + (e1 * phi.cos() + e2 * phi.sin()) * r
            }
        };
        let inc = self.arriving(p, target)?;
        let share = 1.0 / self.samples() as f32;
        Some((Incident { color: inc.color * share, ..inc }, Some(target)))
    }

    /// Every sample of the light seen from `p`: `f` gets what arrives and the point the shadow
    /// feeler must reach, for each sample that sends light. The order and the arithmetic are
    /// [`sample`](Self::sample)'s for `s = 0, 1, …`, so the answers from the same `rng` are the
    /// same (a test holds them equal); the strata's indices, the sample's share and a disc's
    /// orientation are worked out once per call instead of once per sample (this runs for every
    /// lit point and light). The disc's stratum arithmetic repeats `sample`'s: keep the two alike.
    #[inline]
    pub fn each_sample(&self, p: Vec3, rng: &mut Pcg32, mut f: impl FnMut(Incident, Option<Vec3>)) {
        let share = 1.0 / self.samples() as f32;
        let mut emit = |target: Vec3| {
            if let Some(inc) = self.arriving(p, target) {
                f(Incident { color: inc.color * share, ..inc }, Some(target));
            }
        };
        match self.kind {
            LightKind::Rect { u, v, n } => {
                // The corner and one stratum's edges: a sample is `corner + du·a + dv·b`.
                let (du, dv) = (u / n[0] as f32, v / n[1] as f32);
                let corner = self.position - 0.5 * (u + v);
                for j in 0..n[1] {
                    for i in 0..n[0] {
                        let (a, b) = (i as f32 + rng.next_f32(), j as f32 + rng.next_f32());
                        emit(corner + du * a + dv * b);
                    }
                }
            }
            LightKind::Sphere { n: 0, .. } => {}
            LightKind::Sphere { radius, n } => {
                let rings = (n as f32).sqrt().ceil() as u32;
                let per = n.div_ceil(rings);
                let w = (p - self.position).normalize_or(Vec3::Y);
                let e1 = w.any_orthonormal_vector();
                let e2 = w.cross(e1);
                for s in 0..n {
                    let (ring, k) = (s / per, s % per);
                    let r = radius * ((ring as f32 + rng.next_f32()) / rings as f32).sqrt();
                    let phi = std::f32::consts::TAU * (k as f32 + rng.next_f32()) / per as f32;
                    emit(self.position + (e1 * phi.cos() + e2 * phi.sin()) * r);
                }
            }
            _ => {
                if let Some((inc, target)) = self.sample(p, 0, rng) {
                    f(inc, target);
                }
            }
        }
    }

    /// What a light at `target` (its position, or a sample of its area) sends to `p`.
    #[inline(always)]
    fn arriving(&self, p: Vec3, target: Vec3) -> Option<Incident> {
        let (dir, dist) = match self.kind {
            LightKind::Directional { direction } => (-direction, f32::INFINITY),
            _ => {
                // One square root and one division (this runs once per shadow feeler).
                let v = target - p;
                let d2 = v.length_squared();
                if !(d2 > 0.0 && d2.is_finite()) {
                    return None;
                }
                let d = d2.sqrt();
                let inv = 1.0 / d;
                (v * inv, d)
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
            k *= 2.0 * fade * fade / (fade * fade + dist * dist);
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
            LightKind::Rect { u, v, n } => {
                let lim = crate::MAX_COORDINATE;
                if !(u.is_finite() && v.is_finite() && u.abs().max_element() <= lim && v.abs().max_element() <= lim)
                    || u.cross(v).length_squared() == 0.0
                {
                    return Err(format!("edges {u} and {v} must be finite, non-zero and not parallel"));
                }
                if n[0] == 0 || n[1] == 0 || n[0] as u64 * n[1] as u64 > MAX_LIGHT_SAMPLES as u64 {
                    return Err(format!("samples {n:?}: each at least 1, at most {MAX_LIGHT_SAMPLES} in all"));
                }
                Ok(())
            }
            LightKind::Sphere { radius, n } => {
                if !(radius.is_finite() && radius > 0.0 && radius <= crate::MAX_COORDINATE) {
                    return Err(format!("radius {radius} must be finite and positive"));
                }
                if !(1..=MAX_LIGHT_SAMPLES).contains(&n) {
                    return Err(format!("samples {n}: at least 1, at most {MAX_LIGHT_SAMPLES}"));
                }
                Ok(())
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
    fn area_lights_split_their_light_over_their_samples() {
        let mut rng = Pcg32::new(1, 2);
        let rect = Light {
            position: Vec3::new(0.0, 4.0, 0.0),
            color: Vec3::ONE,
            kind: LightKind::Rect { u: Vec3::X * 2.0, v: Vec3::Z * 2.0, n: [4, 3] },
            fade: None,
        };
        assert_eq!(rect.samples(), 12);
        let mut total = Vec3::ZERO;
        for s in 0..12 {
            let (inc, target) = rect.sample(Vec3::ZERO, s, &mut rng).unwrap();
            let t = target.unwrap();
            // Inside the rectangle, in stratum s.
            assert!((t.y - 4.0).abs() < 1e-6 && t.x.abs() <= 1.0 && t.z.abs() <= 1.0, "{t}");
            assert!(t.x >= -1.0 + 0.5 * (s % 4) as f32 - 1e-6 && t.x <= -0.5 + 0.5 * (s % 4) as f32 + 1e-6);
            total += inc.color;
        }
        assert!((total - Vec3::ONE).abs().max_element() < 1e-5);
        let disc = Light { kind: LightKind::Sphere { radius: 0.5, n: 9 }, ..rect };
        for s in 0..9 {
            let (_, t) = disc.sample(Vec3::ZERO, s, &mut rng).unwrap();
            let d = t.unwrap() - disc.position;
            // On the disc facing the point (perpendicular to the line to it).
            assert!(d.length() <= 0.5 + 1e-6 && d.y.abs() < 1e-5, "{d}");
        }
        assert!(Light { kind: LightKind::Rect { u: Vec3::X, v: Vec3::X, n: [2, 2] }, ..rect }.check().is_err());
        assert!(Light { kind: LightKind::Rect { u: Vec3::X, v: Vec3::Z, n: [0, 2] }, ..rect }.check().is_err());
        assert!(Light { kind: LightKind::Sphere { radius: 0.0, n: 4 }, ..rect }.check().is_err());
        assert!(Light { kind: LightKind::Sphere { radius: 1.0, n: 5000 }, ..rect }.check().is_err());
    }

    /// `each_sample` hands out exactly what `sample` answers for `s = 0, 1, …` from the same
    /// generator, skipping the samples that send no light (here: the light's own position).
    #[test]
    fn each_sample_matches_sample_by_sample() {
        let base = Light {
            position: Vec3::new(0.5, 3.0, -1.0),
            color: Vec3::new(1.0, 0.5, 0.25),
            kind: LightKind::Point,
            fade: Some(2.0),
        };
        let lights = [
            base,
            Light { kind: LightKind::Rect { u: Vec3::X * 2.0, v: Vec3::new(0.0, 0.5, 1.5), n: [5, 3] }, ..base },
            Light { kind: LightKind::Sphere { radius: 0.7, n: 10 }, ..base },
            Light { kind: LightKind::Directional { direction: Vec3::NEG_Y }, ..base },
            Light { kind: LightKind::Spot { direction: Vec3::NEG_Y, cos_inner: 0.9, cos_outer: 0.5 }, ..base },
        ];
        for light in lights {
            for p in [Vec3::ZERO, Vec3::new(3.0, -2.0, 7.0), base.position] {
                let mut one = Pcg32::new(7, 3);
                let expected: Vec<_> = (0..light.samples()).filter_map(|s| light.sample(p, s, &mut one)).collect();
                let mut all = Pcg32::new(7, 3);
                let mut got = Vec::new();
                light.each_sample(p, &mut all, |inc, target| got.push((inc, target)));
                assert_eq!(got, expected, "{:?} at {p}", light.kind);
                assert_eq!(all.next_u32(), one.next_u32(), "both drew as many numbers");
            }
        }
        // Lights without strata (rejected by `check`, but their fields are public) send nothing.
        for kind in [LightKind::Sphere { radius: 1.0, n: 0 }, LightKind::Rect { u: Vec3::X, v: Vec3::Z, n: [0, 3] }] {
            let l = Light { kind, ..base };
            let mut rng = Pcg32::new(1, 1);
            assert!(l.sample(Vec3::ZERO, 0, &mut rng).is_none());
            l.each_sample(Vec3::ZERO, &mut rng, |_, _| panic!("no samples expected"));
        }
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
