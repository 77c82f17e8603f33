//! POV-Ray 3.7 side by side: a strahl scene file exported to POV-Ray's scene description language,
//! rendered by Debian's `povray` at the same size, depth and bailout, timed as a whole process.
//!
//! The mapping (strahl → POV-Ray):
//! - coordinates as they are; strahl is right-handed, POV-Ray left-handed, so the camera's
//!   `right` vector is negated (POV-Ray's documented way to render right-handed scenes);
//! - pinhole `fov` → `angle` (both horizontal); fisheye → `fisheye angle`; omnimax → `omnimax`;
//!   panorama (equirectangular) → `spherical angle 360 180`; orthographic → `orthographic` with
//!   `right`/`up` spanning the window;
//! - meshes → `mesh2` (with `normal_vectors` where strahl shades smooth), one object per instance
//!   and geometry with its `matrix` and texture; analytic sphere sets → a `union` of `sphere`s
//!   per set, placed the same way; solids → POV-Ray's own CSG (`union`, `intersection`,
//!   `difference`) over its own primitives in their canonical forms (`sphere`, `box`,
//!   `cylinder`, `cone`, `disc`, `plane`, `torus`, `quadric`), each placed by its `matrix`, with a
//!   texture per primitive where a solid's primitives differ in material;
//! - material: `pigment rgb diffuse`, `finish { ambient a·1 diffuse 1 phong ks phong_size n
//!   reflection r }`; transparent: `pigment rgbf <transmit, 1>` with `interior { ior }` and, with
//!   Fresnel on, `reflection { 0, 1 fresnel on } conserve_energy`; absorption α →
//!   `fade_power 1001` (exponential), `fade_distance 1/k`, `fade_color 1 − α/k`, k = max α
//!   (POV-Ray multiplies by `exp(−(1 − fade_color)·d / fade_distance)`);
//! - checker → `pigment { checker rgb a, rgb b scale s }`; an image texture (OBJ `map_Kd`) on a
//!   mesh with texture coordinates → `uv_mapping image_map { png "file" gamma srgb interpolate 2 }`
//!   with `uv_vectors`/`uv_indices` in its `mesh2`, and the mean of `Kd` as the finish's `diffuse`
//!   (and a factor of `ambient`): POV-Ray cannot multiply an image by a colour;
//! - materials of OBJ groups and MTL files as the renderer's world resolves them;
//! - lights: `light_source` (point), `spotlight radius falloff point_at`, `parallel point_at`,
//!   rect → `area_light u, v, n0, n1 jitter` (POV-Ray's grid spans the edges, strahl's strata
//!   their cells), sphere → `area_light … circular orient jitter`; `fade` → `fade_distance f
//!   fade_power 2` (the same `2 / (1 + (d/f)²)`);
//! - `global_settings { assumed_gamma 1 max_trace_level depth+1 adc_bailout ambient_light }`,
//!   `background`; one sample per pixel (`-A`), else adaptive anti-aliasing off and `+AM1 +R`.
//!
//! What differs by design: POV-Ray lets light through transparent objects to the surfaces behind
//! them (filtered shadows); strahl's shadow feelers, as Whitted's, stop at any surface. POV-Ray's
//! `max_trace_level` counts the primary ray as level 1, so strahl's depth d is POV-Ray's d + 1.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use glam::Vec3;
use strahl::SceneFile;
use strahl::TriangleMesh;
use strahl::render::texture::ImageTexture;
use strahl::render::{FresnelMode, LightKind, Material, Projection, Settings, Texture, World, surface::vertex_normals};

fn v(p: Vec3) -> String {
    format!("<{}, {}, {}>", p.x, p.y, p.z)
}

