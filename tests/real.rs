//! Real frames from ../shared/data/real (skipped with a printed reason when absent; CI runs them).

mod common;

use common::{gpustar, shared_dir};
use serde_json::Value;

#[test]
fn esa_tetra3_frames_are_solved_against_truth() {
    let Some(shared) = shared_dir("esa_tetra3_frames_are_solved_against_truth") else {
        return;
    };
    let set = shared.join("data/real/esa-tetra3");
    let tmp = tempfile::tempdir().unwrap();
    // The camera as a user would write it from the set's camera.json: 1024×768, 11.425°.
    let cam = tmp.path().join("tetra3.toml");
    std::fs::write(&cam, "width = 1024\nheight = 768\nfov_x_deg = 11.425\n").unwrap();
    let results = tmp.path().join("results.jsonl");
    let out = gpustar()
        .args([
            "batch",
            set.to_str().unwrap(),
            "--camera",
            cam.to_str().unwrap(),
        ])
        .args([
            "--epoch",
            "2019.58",
            "-o",
            results.to_str().unwrap(),
            "--backend",
            "cpu",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = gpustar()
        .args([
            "evaluate",
            "--truth",
            set.join("truth.jsonl").to_str().unwrap(),
        ])
        .arg(&results)
        .output()
        .unwrap();
    let s: Value = serde_json::from_slice(&out.stdout).unwrap();
    println!("{s}");
    assert_eq!(s["frames"], 8);
    assert_eq!(s["correct"], 8, "{s}");
    assert_eq!(s["wrong"], 0);
    assert_eq!(s["false_ids"], 0, "{s}");
    // The truth attitude is astrometry.net's; ours agrees to well under a pixel (40″).
    assert!(s["max_error_arcsec"].as_f64().unwrap() < 60.0, "{s}");
}
