//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod formats;

use std::path::{Path, PathBuf};

/// `../shared` beside the project (real frames, Hipparcos-2), if present. A user's clone has
/// none: the caller's test is then skipped with a printed reason. In CI (`CI=true`) a missing
/// `../shared` fails the test instead, so CI never skips these checks silently.
pub fn shared_dir(test: &str) -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared");
    if dir.join("data/real").is_dir() {
        return Some(dir);
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{test}: ../shared is missing, and CI must run this test");
    }
    eprintln!("SKIPPED {test}: ../shared (real frames and hip2.dat) is not beside the project");
    None
}

/// The gpustar binary under test.
pub fn gpustar() -> std::process::Command {
    let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_gpustar"));
    // Keep table caches out of the user's home: `cargo test` sets the clone's own
    // (.cargo/config.toml), which the in-process tests use too; the test binary run by hand
    // falls back to the temp directory.
    if std::env::var_os("GPUSTAR_CACHE_DIR").is_none_or(|d| d.is_empty()) {
        c.env(
            "GPUSTAR_CACHE_DIR",
            std::env::temp_dir().join("gpustar-test-cache"),
        );
    }
    c
}

/// Run a gpustar command that must succeed; its records (JSON Lines on stdout).
pub fn run_records(cmd: &mut std::process::Command) -> Vec<serde_json::Value> {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// The GPU (lavapipe in CI), or None with a printed reason. In CI (`CI=true`) a missing
/// adapter fails the test instead: GPU = CPU must be checked there.
pub fn gpu(test: &str) -> Option<gpustar::gpu::Gpu> {
    match gpustar::gpu::Gpu::new(std::env::var("GPUSTAR_ADAPTER").ok().as_deref()) {
        Ok(g) => Some(g),
        Err(e) => {
            if std::env::var("CI").is_ok_and(|v| v == "true") {
                panic!("{test}: no GPU adapter in CI: {e:#}");
            }
            eprintln!("SKIPPED {test}: {e:#}");
            None
        }
    }
}

/// Frames from the simulator (in memory), 8- or 16-bit.
pub fn sim_frames(
    n: usize,
    size: (u32, u32),
    fov: f64,
    bits: u8,
    seed: u64,
) -> Vec<gpustar::io::frame::Frame<'static>> {
    let s = gpustar::simulate::SimSettings {
        width: size.0,
        height: size.1,
        fov_x_deg: fov,
        bits,
        seed,
        ..Default::default()
    };
    rendered(&s, n).into_iter().map(|(f, _)| f).collect()
}

/// The CPU twins' outputs of every detection stage, dense as the GPU writes them.
pub struct CpuDetect {
    pub tiles: Vec<gpustar::cpu::threshold::TileStats>,
    pub mask: Vec<u32>,
    pub labels: Vec<u32>,
    pub blobs: Vec<gpustar::cpu::centroid::Blob>,
}

pub fn cpu_detect(
    f: &gpustar::io::frame::Frame,
    p: &gpustar::cpu::threshold::DetectParams,
) -> CpuDetect {
    use gpustar::cpu::*;
    let tiles = tile_clip::clipped_tile_stats(&f.pixels, p);
    let runs = threshold::threshold(&f.pixels, &tiles, p);
    let labels = components::components(&runs, p.width);
    CpuDetect {
        blobs: centroid::centroid(&f.pixels, &runs, &labels, &tiles, p),
        mask: threshold::dense_mask(&runs, p.width, p.height),
        labels: components::dense_labels(&runs, &labels, p.width, p.height),
        tiles,
    }
}

/// Run the detection kernels on the GPU and check every stage against its CPU twin: tile
/// statistics, mask, labels and blobs must be equal exactly. Returns the blobs compared.
pub fn assert_detect_stages_equal(
    g: &gpustar::gpu::Gpu,
    frames: &[gpustar::io::frame::Frame],
    tile: u32,
) -> usize {
    assert_detect_stages_equal_with(g, frames, tile, gpustar::cpu::threshold::FILTER_NONE)
}

