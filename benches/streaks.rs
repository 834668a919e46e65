//! What `--streaks` costs: detection per frame with and without the streak stages, on the
//! CPU twins and on the GPU (lavapipe here), for 1024² and 4096² frames of
//! `simulate --streaks` (12° FOV, stars to magnitude 7, one or two streaks on four frames of
//! five): `cargo bench --bench streaks`.
//!
//! "detect" is star detection as `batch` runs it (tiles, threshold, components, centroids,
//! the star list); "+ streaks" adds the streak mask (`streak_rows`, `streak_filter`; on the
//! GPU in the same submission), the segments, the fits and the removal of streak detections.
//! Medians of several runs after a warm-up, over batches of 8 frames; milliseconds per frame
//! and frames/s. `BENCH_SIZES=1024` narrows the run.

mod common;

use common::median_ms;
use gpustar::catalog::Catalog;
use gpustar::cpu::streak_filter::{mask_runs, streak_mask};
use gpustar::cpu::threshold::tile_stats;
use gpustar::gpu::Gpu;
use gpustar::io::frame::Frame;
use gpustar::simulate::SimSettings;
use gpustar::sky::{Station, Utc};
use gpustar::solve::detect::{self, DetectSettings};
use gpustar::streaks::simulate::{StreakSim, render_streaks};
use gpustar::streaks::{self, StreakSettings, segments};

fn main() {
    let gpu = match Gpu::new(std::env::var("GPUSTAR_ADAPTER").ok().as_deref()) {
        Ok(g) => Some(g),
        Err(e) => {
            eprintln!("no GPU: {e:#}; timing the CPU twins only");
            None
        }
    };
    let sizes: Vec<u32> = std::env::var("BENCH_SIZES")
        .ok()
        .map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![1024, 4096]);
    let catalog = Catalog::builtin();
    let ds = DetectSettings::default();
    let ss = StreakSettings::default();
    let st = StreakSim {
        start: Utc::parse("2024-03-15T20:00:00").unwrap(),
        cadence_s: 60.0,
        exposure_s: 5.0,
        station: Station {
            lat_deg: 35.7,
            lon_deg: 51.4,
            height_m: 1200.0,
        },
        snr: (4.0, 25.0),
        length_px: (40.0, 1500.0),
    };
    println!(
        "| size | backend | detect ms/frame | + streaks ms/frame | frames/s: detect, + streaks | slower by | streak stages (CPU): mask, segments, fits, ms/frame |"
    );
    println!("|---|---|---|---|---|---|---|");
    for size in sizes {
        let sim = SimSettings {
            width: size,
            height: size,
            fov_x_deg: 12.0,
            mag_limit: 7.0,
            bits: 16,
            seed: 2026,
            ..SimSettings::default()
        };
        eprintln!("rendering 8 frames of {size}x{size}...");
        let frames: Vec<Frame<'static>> = (0..8)
            .map(|k| Frame {
                width: size,
                height: size,
                pixels: render_streaks(&catalog, &sim, &st, k).unwrap().0.into(),
                saturation: u16::MAX,
            })
            .collect();
        let refs: Vec<&Frame> = frames.iter().collect();
        let p = detect::params(&frames[0], &ds);
        let runs = if size >= 4096 { 3 } else { 7 };
        let per = |ms: f64| ms / frames.len() as f64;
        let cpu_plain = per(median_ms(runs, || {
            for f in &frames {
                std::hint::black_box(detect::detect(f, &ds));
            }
        }));
        let cpu_streaks = per(median_ms(runs, || {
            for f in &frames {
                let (blobs, s) = streaks::detect_cpu(f, &p, &ss, ds.k_sigma);
                std::hint::black_box((detect::star_list(&blobs, &ds), s));
            }
        }));
        // The streak stages alone, on the CPU.
        let tiles: Vec<_> = frames.iter().map(|f| tile_stats(&f.pixels, &p)).collect();
        let sp = ss.params(&p, ds.k_sigma);
        let masks: Vec<_> = frames
            .iter()
            .zip(&tiles)
            .map(|(f, t)| streak_mask(&f.pixels, t, &p, &sp))
            .collect();
        let mask_ms = per(median_ms(runs, || {
            for (f, t) in frames.iter().zip(&tiles) {
                std::hint::black_box(streak_mask(&f.pixels, t, &p, &sp));
            }
        }));
        let seg_ms = per(median_ms(runs, || {
            for m in &masks {
                let runs = mask_runs(m, sp.width, sp.height);
                std::hint::black_box(segments::segments(&runs, sp.width, &Default::default()));
            }
        }));
        let measure_ms = per(median_ms(runs, || {
            for ((f, t), m) in frames.iter().zip(&tiles).zip(&masks) {
                std::hint::black_box(streaks::measure(f, t, m, &p, &ss));
            }
        }));
        let stages = format!(
            "{mask_ms:.2}, {seg_ms:.2}, {:.2}",
            (measure_ms - seg_ms).max(0.0)
        );
        let row = |backend: &str, a: f64, b: f64, stages: &str| {
            println!(
                "| {size}² | {backend} | {a:.2} | {b:.2} | {:.1}, {:.1} | {:+.0} % | {stages} |",
                1e3 / a,
                1e3 / b,
                100.0 * (b / a - 1.0)
            );
        };
        row("cpu", cpu_plain, cpu_streaks, &stages);
        if let Some(g) = &gpu {
            let plain = per(median_ms(runs, || {
                let blobs = g.detect(&refs, &p).unwrap();
                for b in &blobs {
                    std::hint::black_box(detect::star_list(b, &ds));
                }
            }));
            let with = per(median_ms(runs, || {
                let (blobs, px) = g.detect_streaks(&refs, &p, &sp).unwrap();
                for ((b, x), f) in blobs.iter().zip(&px).zip(&frames) {
                    let s = streaks::measure(f, &x.tiles, &x.mask, &p, &ss);
                    std::hint::black_box(detect::star_list(&streaks::off_streaks(b, &s), &ds));
                }
            }));
            row(&g.backend_name(), plain, with, "-");
        }
    }
}
