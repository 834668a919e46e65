//! Stage `pattern` (the scale-free first pass's lookup): the kernel's rows equal the CPU twin's
//! exactly; frames of a field of view the solver is not told (12° and 18° with `--fov-deg
//! 10..20`) solve in the scale-free pass, each within 60″ of the truth with its field fitted,
//! the same on both backends. Catalog stars to magnitude 6.5 (one band: its tables build in
//! seconds), one solver shared by the tests.

use crate::common;

use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::pipeline::{Backend, CameraSource, GpuRunner, Pipeline};
use gpustar::simulate::SimSettings;
use gpustar::solve::scale_free;
use gpustar::solve::{Outcome, Settings, Solver};

/// Focal lengths scale as 1 / tan(FOV / 2).
fn focal(fov_deg: f64) -> f64 {
    1.0 / (fov_deg.to_radians() / 2.0).tan()
}

/// What `--fov-deg 10..20 --mag-limit 6.5` sets for 1024² frames: the camera of 15°, the
/// focal lengths of 20° to 10° relative to it.
fn settings() -> Settings {
    Settings {
        scale_range: Some((focal(20.0) / focal(15.0), focal(10.0) / focal(15.0))),
        mag_limit: Some(6.5),
        table_cache: false,
        ..Settings::default()
    }
}

static SOLVER: std::sync::LazyLock<Solver> = std::sync::LazyLock::new(|| {
    let camera = Camera::from_fov(1024, 1024, 15.0).unwrap();
    Solver::new(&Catalog::builtin(), camera, settings()).unwrap()
});

/// Frames showing stars to magnitude 7 (fainter than the catalog's selection).
fn sim(fov: f64, seed: u64) -> SimSettings {
    SimSettings {
        width: 1024,
        height: 1024,
        fov_x_deg: fov,
        mag_limit: 7.0,
        seed,
        ..Default::default()
    }
}

#[test]
fn pattern_gpu_matches_cpu() {
    let Some(gpu) = common::gpu("pattern_gpu_matches_cpu") else {
        return;
    };
    let solver = &*SOLVER;
    let sf = solver
        .scale_free
        .as_ref()
        .expect("a scale search has a pattern index");
    let mut queries = Vec::new();
    for fov in [12.0, 18.0] {
        for (frame, _) in common::rendered(&sim(fov, 61), 2) {
            let dets = gpustar::solve::detect::detect(&frame, &solver.settings.detect);
            queries.extend(
                solver
                    .scale_free_lookup(&dets, 0..solver.scale_free_rounds(dets.len()))
                    .unwrap()
                    .queries,
            );
        }
    }
    // Keys beyond every pattern's, and the first and last keys, too.
    queries.extend([
        0,
        u32::MAX,
        sf.index.keys[0],
        *sf.index.keys.last().unwrap(),
    ]);
    let table = gpu.upload_patterns(&sf.index).unwrap();
    let on_gpu = gpu.pattern(&table, &queries).unwrap();
    let keys = &sf.index.keys;
    let buckets = gpustar::cpu::pattern::Buckets::new(keys);
    let on_cpu = gpustar::cpu::pattern::pattern(keys, Some(&buckets), &queries);
    assert_eq!(on_gpu, on_cpu);
    assert_eq!(gpustar::cpu::pattern::pattern(keys, None, &queries), on_cpu);
    let found: u32 = on_cpu.iter().map(|r| r.end - r.start).sum();
    println!(
        "pattern GPU = CPU: {} queries, {found} patterns found, index of {} patterns ({} MiB)",
        queries.len(),
        sf.index.len(),
        sf.index.bytes() >> 20
    );
    assert!(found > 0 && on_cpu.iter().all(|r| r.start <= r.end));
}

