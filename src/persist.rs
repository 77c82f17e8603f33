//! A built [`Scene`] as bytes and back, without a rebuild: its meshes, nodes and triangle blocks
//! as they are, little-endian. What the Python package pickles, and what a program that traces
//! one scene many times may keep on disk.
//!
//! Loading trusts nothing: every count is checked against the bytes left before anything is
//! allocated, the meshes are checked as [`TriangleMesh::new`] checks them, and the tree is walked
//! once to make sure every child reference lies in its array, no node is reached twice (so no walk
//! can loop) and no path is deeper than a built tree can be (so the fixed traversal stack is never
//! outgrown). Bytes that fail any check are [`Error::Serialized`]; none can make a query panic,
//! hang or read out of bounds. The build statistics are read back as they were written; the one
//! of them that traversal reads (`bytes`) must match the arrays, the others are only figures.

use glam::{Affine3A, Vec3};

use crate::bvh::build::MEDIAN_DEPTH;
use crate::bvh::node::{EMPTY, Node, WIDTH, is_leaf, leaf_blocks};
use crate::bvh::{BoxTest, BuildConfig, BuildStats, Bvh};
use crate::error::{Error, Result};
use crate::geometry::TriangleMesh;
use crate::geometry::TriangleTest;
use crate::geometry::triangle::{BLOCK, TriBlock};
use crate::instance::{Instance, InstancedScene};
use crate::scene::Scene;
use crate::shapes::{
    Blob, BlobComponent, CsgOp, MAX_SOLID_DEPTH, MeshSolid, Potential, Primitive, QuarticSolver, Solid, SphereSet,
    SphereTest,
};

/// The first bytes of a serialized scene.
const MAGIC: &[u8; 8] = b"STRAHLSC";
/// Format version; bumped whenever the layout of nodes, blocks or this format changes. Version 2
/// appends the sphere sets (their tree is rebuilt on reading), version 3 the solids (likewise),
/// version 4 adds the superellipsoid and blob primitives, version 5 the ratioquadric,
/// super-toroid and super-hyperboloid; older bytes still read.
const VERSION: u32 = 5;
/// Deepest solid tree the reader accepts (the builder's own limit, [`MAX_SOLID_DEPTH`]).
const MAX_SOLID_READ_DEPTH: usize = MAX_SOLID_DEPTH;
/// Deepest wide level a built tree reaches (`MEDIAN_DEPTH` SAH levels, then at most 32 median
/// levels), which the traversal stack is sized for.
const MAX_DEPTH: usize = MEDIAN_DEPTH + 33;

