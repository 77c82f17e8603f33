//! The seeds' SHADE procedure for one ray: at a hit, the local Phong model with a shadow feeler to
//! every light, then a reflected and a refracted ray, `L = L_Phong + r_s·L_s + r_t·L_t`. It does
//! not trace anything itself: it *emits* what it found (radiance, shadow feelers with the light
//! they would bring, child rays with their path weights), so that the wavefront renderer can
//! trace all rays of a bounce as one stream and the ray-tree walker can trace them one by one,
//! with the same optics.

use glam::Vec3;

use super::feelers::{FeelerBatch, LitPoint, rect_feelers};
use super::light::{Incident, LightKind};
use super::material::{FresnelMode, beer_lambert, fresnel_exact, fresnel_schlick, reflect, refract};
use super::{Settings, World};
use crate::ray::{Hit, Ray, offset_ray_origin};
use crate::raygen::Pcg32;

/// Most nested media a path keeps track of (glass in water in glass …); deeper ones are ignored.
pub const MAX_MEDIA: usize = 4;

/// The kind of a ray in the ray tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RayKind {
    /// A camera ray.
    Primary,
    /// A shadow feeler towards a light.
    Shadow,
    /// A mirror reflection.
    Reflected,
    /// A refracted (transmitted) ray.
    Refracted,
}

/// The media a path is inside, innermost last, as material indices.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Media {
    ids: [u32; MAX_MEDIA],
    len: u8,
}

impl Media {
    /// The innermost medium.
    pub fn top(&self) -> Option<u32> {
        self.len.checked_sub(1).map(|i| self.ids[i as usize])
    }

    fn push(&mut self, m: u32) {
        if (self.len as usize) < MAX_MEDIA {
            self.ids[self.len as usize] = m;
            self.len += 1;
        }
    }

    /// Leaves medium `m`: removes its innermost entry (or nothing, if the path was not inside).
    fn remove(&mut self, m: u32) {
        if let Some(i) = self.ids[..self.len as usize].iter().rposition(|&x| x == m) {
            self.ids.copy_within(i + 1..self.len as usize, i);
            self.len -= 1;
        }
    }
}

/// What a ray carries through the wavefront: its pixel, how much of the pixel's colour it
/// contributes, its depth and the media it travels in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Path {
    /// The pixel the path contributes to (`y·width + x`).
    pub pixel: u32,
    /// Recursion depth of the path's next ray.
    pub depth: u32,
    /// The product of the reflection and transmission weights so far.
    pub weight: Vec3,
    /// The stack of media the ray travels in (for refraction and absorption).
    pub media: Media,
    /// Seeds the path's random choices (area lights' jitter): made from the pixel and sample
    /// of the camera ray, then from the parent's seed and the child's kind, so every backend and
    /// every thread count draws the same numbers for the same path.
    pub seed: u64,
}

impl Path {
    /// The path of camera sample `sample` of pixel `(x, y)`.
    pub fn camera(pixel: u32, x: u32, y: u32, sample: u32) -> Self {
        let seed = mix((x as u64) << 32 | y as u64, sample as u64);
        Self { pixel, depth: 0, weight: Vec3::ONE, media: Media::default(), seed }
    }
}

/// A 64-bit mix of two words (the finalizer of SplitMix64 over their combination).
fn mix(a: u64, b: u64) -> u64 {
    let mut z = a ^ b.wrapping_mul(0x9e37_79b9_7f4a_7c15).rotate_left(31);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// What shading one ray produced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Emission<'a> {
    /// Light reaching the pixel directly: ambient, background, already weighted.
    Radiance(Vec3),
    /// A shadow feeler towards light `light`: if it is not occluded, `radiance` reaches the pixel.
    Shadow {
        /// The feeler: from the hit point to the light.
        ray: Ray,
        /// What reaches the pixel if the feeler is unoccluded.
        radiance: Vec3,
        /// Index of the light.
        light: u32,
    },
    /// Up to eight shadow feelers of one area light (rectangle lights), in SoA lanes.
    Shadows(&'a FeelerBatch),
    /// A reflected or refracted ray to trace next.
    Child {
        /// The ray to trace.
        ray: Ray,
        /// Its path: pixel, depth, weight and media.
        path: Path,
        /// Reflected or refracted.
        kind: RayKind,
    },
}

/// Counters of one shading call.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShadeCounts {
    /// Child rays not spawned because their weight fell below the bailout.
    pub cut_by_weight: u64,
    /// Child rays not spawned because the path reached the maximum depth.
    pub cut_by_depth: u64,
    /// Total internal reflections.
    pub tir: u64,
}

