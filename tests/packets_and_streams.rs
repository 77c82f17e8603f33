//! Packet and stream queries give the single-ray answers, serially and in parallel.
#![allow(clippy::needless_range_loop)]

mod common;

use common::*;
use glam::Vec3;
use strahl::Query;
use strahl::{Camera, Coherence, HitPacket, HitStream, PACKET_WIDTH, Ray, RayPacket, RayStream, Scene, raygen};

fn all_apis_agree(scene: &Scene, rays: &RayStream, what: &str) {
    let n = rays.len();
    let single: Vec<_> = (0..n).map(|i| scene.intersect(&rays.get(i))).collect();
    let single_occ: Vec<bool> = (0..n).map(|i| scene.occluded(&rays.get(i))).collect();
    for i in 0..n {
        assert_eq!(single[i].is_some(), single_occ[i], "{what}: occluded vs intersect, ray {i}");
    }
    // Packets, with every other packet missing some lanes.
    for (k, start) in (0..n).step_by(PACKET_WIDTH).enumerate() {
        let mut p = rays.packet(start, PACKET_WIDTH);
        if k % 2 == 1 {
            p.active &= 0b1010_1010_1010_1011;
        }
        let mut hp = HitPacket::default();
        scene.intersect_packet(&p, &mut hp);
        let occ = scene.occluded_packet(&p);
        for lane in 0..PACKET_WIDTH.min(n - start) {
            let expect = if p.is_active(lane) { single[start + lane] } else { None };
            assert_same_hit(hp.get(lane), expect, 0.0, &format!("{what}: packet ray {}", start + lane));
            assert_eq!(occ & (1 << lane) != 0, expect.is_some(), "{what}: occluded packet ray {}", start + lane);
        }
        assert_eq!(occ & !p.active, 0, "inactive lanes are never occluded");
    }
    // Octant groups of up to 32 rays walked together (the occlusion stream of large scenes), with
    // one ray of another octant slipped into every third group: it is walked alone.
    let octant = |i: usize| {
        let r = rays.get(i);
        (r.dir.x.is_sign_negative() as u32)
            | (r.dir.y.is_sign_negative() as u32) << 1
            | (r.dir.z.is_sign_negative() as u32) << 2
    };
    for o in 0..8 {
        let ids: Vec<u16> = (0..n.min(u16::MAX as usize)).filter(|&i| octant(i) == o).map(|i| i as u16).collect();
        for (k, chunk) in ids.chunks(31).enumerate() {
            let mut group = chunk.to_vec();
            if k % 3 == 2
                && let Some(other) = (0..n.min(u16::MAX as usize)).find(|&i| octant(i) != o)
            {
                group.push(other as u16);
            }
            let bits = scene.occluded_octant_rays(rays, 0, &group, o);
            for (lane, &id) in group.iter().enumerate() {
                assert_eq!(bits & (1 << lane) != 0, single_occ[id as usize], "{what}: octant group, ray {id}");
            }
        }
    }
    for coherence in [Coherence::Coherent, Coherence::Incoherent] {
        let mut a = HitStream::default();
        let mut b = HitStream::default();
        scene.intersect_stream(rays, &mut a, coherence);
        scene.intersect_stream_par(rays, &mut b, coherence);
        let mut oa = Vec::new();
        let mut ob = Vec::new();
        scene.occluded_stream(rays, &mut oa, coherence);
        scene.occluded_stream_par(rays, &mut ob, coherence);
        for i in 0..n {
            assert_same_hit(a.get(i), single[i], 0.0, &format!("{what}: stream {coherence:?} ray {i}"));
            assert_same_hit(b.get(i), single[i], 0.0, &format!("{what}: par stream {coherence:?} ray {i}"));
            assert_eq!(oa[i], single_occ[i]);
            assert_eq!(ob[i], single_occ[i]);
        }
    }
}

#[test]
fn coherent_camera_rays() {
    let scene = scene_of(vec![strahl::procedural::sphereflake(2, 8, 16)]);
    let cam = Camera::look_at(Vec3::new(0.0, 1.2, 4.5), Vec3::new(0.0, 0.3, 0.0), Vec3::Y, 60.0);
    let (rays, _) = raygen::primary(&cam, 130, 97);
    all_apis_agree(&scene, &rays, "sphereflake primary");
    let mut hits = HitStream::default();
    scene.intersect_stream(&rays, &mut hits, Coherence::Coherent);
    let (shadow, _) = raygen::shadow(&rays, &hits, Vec3::new(3.0, 6.0, 4.0), 1e-4);
    all_apis_agree(&scene, &shadow, "sphereflake shadow");
    let (diffuse, _) = raygen::diffuse(&rays, &hits, 1, 1e-4);
    all_apis_agree(&scene, &diffuse, "sphereflake diffuse");
}