impl Scene {
    /// The built scene as bytes ([`from_bytes`](Self::from_bytes) reads them back without a
    /// rebuild). The layout is strahl's own and versioned; it is meant for the same version of
    /// strahl, on machines of the same byte order. A solid with a user's
    /// [`Implicit`](crate::Implicit) surface is written as a marker only (a closure has no
    /// bytes): reading such bytes is an [`crate::Error::Serialized`].
    pub fn to_bytes(&self) -> Vec<u8> {
        let bvh = self.bvh();
        // Sized from the arrays themselves, never from the statistics (which a loaded scene took
        // from its bytes unchecked: a fuzzed `bytes` figure asked for 2^56 bytes here).
        let mesh_bytes: usize =
            self.meshes().iter().map(|m| 64 + m.name.len() + 12 * (m.positions().len() + m.indices().len())).sum();
        let tree_bytes =
            bvh.nodes.len() * std::mem::size_of::<Node>() + bvh.blocks.len() * std::mem::size_of::<TriBlock>();
        let mut w = Writer(Vec::with_capacity(256 + mesh_bytes + tree_bytes));
        w.0.extend_from_slice(MAGIC);
        w.u32(VERSION);
        w.u8(test_code(bvh.test));
        w.u8((bvh.box_test == BoxTest::Conservative) as u8);
        w.u8(bvh.prefetch as u8);
        w.u64(self.meshes().len() as u64);
        for m in self.meshes() {
            write_mesh(&mut w, m);
        }
        w.u32(bvh.root);
        w.u64(bvh.nodes.len() as u64);
        for n in &bvh.nodes {
            n.bounds.iter().flatten().for_each(|&x| w.f32(x));
            n.child.iter().for_each(|&c| w.u32(c));
        }
        w.u64(bvh.blocks.len() as u64);
        for b in &bvh.blocks {
            b.rows.iter().flatten().for_each(|&x| w.f32(x));
            b.geom.iter().chain(&b.prim).for_each(|&x| w.u32(x));
        }
        match bvh.bounds {
            Some((lo, hi)) => {
                w.u8(1);
                lo.to_array().iter().chain(&hi.to_array()).for_each(|&x| w.f32(x));
            }
            None => w.u8(0),
        }
        let s = &bvh.stats;
        w.f64(s.build_ms);
        for x in [s.triangles, s.skipped_triangles, s.inner_nodes, s.leaves, s.blocks, s.references] {
            w.u64(x as u64);
        }
        w.f64(s.sah);
        w.u64(s.bytes as u64);
        w.f64(s.bytes_per_triangle);
        w.u64(s.depth as u64);
        // Version 2: the sphere sets and their test; the sphere tree is rebuilt on reading.
        w.u8(SphereTest::ALL.iter().position(|&t| t == self.sphere_test()).unwrap_or(0) as u8);
        w.u64(self.spheres().len() as u64);
        for set in self.spheres() {
            w.u64(set.name().len() as u64);
            w.0.extend_from_slice(set.name().as_bytes());
            w.u64(set.len() as u64);
            for (c, &rad) in set.centers().iter().zip(set.radii()) {
                [c.x, c.y, c.z, rad].iter().for_each(|&x| w.f32(x));
            }
        }
        // Version 3: the solids and their quartic solver; the solid tree is rebuilt on reading.
        w.u8(QuarticSolver::ALL.iter().position(|&q| q == self.quartic_solver()).unwrap_or(0) as u8);
        w.u64(self.solids().len() as u64);
        for solid in self.solids() {
            write_solid(&mut w, solid);
        }
        w.0
    }

