//! Differential: arbitrary triangle soups (NaN, infinities, denormals, huge and tiny coordinates,
//! degenerate and duplicate triangles) and arbitrary rays and intervals, through every triangle
//! test × box test × build preset, single rays, packets and both stream modes, closest and any
//! hit — against brute force with the same triangle test. Disagreements are decided in float64
//! (`strahl::exact_hit`): only one whose float64 answer is clear (away from edges and interval
//! ends by a margin above float32's error at that scale) is a bug; the rest are ties.
#![no_main]

use arbitrary::Arbitrary;
use glam::Vec3;
use libfuzzer_sys::fuzz_target;
use strahl::{
    BoxTest, BuildConfig, Coherence, Hit, HitPacket, HitStream, Instance, InstancedScene, Query, Ray, RayPacket,
    RayStream, Scene, TriangleMesh, TriangleTest,
};

#[derive(Arbitrary, Debug, Clone, Copy)]
enum Coord {
    /// A small integer, scaled by the input's scale: geometry that meets and touches.
    Small(i8),
    /// Any float at all.
    Raw(f32),
}

#[derive(Arbitrary, Debug)]
struct RayIn {
    o: [Coord; 3],
    d: [Coord; 3],
    tnear: Option<Coord>,
    tfar: Option<Coord>,
}

#[derive(Arbitrary, Debug)]
struct Input {
    config: u8,
    scale: u8,
    tris: Vec<[[Coord; 3]; 3]>,
    rays: Vec<RayIn>,
    /// Instances of the soup: a translation (in units of the scale), a turn about y in
    /// 1/256 turns, and a scale exponent.
    instances: Vec<([i8; 3], u8, i8)>,
}

fn value(c: Coord, scale: f32) -> f32 {
    match c {
        Coord::Small(i) => i as f32 * scale / 16.0,
        Coord::Raw(x) => x,
    }
}

/// Float64 verdict on one triangle for one ray: `Some(true)` clearly hit, `Some(false)` clearly
/// missed, `None` too close to an edge or an interval end to tell at float32's precision here.
fn verdict(r: &Ray, tri: [Vec3; 3]) -> Option<bool> {
    // Triangles with a non-finite corner or no area are never hit.
    if !tri.iter().all(|p| p.is_finite()) {
        return Some(false);
    }
    let e1 = (tri[1] - tri[0]).as_dvec3();
    let e2 = (tri[2] - tri[0]).as_dvec3();
    let size = e1.cross(e2).length().sqrt();
    if !(size > 0.0) {
        return Some(false);
    }
    let mag = tri.iter().map(|p| p.abs().max_element()).fold(r.origin.abs().max_element(), f32::max) as f64;
    let eps = f32::EPSILON as f64;
    let margin = 1e-3 + 256.0 * eps * mag / size;
    let dlen = r.dir.as_dvec3().length();
    let (tn, tf) = (r.tnear.max(0.0) as f64, r.tfar as f64);
    match strahl::exact_hit(r.origin, r.dir, tri) {
        None => {
            // Parallel to the plane in float64; near-parallel rays are ties.
            None
        }
        Some((t, b)) => {
            // The tests' products are of third degree: the determinant `(e2 × e1) · d` and
            // `t·det` around size²·|d| and size²·|t·d|. Near float32's smallest normal numbers
            // (and below them, flushed to zero by FTZ/DAZ) no float32 test can tell; an instance
            // scaled by up to 2^7 makes its object's products 2^21 times smaller still.
            let tiny = 1e-28;
            // Beyond the documented range (coordinates within ±2^40, instances scaling by up to
            // 2^7; direction lengths from 1e-12 to 1e13), answers are best effort: only the
            // interval and consistency checks hold there.
            if !(1e-12..=1e13).contains(&dlen) || mag > 4.4e12 {
                return None;
            }
            if size * size * dlen < tiny || size * size * dlen * t.abs() < tiny {
                return None;
            }
            let mb = b[0].min(b[1]).min(b[2]);
            let mt = 1e-3 * t.abs() + 256.0 * eps * mag / dlen;
            if mb < -margin || t < tn - mt || t > tf + mt {
                Some(false)
            } else if mb > margin && t > tn + mt && t < tf - mt {
                Some(true)
            } else {
                None
            }
        }
    }
}

