//! `--centroid cog` against `ml`: images/s of detection + identification on the CPU backend
//! (one thread, frames in turn, as each `batch` worker does), detection alone, and with a GPU
//! the batch's detection with and without the PSF-fit kernel (`cargo bench --bench centroid`).
//!
//! `BENCH_FRAMES=DIR` reads the frames, `camera.toml` and `truth.jsonl` of DIR (e.g. frames of
//! `scripts/sim_frames.py`); without it, 60 frames of `gpustar simulate` (10°, PSF σ 1.2 px)
//! are made in a temporary directory. Each figure is the median of 3 runs after a warm-up.

use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::cpu::centroid::Blob;
use gpustar::gpu::Gpu;
use gpustar::io::frame::Frame;
use gpustar::solve::detect::{self, Centroid};
use gpustar::solve::{Outcome, Settings, Solver};
use std::path::PathBuf;
mod common;

use common::median_ms;

fn main() {
    let tmp = tempfile::tempdir().expect("a temporary directory");
    let catalog = Catalog::builtin();
    let dir = match std::env::var("BENCH_FRAMES") {
        Ok(d) => PathBuf::from(d),
        Err(_) => {
            let s = gpustar::simulate::SimSettings {
                frames: 60,
                fov_x_deg: 10.0,
                psf_sigma_px: 1.2,
                ..Default::default()
            };
            gpustar::simulate::write_set(&catalog, &s, tmp.path(), 2, |_| {}).unwrap();
            tmp.path().to_path_buf()
        }
    };
    let (camera, mag_limit) = Camera::from_toml_file(&dir.join("camera.toml")).unwrap();
    let mut names: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .is_some_and(|x| x == "fits" || x == "png" || x == "tif")
        })
        .collect();
    names.sort();
    let frames: Vec<Frame<'static>> = names.iter().map(|p| Frame::read(p).unwrap()).collect();
    println!("{} frames of {}", frames.len(), dir.display());
    let gpu = Gpu::new(std::env::var("GPUSTAR_ADAPTER").ok().as_deref())
        .map_err(|e| eprintln!("no GPU: {e:#}; the CPU backend only"))
        .ok();
    println!(
        "| centroid | CPU: detect + identify, images/s | solved | CPU: detect, ms/frame | GPU batch detect (+ psf_fit), ms/frame |"
    );
    println!("|---|---|---|---|---|");
    for centroid in [Centroid::Cog, Centroid::Ml] {
        let mut settings = Settings {
            mag_limit,
            ..Settings::default()
        };
        settings.detect.centroid = centroid;
        let solver = Solver::new(&catalog, camera.clone(), settings).unwrap();
        let mut solved = 0;
        let solve_ms = median_ms(3, || {
            solved = frames
                .iter()
                .filter(|f| {
                    matches!(
                        solver.solve_frame_at(f, None).0.outcome,
                        Outcome::Solved(..)
                    )
                })
                .count();
        });
        let d = settings.detect;
        let detect_ms = median_ms(3, || {
            for f in &frames {
                std::hint::black_box(detect::detect(f, &d));
            }
        });
        let gpu_ms = gpu.as_ref().map(|g| {
            let refs: Vec<&Frame> = frames.iter().collect();
            let p = detect::params(refs[0], &d);
            median_ms(3, || {
                let blobs = g.detect(&refs, &p).unwrap();
                let blobs: Vec<&[Blob]> = blobs.iter().map(|b| b.as_slice()).collect();
                std::hint::black_box(
                    detect::stars_with(&refs, &blobs, &d, |w| g.psf_fit(w)).unwrap(),
                );
            })
        });
        let n = frames.len() as f64;
        println!(
            "| {centroid:?} | {:.1} | {solved} / {} | {:.2} | {} |",
            1e3 * n / solve_ms,
            frames.len(),
            detect_ms / n,
            gpu_ms.map_or("-".to_string(), |ms| format!(
                "{:.2} ({})",
                ms / n,
                gpu.as_ref().unwrap().backend_name()
            ))
        );
    }
}
