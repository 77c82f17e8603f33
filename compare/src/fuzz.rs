//! Differential fuzzing against Embree: small random meshes (touching and duplicate triangles,
//! shared edges, degenerate ones, scales from 2^−20 to 2^20) and rays aimed at their vertices,
//! edges and interiors, through both engines' single-ray APIs, closest and any hit. Every
//! disagreement is decided by the harness's float64 classifier (`accuracy::compare`): a tie is no
//! finding; a strahl error is a bug. Embree errors (its default test is not watertight) are
//! counted, not failed on.

use glam::Vec3;
use strahl::raygen::Pcg32;
use strahl::{BuildConfig, Ray, RayStream, Scene, TriangleMesh};

use crate::accuracy::{self, Flat};
use crate::embree;
use crate::harness::{Class, trace_once};

/// What a fuzzing run saw.
#[derive(Clone, Debug, Default)]
pub struct FuzzStats {
    pub scenes: usize,
    pub rays: usize,
    pub disagreements: usize,
    pub ties: usize,
    pub embree_errors: usize,
    /// Descriptions of the strahl errors found (empty: none).
    pub strahl_errors: Vec<String>,
}

/// A random small scene: `(meshes, rays)`.
pub fn random_case(rng: &mut Pcg32) -> (Vec<TriangleMesh>, Vec<Ray>) {
    let scale = 2f32.powi((rng.next_u32() % 41) as i32 - 20);
    let offset = if rng.next_u32().is_multiple_of(4) { scale * 1024.0 * (rng.next_f32() - 0.5) } else { 0.0 };
    let grid = |rng: &mut Pcg32| (rng.next_u32() % 9) as f32 * 0.25 - 1.0;
    let mut p: Vec<Vec3> = Vec::new();
    let mut idx: Vec<[u32; 3]> = Vec::new();
    let n = 1 + rng.next_u32() % 48;
    for _ in 0..n {
        let k = p.len() as u32;
        match rng.next_u32() % 6 {
            // On a coarse lattice: shared edges and vertices, coplanar neighbours.
            0..=2 => {
                for _ in 0..3 {
                    p.push(Vec3::new(grid(rng), grid(rng), grid(rng)));
                }
                idx.push([k, k + 1, k + 2]);
            }
            // A copy of an earlier triangle, or one sharing its edge.
            3 if !idx.is_empty() => {
                let t = idx[(rng.next_u32() as usize) % idx.len()];
                if rng.next_u32().is_multiple_of(2) {
                    idx.push(t);
                } else {
                    p.push(Vec3::new(grid(rng), grid(rng), grid(rng)));
                    idx.push([t[0], t[1], k]);
                }
            }
            // Degenerate: collinear corners.
            4 => {
                let (a, b) = (Vec3::new(grid(rng), grid(rng), grid(rng)), Vec3::new(grid(rng), grid(rng), grid(rng)));
                p.extend([a, b, (a + b) * 0.5]);
                idx.push([k, k + 1, k + 2]);
            }
            _ => {
                for _ in 0..3 {
                    p.push(Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE);
                }
                idx.push([k, k + 1, k + 2]);
            }
        }
    }
    for v in &mut p {
        *v = *v * scale + Vec3::splat(offset);
    }
    let mesh = TriangleMesh::new("fuzz", p.clone(), idx.clone()).expect("indices in range");
    let mut rays = Vec::new();
    for _ in 0..64 {
        let t = idx[(rng.next_u32() as usize) % idx.len()].map(|i| p[i as usize]);
        // Aim at a vertex, an edge or the inside.
        let (a, b) = (rng.next_f32(), rng.next_f32());
        let target = match rng.next_u32() % 3 {
            0 => t[(rng.next_u32() % 3) as usize],
            1 => t[0] + (t[1] - t[0]) * a,
            _ => {
                let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
                t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b
            }
        };
        let dir = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE;
        let back = 1.0 + 8.0 * rng.next_f32();
        let origin = target - dir * back;
        rays.push(Ray::new(origin, dir));
    }
    (vec![mesh], rays)
}

/// Runs `cases` random scenes from `seed` through both engines.
pub fn run(seed: u64, cases: usize, device: &embree::Device, pool: &rayon::ThreadPool) -> anyhow::Result<FuzzStats> {
    let mut rng = Pcg32::new(seed, 77);
    let mut stats = FuzzStats::default();
    for case in 0..cases {
        let (meshes, rays) = random_case(&mut rng);
        let scene = Scene::build(meshes.clone(), &BuildConfig::default())?;
        let escene = embree::Scene::build(device, &meshes, embree::Quality::Medium, false)?;
        let stream: RayStream = rays.iter().copied().collect();
        for class in [Class::Diffuse, Class::Shadow] {
            let (s, e) = trace_once(&scene, &escene, &stream, class, pool);
            let acc = accuracy::compare(&Flat(&meshes), &stream, class.occlusion(), &s, &e);
            let c = &acc.classified;
            stats.disagreements += acc.hit_miss_disagreements + acc.prim_disagreements;
            stats.ties += c.edge_or_vertex_tie + c.depth_tie;
            stats.embree_errors += c.embree_error;
            if c.strahl_error > 0 || c.undecided > 0 {
                stats.strahl_errors.push(format!(
                    "seed {seed} case {case} {}: {} strahl errors, {} undecided: {:?}",
                    class.name(),
                    c.strahl_error,
                    c.undecided,
                    acc.worst
                        .iter()
                        .filter(|w| w.verdict != "edge_or_vertex_tie" && w.verdict != "depth_tie")
                        .collect::<Vec<_>>()
                ));
            }
        }
        stats.scenes += 1;
        stats.rays += rays.len();
    }
    Ok(stats)
}