struct Check<'a> {
    scene: &'a Scene,
    what: String,
}

impl Check<'_> {
    fn tri(&self, h: &Hit) -> [Vec3; 3] {
        self.scene.meshes()[h.geom_id as usize].triangle(h.prim_id as usize)
    }

    /// One query's answer `a` for ray `r` against brute force `b`.
    fn closest(&self, api: &str, r: &Ray, a: Option<Hit>, b: Option<Hit>) {
        if let Some(h) = a {
            let tn = if r.tnear > 0.0 { r.tnear } else { 0.0 };
            assert!(h.t > tn && h.t <= r.tfar, "{}: {api}: t {} outside ({tn}, {}] for {r:?}", self.what, h.t, r.tfar);
            assert!(h.u.is_finite() && h.v.is_finite(), "{}: {api}: barycentrics {h:?}", self.what);
        }
        let close = |x: f32, y: f32| (x - y).abs() <= 1e-5 * x.abs().max(y.abs());
        match (a, b) {
            (None, None) => {}
            (Some(h), None) => assert!(
                verdict(r, self.tri(&h)).is_none(),
                "{}: {api} hit {h:?} that brute force does not find, for {r:?}",
                self.what
            ),
            (None, Some(b)) => assert!(
                verdict(r, self.tri(&b)) != Some(true),
                "{}: {api} lost the clear hit {b:?} for {r:?}",
                self.what
            ),
            (Some(h), Some(b)) if h.t > b.t && !close(h.t, b.t) => assert!(
                verdict(r, self.tri(&b)) != Some(true),
                "{}: {api} found {h:?} behind the clear hit {b:?} for {r:?}",
                self.what
            ),
            (Some(h), Some(b)) if h.t < b.t && !close(h.t, b.t) => assert!(
                verdict(r, self.tri(&h)).is_none(),
                "{}: {api} found {h:?} before brute force's {b:?} for {r:?}",
                self.what
            ),
            _ => {}
        }
    }
}

