//! The loops compiled for AVX2 (`gpustar::simd`) compute what the baseline build computes, bit
//! for bit: tile statistics, masks with and without the matched filter, and whole frames solved
//! (detection, PSF fits, vote selection, verification). Each is run as dispatched and again
//! inside `simd::baseline`; the triangle fallback is compared so in `tests/it/triangle.rs`,
//! the FITS pixels in `io::fits`'s tests.

use crate::common;
use gpustar::cpu::threshold::{self, DetectParams};
use gpustar::simd;
use gpustar::solve::Outcome;

/// Without AVX2 both runs are the baseline: the test says so (and CI, whose machines have
/// AVX2, refuses).
fn note_without_avx2(test: &str) {
    if simd::wider() {
        return;
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{test}: this CPU has no AVX2, and CI must compare the two compilations");
    }
    eprintln!("SKIPPED {test}: this CPU has no AVX2: only the baseline loops ran");
}

#[test]
fn detection_stages_are_the_same_compiled_for_avx2() {
    note_without_avx2("detection_stages_are_the_same_compiled_for_avx2");
    for (bits, saturation) in [(16, 65535), (8, 255)] {
        for f in common::sim_frames(2, (640, 480), 12.0, bits, 3) {
            for filter in [false, true] {
                let p =
                    DetectParams::new(f.width, f.height, 32, 5.0, saturation).with_filter(filter);
                let run = || {
                    let tiles = threshold::tile_stats(&f.pixels, &p);
                    let runs = threshold::threshold(&f.pixels, &tiles, &p);
                    (tiles, runs)
                };
                let (tiles, runs) = run();
                assert!(runs.len() > 20, "{} runs", runs.len());
                assert_eq!(
                    (tiles, runs),
                    simd::baseline(run),
                    "{bits} bit, filter {filter}"
                );
            }
        }
    }
}

#[test]
fn frames_solve_the_same_compiled_for_avx2() {
    note_without_avx2("frames_solve_the_same_compiled_for_avx2");
    let solver = common::solver(10.0, (1024, 1024));
    let outcome = |o: &Outcome| match o {
        Outcome::Solved(r, _) => format!("{r:?}"),
        Outcome::Unsolved(why) => why.to_string(),
    };
    let mut solved = 0;
    for (k, f) in common::sim_frames(4, (1024, 1024), 10.0, 16, 5)
        .iter()
        .enumerate()
    {
        let (a, _, _) = solver.solve_frame(f);
        let (b, _, _) = simd::baseline(|| solver.solve_frame(f));
        assert_eq!(a.detections, b.detections, "frame {k}");
        assert_eq!(outcome(&a.outcome), outcome(&b.outcome), "frame {k}");
        solved += matches!(a.outcome, Outcome::Solved(..)) as usize;
    }
    assert!(
        solved >= 3,
        "{solved} of 4 solved: the identification ran both ways"
    );
}