/// POV-Ray's pigment for an image texture read from a file: `uv_mapping image_map`, bilinear
/// (`interpolate 2`), repeated (POV-Ray's default, as strahl's), its 8-bit colours read as sRGB
/// (as strahl decodes them). `None` for a texture made in memory, a format POV-Ray cannot read,
/// or a path SDL cannot quote.
fn image_pigment(t: &ImageTexture) -> Option<String> {
    let path = std::path::absolute(t.source.as_ref()?).ok()?;
    let kind = match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
        "png" => "png",
        "jpg" | "jpeg" => "jpeg",
        "tga" => "tga",
        "gif" => "gif",
        "tif" | "tiff" => "tiff",
        "ppm" => "ppm",
        "bmp" => "bmp",
        _ => return None,
    };
    let text = path.to_str()?;
    if text.contains(['"', '\\']) {
        return None;
    }
    Some(format!("uv_mapping image_map {{ {kind} \"{text}\" gamma srgb interpolate 2 }}"))
}

/// `m` as a POV-Ray texture (and interior). `textures` are the world's images; `uv` says
/// whether the surface has texture coordinates (without them strahl shades an image-textured
/// material with its diffuse colour, and so does the export).
fn material_sdl(m: &Material, textures: &[ImageTexture], uv: bool) -> String {
    let mut s = String::from("texture { pigment { ");
    // An image times the diffuse colour (strahl's `map_Kd` · `Kd`): POV-Ray cannot multiply a
    // pigment by a colour, so the colour's mean scales the finish's diffuse and ambient terms
    // instead (exact for a grey `Kd`, the usual one under a `map_Kd`).
    let image = match m.texture {
        Some(Texture::Image { index }) if uv && !m.is_transparent() => {
            textures.get(index as usize).and_then(image_pigment)
        }
        _ => None,
    };
    let mut k = 1.0;
    if m.is_transparent() {
        write!(s, "rgbf <{}, {}, {}, 1>", m.transmit.x, m.transmit.y, m.transmit.z).unwrap();
    } else if let Some(img) = image {
        s.push_str(&img);
        k = m.diffuse.element_sum() / 3.0;
    } else if let Some(Texture::Checker { other, size }) = m.texture {
        write!(s, "checker rgb {}, rgb {} scale {size}", v(m.diffuse), v(other)).unwrap();
    } else {
        write!(s, "rgb {}", v(m.diffuse)).unwrap();
    }
    s.push_str(" } finish { ");
    write!(s, "ambient rgb {} diffuse {k} ", v(m.ambient * k)).unwrap();
    let ks = m.specular.element_sum() / 3.0;
    if ks > 0.0 {
        write!(s, "phong {ks} phong_size {} ", m.shininess).unwrap();
    }
    if m.is_transparent() && m.fresnel != FresnelMode::Off {
        write!(s, "reflection {{ {}, 1 fresnel on }} conserve_energy ", v(m.reflect)).unwrap();
    } else if m.reflect != Vec3::ZERO {
        write!(s, "reflection {{ {} }} ", v(m.reflect)).unwrap();
    }
    s.push_str("} }");
    if m.is_transparent() {
        write!(s, " interior {{ ior {}", m.ior).unwrap();
        let k = m.absorption.max_element();
        if k > 0.0 {
            write!(s, " fade_power 1001 fade_distance {} fade_color {}", 1.0 / k, v(Vec3::ONE - m.absorption / k))
                .unwrap();
        }
        s.push_str(" }");
    }
    s
}

