//! The scenes the harness knows: the seven shared benchmark scenes with the cameras and lights of
//! `../shared/BENCHMARKING.md`, the project's own scenes in `data/`, and any OBJ given by path.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use glam::Vec3;
use strahl::{TriangleMesh, load_obj, procedural};

/// Where a scene's meshes come from.
#[derive(Clone, Debug)]
pub enum Source {
    Obj(PathBuf),
    /// `procedural::sphereflake(levels, stacks, slices)`.
    Sphereflake {
        levels: u32,
        stacks: u32,
        slices: u32,
    },
    /// A scene file (`strahl::SceneFile`): instances of meshes, with camera and light.
    SceneFile(PathBuf),
}

/// A scene with its camera and light.
#[derive(Clone, Debug)]
pub struct SceneSpec {
    pub name: String,
    pub source: Source,
    /// `(eye, look_at)`; `None`: fitted to the scene's bounds.
    pub view: Option<(Vec3, Vec3)>,
    pub light: Option<Vec3>,
}

/// The cameras and lights of BENCHMARKING.md: name, folder/file, eye, look-at, light.
/// `(name, file, eye, look_at, light)`.
type Shared = (&'static str, &'static str, [f32; 3], [f32; 3], [f32; 3]);

const SHARED: [Shared; 7] = [
    ("cornell_box", "cornell_box/cornell_box.obj", [278.0, 273.0, -450.0], [278.0, 273.0, 0.0], [278.0, 540.0, 279.0]),
    ("teapot", "teapot/teapot.obj", [0.217, 2.5, 6.0], [0.217, 1.4, 0.0], [3.0, 7.0, 5.0]),
    ("bunny", "bunny/bunny.obj", [-0.017, 0.13, 0.17], [-0.017, 0.10, 0.0], [0.1, 0.3, 0.2]),
    ("sponza_dabrovic", "sponza_dabrovic/sponza.obj", [-10.0, 3.0, 0.0], [10.0, 4.0, 0.0], [0.0, 12.0, 0.0]),
    ("sibenik", "sibenik/sibenik.obj", [-15.0, -8.0, 0.0], [10.0, -5.0, 0.0], [0.0, -5.0, 0.0]),
    ("igea", "igea/igea.obj", [0.0, 0.0, 0.11], [0.0, 0.0, 0.0], [0.05, 0.1, 0.12]),
    ("conference", "conference/conference.obj", [1600.0, 450.0, 500.0], [0.0, 100.0, -300.0], [400.0, 550.0, -100.0]),
];

/// The shared scenes present under `root` (normally `../shared/scenes`).
pub fn shared(root: &Path) -> Vec<SceneSpec> {
    SHARED
        .iter()
        .filter(|s| root.join(s.1).exists())
        .map(|&(name, file, eye, at, light)| SceneSpec {
            name: name.into(),
            source: Source::Obj(root.join(file)),
            view: Some((Vec3::from(eye), Vec3::from(at))),
            light: Some(Vec3::from(light)),
        })
        .collect()
}

/// The project's own scenes: the Cornell box from its published measurements (with the shared
/// camera and light) and the generated sphereflake.
pub fn data(dir: &Path) -> Vec<SceneSpec> {
    let mut v = vec![SceneSpec {
        name: "cornell_box_data".into(),
        source: Source::Obj(dir.join("cornell_box.obj")),
        view: Some((Vec3::new(278.0, 273.0, -450.0), Vec3::new(278.0, 273.0, 0.0))),
        light: Some(Vec3::new(278.0, 540.0, 279.0)),
    }];
    v.push(sphereflake());
    for name in ["forest", "big_world", "trio"] {
        let p = dir.join(format!("{name}.toml"));
        if p.exists() {
            v.push(scene_file(name, p));
        }
    }
    v
}

