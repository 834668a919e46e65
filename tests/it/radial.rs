//! Stage `radial` (`--method radial`, seed 002): the kernel's candidate lists equal the CPU
//! twin's exactly; narrow deep frames solve with radial features + triangles, the same on
//! both backends.

use crate::common;

use gpustar::catalog::Catalog;
use gpustar::gpu::radial::RadialJob;
use gpustar::pipeline::{Backend, CameraSource, GpuRunner, Pipeline};
use gpustar::simulate::SimSettings;
use gpustar::solve::radial::{self, Method};
use gpustar::solve::{Outcome, Settings, Solver};

/// 4° frames of 2048² with 5 false stars: a narrow field where every catalog star (Hp ≤ 8)
/// in view is detected.
fn sim() -> SimSettings {
    SimSettings {
        width: 2048,
        height: 2048,
        fov_x_deg: 4.0,
        mag_limit: 8.0,
        false_stars: 5,
        seed: 44,
        ..Default::default()
    }
}

fn radial_solver(s: &SimSettings) -> Solver {
    let settings = Settings {
        mag_limit: Some(8.0),
        method: Method::Radial,
        table_cache: false,
        ..Settings::default()
    };
    Solver::new(&Catalog::builtin(), s.camera().unwrap(), settings).unwrap()
}

#[test]
fn radial_gpu_matches_cpu() {
    let Some(gpu) = common::gpu("radial_gpu_matches_cpu") else {
        return;
    };
    let s = sim();
    let solver = radial_solver(&s);
    let t = solver.bands[0].radial.as_ref().unwrap();
    let mut jobs = Vec::new();
    for (frame, _) in common::rendered(&s, 4) {
        let dets = gpustar::solve::detect::detect(&frame, &solver.settings.detect);
        let p = solver.prepare(&dets, 0).unwrap();
        jobs.push(RadialJob {
            features: radial::image_features(&p.vectors[..p.n_vote], t),
            k: radial::CANDIDATES,
        });
    }
    let table = gpu.upload_radial(t).unwrap();
    let on_gpu = gpu.radial(&table, &jobs).unwrap();
    let mut filled = 0;
    for (job, g) in jobs.iter().zip(&on_gpu) {
        let c = radial::candidates_cpu(t, &job.features, job.k);
        assert_eq!(c.candidates, g.candidates);
        filled += c.candidates.iter().filter(|&&x| x != 0).count();
    }
    println!(
        "radial GPU = CPU: {} frames, {filled} candidates, {} catalog stars, features {} KiB",
        jobs.len(),
        t.stars,
        t.bytes() >> 10
    );
    assert!(
        filled > 4 * 8 * radial::CANDIDATES / 2,
        "{filled} candidates"
    );
}