/// A solid as POV-Ray SDL: CSG over canonical primitives, each transform an `object { … matrix }`
/// wrapper; `textures` gives each leaf's texture in leaf order (empty strings where the whole
/// object gets one).
fn solid_sdl(solid: &strahl::Solid, textures: &mut std::slice::Iter<'_, String>, out: &mut String) {
    use strahl::{CsgOp, Primitive, Solid};
    match solid {
        Solid::Primitive(p) => {
            let body = match *p {
                Primitive::Superellipsoid { e, n } => format!("superellipsoid {{ <{e}, {n}>"),
                Primitive::Blob(ref b) => blob_sdl(b),
                // POV-Ray's mesh2 is a solid in CSG once it has an inside vector (its own
                // parity test along that direction).
                Primitive::Mesh(ref m) => {
                    format!("{} inside_vector <0.31, 0.73, 0.61>", mesh2_open(m.mesh(), false, None))
                }
                // A Rust closure has no SDL (and scene files cannot hold one): an empty
                // isosurface over its box, so the rest of the scene still renders.
                Primitive::Implicit(ref im) => {
                    let (lo, hi) = im.bounds();
                    format!(
                        "// strahl: a user's implicit surface (no SDL)\nisosurface {{ function {{ 1 }} contained_by {{ box {{ {}, {} }} }}",
                        v(lo),
                        v(hi)
                    )
                }
                Primitive::Supertoroid { .. } | Primitive::Superhyperboloid { .. } | Primitive::Ratioquadric { .. } => {
                    superquadric_sdl(p)
                }
                Primitive::Sphere => "sphere { 0, 1".to_string(),
                Primitive::Box => "box { -1, 1".to_string(),
                Primitive::Cylinder => "cylinder { <0, 0, 0>, <0, 0, 1>, 1".to_string(),
                Primitive::Cone { r0, r1 } => format!("cone {{ <0, 0, 0>, {r0}, <0, 0, 1>, {r1}"),
                Primitive::Disc => "disc { <0, 0, 0>, <0, 0, 1>, 1".to_string(),
                Primitive::Plane => "plane { z, 0".to_string(),
                Primitive::Torus { major, minor } => format!("torus {{ {major}, {minor}"),
                Primitive::Quadric { coeffs: c } => format!(
                    "quadric {{ <{}, {}, {}>, <{}, {}, {}>, <{}, {}, {}>, {}",
                    c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8], c[9]
                ),
            };
            let tex = textures.next().map_or("", |t| t.as_str());
            write!(out, "{body} {tex} }}").unwrap();
        }
        Solid::Transformed(m, inner) => {
            out.push_str("object { ");
            solid_sdl(inner, textures, out);
            let matrix = crate::harness::column_major(m).map(|x| x.to_string()).join(", ");
            write!(out, " matrix <{matrix}> }}").unwrap();
        }
        Solid::Csg(op, operands) => {
            let kind = match (op, operands.len()) {
                (_, 1) => "object",
                (CsgOp::Union, _) => "union",
                (CsgOp::Intersection, _) => "intersection",
                (CsgOp::Difference, _) => "difference",
            };
            write!(out, "{kind} {{ ").unwrap();
            for o in operands {
                solid_sdl(o, textures, out);
                out.push(' ');
            }
            out.push('}');
        }
    }
}

/// The superquadrics POV-Ray has no primitive for (super-toroid, super-hyperboloid,
/// ratioquadric) as an `isosurface` of the field strahl solves, written out in POV-Ray's
/// function syntax. `max_gradient` is the largest gradient found on a 48³ grid of central
/// differences over the bounds, with a margin of 1.5, so POV-Ray's sampling does not step over
/// the surface (the pinched shapes' gradients are unbounded at their cusps: there POV-Ray may
/// still miss slivers).
fn superquadric_sdl(p: &strahl::Primitive) -> String {
    use strahl::Primitive;
    let norm =
        |a: &str, b: &str, e: f32| format!("pow(pow(abs({a}), {0}) + pow(abs({b}), {0}), {1})", 2.0 / e, e / 2.0);
    let (f, half) = match *p {
        Primitive::Supertoroid { major, minor, e, n } => {
            let rho = format!("({} - {major})", norm("x", "z", e));
            (format!("{} - {minor}", norm(&rho, "y", n)), Vec3::new(major + minor, minor, major + minor))
        }
        Primitive::Superhyperboloid { e, n, sheets, height } => {
            let c = 2.0 / n;
            let rho = norm("x", "y", e);
            let (side, r) = if sheets == 2 {
                (format!("{} - abs(z)", norm("1", &rho, n)), (height.powf(c) - 1.0).max(0.0).powf(1.0 / c))
            } else {
                (format!("{rho} - {}", norm("1", "z", n)), (height.powf(c) + 1.0).powf(1.0 / c))
            };
            (format!("max({side}, abs(z) - {height})"), Vec3::new(r, r, height))
        }
        Primitive::Ratioquadric { p: a, q, r } => {
            let g = |v: &str, p: f32| format!("(pow({v}, 2) / ({p} + {} * pow({v}, 2)))", 1.0 - p);
            (format!("{} + {} + {} - 1", g("x", a), g("y", q), g("z", r)), Vec3::ONE)
        }
        _ => unreachable!("only the superquadrics without a POV-Ray primitive"),
    };
    const N: usize = 48;
    let mut gradient = 1.0f64;
    let h = 1e-4 * half.max_element() as f64;
    for i in 0..N * N * N {
        let c = [i % N, i / N % N, i / (N * N)];
        let q = glam::DVec3::from_array(std::array::from_fn(|k| {
            (2.0 * (c[k] as f64 + 0.5) / N as f64 - 1.0) * half[k] as f64 * 1.05
        }));
        let g = glam::DVec3::from_array(std::array::from_fn(|k| {
            let mut dq = glam::DVec3::ZERO;
            dq[k] = h;
            (p.field(q + dq) - p.field(q - dq)) / (2.0 * h)
        }));
        if g.is_finite() {
            gradient = gradient.max(g.length());
        }
    }
    format!(
        "isosurface {{ function {{ {f} }} threshold 0 contained_by {{ box {{ {}, {} }} }} max_gradient {}",
        v(-half * 1.01),
        v(half * 1.01),
        (gradient * 1.5) as f32
    )
}

