//! Scenes strahl makes itself: tessellated spheres and Haines' sphereflake ("A Proposal for
//! Standard Graphics Environments", IEEE CG&A 1987, the SPD `balls` scene), used by the harness,
//! the tests and the benchmarks.

use glam::Vec3;

use crate::geometry::TriangleMesh;

/// A UV sphere of `stacks × slices` quads (poles as triangle fans), as vertices and triangles
/// appended to `positions` and `indices`.
pub fn append_uv_sphere(
    positions: &mut Vec<Vec3>,
    indices: &mut Vec<[u32; 3]>,
    center: Vec3,
    radius: f32,
    stacks: u32,
    slices: u32,
) {
    let stacks = stacks.max(2);
    let slices = slices.max(3);
    let base = positions.len() as u32;
    positions.push(center + Vec3::Y * radius);
    for i in 1..stacks {
        let theta = std::f32::consts::PI * i as f32 / stacks as f32;
        for j in 0..slices {
            let phi = 2.0 * std::f32::consts::PI * j as f32 / slices as f32;
            let d = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
            positions.push(center + d * radius);
        }
    }
    positions.push(center - Vec3::Y * radius);
    let ring = |i: u32, j: u32| base + 1 + (i - 1) * slices + (j % slices);
    let south = base + 1 + (stacks - 1) * slices;
    for j in 0..slices {
        indices.push([base, ring(1, j + 1), ring(1, j)]);
        indices.push([south, ring(stacks - 1, j), ring(stacks - 1, j + 1)]);
    }
    for i in 1..stacks - 1 {
        for j in 0..slices {
            let (a, b, c, d) = (ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1));
            indices.push([a, b, d]);
            indices.push([a, d, c]);
        }
    }
}

/// A tessellated sphere as its own mesh.
pub fn uv_sphere(center: Vec3, radius: f32, stacks: u32, slices: u32) -> TriangleMesh {
    let (mut p, mut i) = (Vec::new(), Vec::new());
    append_uv_sphere(&mut p, &mut i, center, radius, stacks, slices);
    TriangleMesh::new("sphere", p, i).expect("indices are generated in range")
}

/// Haines' sphereflake: a unit sphere at the origin carrying nine spheres of a third its radius
/// (six around its equator, three above), each carrying nine more, `levels` times; every sphere
/// tessellated with `stacks × slices`. `levels = 3`, 12 × 24 gives 820 spheres, 433k triangles.
pub fn sphereflake(levels: u32, stacks: u32, slices: u32) -> TriangleMesh {
    let (mut p, mut idx) = (Vec::new(), Vec::new());
    for (c, r) in sphereflake_spheres(levels) {
        append_uv_sphere(&mut p, &mut idx, c, r, stacks, slices);
    }
    TriangleMesh::new("sphereflake", p, idx).expect("indices are generated in range")
}

/// The spheres of [`sphereflake`] as `(centre, radius)`, in the order it tessellates them:
/// `(9^(levels+1) − 1) / 8` of them (820 at level 3, 597,871 at level 6). Its analytic twin
/// ([`SphereSet`](crate::SphereSet)) models the same surface exactly, with four floats a sphere.
pub fn sphereflake_spheres(levels: u32) -> Vec<(Vec3, f32)> {
    fn grow(out: &mut Vec<(Vec3, f32)>, c: Vec3, r: f32, axis: Vec3, level: u32) {
        out.push((c, r));
        if level == 0 {
            return;
        }
        let (t, b) = axis.any_orthonormal_pair();
        let child_r = r / 3.0;
        let mut place = |elevation: f32, azimuth: f32| {
            let d = (axis * elevation.sin() + (t * azimuth.cos() + b * azimuth.sin()) * elevation.cos()).normalize();
            grow(out, c + d * (r + child_r), child_r, d, level - 1);
        };
        let deg = std::f32::consts::PI / 180.0;
        for k in 0..6 {
            place(0.0, (60 * k) as f32 * deg);
        }
        for k in 0..3 {
            place(60.0 * deg, (30 + 120 * k) as f32 * deg);
        }
    }
    let mut out = Vec::new();
    grow(&mut out, Vec3::ZERO, 1.0, Vec3::Y, levels);
    out
}

/// An axis-aligned box from `min` to `max`: 12 triangles wound counter-clockwise seen from
/// outside (normals point out).
pub fn cuboid(min: Vec3, max: Vec3) -> TriangleMesh {
    let p = |i: u32| {
        Vec3::new(
            if i & 1 == 0 { min.x } else { max.x },
            if i & 2 == 0 { min.y } else { max.y },
            if i & 4 == 0 { min.z } else { max.z },
        )
    };
    let positions: Vec<Vec3> = (0..8).map(p).collect();
    // Faces as corner quads (a, b, c, d) counter-clockwise from outside.
    let faces = [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]];
    let indices = faces.iter().flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]]).collect();
    TriangleMesh::new("box", positions, indices).expect("eight corners, valid indices")
}

/// A `sx × sz` rectangle in the plane y = 0, centred on the origin, facing +y: 2 triangles.
pub fn quad(sx: f32, sz: f32) -> TriangleMesh {
    let (x, z) = (0.5 * sx, 0.5 * sz);
    let positions = vec![Vec3::new(-x, 0.0, -z), Vec3::new(-x, 0.0, z), Vec3::new(x, 0.0, z), Vec3::new(x, 0.0, -z)];
    TriangleMesh::new("quad", positions, vec![[0, 1, 2], [0, 2, 3]]).expect("four corners, valid indices")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_is_closed_and_counted() {
        let m = uv_sphere(Vec3::ZERO, 1.0, 8, 16);
        assert_eq!(m.triangle_count(), 2 * 8 * 16 - 2 * 16);
        // Every edge used exactly twice, in opposite directions: closed and consistently wound.
        let mut edges = std::collections::HashMap::new();
        for t in m.indices() {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1);
            assert_eq!(edges.get(&(b, a)), Some(&1));
        }
        // Outward winding: normals point away from the centre.
        for i in 0..m.triangle_count() {
            let [a, b, c] = m.triangle(i);
            assert!((b - a).cross(c - a).dot(a + b + c) > 0.0);
        }
    }

    #[test]
    fn sphereflake_counts() {
        let m = sphereflake(2, 4, 6);
        let per = 2 * 4 * 6 - 2 * 6;
        assert_eq!(m.triangle_count(), (1 + 9 + 81) * per);
    }
}
