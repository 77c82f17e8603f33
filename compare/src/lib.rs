//! The comparison harness: traces the same rays with strahl and Intel Embree 3 on the same threads
//! and reports speed and accuracy side by side (`../shared/BENCHMARKING.md`).
//!
//! - [`embree`]: bindings to the system `libembree3` (the only unsafe code here)
//! - [`scenes`]: the shared scenes with their cameras and lights, `data/`, any OBJ
//! - [`harness`]: builds, ray classes, timed interleaved passes
//! - [`accuracy`]: diffs of answers, decided in float64
//! - [`report`]: table, Markdown, JSON, charts, pictures
//! - [`rayfile`]: the shared ray and hit file formats
#![deny(unsafe_code)]
// SoA buffers are indexed by one lane index across several arrays.
#![allow(clippy::needless_range_loop)]

pub mod accuracy;
pub mod embree;
pub mod fuzz;
pub mod harness;
pub mod implicit;
pub mod kernel;
pub mod methods;
pub mod povray;
pub mod rayfile;
pub mod render;
pub mod report;
pub mod scenes;
pub mod solids;
pub mod spheres;
pub mod torus;

/// A rayon pool of `threads` workers with flush-to-zero and denormals-are-zero set on each.
pub fn pool(threads: usize) -> anyhow::Result<rayon::ThreadPool> {
    Ok(rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .start_handler(|_| {
            strahl::simd::set_flush_denormals();
        })
        .build()?)
}
