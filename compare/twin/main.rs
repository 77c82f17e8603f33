//! Builds of strahl side by side in one process, so that host noise falls on both alike:
//! `nat` and `dep` are the working tree compiled with and without `-C target-cpu=native` (a
//! dependency build), `nat0` and `dep0` the same for a base commit. `app SCENE PAIRS A B`
//! builds SCENE's meshes (one flattened scene) with A and B in turn, PAIRS times each (the
//! order swapped every pair, three pairs of warm-up first), and prints the median and quartiles
//! of the per-pair time ratio B/A, by wall clock. Set up by `run.sh`.
use std::time::Instant;

type Run = Box<dyn FnMut() -> f64>;

macro_rules! runner {
    ($k:ident, $path:expr) => {{
        let m = $k::SceneFile::read($path)
            .unwrap()
            .build(&Default::default())
            .unwrap()
            .flatten(&Default::default())
            .unwrap()
            .meshes()
            .to_vec();
        let cfg = $k::BuildConfig::default();
        let mut keep = None;
        Box::new(move || {
            let m = m.clone();
            let t = Instant::now();
            let s = $k::Scene::build(m, &cfg).unwrap();
            let r = t.elapsed().as_secs_f64() * 1e3;
            keep = Some(std::hint::black_box(s));
            r
        }) as Run
    }};
}

fn make(name: &str, path: &str) -> Run {
    match name {
        "nat" => runner!(strahl_nat, path),
        "dep" => runner!(strahl_dep, path),
        "nat0" => runner!(strahl_nat0, path),
        "dep0" => runner!(strahl_dep0, path),
        _ => panic!("unknown build {name}"),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = &args[1];
    let pairs: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(50);
    let an = args.get(3).cloned().unwrap_or_else(|| "nat".into());
    let bn = args.get(4).cloned().unwrap_or_else(|| "dep".into());
    let (mut a, mut b) = (make(&an, path), make(&bn, path));
    for _ in 0..3 {
        a();
        b();
    }
    let (mut va, mut vb) = (Vec::new(), Vec::new());
    for i in 0..pairs {
        if i % 2 == 0 {
            va.push(a());
            vb.push(b());
        } else {
            vb.push(b());
            va.push(a());
        }
    }
    let stat = |mut q: Vec<f64>| {
        q.sort_by(f64::total_cmp);
        (q[q.len() / 2], q[q.len() / 4], q[3 * q.len() / 4])
    };
    let (w, wl, wh) = stat(va.iter().zip(&vb).map(|(x, y)| y / x).collect());
    let med = |v: &Vec<f64>| stat(v.clone()).0;
    println!(
        "{path} pairs {pairs}: {an} {:.2} ms, {bn} {:.2} ms (medians); {bn}/{an} time {w:.3} [IQR {wl:.3}-{wh:.3}]",
        med(&va),
        med(&vb)
    );
}
