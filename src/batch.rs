//! Running many files: listing the inputs, choosing the camera for each, and writing records.

use crate::camera::Camera;
use crate::catalog::Catalog;
use crate::detect::{self, Detection};
use crate::frame::{Frame, is_image_path};
use crate::gpu::Gpu;
use crate::gpu::vote::{GpuTable, VoteJob};
use crate::identify::{self, VoteResult};
use crate::record::{Record, Status, Timing};
use crate::solve::{Outcome, Prepared, Settings, Solution, Solver};
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

/// Which backend runs the kernels, as asked on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    /// The GPU if an adapter exists, else the CPU (with a warning).
    Auto,
    /// The GPU; an error when there is no adapter.
    Gpu,
    /// The CPU twins of the kernels.
    Cpu,
}

/// The backend in use.
pub enum Backend {
    Cpu,
    Gpu(Box<Gpu>),
}

pub const BACKEND_CPU: &str = "cpu";

impl Backend {
    /// Open the chosen backend; the adapter is picked by `GPUSTAR_ADAPTER` (a substring of its
    /// name) when set. Returns a warning to print when `auto` fell back to the CPU.
    pub fn open(choice: BackendChoice) -> Result<(Backend, Option<String>)> {
        let name = std::env::var("GPUSTAR_ADAPTER").ok();
        match choice {
            BackendChoice::Cpu => Ok((Backend::Cpu, None)),
            BackendChoice::Gpu => Ok((Backend::Gpu(Box::new(Gpu::new(name.as_deref())?)), None)),
            BackendChoice::Auto => match Gpu::new(name.as_deref()) {
                Ok(g) => Ok((Backend::Gpu(Box::new(g)), None)),
                Err(e) => Ok((Backend::Cpu, Some(format!("{e:#}; using the CPU")))),
            },
        }
    }

    /// The records' `backend` field.
    pub fn name(&self) -> String {
        match self {
            Backend::Cpu => BACKEND_CPU.to_string(),
            Backend::Gpu(g) => g.backend_name(),
        }
    }
}

/// A solver and, on the GPU, its table in GPU memory.
struct SizeSolver {
    solver: Solver,
    gpu_table: Option<GpuTable>,
}

/// Solvers per frame size, built on first use (a table per camera), and the backend.
pub struct Pipeline {
    pub catalog: Catalog,
    pub settings: Settings,
    pub camera: CameraSource,
    pub backend: Backend,
    solvers: HashMap<(u32, u32), std::result::Result<SizeSolver, String>>,
    /// Set once the GPU failed: the rest of the run is on the CPU.
    gpu_failed: bool,
}

/// A decoded input waiting for its record.
struct Decoded {
    index: usize,
    frame: Frame,
    decode_ms: f64,
}

impl Pipeline {
    pub fn new(
        catalog: Catalog,
        settings: Settings,
        camera: CameraSource,
        backend: Backend,
    ) -> Pipeline {
        Pipeline {
            catalog,
            settings,
            camera,
            backend,
            solvers: HashMap::new(),
            gpu_failed: false,
        }
    }

    /// The solver for frames of this size (or why there is none).
    pub fn solver(&mut self, width: u32, height: u32) -> std::result::Result<&Solver, String> {
        self.size_solver(width, height).map(|s| &s.solver)
    }

