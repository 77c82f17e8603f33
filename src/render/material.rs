//! Surface and medium properties, and the optics of the seeds' illumination model: Phong's local
//! model, mirror reflection, Snell refraction with total internal reflection, the exact dielectric
//! Fresnel terms and Schlick's approximation, and Beer–Lambert absorption.

use glam::{Vec2, Vec3};

use super::texture::ImageTexture;

/// How a transparent material splits light between its reflected and refracted rays.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FresnelMode {
    /// Fixed coefficients: `r_s = reflect`, `r_t = transmit` (the lecture's constant model).
    Off,
    /// The exact dielectric terms: `ρ = ½(ρ∥² + ρ⊥²)` reflected, `1 − ρ` refracted.
    #[default]
    Exact,
    /// Schlick's approximation `ρ₀ + (1 − ρ₀)(1 − cos θ)⁵`, θ in the thinner medium.
    Schlick,
}

/// A texture for the diffuse colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Texture {
    /// Solid 3-D checkerboard of cubes `size` wide: the material's diffuse colour and `other`.
    Checker {
        /// The second colour.
        other: Vec3,
        /// Edge length of the cubes.
        size: f32,
    },
    /// Image `index` of the world's textures, at the surface's texture coordinates, times the
    /// diffuse colour (OBJ `map_Kd` times `Kd`); surfaces without coordinates get the colour.
    Image {
        /// Index into the world's textures.
        index: u32,
    },
}

/// A material: Phong's local model plus the recursion's reflection and transmission.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Ambient reflectance (times the scene's ambient light).
    pub ambient: Vec3,
    /// Lambert reflectance `k_d`.
    pub diffuse: Vec3,
    /// Phong specular reflectance `k_s` and exponent `n`.
    pub specular: Vec3,
    /// Phong exponent `n`.
    pub shininess: f32,
    /// Mirror reflection `r_s`.
    pub reflect: Vec3,
    /// Transmission `r_t` (its colour filters the refracted light).
    pub transmit: Vec3,
    /// Index of refraction of the medium behind the surface (used when `transmit` > 0).
    pub ior: f32,
    /// Beer–Lambert absorption coefficient α per unit distance inside the medium, per channel.
    pub absorption: Vec3,
    /// How reflection and transmission weights follow the angle (exact Fresnel, Schlick, or fixed).
    pub fresnel: FresnelMode,
    /// A texture replacing the diffuse colour, if any.
    pub texture: Option<Texture>,
}

impl Default for Material {
    /// A matte light grey.
    fn default() -> Self {
        Self {
            ambient: Vec3::splat(0.1),
            diffuse: Vec3::splat(0.7),
            specular: Vec3::ZERO,
            shininess: 20.0,
            reflect: Vec3::ZERO,
            transmit: Vec3::ZERO,
            ior: 1.0,
            absorption: Vec3::ZERO,
            fresnel: FresnelMode::Exact,
            texture: None,
        }
    }
}

impl Material {
    /// True when the material spawns refracted rays.
    pub fn is_transparent(&self) -> bool {
        self.transmit.max_element() > 0.0
    }

    /// True when the material spawns reflected rays (mirrors, and dielectrics with Fresnel on).
    pub fn is_reflective(&self) -> bool {
        self.reflect.max_element() > 0.0 || (self.is_transparent() && self.fresnel != FresnelMode::Off)
    }

    /// The diffuse colour at world point `p` with texture coordinates `uv`.
    pub fn diffuse_at(&self, p: Vec3, uv: Option<Vec2>, textures: &[ImageTexture]) -> Vec3 {
        match self.texture {
            None => self.diffuse,
            Some(Texture::Image { index }) => match (uv, textures.get(index as usize)) {
                (Some(uv), Some(t)) => self.diffuse * t.sample(uv),
                _ => self.diffuse,
            },
            Some(Texture::Checker { other, size }) => {
                // Nudged like POV-Ray's checker, so that a floor at y = 0 does not flicker.
                let c = (p / size + 1e-4).floor();
                if (c.x as i64 + c.y as i64 + c.z as i64).rem_euclid(2) == 0 { self.diffuse } else { other }
            }
        }
    }