/// A blob: POV-Ray's own `blob` for its potential, an `isosurface` of the same field for the
/// others (with a generous gradient bound, so POV-Ray's sampling does not miss the surface).
fn blob_sdl(b: &strahl::Blob) -> String {
    use strahl::Potential;
    if b.potential() == Potential::Pov {
        let mut s = format!("blob {{ threshold {}", b.threshold());
        for c in b.components() {
            write!(s, " sphere {{ {}, {}, strength {} }}", v(c.center), c.radius, c.strength).unwrap();
        }
        return s;
    }
    let mut f = format!("{}", b.threshold());
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    let mut gradient = 0.0f32;
    for c in b.components() {
        let q = format!(
            "(pow(x - ({}), 2) + pow(y - ({}), 2) + pow(z - ({}), 2)) / {}",
            c.center.x,
            c.center.y,
            c.center.z,
            c.radius * c.radius
        );
        let term = match b.potential() {
            Potential::Pov => unreachable!(),
            Potential::Wyvill => format!("(1 + min({q}, 1) * (-22/9 + min({q}, 1) * (17/9 - 4/9 * min({q}, 1))))"),
            Potential::Rational { d } => format!("(pow(1 - min({q}, 1), 2) / (1 + {d} * min({q}, 1)))"),
            Potential::InverseSquare => format!("(1 / max({q}, 1e-9))"),
        };
        write!(f, " - {} * {term}", c.strength).unwrap();
        if c.strength > 0.0 {
            lo = lo.min(c.center - Vec3::splat(c.radius * 3.0));
            hi = hi.max(c.center + Vec3::splat(c.radius * 3.0));
        }
        gradient += 4.0 * c.strength.abs() / c.radius;
    }
    format!(
        "isosurface {{ function {{ {f} }} threshold 0 contained_by {{ box {{ {}, {} }} }} max_gradient {gradient}",
        v(lo),
        v(hi)
    )
}

fn mesh_sdl(name: &str, m: &TriangleMesh, smooth: bool, uvs: Option<&[[glam::Vec2; 3]]>) -> String {
    format!("#declare {name} = {}}}\n", mesh2_open(m, smooth, uvs))
}

