//! Non-square pixels with `--fov-deg`: frames of a camera whose pixels are 0.8 times as tall as
//! wide solve with `--pixel-aspect 4/5`; taken as square they do not solve right.

use crate::common;

fn correct(truth: &std::path::Path, records: &std::path::Path) -> u64 {
    let out = common::run_ok(&[
        "evaluate",
        "--truth",
        truth.to_str().unwrap(),
        records.to_str().unwrap(),
    ]);
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    summary["correct"].as_u64().unwrap()
}

#[test]
fn non_square_pixels_solve_with_their_aspect() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("frames");
    // 1024 × 768, 15° wide: fx = 512 / tan(7.5°); the pixels 0.8 as tall: fy = fx / 0.8.
    let fx = 512.0 / 7.5f64.to_radians().tan();
    let cam = tmp.path().join("cam.toml");
    std::fs::write(
        &cam,
        format!(
            "width = 1024\nheight = 768\nfx_px = {fx}\nfy_px = {}\n",
            fx / 0.8
        ),
    )
    .unwrap();
    common::simulate(
        &dir,
        &[
            "--camera",
            cam.to_str().unwrap(),
            "-n",
            "4",
            "--seed",
            "9",
            "--mag-limit",
            "7",
        ],
    );
    let truth = dir.join("truth.jsonl");
    let run = |extra: &[&str], name: &str| {
        let out = tmp.path().join(name);
        let args = [
            &[
                "batch",
                dir.to_str().unwrap(),
                "--fov-deg",
                "15",
                "--backend",
                "cpu",
                "-q",
                "-o",
                out.to_str().unwrap(),
            ][..],
            extra,
        ]
        .concat();
        let _ = common::gpustar().args(&args).output().unwrap();
        correct(&truth, &out)
    };
    let with_aspect = run(&["--pixel-aspect", "4/5"], "aspect.jsonl");
    let square = run(&[], "square.jsonl");
    println!("correct: {with_aspect} of 4 with --pixel-aspect 4/5, {square} taken as square");
    assert_eq!(with_aspect, 4);
    assert!(square < 4, "{square} of 4 right with square pixels");
}

#[test]
fn pixel_aspect_needs_a_field_of_view_and_a_sane_value() {
    for args in [
        &["solve", "x.png", "--pixel-aspect", "0.9"][..],
        &["solve", "x.png", "--fov-deg", "10", "--pixel-aspect", "3"],
        &["solve", "x.png", "--fov-deg", "10", "--pixel-aspect", "1/0"],
        &["solve", "x.png", "--fov-deg", "10", "--pixel-aspect", "a/b"],
    ] {
        let out = common::gpustar().args(args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("pixel"),
            "{args:?}"
        );
    }
}
