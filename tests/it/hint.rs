//! Pointing hints (issue 24, item 3): a frame with a hint is solved from its region's stars,
//! and a wrong hint costs a lost-in-space search, never a wrong answer.

use crate::common;

/// Boresight error of a solved record against its truth, degrees.
fn boresight_error_deg(r: &serde_json::Value, t: &serde_json::Value) -> f64 {
    let v = |ra: f64, dec: f64| gpustar::catalog::radec_to_vector(ra, dec);
    let a = v(
        r["ra_deg"].as_f64().unwrap(),
        r["dec_deg"].as_f64().unwrap(),
    );
    let b = v(
        t["ra_deg"].as_f64().unwrap(),
        t["dec_deg"].as_f64().unwrap(),
    );
    gpustar::camera::angle(&a, &b).to_degrees()
}

#[test]
fn hinted_frames_solve_in_their_region_and_a_wrong_hint_falls_back() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    common::simulate_small(&frames, 2);
    let truth = common::truths(&frames);
    let out = dir.path().join("out.jsonl");
    let run = |hint: &str| {
        let (f, o) = (frames.to_str().unwrap(), out.to_str().unwrap());
        let mut args = vec![
            "batch",
            f,
            "--fov-deg",
            "18",
            "--backend",
            "cpu",
            "-q",
            "-o",
            o,
        ];
        args.extend(["--hint", hint]);
        common::run_ok(&args);
        std::fs::read_to_string(&out)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .collect::<Vec<_>>()
    };
    let (ra, dec) = (
        truth[0]["ra_deg"].as_f64().unwrap(),
        truth[0]["dec_deg"].as_f64().unwrap(),
    );
    // A hint 0.5° off the first frame's centre, radius 1°.
    let near = run(&format!("{},{},1", ra, dec - 0.5));
    // The antipode of the first frame: its region holds none of its stars.
    let far = run(&format!("{},{},1", (ra + 180.0) % 360.0, -dec));
    for (records, what) in [(&near, "near"), (&far, "far")] {
        assert_eq!(records.len(), 2);
        for (r, t) in records.iter().zip(&truth) {
            assert_eq!(r["status"], "solved", "{what}: {r}");
            let err = boresight_error_deg(r, t);
            assert!(err < 0.01, "{what}: {} off by {err}°", r["file"]);
            assert_eq!(r["hint"]["source"], "--hint");
        }
    }
    let offset = |r: &serde_json::Value| r["hint"]["offset_deg"].as_f64().unwrap();
    assert!((offset(&near[0]) - 0.5).abs() < 0.01, "{}", near[0]["hint"]);
    assert!(offset(&far[0]) > 170.0, "{}", far[0]["hint"]);
    // Frames without header keywords under `--hint header`: lost-in-space, no hint field.
    let none = run("header");
    assert!(
        none.iter()
            .all(|r| r["status"] == "solved" && r.get("hint").is_none())
    );
}

#[test]
fn bad_hints_are_refused_with_the_usage() {
    for bad in ["10", "10,95", "10,20,0", "somewhere"] {
        let out = common::gpustar()
            .args(["batch", ".", "--fov-deg", "10", "--hint", bad])
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "--hint {bad}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("--hint expects RA,DEC"), "{err}");
    }
}

/// The regional search itself: a region's few hundred stars solve the frame, its false-match
/// test counts its own hypotheses at half the budget, and a region the frame is not in
/// gives no solution (the fallback is the caller's).
#[test]
fn a_region_solves_its_own_frames_and_no_others() {
    use gpustar::solve::hinted::regional_solver;
    use gpustar::solve::{Outcome, Settings};
    let catalog = gpustar::catalog::Catalog::builtin();
    let size = (512, 512);
    let s = gpustar::simulate::SimSettings {
        width: size.0,
        height: size.1,
        fov_x_deg: 12.0,
        seed: 31,
        ..Default::default()
    };
    let set = common::rendered(&s, 4);
    let camera = gpustar::camera::Camera::from_fov(size.0, size.1, 12.0).unwrap();
    let settings = Settings::default();
    let hint = |t: &gpustar::simulate::Truth, off: f64| gpustar::sky::hint::Hint {
        ra_deg: t.ra_deg,
        dec_deg: (t.dec_deg + off).clamp(-90.0, 90.0),
        radius_deg: 1.0,
        source: "test",
    };
    let mut solved = 0;
    for (f, t) in &set {
        let dets = gpustar::solve::detect::detect(f, &settings.detect);
        let here = regional_solver(&catalog, &camera, &settings, &hint(t, 0.6)).unwrap();
        assert!(
            here.bands[0].refs.len() < 2000,
            "{} stars",
            here.bands[0].refs.len()
        );
        assert_eq!(here.settings.searches, 2);
        if let Outcome::Solved(r, _) = here.identify(dets.clone(), None).outcome {
            let truth = nalgebra::Matrix3::from_fn(|i, j| t.rotation_matrix[i][j]);
            let err = gpustar::solve::attitude::attitude_error(&r.r, &truth).to_degrees();
            assert!(err < 0.01, "{err}°");
            solved += 1;
        }
        let elsewhere = regional_solver(&catalog, &camera, &settings, &hint(t, 40.0));
        if let Ok(other) = elsewhere {
            assert!(matches!(
                other.identify(dets, None).outcome,
                Outcome::Unsolved(_)
            ));
        }
    }
    assert_eq!(solved, set.len());
}

