//! Accuracy against speed, per method (`../shared/ACCURACY.md`, "Metrics" and "The chart"): every
//! triangle test × box test of strahl and Embree's default and ROBUST modes, measured on the same
//! rays — the harness's ray sets for speed, t error and agreement, and dedicated sets for leaks
//! (rays from inside a closed sphere placed ever farther from the origin) and for edge- and
//! vertex-aimed rays on closed meshes.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::Vec3;
use serde::Serialize;
use strahl::raygen;
use strahl::{
    BoxTest, BuildConfig, Coherence, HitStream, Query, Ray, RayStream, Scene, TriangleMesh, TriangleTest, procedural,
};

use crate::embree;
use crate::harness::{self, Answers, Class};

/// Scene offsets of the leak test.
pub const OFFSETS: [(&str, f32); 5] = [("0", 0.0), ("1e3", 1e3), ("1e4", 1e4), ("1e5", 1e5), ("1e6", 1e6)];

#[derive(Clone, Debug)]
pub struct Settings {
    /// UV sphere of the leak test: stacks × slices (ACCURACY.md: 500 × 1000, a million triangles).
    pub sphere: (u32, u32),
    pub leak_rays: usize,
    pub edge_rays: usize,
    pub vertex_rays: usize,
    pub passes: usize,
}

