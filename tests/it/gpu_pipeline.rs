//! The whole pipeline on the GPU against the CPU: the same records (status, HIP ids, centroids
//! and attitude within the PSF fit's f32 tolerance) on simulated and real frames; deterministic across runs; O(1) submissions and maps
//! per batch. Runs on lavapipe in CI; skipped with a printed reason where there is no adapter.

use crate::common;

use common::{gpu, gpustar, shared_dir};
use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::pipeline::{Backend, CameraSource, GpuRunner, Pipeline};
use gpustar::record::{Record, Timing};
use gpustar::solve::Settings;
use std::path::{Path, PathBuf};

/// Records without what legitimately differs between backends and runs.
fn comparable(mut r: Record) -> String {
    r.timing_ms = Timing::default();
    r.backend.clear();
    r.to_json_line()
}

/// GPU = CPU: the same records, floats within `common::assert_records_match`'s tolerances.
fn assert_same(gpu: Record, cpu: Record) {
    let value = |r: Record| serde_json::from_str(&comparable(r)).unwrap();
    common::assert_records_match(&value(gpu), &value(cpu));
}

fn simulate(dir: &Path, n: usize, fov: &str, size: &str) {
    common::simulate(
        dir,
        &["-n", &n.to_string(), "--fov-deg", fov, "--size", size],
    );
}

fn inputs(dir: &Path) -> Vec<(PathBuf, String)> {
    gpustar::io::inputs::list(dir, false)
        .unwrap()
        .into_iter()
        .map(|i| (i.path, i.name))
        .collect()
}

fn pipeline(backend: Backend, fov: f64, epoch: f64) -> Pipeline {
    let settings = Settings {
        epoch,
        mag_limit: Some(6.0),
        ..Settings::default()
    };
    Pipeline::new(
        Catalog::builtin(),
        settings,
        CameraSource::fov(fov),
        backend,
    )
}

#[test]
fn gpu_records_equal_cpu_records_on_simulated_frames() {
    let Some(g) = gpu("gpu_records_equal_cpu_records_on_simulated_frames") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    simulate(tmp.path(), 12, "18", "1024x1024");
    let files = inputs(tmp.path());
    let name = g.backend_name();
    let gpu_records =
        pipeline(Backend::Gpu(Box::new(GpuRunner::new(g))), 18.0, 2000.0).process_batch(&files);
    let cpu_records = pipeline(Backend::Cpu, 18.0, 2000.0).process_batch(&files);
    assert_eq!(gpu_records.len(), 12);
    for (a, b) in gpu_records.into_iter().zip(cpu_records) {
        assert_eq!(a.backend, name);
        assert_eq!(b.backend, "cpu");
        assert_eq!(a.status, gpustar::record::Status::Solved, "{}", a.file);
        assert_same(a, b);
    }
}

#[test]
fn gpu_records_equal_cpu_records_on_real_frames() {
    let Some(shared) = shared_dir("gpu_records_equal_cpu_records_on_real_frames") else {
        return;
    };
    let Some(g) = gpu("gpu_records_equal_cpu_records_on_real_frames") else {
        return;
    };
    let set = shared.join("data/real/esa-tetra3");
    let files = inputs(&set);
    let camera = Camera::from_fov(1024, 768, 11.425).unwrap();
    let make = |backend| {
        let settings = Settings {
            epoch: 2019.58,
            ..Settings::default()
        };
        Pipeline::new(
            Catalog::builtin(),
            settings,
            CameraSource::Fixed(camera.clone()),
            backend,
        )
    };
    let gpu_records = make(Backend::Gpu(Box::new(GpuRunner::new(g)))).process_batch(&files);
    let cpu_records = make(Backend::Cpu).process_batch(&files);
    let solved = gpu_records
        .iter()
        .filter(|r| r.status == gpustar::record::Status::Solved)
        .count();
    assert_eq!(solved, 8);
    for (a, b) in gpu_records.into_iter().zip(cpu_records) {
        assert!(a.backend.starts_with("gpu: "));
        assert_same(a, b);
    }
}

#[test]
fn twenty_runs_of_a_batch_are_identical_and_cost_three_submissions_each() {
    let Some(g) = gpu("twenty_runs_of_a_batch_are_identical_and_cost_three_submissions_each")
    else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    simulate(tmp.path(), 32, "18", "512x512");
    let files = inputs(tmp.path());
    let mut p = pipeline(Backend::Gpu(Box::new(GpuRunner::new(g))), 18.0, 2000.0);
    let counters = |p: &Pipeline| match &p.backend {
        Backend::Gpu(g) => g.gpu.counters(),
        Backend::Cpu => unreachable!(),
    };
    // The first run also builds the table and uploads it.
    let first: Vec<String> = p
        .process_batch(&files)
        .into_iter()
        .map(comparable)
        .collect();
    for run in 1..20 {
        let before = counters(&p);
        let again: Vec<String> = p
            .process_batch(&files)
            .into_iter()
            .map(comparable)
            .collect();
        let after = counters(&p);
        assert!(again == first, "run {run} differs from run 0");
        // A batch of 32 frames: one submission and one map each for detection, the PSF fits
        // and voting.
        assert_eq!(
            after.submissions - before.submissions,
            3,
            "submissions per batch"
        );
        assert_eq!(after.maps - before.maps, 3, "buffer maps per batch");
    }
}

#[test]
fn backend_gpu_through_the_binary_names_the_adapter() {
    if gpu("backend_gpu_through_the_binary_names_the_adapter").is_none() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    simulate(tmp.path(), 2, "18", "512x512");
    let out = gpustar()
        .args([
            "batch",
            tmp.path().to_str().unwrap(),
            "--fov-deg",
            "18",
            "--backend",
            "gpu",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for line in String::from_utf8(out.stdout).unwrap().lines() {
        let r: serde_json::Value = serde_json::from_str(line).unwrap();
        assert!(r["backend"].as_str().unwrap().starts_with("gpu: "), "{r}");
        assert_eq!(r["status"], "solved");
    }
}

#[test]
fn gpu_records_equal_cpu_records_on_frames_the_spread_retry_solves() {
    let Some(g) = gpu("gpu_records_equal_cpu_records_on_frames_the_spread_retry_solves") else {
        return;
    };
    // Simulated 14° frames with a bright cluster of spots in one corner (tests/it/spread.rs):
    // only the spread retry solves them.
    let tmp = tempfile::tempdir().unwrap();
    let s = gpustar::simulate::SimSettings {
        fov_x_deg: 14.0,
        mag_limit: 6.0,
        seed: 5,
        ..Default::default()
    };
    for (k, (mut f, _)) in common::rendered(&s, 4).into_iter().enumerate() {
        common::crowd_corner(&mut f, 90, k as u64);
        let px: Vec<u8> = f.pixels.iter().map(|&p| p as u8).collect();
        image::GrayImage::from_raw(f.width, f.height, px)
            .unwrap()
            .save(tmp.path().join(format!("crowded_{k}.png")))
            .unwrap();
    }
    let files = inputs(tmp.path());
    let gpu_records =
        pipeline(Backend::Gpu(Box::new(GpuRunner::new(g))), 14.0, 2000.0).process_batch(&files);
    let cpu_records = pipeline(Backend::Cpu, 14.0, 2000.0).process_batch(&files);
    assert_eq!(gpu_records.len(), 4);
    for (a, b) in gpu_records.into_iter().zip(cpu_records) {
        assert_eq!(a.status, gpustar::record::Status::Solved, "{}", a.file);
        assert_same(a, b);
    }
}