    fn size_solver(&mut self, width: u32, height: u32) -> std::result::Result<&SizeSolver, String> {
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
            let solver =
                Solver::new(&self.catalog, camera, self.settings).map_err(|e| format!("{e:#}"))?;
            let gpu_table = match &self.backend {
                Backend::Gpu(g) => Some(
                    g.upload_table(&solver.table, solver.refs.len())
                        .map_err(|e| format!("{e:#}"))?,
                ),
                Backend::Cpu => None,
            };
            Ok(SizeSolver { solver, gpu_table })
        });
        entry.as_ref().map_err(|e| e.clone())
    }

    /// Read and solve one file: always exactly one record.
    pub fn process(&mut self, path: &Path, name: &str) -> Record {
        self.process_batch(&[(path.to_path_buf(), name.to_string())])
            .pop()
            .expect("one record per input")
    }

    /// Read and solve a batch of files: exactly one record per file, in input order. Frames
    /// of one size go through the GPU together (one submission for detection, one for voting).
    pub fn process_batch(&mut self, inputs: &[(PathBuf, String)]) -> Vec<Record> {
        let mut records: Vec<Option<Record>> = vec![None; inputs.len()];
        let mut by_size: Vec<((u32, u32), Vec<Decoded>)> = Vec::new();
        for (index, (path, name)) in inputs.iter().enumerate() {
            let t0 = Instant::now();
            match Frame::read(path) {
                Ok(frame) => {
                    let decode_ms = t0.elapsed().as_secs_f64() * 1e3;
                    let size = (frame.width, frame.height);
                    let d = Decoded {
                        index,
                        frame,
                        decode_ms,
                    };
                    match by_size.iter_mut().find(|(s, _)| *s == size) {
                        Some((_, v)) => v.push(d),
                        None => by_size.push((size, vec![d])),
                    }
                }
                Err(e) => {
                    records[index] =
                        Some(Record::error(name, format!("{e:#}"), &self.backend.name()))
                }
            }
        }
        for ((w, h), group) in by_size {
            match self.solve_group(w, h, &group, inputs) {
                Ok(recs) => {
                    for (d, r) in group.iter().zip(recs) {
                        records[d.index] = Some(r);
                    }
                }
                Err(e) => {
                    for d in &group {
                        records[d.index] = Some(Record::error(
                            &inputs[d.index].1,
                            e.clone(),
                            &self.backend.name(),
                        ));
                    }
                }
            }
        }
        records
            .into_iter()
            .map(|r| r.expect("every input has a record"))
            .collect()
    }

    /// Frames of one size: detection and voting on the backend, the rest on the CPU.
    fn solve_group(
        &mut self,
        w: u32,
        h: u32,
        group: &[Decoded],
        inputs: &[(PathBuf, String)],
    ) -> std::result::Result<Vec<Record>, String> {
        let use_gpu = matches!(self.backend, Backend::Gpu(_)) && !self.gpu_failed;
        let backend_name = if use_gpu {
            self.backend.name()
        } else {
            BACKEND_CPU.to_string()
        };
        self.size_solver(w, h)?;
        let ss = self.solvers[&(w, h)].as_ref().expect("built above");
        let solver = &ss.solver;
        let settings = &solver.settings.detect;
        let n = group.len() as f64;
        // Detection.
        let t0 = Instant::now();
        let p = detect::params(&group[0].frame, settings);
        let mut detect_ms = vec![0.0; group.len()];
        let mut gpu_error = None;
        let blobs = match (&self.backend, use_gpu) {
            (Backend::Gpu(g), true) => {
                let frames: Vec<&Frame> = group.iter().map(|d| &d.frame).collect();
                match g.detect(&frames, &p) {
                    Ok(b) => {
                        detect_ms.fill(t0.elapsed().as_secs_f64() * 1e3 / n);
                        Some(b)
                    }
                    Err(e) => {
                        gpu_error = Some(e);
                        None
                    }
                }
            }
            _ => None,
        };
        let blobs = blobs.unwrap_or_else(|| {
            group
                .iter()
                .zip(detect_ms.iter_mut())
                .map(|(d, ms)| {
                    let t = Instant::now();
                    let b = detect::blobs_cpu(&d.frame, &p);
                    *ms = t.elapsed().as_secs_f64() * 1e3;
                    b
                })
                .collect()
        });
        let detections: Vec<Vec<Detection>> = blobs
            .iter()
            .map(|b| detect::star_list(b, settings))
            .collect();
        // Identification.
        let t1 = Instant::now();
        let prepared: Vec<Option<Prepared>> =
            detections.iter().map(|d| solver.prepare(d)).collect();
        let mut identify_ms = vec![0.0; group.len()];
        let mut voted: Vec<Option<VoteResult>> = vec![None; group.len()];
        if let (Backend::Gpu(g), true, Some(table), None) =
            (&self.backend, use_gpu, &ss.gpu_table, &gpu_error)
        {
            let jobs: Vec<VoteJob> = prepared
                .iter()
                .flatten()
                .map(|p| VoteJob {
                    ranges: p.ranges.clone(),
                    stars: p.n_vote,
                    k: p.k,
                })
                .collect();
            match g.vote(table, &jobs) {
                Ok(results) => {
                    let mut it = results.into_iter();
                    for (v, p) in voted.iter_mut().zip(&prepared) {
                        if p.is_some() {
                            *v = it.next();
                        }
                    }
                }
                Err(e) => gpu_error = Some(e),
            }
        }
        let mut outcomes = Vec::with_capacity(group.len());
        for (k, (dets, prep)) in detections.iter().zip(&prepared).enumerate() {
            let t = Instant::now();
            let outcome = match prep {
                None => Outcome::Unsolved("too_few_stars"),
                Some(p) => {
                    let v = voted[k].take().unwrap_or_else(|| {
                        identify::vote_cpu(
                            &solver.table,
                            &p.ranges,
                            p.n_vote,
                            solver.refs.len(),
                            p.k,
                        )
                    });
                    solver.finish(dets, &p.vectors, &v)
                }
            };
            identify_ms[k] = t.elapsed().as_secs_f64() * 1e3;
            outcomes.push(outcome);
        }
        if use_gpu && gpu_error.is_none() {
            // The GPU part of the time is shared by the batch.
            let shared = (t1.elapsed().as_secs_f64() * 1e3 - identify_ms.iter().sum::<f64>()) / n;
            identify_ms.iter_mut().for_each(|ms| *ms += shared.max(0.0));
        }
        let backend_name = match &gpu_error {
            Some(e) => {
                eprintln!(
                    "gpustar: warning: {e:#}; this batch and the rest of the run use the CPU"
                );
                self.gpu_failed = true;
                BACKEND_CPU.to_string()
            }
            None => backend_name,
        };
        let ss = self.solvers[&(w, h)].as_ref().expect("built above");
        Ok(group
            .iter()
            .zip(detections)
            .zip(outcomes)
            .enumerate()
            .map(|(k, ((d, detections), outcome))| {
                let sol = Solution {
                    detections,
                    outcome,
                };
                let timing = Timing {
                    decode: d.decode_ms,
                    detect: detect_ms[k],
                    identify: identify_ms[k],
                    total: d.decode_ms + detect_ms[k] + identify_ms[k],
                };
                ss.solver
                    .record(&inputs[d.index].1, &sol, timing, &backend_name)
            })
            .collect())
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