/// The scale-free pass alone on a frame: its solution, if it accepts one, and that
/// solution's angle from the truth (arcsec).
fn pass_alone(
    solver: &Solver,
    frame: &gpustar::io::frame::Frame,
    truth: &gpustar::simulate::Truth,
) -> Option<(gpustar::solve::refine::Refined, f64)> {
    let sf = solver.scale_free.as_ref().expect("a pattern index");
    let dets = gpustar::solve::detect::detect(frame, &solver.settings.detect);
    let lookup = solver.scale_free_lookup(&dets, 0..solver.scale_free_rounds(dets.len()))?;
    let rows = scale_free::rows_cpu(sf, &lookup);
    let Some(Outcome::Solved(r, _)) =
        solver.finish_scale_free(&dets, &lookup, &rows, None, &mut Default::default())
    else {
        return None;
    };
    // A frame whose pass has checked its share of patterns already checks no more.
    let mut spent = scale_free::Checked {
        patterns: scale_free::MAX_PATTERNS,
        refined: 0,
        spent: false,
    };
    let over = solver.finish_scale_free(&dets, &lookup, &rows, None, &mut spent);
    assert!(over.is_none() && spent.spent && spent.patterns == scale_free::MAX_PATTERNS);
    // Looked up one round at a time (the CPU's way), what the earlier rounds checked and
    // refined carried over: the same solution as all rounds at once (the GPU's way).
    let mut checked = scale_free::Checked::default();
    let mut by_round = None;
    for round in 0..solver.scale_free_rounds(dets.len()) {
        let l = solver.scale_free_lookup(&dets, round..round + 1)?;
        let rows = scale_free::rows_cpu(sf, &l);
        by_round = solver.finish_scale_free(&dets, &l, &rows, None, &mut checked);
        if by_round.is_some() || checked.spent {
            break;
        }
    }
    let Some(Outcome::Solved(b, _)) = by_round else {
        panic!("solved all at once, not round by round");
    };
    assert_eq!((b.r, b.matches.len()), (r.r, r.matches.len()));
    let err = gpustar::solve::attitude::attitude_error(
        &r.r,
        &nalgebra::Matrix3::from_fn(|i, j| truth.rotation_matrix[i][j]),
    );
    Some((r, err.to_degrees() * 3600.0))
}

#[test]
fn unknown_fields_solve_in_the_scale_free_pass() {
    let solver = &*SOLVER;
    let mut solved = 0;
    let mut frames = 0;
    for fov in [12.0, 18.0] {
        for (frame, truth) in common::rendered(&sim(fov, 62), 4) {
            frames += 1;
            let Some((r, err)) = pass_alone(solver, &frame, &truth) else {
                continue;
            };
            assert!(err < 60.0, "{fov}°: {err}″ from the truth");
            let fitted = r.camera.fov_x_deg();
            assert!(
                (fitted - fov).abs() < 0.01 * fov,
                "{fov}°: fitted {fitted}°"
            );
            assert!(r.hypotheses >= 1 && r.fixed == 4);
            solved += 1;
        }
    }
    println!("scale-free pass: {solved} of {frames} frames solved");
    assert_eq!(solved, frames, "{solved} of {frames} solved");
}

/// With a known scale the pass comes first too: easy 15° frames solve in it, the camera kept
/// as given (no focal length fitted), judged against the pass's 1/65536 of the budget.
#[test]
fn known_fields_solve_in_the_pass_with_the_camera_given() {
    let camera = Camera::from_fov(1024, 1024, 15.0).unwrap();
    let settings = Settings {
        mag_limit: Some(6.5),
        table_cache: false,
        ..Settings::default()
    };
    let solver = Solver::new(&Catalog::builtin(), camera.clone(), settings).unwrap();
    assert!(solver.scale_free.is_some(), "a known scale has the pass");
    assert_eq!(
        solver.scale_free.as_ref().map(|sf| sf.limits.share),
        Some(scale_free::KNOWN_SCALE_SHARE)
    );
    assert!(
        !solver.passes.is_empty(),
        "a known scale is voted after the pass"
    );
    let mut solved = 0;
    let frames = common::rendered(&sim(15.0, 63), 4);
    for (frame, truth) in &frames {
        let Some((r, err)) = pass_alone(&solver, frame, truth) else {
            continue;
        };
        assert!(err < 60.0, "{err}″ from the truth");
        assert_eq!(r.camera.fx, camera.fx, "the focal length was fitted");
        solved += 1;
    }
    assert_eq!(solved, frames.len(), "{solved} of {} solved", frames.len());
}

