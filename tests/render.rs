//! The renderer end to end: the wavefront against the depth-first recursion, thread-count
//! independence, physics that must hold in a whole image (energy conservation of Fresnel
//! splits, Beer–Lambert through a slab), the ray tree of a known scene, and bad input.

use std::path::Path;

use glam::Vec3;
use strahl::render::{RayKind, Renderer, Settings, World};
use strahl::{BuildConfig, InstancedScene, SceneFile};

fn load(text: &str) -> (SceneFile, InstancedScene, World) {
    let file = SceneFile::parse(text, Path::new("/virtual/scene.toml")).unwrap();
    let objects = file.load_objects().unwrap();
    let world = file.world(&objects).unwrap();
    let scene = InstancedScene::build(objects, file.instances.clone(), &BuildConfig::default()).unwrap();
    (file, scene, world)
}

fn renderer<'a>(
    file: &SceneFile,
    scene: &'a InstancedScene,
    world: &'a World,
    settings: Settings,
) -> Renderer<'a, InstancedScene> {
    Renderer { query: scene, world, camera: file.camera.unwrap().render_camera().unwrap(), settings }
}

fn whitted() -> String {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
    std::fs::read_to_string(dir.join("whitted.toml")).unwrap()
}

#[test]
fn wavefront_equals_the_recursion_and_ignores_thread_count() {
    let (file, scene, world) = load(&whitted());
    let mut settings = file.render.settings;
    (settings.width, settings.height, settings.spp) = (96, 72, 2);
    let r = renderer(&file, &scene, &world, settings);
    let (wave, ws) = r.render(&|_| {}).unwrap();
    let (rec, rs) = r.render_recursive().unwrap();
    // The same rays of every kind, the same cut-offs.
    assert_eq!(ws.rays, rs.rays);
    assert_eq!(ws.counts_cut_by_weight, rs.counts_cut_by_weight);
    assert!(ws.rays[RayKind::Refracted as usize] > 1000 && ws.rays[RayKind::Reflected as usize] > 1000);
    // The same colours, up to the order of float sums.
    let worst = wave.pixels.iter().zip(&rec.pixels).map(|(a, b)| (*a - *b).abs().max_element()).fold(0.0, f32::max);
    assert!(worst < 1e-5, "largest difference {worst}");
    // One thread or two: bit-identical.
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let (a, _) = one.install(|| r.render(&|_| {})).unwrap();
    let (b, _) = two.install(|| r.render(&|_| {})).unwrap();
    assert_eq!(a, b);
    assert_eq!(a, wave);
}

/// Rectangle lights' feelers leave shading in SIMD batches, which the wavefront appends to its
/// streams and the recursion unpacks one by one: both must trace the same feelers.
#[test]
fn wavefront_equals_the_recursion_under_an_area_light() {
    let text = whitted().replacen(
        "[[light]]",
        "[[light]]\nkind = \"rect\"\nposition = [0.0, 9.0, -2.0]\nu = [3.0, 0.0, 0.0]\nv = [0.0, 0.5, 2.0]\nsamples = [5, 3]\ncolor = 0.8\nfade = 12.0\n\n[[light]]",
        1,
    );
    let (file, scene, world) = load(&text);
    let mut settings = file.render.settings;
    (settings.width, settings.height) = (64, 48);
    let r = renderer(&file, &scene, &world, settings);
    let (wave, ws) = r.render(&|_| {}).unwrap();
    let (rec, rs) = r.render_recursive().unwrap();
    assert_eq!(ws.rays, rs.rays);
    let hits = ws.rays[RayKind::Primary as usize];
    assert!(ws.rays[RayKind::Shadow as usize] > 8 * hits, "15 feelers per lit point: {:?}", ws.rays);
    let worst = wave.pixels.iter().zip(&rec.pixels).map(|(a, b)| (*a - *b).abs().max_element()).fold(0.0, f32::max);
    assert!(worst < 1e-5, "largest difference {worst}");
}

