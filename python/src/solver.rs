//! `Solver`: built once and reused, shareable between threads; `ManyRun` streams frames to its
//! workers (`solve_many`).

use crate::arrays::{decoded_of, held};
use crate::options::build;
use crate::records::RecordHandle;
use crate::{Error, InputError, py_err};
use gpustar::Backend;
use gpustar::front::Counts;
use gpustar::front::Detection;
use gpustar::front::run_frames;
use gpustar::front::{Decoded, Solvers};
use gpustar::{Frame, Record};
use gpustar::{RunOptions, RunSummary};
use numpy::PyReadonlyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// Where a solver's kernels run.
pub(crate) enum Engine {
    Cpu,
    /// The GPU context (always `Backend::Gpu`) is used by one call at a time.
    Gpu(Mutex<Backend>),
}

/// A solver built once (catalog, distance tables, GPU context) and reused; shareable
/// between threads.
#[pyclass(frozen, module = "gpustar._gpustar")]
pub(crate) struct Solver {
    pub(crate) solvers: Arc<Solvers>,
    pub(crate) engine: Arc<Engine>,
    pub(crate) backend: String,
    pub(crate) threads: usize,
    pub(crate) batch_size: usize,
}

impl Solver {
    /// One frame's record, on the caller's thread (CPU) or as a batch of one (GPU).
    pub(crate) fn solve_one(&self, d: Decoded<'_>) -> Record {
        match self.engine.as_ref() {
            Engine::Cpu => self.solvers.solve_cpu(d),
            Engine::Gpu(b) => match &mut *b.lock().unwrap_or_else(|e| e.into_inner()) {
                Backend::Gpu(g) => g.solve(&self.solvers, vec![d]).remove(0),
                Backend::Cpu => self.solvers.solve_cpu(d),
            },
        }
    }
}

#[pymethods]
impl Solver {
    #[new]
    #[pyo3(signature = (camera=None, fov_deg=None, catalog=None, backend="auto", options=None))]
    fn new(
        py: Python<'_>,
        camera: Option<Bound<'_, PyAny>>,
        fov_deg: Option<Bound<'_, PyAny>>,
        catalog: Option<PathBuf>,
        backend: &str,
        options: Option<Bound<'_, PyDict>>,
    ) -> PyResult<Solver> {
        let b = build(camera.as_ref(), fov_deg.as_ref(), catalog, backend, options)?;
        let (engine, name) = py
            .detach(|| -> gpustar::Result<(Engine, String)> {
                let (backend, _note) = Backend::open(b.backend)?;
                let name = backend.name();
                Ok(match backend {
                    Backend::Cpu => (Engine::Cpu, name),
                    gpu => (Engine::Gpu(Mutex::new(gpu)), name),
                })
            })
            .map_err(py_err)?;
        Ok(Solver {
            solvers: Arc::new(b.solvers),
            engine: Arc::new(engine),
            backend: name,
            threads: b.threads,
            batch_size: b.batch_size,
        })
    }

    /// The records' `backend` field: "cpu" or the GPU adapter's name.
    #[getter]
    fn backend(&self) -> String {
        self.backend.clone()
    }

    /// Build the distance table for frames of this size now rather than on the first solve.
    fn prepare(&self, py: Python<'_>, width: u32, height: u32) -> PyResult<()> {
        py.detach(|| self.solvers.get(width, height))
            .map(drop)
            .map_err(py_err)
    }

    /// One frame: its record (a C-contiguous uint16 array is solved where it lies).
    #[pyo3(signature = (image, name, epoch=None, header=None))]
    fn solve(
        &self,
        py: Python<'_>,
        image: Bound<'_, PyAny>,
        name: &str,
        epoch: Option<f64>,
        header: Option<BTreeMap<String, String>>,
    ) -> PyResult<RecordHandle> {
        let held = held(&image)?;
        let d = decoded_of(&held, name, epoch, header, true)?;
        let record = py.detach(|| self.solve_one(d));
        Ok(RecordHandle::new(record))
    }

    /// Read and solve one image file as `gpustar solve FILE` does (its record's `file` is the
    /// path as given; a file that cannot be read gets an error record, not an exception).
    fn solve_file(&self, py: Python<'_>, path: PathBuf) -> PyResult<RecordHandle> {
        let name = path.display().to_string();
        let record = py.detach(|| self.solve_one(self.solvers.decode(&path, &name)));
        Ok(RecordHandle::new(record))
    }

