//! Frames held in memory, through the library as a program embedding it would give them:
//! `batch::run_frames` streams them to the workers as `batch::run` streams files, and a frame
//! whose pixels are borrowed (`Frame::from_samples` of u16 values) is solved where it lies.
//! Either way the records are the files' records.

use crate::common::run_ok;
use gpustar::batch::{self, RunOptions};
use gpustar::io::array::Samples;
use gpustar::io::output::{Format, RecordWriter};
use gpustar::pipeline::{Backend, CameraSource, Decoded, Solvers};
use gpustar::{Camera, Catalog, Frame, Record, Settings};
use std::borrow::Cow;
use std::sync::atomic::AtomicBool;

/// A record less its timings (which differ between any two runs).
fn untimed(r: &Record) -> serde_json::Value {
    let mut v = serde_json::to_value(r).unwrap();
    v.as_object_mut().unwrap().remove("timing_ms");
    v
}

#[test]
fn frames_in_memory_give_the_records_of_their_files() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    let d = dir.to_str().unwrap();
    run_ok(&[
        "simulate",
        "--out",
        d,
        "-n",
        "6",
        "--fov-deg",
        "18",
        "--seed",
        "27",
    ]);
    let (camera, _) = Camera::from_toml_file(&dir.join("camera.toml")).unwrap();
    let settings = Settings {
        mag_limit: Some(6.0),
        ..Settings::default()
    };
    let solvers = Solvers::new(Catalog::builtin(), settings, CameraSource::Fixed(camera));
    let inputs = gpustar::io::inputs::list(&dir, false).unwrap();
    let opts = RunOptions {
        threads: 2,
        batch_size: 4,
        flush_every: std::time::Duration::from_millis(250),
        sequence: None,
        tracklets: false,
        star_lists: None,
    };
    let stop = AtomicBool::new(false);
    let mut files = Vec::new();
    let mut writer = RecordWriter::new(Box::new(std::io::sink()), Format::Jsonl, true);
    batch::run(
        inputs.clone(),
        &solvers,
        &mut Backend::Cpu,
        &mut writer,
        opts,
        &stop,
        |r, _| files.push(untimed(r)),
    )
    .unwrap();
    let decoded: Vec<Decoded<'static>> = inputs
        .iter()
        .map(|i| {
            let (f, info) = Frame::read_info(&i.path).unwrap();
            Decoded::in_memory(&i.name, Ok((f, info.warnings)), info.epoch, info.keywords)
        })
        .collect();
    let mut memory = Vec::new();
    let summary = batch::run_frames(
        decoded.into_iter(),
        &solvers,
        &mut Backend::Cpu,
        opts,
        &stop,
        |r, _| memory.push(untimed(r)),
    )
    .unwrap();
    assert_eq!(memory, files);
    assert!(summary.counts.solved >= 5, "{:?}", summary.counts);
    // One frame's pixels borrowed from a buffer the caller keeps (with the file's saturation
    // level: from_samples takes u16 values as 16-bit).
    let (owned, info) = Frame::read_info(&inputs[0].path).unwrap();
    let (borrowed, _) =
        Frame::from_samples(owned.width, owned.height, Samples::U16(&owned.pixels)).unwrap();
    assert!(matches!(borrowed.pixels, Cow::Borrowed(_)));
    let frame = Frame {
        saturation: owned.saturation,
        ..borrowed
    };
    let d = Decoded::in_memory(
        &inputs[0].name,
        Ok((frame, info.warnings)),
        info.epoch,
        info.keywords,
    );
    assert_eq!(untimed(&solvers.solve_cpu(d)), files[0]);
}