/// The shadow feeler of one light sample `inc` (reaching `target`, or `None` for directional
/// light) from `at`, and the light it brings by the local model (Lambert and Phong); `None` if the
/// sample is behind the surface or brings nothing.
#[inline(always)]
pub fn feeler(at: &LitPoint, inc: &Incident, target: Option<Vec3>) -> Option<(Ray, Vec3)> {
    let cos = at.ns.dot(inc.dir);
    if cos <= 0.0 || at.n_face.dot(inc.dir) <= 0.0 {
        return None;
    }
    let r = reflect(-inc.dir, at.ns);
    let spec = if at.ks == Vec3::ZERO { 0.0 } else { r.dot(-at.d).max(0.0).powf(at.shininess) };
    let radiance = at.weight * inc.color * (at.kd * cos + at.ks * spec);
    if radiance.max_element() <= 0.0 {
        return None;
    }
    let ray = match target {
        // The segment to the light: t in (0, 1) of the unnormalized direction.
        Some(t) => Ray::segment(at.origin, t - at.origin, 0.0, 1.0),
        None => Ray::new(at.origin, inc.dir),
    };
    Some((ray, radiance))
}

/// Shades `ray` (carrying `path`) given its closest hit; returns nothing to trace further on a
/// miss. `emit` receives the emissions in a fixed order (radiance, shadows by light, reflected,
/// refracted), so every renderer that calls this sums the same terms.
pub fn shade(
    world: &World,
    settings: &Settings,
    ray: &Ray,
    hit: Option<&Hit>,
    path: &Path,
    counts: &mut ShadeCounts,
    mut emit: impl FnMut(Emission<'_>),
) {
    let mut weight = path.weight;
    let medium = path.media.top().map(|m| &world.materials[m as usize]);
    let dir_len = ray.dir.length();
    let Some(hit) = hit else {
        // Light from the background, unless an absorbing medium swallows it on the infinite way.
        if medium.is_none_or(|m| m.absorption == Vec3::ZERO) {
            emit(Emission::Radiance(weight * world.background));
        }
        return;
    };
    if let Some(m) = medium {
        weight *= beer_lambert(m.absorption, hit.t * dir_len);
    }
    let Some(sp) = world.surfaces.resolve(ray, hit) else {
        return;
    };
    let mat = &world.materials[sp.material as usize];
    let d = ray.dir / dir_len;
    // The side the ray arrives from: front (against the winding's normal) or back.
    let front = d.dot(sp.ng) < 0.0;
    let n_face = if front { sp.ng } else { -sp.ng };
    let mut ns = if front { sp.ns } else { -sp.ns };
    if ns.dot(-d) <= 0.0 {
        ns = n_face;
    }
    let kd = mat.diffuse_at(sp.p, sp.uv, &world.textures);

    // Ambient.
    let ambient = weight * mat.ambient * kd * world.ambient;
    if ambient != Vec3::ZERO {
        emit(Emission::Radiance(ambient));
    }

    // Phong: a shadow feeler to every light that faces the surface.
    let at = LitPoint {
        p: sp.p,
        origin: offset_ray_origin(sp.p, n_face),
        ns,
        n_face,
        d,
        weight,
        kd,
        ks: mat.specular,
        shininess: mat.shininess,
    };
    let lit = mat.diffuse != Vec3::ZERO || mat.texture.is_some() || mat.specular != Vec3::ZERO;
    for (li, light) in world.lights.iter().enumerate() {
        if !lit {
            break;
        }
        // Area lights' strata are jittered by a generator seeded with the path and the light,
        // so the image depends neither on the order of shading nor on the backend.
        let li = li as u32;
        match light.kind {
            LightKind::Rect { .. } => {
                rect_feelers(light, li, &at, &mut Pcg32::new(path.seed, li as u64), |b| emit(Emission::Shadows(b)));
            }
            LightKind::Sphere { .. } => {
                light.each_sample(sp.p, &mut Pcg32::new(path.seed, li as u64), |inc, target| {
                    if let Some((ray, radiance)) = feeler(&at, &inc, target) {
                        emit(Emission::Shadow { ray, radiance, light: li });
                    }
                });
            }
            _ => {
                // One sample (`Light::sample`'s), no jitter: no closure in the way of inlining.
                if let Some(inc) = light.incident(sp.p)
                    && let Some((ray, radiance)) = feeler(&at, &inc, light.fixed_target())
                {
                    emit(Emission::Shadow { ray, radiance, light: li });
                }
            }
        }
    }

    // Reflection and refraction.
    if !(mat.is_reflective() || mat.is_transparent()) {
        return;
    }
    if path.depth >= settings.max_depth {
        counts.cut_by_depth += mat.is_reflective() as u64 + mat.is_transparent() as u64;
        return;
    }
    let n1 = medium.map_or(1.0, |m| m.ior);
    let mut inner = path.media;
    let n2 = if front {
        inner.push(sp.material);
        mat.ior
    } else {
        inner.remove(sp.material);
        inner.top().map_or(1.0, |m| world.materials[m as usize].ior)
    };
    let cos1 = (-d).dot(ns);
    let (mut kr, mut kt) = (mat.reflect, Vec3::ZERO);
    let refracted = if mat.is_transparent() { refract(d, ns, n1, n2) } else { None };
    if mat.is_transparent() {
        match refracted {
            None => {
                // Total internal reflection: all the transmitted energy goes to the reflected ray.
                counts.tir += 1;
                kr += mat.transmit;
            }
            Some(_) => {
                let rho = match mat.fresnel {
                    FresnelMode::Off => 0.0,
                    FresnelMode::Exact => fresnel_exact(cos1, n1, n2),
                    FresnelMode::Schlick => fresnel_schlick(cos1, n1, n2),
                };
                kr += mat.transmit * rho;
                kt = mat.transmit * (1.0 - rho);
            }
        }
    }
    let child = |k: Vec3, media: Media, kind: RayKind| Path {
        pixel: path.pixel,
        depth: path.depth + 1,
        weight: weight * k,
        media,
        seed: mix(path.seed, kind as u64),
    };
    if kr != Vec3::ZERO {
        let c = child(kr, path.media, RayKind::Reflected);
        if c.weight.max_element() < settings.bailout {
            counts.cut_by_weight += 1;
        } else {
            let mut dir = reflect(d, ns);
            if dir.dot(n_face) <= 0.0 {
                dir = reflect(d, n_face);
            }
            let ray = Ray::new(at.origin, dir);
            emit(Emission::Child { ray, path: c, kind: RayKind::Reflected });
        }
    }
    if let (Some(t), true) = (refracted, kt != Vec3::ZERO) {
        let c = child(kt, inner, RayKind::Refracted);
        if c.weight.max_element() < settings.bailout {
            counts.cut_by_weight += 1;
        } else if t.dot(n_face) < 0.0 {
            let ray = Ray::new(offset_ray_origin(sp.p, -n_face), t);
            emit(Emission::Child { ray, path: c, kind: RayKind::Refracted });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn media_stack_nests() {
        let mut m = Media::default();
        assert_eq!(m.top(), None);
        m.push(1);
        m.push(2);
        assert_eq!(m.top(), Some(2));
        m.remove(1);
        assert_eq!(m.top(), Some(2));
        m.remove(2);
        assert_eq!(m.top(), None);
        m.remove(5);
        for i in 0..10 {
            m.push(i);
        }
        assert_eq!(m.top(), Some(3), "deeper media than MAX_MEDIA are ignored");
    }
}

/// Most surfaces a filtered shadow feeler passes through; a feeler that would cross more counts as
/// blocked.
pub const MAX_SHADOW_CROSSINGS: u32 = 8;

/// What a shadow feeler does at a surface when shadows are filtered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ShadowStep {
    /// An opaque surface (or too little light left): the light does not arrive.
    Blocked,
    /// A transparent surface: the feeler goes on from just behind it to the same end, its light
    /// filtered by the surface's `transmit` colour (POV-Ray's filtered shadows: no refraction,
    /// no caustics, no absorption along the way).
    Through {
        /// The feeler's continuation behind the surface.
        ray: Ray,
        /// The light it carries, filtered so far.
        radiance: Vec3,
    },
}

/// The next step of the shadow feeler `ray` carrying `radiance`, which hit `hit`.
pub fn shadow_through(world: &World, settings: &Settings, ray: &Ray, hit: &Hit, radiance: Vec3) -> ShadowStep {
    let Some(sp) = world.surfaces.resolve(ray, hit) else { return ShadowStep::Blocked };
    let mat = &world.materials[sp.material as usize];
    let radiance = radiance * mat.transmit;
    if !mat.is_transparent() || radiance.max_element() < settings.bailout.max(f32::MIN_POSITIVE) {
        return ShadowStep::Blocked;
    }
    let n_face = if ray.dir.dot(sp.ng) < 0.0 { sp.ng } else { -sp.ng };
    let origin = offset_ray_origin(sp.p, -n_face);
    let ray = if ray.tfar.is_finite() {
        let end = ray.origin + ray.dir * ray.tfar;
        Ray::segment(origin, end - origin, 0.0, 1.0)
    } else {
        Ray::new(origin, ray.dir)
    };
    ShadowStep::Through { ray, radiance }
}