fuzz_target!(|input: Input| {
    if input.tris.len() > 256 || input.rays.is_empty() || input.rays.len() > 48 {
        return;
    }
    let scale = 2f32.powi((input.scale % 96) as i32 - 48);
    let mut p = Vec::new();
    let mut idx = Vec::new();
    for t in &input.tris {
        let k = p.len() as u32;
        for c in t {
            p.push(Vec3::new(value(c[0], scale), value(c[1], scale), value(c[2], scale)));
        }
        idx.push([k, k + 1, k + 2]);
    }
    let Ok(mesh) = TriangleMesh::new("fuzz", p, idx) else { return };
    let object = mesh.clone();
    let rays: Vec<Ray> = input
        .rays
        .iter()
        .map(|r| {
            let v = |c: [Coord; 3]| Vec3::new(value(c[0], scale), value(c[1], scale), value(c[2], scale));
            Ray::segment(
                v(r.o),
                v(r.d),
                r.tnear.map_or(0.0, |c| value(c, scale)),
                r.tfar.map_or(f32::INFINITY, |c| value(c, scale)),
            )
        })
        .collect();
    let test = TriangleTest::ALL[(input.config % 3) as usize];
    let boxes = BoxTest::ALL[(input.config / 3 % 2) as usize];
    let base = if input.config / 6 % 2 == 1 { BuildConfig::high() } else { BuildConfig::default() };
    let Ok(scene) = Scene::build(vec![mesh], &base.with_tests(test, boxes)) else { return };
    let check = Check { scene: &scene, what: format!("{test:?}/{boxes:?}/{}", input.config / 6 % 2) };
    let brute: Vec<Option<Hit>> = rays.iter().map(|r| scene.intersect_brute_force(r)).collect();
    // The fast box test may lose hits by design (ACCURACY.md): only the conservative one
    // promises never to.
    let strict = boxes == BoxTest::Conservative;
    for (i, r) in rays.iter().enumerate() {
        let single = scene.intersect(r);
        if strict {
            check.closest("single", r, single, brute[i]);
        }
        assert_eq!(scene.occluded(r), single.is_some(), "{}: occluded vs intersect for {r:?}", check.what);
    }
    for (c, chunk) in rays.chunks(16).enumerate() {
        let packet = RayPacket::from_rays(chunk);
        let mut hp = HitPacket::default();
        scene.intersect_packet(&packet, &mut hp);
        let occ = scene.occluded_packet(&packet);
        for (l, r) in chunk.iter().enumerate() {
            if strict {
                check.closest("packet", r, hp.get(l), brute[16 * c + l]);
            }
            if occ & (1 << l) != 0 {
                assert!(
                    hp.get(l).is_some() || brute[16 * c + l].is_some() || !strict,
                    "{}: occluded packet lane",
                    check.what
                );
            }
        }
    }
    let stream: RayStream = rays.iter().copied().collect();
    for mode in [Coherence::Coherent, Coherence::Incoherent] {
        let mut hs = HitStream::default();
        scene.intersect_stream(&stream, &mut hs, mode);
        let mut occ = Vec::new();
        scene.occluded_stream(&stream, &mut occ, mode);
        for (i, r) in rays.iter().enumerate() {
            if strict {
                check.closest(&format!("stream {mode:?}"), r, hs.get(i), brute[i]);
            }
            assert_eq!(occ.len(), rays.len());
        }
    }
    // Instanced against flattened: the same placements built both ways. Each engine of the two
    // rounds its own way (the instance moves the ray, the flattening the vertices), so a
    // disagreement is a bug only where the flattened triangle's float64 verdict is clear.
    if input.instances.is_empty() || input.instances.len() > 4 || !strict {
        return;
    }
    let instances: Vec<Instance> = input
        .instances
        .iter()
        .map(|&(t, turn, s)| {
            let at = Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32) * scale;
            let rot = glam::Quat::from_rotation_y(turn as f32 / 256.0 * std::f32::consts::TAU);
            let sc = 2f32.powi((s % 8) as i32);
            Instance::new(0, glam::Affine3A::from_scale_rotation_translation(Vec3::splat(sc), rot, at))
        })
        .collect();
    let config = base.with_tests(test, boxes);
    let Ok(world) = InstancedScene::build(vec![vec![object]], instances, &config) else { return };
    let Ok(flat) = world.flatten(&config) else { return };
    let fcheck = Check { scene: &flat, what: format!("{} instanced", check.what) };
    for r in &rays {
        let (a, f) = (world.intersect(r), flat.intersect(r));
        // A hit the flattened world finds clearly must not be lost by the instanced one. Each
        // rounds its own way (the flattening moves the vertices, the instance level the ray), so
        // the verdict is taken in object space, on the object's own triangle and the ray moved
        // there. (A hit only the instanced world finds is no BVH matter: the flattened vertices'
        // rounding decides those.) Badouel's test projects the hit point `o + t·d`, whose error
        // grows with `|t·d|` beyond the verdict's margin; it is held to consistency only.
        if let (None, Some(h), true) = (a, f, test != TriangleTest::Badouel) {
            let inst = &world.instances()[h.geom_id as usize];
            let to_object = inst.transform.inverse();
            let local = Ray {
                origin: to_object.transform_point3(r.origin),
                dir: to_object.transform_vector3(r.dir),
                ..*r
            };
            let tri = world.objects()[inst.object].meshes()[0].triangle(h.prim_id as usize);
            assert!(
                verdict(&local, tri) != Some(true),
                "{}: the instanced world lost the clear hit {h:?} for {r:?}",
                fcheck.what
            );
        }
        assert_eq!(world.occluded(r), a.is_some(), "{}: occluded vs intersect for {r:?}", fcheck.what);
    }
});
