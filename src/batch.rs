//! Running many files: listing the inputs, choosing the camera for each, and writing records.

use crate::camera::Camera;
use crate::catalog::Catalog;
use crate::frame::{Frame, is_image_path};
use crate::record::{Record, Status, Timing};
use crate::solve::{Settings, Solver};
use anyhow::{Context, Result, bail};
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Where the camera model comes from.
#[derive(Clone, Debug)]
pub enum CameraSource {
    /// A camera file: frames of another size are errors.
    Fixed(Camera),
    /// `--fov-deg`: square pixels, centred, no distortion, sized by each frame.
    Fov(f64),
}

/// Solvers per frame size, built on first use (a table per camera).
pub struct Pipeline {
    pub catalog: Catalog,
    pub settings: Settings,
    pub camera: CameraSource,
    solvers: HashMap<(u32, u32), std::result::Result<Solver, String>>,
}

pub const BACKEND_CPU: &str = "cpu";

impl Pipeline {
    pub fn new(catalog: Catalog, settings: Settings, camera: CameraSource) -> Pipeline {
        Pipeline {
            catalog,
            settings,
            camera,
            solvers: HashMap::new(),
        }
    }

    /// The solver for frames of this size (or why there is none).
    pub fn solver(&mut self, width: u32, height: u32) -> std::result::Result<&Solver, String> {
        let entry = self.solvers.entry((width, height)).or_insert_with(|| {
            let camera = match &self.camera {
                CameraSource::Fixed(c) => {
                    if (c.width, c.height) != (width, height) {
                        return Err(format!(
                            "image is {width}x{height} but the camera file says {}x{}: pass the \
                             camera of this image (--camera FILE), or --fov-deg",
                            c.width, c.height
                        ));
                    }
                    c.clone()
                }
                CameraSource::Fov(fov) => {
                    Camera::from_fov(width, height, *fov).map_err(|e| format!("{e:#}"))?
                }
            };
            Solver::new(&self.catalog, camera, self.settings).map_err(|e| format!("{e:#}"))
        });
        entry.as_ref().map_err(|e| e.clone())
    }

    /// Read and solve one file: always exactly one record.
    pub fn process(&mut self, path: &Path, name: &str) -> Record {
        let t0 = Instant::now();
        let frame = match Frame::read(path) {
            Ok(f) => f,
            Err(e) => return Record::error(name, format!("{e:#}"), BACKEND_CPU),
        };
        let decode_ms = t0.elapsed().as_secs_f64() * 1e3;
        let solver = match self.solver(frame.width, frame.height) {
            Ok(s) => s,
            Err(e) => return Record::error(name, e, BACKEND_CPU),
        };
        let (sol, detect_ms, identify_ms) = solver.solve_frame(&frame);
        let timing = Timing {
            decode: decode_ms,
            detect: detect_ms,
            identify: identify_ms,
            total: t0.elapsed().as_secs_f64() * 1e3,
        };
        solver.record(name, &sol, timing, BACKEND_CPU)
    }
}

/// The image files directly in `dir`, sorted by name: (path, name relative to `dir`).
pub fn list_inputs(dir: &Path) -> Result<Vec<(PathBuf, String)>> {
    if !dir.is_dir() {
        bail!("{} is not a directory", dir.display());
    }
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))? {
        let entry = entry.with_context(|| format!("cannot list {}", dir.display()))?;
        let path = entry.path();
        if path.is_file() && is_image_path(&path) {
            let name = entry.file_name().to_string_lossy().into_owned();
            out.push((path, name));
        }
    }
    out.sort_by(|a, b| a.1.cmp(&b.1));
    Ok(out)
}

/// Output format of the records.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// One JSON object per line (spec/INTERFACE.md).
    Jsonl,
    /// A header and one row per file, without the per-star matches.
    Csv,
}

/// Writes records in the chosen format.
pub struct RecordWriter {
    out: Box<dyn Write>,
    format: Format,
    header_done: bool,
}

const CSV_HEADER: &str = "file,status,reason,error,ra_deg,dec_deg,roll_deg,qw,qx,qy,qz,fov_x_deg,fov_y_deg,stars_detected,stars_matched,rmse_arcsec,p90_arcsec,max_arcsec,false_match_prob,total_ms,backend";

impl RecordWriter {
    pub fn new(out: Box<dyn Write>, format: Format) -> RecordWriter {
        RecordWriter {
            out,
            format,
            header_done: false,
        }
    }

    pub fn write(&mut self, r: &Record) -> Result<()> {
        match self.format {
            Format::Jsonl => writeln!(self.out, "{}", r.to_json_line())?,
            Format::Csv => {
                if !self.header_done {
                    writeln!(self.out, "{CSV_HEADER}")?;
                    self.header_done = true;
                }
                writeln!(self.out, "{}", csv_row(r))?;
            }
        }
        Ok(())
    }

    pub fn flush(&mut self) -> Result<()> {
        self.out.flush().context("cannot write the results")
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn csv_row(r: &Record) -> String {
    let num = |v: Option<f64>| v.map(|x| x.to_string()).unwrap_or_default();
    let int = |v: Option<usize>| v.map(|x| x.to_string()).unwrap_or_default();
    let q = r.quaternion.map(|q| q.map(Some)).unwrap_or([None; 4]);
    let status = match r.status {
        Status::Solved => "solved",
        Status::Unsolved => "unsolved",
        Status::Error => "error",
    };
    [
        csv_field(&r.file),
        status.to_string(),
        csv_field(r.reason.as_deref().unwrap_or("")),
        csv_field(r.error.as_deref().unwrap_or("")),
        num(r.ra_deg),
        num(r.dec_deg),
        num(r.roll_deg),
        num(q[0]),
        num(q[1]),
        num(q[2]),
        num(q[3]),
        num(r.fov_x_deg),
        num(r.fov_y_deg),
        int(r.stars_detected),
        int(r.stars_matched),
        num(r.rmse_arcsec),
        num(r.p90_arcsec),
        num(r.max_arcsec),
        num(r.false_match_prob),
        r.timing_ms.total.to_string(),
        csv_field(&r.backend),
    ]
    .join(",")
}

/// Counts over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    pub solved: usize,
    pub unsolved: usize,
    pub errors: usize,
}

impl Counts {
    pub fn add(&mut self, r: &Record) {
        match r.status {
            Status::Solved => self.solved += 1,
            Status::Unsolved => self.unsolved += 1,
            Status::Error => self.errors += 1,
        }
    }

    pub fn total(&self) -> usize {
        self.solved + self.unsolved + self.errors
    }
}
