//! An area light's shadow feelers from one lit point, eight at a time.
//!
//! A rectangle light of `n₀ × n₁` strata sends that many feelers from every lit point (16 in the
//! Cornell box): the light sample, the direction and distance, the Lambert and Phong terms and the
//! feeler itself are the same arithmetic for each, so they run in eight lanes (`wide`'s `f32x8`),
//! and the feelers leave in SoA lanes ([`FeelerBatch`]) that the wavefront appends to its shadow
//! stream column by column. Only the jitter is drawn one number at a time, from the path's
//! generator in the strata's order, so the samples are [`Light::each_sample`]'s. The arithmetic is
//! the scalar path's ([`super::shade::feeler`]) but for the Phong highlight's power, which is
//! `wide`'s `powf_simd` here (within a few units in the last place of `powf`; a test holds the
//! two paths together).

use glam::Vec3;
use wide::f32x8;

use super::light::{Light, LightKind};
use crate::raygen::Pcg32;

/// Lanes of a batch.
pub const LANES: usize = 8;

/// Up to eight shadow feelers of one light from one point, packed from lane 0: each the segment
/// `origin + t·dir[·][i]`, `t ∈ (0, 1)`, to a point on the light, bringing `radiance[·][i]` if
/// nothing blocks it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FeelerBatch {
    /// The feelers' common origin (the lit point, offset off the surface).
    pub origin: Vec3,
    /// Directions (unnormalized: origin to light sample), by component.
    pub dir: [[f32; LANES]; 3],
    /// Light brought if unblocked, by channel.
    pub radiance: [[f32; LANES]; 3],
    /// Feelers in the batch (lanes `0..len`).
    pub len: usize,
    /// Index of the light.
    pub light: u32,
}

impl FeelerBatch {
    /// Feeler `i` as a segment and the light it brings.
    pub fn feeler(&self, i: usize) -> (crate::ray::Ray, Vec3) {
        let dir = Vec3::new(self.dir[0][i], self.dir[1][i], self.dir[2][i]);
        let radiance = Vec3::new(self.radiance[0][i], self.radiance[1][i], self.radiance[2][i]);
        (crate::ray::Ray::segment(self.origin, dir, 0.0, 1.0), radiance)
    }

    /// Every feeler, in lane order.
    pub fn feelers(&self) -> impl Iterator<Item = (crate::ray::Ray, Vec3)> + '_ {
        (0..self.len).map(|i| self.feeler(i))
    }
}

/// What the feelers of one lit point share.
#[derive(Clone, Copy, Debug)]
pub struct LitPoint {
    /// The surface point.
    pub p: Vec3,
    /// Where its feelers start (off the surface, on the arriving side).
    pub origin: Vec3,
    /// Unit shading normal facing the arriving ray.
    pub ns: Vec3,
    /// Unit geometric normal facing the arriving ray.
    pub n_face: Vec3,
    /// Unit direction of the arriving ray.
    pub d: Vec3,
    /// The path's weight.
    pub weight: Vec3,
    /// Diffuse colour at the point.
    pub kd: Vec3,
    /// Specular colour of the material.
    pub ks: Vec3,
    /// Phong exponent.
    pub shininess: f32,
}

fn splat(v: Vec3) -> [f32x8; 3] {
    [f32x8::splat(v.x), f32x8::splat(v.y), f32x8::splat(v.z)]
}

