//! `batch --sequence` through the real binary, on sequences of `simulate --sequence` (a
//! turning camera, 1.5 times as many moving particles as stars, most brighter than the stars):
//! frames solved from the tenth on, particles flagged and never matched, tracking used, GPU =
//! CPU, bad frames inside a sequence, and shards that keep a sequence whole.

use crate::common;

use common::{gpustar, run_records, truths};
use gpustar::solve::attitude::attitude_error;
use nalgebra::Matrix3;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Two sequences of 12 frames, 1 s apart, in `tmp/sim`.
fn simulated(tmp: &Path) -> PathBuf {
    let dir = tmp.join("sim");
    common::simulate(
        &dir,
        &["--sequence", "--sequences", "2", "-n", "12", "--seed", "5"],
    );
    dir
}

fn batch(dir: &Path, camera: &Path, extra: &[&str]) -> Vec<Value> {
    let mut cmd = gpustar();
    cmd.args(["batch", dir.to_str().unwrap(), "-r", "--camera"])
        .arg(camera)
        .args(extra);
    run_records(&mut cmd)
}

fn matrix(v: &Value) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| v[i][j].as_f64().unwrap())
}

fn near(a: &Value, x: f64, y: f64, r: f64) -> bool {
    (a["x"].as_f64().unwrap() - x).hypot(a["y"].as_f64().unwrap() - y) <= r
}

#[test]
fn particles_are_flagged_and_frames_solve_from_the_tenth_on() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = simulated(tmp.path());
    let camera = dir.join("camera.toml");
    let truth = truths(&dir);
    let alone = batch(&dir, &camera, &["--backend", "cpu"]);
    let seq = batch(&dir, &camera, &["--backend", "cpu", "--sequence"]);
    assert_eq!(seq.len(), truth.len());
    let (mut tp, mut reported, mut detectable, mut tracked) = (0, 0, 0, 0);
    for ((r, t), a) in seq.iter().zip(&truth).zip(&alone) {
        assert_eq!(r["file"], t["file"]);
        let correct = |r: &Value| {
            r["status"] == "solved"
                && attitude_error(
                    &matrix(&r["rotation_matrix"]),
                    &matrix(&t["rotation_matrix"]),
                )
                .to_degrees()
                    * 3600.0
                    <= 60.0
        };
        if t["index"].as_u64().unwrap() >= 9 {
            assert!(correct(r), "{}: {r}", t["file"]);
        }
        // Never worse than alone: not wrong where alone is right, no fewer stars.
        if correct(a) {
            assert!(correct(r), "{}", t["file"]);
            assert!(r["stars_matched"].as_u64() >= a["stars_matched"].as_u64());
        }
        tracked += usize::from(r["sequence_mode"] == "tracking");
        let particles = t["particles"].as_array().unwrap();
        let stars = t["stars"].as_array().unwrap();
        for p in r["particles"].as_array().unwrap() {
            reported += 1;
            tp += usize::from(
                particles
                    .iter()
                    .any(|q| near(p, q["x"].as_f64().unwrap(), q["y"].as_f64().unwrap(), 3.0)),
            );
        }
        if t["index"].as_u64().unwrap() >= 9 {
            detectable += particles
                .iter()
                .filter(|q| {
                    let (x, y) = (q["x"].as_f64().unwrap(), q["y"].as_f64().unwrap());
                    x > 3.0 && y > 3.0 && x < 1020.0 && y < 1020.0
                })
                .count();
        }
        // No identified star on a particle (unless a catalog star is there too).
        for m in r["matches"].as_array().into_iter().flatten() {
            let on_particle = particles
                .iter()
                .any(|q| near(m, q["x"].as_f64().unwrap(), q["y"].as_f64().unwrap(), 2.0));
            let on_star = stars
                .iter()
                .any(|s| near(m, s["x"].as_f64().unwrap(), s["y"].as_f64().unwrap(), 2.0));
            assert!(
                !on_particle || on_star,
                "{}: a match on a particle: {m}",
                t["file"]
            );
        }
    }
    let precision = tp as f64 / reported as f64;
    // Recall over the frames from the tenth on, where the test has had its frames.
    let recalled: usize =
        seq.iter()
            .zip(&truth)
            .filter(|(_, t)| t["index"].as_u64().unwrap() >= 9)
            .map(|(r, t)| {
                let particles = t["particles"].as_array().unwrap();
                particles
                    .iter()
                    .filter(|q| {
                        let (x, y) = (q["x"].as_f64().unwrap(), q["y"].as_f64().unwrap());
                        x > 3.0 && y > 3.0 && x < 1020.0 && y < 1020.0
                    })
                    .filter(|q| {
                        r["particles"].as_array().unwrap().iter().any(|p| {
                            near(p, q["x"].as_f64().unwrap(), q["y"].as_f64().unwrap(), 3.0)
                        })
                    })
                    .count()
            })
            .sum();
    let recall = recalled as f64 / detectable as f64;
    assert!(
        precision >= 0.95 && recall >= 0.9,
        "precision {precision}, recall {recall}"
    );
    assert!(
        tracked >= seq.len() - 6,
        "{tracked} of {} tracked",
        seq.len()
    );
    // Alone, the particles outvote the stars on many frames.
    let solved_alone = alone.iter().filter(|r| r["status"] == "solved").count();
    let solved = seq.iter().filter(|r| r["status"] == "solved").count();
    assert!(
        solved_alone + 6 <= solved,
        "{solved_alone} solved alone, {solved} in sequence"
    );
    println!(
        "sequence: precision {precision:.3}, recall {recall:.3}, {tracked} of {} tracked, \
         {solved_alone} solved alone",
        seq.len()
    );
}