/// A `mesh2` of `m` without its closing brace (a solid adds its inside vector and texture):
/// vertices, the vertex normals if `smooth`, the hittable triangles, and their corners' texture
/// coordinates where `uvs` gives them (one per triangle of `m`).
fn mesh2_open(m: &TriangleMesh, smooth: bool, uvs: Option<&[[glam::Vec2; 3]]>) -> String {
    let mut s = format!("mesh2 {{\n  vertex_vectors {{ {}", m.positions().len());
    for p in m.positions() {
        write!(s, ", {}", v(*p)).unwrap();
    }
    s.push_str(" }\n");
    if smooth {
        let n = vertex_normals(m);
        write!(s, "  normal_vectors {{ {}", n.len()).unwrap();
        for p in &n {
            // POV-Ray rejects zero normals; a vertex of only degenerate triangles gets any.
            write!(s, ", {}", v(if *p == Vec3::ZERO { Vec3::Y } else { *p })).unwrap();
        }
        s.push_str(" }\n");
    }
    // Degenerate triangles are left out (POV-Ray warns about each; neither engine hits them).
    let tris: Vec<usize> = (0..m.triangle_count()).filter(|&i| m.is_hittable(i)).collect();
    // Corner coordinates as their own vectors, three per triangle (strahl keeps them per
    // corner, as OBJ's `vt` indices may differ from the vertices').
    let uvs = uvs.filter(|u| u.len() == m.triangle_count());
    if let Some(uvs) = uvs {
        write!(s, "  uv_vectors {{ {}", 3 * tris.len()).unwrap();
        for &i in &tris {
            for t in uvs[i] {
                // SDL has no NaN; strahl shades a non-finite coordinate with the top-left texel.
                let t = if t.is_finite() { t } else { glam::Vec2::new(0.0, 1.0) };
                write!(s, ", <{}, {}>", t.x, t.y).unwrap();
            }
        }
        s.push_str(" }\n");
    }
    write!(s, "  face_indices {{ {}", tris.len()).unwrap();
    for &i in &tris {
        let [a, b, c] = m.indices()[i];
        write!(s, ", <{a}, {b}, {c}>").unwrap();
    }
    s.push_str(" }\n");
    if uvs.is_some() {
        write!(s, "  uv_indices {{ {}", tris.len()).unwrap();
        for k in 0..tris.len() {
            write!(s, ", <{}, {}, {}>", 3 * k, 3 * k + 1, 3 * k + 2).unwrap();
        }
        s.push_str(" }\n");
    }
    s
}