    /// A scene from the bytes of [`to_bytes`](Self::to_bytes), checked (see the module's
    /// documentation); [`Error::Serialized`] says what is wrong with bytes that are not such a
    /// scene.
    pub fn from_bytes(bytes: &[u8]) -> Result<Scene> {
        let mut r = Reader { b: bytes };
        if r.take(8)? != MAGIC {
            return Err(bad("not a serialized strahl scene (no STRAHLSC header)"));
        }
        let version = r.u32()?;
        if !(1..=VERSION).contains(&version) {
            return Err(bad(format!("format version {version}; this strahl reads version {VERSION}")));
        }
        let test = match r.u8()? {
            0 => TriangleTest::MollerTrumbore,
            1 => TriangleTest::Badouel,
            2 => TriangleTest::Watertight,
            t => return Err(bad(format!("unknown triangle test {t}"))),
        };
        let box_test = if r.flag()? { BoxTest::Conservative } else { BoxTest::Fast };
        let prefetch = r.flag()?;
        let mesh_count = r.count(24)?;
        let mut meshes = Vec::with_capacity(mesh_count);
        for _ in 0..mesh_count {
            meshes.push(read_mesh(&mut r)?);
        }
        let root = r.u32()?;
        let node_count = r.count(4 * (6 * WIDTH + WIDTH))?;
        let mut nodes = Vec::with_capacity(node_count);
        for _ in 0..node_count {
            let mut n = Node::default();
            for row in n.bounds.iter_mut() {
                for x in row.iter_mut() {
                    *x = r.f32()?;
                }
            }
            for c in n.child.iter_mut() {
                *c = r.u32()?;
            }
            nodes.push(n);
        }
        let block_count = r.count(4 * (9 * BLOCK + 2 * BLOCK))?;
        let mut blocks = Vec::with_capacity(block_count);
        for _ in 0..block_count {
            let mut rows = [[0.0; BLOCK]; 9];
            for row in rows.iter_mut() {
                for x in row.iter_mut() {
                    *x = r.f32()?;
                }
            }
            let mut ids = [0u32; 2 * BLOCK];
            for x in ids.iter_mut() {
                *x = r.u32()?;
            }
            let (geom, prim) =
                (ids[..BLOCK].try_into().expect("BLOCK ids"), ids[BLOCK..].try_into().expect("BLOCK ids"));
            blocks.push(TriBlock { rows, geom, prim });
        }
        let bounds = match r.flag()? {
            false => None,
            true => {
                let v: Vec<f32> = (0..6).map(|_| r.f32()).collect::<Result<_>>()?;
                Some((Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5])))
            }
        };
        let build_ms = r.f64()?;
        let mut counts = [0usize; 6];
        for c in counts.iter_mut() {
            *c = r.u64()? as usize;
        }
        let [triangles, skipped_triangles, inner_nodes, leaves, blocks_stat, references] = counts;
        let stats = BuildStats {
            build_ms,
            triangles,
            skipped_triangles,
            inner_nodes,
            leaves,
            blocks: blocks_stat,
            references,
            sah: r.f64()?,
            bytes: r.u64()? as usize,
            bytes_per_triangle: r.f64()?,
            depth: r.u64()? as usize,
            shapes: 0,
        };
        let mut sphere_test = SphereTest::default();
        let mut spheres = Vec::new();
        if version >= 2 {
            let code = r.u8()? as usize;
            sphere_test = *SphereTest::ALL.get(code).ok_or_else(|| bad(format!("unknown sphere test {code}")))?;
            let sets = r.count(16)?;
            for _ in 0..sets {
                let len = r.count(1)?;
                let name =
                    String::from_utf8(r.take(len)?.to_vec()).map_err(|_| bad("a sphere set's name is not UTF-8"))?;
                let n = r.count(16)?;
                let pairs = (0..n)
                    .map(|_| Ok((Vec3::new(r.f32()?, r.f32()?, r.f32()?), r.f32()?)))
                    .collect::<Result<Vec<_>>>()?;
                spheres.push(SphereSet::from_pairs(name, &pairs)?);
            }
        }
        let mut quartic_solver = QuarticSolver::default();
        let mut solids = Vec::new();
        if version >= 3 {
            let code = r.u8()? as usize;
            quartic_solver =
                *QuarticSolver::ALL.get(code).ok_or_else(|| bad(format!("unknown quartic solver {code}")))?;
            let n = r.count(2)?;
            for _ in 0..n {
                solids.push(read_solid(&mut r, 0)?);
            }
        }
        if !r.b.is_empty() {
            return Err(bad(format!("{} bytes after the scene", r.b.len())));
        }
        // The one figure traversal reads (whether the tree is out of the cache), and what
        // two-level scenes sum over their objects: it must be the arrays' own size.
        let tree_bytes = nodes.len() * std::mem::size_of::<Node>() + blocks.len() * std::mem::size_of::<TriBlock>();
        if stats.bytes != tree_bytes {
            return Err(bad(format!("the statistics give {} bytes for a tree of {tree_bytes}", stats.bytes)));
        }
        check_tree(&nodes, blocks.len(), root)?;
        check_blocks(&blocks, test, &meshes)?;
        let bvh = Bvh { nodes, blocks, root, bounds, test, box_test, stats, prefetch };
        Scene::from_parts(
            meshes,
            bvh,
            spheres,
            solids,
            BuildConfig { sphere_test, quartic_solver, ..BuildConfig::default() },
        )
    }
}

/// Writes a mesh: name, positions, triangles.
fn write_mesh(w: &mut Writer, m: &TriangleMesh) {
    w.u64(m.name.len() as u64);
    w.0.extend_from_slice(m.name.as_bytes());
    w.u64(m.positions().len() as u64);
    m.positions().iter().for_each(|p| p.to_array().iter().for_each(|&x| w.f32(x)));
    w.u64(m.indices().len() as u64);
    m.indices().iter().flatten().for_each(|&i| w.u32(i));
}

