//! The library in one page: load an OBJ (or build a procedural sphereflake), trace a camera's
//! rays as a coherent stream and their shadow rays towards a light, and write a shaded PNG.
//!
//! `cargo run --release --example quickstart -- [scene.obj] [out.png]` (the rates printed are of
//! one pass each, the first including the thread pool's start).
use std::time::Instant;

use glam::Vec3;
use strahl::{BuildConfig, Camera, Coherence, HitStream, Query, Scene, procedural, raygen};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let out = args.get(2).cloned().unwrap_or_else(|| "quickstart.png".into());
    let t = Instant::now();
    let scene = match args.get(1) {
        Some(obj) => Scene::from_obj(obj, &BuildConfig::default())?,
        None => Scene::build(vec![procedural::sphereflake(3, 12, 24)], &BuildConfig::default())?,
    };
    println!("built {} triangles in {:.1} ms", scene.triangle_count(), t.elapsed().as_secs_f64() * 1e3);
    let Some((lo, hi)) = scene.bounds() else {
        return Err("the scene has no triangles".into());
    };

    // A camera looking at the scene's centre from outside its bounding box.
    let (centre, size) = ((lo + hi) * 0.5, (hi - lo).length());
    let camera = Camera::look_at(centre + Vec3::new(0.6, 0.5, 1.0) * size, centre, Vec3::Y, 45.0);
    let (w, h) = (512u32, 512u32);
    strahl::simd::set_flush_denormals();

    // Camera rays in 4×4 tiles, traced as one coherent stream on the rayon pool.
    let (rays, pixel) = raygen::primary(&camera, w, h);
    let mut hits = HitStream::default();
    let t = Instant::now();
    scene.intersect_stream_par(&rays, &mut hits, Coherence::Coherent);
    let primary = t.elapsed().as_secs_f64();

    // Shadow rays from every hit towards a light above the camera.
    let light = centre + Vec3::new(0.3, 1.5, 0.8) * size;
    let (shadow, from) = raygen::shadow(&rays, &hits, light, 1e-4 * size);
    let mut blocked = Vec::new();
    let t = Instant::now();
    scene.occluded_stream_par(&shadow, &mut blocked, Coherence::Coherent);
    let shadows = t.elapsed().as_secs_f64();

    // Lambert shading, halved in shadow.
    let mut lit = vec![false; rays.len()];
    for (k, &i) in from.iter().enumerate() {
        lit[i as usize] = !blocked[k];
    }
    let mut img = image::GrayImage::new(w, h);
    for i in 0..rays.len() {
        let p = pixel[i];
        let v = hits.get(i).map_or(0.1, |hit| {
            let ray = rays.get(i);
            let n = hit.ng.normalize_or_zero();
            let n = if n.dot(ray.dir) > 0.0 { -n } else { n };
            let l = (light - ray.at(hit.t)).normalize_or_zero();
            let diffuse = n.dot(l).max(0.0);
            0.15 + 0.85 * diffuse * if lit[i] { 1.0 } else { 0.3 }
        });
        img.put_pixel(p % w, p / w, image::Luma([(v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0) as u8]));
    }
    img.save(&out)?;
    let mrays = |n: usize, s: f64| n as f64 / s / 1e6;
    println!(
        "{} camera rays: {:.1} Mrays/s; {} shadow rays: {:.1} Mrays/s; wrote {out}",
        rays.len(),
        mrays(rays.len(), primary),
        shadow.len(),
        mrays(shadow.len(), shadows)
    );
    Ok(())
}
