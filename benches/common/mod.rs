//! Shared by the benchmarks.

use std::time::Instant;

/// The median time of `runs` runs of `f` (ms), after a warm-up run (shader compilation,
/// buffer allocation).
pub fn median_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}