    /// A description of what is wrong with the material, if anything: colours finite and not
    /// negative, `ior` finite and positive, exponent finite and not negative, checker size positive.
    pub fn check(&self) -> Result<(), String> {
        let colours = [
            ("ambient", self.ambient),
            ("diffuse", self.diffuse),
            ("specular", self.specular),
            ("reflect", self.reflect),
            ("transmit", self.transmit),
            ("absorption", self.absorption),
        ];
        for (name, c) in colours {
            if !(c.is_finite() && c.min_element() >= 0.0) {
                return Err(format!("`{name}` {c} must be finite and not negative"));
            }
        }
        if !(self.ior.is_finite() && self.ior > 0.0) {
            return Err(format!("`ior` {} must be finite and positive", self.ior));
        }
        if !(self.shininess.is_finite() && self.shininess >= 0.0) {
            return Err(format!("`shininess` {} must be finite and not negative", self.shininess));
        }
        if let Some(Texture::Checker { other, size }) = self.texture
            && !(other.is_finite() && other.min_element() >= 0.0 && size.is_finite() && size > 0.0)
        {
            return Err(format!("checker colour {other} and size {size} must be finite, not negative, size > 0"));
        }
        Ok(())
    }
}

/// Mirror reflection of direction `d` about unit normal `n`: `d − 2(d·n)n`.
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - n * (2.0 * d.dot(n))
}

/// The refracted unit direction for unit incident direction `d` through a surface with unit normal
/// `n` facing the incident side (`d·n < 0`), from index `n1` into `n2` — the lecture's
/// `t = (n1/n2)(d + n cos θ1) − n cos θ2` — or `None` on total internal reflection (the radicand
/// `cos² θ2 = 1 − (n1/n2)²(1 − cos² θ1)` negative).
pub fn refract(d: Vec3, n: Vec3, n1: f32, n2: f32) -> Option<Vec3> {
    let eta = n1 / n2;
    let cos1 = (-d.dot(n)).clamp(0.0, 1.0);
    let cos2_sq = 1.0 - eta * eta * (1.0 - cos1 * cos1);
    if cos2_sq < 0.0 {
        return None;
    }
    Some((d + n * cos1) * eta - n * cos2_sq.sqrt())
}

/// The exact Fresnel reflectance of an unpolarized ray from index `n1` into `n2` at incidence
/// cosine `cos1`: `ρ∥ = (n2 cos θ1 − n1 cos θ2)/(n2 cos θ1 + n1 cos θ2)`,
/// `ρ⊥ = (n1 cos θ1 − n2 cos θ2)/(n1 cos θ1 + n2 cos θ2)`, `ρ = ½(ρ∥² + ρ⊥²)`; 1 on total internal
/// reflection. (The lecture prints ρ⊥'s denominator as ρ∥'s; the two agree only at normal
/// incidence, and the one here is the physical term.) Computed in f64.
pub fn fresnel_exact(cos1: f32, n1: f32, n2: f32) -> f32 {
    let (cos1, n1, n2) = (cos1.clamp(0.0, 1.0) as f64, n1 as f64, n2 as f64);
    let sin2_sq = (n1 / n2).powi(2) * (1.0 - cos1 * cos1);
    if sin2_sq >= 1.0 {
        return 1.0;
    }
    let cos2 = (1.0 - sin2_sq).sqrt();
    let par = (n2 * cos1 - n1 * cos2) / (n2 * cos1 + n1 * cos2);
    let perp = (n1 * cos1 - n2 * cos2) / (n1 * cos1 + n2 * cos2);
    (0.5 * (par * par + perp * perp)) as f32
}

/// Schlick's approximation `ρ₀ + (1 − ρ₀)(1 − cos θ)⁵` with `ρ₀ = ((n1 − n2)/(n1 + n2))²`, θ the
/// angle in the optically thinner medium (the larger one); 1 on total internal reflection.
pub fn fresnel_schlick(cos1: f32, n1: f32, n2: f32) -> f32 {
    let r0 = ((n1 - n2) / (n1 + n2)).powi(2);
    let cos1 = cos1.clamp(0.0, 1.0);
    let cos = if n1 <= n2 {
        cos1
    } else {
        let sin2_sq = (n1 / n2).powi(2) * (1.0 - cos1 * cos1);
        if sin2_sq >= 1.0 {
            return 1.0;
        }
        (1.0 - sin2_sq).sqrt()
    };
    r0 + (1.0 - r0) * (1.0 - cos).powi(5)
}

