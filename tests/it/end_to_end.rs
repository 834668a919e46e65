//! The whole pipeline through the real binary on simulated frames: simulate → batch → evaluate.

use crate::common;

use common::{gpustar, run_ok};
use serde_json::Value;
use std::path::Path;

fn evaluate(dir: &Path, results: &Path) -> Value {
    let out = run_ok(&[
        "evaluate",
        "--truth",
        dir.join("truth.jsonl").to_str().unwrap(),
        results.to_str().unwrap(),
    ]);
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Simulate `frames` frames into `tmp/sim` and solve them on the CPU (catalog to Hp 6):
/// the frames' directory and the records' file.
fn simulate_and_batch(
    tmp: &Path,
    extra: &[&str],
    frames: usize,
) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = tmp.join("sim");
    let n = frames.to_string();
    let mut args = vec!["simulate", "--out", dir.to_str().unwrap(), "-n", &n];
    args.extend_from_slice(extra);
    run_ok(&args);
    let results = tmp.join("results.jsonl");
    run_ok(&[
        "batch",
        "--backend",
        "cpu",
        dir.to_str().unwrap(),
        "--camera",
        dir.join("camera.toml").to_str().unwrap(),
        "--mag-limit",
        "6",
        "-o",
        results.to_str().unwrap(),
    ]);
    let text = std::fs::read_to_string(&results).unwrap();
    assert_eq!(text.lines().count(), frames, "one record per frame");
    (dir, results)
}

fn simulate_and_solve(extra: &[&str], frames: usize) -> Value {
    let tmp = tempfile::tempdir().unwrap();
    let (dir, results) = simulate_and_batch(tmp.path(), extra, frames);
    evaluate(&dir, &results)
}

#[test]
fn simulated_18_degree_frames_are_all_solved_correctly() {
    let s = simulate_and_solve(&["--fov-deg", "18", "--seed", "7"], 6);
    println!("{s}");
    assert_eq!(s["correct"], 6, "{s}");
    assert_eq!(s["wrong"], 0);
    assert_eq!(s["false_ids"], 0);
    assert!(s["median_error_arcsec"].as_f64().unwrap() < 10.0, "{s}");
}

#[test]
fn simulated_16_bit_10_degree_frames_have_no_wrong_solution() {
    let s = simulate_and_solve(
        &[
            "--fov-deg",
            "10",
            "--bits",
            "16",
            "--seed",
            "3",
            "--size",
            "800x600",
        ],
        4,
    );
    println!("{s}");
    assert_eq!(s["wrong"], 0, "{s}");
    assert_eq!(s["false_ids"], 0, "{s}");
    // A 10° field can hold too few stars; most frames solve.
    assert!(s["correct"].as_u64().unwrap() >= 3, "{s}");
}

#[test]
fn every_image_gets_one_record_in_sorted_order_and_bad_files_are_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    run_ok(&[
        "simulate",
        "--out",
        dir.to_str().unwrap(),
        "-n",
        "2",
        "--size",
        "512x512",
    ]);
    std::fs::write(dir.join("a_text.png"), "not an image").unwrap();
    std::fs::write(dir.join("notes.txt"), "ignored: not an image type").unwrap();
    let out = gpustar()
        .args([
            "batch",
            dir.to_str().unwrap(),
            "--fov-deg",
            "18",
            "--mag-limit",
            "6",
            "--backend",
            "cpu",
        ])
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(1),
        "an error record makes the exit status 1"
    );
    let records: Vec<Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let files: Vec<&str> = records
        .iter()
        .map(|r| r["file"].as_str().unwrap())
        .collect();
    assert_eq!(files, ["a_text.png", "sim_00000.png", "sim_00001.png"]);
    assert_eq!(records[0]["status"], "error");
    assert!(records[0]["error"].as_str().unwrap().contains("a_text.png"));
    for r in &records[1..] {
        assert_eq!(r["status"], "solved", "{r}");
        assert_eq!(r["backend"], "cpu");
    }
    // A camera file of another size is an error record, not a guess.
    let cam = dir.join("other.toml");
    std::fs::write(&cam, "width = 640\nheight = 480\nfov_x_deg = 18\n").unwrap();
    let out = gpustar()
        .args([
            "solve",
            dir.join("sim_00000.png").to_str().unwrap(),
            "--camera",
            cam.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let r: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["status"], "error");
    assert!(r["error"].as_str().unwrap().contains("512x512"), "{r}");
}