/// As [`assert_detect_stages_equal`], with the matched filter at `gain`
/// (`cpu::threshold::FILTER_NONE`: off; `WHITE_GAIN` for white noise).
pub fn assert_detect_stages_equal_with(
    g: &gpustar::gpu::Gpu,
    frames: &[gpustar::io::frame::Frame],
    tile: u32,
    gain: u32,
) -> usize {
    let f0 = &frames[0];
    let p = gpustar::cpu::threshold::DetectParams::new(
        f0.width,
        f0.height,
        tile,
        5.0,
        f0.saturation as u32,
    )
    .with_filter_gain(gain);
    let refs: Vec<&gpustar::io::frame::Frame> = frames.iter().collect();
    let (blobs, ins) = g.detect_inspect(&refs, &p).unwrap();
    let mut n = 0;
    for (k, f) in frames.iter().enumerate() {
        let c = cpu_detect(f, &p);
        assert!(
            c.tiles == ins.tiles[k],
            "frame {k}: tile_stats → tile_clip differ"
        );
        assert!(c.mask == ins.mask[k], "frame {k}: threshold masks differ");
        assert!(
            c.labels == ins.labels[k],
            "frame {k}: component labels differ"
        );
        assert!(c.blobs == blobs[k], "frame {k}: centroid moments differ");
        n += c.blobs.len();
    }
    n
}

/// A 64×48 frame with '#' drawn as bright pixels (200) on a dark sky (10) from the top left.
pub fn drawn(rows: &[&str]) -> gpustar::io::frame::Frame<'static> {
    let (w, h) = (64u32, 48u32);
    let mut pixels = vec![10u16; (w * h) as usize];
    for (y, r) in rows.iter().enumerate() {
        for (x, c) in r.bytes().enumerate() {
            if c == b'#' {
                pixels[y * w as usize + x] = 200;
            }
        }
    }
    gpustar::io::frame::Frame {
        width: w,
        height: h,
        pixels: pixels.into(),
        saturation: 255,
    }
}

/// Frames 0..n of a simulation, decoded as batch would see them, with their truth.
pub fn rendered(
    s: &gpustar::simulate::SimSettings,
    n: usize,
) -> Vec<(gpustar::io::frame::Frame<'static>, gpustar::simulate::Truth)> {
    let cat = gpustar::catalog::Catalog::builtin();
    let camera = s.camera().unwrap();
    (0..n)
        .map(|k| {
            let (pixels, truth) = gpustar::simulate::render(&cat, s, k).unwrap();
            let frame = gpustar::io::frame::Frame {
                width: camera.width,
                height: camera.height,
                pixels: pixels.into(),
                saturation: if s.bits == 8 { 255 } else { 65535 },
            };
            (frame, truth)
        })
        .collect()
}

/// A solver for a pinhole camera with catalog stars to magnitude 6 (no table cache).
pub fn solver(fov: f64, size: (u32, u32)) -> gpustar::solve::Solver {
    let s = gpustar::solve::Settings {
        mag_limit: Some(6.0),
        table_cache: false,
        ..gpustar::solve::Settings::default()
    };
    let camera = gpustar::camera::Camera::from_fov(size.0, size.1, fov).unwrap();
    gpustar::solve::Solver::new(&gpustar::catalog::Catalog::builtin(), camera, s).unwrap()
}

/// Vote and select on the GPU and check the counters and candidate lists against the CPU.
pub fn assert_votes_equal(
    g: &gpustar::gpu::Gpu,
    solver: &gpustar::solve::Solver,
    jobs: &[gpustar::gpu::vote::VoteJob],
) {
    let band = &solver.bands[0];
    let n_ref = band.refs.len();
    let table = g.upload_table(band.table(), n_ref).unwrap();
    let (results, votes) = g.vote_inspect(band.table(), &table, jobs).unwrap();
    for (f, job) in jobs.iter().enumerate() {
        let (cpu_votes, hyp) =
            gpustar::cpu::vote::vote(band.table(), &job.ranges, job.stars, n_ref);
        assert!(cpu_votes == votes[f], "job {f}: vote counters differ");
        let cpu =
            gpustar::solve::identify::vote_cpu(band.table(), &job.ranges, job.stars, n_ref, job.k);
        assert_eq!(results[f].hypotheses, hyp, "job {f}: hypotheses");
        assert_eq!(results[f].k, cpu.k);
        assert!(
            results[f].candidates == cpu.candidates,
            "job {f}: candidates differ"
        );
    }
}

/// Paint `n` bright round spots (σ 1.2 px) into the top-right quarter of an 8-bit frame: a
/// cluster brighter than most stars.
pub fn crowd_corner(frame: &mut gpustar::io::frame::Frame, n: usize, seed: u64) {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (w, h) = (frame.width as f64, frame.height as f64);
    for _ in 0..n {
        let cx = w / 2.0 + rng.random::<f64>() * w / 2.0;
        let cy = rng.random::<f64>() * h / 2.0;
        let peak = 120.0 + 120.0 * rng.random::<f64>();
        for y in (cy as i64 - 5).max(0)..(cy as i64 + 6).min(h as i64) {
            for x in (cx as i64 - 5).max(0)..(cx as i64 + 6).min(w as i64) {
                let r2 = (x as f64 - cx).powi(2) + (y as f64 - cy).powi(2);
                let p = &mut frame.pixels.to_mut()[(y * w as i64 + x) as usize];
                *p = (*p as f64 + peak * (-r2 / (2.0 * 1.44)).exp()).min(255.0) as u16;
            }
        }
    }
}