/// Beer–Lambert: the fraction `e^(−α s)` of light left after distance `s` in a medium, per channel.
pub fn beer_lambert(absorption: Vec3, s: f32) -> Vec3 {
    (-absorption * s.max(0.0)).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_is_four_percent_at_normal_incidence_for_glass() {
        // The lecture's example: air to glass, ρ∥ = ρ⊥ = 1/5, ρ = 4 %.
        assert!((fresnel_exact(1.0, 1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!((fresnel_exact(1.0, 1.5, 1.0) - 0.04).abs() < 1e-6);
        assert!((fresnel_schlick(1.0, 1.0, 1.5) - 0.04).abs() < 1e-6);
        // Grazing incidence reflects everything.
        assert!(fresnel_exact(0.0, 1.0, 1.5) > 0.999);
    }

    #[test]
    fn total_internal_reflection_beyond_the_critical_angle() {
        // Glass to air: critical angle asin(1/1.5) = 41.81°.
        let crit = (1.0f32 / 1.5).asin();
        let below = (crit - 0.01).cos();
        let above = (crit + 0.01).cos();
        assert!(fresnel_exact(below, 1.5, 1.0) < 1.0);
        assert_eq!(fresnel_exact(above, 1.5, 1.0), 1.0);
        assert_eq!(fresnel_schlick(above, 1.5, 1.0), 1.0);
        let n = Vec3::Y;
        let d = |c: f32| Vec3::new((1.0 - c * c).sqrt(), -c, 0.0);
        assert!(refract(d(below), n, 1.5, 1.0).is_some());
        assert!(refract(d(above), n, 1.5, 1.0).is_none());
    }

    #[test]
    fn schlick_error_is_bounded() {
        // Over all incidence angles, air↔glass both ways and air→water: Schlick within 0.065 of
        // the exact terms (measured worst: 0.060, at grazing angles).
        let mut worst = 0.0f32;
        for i in 0..=1000 {
            let c = i as f32 / 1000.0;
            for (n1, n2) in [(1.0, 1.5), (1.5, 1.0), (1.0, 1.33)] {
                worst = worst.max((fresnel_exact(c, n1, n2) - fresnel_schlick(c, n1, n2)).abs());
            }
        }
        assert!(worst < 0.065, "worst |Schlick − exact| = {worst}");
        assert!(worst > 0.001, "Schlick is an approximation: {worst}");
    }

    #[test]
    fn snell_law_holds() {
        let n = Vec3::Y;
        let d = Vec3::new(0.6, -0.8, 0.0);
        let t = refract(d, n, 1.0, 1.5).unwrap();
        assert!((t.length() - 1.0).abs() < 1e-6);
        // n1 sin θ1 = n2 sin θ2.
        assert!((1.0 * d.x - 1.5 * t.x).abs() < 1e-6);
        assert!(t.y < 0.0);
        assert_eq!(refract(Vec3::NEG_Y, n, 1.0, 1.5).unwrap(), Vec3::NEG_Y);
    }

    #[test]
    fn beer_lambert_on_a_slab() {
        let a = Vec3::new(0.0, 0.5, 2.0);
        let k = beer_lambert(a, 2.0);
        assert_eq!(k.x, 1.0);
        assert!((k.y - (-1.0f32).exp()).abs() < 1e-6 && (k.z - (-4.0f32).exp()).abs() < 1e-6);
        // Two slabs of 1 = one of 2.
        assert!((beer_lambert(a, 1.0) * beer_lambert(a, 1.0) - k).abs().max_element() < 1e-6);
    }

    #[test]
    fn checker_alternates() {
        let m = Material { texture: Some(Texture::Checker { other: Vec3::ZERO, size: 1.0 }), ..Default::default() };
        assert_eq!(m.diffuse_at(Vec3::new(0.5, 0.5, 0.5), None, &[]), m.diffuse);
        assert_eq!(m.diffuse_at(Vec3::new(1.5, 0.5, 0.5), None, &[]), Vec3::ZERO);
        assert_eq!(m.diffuse_at(Vec3::new(-0.5, 0.5, 0.5), None, &[]), Vec3::ZERO);
    }

    #[test]
    fn bad_materials_are_named() {
        assert!(Material::default().check().is_ok());
        let m = Material { ior: 0.0, ..Default::default() };
        assert!(m.check().unwrap_err().contains("ior"));
        let m = Material { diffuse: Vec3::new(f32::NAN, 0.0, 0.0), ..Default::default() };
        assert!(m.check().unwrap_err().contains("diffuse"));
        let m = Material { reflect: Vec3::splat(-1.0), ..Default::default() };
        assert!(m.check().unwrap_err().contains("reflect"));
    }
}