/// The scene as POV-Ray SDL, rendered at `settings`. `world` is the file's
/// [`world`](SceneFile::world) for `objects`: the materials of OBJ groups and MTL files and the
/// meshes' texture coordinates come from it.
pub fn export(
    file: &SceneFile,
    objects: &[Vec<TriangleMesh>],
    world: &World,
    settings: &Settings,
) -> anyhow::Result<String> {
    let cam = file.camera.ok_or_else(|| anyhow::anyhow!("{}: no camera", file.path.display()))?;
    let rc = cam.render_camera().ok_or_else(|| anyhow::anyhow!("bad camera"))?;
    let aspect = settings.width as f32 / settings.height as f32;
    let mut s = String::from("#version 3.7;\n");
    writeln!(
        s,
        "global_settings {{ assumed_gamma 1.0 max_trace_level {} adc_bailout {} ambient_light rgb {} }}",
        settings.max_depth + 1,
        settings.bailout,
        v(file.render.ambient)
    )?;
    writeln!(s, "background {{ rgb {} }}", v(file.render.background))?;
    // POV-Ray's spherical camera turns its rays about its `right` vector with a fixed sense, so
    // the negated `right` that makes other cameras right-handed turns its image upside down (and
    // a positive one mirrors it). For the panorama the world is mirrored instead, across the
    // camera's vertical plane, and the camera left as POV-Ray expects it.
    let mirror = matches!(rc.projection, Projection::Panorama);
    let h = if mirror {
        let r = rc.right;
        let lin = glam::Mat3::IDENTITY - glam::Mat3::from_cols(r * r.x, r * r.y, r * r.z) * 2.0;
        glam::Affine3A::from_translation(cam.eye)
            * glam::Affine3A::from_mat3(lin)
            * glam::Affine3A::from_translation(-cam.eye)
    } else {
        glam::Affine3A::IDENTITY
    };
    let (pt, dv) = (|p: Vec3| h.transform_point3(p), |d: Vec3| h.transform_vector3(d));
    let handed = if mirror { 1.0 } else { -1.0 };
    let (kind, right, up) = match rc.projection {
        Projection::Pinhole { fov_deg } => (format!("perspective angle {fov_deg}"), aspect, 1.0),
        Projection::Orthographic { width } => ("orthographic".into(), width, width / aspect),
        Projection::Fisheye { fov_deg } => (format!("fisheye angle {fov_deg}"), aspect, 1.0),
        Projection::Omnimax => ("omnimax".into(), aspect, 1.0),
        Projection::Panorama => ("spherical angle 360 180".into(), aspect, 1.0),
    };
    writeln!(
        s,
        "camera {{ {kind} location {} right {} up {} sky {} look_at {} }}",
        v(cam.eye),
        v(Vec3::new(handed * right, 0.0, 0.0)),
        v(Vec3::new(0.0, up, 0.0)),
        v(cam.up),
        v(cam.look_at)
    )?;
    for l in &file.lights {
        let fade = l.fade.map_or(String::new(), |f| format!(" fade_distance {f} fade_power 2"));
        let body = match l.kind {
            LightKind::Point => format!("{} color rgb {}{fade}", v(pt(l.position)), v(l.color)),
            LightKind::Directional { direction } => {
                // A parallel light from far up-stream, pointing along the direction.
                let direction = dv(direction);
                let from = -direction * 1e5;
                format!("{} color rgb {} parallel point_at {}", v(from), v(l.color), v(from + direction))
            }
            LightKind::Spot { direction, cos_inner, cos_outer } => format!(
                "{} color rgb {} spotlight radius {} falloff {} tightness 0 point_at {}{fade}",
                v(pt(l.position)),
                v(l.color),
                cos_inner.acos().to_degrees(),
                cos_outer.acos().to_degrees(),
                v(pt(l.position + direction))
            ),
            LightKind::Rect { u, v: e2, n } => format!(
                "{} color rgb {} area_light {}, {}, {}, {} jitter adaptive 0{fade}",
                v(pt(l.position)),
                v(l.color),
                v(dv(u)),
                v(dv(e2)),
                n[0].max(2),
                n[1].max(2)
            ),
            LightKind::Sphere { radius, n } => {
                let k = ((n as f32).sqrt().round() as u32).max(2);
                format!(
                    "{} color rgb {} area_light <{d}, 0, 0>, <0, 0, {d}>, {k}, {k} circular orient jitter adaptive 0{fade}",
                    v(pt(l.position)),
                    v(l.color),
                    d = 2.0 * radius
                )
            }
        };
        writeln!(s, "light_source {{ {body} }}")?;
    }
    for (o, meshes) in objects.iter().enumerate() {
        for (g, m) in meshes.iter().enumerate() {
            if m.triangle_count() > 0 {
                let uvs = world.surfaces.geometry_shading(o, g).and_then(|(_, uvs)| uvs);
                s.push_str(&mesh_sdl(&format!("M{o}_{g}"), m, file.mesh_shading[o].smooth, uvs));
            }
        }
    }
    // Analytic spheres as POV-Ray's own `sphere`s, one union per set (POV-Ray bounds the
    // union's members itself).
    let spheres = file.load_spheres()?;
    for (o, sets) in spheres.iter().enumerate() {
        for (k, set) in sets.iter().enumerate() {
            writeln!(s, "#declare S{o}_{k} = union {{")?;
            for (c, r) in set.centers().iter().zip(set.radii()) {
                writeln!(s, "  sphere {{ <{}, {}, {}>, {} }}", c.x, c.y, c.z, r)?;
            }
            writeln!(s, "}}")?;
        }
    }
    for (i, inst) in file.instances.iter().enumerate() {
        let sh = &file.mesh_shading[inst.object];
        let m = h * inst.transform;
        // POV-Ray's `matrix` takes the same twelve numbers as Embree's column-major 3×4.
        let matrix = format!("matrix <{}>", crate::harness::column_major(&m).map(|x| x.to_string()).join(", "));
        for (g, mesh) in objects[inst.object].iter().enumerate() {
            if mesh.triangle_count() == 0 {
                continue;
            }
            // The geometry's material as the renderer resolves it (scene file, OBJ group or
            // MTL), unless the instance names one.
            let (own, uvs) = world
                .surfaces
                .geometry_shading(inst.object, g)
                .ok_or_else(|| anyhow::anyhow!("the world has no geometry {g} of object {}", inst.object))?;
            let mat = file.instance_materials[i].unwrap_or(own);
            let material = world.materials.get(mat as usize).ok_or_else(|| anyhow::anyhow!("no material {mat}"))?;
            let tex = material_sdl(material, &world.textures, uvs.is_some());
            writeln!(s, "object {{ M{}_{g} {tex} {matrix} }}", inst.object)?;
        }
        for k in 0..spheres[inst.object].len() {
            let mat = file.instance_materials[i].unwrap_or(sh.material);
            let material = &file.materials[mat as usize].1;
            writeln!(
                s,
                "object {{ S{}_{k} {} {matrix} }}",
                inst.object,
                material_sdl(material, &world.textures, false)
            )?;
        }
        if let strahl::scene_file::MeshSource::Solid(solid) = &file.meshes[inst.object].1 {
            // One texture for the whole where the instance names one or every primitive has the
            // same material (POV-Ray's CSG keeps one interior, for glass); else one per primitive.
            let leaves = &sh.leaf_materials;
            let whole =
                file.instance_materials[i].or_else(|| leaves.iter().all(|&l| l == leaves[0]).then_some(leaves[0]));
            let textures: Vec<String> = match whole {
                Some(_) => vec![String::new(); leaves.len()],
                None => leaves
                    .iter()
                    .map(|&l| material_sdl(&file.materials[l as usize].1, &world.textures, false))
                    .collect(),
            };
            let mut body = String::new();
            solid_sdl(solid, &mut textures.iter(), &mut body);
            let tex =
                whole.map_or(String::new(), |m| material_sdl(&file.materials[m as usize].1, &world.textures, false));
            writeln!(s, "object {{ {body} {tex} {matrix} }}")?;
        }
    }
    Ok(s)
}

