//! `--scale-arcsec`: the pixel scale as solve-field's `arcsecperpix` and ASTAP's `-scale` state
//! it, one value or a range, beside `--fov-deg` (issue 47).

use crate::common;

use common::{gpustar, run_records};

fn records(dir: &std::path::Path, scale: &[&str]) -> Vec<serde_json::Value> {
    let mut c = gpustar();
    c.args([
        "batch",
        dir.to_str().unwrap(),
        "-j",
        "1",
        "--backend",
        "cpu",
    ])
    .args(scale);
    run_records(&mut c)
        .into_iter()
        .map(|mut r| {
            r.as_object_mut().unwrap().remove("timing_ms");
            r
        })
        .collect()
}

#[test]
fn a_pixel_scale_solves_as_its_field_of_view_does() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    common::simulate_small(&dir, 4); // 256² frames of 18°
    // One pixel at the centre of a 256-pixel-wide 18° pinhole frame: atan(tan(9°) / 128).
    let arcsec = ((9f64.to_radians().tan() / 128.0).atan().to_degrees() * 3600.0).to_string();
    let by_fov = records(&dir, &["--fov-deg", "18"]);
    let by_scale = records(&dir, &["--scale-arcsec", &arcsec]);
    assert_eq!(by_fov.len(), 4);
    assert!(by_fov.iter().all(|r| r["status"] == "solved"), "{by_fov:?}");
    for (a, b) in by_fov.iter().zip(&by_scale) {
        common::assert_records_match(a, b);
    }
    // A range around it searches the scale; the records give the fitted field.
    for r in records(&dir, &["--scale-arcsec", "240..275"]) {
        assert_eq!(r["status"], "solved", "{r}");
        let fov = r["fov_x_deg"].as_f64().unwrap();
        assert!((fov - 18.0).abs() < 0.05, "{r}");
    }
}

#[test]
fn scale_options_that_cannot_go_together_or_are_out_of_range_stop_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    common::simulate_small(&dir, 1);
    let d = dir.to_str().unwrap();
    let camera = dir.join("camera.toml");
    for args in [
        vec!["--scale-arcsec", "250", "--fov-deg", "18"],
        vec![
            "--scale-arcsec",
            "250",
            "--camera",
            camera.to_str().unwrap(),
        ],
        vec!["--scale-arcsec", "0"],
        vec!["--scale-arcsec", "40000"],
        vec!["--scale-arcsec", "3..2"],
        vec!["--scale-arcsec", "x"],
        vec![
            "--pixel-aspect",
            "1.1",
            "--camera",
            camera.to_str().unwrap(),
        ],
    ] {
        let out = gpustar().args(["batch", d]).args(&args).output().unwrap();
        assert_eq!(
            out.status.code(),
            Some(2),
            "{args:?}: {}",
            common::stderr(&out)
        );
        assert!(out.stdout.is_empty(), "{args:?}");
    }
}