#[test]
fn a_starless_frame_is_unsolved_with_a_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("dark.png");
    image::GrayImage::from_fn(256, 256, |x, y| {
        image::Luma([10 + ((x * 7 + y * 13) % 3) as u8])
    })
    .save(&path)
    .unwrap();
    // `solve` says unsolved in its exit status too (4); `batch` keeps 0 for unsolved frames.
    let out = gpustar()
        .args(["solve", path.to_str().unwrap(), "--fov-deg", "10"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(4), "{}", common::stderr(&out));
    let r: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["status"], "unsolved");
    assert_eq!(r["reason"], "too_few_stars");
    let out = run_ok(&["batch", tmp.path().to_str().unwrap(), "--fov-deg", "10"]);
    let r: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["status"], "unsolved");
}

/// Off a terminal (a Slurm log, a pipe) a long run prints a progress line every
/// `--progress-every` seconds, where a terminal shows the bar; `-q` and 0 print none.
#[test]
fn a_run_logged_to_a_file_says_its_progress_in_lines() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    common::simulate_small(&dir, 12);
    let run = |extra: &[&str]| {
        let mut c = gpustar();
        c.args(["batch", dir.to_str().unwrap(), "--fov-deg", "18", "-j", "1"])
            .args(extra);
        let out = c.output().unwrap();
        assert!(out.status.success(), "{}", common::stderr(&out));
        common::stderr(&out)
    };
    let lines = |e: &str| e.lines().filter(|l| l.contains(" files (")).count();
    let every = run(&["--progress-every", "0.000001"]);
    // Every input but the last (the summary says that one) gets a line.
    assert_eq!(lines(&every), 11, "{every}");
    let first = every.lines().find(|l| l.contains(" files (")).unwrap();
    assert!(
        first.starts_with("gpustar: 1/12 files (8 %): ") && first.contains("images/s"),
        "{first}"
    );
    assert_eq!(lines(&run(&["--progress-every", "0"])), 0);
    assert_eq!(lines(&run(&["--progress-every", "0.000001", "-q"])), 0);
    // The default, 10 s, says nothing in a run this short.
    assert_eq!(lines(&run(&[])), 0);
}

/// `gpustar info | head`, `gpustar evaluate ... | head`: a reader that closes the pipe before
/// the output comes ends the command quietly (exit 0), not with a broken-pipe panic (101).
#[test]
fn a_reader_that_stops_early_ends_info_and_evaluate_quietly() {
    let tmp = tempfile::tempdir().unwrap();
    let (dir, results) = simulate_and_batch(tmp.path(), &[], 2);
    let truth = dir.join("truth.jsonl");
    let evaluate = [
        "evaluate",
        "--per-frame",
        "--truth",
        truth.to_str().unwrap(),
        results.to_str().unwrap(),
    ];
    for args in [&["info"][..], &evaluate[..]] {
        let mut child = gpustar()
            .args(args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        assert!(
            out.status.success(),
            "gpustar {args:?}: {:?} {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// `--format csv` carries what the JSON record says (issue 47): numbers as JSON writes them,
/// so a false-match probability of 1e-100 is `1e-100`, not a hundred zeros, and reads back to
/// the same value; the epoch, the attitude's 1σ and the parity are columns.
#[test]
fn csv_rows_carry_the_json_records_numbers() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    common::simulate_small(&dir, 3);
    let run = |format: &str| {
        let out = run_ok(&[
            "batch",
            dir.to_str().unwrap(),
            "--fov-deg",
            "18",
            "--format",
            format,
            "-q",
        ]);
        String::from_utf8(out.stdout).unwrap()
    };
    // serde_json's reader rounds some numbers one unit in the last place off (without its
    // float_roundtrip feature): compared to that, not to the bit.
    let same = |a: f64, b: f64| (a - b).abs() <= 2.0 * f64::EPSILON * a.abs().max(b.abs());
    let json: Vec<Value> = run("jsonl")
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let csv = run("csv");
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    assert_eq!(rows.len(), json.len());
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    for (row, r) in rows.iter().zip(&json) {
        assert_eq!(row.len(), header.len(), "{row:?}");
        assert_eq!(r["status"], "solved", "{r}");
        let p = &row[col("false_match_prob")];
        assert!(p.contains('e') && p.len() < 30, "{p}");
        assert!(
            same(p.parse().unwrap(), r["false_match_prob"].as_f64().unwrap()),
            "{p}"
        );
        for (name, value) in [
            ("epoch", &r["epoch"]),
            (
                "sigma_boresight_arcsec",
                &r["attitude_sigma_arcsec"]["boresight"],
            ),
            ("sigma_roll_arcsec", &r["attitude_sigma_arcsec"]["roll"]),
            ("ra_deg", &r["ra_deg"]),
        ] {
            let v = row[col(name)].parse::<f64>().unwrap();
            assert!(same(v, value.as_f64().unwrap()), "{name}: {v} {value}");
        }
        assert_eq!(row[col("mirrored")], r["mirrored"].to_string());
    }
}