/// A white furnace: a non-absorbing glass body in a uniformly white world, no lights, no
/// ambient. Every Fresnel split and total internal reflection conserves energy, so every pixel
/// must come out white, up to what the depth limit drops.
fn furnace(mesh: &str, depth: u32) -> (f32, f32) {
    let text = format!(
        r#"
[camera]
eye = [0.0, 0.0, -5.0]
look_at = [0.0, 0.0, 0.0]
fov = 40.0
[render]
background = 1.0
ambient = 0.0
[material.glass]
color = 0.0
transmit = 1.0
ior = 1.5
[mesh.body]
{mesh}
material = "glass"
[[instance]]
mesh = "body"
"#
    );
    let (file, scene, world) = load(&text);
    let settings = Settings { width: 48, height: 48, max_depth: depth, bailout: 0.0, ..Settings::default() };
    let (img, stats) = renderer(&file, &scene, &world, settings).render(&|_| {}).unwrap();
    assert!(stats.rays[RayKind::Refracted as usize] > 500);
    let lo = img.pixels.iter().map(|p| p.min_element()).fold(f32::INFINITY, f32::min);
    let hi = img.pixels.iter().map(|p| p.max_element()).fold(0.0, f32::max);
    (lo, hi)
}

#[test]
fn fresnel_splits_conserve_energy() {
    // A slab seen head-on: exact up to the rays beyond depth 12.
    let (lo, hi) = furnace("box = { min = [-1.0, -1.0, -0.5], max = [1.0, 1.0, 0.5] }", 12);
    assert!(lo > 0.999 && hi < 1.0 + 1e-5, "slab: {lo}..{hi}");
    // A smooth-shaded sphere: shading normals bend rays, total internal reflection happens.
    let (lo, hi) = furnace("sphere = { radius = 1.0, stacks = 32, slices = 64 }", 16);
    assert!(lo > 0.99 && hi < 1.0 + 1e-5, "sphere: {lo}..{hi}");
    // Cutting depth loses energy: the furnace shows it.
    let (lo, _) = furnace("sphere = { radius = 1.0, stacks = 32, slices = 64 }", 1);
    assert!(lo < 0.95, "depth 1 keeps {lo}");
}

#[test]
fn beer_lambert_through_a_slab_of_known_thickness() {
    // Index 1 (no bending, no Fresnel reflection), absorption per channel, 2 units thick: the
    // white background seen through it is e^(−2α).
    let text = r#"
[camera]
eye = [0.0, 0.0, -5.0]
look_at = [0.0, 0.0, 0.0]
fov = 20.0
[render]
background = 1.0
ambient = 0.0
[material.tinted]
color = 0.0
transmit = 1.0
ior = 1.0
absorption = [0.0, 0.25, 1.0]
[mesh.slab]
box = { min = [-5.0, -5.0, -1.0], max = [5.0, 5.0, 1.0] }
material = "tinted"
[[instance]]
mesh = "slab"
"#;
    let (file, scene, world) = load(text);
    let settings = Settings { width: 8, height: 8, ..Settings::default() };
    let (img, _) = renderer(&file, &scene, &world, settings).render(&|_| {}).unwrap();
    let centre = img.get(4, 4);
    // The centre pixel's ray is almost perpendicular: path length 2 within 1e-3.
    let want = Vec3::new(1.0, (-0.5f32).exp(), (-2.0f32).exp());
    assert!((centre - want).abs().max_element() < 2e-3, "{centre} vs {want}");
}

