//! Scene-file text: parsing answers with a scene or a typed error; a parsed scene of modest size
//! (generated meshes only: no files are read) builds, answers a ray, and — when it has a camera —
//! renders a tiny image with its own materials, lights and projection, with the wavefront and the
//! depth-first recursion agreeing.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strahl::render::{Renderer, Settings};
use strahl::scene_file::MeshSource;
use strahl::{BuildConfig, Query, SceneFile};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(file) = SceneFile::parse(text, std::path::Path::new("/nonexistent/fuzz.toml")) else { return };
    // Keep each execution small: the limits themselves are tested by their own errors.
    let small = file.instances.len() <= 256
        && file.meshes.iter().all(|(_, s)| match *s {
            MeshSource::Obj(_) | MeshSource::ObjWithMaterials(_) | MeshSource::Box { .. } | MeshSource::Quad { .. } => true,
            MeshSource::Sphereflake { levels, stacks, slices } => levels <= 1 && stacks <= 16 && slices <= 16,
            MeshSource::Sphere { stacks, slices, .. } => stacks <= 64 && slices <= 64,
            MeshSource::AnalyticSphere { .. } => true,
            MeshSource::AnalyticSphereflake { levels } => levels <= 3,
            MeshSource::Solid(_) => true,
        });
    if !small {
        return;
    }
    // OBJ meshes name files that do not exist: a typed error.
    let Ok(objects) = file.load_objects() else { return };
    let world = file.world(&objects);
    let Ok(scene) = file.build_from(objects, &BuildConfig::default()) else { return };
    let r = strahl::Ray::new(glam::Vec3::new(0.0, 0.0, 10.0), glam::Vec3::new(0.0, 0.0, -1.0));
    let _ = scene.intersect(&r);
    let _ = scene.occluded(&r);
    let (Ok(world), Some(camera)) = (world, file.camera.and_then(|c| c.render_camera())) else { return };
    let s = file.render.settings;
    let settings = Settings { width: 6, height: 4, spp: s.spp.min(2), max_depth: s.max_depth.min(4), ..s };
    let r = Renderer { query: &scene, world: &world, camera, settings };
    let (a, sa) = r.render(&|_| {}).expect("checked settings render");
    let (b, sb) = r.render_recursive().expect("checked settings render");
    assert_eq!(sa.rays, sb.rays);
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        // Both sum the same terms in another order; non-finite only if both are.
        let tol = 1e-4 * p.abs().max_element().max(1.0);
        assert!(
            p.is_finite() == q.is_finite() && (!p.is_finite() || (*p - *q).abs().max_element() <= tol),
            "{p} vs {q}"
        );
    }
    let _ = r.ray_tree(0, 0).expect("pixel inside the image");
});