/// Reads what [`write_mesh`] wrote, checked by [`TriangleMesh::new`].
fn read_mesh(r: &mut Reader) -> Result<TriangleMesh> {
    let len = r.count(1)?;
    let name = String::from_utf8(r.take(len)?.to_vec()).map_err(|_| bad("a mesh name is not UTF-8"))?;
    let n = r.count(12)?;
    let positions = (0..n).map(|_| Ok(Vec3::new(r.f32()?, r.f32()?, r.f32()?))).collect::<Result<Vec<_>>>()?;
    let m = r.count(12)?;
    let indices = (0..m).map(|_| Ok([r.u32()?, r.u32()?, r.u32()?])).collect::<Result<Vec<_>>>()?;
    TriangleMesh::new(name, positions, indices)
}

/// Writes a solid tree: a tag (0 primitive, 1 transformed, 2 CSG), then the primitive's kind
/// and ten parameters, the 3×4 matrix (columns) and the child, or the operation and operands.
fn write_solid(w: &mut Writer, s: &Solid) {
    match s {
        Solid::Primitive(p) => {
            w.u8(0);
            let (kind, params) = primitive_code(p);
            w.u8(kind);
            params.iter().for_each(|&x| w.f32(x));
            if let Primitive::Blob(b) = p {
                // The potential, then the balls: centre, radius, strength.
                w.u8(potential_code(b.potential()));
                w.u64(b.components().len() as u64);
                for c in b.components() {
                    c.center.to_array().iter().chain(&[c.radius, c.strength]).for_each(|&x| w.f32(x));
                }
            }
            if let Primitive::Mesh(m) = p {
                // The mesh as the scene's meshes are written: name, positions, triangles.
                write_mesh(w, m.mesh());
            }
        }
        Solid::Transformed(m, inner) => {
            w.u8(1);
            m.to_cols_array().iter().for_each(|&x| w.f32(x));
            write_solid(w, inner);
        }
        Solid::Csg(op, operands) => {
            w.u8(2);
            w.u8(match op {
                CsgOp::Union => 0,
                CsgOp::Intersection => 1,
                CsgOp::Difference => 2,
            });
            w.u64(operands.len() as u64);
            operands.iter().for_each(|o| write_solid(w, o));
        }
    }
}

/// A primitive's kind code and parameters (unused ones 0).
fn primitive_code(p: &Primitive) -> (u8, [f32; 10]) {
    let mut a = [0.0; 10];
    let kind = match *p {
        Primitive::Sphere => 0,
        Primitive::Box => 1,
        Primitive::Cylinder => 2,
        Primitive::Cone { r0, r1 } => {
            a[..2].copy_from_slice(&[r0, r1]);
            3
        }
        Primitive::Disc => 4,
        Primitive::Plane => 5,
        Primitive::Torus { major, minor } => {
            a[..2].copy_from_slice(&[major, minor]);
            6
        }
        Primitive::Quadric { coeffs } => {
            a = coeffs;
            7
        }
        Primitive::Superellipsoid { e, n } => {
            a[..2].copy_from_slice(&[e, n]);
            8
        }
        Primitive::Ratioquadric { p, q, r } => {
            a[..3].copy_from_slice(&[p, q, r]);
            10
        }
        Primitive::Supertoroid { major, minor, e, n } => {
            a[..4].copy_from_slice(&[major, minor, e, n]);
            11
        }
        Primitive::Superhyperboloid { e, n, sheets, height } => {
            a[..3].copy_from_slice(&[e, n, height]);
            // The sheet count as a float, so that it stays in the parameter block.
            a[3] = sheets as f32;
            12
        }
        // A closure cannot be written: a marker, which reading refuses with a typed error.
        Primitive::Implicit(_) => 13,
        // The mesh follows the parameters (see `write_solid`).
        Primitive::Mesh(_) => 14,
        Primitive::Blob(ref b) => {
            a[0] = b.threshold();
            if let Potential::Rational { d } = b.potential() {
                a[1] = d;
            }
            9
        }
    };
    (kind, a)
}

fn potential_code(p: Potential) -> u8 {
    match p {
        Potential::Pov => 0,
        Potential::Wyvill => 1,
        Potential::Rational { .. } => 2,
        Potential::InverseSquare => 3,
    }
}