/// Renders `pov` with POV-Ray into `out` (PNG, sRGB), `threads` render threads, and returns the
/// process's wall time in seconds.
pub fn render(pov: &Path, out: &Path, settings: &Settings, threads: usize) -> anyhow::Result<f64> {
    let mut cmd = Command::new("povray");
    cmd.arg(format!("+I{}", pov.display()))
        .arg(format!("+O{}", out.display()))
        .arg(format!("+W{}", settings.width))
        .arg(format!("+H{}", settings.height))
        .arg(format!("+WT{threads}"))
        .args(["+FN", "-D", "-P", "-V", "-GA", "File_Gamma=sRGB", "+Q9"]);
    if settings.spp > 1 {
        let n = (settings.spp as f32).sqrt().round().max(2.0) as u32;
        cmd.args(["+A0.0", "+AM1"]).arg(format!("+R{}", n - 1));
    } else {
        cmd.arg("-A");
    }
    let start = Instant::now();
    let output = cmd.output().map_err(|e| anyhow::anyhow!("cannot run povray: {e}"))?;
    let secs = start.elapsed().as_secs_f64();
    if !output.status.success() {
        anyhow::bail!("povray failed on {}: {}", pov.display(), String::from_utf8_lossy(&output.stderr));
    }
    Ok(secs)
}

/// Whether `povray` can be run.
pub fn available() -> bool {
    Command::new("povray").arg("--version").output().is_ok()
}

/// Where the exported scene of `name` goes in `out`.
pub fn pov_path(out: &Path, name: &str) -> PathBuf {
    out.join(format!("{name}.pov"))
}
