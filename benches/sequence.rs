//! What `--sequence` costs and saves after detection: the sequence stage (motion between
//! frames, the particle test, tracking, lost-in-space when tracking fails) against
//! lost-in-space identification of the same detections, per frame, on sequences of
//! `simulate --sequence` (18°, 1024², 30 frames 1 s apart, the camera turning 0.05–0.5°/s),
//! with 1.5 times as many particles as stars and with none: `cargo bench --bench sequence`.
//!
//! Detection is left out (it is the same with and without a sequence, except that a sequence
//! keeps 250 detections instead of 100). Medians of 5 runs after a warm-up; milliseconds per
//! frame and frames/s on one thread, and how many frames each way solves.

use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::pipeline::{CameraSource, Solvers};
use gpustar::record::Status;
use gpustar::sequence::simulate::{SequenceSim, write_set};
use gpustar::sequence::{DETECT_STARS, Detected, SequenceOptions, Sequencer};
use gpustar::simulate::SimSettings;
use gpustar::solve::{Outcome, Settings};
use std::time::Instant;

fn main() {
    let catalog = Catalog::builtin();
    for ratio in [1.5, 0.0] {
        let tmp = tempfile::tempdir().expect("a temporary directory");
        let q = SequenceSim {
            sequences: 2,
            frames: 30,
            particle_ratio: ratio,
            ..SequenceSim::default()
        };
        let s = SimSettings::default();
        write_set(&catalog, &s, &q, tmp.path(), 2).expect("the sequences");
        let (camera, _) = Camera::from_toml_file(&tmp.path().join("camera.toml")).unwrap();
        let solvers = Solvers::new(
            catalog.clone(),
            Settings::default(),
            CameraSource::Fixed(camera),
        );
        let names: Vec<String> = (0..q.sequences)
            .flat_map(|j| (0..q.frames).map(move |k| gpustar::sequence::simulate::frame_name(j, k)))
            .collect();
        let detected = || -> Vec<Detected> {
            names
                .iter()
                .map(|n| solvers.detect_cpu(solvers.decode(&tmp.path().join(n), n), DETECT_STARS))
                .collect()
        };
        // Lost-in-space on the brightest 100, as `batch` without --sequence.
        let frames = detected();
        let solver = solvers.get(1024, 1024).unwrap();
        let max = solver.settings.detect.max_stars;
        let lists: Vec<_> = frames
            .iter()
            .map(|d| {
                let v = d.detections.as_ref().unwrap();
                v[..v.len().min(max)].to_vec()
            })
            .collect();
        let mut lis_solved = 0;
        let lis = median(|| {
            let t0 = Instant::now();
            lis_solved = lists
                .iter()
                .filter(|l| {
                    matches!(
                        solver.identify(l.to_vec(), None).outcome,
                        Outcome::Solved(..)
                    )
                })
                .count();
            t0.elapsed().as_secs_f64() * 1e3
        });
        let mut seq_solved = 0;
        let seq = median(|| {
            let frames = detected();
            let mut sequencer = Sequencer::new(&solvers, SequenceOptions::default());
            let t0 = Instant::now();
            seq_solved = frames
                .into_iter()
                .map(|d| sequencer.next(d))
                .filter(|r| r.status == Status::Solved)
                .count();
            t0.elapsed().as_secs_f64() * 1e3
        });
        let n = names.len() as f64;
        println!(
            "particles {ratio:.1}x stars, {n} frames: lost-in-space {:.2} ms/frame ({:.0} frames/s, \
             {lis_solved} solved); sequence stage {:.2} ms/frame ({:.0} frames/s, {seq_solved} \
             solved): {:.1}x",
            lis / n,
            1e3 * n / lis,
            seq / n,
            1e3 * n / seq,
            lis / seq
        );
    }
}

/// The median of 5 timed runs after a warm-up; `f` returns its own time (ms), so that what it
/// prepares is not counted.
fn median(mut f: impl FnMut() -> f64) -> f64 {
    f();
    let mut t: Vec<f64> = (0..5).map(|_| f()).collect();
    t.sort_by(f64::total_cmp);
    t[2]
}