    /// Start solving frames streamed in with `ManyRun.put` (worker threads on the CPU, GPU
    /// batches of `batch_size`), as `batch` streams files.
    #[pyo3(signature = (batch_size=None))]
    fn start_many(&self, batch_size: Option<usize>) -> PyResult<ManyRun> {
        let opts = RunOptions {
            threads: self.threads,
            batch_size: batch_size.unwrap_or(self.batch_size).clamp(1, 4096),
            flush_every: std::time::Duration::from_millis(250),
            sequence: None,
            tracklets: false,
            star_lists: None,
        };
        let (frames_tx, frames_rx) = crossbeam_channel::unbounded::<Decoded<'static>>();
        let (records_tx, records_rx) = crossbeam_channel::unbounded::<Record>();
        let stop = Arc::new(AtomicBool::new(false));
        let (solvers, engine, stop2) = (self.solvers.clone(), self.engine.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            let send = |r: &Record, _: &Counts| {
                let _ = records_tx.send(r.clone());
            };
            match engine.as_ref() {
                Engine::Cpu => run_frames(
                    frames_rx.into_iter(),
                    &solvers,
                    &mut Backend::Cpu,
                    opts,
                    &stop2,
                    send,
                ),
                Engine::Gpu(b) => {
                    let mut b = b.lock().unwrap_or_else(|e| e.into_inner());
                    run_frames(frames_rx.into_iter(), &solvers, &mut b, opts, &stop2, send)
                }
            }
        });
        // Frames in flight: enough that the workers never wait for Python (at least one
        // GPU batch, or two frames per CPU thread), as many as `batch` would have, and within
        // a memory budget.
        let least = match self.engine.as_ref() {
            Engine::Cpu => 2 * opts.threads.max(1),
            Engine::Gpu(_) => opts.batch_size,
        };
        Ok(ManyRun {
            frames: Some(frames_tx),
            records: records_rx,
            stop,
            thread: Some(thread),
            window: (least, opts.window().max(least)),
        })
    }

    /// The Rust path's time (ms) of each of `reps` solves of this image, the frame made
    /// beforehand and no Python in between: what scripts/bench_python.py sets the per-call
    /// cost of `solve` against (the same name and epoch as the `solve` it is set against).
    #[pyo3(signature = (image, reps, name="x", epoch=None))]
    fn _library_call_ms(
        &self,
        py: Python<'_>,
        image: Bound<'_, PyAny>,
        reps: usize,
        name: &str,
        epoch: Option<f64>,
    ) -> PyResult<Vec<f64>> {
        let held = held(&image)?;
        let (frame, _) = held.frame().map_err(py_err)?;
        let frame = frame.into_owned();
        Ok(py.detach(|| {
            (0..reps)
                .map(|_| {
                    let d = Decoded::in_memory(
                        name,
                        Ok((frame.clone(), Vec::new())),
                        epoch,
                        BTreeMap::new(),
                    );
                    let t0 = std::time::Instant::now();
                    let r = self.solve_one(d);
                    let ms = t0.elapsed().as_secs_f64() * 1e3;
                    drop(r);
                    ms
                })
                .collect()
        }))
    }

    /// Stars the caller detected: x, y (pixels) and fluxes (or brightest first when None).
    #[pyo3(signature = (x, y, width, height, fluxes=None, name="centroids", epoch=None))]
    #[allow(clippy::too_many_arguments)]
    fn solve_centroids(
        &self,
        py: Python<'_>,
        x: PyReadonlyArray1<'_, f64>,
        y: PyReadonlyArray1<'_, f64>,
        width: u32,
        height: u32,
        fluxes: Option<PyReadonlyArray1<'_, f64>>,
        name: &str,
        epoch: Option<f64>,
    ) -> PyResult<RecordHandle> {
        let (x, y) = (x.as_array(), y.as_array());
        let n = x.len();
        let f: Vec<f64> = match &fluxes {
            Some(f) => f.as_array().to_vec(),
            None => (0..n).map(|i| (n - i) as f64).collect(),
        };
        if y.len() != n || f.len() != n {
            return Err(InputError::new_err(format!(
                "{n} x, {} y and {} fluxes: give one of each per star",
                y.len(),
                f.len()
            )));
        }
        let mut stars = Vec::with_capacity(n);
        for i in 0..n {
            let (sx, sy, sf) = (x[i], y[i], f[i]);
            if !(sx.is_finite() && sy.is_finite() && sf.is_finite()) {
                return Err(InputError::new_err(format!(
                    "star {i} has a NaN or infinite x, y or flux"
                )));
            }
            stars.push(Detection {
                x: sx,
                y: sy,
                flux: sf,
                area: 1,
                peak: 0,
                saturated: false,
                sigma_px: None,
            });
        }
        let r = py.detach(|| {
            self.solvers
                .solve_detections(name, (width, height), stars, epoch)
        });
        Ok(RecordHandle::new(r))
    }
}

