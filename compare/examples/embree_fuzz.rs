//! Differential fuzzing against Embree for as long as asked: `cargo run --release -p compare
//! --example embree_fuzz -- [cases] [seed]` (RELIABILITY.md). Exits non-zero on a strahl error.
fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let cases: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(10_000);
    let seed: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(1);
    let pool = compare::pool(2)?;
    let device = compare::embree::Device::new("threads=2")?;
    let t = std::time::Instant::now();
    let s = compare::fuzz::run(seed, cases, &device, &pool)?;
    println!(
        "{} scenes, {} rays × 2 queries in {:.1} s: {} disagreements, {} ties, {} Embree errors, {} strahl errors",
        s.scenes,
        s.rays,
        t.elapsed().as_secs_f64(),
        s.disagreements,
        s.ties,
        s.embree_errors,
        s.strahl_errors.len()
    );
    for e in &s.strahl_errors {
        println!("{e}");
    }
    anyhow::ensure!(s.strahl_errors.is_empty(), "strahl errors found");
    Ok(())
}