impl Default for Settings {
    fn default() -> Self {
        Self { sphere: (500, 1000), leak_rays: 100_000, edge_rays: 50_000, vertex_rays: 20_000, passes: 3 }
    }
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct Speed {
    pub primary: f64,
    pub shadow: f64,
    pub diffuse: f64,
}

impl Speed {
    pub fn geomean(&self) -> f64 {
        (self.primary * self.shadow * self.diffuse).cbrt()
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct MethodResult {
    pub name: &'static str,
    pub box_test: &'static str,
    /// Mrays/s over all scenes of the run (total rays / total best time), on the faster of the
    /// single-ray and packet APIs per scene and class.
    pub mrays: Speed,
    pub leak_rate: BTreeMap<&'static str, f64>,
    pub edge_zero_hit_rate: f64,
    pub edge_double_hit_rate: f64,
    pub vertex_zero_hit_rate: f64,
    /// Distance in ulps between the f32 t and the float64 t of the same triangle, over primary and
    /// diffuse hits.
    pub t_ulp_median: f64,
    pub t_ulp_p999: f64,
    /// Hit/miss agreement with Embree on the primary and diffuse rays of the run.
    pub embree_default_agreement: f64,
    pub embree_robust_agreement: f64,
    pub watertight: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct EmbreeResult {
    pub mode: &'static str,
    pub mrays: Speed,
    pub leak_rate: BTreeMap<&'static str, f64>,
    pub edge_zero_hit_rate: f64,
    pub vertex_zero_hit_rate: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct AccuracyReport {
    pub methods: Vec<MethodResult>,
    pub embree: Vec<EmbreeResult>,
    /// What the sets were made of.
    pub leak_test: String,
    pub closed_meshes: Vec<String>,
}

/// One scene's meshes and ray sets from the main run (rays, Embree default answers).
pub struct SceneRays {
    pub meshes: Vec<TriangleMesh>,
    pub sets: Vec<(Class, RayStream, Answers)>,
}

/// Edge-aimed rays with their two triangles, and vertex-aimed rays with their fans.
type EdgeRays = Vec<(Ray, [u32; 2])>;
type VertexRays = Vec<(Ray, Vec<u32>)>;

fn rate(n: usize, total: usize) -> f64 {
    if total == 0 { 0.0 } else { n as f64 / total as f64 }
}

fn ulps(a: f32, b: f32) -> u32 {
    if a.is_sign_negative() != b.is_sign_negative() {
        return u32::MAX;
    }
    a.to_bits().abs_diff(b.to_bits())
}

/// Times `f` `passes` times on the pool and returns the best seconds.
fn best_time(pool: &rayon::ThreadPool, passes: usize, mut f: impl FnMut() + Send) -> f64 {
    pool.install(&mut f);
    (0..passes.max(1))
        .map(|_| {
            let s = Instant::now();
            pool.install(&mut f);
            s.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn misses_strahl(scene: &Scene, rays: &RayStream, pool: &rayon::ThreadPool) -> usize {
    let mut h = HitStream::default();
    pool.install(|| scene.intersect_stream_par(rays, &mut h, Coherence::Incoherent));
    (0..h.len()).filter(|&i| h.get(i).is_none()).count()
}

fn misses_embree(scene: &embree::Scene, rays: &RayStream, pool: &rayon::ThreadPool) -> usize {
    let mut a = Answers::misses(rays.len());
    pool.install(|| harness::embree_single(scene, rays, Class::Diffuse, &mut a));
    (0..a.len()).filter(|&i| !a.hit(i)).count()
}

/// Closed meshes for edge- and vertex-aimed rays: a sphere, and the shared igea and bunny when
/// present (edges on holes of a scan are skipped by the ray generator).
fn closed_meshes(shared: &std::path::Path) -> Vec<(String, TriangleMesh)> {
    let mut v = vec![("sphere 200×400".to_string(), procedural::uv_sphere(Vec3::ZERO, 1.0, 200, 400))];
    for (name, file) in [("igea", "igea/igea.obj"), ("bunny", "bunny/bunny.obj")] {
        if let Ok(mut m) = strahl::load_obj(shared.join(file))
            && !m.is_empty()
        {
            v.push((name.to_string(), m.remove(0)));
        }
    }
    v
}

/// Runs every measurement. `scenes` are the run's scenes with their ray sets.
pub fn run(
    scenes: &[SceneRays],
    shared: &std::path::Path,
    pool: &rayon::ThreadPool,
    device: &embree::Device,
    settings: &Settings,
    mut progress: impl FnMut(&str),
) -> anyhow::Result<AccuracyReport> {
    // The sets every engine and method sees.
    let spheres: Vec<(&'static str, TriangleMesh, RayStream)> = OFFSETS
        .iter()
        .map(|&(name, off)| {
            let c = Vec3::new(1.0, 0.37, -0.71) * off;
            let (st, sl) = settings.sphere;
            (name, procedural::uv_sphere(c, 1.0, st, sl), raygen::inside_rays(c, 0.5, settings.leak_rays, 7))
        })
        .collect();
    let closed = closed_meshes(shared);
    let aimed: Vec<(EdgeRays, VertexRays)> = closed
        .iter()
        .map(|(_, m)| {
            (raygen::edge_aimed_rays(m, settings.edge_rays, 3), raygen::vertex_aimed_rays(m, settings.vertex_rays, 4))
        })
        .collect();
    let streams: Vec<(RayStream, RayStream)> =
        aimed.iter().map(|(e, v)| (e.iter().map(|x| x.0).collect(), v.iter().map(|x| x.0).collect())).collect();

    // Embree ROBUST answers on the run's rays, for agreement.
    progress("embree robust");
    let mut robust_answers = Vec::new();
    for sc in scenes {
        let es = embree::Scene::build(device, &sc.meshes, embree::Quality::Medium, true)?;
        let mut per = Vec::new();
        for (class, rays, _) in &sc.sets {
            let mut a = Answers::misses(rays.len());
            pool.install(|| harness::embree_single(&es, rays, *class, &mut a));
            per.push(a);
        }
        robust_answers.push(per);
    }

    let mut methods = Vec::new();
    for test in TriangleTest::ALL {
        for boxt in BoxTest::ALL {
            progress(&format!("{} {}", test.name(), boxt.name()));
            let cfg = BuildConfig::default().with_tests(test, boxt);
            // Speed, t error and agreement on the run's ray sets.
            let (mut rays_n, mut secs) = ([0usize; 3], [0f64; 3]);
            let mut ulp = Vec::new();
            let (mut agree_d, mut agree_r, mut agree_n) = (0usize, 0usize, 0usize);
            for (si, sc) in scenes.iter().enumerate() {
                let scene = pool.install(|| Scene::build(sc.meshes.clone(), &cfg))?;
                for (k, (class, rays, emb)) in sc.sets.iter().enumerate() {
                    let mut a = Answers::misses(rays.len());
                    let ci = Class::ALL.iter().position(|c| c == class).unwrap_or(0);
                    // Each method on its faster API (the watertight packet form tests lanes one by one).
                    let t = best_time(pool, settings.passes, || harness::strahl_single(&scene, rays, *class, &mut a))
                        .min(best_time(pool, settings.passes, || harness::strahl_packet(&scene, rays, *class, &mut a)));
                    rays_n[ci] += rays.len();
                    secs[ci] += t;
                    if class.occlusion() {
                        continue;
                    }
                    let rob = &robust_answers[si][k];
                    for i in 0..rays.len() {
                        agree_n += 1;
                        agree_d += (a.hit(i) == emb.hit(i)) as usize;
                        agree_r += (a.hit(i) == rob.hit(i)) as usize;
                        if a.hit(i) {
                            let m = &sc.meshes[a.geom[i] as usize];
                            let r = rays.get(i);
                            if let Some((t64, _)) = strahl::exact_hit(r.origin, r.dir, m.triangle(a.prim[i] as usize)) {
                                ulp.push(ulps(a.t[i], t64 as f32));
                            }
                        }
                    }
                }
            }
            ulp.sort_unstable();
            let q =
                |f: f64| if ulp.is_empty() { 0.0 } else { ulp[((ulp.len() - 1) as f64 * f).round() as usize] as f64 };
            let mrays = |c: usize| if secs[c] > 0.0 { rays_n[c] as f64 / secs[c] / 1e6 } else { 0.0 };
            // Leaks.
            let mut leak_rate = BTreeMap::new();
            for (name, mesh, rays) in &spheres {
                let scene = pool.install(|| Scene::build(vec![mesh.clone()], &cfg))?;
                leak_rate.insert(*name, rate(misses_strahl(&scene, rays, pool), rays.len()));
            }
            // Edge- and vertex-aimed rays.
            let (mut ez, mut ed, mut en, mut vz, mut vn) = (0usize, 0usize, 0usize, 0usize, 0usize);
            for ((_, mesh), ((edges, _), (es, vs))) in closed.iter().zip(aimed.iter().zip(&streams)) {
                let scene = pool.install(|| Scene::build(vec![mesh.clone()], &cfg))?;
                ez += misses_strahl(&scene, es, pool);
                en += es.len();
                vz += misses_strahl(&scene, vs, pool);
                vn += vs.len();
                ed += edges
                    .iter()
                    .filter(|(r, t)| {
                        t.iter().all(|&t| strahl::intersect_triangle(test, r, mesh.triangle(t as usize)).is_some())
                    })
                    .count();
            }
            methods.push(MethodResult {
                name: test.name(),
                box_test: boxt.name(),
                mrays: Speed { primary: mrays(0), shadow: mrays(1), diffuse: mrays(2) },
                leak_rate,
                edge_zero_hit_rate: rate(ez, en),
                edge_double_hit_rate: rate(ed, en),
                vertex_zero_hit_rate: rate(vz, vn),
                t_ulp_median: q(0.5),
                t_ulp_p999: q(0.999),
                embree_default_agreement: rate(agree_d, agree_n),
                embree_robust_agreement: rate(agree_r, agree_n),
                watertight: test.is_watertight() && boxt == BoxTest::Conservative,
            });
        }
    }

    let mut emb = Vec::new();
    for (mode, robust) in [("default", false), ("robust", true)] {
        progress(&format!("embree {mode}"));
        let (mut rays_n, mut secs) = ([0usize; 3], [0f64; 3]);
        for sc in scenes {
            let es = embree::Scene::build(device, &sc.meshes, embree::Quality::Medium, robust)?;
            for (class, rays, _) in &sc.sets {
                let ci = Class::ALL.iter().position(|c| c == class).unwrap_or(0);
                let mut a = Answers::misses(rays.len());
                let t = best_time(pool, settings.passes, || harness::embree_single(&es, rays, *class, &mut a))
                    .min(best_time(pool, settings.passes, || harness::embree_packet(&es, rays, *class, &mut a)));
                rays_n[ci] += rays.len();
                secs[ci] += t;
            }
        }
        let mrays = |c: usize| if secs[c] > 0.0 { rays_n[c] as f64 / secs[c] / 1e6 } else { 0.0 };
        let mut leak_rate = BTreeMap::new();
        for (name, mesh, rays) in &spheres {
            let es = embree::Scene::build(device, std::slice::from_ref(mesh), embree::Quality::Medium, robust)?;
            leak_rate.insert(*name, rate(misses_embree(&es, rays, pool), rays.len()));
        }
        let (mut ez, mut en, mut vz, mut vn) = (0usize, 0usize, 0usize, 0usize);
        for ((_, mesh), (es_rays, vs_rays)) in closed.iter().zip(&streams) {
            let es = embree::Scene::build(device, std::slice::from_ref(mesh), embree::Quality::Medium, robust)?;
            ez += misses_embree(&es, es_rays, pool);
            en += es_rays.len();
            vz += misses_embree(&es, vs_rays, pool);
            vn += vs_rays.len();
        }
        emb.push(EmbreeResult {
            mode,
            mrays: Speed { primary: mrays(0), shadow: mrays(1), diffuse: mrays(2) },
            leak_rate,
            edge_zero_hit_rate: rate(ez, en),
            vertex_zero_hit_rate: rate(vz, vn),
        });
    }
    Ok(AccuracyReport {
        methods,
        embree: emb,
        leak_test: format!(
            "UV sphere {}×{} of radius 1 centred at (1, 0.37, −0.71)·offset, {} rays from random points within 0.5 of its centre",
            settings.sphere.0, settings.sphere.1, settings.leak_rays
        ),
        closed_meshes: closed.iter().map(|(n, m)| format!("{n} ({} triangles)", m.triangle_count())).collect(),
    })
}

/// The two charts of ACCURACY.md: speed against edge-ray leaks and against t error (with the
/// Pareto front), and leak rate against scene offset.
pub fn charts(dir: &std::path::Path, r: &AccuracyReport) -> anyhow::Result<()> {
    use plotters::prelude::*;
    if !crate::report::ensure_font() {
        anyhow::bail!("no DejaVu font found for chart labels");
    }
    const FLOOR: f64 = 1e-7;
    let mut pts: Vec<(String, f64, f64, f64, bool)> = r
        .methods
        .iter()
        .map(|m| (format!("{} / {}", m.name, m.box_test), m.mrays.geomean(), m.edge_zero_hit_rate, m.t_ulp_p999, false))
        .collect();
    pts.extend(
        r.embree
            .iter()
            .map(|e| (format!("Embree {}", e.mode), e.mrays.geomean(), e.edge_zero_hit_rate, f64::NAN, true)),
    );
    let xmax = pts.iter().map(|p| p.1).fold(1.0, f64::max) * 1.15;
    let path = dir.join("accuracy_speed.png");
    let root = BitMapBackend::new(&path, (1400, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(700);
    // Panel 1: edge-aimed zero-hit rate (log) against speed, Pareto front.
    {
        let mut c = ChartBuilder::on(&left)
            .caption("speed vs edge-ray leaks (lower right is better)", ("sans-serif", 20))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(0f64..xmax, (FLOOR..1.0f64).log_scale())?;
        c.configure_mesh()
            .x_desc("Mrays/s (geometric mean of primary, shadow, diffuse)")
            .y_desc("edge-aimed zero-hit rate (0 drawn at 1e-7)")
            .y_label_formatter(&|y| format!("{y:.0e}"))
            .label_style(("sans-serif", 13))
            .draw()?;
        let mut front: Vec<(f64, f64)> = Vec::new();
        let mut sorted: Vec<(f64, f64)> = pts.iter().map(|p| (p.1, p.2.max(FLOOR))).collect();
        sorted.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut best = f64::INFINITY;
        for (x, y) in sorted {
            if y < best {
                front.push((x, y));
                best = y;
            }
        }
        c.draw_series(LineSeries::new(front, RGBColor(150, 150, 150).stroke_width(2)))?;
        for (k, (name, x, y, _, is_embree)) in pts.iter().enumerate() {
            let color = if *is_embree { RED } else { BLUE };
            let at = (*x, y.max(FLOOR));
            // Alternate labels above and below: box-test pairs often sit on the same spot.
            let dy = if k % 2 == 0 { -18 } else { 6 };
            c.draw_series(std::iter::once(
                EmptyElement::at(at)
                    + Circle::new((0, 0), 6, color.filled())
                    + Text::new(name.clone(), (8, dy), ("sans-serif", 12)),
            ))?;
        }
    }
    // Panel 2: p99.9 t error in ulps against speed.
    {
        let ymax = pts.iter().filter(|p| p.3.is_finite()).map(|p| p.3).fold(4.0, f64::max) * 1.2;
        let mut c = ChartBuilder::on(&right)
            .caption("speed vs t error (strahl methods)", ("sans-serif", 20))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(0f64..xmax, 0f64..ymax)?;
        c.configure_mesh()
            .x_desc("Mrays/s")
            .y_desc("p99.9 |t − t64| in ulps")
            .label_style(("sans-serif", 13))
            .draw()?;
        for (k, (name, x, _, u, _)) in pts.iter().filter(|p| p.3.is_finite()).enumerate() {
            let dy = if k % 2 == 0 { -18 } else { 6 };
            c.draw_series(std::iter::once(
                EmptyElement::at((*x, *u))
                    + Circle::new((0, 0), 6, BLUE.filled())
                    + Text::new(name.clone(), (8, dy), ("sans-serif", 12)),
            ))?;
        }
    }
    root.present()?;

    // Leak rate against offset.
    let path = dir.join("accuracy_leaks.png");
    let root = BitMapBackend::new(&path, (900, 550)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut c = ChartBuilder::on(&root)
        .caption("rays leaking out of a closed sphere, by scene offset", ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..4.0, (FLOOR..1.0f64).log_scale())?;
    c.configure_mesh()
        .x_labels(5)
        .x_label_formatter(&|x| OFFSETS.get(x.round() as usize).map(|o| o.0.to_string()).unwrap_or_default())
        .x_desc("offset of the sphere from the origin")
        .y_desc("leak rate (0 drawn at 1e-7)")
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .label_style(("sans-serif", 13))
        .draw()?;
    let mut series: Vec<(String, Vec<f64>)> = r
        .methods
        .iter()
        .map(|m| (format!("{} / {}", m.name, m.box_test), OFFSETS.iter().map(|o| m.leak_rate[o.0]).collect()))
        .collect();
    series.extend(
        r.embree.iter().map(|e| (format!("Embree {}", e.mode), OFFSETS.iter().map(|o| e.leak_rate[o.0]).collect())),
    );
    for (k, (name, ys)) in series.into_iter().enumerate() {
        let color = Palette99::pick(k).to_rgba();
        let pts: Vec<(f64, f64)> = ys.iter().enumerate().map(|(i, y)| (i as f64, y.max(FLOOR))).collect();
        c.draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
            .label(name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2)));
        c.draw_series(pts.into_iter().map(|p| Circle::new(p, 4, color.filled())))?;
    }
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 12))
        .draw()?;
    root.present()?;
    Ok(())
}
