//! `--method radial` against `vote`: identify time per frame (CPU twins, one thread, after
//! detection), frames solved, and the memory of each method's table, at 4° on 4096² and at
//! 10° on 1024²; with a GPU, the batch's vote + select against radial + select
//! (`cargo bench --bench radial`).
//!
//! `BENCH_FRAMES_4=DIR` and `BENCH_FRAMES_10=DIR` read the frames and `camera.toml` of DIRs
//! (e.g. of `scripts/sim_frames.py`); without them, 16 frames of `gpustar simulate` each
//! (4°: Hp ≤ 8, 10 false stars; 10°: Hp ≤ 6) are made in temporary directories.

use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::gpu::Gpu;
use gpustar::gpu::radial::RadialJob;
use gpustar::gpu::vote::VoteJob;
use gpustar::io::frame::Frame;
use gpustar::solve::detect::Detection;
use gpustar::solve::radial::{self, Method};
use gpustar::solve::{Outcome, Settings, Solver};
use std::path::PathBuf;
mod common;

use common::median_ms;

fn frames_of(var: &str, tmp: &std::path::Path, fov: f64, size: u32, mag: f64) -> PathBuf {
    if let Ok(d) = std::env::var(var) {
        return PathBuf::from(d);
    }
    let s = gpustar::simulate::SimSettings {
        width: size,
        height: size,
        fov_x_deg: fov,
        mag_limit: mag,
        false_stars: 10,
        frames: 16,
        bits: 16,
        ..Default::default()
    };
    gpustar::simulate::write_set(&Catalog::builtin(), &s, tmp, 2, |_| {}).unwrap();
    tmp.to_path_buf()
}

fn main() {
    let catalog = Catalog::builtin();
    let gpu = Gpu::new(std::env::var("GPUSTAR_ADAPTER").ok().as_deref())
        .map_err(|e| eprintln!("no GPU: {e:#}; the CPU twins only"))
        .ok();
    let (t4, t10) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let sets = [
        (
            "4°, 4096²",
            frames_of("BENCH_FRAMES_4", t4.path(), 4.0, 4096, 8.0),
        ),
        (
            "10°, 1024²",
            frames_of("BENCH_FRAMES_10", t10.path(), 10.0, 1024, 6.0),
        ),
    ];
    println!(
        "| set | method | table MB | identify ms/frame, median (p90) | solved | GPU batch scoring ms/frame |"
    );
    println!("|---|---|---|---|---|---|");
    for (name, dir) in sets {
        let (camera, mag_limit) = Camera::from_toml_file(&dir.join("camera.toml")).unwrap();
        let mut names: Vec<PathBuf> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "fits" || x == "png"))
            .collect();
        names.sort();
        for method in [Method::Vote, Method::Radial] {
            let settings = Settings {
                mag_limit,
                method,
                ..Settings::default()
            };
            let solver = Solver::new(&catalog, camera.clone(), settings).unwrap();
            let dets: Vec<Vec<Detection>> = names
                .iter()
                .map(|p| gpustar::solve::detect::detect(&Frame::read(p).unwrap(), &settings.detect))
                .collect();
            // One warm-up (the table's pages, the epoch's catalog), then each frame once.
            if let Some(d) = dets.first() {
                solver.identify(d.clone(), None);
            }
            let mut times = Vec::new();
            let mut solved = 0;
            for d in &dets {
                let t0 = std::time::Instant::now();
                let sol = solver.identify(d.clone(), None);
                times.push(t0.elapsed().as_secs_f64() * 1e3);
                solved += matches!(sol.outcome, Outcome::Solved(..)) as usize;
            }
            times.sort_by(f64::total_cmp);
            let band = &solver.bands[0];
            let mb = match &band.radial {
                Some(t) => t.bytes(),
                None => band.table().bytes(),
            } as f64
                / 1e6;
            let prepared: Vec<_> = dets.iter().filter_map(|d| solver.prepare(d, 0)).collect();
            let gpu_ms = gpu.as_ref().map(|g| match &band.radial {
                Some(t) => {
                    let table = g.upload_radial(t).unwrap();
                    let jobs: Vec<RadialJob> = prepared
                        .iter()
                        .map(|p| RadialJob {
                            features: radial::image_features(&p.vectors[..p.n_vote], t),
                            k: radial::CANDIDATES,
                        })
                        .collect();
                    median_ms(3, || {
                        g.radial(&table, &jobs).unwrap();
                    })
                }
                None => {
                    let table = g.upload_table(band.table(), band.refs.len()).unwrap();
                    let jobs: Vec<VoteJob> = prepared.iter().map(VoteJob::of).collect();
                    median_ms(3, || {
                        g.vote(band.table(), &table, &jobs).unwrap();
                    })
                }
            });
            println!(
                "| {name} | {method:?} | {mb:.1} | {:.2} ({:.2}) | {solved} / {} | {} |",
                times[times.len() / 2],
                times[(times.len() * 9 / 10).min(times.len() - 1)],
                dets.len(),
                gpu_ms.map_or("-".into(), |ms| format!(
                    "{:.2} ({})",
                    ms / prepared.len().max(1) as f64,
                    gpu.as_ref().unwrap().backend_name()
                ))
            );
        }
    }
}