#[test]
fn incoherent_random_rays() {
    let scene = scene_of(vec![random_soup(5, 5000, 0.05)]);
    let rays: RayStream = random_rays(5, 5000).into_iter().collect();
    all_apis_agree(&scene, &rays, "soup");
}

#[test]
fn every_method_agrees_across_apis() {
    let mesh = strahl::procedural::sphereflake(1, 8, 16);
    let cam = Camera::look_at(Vec3::new(0.0, 1.2, 4.5), Vec3::new(0.0, 0.3, 0.0), Vec3::Y, 60.0);
    let (primary, _) = raygen::primary(&cam, 64, 48);
    let random: RayStream = random_rays(8, 2000).into_iter().collect();
    for t in strahl::TriangleTest::ALL {
        for b in strahl::BoxTest::ALL {
            let scene = Scene::build(vec![mesh.clone()], &strahl::BuildConfig::default().with_tests(t, b)).unwrap();
            all_apis_agree(&scene, &primary, &format!("{t:?} {b:?} primary"));
            all_apis_agree(&scene, &random, &format!("{t:?} {b:?} random"));
        }
    }
}

#[test]
fn mixed_bad_lanes_in_a_packet() {
    let scene = scene_of(vec![random_soup(6, 200, 0.2)]);
    let good: Vec<Ray> = random_rays(6, PACKET_WIDTH);
    let mut rays = good.clone();
    rays[1].dir = Vec3::ZERO;
    rays[3].origin.x = f32::NAN;
    rays[5].tnear = 10.0;
    rays[5].tfar = 1.0;
    rays[7].dir.y = f32::INFINITY;
    rays[9].tfar = f32::NAN;
    let p = RayPacket::from_rays(&rays);
    let mut hp = HitPacket::default();
    scene.intersect_packet(&p, &mut hp);
    let occ = scene.occluded_packet(&p);
    for lane in 0..PACKET_WIDTH {
        let expect = scene.intersect(&rays[lane]);
        if [1, 3, 5, 7, 9].contains(&lane) {
            assert!(expect.is_none() && hp.get(lane).is_none() && occ & (1 << lane) == 0, "lane {lane}");
        } else {
            assert_same_hit(hp.get(lane), expect, 0.0, "good lane");
        }
    }
}

#[test]
fn negative_and_signed_zero_tnear_agree_across_apis() {
    // Packets use integer minima and maxima only when every live lane's tnear is >= 0; camera
    // packets at -0.0 (frustum), and packets with some lanes reaching behind their origin.
    let scene = scene_of(vec![strahl::procedural::sphereflake(2, 8, 16)]);
    let cam = Camera::look_at(Vec3::new(0.0, 0.2, 1.6), Vec3::new(0.0, 0.3, 0.0), Vec3::Y, 60.0);
    let (primary, _) = raygen::primary(&cam, 64, 48);
    let with_tnear = |f: &dyn Fn(usize) -> f32| -> RayStream {
        (0..primary.len()).map(|i| Ray { tnear: f(i), ..primary.get(i) }).collect()
    };
    all_apis_agree(&scene, &with_tnear(&|_| -0.0), "tnear -0.0");
    all_apis_agree(&scene, &with_tnear(&|_| -1.0), "tnear -1");
    all_apis_agree(&scene, &with_tnear(&|i| if i % 7 == 3 { -0.8 } else { 0.0 }), "some lanes tnear < 0");
    let random: RayStream = random_rays(12, 3000)
        .into_iter()
        .enumerate()
        .map(|(i, r)| Ray { tnear: -((i % 3) as f32) * 0.4, ..r })
        .collect();
    all_apis_agree(&scene, &random, "random rays, tnear 0 / -0.4 / -0.8");
}

