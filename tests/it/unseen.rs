//! Frames from sensors gpustar has not seen (issue 15): the detection retry with the matched
//! filter, star positions at a day's own epoch whatever the frame order, and `calibrate` on a
//! simulated wide distorted lens.

use crate::common;

use common::run_ok;
use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::simulate::{SimSettings, render};
use gpustar::solve::{Outcome, Settings, Solver};
use serde_json::Value;

/// Sparse 10° frames whose faint stars (PSF σ 1.2 px, Hp 6 at peak SNR ≈ 3.5) only the matched
/// filter detects: frames that fail with the raw threshold are solved by the retry, right, and
/// with more detections; and the retry's solutions are the same with the shallow selection
/// there or not (no magnitude limit, as `--fov-deg` alone gives).
#[test]
fn the_detection_retry_solves_frames_of_faint_stars() {
    let catalog = Catalog::builtin();
    let s = SimSettings {
        fov_x_deg: 10.0,
        psf_sigma_px: 1.2,
        // Hp 6 at about 3.5σ peak: sky 400 e⁻, read 15 e⁻ (σ 25 e⁻).
        flux_mag0_e: 6.0e5 * 3.5 / 10.0,
        frames: 40,
        seed: 77,
        ..Default::default()
    };
    let camera = s.camera().unwrap();
    let solver = |retry: bool| {
        let settings = Settings {
            detect_retry: retry,
            ..Settings::default()
        };
        Solver::new(&catalog, camera.clone(), settings).unwrap()
    };
    let (with, without) = (solver(true), solver(false));
    assert!(
        with.shallow_band.is_some(),
        "no magnitude limit: a shallow pass"
    );
    let (mut rescued, mut solved_without) = (0, 0);
    for k in 0..s.frames {
        let (pixels, truth) = render(&catalog, &s, k).unwrap();
        let frame = gpustar::io::frame::Frame {
            width: camera.width,
            height: camera.height,
            pixels: pixels.into(),
            saturation: 255,
        };
        let right = |o: &Outcome| match o {
            Outcome::Solved(r, _) => {
                let t = nalgebra::Matrix3::from_fn(|i, j| truth.rotation_matrix[i][j]);
                Some(gpustar::solve::attitude::attitude_error(&r.r, &t).to_degrees() < 0.1)
            }
            Outcome::Unsolved(_) => None,
        };
        let (a, _, _) = with.solve_frame_at(&frame, None);
        let (b, _, _) = without.solve_frame_at(&frame, None);
        assert_ne!(
            right(&a.outcome),
            Some(false),
            "frame {k}: wrong with the retry"
        );
        assert_ne!(right(&b.outcome), Some(false), "frame {k}: wrong without");
        solved_without += right(&b.outcome).is_some() as usize;
        if right(&a.outcome) == Some(true) && right(&b.outcome).is_none() {
            rescued += 1;
            assert!(a.detections.len() > b.detections.len(), "frame {k}");
        }
    }
    println!("detection retry: {rescued} frames rescued, {solved_without} solved without");
    assert!(
        rescued >= 3,
        "{rescued} rescued ({solved_without} solved without)"
    );
}

/// Two frames of the same day at different times use the same star positions (the day's),
/// whichever comes first: records do not depend on thread scheduling.
#[test]
fn star_positions_are_the_days_whatever_the_order() {
    let catalog = Catalog::builtin();
    let camera = Camera::from_fov(1024, 1024, 18.0).unwrap();
    let solver = Solver::new(&catalog, camera, Settings::default()).unwrap();
    let (morning, evening) = (2016.2568, 2016.2571);
    let band = &solver.bands[0];
    let a = band.refs_at(Some(morning));
    let b = band.refs_at(Some(evening));
    assert_eq!(a.selection.epoch, b.selection.epoch);
    let other = Solver::new(
        &catalog,
        Camera::from_fov(1024, 1024, 18.0).unwrap(),
        Settings::default(),
    )
    .unwrap();
    let c = other.bands[0].refs_at(Some(evening));
    assert_eq!(c.selection.epoch, a.selection.epoch);
    assert!((a.selection.epoch - morning).abs() < 1.0 / 365.25);
}

/// A 50° lens with 5 % barrel distortion at the corners, known to its user by its focal length
/// alone: `calibrate` recovers k1, k2 and the principal point, and with its camera file every
/// frame solves with the roll within 0.05°.
#[test]
fn calibrate_recovers_a_wide_distorted_lens() {
    let tmp = tempfile::tempdir().unwrap();
    let lens = tmp.path().join("lens.toml");
    std::fs::write(
        &lens,
        "width = 1280\nheight = 960\nfx_px = 1372.5\nfy_px = 1372.5\ncx_px = 646.5\n\
         cy_px = 474.5\nk1 = -0.15\nk2 = 0.02\n",
    )
    .unwrap();
    let focal = tmp.path().join("focal.toml");
    std::fs::write(&focal, "width = 1280\nheight = 960\nfx_px = 1372.5\n").unwrap();
    let sim = tmp.path().join("sim");
    let p = |p: &std::path::Path| p.to_str().unwrap().to_string();
    run_ok(&[
        "simulate",
        "--camera",
        &p(&lens),
        "--out",
        &p(&sim),
        "-n",
        "12",
        "--mag-limit",
        "5.5",
        "--centroid-noise-px",
        "0.2",
        "--seed",
        "3",
    ]);
    let cal = tmp.path().join("cal.toml");
    run_ok(&[
        "calibrate",
        &p(&sim),
        "--camera",
        &p(&focal),
        "-o",
        &p(&cal),
    ]);
    let (fitted, _) = Camera::from_toml_file(&cal).unwrap();
    assert!((fitted.k1 + 0.15).abs() < 0.005, "{fitted:?}");
    assert!((fitted.k2 - 0.02).abs() < 0.01, "{fitted:?}");
    assert!(
        (fitted.cx - 646.5).abs() < 1.0 && (fitted.cy - 474.5).abs() < 1.0,
        "{fitted:?}"
    );
    assert!((fitted.fx / 1372.5 - 1.0).abs() < 1e-3, "{fitted:?}");
    let records = tmp.path().join("cal.jsonl");
    run_ok(&[
        "batch",
        &p(&sim),
        "--camera",
        &p(&cal),
        "--backend",
        "cpu",
        "-q",
        "-o",
        &p(&records),
    ]);
    let eval = run_ok(&[
        "evaluate",
        "--truth",
        &p(&sim.join("truth.jsonl")),
        &p(&records),
        "--per-frame",
    ]);
    let text = String::from_utf8(eval.stdout).unwrap();
    let mut rolls = 0;
    for line in text.lines().filter(|l| l.contains("roll_error_arcsec")) {
        let v: Value = serde_json::from_str(line).unwrap();
        assert_eq!(v["status"], "solved", "{line}");
        let roll = v["roll_error_arcsec"].as_f64().unwrap();
        assert!(roll.abs() < 0.05 * 3600.0, "{line}");
        rolls += 1;
    }
    assert_eq!(rolls, 12, "{text}");
}