#[test]
fn ray_tree_of_a_hall_of_mirrors() {
    // Two facing half-mirrors; the camera looks straight at one between them. The tree is a chain:
    // a primary ray, then one reflected ray per bounce, and a shadow feeler at every hit.
    let text = r#"
[camera]
eye = [0.0, 0.0, 0.0]
look_at = [0.0, 0.0, 1.0]
fov = 10.0
[[light]]
position = [0.0, 0.5, 0.0]
[material.mirror]
color = 0.5
reflect = 0.5
[mesh.wall]
quad = { size = [10.0, 10.0] }
material = "mirror"
[[instance]]
mesh = "wall"
rotate = [-90.0, 0.0, 0.0]
translate = [0.0, 0.0, 2.0]
[[instance]]
mesh = "wall"
rotate = [90.0, 0.0, 0.0]
translate = [0.0, 0.0, -2.0]
"#;
    let (file, scene, world) = load(text);
    let settings = Settings { width: 3, height: 3, max_depth: 3, bailout: 0.0, ..Settings::default() };
    let r = renderer(&file, &scene, &world, settings);
    let (nodes, colour) = r.ray_tree(1, 1).unwrap();
    let count = |k: RayKind| nodes.iter().filter(|n| n.kind == k).count();
    assert_eq!((count(RayKind::Primary), count(RayKind::Reflected), count(RayKind::Shadow)), (1, 3, 4));
    assert_eq!(nodes.iter().map(|n| n.depth).max(), Some(3));
    // Weights halve at each bounce; every hit is 2 units away in a unit direction, or 4 after.
    let reflected: Vec<_> = nodes.iter().filter(|n| n.kind == RayKind::Reflected).collect();
    assert_eq!(reflected.iter().map(|n| n.weight[0]).collect::<Vec<_>>(), [0.5, 0.25, 0.125]);
    assert!(reflected.iter().all(|n| (n.t.unwrap() - 4.0).abs() < 1e-3));
    assert!(nodes.iter().filter(|n| n.kind == RayKind::Shadow).all(|n| n.t.is_none() && n.tfar == Some(1.0)));
    // Parents come first.
    assert!(nodes.iter().enumerate().all(|(i, n)| n.parent.is_none_or(|p| p < i)));
    assert!(colour.x > 0.0);
    // A bailout of 0.2 stops the chain after the second reflection (weight 0.125 < 0.2).
    let r = Renderer { settings: Settings { bailout: 0.2, ..settings }, ..r };
    let (nodes, _) = r.ray_tree(1, 1).unwrap();
    assert_eq!(nodes.iter().filter(|n| n.kind == RayKind::Reflected).count(), 2);
    let (_, stats) = r.render(&|_| {}).unwrap();
    assert_eq!(stats.counts_cut_by_weight, 9);
    assert!(r.ray_tree(3, 0).is_err());
}

#[test]
fn bad_settings_and_materials_are_typed_errors() {
    let (file, scene, world) = load(&whitted());
    for (settings, needle) in [
        (Settings { width: 0, ..Settings::default() }, "image size"),
        (Settings { height: 1 << 20, ..Settings::default() }, "image size"),
        (Settings { spp: 0, ..Settings::default() }, "samples"),
        (Settings { spp: 1 << 20, ..Settings::default() }, "samples"),
        (Settings { max_depth: 1000, ..Settings::default() }, "depth"),
        (Settings { bailout: f32::NAN, ..Settings::default() }, "bailout"),
    ] {
        let e = renderer(&file, &scene, &world, settings).render(&|_| {}).unwrap_err();
        assert!(e.to_string().contains(needle), "{e}");
    }
    let base = whitted();
    for (from, to, needle) in [
        ("ior = 1.5", "ior = 0.0", "`ior` 0"),
        ("ior = 1.5", "ior = -1.0", "`ior` -1"),
        ("color = 0.05", "color = nan", "material `mirror`: `diffuse`"),
        ("color = 0.05", "color = -1.0", "material `mirror`: `diffuse`"),
        ("material = \"glass\"", "material = \"crystal\"", "material `crystal`"),
        ("color = 0.9\n", "color = 0.9\nkind = \"laser\"\n", "kind `laser`"),
        ("max_depth = 5", "max_depth = 500", "depth 500"),
        ("width = 640", "width = 0", "image size"),
        ("fresnel", "fresnel", ""),
        ("reflect = 0.85", "reflect = 0.85\nfresnel = \"fast\"", "fresnel `fast`"),
        ("fov = 50.0", "fov = 50.0\nprojection = \"fish\"", "projection `fish`"),
        ("size = 1.0 }", "size = 0.0 }", "checker"),
    ] {
        if needle.is_empty() {
            continue;
        }
        let text = base.replacen(from, to, 1);
        assert_ne!(text, base, "{from}");
        let e = SceneFile::parse(&text, Path::new("/virtual/w.toml")).unwrap_err();
        assert!(e.to_string().contains(needle) && e.to_string().contains("w.toml"), "{needle}: {e}");
    }
    // A group that the OBJ does not have: named when the world is made.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
    let text =
        "[mesh.box]\nobj = \"cornell_box.obj\"\ngroups = { attic = \"default\" }\n[[instance]]\nmesh = \"box\"\n";
    let file = SceneFile::parse(text, &dir.join("x.toml")).unwrap();
    let e = file.world(&file.load_objects().unwrap()).unwrap_err();
    assert!(e.to_string().contains("group `attic`"), "{e}");
}