/// Reads what [`write_solid`] wrote, `depth` levels down.
fn read_solid(r: &mut Reader, depth: usize) -> Result<Solid> {
    if depth > MAX_SOLID_READ_DEPTH {
        return Err(bad(format!("a solid deeper than {MAX_SOLID_READ_DEPTH} levels")));
    }
    match r.u8()? {
        0 => {
            let kind = r.u8()?;
            let mut a = [0.0f32; 10];
            for x in &mut a {
                *x = r.f32()?;
            }
            // Parameters a kind does not use must be written as +0.0, so that bytes read back
            // are the bytes written.
            let potential = match kind {
                9 => Some(match r.u8()? {
                    0 => Potential::Pov,
                    1 => Potential::Wyvill,
                    2 => Potential::Rational { d: a[1] },
                    3 => Potential::InverseSquare,
                    k => return Err(bad(format!("unknown blob potential {k}"))),
                }),
                _ => None,
            };
            let used = match (kind, potential) {
                (3 | 6 | 8, _) | (9, Some(Potential::Rational { .. })) => 2,
                (9, _) => 1,
                (10, _) => 3,
                (11 | 12, _) => 4,
                (7, _) => 10,
                _ => 0,
            };
            if a[used..].iter().any(|x| x.to_bits() != 0) {
                return Err(bad(format!("primitive kind {kind} with parameters it does not use")));
            }
            Ok(Solid::Primitive(match kind {
                0 => Primitive::Sphere,
                1 => Primitive::Box,
                2 => Primitive::Cylinder,
                3 => Primitive::Cone { r0: a[0], r1: a[1] },
                4 => Primitive::Disc,
                5 => Primitive::Plane,
                6 => Primitive::Torus { major: a[0], minor: a[1] },
                7 => Primitive::Quadric { coeffs: a },
                8 => Primitive::Superellipsoid { e: a[0], n: a[1] },
                10 => Primitive::Ratioquadric { p: a[0], q: a[1], r: a[2] },
                11 => Primitive::Supertoroid { major: a[0], minor: a[1], e: a[2], n: a[3] },
                12 => {
                    // Any other count is refused by the solid's check, like any bad parameter.
                    let sheets = if a[3] == 1.0 || a[3] == 2.0 { a[3] as u8 } else { 0 };
                    Primitive::Superhyperboloid { e: a[0], n: a[1], sheets, height: a[2] }
                }
                9 => {
                    let n = r.count(20)?;
                    let mut components = Vec::with_capacity(n);
                    for _ in 0..n {
                        let mut c = [0.0f32; 5];
                        for x in &mut c {
                            *x = r.f32()?;
                        }
                        components.push(BlobComponent {
                            center: glam::Vec3::new(c[0], c[1], c[2]),
                            radius: c[3],
                            strength: c[4],
                        });
                    }
                    let potential = potential.unwrap_or(Potential::Pov);
                    Primitive::Blob(std::sync::Arc::new(Blob::new(a[0], potential, components)))
                }
                14 => {
                    let mesh = read_mesh(r)?;
                    Primitive::Mesh(std::sync::Arc::new(MeshSolid::new(mesh)?))
                }
                13 => {
                    return Err(bad(
                        "the scene held a user's implicit surface (a Rust closure), which bytes cannot carry: \
                         build it in code"
                            .to_string(),
                    ));
                }
                k => return Err(bad(format!("unknown primitive kind {k}"))),
            }))
        }
        1 => {
            let mut m = [0.0f32; 12];
            for x in &mut m {
                *x = r.f32()?;
            }
            let inner = read_solid(r, depth + 1)?;
            Ok(Solid::Transformed(Affine3A::from_cols_array(&m), Box::new(inner)))
        }
        2 => {
            let op = match r.u8()? {
                0 => CsgOp::Union,
                1 => CsgOp::Intersection,
                2 => CsgOp::Difference,
                k => return Err(bad(format!("unknown CSG operation {k}"))),
            };
            let n = r.count(2)?;
            let operands = (0..n).map(|_| read_solid(r, depth + 1)).collect::<Result<Vec<_>>>()?;
            Ok(Solid::Csg(op, operands))
        }
        t => Err(bad(format!("unknown solid tag {t}"))),
    }
}