/// GPU = CPU for hinted frames, including one whose hint is wrong (its region does not solve
/// it, so the GPU run builds the lost-in-space solver on demand and votes on the GPU).
#[test]
fn hinted_records_are_the_same_on_both_backends() {
    if common::gpu("hinted_records_are_the_same_on_both_backends").is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    common::simulate_small(&frames, 3);
    let t = &common::truths(&frames)[0];
    let hint = format!(
        "{},{},1",
        t["ra_deg"].as_f64().unwrap(),
        t["dec_deg"].as_f64().unwrap() - 0.4
    );
    let run = |backend: &str| {
        let out = dir.path().join(format!("{backend}.jsonl"));
        let (f, o) = (frames.to_str().unwrap(), out.to_str().unwrap());
        common::run_ok(&[
            "batch",
            f,
            "--fov-deg",
            "18",
            "--backend",
            backend,
            "-q",
            "-o",
            o,
            "--hint",
            &hint,
        ]);
        std::fs::read_to_string(&out)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .collect::<Vec<_>>()
    };
    let (cpu, gpu) = (run("cpu"), run("gpu"));
    assert_eq!(cpu.len(), 3);
    for (c, g) in cpu.iter().zip(&gpu) {
        assert_eq!(c["status"], "solved", "{c}");
        assert!(
            g["backend"].as_str().unwrap().starts_with("gpu"),
            "{}",
            g["backend"]
        );
        let comparable = |r: &serde_json::Value| {
            let mut r = r.clone();
            r["backend"] = "".into();
            r["timing_ms"] = serde_json::Value::Null;
            r
        };
        common::assert_records_match(&comparable(g), &comparable(c));
    }
}

#[test]
fn hints_are_refused_with_sequences() {
    let dir = tempfile::tempdir().unwrap();
    common::simulate_small(dir.path(), 1);
    let out = common::gpustar()
        .args(["batch", dir.path().to_str().unwrap(), "--fov-deg", "18"])
        .args(["--sequence", "--hint", "10,10"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--hint is not used with --sequence"), "{err}");
}

/// Issue 45, item 5: under `--hint header`, pointing keywords that cannot be used (RA = 'abc',
/// DEC = 95) are named in the frame's record with why, where they were passed over silently.
#[test]
fn unusable_header_pointing_keywords_are_named_in_the_record() {
    let dir = tempfile::tempdir().unwrap();
    let card = |k: &str, v: &str| format!("{:<80}", format!("{k:<8}= {v:>20}"));
    let side = 128usize;
    let mut header = [
        card("SIMPLE", "T"),
        card("BITPIX", "8"),
        card("NAXIS", "2"),
        card("NAXIS1", &side.to_string()),
        card("NAXIS2", &side.to_string()),
        card("RA", "'abc'"),
        card("DEC", "95"),
        format!("{:<80}", "END"),
    ]
    .concat()
    .into_bytes();
    header.resize(2880, b' ');
    header.resize(2880 + (side * side).div_ceil(2880) * 2880, 10);
    std::fs::write(dir.path().join("f.fits"), header).unwrap();
    let out = dir.path().join("out.jsonl");
    let (d, o) = (dir.path().to_str().unwrap(), out.to_str().unwrap());
    common::run_ok(&[
        "batch",
        d,
        "--fov-deg",
        "10",
        "--backend",
        "cpu",
        "-q",
        "--hint",
        "header",
        "-o",
        o,
    ]);
    let r: serde_json::Value =
        serde_json::from_str(std::fs::read_to_string(&out).unwrap().trim()).unwrap();
    let warnings = r["warnings"].to_string();
    assert!(
        warnings.contains("--hint header: RA = abc not used: not a right ascension"),
        "{r}"
    );
    assert!(
        warnings.contains("--hint header: DEC = 95 not used: not a declination"),
        "{r}"
    );
    assert!(r.get("hint").is_none(), "{r}");
}