#[test]
fn gpu_records_equal_cpu_records() {
    let Some(_) = common::gpu("gpu_records_equal_cpu_records") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let dir = simulated(tmp.path());
    let camera = dir.join("camera.toml");
    let cpu = batch(&dir, &camera, &["--backend", "cpu", "--sequence"]);
    let gpu = batch(&dir, &camera, &["--backend", "gpu", "--sequence"]);
    let strip = |mut r: Value| {
        r.as_object_mut().unwrap().remove("timing_ms");
        r.as_object_mut().unwrap().remove("backend");
        r
    };
    for (c, g) in cpu.into_iter().zip(gpu) {
        assert_ne!(g["backend"], "cpu");
        common::assert_records_match(&strip(g), &strip(c));
    }
}

/// A corrupt frame, a frame repeating the previous one's time, and one out of time order:
/// each gets its record (the two misplaced ones solved on their own), and the sequence goes on
/// past them: the frames after them are solved.
#[test]
fn bad_frames_inside_a_sequence() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = simulated(tmp.path());
    let camera = dir.join("camera.toml");
    let seq = dir.join("seq_000");
    std::fs::write(seq.join("frame_004b.fits"), b"SIMPLE  =  garbage").unwrap();
    // frame_007 again after frame_007: the same time.
    std::fs::copy(seq.join("frame_007.fits"), seq.join("frame_007b.fits")).unwrap();
    // frame_002 again after frame_010: a time before the previous frame's.
    std::fs::copy(seq.join("frame_002.fits"), seq.join("frame_010b.fits")).unwrap();
    let mut cmd = gpustar();
    cmd.args(["batch", seq.to_str().unwrap(), "--camera"])
        .arg(&camera)
        .args(["--backend", "cpu", "--sequence"]);
    let out = cmd.output().unwrap();
    // The corrupt frame's error record makes the exit code 1; every file has its record.
    assert_eq!(out.status.code(), Some(1));
    let recs: Vec<Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(recs.len(), 15);
    let by_name = |n: &str| recs.iter().find(|r| r["file"] == n).unwrap();
    assert_eq!(by_name("frame_004b.fits")["status"], "error");
    for n in ["frame_007b.fits", "frame_010b.fits"] {
        let r = by_name(n);
        let w = r["warnings"].to_string();
        assert!(w.contains("solved on its own"), "{n}: {r}");
        assert_eq!(r["sequence_mode"], "lost_in_space");
    }
    let misplaced = ["frame_004b.fits", "frame_007b.fits", "frame_010b.fits"];
    for r in &recs {
        let name = r["file"].as_str().unwrap();
        if !misplaced.contains(&name) && name > "frame_003.fits" {
            assert_eq!(r["status"], "solved", "{r}");
            assert_eq!(r["sequence_mode"], "tracking", "{r}");
        }
    }
}

