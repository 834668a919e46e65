//! Per-stage time of the kernels on the GPU (lavapipe here) and of their CPU twins (psf_fit:
//! the windows of each frame's star list, as `--centroid ml` fits them), for
//! 1024² and 4096² frames in batches of 1, 8 and 64: `cargo bench --bench stages`.
//!
//! Frames come from the simulator (18° FOV, stars to magnitude 6, 3 false stars, 5 hot pixels;
//! eight distinct frames, repeated to fill a batch). GPU stage times are differences between
//! runs that stop after successive kernels; "io" is what remains with no kernel: upload,
//! clears and read-back. Every time is the median of several runs after a warm-up run, in
//! milliseconds per frame. `BENCH_SIZES=1024` or `BENCH_BATCHES=1,8` narrow the run.

use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::cpu;
use gpustar::gpu::Gpu;
use gpustar::gpu::detect::DETECT_KERNELS;
use gpustar::gpu::vote::VoteJob;
use gpustar::io::frame::Frame;
use gpustar::simulate::{SimSettings, render};
use gpustar::solve::detect::{self, DetectSettings};
use gpustar::solve::{Settings, Solver};
mod common;

use common::median_ms;

fn list(var: &str, default: &[usize]) -> Vec<usize> {
    std::env::var(var)
        .ok()
        .map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect())
        .unwrap_or_else(|| default.to_vec())
}