#[test]
fn coherent_groups_of_mixed_packets() {
    // A coherent stream traces 64 rays (four packets) as one group when all share an origin and
    // direction octant, and packet by packet otherwise. Blocks here mix: a second camera's tile
    // (another origin), a tile with NaN and zero-direction lanes, an all-invalid tile, a tile
    // looking the other way along x (another octant), and whole blocks of one camera.
    let scene = scene_of(vec![strahl::procedural::sphereflake(2, 8, 16)]);
    let a = Camera::look_at(Vec3::new(0.0, 0.2, 1.6), Vec3::new(0.0, 0.3, 0.0), Vec3::Y, 60.0);
    let b = Camera::look_at(Vec3::new(0.3, 1.0, 1.2), Vec3::new(0.0, 0.3, 0.0), Vec3::Y, 60.0);
    let (ra, _) = raygen::primary(&a, 64, 64);
    let (rb, _) = raygen::primary(&b, 64, 64);
    let mut rays = RayStream::default();
    for i in 0..ra.len() {
        let (block, tile, lane) = (i / 64, i / 16 % 4, i % 16);
        let r = match (block % 5, tile) {
            (0, 1) => rb.get(i),
            (1, 2) if lane % 3 == 0 => Ray { dir: Vec3::new(f32::NAN, 0.0, -1.0), ..ra.get(i) },
            (1, 2) if lane % 3 == 1 => Ray { dir: Vec3::ZERO, ..ra.get(i) },
            (2, 3) => Ray { dir: Vec3::ZERO, ..ra.get(i) },
            (3, 0) => Ray { dir: ra.get(i).dir * Vec3::new(-1.0, 1.0, 1.0), ..ra.get(i) },
            _ => ra.get(i),
        };
        rays.push(&r);
    }
    all_apis_agree(&scene, &rays, "mixed groups");
}

#[test]
fn reused_hit_streams_hold_only_the_new_answers() {
    // Stream queries clear each chunk as they trace it: a stream reused for rays that all miss,
    // shorter and longer than before, must hold no hit from the earlier query.
    let scene = scene_of(vec![strahl::procedural::sphereflake(2, 8, 16)]);
    let cam = Camera::look_at(Vec3::new(0.0, 0.2, 1.6), Vec3::new(0.0, 0.3, 0.0), Vec3::Y, 60.0);
    let (rays, _) = raygen::primary(&cam, 96, 96);
    let away =
        |n: usize| -> RayStream { (0..n).map(|i| Ray { dir: -rays.get(i % rays.len()).dir, ..rays.get(0) }).collect() };
    for coherence in [Coherence::Coherent, Coherence::Incoherent] {
        let mut hits = HitStream::default();
        scene.intersect_stream_par(&rays, &mut hits, coherence);
        assert!((0..hits.len()).any(|i| hits.get(i).is_some()));
        for n in [rays.len() / 3, rays.len(), rays.len() + 777] {
            scene.intersect_stream_par(&rays, &mut hits, coherence);
            let misses = away(n);
            scene.intersect_stream_par(&misses, &mut hits, coherence);
            assert_eq!(hits.len(), n);
            for i in 0..n {
                assert_same_hit(
                    hits.get(i),
                    scene.intersect(&misses.get(i)),
                    0.0,
                    &format!("{coherence:?} ray {i} of {n}"),
                );
                assert_eq!(hits.t[i], f32::INFINITY);
            }
            let mut serial = HitStream::default();
            scene.intersect_stream(&rays, &mut serial, coherence);
            scene.intersect_stream(&misses, &mut serial, coherence);
            assert!((0..n).all(|i| serial.get(i).is_none() && serial.t[i] == f32::INFINITY));
        }
    }
}

#[test]
fn octant_groups_past_32_rays_trace_only_the_first_32() {
    let scene = scene_of(vec![strahl::procedural::sphereflake(1, 8, 16)]);
    // Rays along -z from in front of the flake: all in one octant (bit 2), most occluded.
    let rays: RayStream =
        (0..40).map(|i| Ray::new(Vec3::new(-0.5 + 0.025 * i as f32, 0.3, 3.0), Vec3::new(0.0, 0.0, -1.0))).collect();
    let ids: Vec<u16> = (0..40).collect();
    let bits = scene.occluded_octant_rays(&rays, 0, &ids, 4);
    let expect = (0..32).fold(0u32, |m, i| m | (scene.occluded(&rays.get(i)) as u32) << i);
    assert_eq!(bits, expect);
    assert!(expect.count_ones() > 8, "the test rays should mostly hit: {expect:b}");
}