/// The scaling series: sphereflakes of one shape from 11 thousand to 11 million triangles
/// (`levels`, `stacks`; slices are twice the stacks), well past a 32 MiB L3 cache at the top.
pub fn scaling() -> Vec<SceneSpec> {
    [(2, 6), (2, 10), (3, 6), (3, 10), (3, 18), (4, 10), (4, 20)]
        .into_iter()
        .map(|(levels, stacks)| {
            let tris = (9usize.pow(levels + 1) - 1) / 8 * (4 * stacks * stacks - 4 * stacks) as usize;
            SceneSpec {
                name: format!("flake_{}k", tris / 1000),
                source: Source::Sphereflake { levels, stacks, slices: 2 * stacks },
                view: Some((Vec3::new(0.0, 1.3, 3.4), Vec3::new(0.0, 0.25, 0.0))),
                light: Some(Vec3::new(3.0, 6.0, 4.0)),
            }
        })
        .collect()
}

/// An instanced scene from a scene file; camera and light come from the file.
pub fn scene_file(name: &str, path: PathBuf) -> SceneSpec {
    SceneSpec { name: name.into(), source: Source::SceneFile(path), view: None, light: None }
}

/// Haines' sphereflake, 820 spheres, 433k triangles.
pub fn sphereflake() -> SceneSpec {
    SceneSpec {
        name: "sphereflake".into(),
        source: Source::Sphereflake { levels: 3, stacks: 12, slices: 24 },
        view: Some((Vec3::new(0.0, 1.3, 3.4), Vec3::new(0.0, 0.25, 0.0))),
        light: Some(Vec3::new(3.0, 6.0, 4.0)),
    }
}

/// A scene named by a path: an OBJ file, or a folder holding one. Known names (the shared scenes)
/// get their table camera; others a camera fitted to their bounds.
pub fn from_path(p: &Path) -> anyhow::Result<SceneSpec> {
    let file = if p.is_dir() {
        let mut objs: Vec<PathBuf> = std::fs::read_dir(p)
            .with_context(|| format!("reading {}", p.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|f| f.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj")))
            .collect();
        objs.sort();
        match objs.into_iter().next() {
            Some(f) => f,
            None => bail!("{} holds no .obj file", p.display()),
        }
    } else {
        p.to_path_buf()
    };
    if file.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml")) {
        let stem = file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scene".into());
        return Ok(scene_file(&stem, file));
    }
    let stem = file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scene".into());
    let known = SHARED.iter().find(|s| Path::new(s.1).file_stem().is_some_and(|f| f.to_string_lossy() == stem));
    Ok(match known {
        Some(&(name, _, eye, at, light)) => SceneSpec {
            name: name.into(),
            source: Source::Obj(file),
            view: Some((Vec3::from(eye), Vec3::from(at))),
            light: Some(Vec3::from(light)),
        },
        None => SceneSpec { name: stem, source: Source::Obj(file), view: None, light: None },
    })
}

impl SceneSpec {
    pub fn load(&self) -> anyhow::Result<Vec<TriangleMesh>> {
        match &self.source {
            Source::Obj(p) => load_obj(p).with_context(|| format!("loading scene {}", self.name)),
            Source::Sphereflake { levels, stacks, slices } => {
                Ok(vec![procedural::sphereflake(*levels, *stacks, *slices)])
            }
            Source::SceneFile(p) => bail!("{} is an instanced scene; use SceneSpec::scene_file", p.display()),
        }
    }

    /// The parsed scene file of an instanced scene, `None` for a flat one.
    pub fn scene_file(&self) -> anyhow::Result<Option<strahl::SceneFile>> {
        match &self.source {
            Source::SceneFile(p) => Ok(Some(strahl::SceneFile::read(p)?)),
            _ => Ok(None),
        }
    }

    /// Camera `(eye, at)` and light, fitted to `bounds` where the spec names none.
    pub fn view_and_light(&self, bounds: Option<(Vec3, Vec3)>) -> ((Vec3, Vec3), Vec3) {
        let (lo, hi) = bounds.unwrap_or((Vec3::splat(-1.0), Vec3::splat(1.0)));
        let c = (lo + hi) * 0.5;
        let d = (hi - lo).length().max(1e-6);
        let view = self.view.unwrap_or((c + Vec3::new(0.3, 0.35, 1.0).normalize() * d * 1.1, c));
        let light = self.light.unwrap_or(c + Vec3::new(0.3 * d, 0.8 * d, 0.5 * d));
        (view, light)
    }
}
