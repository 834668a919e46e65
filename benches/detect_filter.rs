//! Detection with and without the matched filter (`--detect-filter binomial`): completeness
//! against each star's peak SNR, detections that are no star (noise, hot pixels), and time per
//! frame on the CPU twins.
//!
//! `BENCH_FRAMES=DIR cargo bench --bench detect_filter` reads the frames and `truth.jsonl` of
//! DIR (e.g. frames of `scripts/sim_frames.py`, which lists each star's `peak_snr`, its false
//! stars and hot pixels); without it, 60 frames of `gpustar simulate` (10°, Hp ≤ 6) are made
//! in a temporary directory, whose truth has no SNR (completeness is then by magnitude).

use gpustar::io::frame::Frame;
use gpustar::solve::detect::{self, DetectSettings, Detection};
use serde_json::Value;
use std::path::PathBuf;
use std::time::Instant;

fn main() {
    let tmp = tempfile::tempdir().expect("a temporary directory");
    let dir = match std::env::var("BENCH_FRAMES") {
        Ok(d) => PathBuf::from(d),
        Err(_) => {
            let s = gpustar::simulate::SimSettings {
                frames: 60,
                fov_x_deg: 10.0,
                psf_sigma_px: 1.2,
                ..Default::default()
            };
            let catalog = gpustar::catalog::Catalog::builtin();
            gpustar::simulate::write_set(&catalog, &s, tmp.path(), 2, |_| {}).unwrap();
            tmp.path().to_path_buf()
        }
    };
    let truth: Vec<Value> = std::fs::read_to_string(dir.join("truth.jsonl"))
        .expect("truth.jsonl")
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let frames: Vec<Frame<'static>> = truth
        .iter()
        .map(|t| Frame::read(&dir.join(t["file"].as_str().unwrap())).unwrap())
        .collect();
    println!("{} frames of {}", frames.len(), dir.display());
    let bins = [0.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 15.0, 1e9];
    for filter in [false, true] {
        let s = DetectSettings {
            matched_filter: filter,
            max_stars: usize::MAX,
            ..Default::default()
        };
        let t0 = Instant::now();
        let found: Vec<Vec<Detection>> = frames.iter().map(|f| detect::detect(f, &s)).collect();
        let ms = t0.elapsed().as_secs_f64() * 1e3 / frames.len() as f64;
        let (mut hit, mut all) = (vec![0usize; bins.len() - 1], vec![0usize; bins.len() - 1]);
        let (mut noise, mut hot_found, mut false_stars) = (0usize, 0usize, 0usize);
        for (t, dets) in truth.iter().zip(&found) {
            let near = |x: f64, y: f64| dets.iter().any(|d| (d.x - x).hypot(d.y - y) <= 1.5);
            for st in t["stars"].as_array().unwrap() {
                let (x, y) = (st["x"].as_f64().unwrap(), st["y"].as_f64().unwrap());
                // SNR when the truth has it, else by magnitude (6 − Hp + 5 stands in).
                let snr = st["peak_snr"]
                    .as_f64()
                    .unwrap_or(11.0 - st["mag"].as_f64().unwrap());
                let b = bins
                    .windows(2)
                    .position(|w| snr >= w[0] && snr < w[1])
                    .unwrap();
                all[b] += 1;
                hit[b] += near(x, y) as usize;
            }
            let points = |k: &str| -> Vec<(f64, f64)> {
                t[k].as_array()
                    .map(|a| {
                        a.iter()
                            .map(|p| (p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
                            .collect()
                    })
                    .unwrap_or_default()
            };
            let fakes = points("false_stars");
            let hot = points("hot_pixels");
            for d in dets {
                let close = |(x, y): &(f64, f64)| (d.x - x).hypot(d.y - y) <= 1.5;
                let star = t["stars"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|st| close(&(st["x"].as_f64().unwrap(), st["y"].as_f64().unwrap())));
                if fakes.iter().any(close) {
                    false_stars += 1;
                } else if hot.iter().any(close) {
                    hot_found += 1;
                } else if !star {
                    noise += 1;
                }
            }
        }
        let n = frames.len() as f64;
        println!(
            "filter {}: {ms:.2} ms/frame ({:.0} frames/s); a frame: {:.2} detections on nothing \
             (noise), {:.2} on hot pixels, {:.2} false stars found",
            if filter { "binomial" } else { "none" },
            1e3 / ms,
            noise as f64 / n,
            hot_found as f64 / n,
            false_stars as f64 / n
        );
        let cells: Vec<String> = bins
            .windows(2)
            .zip(hit.iter().zip(&all))
            .map(|(w, (h, a))| {
                format!(
                    "SNR {}-{}: {}/{} {:.0}%",
                    w[0],
                    if w[1] > 1e8 {
                        "".to_string()
                    } else {
                        w[1].to_string()
                    },
                    h,
                    a,
                    100.0 * *h as f64 / (*a).max(1) as f64
                )
            })
            .collect();
        println!("  completeness {}", cells.join(", "));
    }
}