/// A range wider than ±5 % is not walked scale by scale (`--fov-walk` asks for it): a frame
/// the pass cannot solve, eight stars at places no sky has, is unsolved after the pass and
/// says why.
#[test]
fn a_wide_range_is_not_walked_after_the_pass() {
    let solver = &*SOLVER;
    assert!(solver.passes.is_empty(), "10..20° is walked");
    // A regular grid: every quad's ratios are those of a few shapes, none a sky quad's.
    let dets: Vec<gpustar::solve::detect::Detection> = (0..8)
        .map(|i| gpustar::solve::detect::Detection {
            x: 100.0 + 250.0 * (i % 4) as f64,
            y: 300.0 + 400.0 * (i / 4) as f64,
            flux: 1000.0 - i as f64,
            area: 9,
            peak: 500,
            saturated: false,
            sigma_px: None,
        })
        .collect();
    let sol = solver.identify(dets, None);
    assert!(
        matches!(
            sol.outcome,
            Outcome::Unsolved(gpustar::solve::Unsolved::NoConsistentMatch)
        ),
        "{:?}",
        sol.outcome
    );
}

#[test]
fn unknown_fields_give_the_same_records_on_both_backends() {
    let Some(g) = common::gpu("unknown_fields_give_the_same_records_on_both_backends") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    for fov in [12.0, 18.0] {
        for (k, (f, _)) in common::rendered(&sim(fov, 63), 2).iter().enumerate() {
            let name = format!("f{fov}_{k}.png");
            let path = tmp.path().join(&name);
            let px: Vec<u8> = f.pixels.iter().map(|&p| p as u8).collect();
            image::GrayImage::from_raw(f.width, f.height, px)
                .unwrap()
                .save(&path)
                .unwrap();
            files.push((path, name));
        }
    }
    let pipeline = |backend| {
        Pipeline::new(
            Catalog::builtin(),
            settings(),
            CameraSource::fov(15.0),
            backend,
        )
    };
    let on_gpu = pipeline(Backend::Gpu(Box::new(GpuRunner::new(g)))).process_batch(&files);
    let on_cpu = pipeline(Backend::Cpu).process_batch(&files);
    let mut solved = 0;
    for (a, b) in on_gpu.into_iter().zip(on_cpu) {
        let value = |mut r: gpustar::record::Record| {
            r.timing_ms = Default::default();
            r.backend.clear();
            serde_json::from_str::<serde_json::Value>(&r.to_json_line()).unwrap()
        };
        let (a, b) = (value(a), value(b));
        solved += usize::from(a["status"] == "solved");
        common::assert_records_match(&a, &b);
    }
    assert_eq!(solved, 4, "{solved} of 4 solved");
}

/// A pattern index is mapped without being read whole (a deep catalog's is gigabytes), so a
/// damaged one reaches the pass: quads naming stars the selection lacks are no candidates,
/// and a frame the pass solves with the true index finds nothing with them, without a panic.
#[test]
fn quads_naming_stars_the_selection_lacks_are_skipped() {
    let camera = Camera::from_fov(1024, 1024, 15.0).unwrap();
    let mut solver = Solver::new(&Catalog::builtin(), camera, settings()).unwrap();
    let stars = solver.bands[solver.scale_free.as_ref().unwrap().band]
        .refs
        .len() as u32;
    let (frame, truth) = common::rendered(&sim(15.0, 62), 1).remove(0);
    assert!(
        pass_alone(&solver, &frame, &truth).is_some(),
        "solved with the true index"
    );
    let sf = solver.scale_free.as_mut().unwrap();
    let beyond: Vec<[u32; 4]> = (sf.index.quads.iter())
        .map(|q| [q[0], q[1], q[2], stars + q[3]])
        .collect();
    sf.index.quads = beyond.into();
    assert!(pass_alone(&solver, &frame, &truth).is_none());
}