#[test]
fn the_command_line_renders_and_fails_cleanly() {
    let exe = env!("CARGO_BIN_EXE_strahl");
    let dir = std::env::temp_dir().join(format!("strahl-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/whitted.toml");
    let out = dir.join("w.png");
    let run = |args: &[&str]| std::process::Command::new(exe).args(args).output().unwrap();
    let ok = run(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--width",
        "64",
        "--height",
        "48",
        "--ray-tree",
        "20,30",
    ]);
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    let img = image::open(&out).unwrap();
    assert_eq!((img.width(), img.height()), (64, 48));
    let tree: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("w.raytree.json")).unwrap()).unwrap();
    assert!(tree["rays"].as_array().unwrap().len() >= 2);
    let picture = image::open(dir.join("w.raytree.png")).unwrap();
    assert_eq!((picture.width(), picture.height()), (64, 48));
    // Bad input: an error message, a failing exit code, no image.
    let bad = dir.join("bad.png");
    for args in [
        vec!["render", "/nonexistent/scene.toml", "-o", bad.to_str().unwrap()],
        vec!["render", scene.to_str().unwrap(), "-o", bad.to_str().unwrap(), "--spp", "0"],
        vec!["render", scene.to_str().unwrap(), "-o", bad.to_str().unwrap(), "--threads", "0"],
        vec!["render", scene.to_str().unwrap(), "-o", bad.to_str().unwrap(), "--ray-tree", "9999,1"],
    ] {
        let r = run(&args);
        assert!(!r.status.success() && !r.stderr.is_empty(), "{args:?}");
        assert!(!String::from_utf8_lossy(&r.stderr).contains("panicked"), "{args:?}");
    }
    let missing_dir = dir.join("no/such/dir/x.png");
    let r =
        run(&["render", scene.to_str().unwrap(), "-o", missing_dir.to_str().unwrap(), "--width", "8", "--height", "8"]);
    assert!(!r.status.success());
    let left: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left.len(), 3, "{left:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn ray_tree_picture_draws_every_kind() {
    let (file, scene, world) = load(&whitted());
    let settings = Settings { width: 160, height: 120, ..file.render.settings };
    let r = renderer(&file, &scene, &world, settings);
    // A pixel on the glass sphere: primary, reflected, refracted and shadow rays.
    let (nodes, _) = r.ray_tree(112, 62).unwrap();
    for k in [RayKind::Primary, RayKind::Reflected, RayKind::Refracted, RayKind::Shadow] {
        assert!(nodes.iter().any(|n| n.kind == k), "{k:?} missing from {nodes:?}");
    }
    let view = strahl::render::tree::side_view(&r.camera, &nodes, 60.0).unwrap();
    let (_, radius) = strahl::render::tree::tree_extent(&nodes).unwrap();
    let picture = r.ray_tree_picture(&nodes, view, 2.0 * radius).unwrap();
    let (plain, _) = Renderer { camera: view, ..r }.render(&|_| {}).unwrap();
    let drawn = picture.pixels.iter().zip(&plain.pixels).filter(|(a, b)| a != b).count();
    assert!(drawn > 100 && drawn < picture.pixels.len() / 4, "{drawn} pixels drawn");
    for k in [RayKind::Primary, RayKind::Reflected, RayKind::Refracted] {
        let c = strahl::render::tree::kind_colour(k, false);
        assert!(picture.pixels.contains(&c), "no pixel of {k:?}'s colour");
    }
    // Only pinhole views.
    let fish = strahl::render::RenderCamera { projection: strahl::render::Projection::Panorama, ..view };
    assert!(r.ray_tree_picture(&nodes, fish, 1.0).is_err());
}

