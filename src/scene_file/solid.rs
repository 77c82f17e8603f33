//! The `solid = { … }` source of a scene file's mesh: a tree of primitives and CSG operations,
//! each node optionally placed (`translate`, `rotate`, `scale` or `matrix`) and given a
//! material. Primitives take POV-Ray's parameters (a cylinder from `base` to `cap`, a plane by
//! its `normal` and `offset`), turned here into a canonical [`Primitive`] and its placement.

use std::path::Path;
use std::sync::Arc;

use glam::{Affine3A, Mat3, Vec3};
use serde::Deserialize;

use super::{Scale, placement};
use crate::geometry::TriangleMesh;
use crate::shapes::{Blob, BlobComponent, CsgOp, MAX_SOLID_DEPTH, MeshSolid, Potential, Primitive, Solid};

/// One node of a solid tree, as written.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSolid {
    sphere: Option<RawSphere>,
    #[serde(rename = "box")]
    cuboid: Option<RawBox>,
    cylinder: Option<RawCylinder>,
    cone: Option<RawCone>,
    disc: Option<RawDisc>,
    plane: Option<RawPlane>,
    torus: Option<RawTorus>,
    quadric: Option<[f32; 10]>,
    superellipsoid: Option<RawSuperellipsoid>,
    supertoroid: Option<RawSupertoroid>,
    superhyperboloid: Option<RawSuperhyperboloid>,
    ratioquadric: Option<RawRatioquadric>,
    blob: Option<RawBlob>,
    /// A closed triangle mesh from an OBJ file (every object and group of it, as one mesh),
    /// relative to the scene file.
    obj: Option<String>,
    union: Option<Vec<RawSolid>>,
    intersection: Option<Vec<RawSolid>>,
    difference: Option<Vec<RawSolid>>,
    translate: Option<[f32; 3]>,
    rotate: Option<[f32; 3]>,
    scale: Option<Scale>,
    matrix: Option<Vec<[f32; 4]>>,
    material: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSphere {
    #[serde(default)]
    center: [f32; 3],
    #[serde(default = "one")]
    radius: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBox {
    #[serde(default = "minus_ones")]
    min: [f32; 3],
    #[serde(default = "ones")]
    max: [f32; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCylinder {
    #[serde(default)]
    base: [f32; 3],
    #[serde(default = "up")]
    cap: [f32; 3],
    #[serde(default = "one")]
    radius: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCone {
    #[serde(default)]
    base: [f32; 3],
    #[serde(default = "up")]
    cap: [f32; 3],
    base_radius: f32,
    cap_radius: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDisc {
    #[serde(default)]
    center: [f32; 3],
    #[serde(default = "up")]
    normal: [f32; 3],
    #[serde(default = "one")]
    radius: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlane {
    normal: [f32; 3],
    #[serde(default)]
    offset: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTorus {
    major: f32,
    minor: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSuperellipsoid {
    e: f32,
    n: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSupertoroid {
    major: f32,
    minor: f32,
    #[serde(default = "one")]
    e: f32,
    #[serde(default = "one")]
    n: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSuperhyperboloid {
    #[serde(default = "one")]
    e: f32,
    #[serde(default = "one")]
    n: f32,
    #[serde(default = "one_sheet")]
    sheets: u8,
    height: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRatioquadric {
    p: f32,
    q: f32,
    r: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBlob {
    threshold: f32,
    /// `"pov"` (the default), `"wyvill"`, `"rational"` (with `d`) or `"inverse_square"`.
    #[serde(default)]
    potential: Option<String>,
    d: Option<f32>,
    components: Vec<RawBlobComponent>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBlobComponent {
    center: [f32; 3],
    radius: f32,
    #[serde(default = "one")]
    strength: f32,
}

fn one() -> f32 {
    1.0
}
fn one_sheet() -> u8 {
    1
}
fn ones() -> [f32; 3] {
    [1.0; 3]
}
fn minus_ones() -> [f32; 3] {
    [-1.0; 3]
}
fn up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}

/// A frame whose third column is `axis` (any length) and whose first two are unit vectors
/// perpendicular to it and each other, scaled by `r`; `None` for a zero or non-finite axis.
fn frame(axis: Vec3, r: f32) -> Option<Mat3> {
    if !(axis.is_finite() && axis.length_squared() > 0.0) {
        return None;
    }
    let (u, v) = axis.normalize().any_orthonormal_pair();
    Some(Mat3::from_cols(u * r, v * r, axis))
}

/// A solid tree and the material name of each of its leaves (in the order the scene numbers
/// them: depth first, operands left to right), `None` where no node on the way names one.
pub(super) type Built = (Solid, Vec<Option<String>>);

/// Turns the written tree into a [`Solid`]; `Err` names the node (by its path of operand
/// indices) and what is wrong with it.
pub(super) fn build(raw: &RawSolid, base: &Path) -> Result<Built, String> {
    let mut leaves = Vec::new();
    let solid = node(raw, "solid", None, 0, base, &mut leaves)?;
    Ok((solid, leaves))
}

fn node(
    raw: &RawSolid,
    at: &str,
    material: Option<&String>,
    depth: usize,
    base: &Path,
    leaves: &mut Vec<Option<String>>,
) -> Result<Solid, String> {
    if depth > MAX_SOLID_DEPTH {
        return Err(format!("{at}: deeper than {MAX_SOLID_DEPTH} levels"));
    }
    let material = raw.material.as_ref().or(material);
    let kinds = [
        raw.sphere.is_some(),
        raw.cuboid.is_some(),
        raw.cylinder.is_some(),
        raw.cone.is_some(),
        raw.disc.is_some(),
        raw.plane.is_some(),
        raw.torus.is_some(),
        raw.quadric.is_some(),
        raw.superellipsoid.is_some(),
        raw.supertoroid.is_some(),
        raw.superhyperboloid.is_some(),
        raw.ratioquadric.is_some(),
        raw.blob.is_some(),
        raw.obj.is_some(),
        raw.union.is_some(),
        raw.intersection.is_some(),
        raw.difference.is_some(),
    ];
    if kinds.iter().filter(|&&k| k).count() != 1 {
        return Err(format!(
            "{at}: needs exactly one of sphere, box, cylinder, cone, disc, plane, torus, quadric, superellipsoid, \
             supertoroid, superhyperboloid, ratioquadric, blob, obj, union, intersection, difference"
        ));
    }
    let bad = |what: String| Err(format!("{at}: {what}"));
    let v = Vec3::from;
    let placed = |p: Primitive, m: Affine3A| Solid::new(p).transformed(m);
    let solid = if let Some(s) = &raw.sphere {
        if !(s.radius > 0.0 && s.radius.is_finite()) {
            return bad(format!("sphere radius {} must be positive", s.radius));
        }
        leaves.push(material.cloned());
        placed(
            Primitive::Sphere,
            Affine3A::from_scale_rotation_translation(Vec3::splat(s.radius), Default::default(), v(s.center)),
        )
    } else if let Some(b) = &raw.cuboid {
        let (lo, hi) = (v(b.min), v(b.max));
        if !(lo.cmplt(hi).all() && lo.is_finite() && hi.is_finite()) {
            return bad(format!("box min {lo} must lie below max {hi}"));
        }
        leaves.push(material.cloned());
        placed(
            Primitive::Box,
            Affine3A::from_scale_rotation_translation((hi - lo) * 0.5, Default::default(), (hi + lo) * 0.5),
        )
    } else if let Some(c) = &raw.cylinder {
        let Some(m) = frame(v(c.cap) - v(c.base), c.radius).filter(|_| c.radius > 0.0 && c.radius.is_finite()) else {
            return bad(format!("cylinder needs base ≠ cap and a positive radius (radius {})", c.radius));
        };
        leaves.push(material.cloned());
        placed(Primitive::Cylinder, Affine3A::from_mat3_translation(m, v(c.base)))
    } else if let Some(c) = &raw.cone {
        let r = c.base_radius.max(c.cap_radius);
        let ok = c.base_radius >= 0.0 && c.cap_radius >= 0.0 && r > 0.0 && r.is_finite();
        let Some(m) = frame(v(c.cap) - v(c.base), r).filter(|_| ok) else {
            return bad(format!(
                "cone needs base ≠ cap and radii ≥ 0, not both 0 (radii {} and {})",
                c.base_radius, c.cap_radius
            ));
        };
        leaves.push(material.cloned());
        placed(
            Primitive::Cone { r0: c.base_radius / r, r1: c.cap_radius / r },
            Affine3A::from_mat3_translation(m, v(c.base)),
        )
    } else if let Some(d) = &raw.disc {
        let Some(m) = frame(v(d.normal), d.radius).filter(|_| d.radius > 0.0 && d.radius.is_finite()) else {
            return bad(format!("disc needs a non-zero normal and a positive radius (radius {})", d.radius));
        };
        let m = Mat3::from_cols(m.x_axis, m.y_axis, v(d.normal).normalize());
        leaves.push(material.cloned());
        placed(Primitive::Disc, Affine3A::from_mat3_translation(m, v(d.center)))
    } else if let Some(p) = &raw.plane {
        let Some(m) = frame(v(p.normal).normalize_or_zero(), 1.0).filter(|_| p.offset.is_finite()) else {
            return bad(format!("plane needs a non-zero normal and a finite offset (offset {})", p.offset));
        };
        // Inside where normal · p ≤ offset: the canonical z ≤ 0 moved along the unit normal.
        let n = v(p.normal);
        leaves.push(material.cloned());
        placed(Primitive::Plane, Affine3A::from_mat3_translation(m, n.normalize() * (p.offset / n.length())))
    } else if let Some(t) = &raw.torus {
        leaves.push(material.cloned());
        Solid::new(Primitive::Torus { major: t.major, minor: t.minor })
    } else if let Some(q) = raw.quadric {
        leaves.push(material.cloned());
        Solid::new(Primitive::Quadric { coeffs: q })
    } else if let Some(se) = &raw.superellipsoid {
        leaves.push(material.cloned());
        Solid::new(Primitive::Superellipsoid { e: se.e, n: se.n })
    } else if let Some(t) = &raw.supertoroid {
        leaves.push(material.cloned());
        Solid::new(Primitive::Supertoroid { major: t.major, minor: t.minor, e: t.e, n: t.n })
    } else if let Some(h) = &raw.superhyperboloid {
        leaves.push(material.cloned());
        Solid::new(Primitive::Superhyperboloid { e: h.e, n: h.n, sheets: h.sheets, height: h.height })
    } else if let Some(q) = &raw.ratioquadric {
        leaves.push(material.cloned());
        Solid::new(Primitive::Ratioquadric { p: q.p, q: q.q, r: q.r })
    } else if let Some(b) = &raw.blob {
        let potential = match (b.potential.as_deref(), b.d) {
            (None | Some("pov"), None) => Potential::Pov,
            (Some("wyvill"), None) => Potential::Wyvill,
            (Some("inverse_square"), None) => Potential::InverseSquare,
            (Some("rational"), Some(d)) => Potential::Rational { d },
            (Some("rational"), None) => return bad("blob potential \"rational\" needs its parameter d".into()),
            (Some(p @ ("pov" | "wyvill" | "inverse_square")), Some(_)) => {
                return bad(format!("only the rational blob potential takes d, not {p}"));
            }
            (None, Some(_)) => return bad("only the rational blob potential takes d".into()),
            (Some(p), _) => return bad(format!("blob potential {p:?}: use pov, wyvill, rational or inverse_square")),
        };
        let components = b
            .components
            .iter()
            .map(|c| BlobComponent { center: v(c.center), radius: c.radius, strength: c.strength })
            .collect();
        leaves.push(material.cloned());
        Solid::new(Primitive::Blob(Arc::new(Blob::new(b.threshold, potential, components))))
    } else if let Some(file) = &raw.obj {
        let path = base.join(file);
        let meshes = crate::geometry::load_obj(&path).map_err(|e| format!("{at}: {e}"))?;
        // One mesh of every object and group.
        let (mut positions, mut indices) = (Vec::new(), Vec::new());
        for m in &meshes {
            let offset = positions.len() as u32;
            positions.extend_from_slice(m.positions());
            indices.extend(m.indices().iter().map(|t| t.map(|i| i + offset)));
        }
        let mesh =
            TriangleMesh::new(path.display().to_string(), positions, indices).map_err(|e| format!("{at}: {e}"))?;
        let solid = MeshSolid::new(mesh).map_err(|e| format!("{at}: {e}"))?;
        leaves.push(material.cloned());
        Solid::new(Primitive::Mesh(Arc::new(solid)))
    } else {
        let (op, operands) = match (&raw.union, &raw.intersection, &raw.difference) {
            (Some(o), _, _) => (CsgOp::Union, o),
            (_, Some(o), _) => (CsgOp::Intersection, o),
            (_, _, Some(o)) => (CsgOp::Difference, o),
            _ => unreachable!("counted above"),
        };
        if operands.is_empty() {
            return bad(format!("{op:?} of no operands").to_lowercase());
        }
        let children = operands
            .iter()
            .enumerate()
            .map(|(i, o)| {
                let at = format!("{at}.{}[{i}]", format!("{op:?}").to_lowercase());
                node(o, &at, material, depth + 1, base, leaves)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Solid::Csg(op, children)
    };
    let transform = placement(raw.translate, raw.rotate, raw.scale, &raw.matrix).map_err(|m| format!("{at}: {m}"))?;
    Ok(match transform {
        Some(m) if !crate::instance::is_invertible(&m) => {
            return bad("the transform is not finite and invertible".into());
        }
        Some(m) => solid.transformed(m),
        None => solid,
    })
}