/// (solved, wrong) over simulated frames: wrong = solved with an attitude more than
/// `wrong_deg` from the truth.
pub fn solved_and_wrong(
    solver: &gpustar::solve::Solver,
    set: &[(gpustar::io::frame::Frame<'_>, gpustar::simulate::Truth)],
    wrong_deg: f64,
) -> (usize, usize) {
    let (mut solved, mut wrong) = (0, 0);
    for (f, t) in set {
        if let gpustar::solve::Outcome::Solved(r, _) = solver.solve_frame(f).0.outcome {
            solved += 1;
            let truth = nalgebra::Matrix3::from_fn(|i, j| t.rotation_matrix[i][j]);
            if gpustar::solve::attitude::attitude_error(&r.r, &truth).to_degrees() > wrong_deg {
                wrong += 1;
            }
        }
    }
    (solved, wrong)
}

/// What a retry adds on a set of `n` frames, given (solved, wrong) with it and without it:
/// no wrong answer either way, at least `min_with` solved with it, at least 3 more than without.
pub fn assert_retry_adds(
    case: &str,
    retry: &str,
    n: usize,
    min_with: usize,
    (with, wrong_with): (usize, usize),
    (without, wrong_without): (usize, usize),
) {
    println!("{case}, {n} frames: {with} solved with {retry}, {without} without");
    assert_eq!((wrong_with, wrong_without), (0, 0));
    assert!(with >= min_with, "{with}/{n} solved with {retry}");
    assert!(
        with >= without + 3,
        "{without}/{n} solved without it: {retry} adds little"
    );
}

/// GPU = CPU for records: everything equal but the floats that carry the PSF fit's f32
/// (`--centroid ml`, the default): centroids within 1e-5 px (tests/it/psf_fit.rs measures 4.5e-7),
/// RA/Dec/roll within 1e-6° (0.004″), rotation matrix and quaternion elements within 1e-8
/// (0.002″), other floats within 1e-4 relative, plus 1e-5 px or 1e-4″ for pixel and arcsec
/// values (residuals, rms, 1σ, the floor move with the centroids: a 0.02″ residual by 2e-6″).
/// Integers, strings and the shapes of lists exactly.
pub fn assert_records_match(a: &serde_json::Value, b: &serde_json::Value) {
    fn walk(path: &str, key: &str, a: &serde_json::Value, b: &serde_json::Value) {
        use serde_json::Value;
        match (a, b) {
            (Value::Object(x), Value::Object(y)) => {
                let keys = |m: &serde_json::Map<String, Value>| -> Vec<String> {
                    m.keys().cloned().collect()
                };
                assert_eq!(keys(x), keys(y), "{path}: fields");
                for (k, v) in x {
                    walk(&format!("{path}.{k}"), k, v, &y[k]);
                }
            }
            (Value::Array(x), Value::Array(y)) => {
                assert_eq!(x.len(), y.len(), "{path}: length");
                for (i, (u, v)) in x.iter().zip(y).enumerate() {
                    walk(&format!("{path}[{i}]"), key, u, v);
                }
            }
            (Value::Number(x), Value::Number(y)) if x.is_f64() || y.is_f64() => {
                let (u, v) = (x.as_f64().unwrap(), y.as_f64().unwrap());
                let rel = 1e-4 * u.abs().max(v.abs());
                let tol = match key {
                    "x" | "y" => 1e-5,
                    "ra_deg" | "dec_deg" | "roll_deg" => 1e-6,
                    "rotation_matrix" | "quaternion" => 1e-8,
                    k if k.ends_with("_px") => rel + 1e-5,
                    k if k.ends_with("_arcsec") || k == "boresight" || k == "roll" => rel + 1e-4,
                    _ => rel + 1e-12,
                };
                assert!(
                    (u - v).abs() <= tol,
                    "{path}: {u} vs {v} (tolerance {tol:e})"
                );
            }
            _ => assert_eq!(a, b, "{path}"),
        }
    }
    walk("record", "", a, b);
}

/// `batch DIR` of 18° frames (catalog to magnitude 6) on the CPU into `out`: the arguments.
pub fn batch18_args(dir: &std::path::Path, out: &std::path::Path) -> Vec<String> {
    let (dir, out) = (dir.to_str().unwrap(), out.to_str().unwrap());
    [
        "batch",
        dir,
        "--fov-deg",
        "18",
        "--mag-limit",
        "6",
        "--backend",
        "cpu",
        "-o",
        out,
    ]
    .map(String::from)
    .to_vec()
}

/// `gpustar ARGS…`, which must succeed; its output.
pub fn run_ok(args: &[&str]) -> std::process::Output {
    let out = gpustar().args(args).output().unwrap();
    assert!(
        out.status.success(),
        "gpustar {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `n` 512² frames of 12° with streaks (`simulate --streaks`, stars to 7.5), in `tmp/sim`.
pub fn simulated_streaks(tmp: &Path, n: usize) -> PathBuf {
    let dir = tmp.join("sim");
    let n = n.to_string();
    run_ok(&[
        "simulate",
        "--streaks",
        "--out",
        dir.to_str().unwrap(),
        "-n",
        &n,
        "--size",
        "512x512",
        "--fov-deg",
        "12",
        "--mag-limit",
        "7.5",
    ]);
    dir
}

/// `gpustar simulate --out DIR ARGS…`, which must succeed.
pub fn simulate(dir: &std::path::Path, args: &[&str]) {
    run_ok(&[&["simulate", "--out", dir.to_str().unwrap()], args].concat());
}

/// The truth records a simulation wrote in `dir`.
pub fn truths(dir: &std::path::Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(dir.join("truth.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// `n` simulated 256² frames of 18° (fast to solve) in `dir`.
pub fn simulate_small(dir: &std::path::Path, n: usize) {
    let n = n.to_string();
    simulate(
        dir,
        &[
            "-n",
            &n,
            "--fov-deg",
            "18",
            "--size",
            "256x256",
            "--seed",
            "9",
        ],
    );
}

/// Start runs with `spawn` and SIGKILL each at a pseudo-random moment, until one finishes by
/// itself (it must succeed); returns how many were killed. A run is killed once its output
/// `out` has grown by a share between `from` and `to` of what is left to write (`full_bytes`
/// is an uninterrupted run's size), then 0–50 ms later, so that kills fall anywhere between
/// flushes and every attempt makes progress whatever the machine's speed or load. `seed`
/// fixes the shares and delays.
pub fn kill_until_done(
    mut spawn: impl FnMut() -> std::process::Child,
    out: &std::path::Path,
    full_bytes: u64,
    (from, to): (f64, f64),
    mut seed: u32,
) -> usize {
    use std::time::{Duration, Instant};
    let size = || std::fs::metadata(out).map_or(0, |m| m.len());
    let t0 = Instant::now();
    let mut kills = 0;
    loop {
        assert!(
            t0.elapsed() < Duration::from_secs(300) && kills < 100,
            "the run never finished ({kills} kills)"
        );
        let mut next = || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            f64::from(seed >> 8) / f64::from(1u32 << 24)
        };
        let (share, delay) = (from + (to - from) * next(), 0.05 * next());
        let start_size = size();
        let target = start_size + (share * full_bytes.saturating_sub(start_size) as f64) as u64;
        let mut child = spawn();
        let mut reached: Option<Instant> = None;
        loop {
            if let Some(status) = child.try_wait().unwrap() {
                assert!(status.success(), "a resumed run failed: {status}");
                return kills;
            }
            if reached.is_none() && size() > target.max(start_size) {
                reached = Some(Instant::now());
            }
            if reached.is_some_and(|r| r.elapsed().as_secs_f64() >= delay) {
                child.kill().unwrap(); // SIGKILL
                child.wait().unwrap();
                kills += 1;
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

/// Run with a time limit: a hang (a FIFO or a device at a path once hung a run) fails the
/// test instead of stalling CI.
pub fn run_within(mut c: std::process::Command, limit_s: u64) -> std::process::Output {
    use std::process::Stdio;
    let child = c
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let id = child.id();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || tx.send(child.wait_with_output().unwrap()));
    match rx.recv_timeout(std::time::Duration::from_secs(limit_s)) {
        Ok(out) => out,
        Err(_) => {
            let _ = std::process::Command::new("kill")
                .args(["-9", &id.to_string()])
                .status();
            panic!("the run took more than {limit_s} s");
        }
    }
}

/// A process's stderr as text.
pub fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Make a FIFO at `path`.
pub fn mkfifo(path: &Path) {
    assert!(
        std::process::Command::new("mkfifo")
            .arg(path)
            .status()
            .unwrap()
            .success()
    );
}
