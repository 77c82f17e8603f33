//! Scene-file text: parsing answers with a scene or a typed error; a parsed scene of modest size
//! (generated meshes only: no files are read) builds and answers a ray.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strahl::scene_file::MeshSource;
use strahl::{BuildConfig, Query, SceneFile};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(file) = SceneFile::parse(text, std::path::Path::new("/nonexistent/fuzz.toml")) else { return };
    // Keep each execution small: the limits themselves are tested by their own errors.
    let small = file.instances.len() <= 256
        && file.meshes.iter().all(|(_, s)| match *s {
            MeshSource::Obj(_) => true,
            MeshSource::Sphereflake { levels, stacks, slices } => levels <= 1 && stacks <= 16 && slices <= 16,
            MeshSource::Sphere { stacks, slices, .. } => stacks <= 64 && slices <= 64,
        });
    if !small {
        return;
    }
    // OBJ meshes name files that do not exist: a typed error.
    let Ok(scene) = file.build(&BuildConfig::default()) else { return };
    let r = strahl::Ray::new(glam::Vec3::new(0.0, 0.0, 10.0), glam::Vec3::new(0.0, 0.0, -1.0));
    let _ = scene.intersect(&r);
    let _ = scene.occluded(&r);
});