/// The shadow feelers of rectangle light `light` (index `index`) from `at`, in batches of up to
/// eight handed to `f`; nothing is done if the light is not a rectangle. The samples
/// and their order are [`Light::each_sample`]'s, drawn from `rng`; a sample that sends no light
/// (behind the surface, at the point itself, no highlight and no diffuse colour) makes no feeler.
#[inline(never)]
pub fn rect_feelers(light: &Light, index: u32, at: &LitPoint, rng: &mut Pcg32, mut f: impl FnMut(&FeelerBatch)) {
    let LightKind::Rect { u, v, n } = light.kind else { return };
    let total = n[0] * n[1];
    if total == 0 {
        return;
    }
    let (du, dv) = (u / n[0] as f32, v / n[1] as f32);
    let corner = light.position - 0.5 * (u + v);
    let share = 1.0 / total as f32;
    let (corner, du, dv, p, origin) = (splat(corner), splat(du), splat(dv), splat(at.p), splat(at.origin));
    let (ns, n_face, d) = (splat(at.ns), splat(at.n_face), splat(at.d));
    let lane = f32x8::from([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
    let specular = at.ks != Vec3::ZERO;
    let shininess = f32x8::splat(at.shininess);
    let mut batch = FeelerBatch { origin: at.origin, light: index, ..Default::default() };
    let (mut i, mut j) = (0, 0);
    let mut s = 0;
    while s < total {
        let m = (total - s).min(LANES as u32);
        let (mut a, mut b) = ([0.0; LANES], [0.0; LANES]);
        for k in 0..m as usize {
            a[k] = i as f32 + rng.next_f32();
            b[k] = j as f32 + rng.next_f32();
            i += 1;
            if i == n[0] {
                (i, j) = (0, j + 1);
            }
        }
        s += m;
        let (a, b) = (f32x8::from(a), f32x8::from(b));
        // The sample `corner + du·a + dv·b`, and `Light::arriving`'s direction and distance.
        let target: [f32x8; 3] = std::array::from_fn(|c| corner[c] + du[c] * a + dv[c] * b);
        let w: [f32x8; 3] = std::array::from_fn(|c| target[c] - p[c]);
        let d2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
        let mut ok =
            lane.simd_lt(f32x8::splat(m as f32)) & d2.simd_gt(f32x8::ZERO) & d2.simd_lt(f32x8::splat(f32::INFINITY));
        let dist = d2.sqrt();
        let inv = f32x8::ONE / dist;
        let dir: [f32x8; 3] = std::array::from_fn(|c| w[c] * inv);
        // `Light::arriving`'s fade, then the sample's share, in its order of operations.
        let fade = match light.fade {
            Some(fade) => {
                let f2 = f32x8::splat(fade * fade);
                Some(f32x8::splat(2.0) * f2 / (f2 + dist * dist))
            }
            None => None,
        };
        // Lambert and Phong (`shade::feeler`).
        let cos = ns[0] * dir[0] + ns[1] * dir[1] + ns[2] * dir[2];
        let face = n_face[0] * dir[0] + n_face[1] * dir[1] + n_face[2] * dir[2];
        ok &= cos.simd_gt(f32x8::ZERO) & face.simd_gt(f32x8::ZERO);
        if !ok.any() {
            continue;
        }
        let spec = if specular {
            // reflect(−dir, ns) = 2·cos·ns − dir, against −d.
            let r: [f32x8; 3] = std::array::from_fn(|c| (cos + cos) * ns[c] - dir[c]);
            let rd = -(r[0] * d[0] + r[1] * d[1] + r[2] * d[2]);
            rd.max(f32x8::ZERO).powf_simd(shininess)
        } else {
            f32x8::ZERO
        };
        let radiance: [f32x8; 3] = std::array::from_fn(|c| {
            let color = f32x8::splat(light.color[c]);
            let light_c = fade.map_or(color, |k| color * k) * f32x8::splat(share);
            f32x8::splat(at.weight[c]) * light_c * (f32x8::splat(at.kd[c]) * cos + f32x8::splat(at.ks[c]) * spec)
        });
        let brightest = radiance[0].max(radiance[1]).max(radiance[2]);
        ok &= brightest.simd_gt(f32x8::ZERO);
        let mask = ok.to_bitmask() as u32;
        if mask == 0 {
            continue;
        }
        let feeler: [[f32; LANES]; 3] = std::array::from_fn(|c| (target[c] - origin[c]).to_array());
        let radiance = radiance.map(f32x8::to_array);
        if mask == (1 << m) - 1 {
            batch.dir = feeler;
            batch.radiance = radiance;
            batch.len = m as usize;
        } else {
            batch.len = 0;
            let mut bits = mask;
            while bits != 0 {
                let l = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                for c in 0..3 {
                    batch.dir[c][batch.len] = feeler[c][l];
                    batch.radiance[c][batch.len] = radiance[c][l];
                }
                batch.len += 1;
            }
        }
        f(&batch);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::shade::feeler;

    fn unit(rng: &mut Pcg32) -> Vec3 {
        crate::raygen::uniform_direction(rng)
    }

    /// The batches hold the scalar path's feelers, in its order: the rays to the bit, the light
    /// they bring within the SIMD power's rounding.
    #[test]
    fn batches_match_the_scalar_feelers() {
        let mut rng = Pcg32::new(7, 1);
        let mut feelers = 0;
        for case in 0..300u32 {
            let n = [1 + case % 5, 1 + (case / 5) % 4];
            let fade = (case % 3 == 0).then_some(3.0);
            let kind = LightKind::Rect { u: Vec3::new(2.0, 0.0, 0.3), v: Vec3::new(0.0, 0.2, 1.5), n };
            let light = Light { position: Vec3::new(0.5, 4.0, -0.5), color: Vec3::new(1.0, 0.8, 0.6), kind, fade };
            let p = Vec3::new(6.0 * rng.next_f32() - 3.0, 2.0 * rng.next_f32() - 1.0, 6.0 * rng.next_f32() - 3.0);
            let n_face = unit(&mut rng);
            let ns = (n_face + 0.3 * unit(&mut rng)).normalize();
            let at = LitPoint {
                p,
                origin: crate::ray::offset_ray_origin(p, n_face),
                ns,
                n_face,
                d: unit(&mut rng),
                weight: Vec3::new(0.9, 0.5, 0.7),
                kd: Vec3::new(0.8, 0.1 * (case % 4) as f32, 0.3),
                ks: if case % 2 == 0 { Vec3::splat(0.6) } else { Vec3::ZERO },
                shininess: [1.0, 7.5, 20.0, 300.0][(case % 4) as usize],
            };
            let seed = rng.next_u32() as u64;
            let mut expect = Vec::new();
            light.each_sample(p, &mut Pcg32::new(seed, 3), |inc, target| expect.extend(feeler(&at, &inc, target)));
            let mut got = Vec::new();
            rect_feelers(&light, 2, &at, &mut Pcg32::new(seed, 3), |b| {
                assert!(b.len <= LANES && b.light == 2);
                got.extend(b.feelers());
            });
            assert_eq!(got.len(), expect.len(), "case {case}");
            for ((r, c), (er, ec)) in got.iter().zip(&expect) {
                assert_eq!(r, er, "case {case}");
                let err = (*c - *ec).abs().max_element();
                assert!(err <= 2e-6 * ec.max_element(), "case {case}: {c} against {ec}");
            }
            feelers += got.len();
        }
        assert!(feelers > 1000, "too few lit samples to test: {feelers}");
    }

    #[test]
    fn other_lights_are_left_to_the_scalar_path() {
        let at = LitPoint {
            p: Vec3::ZERO,
            origin: Vec3::ZERO,
            ns: Vec3::Y,
            n_face: Vec3::Y,
            d: Vec3::NEG_Y,
            weight: Vec3::ONE,
            kd: Vec3::ONE,
            ks: Vec3::ZERO,
            shininess: 1.0,
        };
        let light = Light::point(Vec3::Y, Vec3::ONE);
        let mut batches = 0;
        rect_feelers(&light, 0, &at, &mut Pcg32::new(0, 0), |_| batches += 1);
        assert_eq!(batches, 0, "no batch for a point light");
    }
}