struct Row {
    size: u32,
    batch: usize,
    backend: String,
    stages: Vec<(&'static str, f64)>,
    counters: Option<(u64, u64)>,
}

fn main() {
    let gpu = match Gpu::new(std::env::var("GPUSTAR_ADAPTER").ok().as_deref()) {
        Ok(g) => Some(g),
        Err(e) => {
            eprintln!("no GPU: {e:#}; timing the CPU twins only");
            None
        }
    };
    let catalog = Catalog::builtin();
    let settings = DetectSettings::default();
    let mut rows = Vec::new();
    for size in list("BENCH_SIZES", &[1024, 4096]) {
        let size = size as u32;
        let sim = SimSettings {
            width: size,
            height: size,
            fov_x_deg: 18.0,
            seed: 2026,
            ..SimSettings::default()
        };
        eprintln!("rendering 8 frames of {size}x{size}...");
        let distinct: Vec<Frame<'static>> = (0..8)
            .map(|k| Frame {
                width: size,
                height: size,
                pixels: render(&catalog, &sim, k).unwrap().0.into(),
                saturation: 255,
            })
            .collect();
        let camera = Camera::from_fov(size, size, 18.0).unwrap();
        let solve_settings = Settings {
            mag_limit: Some(6.0),
            ..Settings::default()
        };
        let solver = Solver::new(&catalog, camera, solve_settings).unwrap();
        let p = detect::params(&distinct[0], &settings);
        // A known scale: one band.
        let table = solver.bands[0].table();
        let n_ref = solver.bands[0].refs.len();
        let jobs_of = |frames: &[&Frame]| -> Vec<VoteJob> {
            frames
                .iter()
                .filter_map(|f| {
                    let d = detect::detect(f, &settings);
                    solver.prepare(&d, 0).map(|p| VoteJob {
                        ranges: p.ranges,
                        stars: p.n_vote,
                        k: p.k,
                    })
                })
                .collect()
        };
        let gpu_table = gpu.as_ref().map(|g| g.upload_table(table, n_ref).unwrap());
        for batch in list("BENCH_BATCHES", &[1, 8, 64]) {
            let frames: Vec<&Frame> = (0..batch).map(|k| &distinct[k % 8]).collect();
            let jobs = jobs_of(&frames);
            let runs = if (size as usize) * (size as usize) * batch > 64 << 20 {
                1
            } else {
                5
            };
            eprintln!("{size}x{size}, batch {batch}: CPU twins...");
            let per = |ms: f64| ms / batch as f64;
            // CPU twins, stage by stage over the batch.
            let tiles: Vec<_> = frames
                .iter()
                .map(|f| cpu::threshold::tile_stats(&f.pixels, &p))
                .collect();
            let runs_: Vec<_> = frames
                .iter()
                .zip(&tiles)
                .map(|(f, t)| cpu::threshold::threshold(&f.pixels, t, &p))
                .collect();
            let labels: Vec<_> = runs_
                .iter()
                .map(|r| cpu::components::components(r, p.width))
                .collect();
            let mut cpu_stages = vec![
                (
                    "tile_stats",
                    per(median_ms(runs, || {
                        for f in &frames {
                            std::hint::black_box(cpu::threshold::tile_stats(&f.pixels, &p));
                        }
                    })),
                ),
                (
                    "threshold",
                    per(median_ms(runs, || {
                        for (f, t) in frames.iter().zip(&tiles) {
                            std::hint::black_box(cpu::threshold::threshold(&f.pixels, t, &p));
                        }
                    })),
                ),
                (
                    "components",
                    per(median_ms(runs, || {
                        for r in &runs_ {
                            std::hint::black_box(cpu::components::components(r, p.width));
                        }
                    })),
                ),
                (
                    "centroid",
                    per(median_ms(runs, || {
                        for (((f, r), l), t) in frames.iter().zip(&runs_).zip(&labels).zip(&tiles) {
                            std::hint::black_box(cpu::centroid::centroid(&f.pixels, r, l, t, &p));
                        }
                    })),
                ),
            ];
            // The PSF fits (`--centroid ml`) of each frame's star list.
            let windows: Vec<_> = frames
                .iter()
                .flat_map(|f| {
                    detect::star_list(&detect::blobs_cpu(f, &p), &settings)
                        .into_iter()
                        .filter_map(|d| {
                            cpu::psf_fit::window(&f.pixels, f.width, f.height, d.x, d.y)
                        })
                })
                .collect();
            cpu_stages.push((
                "psf_fit",
                per(median_ms(runs, || {
                    for w in &windows {
                        std::hint::black_box(cpu::psf_fit::psf_fit(w));
                    }
                })),
            ));
            let mut votes = Vec::new();
            cpu_stages.push((
                "vote",
                per(median_ms(runs, || {
                    votes = jobs
                        .iter()
                        .map(|j| cpu::vote::vote(table, &j.ranges, j.stars, n_ref).0)
                        .collect();
                })),
            ));
            cpu_stages.push((
                "select",
                per(median_ms(runs, || {
                    for (v, j) in votes.iter().zip(&jobs) {
                        std::hint::black_box(cpu::select::select(v, j.stars, n_ref, j.k));
                    }
                })),
            ));
            rows.push(Row {
                size,
                batch,
                backend: "cpu".into(),
                stages: cpu_stages,
                counters: None,
            });
            let (Some(g), Some(gpu_table)) = (&gpu, &gpu_table) else {
                continue;
            };
            eprintln!("{size}x{size}, batch {batch}: GPU kernels...");
            let mut prefix = Vec::new();
            for k in 0..=DETECT_KERNELS.len() {
                prefix.push(per(median_ms(runs, || {
                    g.detect_prefix(&frames, &p, k).unwrap()
                })));
            }
            let mut stages: Vec<(&'static str, f64)> = vec![("io (detect)", prefix[0])];
            for (k, name) in DETECT_KERNELS.iter().enumerate() {
                stages.push((name, (prefix[k + 1] - prefix[k]).max(0.0)));
            }
            // One submission for the batch's windows, upload and read-back included.
            stages.push((
                "psf_fit",
                per(median_ms(runs, || {
                    g.psf_fit(&windows).unwrap();
                })),
            ));
            let v: Vec<f64> = (0..=2)
                .map(|k| {
                    per(median_ms(runs, || {
                        g.vote_prefix(table, gpu_table, &jobs, k).unwrap()
                    }))
                })
                .collect();
            stages.push(("io (vote)", v[0]));
            stages.push(("vote", (v[1] - v[0]).max(0.0)));
            stages.push(("select", (v[2] - v[1]).max(0.0)));
            let before = g.counters();
            g.detect(&frames, &p).unwrap();
            g.psf_fit(&windows).unwrap();
            g.vote(table, gpu_table, &jobs).unwrap();
            let after = g.counters();
            rows.push(Row {
                size,
                batch,
                backend: g.backend_name(),
                stages,
                counters: Some((
                    after.submissions - before.submissions,
                    after.maps - before.maps,
                )),
            });
        }
    }
    println!(
        "| size | batch | backend | stage times, ms per frame | total ms/frame | frames/s | submissions, maps per batch |"
    );
    println!("|---|---|---|---|---|---|---|");
    for r in &rows {
        let total: f64 = r.stages.iter().map(|s| s.1).sum();
        let stages: Vec<String> = r
            .stages
            .iter()
            .map(|(n, ms)| format!("{n} {ms:.2}"))
            .collect();
        println!(
            "| {}² | {} | {} | {} | {:.2} | {:.1} | {} |",
            r.size,
            r.batch,
            r.backend,
            stages.join(", "),
            total,
            1e3 / total,
            r.counters
                .map(|(s, m)| format!("{s}, {m}"))
                .unwrap_or_else(|| "-".into())
        );
    }
}