/// The first bytes of a serialized two-level scene.
const MAGIC_INSTANCED: &[u8; 8] = b"STRAHLIN";

impl InstancedScene {
    /// The scene as bytes: each object's built BVH (as [`Scene::to_bytes`]) and the instances.
    /// [`from_bytes`](Self::from_bytes) rebuilds only the top level, one box per instance.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer(Vec::new());
        w.0.extend_from_slice(MAGIC_INSTANCED);
        w.u32(VERSION);
        w.u64(self.objects().len() as u64);
        for o in self.objects() {
            let b = o.to_bytes();
            w.u64(b.len() as u64);
            w.0.extend_from_slice(&b);
        }
        w.u64(self.instances().len() as u64);
        for inst in self.instances() {
            w.u64(inst.object as u64);
            inst.transform.to_cols_array().iter().for_each(|&x| w.f32(x));
        }
        w.0
    }

    /// A two-level scene from the bytes of [`to_bytes`](Self::to_bytes): the objects loaded as
    /// [`Scene::from_bytes`] loads them, the top level built anew; errors as there, and as
    /// [`from_scenes`](Self::from_scenes) gives them for the instances.
    pub fn from_bytes(bytes: &[u8]) -> Result<InstancedScene> {
        let mut r = Reader { b: bytes };
        if r.take(8)? != MAGIC_INSTANCED {
            return Err(bad("not a serialized strahl two-level scene (no STRAHLIN header)"));
        }
        let version = r.u32()?;
        // The two-level layout has not changed since version 1; the objects carry their own.
        if !(1..=VERSION).contains(&version) {
            return Err(bad(format!("format version {version}; this strahl reads version {VERSION}")));
        }
        let n = r.count(8)?;
        let mut objects = Vec::with_capacity(n);
        for _ in 0..n {
            let len = r.count(1)?;
            objects.push(Scene::from_bytes(r.take(len)?)?);
        }
        let k = r.count(8 + 12 * 4)?;
        let mut instances = Vec::with_capacity(k);
        for _ in 0..k {
            let object = r.u64()?;
            let mut m = [0.0f32; 12];
            for x in m.iter_mut() {
                *x = r.f32()?;
            }
            let object = usize::try_from(object).map_err(|_| bad("an instance's object index overflows"))?;
            instances.push(Instance::new(object, Affine3A::from_cols_array(&m)));
        }
        if !r.b.is_empty() {
            return Err(bad(format!("{} bytes after the scene", r.b.len())));
        }
        InstancedScene::from_scenes(objects, instances)
    }
}

fn bad(message: impl Into<String>) -> Error {
    Error::Serialized(message.into())
}

fn test_code(t: TriangleTest) -> u8 {
    match t {
        TriangleTest::MollerTrumbore => 0,
        TriangleTest::Badouel => 1,
        TriangleTest::Watertight => 2,
    }
}

/// Every child reference in range, every node reached once from the root, no path deeper than
/// [`MAX_DEPTH`] wide levels.
fn check_tree(nodes: &[Node], blocks: usize, root: u32) -> Result<()> {
    let leaf_ok = |r: u32| {
        let (start, count) = leaf_blocks(r);
        start.checked_add(count).is_some_and(|end| end <= blocks)
    };
    if root == EMPTY {
        return Ok(());
    }
    let mut seen = vec![false; nodes.len()];
    let mut stack = vec![(root, 1usize)];
    while let Some((r, depth)) = stack.pop() {
        if is_leaf(r) {
            if !leaf_ok(r) {
                return Err(bad(format!("a leaf names blocks beyond the {blocks} there are")));
            }
            continue;
        }
        let i = r as usize;
        if i >= nodes.len() {
            return Err(bad(format!("a child reference ({i}) beyond the {} nodes", nodes.len())));
        }
        if std::mem::replace(&mut seen[i], true) {
            return Err(bad(format!("node {i} is reached twice")));
        }
        if depth > MAX_DEPTH {
            return Err(bad(format!("the tree is deeper than {MAX_DEPTH} levels")));
        }
        stack.extend(nodes[i].child.iter().filter(|&&c| c != EMPTY).map(|&c| (c, depth + 1)));
    }
    Ok(())
}

