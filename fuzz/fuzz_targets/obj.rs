//! OBJ bytes: the loader answers with meshes or a typed error, never a panic, hang or abort; every
//! mesh it returns has its indices in range and builds.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strahl::{BuildConfig, Scene};

fuzz_target!(|data: &[u8]| {
    let Ok(meshes) = strahl::parse_obj(data, std::path::Path::new("fuzz.obj")) else { return };
    for m in &meshes {
        let n = m.positions().len();
        assert!(m.indices().iter().flatten().all(|&i| (i as usize) < n));
    }
    let tris: usize = meshes.iter().map(|m| m.triangle_count()).sum();
    if tris <= 4096 {
        let scene = Scene::build(meshes, &BuildConfig::default()).expect("a loaded OBJ builds");
        let r = strahl::Ray::new(glam::Vec3::new(0.1, 0.2, 5.0), glam::Vec3::new(0.0, 0.0, -1.0));
        let _ = strahl::Query::intersect(&scene, &r);
    }
});