#[test]
fn shards_keep_a_sequence_whole() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("seqs");
    for s in 0..6 {
        let d = dir.join(format!("head_{s}"));
        std::fs::create_dir_all(&d).unwrap();
        for k in 0..3 {
            // Not images gpustar can read: each gets an error record, which is all a shard
            // test needs.
            std::fs::write(d.join(format!("f{k}.png")), b"not a png").unwrap();
        }
    }
    let mut seen: Vec<(String, usize)> = Vec::new();
    for k in 0..2 {
        let out = gpustar()
            .args([
                "batch",
                dir.to_str().unwrap(),
                "-r",
                "--fov-deg",
                "18",
                "--sequence",
            ])
            .args(["--backend", "cpu", "--shard", &format!("{k}/2")])
            .output()
            .unwrap();
        for l in String::from_utf8(out.stdout).unwrap().lines() {
            let r: Value = serde_json::from_str(l).unwrap();
            let name = r["file"].as_str().unwrap();
            seen.push((name.split('/').next().unwrap().to_string(), k));
        }
    }
    assert_eq!(seen.len(), 18);
    for (head, shard) in &seen {
        assert!(
            seen.iter().all(|(h, s)| h != head || s == shard),
            "{head} split"
        );
    }
}

/// swarm-a's real frames as sequences (one directory per satellite, head and day; 600 s
/// apart, the attitude turning 25–39° between frames): frames from each series' third on are
/// tracked at the rate of the last two solutions, and every frame is solved within 100″ of
/// the truth across the line of sight (Swarm's pixels are 89″ × 171″; lost-in-space's median
/// there is 15″) and within a pixel at the frame's ends in roll (1/376 rad = 549″: the
/// truths' roll, astrometry.net's TAN-SIP on a 752×290 frame, differs from gpustar's k1 fit by
/// up to 260″ with centres of gravity and 318″ with PSF fits on frame _152, and Swarm's own
/// solution is 261″ from it there).
#[test]
fn swarm_a_series_are_tracked() {
    let Some(shared) = common::shared_dir("swarm_a_series_are_tracked") else {
        return;
    };
    let real = shared.join("data/real/swarm-a");
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("swarm");
    for e in std::fs::read_dir(&real).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        if !name.ends_with(".png") {
            continue;
        }
        // SWA_StrA_2014-10-21T10h30m10.000Z_151.png → SWA_StrA_2014-10-21
        let series = dir.join(name.split('T').next().unwrap());
        std::fs::create_dir_all(&series).unwrap();
        std::fs::copy(&p, series.join(&name)).unwrap();
    }
    let camera =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/cameras/swarm-a.toml");
    let opts = [
        "--epoch",
        "2014.85",
        "--fov-tolerance",
        "0.01",
        "--fit",
        "distortion",
    ];
    let mut base = vec!["--backend", "cpu"];
    base.extend(opts);
    let alone = batch(&dir, &camera, &base);
    base.extend(["--sequence", "--frame-interval", "600"]);
    let seq = batch(&dir, &camera, &base);
    let truth: Vec<Value> = std::fs::read_to_string(real.join("truth.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let mut tracked = 0;
    for (r, a) in seq.iter().zip(&alone) {
        assert_eq!(r["file"], a["file"]);
        assert_eq!(r["status"], "solved", "{r}");
        let name = r["file"].as_str().unwrap().rsplit('/').next().unwrap();
        let t = truth.iter().find(|t| t["file"] == name).unwrap();
        // The error rotation's axis in the camera frame: z is the line of sight.
        let d = matrix(&r["rotation_matrix"]) * matrix(&t["rotation_matrix"]).transpose();
        let arcsec = |v: f64| (v / 2.0).asin().to_degrees() * 3600.0;
        let across = arcsec((d[(2, 1)] - d[(1, 2)]).hypot(d[(0, 2)] - d[(2, 0)]));
        let roll = arcsec(d[(1, 0)] - d[(0, 1)]).abs();
        let edge = (1.0f64 / 376.0).to_degrees() * 3600.0;
        assert!(
            across < 100.0 && roll < edge,
            "{name}: {across}″ across the line of sight, {roll}″ in roll from the truth"
        );
        if r["sequence_mode"] == "tracking" {
            tracked += 1;
            // No fewer stars than alone.
            assert!(
                r["stars_matched"].as_u64() >= a["stars_matched"].as_u64(),
                "{r}"
            );
        }
    }
    assert!(tracked >= 14, "{tracked} of {} frames tracked", seq.len());
    println!("swarm-a: {tracked} of {} frames tracked", seq.len());
}