/// Every used lane of every block names a triangle of a mesh.
fn check_blocks(blocks: &[TriBlock], test: TriangleTest, meshes: &[TriangleMesh]) -> Result<()> {
    for (bi, b) in blocks.iter().enumerate() {
        for lane in 0..BLOCK {
            if b.prim[lane] == u32::MAX {
                continue;
            }
            let g = b.geom_id(test, lane) as usize;
            if meshes.get(g).is_none_or(|m| b.prim[lane] as usize >= m.triangle_count()) {
                return Err(bad(format!(
                    "block {bi} names triangle {} of geometry {g}, which does not exist",
                    b.prim[lane]
                )));
            }
        }
    }
    Ok(())
}

struct Writer(Vec<u8>);

impl Writer {
    fn u8(&mut self, x: u8) {
        self.0.push(x);
    }
    fn u32(&mut self, x: u32) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn u64(&mut self, x: u64) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn f32(&mut self, x: f32) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn f64(&mut self, x: f64) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
}

struct Reader<'a> {
    b: &'a [u8],
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        if n > self.b.len() {
            return Err(bad("cut off: fewer bytes than the scene needs"));
        }
        let (head, rest) = self.b.split_at(n);
        self.b = rest;
        Ok(head)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N]> {
        Ok(self.take(N)?.try_into().expect("N bytes"))
    }
    fn u8(&mut self) -> Result<u8> {
        Ok(self.take(1)?[0])
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    /// A byte that must be 0 or 1, so that every scene has one encoding.
    fn flag(&mut self) -> Result<bool> {
        match self.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            b => Err(bad(format!("a flag byte of {b}, not 0 or 1"))),
        }
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    fn f32(&mut self) -> Result<f32> {
        Ok(f32::from_le_bytes(self.array()?))
    }
    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    /// A count of items of at least `min_size` bytes each, refused if the bytes left cannot hold
    /// them (so a corrupt count never allocates).
    fn count(&mut self, min_size: usize) -> Result<usize> {
        let n = self.u64()?;
        if n.saturating_mul(min_size as u64) > self.b.len() as u64 {
            return Err(bad(format!("a count of {n} items does not fit the {} bytes left", self.b.len())));
        }
        Ok(n as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::BuildConfig;
    use crate::procedural::{sphereflake, uv_sphere};
    use crate::ray::Ray;
    use crate::scene::Query;

    #[test]
    fn round_trip_answers_alike_and_corruption_is_refused() {
        let meshes = vec![sphereflake(1, 8, 16), uv_sphere(Vec3::new(3.0, 0.0, 0.0), 1.0, 8, 16)];
        for cfg in [BuildConfig::default(), BuildConfig::watertight(), BuildConfig::high()] {
            let scene = Scene::build(meshes.clone(), &cfg).unwrap();
            let bytes = scene.to_bytes();
            let back = Scene::from_bytes(&bytes).unwrap();
            assert_eq!(back.meshes(), scene.meshes());
            assert_eq!(back.stats(), scene.stats());
            for i in 0..200 {
                let a = i as f32 * 0.031;
                let ray = Ray::new(Vec3::new(5.0 * a.cos(), 1.0, 5.0 * a.sin()), Vec3::new(-a.cos(), -0.2, -a.sin()));
                assert_eq!(scene.intersect(&ray), back.intersect(&ray));
            }
            // Every cut is refused; so are flipped bytes that break a check (others may load as
            // another valid scene, which is fine: queries on it stay defined).
            for cut in [0, 7, 12, bytes.len() / 2, bytes.len() - 1] {
                assert!(Scene::from_bytes(&bytes[..cut]).is_err(), "cut at {cut}");
            }
            let mut extra = bytes.clone();
            extra.push(0);
            assert!(Scene::from_bytes(&extra).is_err());
            // A `bytes` figure that is not the tree's (fuzzing found one that asked `to_bytes`
            // for 2^56 bytes of capacity): refused.
            let mut figure = bytes.clone();
            // The figure sits 24 bytes before the statistics' end, which the sphere section
            // (test code and a zero set count: 9 bytes) and the solid section (solver code and a
            // zero count: 9 bytes) follow.
            let at = figure.len() - 24 - 9 - 9;
            figure[at + 6] = 0xf7;
            assert!(matches!(Scene::from_bytes(&figure), Err(Error::Serialized(m)) if m.contains("statistics")));
        }
        let empty = Scene::build(vec![], &BuildConfig::default()).unwrap();
        assert!(Scene::from_bytes(&empty.to_bytes()).unwrap().intersect(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
    }

    /// Single flipped bytes anywhere: refused, or a scene whose queries still answer (no panic,
    /// no hang).
    #[test]
    fn flipped_bytes_never_break_a_query() {
        let scene = Scene::build(vec![uv_sphere(Vec3::ZERO, 1.0, 6, 12)], &BuildConfig::watertight()).unwrap();
        let bytes = scene.to_bytes();
        let mut rng = crate::raygen::Pcg32::new(3, 5);
        let (mut refused, mut loaded) = (0, 0);
        for _ in 0..3000 {
            let mut b = bytes.clone();
            let at = (rng.next_f32() * b.len() as f32) as usize % b.len();
            b[at] ^= 1 << ((rng.next_f32() * 8.0) as u32 % 8);
            match Scene::from_bytes(&b) {
                Err(_) => refused += 1,
                Ok(s) => {
                    loaded += 1;
                    for k in 0..8 {
                        let a = k as f32;
                        let ray =
                            Ray::new(Vec3::new(a.cos() * 3.0, 0.3, a.sin() * 3.0), Vec3::new(-a.cos(), 0.0, -a.sin()));
                        let _ = (s.intersect(&ray), s.occluded(&ray));
                    }
                }
            }
        }
        assert!(refused > 0 && loaded > 0, "{refused} refused, {loaded} loaded");
    }

    #[test]
    fn instanced_round_trip() {
        let objects = vec![vec![uv_sphere(Vec3::ZERO, 1.0, 8, 16)]];
        let instances = (0..5)
            .map(|i| {
                Instance::new(
                    0,
                    Affine3A::from_scale_rotation_translation(
                        Vec3::splat(0.5 + i as f32 * 0.1),
                        glam::Quat::from_rotation_y(i as f32),
                        Vec3::new(3.0 * i as f32, 0.0, 0.0),
                    ),
                )
            })
            .collect();
        let scene = InstancedScene::build(objects, instances, &BuildConfig::watertight()).unwrap();
        let back = InstancedScene::from_bytes(&scene.to_bytes()).unwrap();
        assert_eq!(back.instances(), scene.instances());
        for i in 0..100 {
            let ray = Ray::new(Vec3::new(i as f32 * 0.13, 5.0, 0.1), Vec3::new(0.0, -1.0, 0.05));
            assert_eq!(scene.intersect(&ray), back.intersect(&ray));
        }
        assert!(InstancedScene::from_bytes(&scene.to_bytes()[..40]).is_err());
        assert!(Scene::from_bytes(&scene.to_bytes()).is_err());
    }

    #[test]
    fn cycles_and_references_out_of_range_are_refused() {
        let mut n = Node::default();
        n.child[0] = 0; // itself
        assert!(check_tree(&[n], 0, 0).is_err());
        let mut n = Node::default();
        n.child[0] = 5;
        assert!(check_tree(&[n], 0, 0).is_err());
        n.child[0] = crate::bvh::node::leaf_ref(0, 2);
        assert!(check_tree(&[n], 1, 0).is_err());
        assert!(check_tree(&[n], 2, 0).is_ok());
        // A chain deeper than any build.
        let chain: Vec<Node> = (0..MAX_DEPTH as u32 + 2)
            .map(|i| {
                let mut n = Node::default();
                n.child[0] = i + 1;
                n
            })
            .collect();
        let mut chain = chain;
        chain.last_mut().unwrap().child[0] = EMPTY;
        assert!(check_tree(&chain, 0, 0).is_err());
    }
}