/// Frames solved within 60″ of the truth by a method (and none beyond it).
fn solved_by(
    method: Method,
    frames: &[(gpustar::io::frame::Frame<'static>, gpustar::simulate::Truth)],
) -> usize {
    let s = sim();
    let settings = Settings {
        mag_limit: Some(8.0),
        method,
        table_cache: false,
        ..Settings::default()
    };
    let solver = Solver::new(&Catalog::builtin(), s.camera().unwrap(), settings).unwrap();
    let mut solved = 0;
    for (frame, truth) in frames {
        let (sol, _, _) = solver.solve_frame(frame);
        if let Outcome::Solved(r, _) = &sol.outcome {
            let err = gpustar::solve::attitude::attitude_error(
                &r.r,
                &nalgebra::Matrix3::from_fn(|i, j| truth.rotation_matrix[i][j]),
            );
            assert!(
                err.to_degrees() * 3600.0 < 60.0,
                "{method:?}: {err} rad from the truth"
            );
            solved += 1;
        }
    }
    solved
}

#[test]
fn narrow_frames_solve_with_radial_features_on_both_backends() {
    let s = sim();
    let frames = common::rendered(&s, 6);
    let solved = solved_by(Method::Radial, &frames);
    let triangles = solved_by(Method::Triangle, &frames);
    println!("4° frames: radial solves {solved} of 6, triangles alone {triangles}");
    assert!(solved >= 5, "{solved} of 6 solved");
    assert!(triangles >= 4, "triangles alone solve {triangles} of 6");
    let settings = Settings {
        mag_limit: Some(8.0),
        method: Method::Radial,
        table_cache: false,
        ..Settings::default()
    };
    gpu_records_match_cpu(
        "narrow_frames_solve_with_radial_features_on_both_backends",
        &s,
        &frames,
        settings,
    );
}

/// The same records through the GPU pipeline (lavapipe in CI) as through the CPU's.
fn gpu_records_match_cpu(
    test: &str,
    s: &SimSettings,
    frames: &[(gpustar::io::frame::Frame, gpustar::simulate::Truth)],
    settings: Settings,
) {
    let Some(g) = common::gpu(test) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    for (k, (f, _)) in frames.iter().enumerate() {
        let path = tmp.path().join(format!("f{k}.png"));
        let px: Vec<u8> = f.pixels.iter().map(|&p| p as u8).collect();
        image::GrayImage::from_raw(f.width, f.height, px)
            .unwrap()
            .save(&path)
            .unwrap();
        files.push((path, format!("f{k}.png")));
    }
    let pipeline = |backend| {
        Pipeline::new(
            Catalog::builtin(),
            settings,
            CameraSource::Fixed(s.camera().unwrap()),
            backend,
        )
    };
    let on_gpu = pipeline(Backend::Gpu(Box::new(GpuRunner::new(g)))).process_batch(&files);
    let on_cpu = pipeline(Backend::Cpu).process_batch(&files);
    for (a, b) in on_gpu.into_iter().zip(on_cpu) {
        let value = |mut r: gpustar::record::Record| {
            r.timing_ms = Default::default();
            r.backend.clear();
            serde_json::from_str::<serde_json::Value>(&r.to_json_line()).unwrap()
        };
        common::assert_records_match(&value(a), &value(b));
    }
}

/// `--method radial` falls back to the vote (`Method::identifiers`): among 4° frames with 15
/// false stars, some that radial features cannot solve are solved by the vote after them,
/// right, and the GPU pipeline (lavapipe in CI) writes the same records as the CPU.
#[test]
fn radial_falls_back_to_the_vote_on_both_backends() {
    let s = SimSettings {
        false_stars: 15,
        seed: 2801,
        ..sim()
    };
    let frames = common::rendered(&s, 8);
    let settings = Settings {
        mag_limit: Some(8.0),
        method: Method::Radial,
        table_cache: false,
        // One detection list, so that "radial fails on it" is the whole story.
        detect_retry: false,
        ..Settings::default()
    };
    let solver = Solver::new(&Catalog::builtin(), s.camera().unwrap(), settings).unwrap();
    let radial_passes = solver.passes.len() / 2;
    assert!(
        solver.passes[..radial_passes]
            .iter()
            .all(|p| p.method == Method::Radial)
    );
    assert!(
        solver.passes[radial_passes..]
            .iter()
            .all(|p| p.method == Method::Vote)
    );
    let (mut by_radial, mut by_vote) = (0, 0);
    for (frame, truth) in &frames {
        let dets = gpustar::solve::detect::detect(frame, &solver.settings.detect);
        let radial_solves = (0..radial_passes).any(|h| {
            solver.prepare(&dets, h).is_some_and(|p| {
                let t = solver.bands[p.band].radial.as_ref().unwrap();
                let image = radial::image_features(&p.vectors[..p.n_vote], t);
                let found = radial::candidates_cpu(t, &image, radial::CANDIDATES);
                matches!(
                    solver.finish_radial(&dets, &p, &found, None),
                    Outcome::Solved(..)
                )
            })
        });
        let (sol, _, _) = solver.solve_frame(frame);
        if let Outcome::Solved(r, _) = &sol.outcome {
            let err = gpustar::solve::attitude::attitude_error(
                &r.r,
                &nalgebra::Matrix3::from_fn(|i, j| truth.rotation_matrix[i][j]),
            );
            assert!(err.to_degrees() * 3600.0 < 60.0, "{err} rad from the truth");
            if radial_solves {
                by_radial += 1;
            } else {
                by_vote += 1;
            }
        }
    }
    println!(
        "4° frames, 15 false stars: {by_radial} of 8 solved by radial features, {by_vote} by \
         the vote after them"
    );
    assert!(by_radial >= 3 && by_vote >= 2, "{by_radial}, {by_vote}");
    gpu_records_match_cpu(
        "radial_falls_back_to_the_vote_on_both_backends",
        &s,
        &frames,
        solver.settings,
    );
}
