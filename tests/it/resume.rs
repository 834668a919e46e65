//! Exactly once: a batch killed with SIGKILL at random moments and restarted with --resume
//! ends with exactly one complete record per input, equal to an uninterrupted run's; torn last
//! lines are cut off; shards merge back to every input exactly once.

use crate::common;

use common::{gpustar, kill_until_done};
use serde_json::Value;
use std::path::Path;
use std::time::{Duration, Instant};

/// [`common::batch18_args`], quiet.
fn batch_args(dir: &Path, out: &Path) -> Vec<String> {
    let mut args = common::batch18_args(dir, out);
    args.push("-q".into());
    args
}

/// The records of a file, without timings, keyed by file name (panics on duplicates).
fn records(path: &Path) -> Vec<(String, String)> {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(
        text.is_empty() || text.ends_with('\n'),
        "the file ends with a complete line"
    );
    let mut out: Vec<(String, String)> = text
        .lines()
        .map(|l| {
            let mut v: Value = serde_json::from_str(l).expect("every line is a complete record");
            v["timing_ms"] = Value::Null;
            (v["file"].as_str().unwrap().to_string(), v.to_string())
        })
        .collect();
    out.sort();
    let before = out.len();
    out.dedup_by(|a, b| a.0 == b.0);
    assert_eq!(before, out.len(), "no input has two records");
    out
}

#[test]
fn sigkill_at_random_moments_then_resume_gives_every_record_exactly_once() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("frames");
    common::simulate_small(&dir, 600);
    let clean = tmp.path().join("clean.jsonl");
    assert!(
        gpustar()
            .args(batch_args(&dir, &clean))
            .status()
            .unwrap()
            .success()
    );
    let out = tmp.path().join("killed.jsonl");
    let mut args = batch_args(&dir, &out);
    args.push("--resume".into());
    // Kill times between 5 % and 45 % of an uninterrupted run (records are flushed every 64
    // records or 250 ms).
    let kills = kill_until_done(
        || gpustar().args(&args).spawn().unwrap(),
        &out,
        std::fs::metadata(&clean).unwrap().len(),
        (0.05, 0.45),
        0x2545F491,
    );
    println!("{kills} kills before the run finished");
    assert!(
        kills >= 3,
        "the test must really interrupt the run ({kills} kills)"
    );
    let (a, b) = (records(&clean), records(&out));
    assert_eq!(a.len(), 600);
    assert!(a == b, "resumed records differ from an uninterrupted run's");
}

#[test]
fn resume_cuts_a_torn_last_line_and_skips_recorded_inputs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("frames");
    common::simulate_small(&dir, 6);
    let out = tmp.path().join("out.jsonl");
    assert!(
        gpustar()
            .args(batch_args(&dir, &out))
            .status()
            .unwrap()
            .success()
    );
    // Keep two complete records and half of the third, as a crash mid-write would.
    let text = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let torn = format!(
        "{}\n{}\n{}",
        lines[0],
        lines[1],
        &lines[2][..lines[2].len() / 2]
    );
    std::fs::write(&out, torn).unwrap();
    let mut args = batch_args(&dir, &out);
    args.retain(|a| a != "-q");
    args.push("--resume".into());
    let run = gpustar().args(&args).output().unwrap();
    assert!(run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("cut an incomplete last record"), "{stderr}");
    assert!(
        stderr.contains("2 of 6 inputs already have a record"),
        "{stderr}"
    );
    assert_eq!(records(&out).len(), 6);
}

#[test]
fn shards_merge_to_every_input_exactly_once() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("frames");
    common::simulate_small(&dir, 24);
    let mut parts = Vec::new();
    for k in 0..3 {
        let part = tmp.path().join(format!("part-{k}.jsonl"));
        let mut args = batch_args(&dir, &part);
        args.extend(["--shard".to_string(), format!("{k}/3")]);
        assert!(gpustar().args(&args).status().unwrap().success());
        parts.push(part);
    }
    let sizes: Vec<usize> = parts.iter().map(|p| records(p).len()).collect();
    assert_eq!(
        sizes.iter().sum::<usize>(),
        24,
        "shards {sizes:?} split the inputs"
    );
    assert!(
        sizes.iter().all(|&s| s > 0),
        "every shard takes some inputs: {sizes:?}"
    );
    let merged = tmp.path().join("merged.jsonl");
    let m = gpustar()
        .arg("merge")
        .args(&parts)
        .args([
            "--dir",
            dir.to_str().unwrap(),
            "-o",
            merged.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(m.status.success(), "{}", String::from_utf8_lossy(&m.stderr));
    let names: Vec<String> = std::fs::read_to_string(&merged)
        .unwrap()
        .lines()
        .map(|l| {
            serde_json::from_str::<Value>(l).unwrap()["file"]
                .as_str()
                .unwrap()
                .to_string()
        })
        .collect();
    let mut sorted = names.clone();
    sorted.sort();
    assert_eq!(names, sorted, "merged in input order");
    assert_eq!(names.len(), 24);
    // A missing shard is caught.
    let m = gpustar()
        .arg("merge")
        .args(&parts[..2])
        .args([
            "--dir",
            dir.to_str().unwrap(),
            "-o",
            merged.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(m.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&m.stderr).contains("missing"));
    // A shard given twice is caught, even without the directory to check against.
    let m = gpustar()
        .arg("merge")
        .args(&parts)
        .arg(&parts[0])
        .args(["--no-check", "-o", merged.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(m.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&m.stderr).contains("duplicated"));
}

#[test]
fn ctrl_c_stops_cleanly_with_complete_records_and_exit_130() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("frames");
    common::simulate_small(&dir, 400);
    let out = tmp.path().join("out.jsonl");
    let mut child = gpustar().args(batch_args(&dir, &out)).spawn().unwrap();
    // Wait until some records are out, then interrupt as Ctrl-C does.
    let t0 = Instant::now();
    while std::fs::metadata(&out).map(|m| m.len()).unwrap_or(0) == 0 {
        assert!(t0.elapsed() < Duration::from_secs(60), "no record appeared");
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before the interrupt"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let kill = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = child.wait().unwrap();
    let partial = records(&out).len();
    if status.code() == Some(0) {
        // The run was already on its last records when the signal came.
        assert_eq!(partial, 400);
        return;
    }
    assert_eq!(
        status.code(),
        Some(130),
        "an interrupted run exits with 130"
    );
    assert!(
        partial > 0 && partial < 400,
        "{partial} records before the stop"
    );
    // Resuming finishes the rest.
    let mut args = batch_args(&dir, &out);
    args.push("--resume".into());
    assert!(gpustar().args(&args).status().unwrap().success());
    assert_eq!(records(&out).len(), 400);
}
