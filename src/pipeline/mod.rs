//! Solving many frames: the solvers per frame size (shared by worker threads), the CPU path
//! (one frame at a time, on any thread) and the GPU path (batches of frames on the thread
//! that owns the GPU context, `gpu_runner.rs`). `batch::run` streams a directory through them.
//! Both paths end in the same `solve_with`/`Solvers::record`, so they build the same records.

mod camera_source;
mod cpu_runner;
mod gpu_runner;
mod hints;
mod solvers;
pub mod star_lists;

use crate::catalog::Catalog;
use crate::error::Result;
use crate::gpu::Gpu;
use crate::record::Record;
use crate::solve::Settings;
pub use camera_source::{CameraSource, MIN_SIDE};
pub use gpu_runner::GpuRunner;
pub use solvers::{BACKEND_CPU, DEFAULT_MAX_PIXELS, Decoded, Detected, SharedSolver, Solvers};
use std::path::PathBuf;

crate::choice! {
    /// Which backend runs the kernels, as asked on the command line.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum BackendChoice {
        Auto = "auto", "The GPU if an adapter exists, else the CPU (with a warning)",
        Gpu = "gpu", "The GPU; an error when there is no adapter",
        Cpu = "cpu", "The CPU twins of the kernels",
    }
}

/// The backend in use.
pub enum Backend {
    Cpu,
    Gpu(Box<GpuRunner>),
}

/// What opening the backend has to say: a warning (no GPU at all), or why `auto` chose the
/// CPU (for `-v`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BackendNote {
    Warning(String),
    Info(String),
}

impl Backend {
    /// Open the chosen backend; the adapter is picked by `GPUSTAR_ADAPTER` (a substring of its
    /// name) when set. `auto` takes the CPU twins when there is no adapter (with a warning) or
    /// when the best one is a software rasterizer (lavapipe runs the kernels on the CPU, about
    /// 15 times slower than the twins on 2 cores): ask for it with `--backend gpu` or by name.
    pub fn open(choice: BackendChoice) -> Result<(Backend, Option<BackendNote>)> {
        let name = std::env::var("GPUSTAR_ADAPTER").ok();
        let gpu = |g| Backend::Gpu(Box::new(GpuRunner::new(g)));
        match choice {
            BackendChoice::Cpu => Ok((Backend::Cpu, None)),
            BackendChoice::Gpu => Ok((gpu(Gpu::new(name.as_deref())?), None)),
            BackendChoice::Auto => {
                let fallback = |e: crate::error::Error| {
                    let w = BackendNote::Warning(format!("{e:#}; using the CPU"));
                    Ok((Backend::Cpu, Some(w)))
                };
                // The adapter is looked at before a device is made (that takes a third of a
                // second on lavapipe).
                match crate::gpu::best_adapter(name.as_deref()) {
                    Ok(a) if a.software && name.is_none() => {
                        let why = format!(
                            "the only GPU adapter, {}, is a software rasterizer: the CPU twins \
                             of the kernels are faster (--backend gpu uses it anyway)",
                            a.name
                        );
                        Ok((Backend::Cpu, Some(BackendNote::Info(why))))
                    }
                    Ok(_) => match Gpu::new(name.as_deref()) {
                        Ok(g) => Ok((gpu(g), None)),
                        Err(e) => fallback(e),
                    },
                    Err(e) => fallback(e),
                }
            }
        }
    }

    /// The records' `backend` field.
    pub fn name(&self) -> String {
        match self {
            Backend::Cpu => BACKEND_CPU.to_string(),
            Backend::Gpu(g) => g.name(),
        }
    }
}

/// A single-threaded pipeline: decode the files in turn, then solve them as one batch on the
/// backend given. `batch::run` streams large runs over threads (the `batch` and
/// `solve` commands go through it); this serves `calibrate`, tests and library users:
///
/// ```no_run
/// use gpustar::{Backend, Camera, CameraSource, Catalog, Pipeline, Settings};
/// let camera = Camera::from_fov(1024, 1024, 10.0)?;
/// let mut p = Pipeline::new(Catalog::load(None)?, Settings::default(), CameraSource::Fixed(camera), Backend::Cpu);
/// for r in p.process_batch(&[("frame.png".into(), "frame.png".to_string())]) {
///     println!("{}: {:?} {:?}", r.file, r.status, r.ra_deg);
/// }
/// # Ok::<(), gpustar::Error>(())
/// ```
pub struct Pipeline {
    pub solvers: Solvers,
    pub backend: Backend,
}

impl Pipeline {
    pub fn new(
        catalog: Catalog,
        settings: Settings,
        camera: CameraSource,
        backend: Backend,
    ) -> Self {
        Pipeline {
            solvers: Solvers::new(catalog, settings, camera),
            backend,
        }
    }

    /// One record per input, in input order.
    pub fn process_batch(&mut self, inputs: &[(PathBuf, String)]) -> Vec<Record> {
        let decoded: Vec<Decoded> = inputs
            .iter()
            .map(|(p, n)| self.solvers.decode(p, n))
            .collect();
        match &mut self.backend {
            Backend::Cpu => decoded
                .into_iter()
                .map(|d| self.solvers.solve_cpu(d))
                .collect(),
            Backend::Gpu(g) => g.solve(&self.solvers, decoded),
        }
    }
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
        use crate::record::Status;
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