#[test]
fn area_lights_cast_soft_shadows() {
    // A floor, a box above it, a light above the box; seen straight down. A point light casts a
    // hard shadow (every floor pixel fully lit or fully dark); a rectangle light of the same
    // centre casts a penumbra of pixels in between, and splits its light so the lit floor far
    // from the box is as bright as under the point light.
    let scene = |light: &str| {
        format!(
            r#"
[camera]
projection = "orthographic"
width = 8.0
eye = [0.0, 10.0, 0.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
[render]
ambient = 0.0
{light}
[material.floor]
color = 1.0
ambient = 0.0
[mesh.floor]
quad = {{ size = [20.0, 20.0] }}
material = "floor"
[mesh.block]
box = {{ min = [-1.0, 1.0, -1.0], max = [1.0, 1.5, 1.0] }}
material = "floor"
[[instance]]
mesh = "floor"
[[instance]]
mesh = "block"
"#
        )
    };
    let levels = |light: &str| {
        let (file, scene, world) = load(&scene(light));
        let settings = Settings { width: 64, height: 64, ..Settings::default() };
        let (img, stats) = renderer(&file, &scene, &world, settings).render(&|_| {}).unwrap();
        // Floor pixels only: the box's top is nearer the light and brighter.
        let floor: Vec<f32> = img.pixels.iter().map(|p| p.x).collect();
        (floor, stats)
    };
    let (hard, hs) = levels("[[light]]\nposition = [0.0, 4.0, 0.0]\n");
    let (soft, ss) = levels(
        "[[light]]\nkind = \"rect\"\nposition = [0.0, 4.0, 0.0]\nu = [3.0, 0.0, 0.0]\nv = [0.0, 0.0, 3.0]\nsamples = [4, 4]\n",
    );
    assert_eq!(ss.rays[RayKind::Shadow as usize], 16 * hs.rays[RayKind::Shadow as usize]);
    let lit = hard[0];
    let dark = hard.iter().filter(|&&x| x == 0.0).count();
    let between = |img: &[f32]| img.iter().filter(|&&x| x > 0.02 * lit && x < 0.6 * lit).count();
    assert!(dark > 100, "the point light's umbra: {dark} pixels");
    assert_eq!(between(&hard), 0, "a point light casts no penumbra");
    assert!(between(&soft) > 100, "the rectangle's penumbra: {} pixels", between(&soft));
    // The corner pixel sees the whole rectangle: about as lit as under the point light.
    assert!((soft[0] - lit).abs() < 0.05 * lit, "{} vs {lit}", soft[0]);
}

#[test]
fn obj_materials_and_textures() {
    let dir = std::env::temp_dir().join(format!("strahl-mtl-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A 2×2 texture: red, green / blue, white.
    let texels = vec![255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255];
    image::RgbImage::from_raw(2, 2, texels).unwrap().save(dir.join("tex.png")).unwrap();
    std::fs::write(
        dir.join("m.mtl"),
        "newmtl painted\nKa 1 1 1\nKd 1 1 1\nillum 1\nmap_Kd tex.png\n\nnewmtl shiny\nKd 0.2 0.2 0.2\nKs 0.5 0.5 0.5\nNs 40\nillum 3\n\nnewmtl glass\nKd 0 0 0\nNi 1.33\nd 0.1\nTf 1 0.5 0.5\nillum 7\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("q.obj"),
        "mtllib m.mtl\nv -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
         o floor\nusemtl painted\nf 1/1 4/4 3/3 2/2\nusemtl shiny\nf 1 2 3\no pane\nusemtl glass\nf 1 2 3\n",
    )
    .unwrap();
    let text = r#"
[camera]
projection = "orthographic"
width = 2.0
eye = [0.0, 5.0, 0.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
[mesh.q]
obj = "q.obj"
mtl = true
[[instance]]
mesh = "q"
"#;
    let file = SceneFile::parse(text, &dir.join("s.toml")).unwrap();
    let objects = file.load_objects().unwrap();
    // Split where the material changes: painted floor, shiny floor, glass pane.
    assert_eq!(objects[0].iter().map(|m| m.triangle_count()).collect::<Vec<_>>(), [2, 1, 1]);
    let world = file.world(&objects).unwrap();
    let m = &world.materials;
    assert_eq!(m.len(), 1 + 3);
    assert_eq!(m[2].reflect, Vec3::splat(0.5));
    assert!((m[3].ior - 1.33).abs() < 1e-6 && m[3].transmit == Vec3::new(1.0, 0.5, 0.5));
    // Only the painted floor is visible from above if the others are removed: render the
    // painted part alone by an OBJ without them.
    std::fs::write(dir.join("q.obj"), "mtllib m.mtl\nv -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl painted\nf 1/1 4/4 3/3 2/2\n").unwrap();
    let file = SceneFile::parse(text, &dir.join("s.toml")).unwrap();
    let objects = file.load_objects().unwrap();
    let world = file.world(&objects).unwrap();
    let scene = InstancedScene::build(objects, file.instances.clone(), &BuildConfig::default()).unwrap();
    let settings = Settings { width: 2, height: 2, ..Settings::default() };
    let (img, _) = renderer(&file, &scene, &world, settings).render(&|_| {}).unwrap();
    // Pixel centres fall on texel centres: each pixel is one texel's colour (ambient 1 × Ka 1).
    let mut got: Vec<[u32; 3]> = img.pixels.iter().map(|p| p.to_array().map(|c| (c * 1000.0).round() as u32)).collect();
    got.sort();
    assert_eq!(got, [[0, 0, 1000], [0, 1000, 0], [1000, 0, 0], [1000, 1000, 1000]]);
    // Missing library, missing texture: typed errors naming the file.
    std::fs::write(dir.join("q.obj"), "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let e = SceneFile::parse(text, &dir.join("s.toml")).unwrap().load_objects().unwrap_err();
    assert!(e.to_string().contains("gone.mtl"), "{e}");
    std::fs::write(dir.join("m.mtl"), "newmtl painted\nmap_Kd nothere.png\n").unwrap();
    std::fs::write(dir.join("q.obj"), "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl painted\nf 1 2 3\n").unwrap();
    let file = SceneFile::parse(text, &dir.join("s.toml")).unwrap();
    let e = file.world(&file.load_objects().unwrap()).unwrap_err();
    assert!(e.to_string().contains("nothere.png"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn filtered_shadows_pass_through_glass() {
    // A floor lit from straight above through a thin pane of coloured glass (index 1, so the
    // refracted camera rays are not bent): opaque shadows leave the floor under the pane dark;
    // filtered ones let through transmit² (two crossings) of the light.
    let scene = |shadows: &str| {
        format!(
            r#"
[camera]
projection = "orthographic"
width = 4.0
eye = [0.0, 10.0, 0.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
[render]
ambient = 0.0
shadows = "{shadows}"
[[light]]
position = [0.0, 50.0, 0.0]
[material.floor]
color = 1.0
ambient = 0.0
[material.pane]
color = 0.0
ambient = 0.0
transmit = [1.0, 0.5, 0.25]
ior = 1.0
fresnel = "off"
[mesh.floor]
quad = {{ size = [20.0, 20.0] }}
material = "floor"
[mesh.pane]
box = {{ min = [-5.0, 2.0, -5.0], max = [5.0, 2.1, 5.0] }}
material = "pane"
[[instance]]
mesh = "floor"
[[instance]]
mesh = "pane"
"#
        )
    };
    let render = |shadows: &str| {
        let (file, scene, world) = load(&scene(shadows));
        let settings = Settings { width: 8, height: 8, ..file.render.settings };
        let r = renderer(&file, &scene, &world, settings);
        let (img, st) = r.render(&|_| {}).unwrap();
        let (rec, rst) = r.render_recursive().unwrap();
        assert_eq!(st.rays, rst.rays);
        assert!(img.pixels.iter().zip(&rec.pixels).all(|(a, b)| (*a - *b).abs().max_element() < 1e-5));
        img.get(4, 4)
    };
    // The camera sees the floor through the pane: transmit² on the way in, again on the light's.
    let opaque = render("opaque");
    assert_eq!(opaque, Vec3::ZERO);
    let filtered = render("filtered");
    let t2 = Vec3::new(1.0, 0.25, 0.0625);
    let lit = filtered / (t2 * t2);
    assert!((lit.x - lit.y).abs() < 1e-4 && (lit.x - lit.z).abs() < 1e-4 && lit.x > 0.9, "{filtered}");
    let e = SceneFile::parse(&scene("soft"), Path::new("/v/s.toml")).unwrap_err();
    assert!(e.to_string().contains("shadows `soft`"), "{e}");
}

/// A backend whose stream queries use the rayon pool themselves.
struct ParallelStreams<'a>(&'a InstancedScene);

impl strahl::Query for ParallelStreams<'_> {
    fn intersect(&self, ray: &strahl::Ray) -> Option<strahl::Hit> {
        self.0.intersect(ray)
    }
    fn occluded(&self, ray: &strahl::Ray) -> bool {
        self.0.occluded(ray)
    }
    fn intersect_packet_each(&self, rays: &strahl::RayPacket, f: impl FnMut(usize, &strahl::Hit)) {
        self.0.intersect_packet_each(rays, f)
    }
    fn occluded_packet(&self, rays: &strahl::RayPacket) -> u32 {
        self.0.occluded_packet(rays)
    }
    fn intersect_stream(&self, rays: &strahl::RayStream, hits: &mut strahl::HitStream, c: strahl::Coherence) {
        self.0.intersect_stream_par(rays, hits, c)
    }
    fn occluded_stream(&self, rays: &strahl::RayStream, occluded: &mut Vec<bool>, c: strahl::Coherence) {
        self.0.occluded_stream_par(rays, occluded, c)
    }
}

#[test]
fn backends_that_use_the_pool_inside_queries() {
    // A backend that answers streams on the pool gives the same image. (While a run waits for
    // such a query its thread may start another run; the renderer gives that one fresh buffers.
    // Whether it happens depends on rayon's scheduling, so this test may not exercise it.)
    let (file, scene, world) = load(&whitted());
    let settings = Settings { width: 256, height: 192, ..file.render.settings };
    let camera = file.camera.unwrap().render_camera().unwrap();
    let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let (a, _) = two.install(|| Renderer { query: &scene, world: &world, camera, settings }.render(&|_| {})).unwrap();
    let par = ParallelStreams(&scene);
    let (b, _) = two.install(|| Renderer { query: &par, world: &world, camera, settings }.render(&|_| {})).unwrap();
    assert_eq!(a, b);
}