/// Frames streamed to a solver's workers (`Solver.solve_many`): `put` hands one over,
/// `next_record` takes the records in the order put.
#[pyclass(module = "gpustar._gpustar")]
pub(crate) struct ManyRun {
    pub(crate) frames: Option<crossbeam_channel::Sender<Decoded<'static>>>,
    pub(crate) records: crossbeam_channel::Receiver<Record>,
    pub(crate) stop: Arc<AtomicBool>,
    pub(crate) thread: Option<std::thread::JoinHandle<gpustar::Result<RunSummary>>>,
    /// The least and the most frames in flight.
    pub(crate) window: (usize, usize),
}

/// The pixels `solve_many` holds in flight at most (beyond the least window): 256 MiB.
pub(crate) const MANY_BUDGET_BYTES: usize = 256 << 20;

#[pymethods]
impl ManyRun {
    /// Frames of `width` × `height` to put ahead of the records taken, at most.
    fn window_for(&self, width: usize, height: usize) -> usize {
        let (least, most) = self.window;
        (MANY_BUDGET_BYTES / (2 * width * height).max(1)).clamp(least, most)
    }

    /// Hand over the next frame (its pixels copied: the workers solve it while Python goes
    /// on). An array refused for its values becomes an error record; what is not an array
    /// raises `InputError`.
    #[pyo3(signature = (image, name, epoch=None))]
    fn put(
        &mut self,
        py: Python<'_>,
        image: Bound<'_, PyAny>,
        name: &str,
        epoch: Option<f64>,
    ) -> PyResult<()> {
        let held = held(&image)?;
        let d = decoded_of(&held, name, epoch, None, false)?;
        let d = Decoded {
            frame: d.frame.map(Frame::into_owned),
            ..d
        };
        match &self.frames {
            Some(tx) if tx.send(d).is_ok() => Ok(()),
            // The run has ended: its error, if it failed.
            _ => {
                self.finish(py)?;
                Err(Error::new_err("the run is closed"))
            }
        }
    }

    /// No more frames: the run ends when those put are solved.
    fn close(&mut self) {
        self.frames = None;
    }

    /// The next record in the order put; with `wait` false, None when it is not done yet.
    /// None when the run is over (then its error, if any, is raised).
    fn next_record(&mut self, py: Python<'_>, wait: bool) -> PyResult<Option<RecordHandle>> {
        let rx = self.records.clone();
        let got = if wait {
            py.detach(move || rx.recv().ok())
        } else {
            match rx.try_recv() {
                Ok(r) => Some(r),
                Err(crossbeam_channel::TryRecvError::Empty) => return Ok(None),
                Err(crossbeam_channel::TryRecvError::Disconnected) => None,
            }
        };
        if let Some(record) = got {
            return Ok(Some(RecordHandle::new(record)));
        }
        self.finish(py)?;
        Ok(None)
    }
}

impl ManyRun {
    /// Wait for the run's thread to end; its error, if it failed.
    pub(crate) fn finish(&mut self, py: Python<'_>) -> PyResult<()> {
        if let Some(t) = self.thread.take() {
            py.detach(|| t.join())
                .map_err(|_| Error::new_err("the solving thread panicked"))?
                .map_err(py_err)?;
        }
        Ok(())
    }
}

impl Drop for ManyRun {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        self.frames = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
