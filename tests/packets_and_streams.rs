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
