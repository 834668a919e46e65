//! `batch`: a run over a directory on a thread of its own, as `gpustar batch` runs it.

use crate::options::build;
use crate::records::RecordHandle;
use crate::{Error, OutputError, config, py_err};
use gpustar::Backend;
use gpustar::Record;
use gpustar::SequenceOptions;
use gpustar::front::Choice;
use gpustar::front::Products;
use gpustar::front::{Exports, NO_SITE};
use gpustar::front::{Format, RecordWriter, open_output, restore_input_order, resumed_inputs};
use gpustar::front::{RunFiles, Sidecar, check_outputs, sidecar};
use gpustar::front::{Shard, inputs};
use gpustar::{RunOptions, RunSummary, run};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// A `batch` run on a thread of its own, its records handed over in input order.
#[pyclass(module = "gpustar._gpustar")]
pub(crate) struct BatchRun {
    pub(crate) records: crossbeam_channel::Receiver<Record>,
    pub(crate) stop: Arc<AtomicBool>,
    pub(crate) thread: Option<std::thread::JoinHandle<gpustar::Result<RunSummary>>>,
    pub(crate) total: usize,
}

#[pymethods]
impl BatchRun {
    /// Inputs this run solves (after shard and resume).
    #[getter]
    fn total(&self) -> usize {
        self.total
    }

    /// The next record, or None when the run is over (then its error, if any, is raised).
    fn next_record(&mut self, py: Python<'_>) -> PyResult<Option<RecordHandle>> {
        let rx = self.records.clone();
        match py.detach(move || rx.recv()) {
            Ok(record) => Ok(Some(RecordHandle::new(record))),
            Err(_) => {
                if let Some(t) = self.thread.take() {
                    let summary = py
                        .detach(|| t.join())
                        .map_err(|_| Error::new_err("the batch run's thread panicked"))?
                        .map_err(py_err)?;
                    if let Some(e) = summary.write_error {
                        return Err(OutputError::new_err(e));
                    }
                }
                Ok(None)
            }
        }
    }

    /// Start no new input; the run ends after those in flight.
    fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
    }
}

impl Drop for BatchRun {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            // Drain so that the writer is never blocked on a full channel.
            while self.records.recv().is_ok() {}
            let _ = t.join();
        }
    }
}

/// Start `gpustar batch DIRECTORY` with these options.
#[pyfunction]
#[pyo3(signature = (directory, camera=None, fov_deg=None, catalog=None, backend="auto",
    output=None, resume=false, retry_errors=false, shard=None, recursive=false, sequence=false,
    frame_interval_s=None, options=None, format="jsonl", dark=None, dark_median=false,
    wcs_dir=None, annotate_dir=None, tdm=None, iod=None, iod_station=NO_SITE, overwrite=false))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn start_batch(
    py: Python<'_>,
    directory: PathBuf,
    camera: Option<Bound<'_, PyAny>>,
    fov_deg: Option<Bound<'_, PyAny>>,
    catalog: Option<PathBuf>,
    backend: &str,
    output: Option<PathBuf>,
    resume: bool,
    retry_errors: bool,
    shard: Option<String>,
    recursive: bool,
    sequence: bool,
    frame_interval_s: Option<f64>,
    options: Option<Bound<'_, PyDict>>,
    format: &str,
    dark: Option<PathBuf>,
    dark_median: bool,
    wcs_dir: Option<PathBuf>,
    annotate_dir: Option<PathBuf>,
    tdm: Option<PathBuf>,
    iod: Option<PathBuf>,
    iod_station: u16,
    overwrite: bool,
) -> PyResult<BatchRun> {
    let format = Format::parse_name(format).map_err(|e| config(format!("format: {e}")))?;
    if format == Format::Csv && output.is_none() {
        return Err(config(
            "format is the output file's: give output=FILE (the records come as results)",
        ));
    }
    if dark.is_some() && dark_median {
        return Err(config("dark and dark_median do not go together: give one"));
    }
    if iod_station > NO_SITE {
        return Err(config(format!(
            "iod_station: {iod_station} is outside 0 to {NO_SITE}"
        )));
    }
    if (resume || retry_errors) && output.is_none() {
        return Err(config(
            "resume needs output=FILE: the records of an earlier run",
        ));
    }
    if retry_errors && !resume {
        return Err(config("retry_errors goes with resume=True"));
    }
    let catalog_path = catalog.clone();
    let mut b = build(camera.as_ref(), fov_deg.as_ref(), catalog, backend, options)?;
    // The batch's own options that shape the records, as the command line's configuration has
    // them.
    b.config.sequence = sequence;
    b.config.frame_interval = frame_interval_s.filter(|_| sequence);
    b.config.dark = dark.clone();
    b.config.dark_median = dark_median;
    if b.solvers.streaks.is_none() {
        for (k, given) in [("tdm", tdm.is_some()), ("iod", iod.is_some())] {
            if given {
                return Err(config(format!("{k} is an option of streaks=True")));
            }
        }
    }
    // As `--dark`, `--dark-median`, `--wcs-dir`, `--annotate-dir`, `--tdm`, `--iod`: the
    // library's own.
    b.solvers.darks = b.config.darks(&b.solvers.camera).map_err(py_err)?;
    let mut exports = Exports::new(tdm, iod, iod_station);
    let mut products = Products {
        wcs_dir,
        annotate_dir,
        overwrite,
        ..Products::default()
    };
    if sequence && b.solvers.streaks.is_some() {
        return Err(config(
            "sequence and streaks do not go together yet: run the sequences and the streak \
             frames separately",
        ));
    }
    let shard: Option<Shard> = match shard {
        Some(s) => Some(s.parse().map_err(config)?),
        None => None,
    };
    let mut list = inputs::list(&directory, recursive).map_err(py_err)?;
    if let Some(shard) = shard {
        // A sequence goes to one shard whole, as on the command line.
        list.retain(|i| {
            shard.takes(if sequence {
                gpustar::front::sequence_of(&i.name)
            } else {
                &i.name
            })
        });
    }
    // Every output checked before any work, and before `output` is emptied (as the command
    // line does).
    let read: Vec<(&std::path::Path, &'static str)> =
        [(&catalog_path, "the catalog"), (&dark, "the dark frame")]
            .into_iter()
            .filter_map(|(p, w)| p.as_deref().map(|p| (p, w)))
            .collect();
    check_outputs(
        &RunFiles {
            dirs: vec![(&directory, recursive)],
            inputs: &list,
            read,
            records: output.as_deref(),
            stdout: false,
            resume,
        },
        &exports,
        &mut products,
    )
    .map_err(py_err)?;
    b.solvers.products = products;
    let mut retried_order: Option<(PathBuf, Vec<String>)> = None;
    // As the command line: the configuration kept beside the records, and a resumed run's
    // checked against it before the records are touched.
    let side = Sidecar::new(&b.config, &b.solvers.catalog);
    if let Some(p) = &output {
        sidecar::check(p).map_err(py_err)?;
        if resume {
            sidecar::check_resume(p, &side).map_err(py_err)?;
        }
    }
    let (out, header): (Box<dyn std::io::Write + Send>, bool) = match &output {
        Some(p) => {
            let opened = open_output(p, format, resume, retry_errors).map_err(py_err)?;
            sidecar::write(p, &side).map_err(py_err)?;
            // Redone error records are put back in their places when the run ends.
            if opened.previous.retried > 0 {
                retried_order = Some((p.clone(), list.iter().map(|i| i.name.clone()).collect()));
            }
            list = resumed_inputs(list, &opened.previous.done, sequence);
            // The exports are written whole at the end, with the streaks already recorded.
            if resume && exports.wanted() {
                for r in &opened.previous.streaks {
                    exports.add(r);
                }
            }
            (Box::new(opened.file), !opened.previous.has_header)
        }
        None => (Box::new(std::io::sink()), true),
    };
    let total = list.iter().filter(|i| !i.replay).count();
    let (mut backend, _) = py.detach(|| Backend::open(b.backend)).map_err(py_err)?;
    let opts = RunOptions {
        threads: b.threads,
        batch_size: b.batch_size,
        flush_every: std::time::Duration::from_millis(250),
        sequence: sequence.then(|| SequenceOptions {
            frame_interval_s,
            ..SequenceOptions::default()
        }),
        // As the command line: with streaks, a directory's frames are linked into tracklets.
        tracklets: b.solvers.streaks.is_some(),
        star_lists: None,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = crossbeam_channel::bounded::<Record>(4 * b.batch_size.max(b.threads));
    let solvers = b.solvers;
    let stop2 = stop.clone();
    let thread = std::thread::spawn(move || {
        let mut writer = RecordWriter::new(out, format, header);
        let summary = run(
            list,
            &solvers,
            &mut backend,
            &mut writer,
            opts,
            &stop2,
            |r, _| {
                exports.add(r);
                // A closed receiver (the iterator dropped) has set the stop flag.
                let _ = tx.send(r.clone());
            },
        )?;
        if let (Some((path, order)), None, false) =
            (&retried_order, &summary.write_error, summary.interrupted)
        {
            writer.flush()?;
            restore_input_order(path, format, order)?;
        }
        if exports.wanted() && summary.write_error.is_none() {
            exports.finish(&gpustar::front::now_utc_iso())?;
        }
        Ok(summary)
    });
    Ok(BatchRun {
        records: rx,
        stop,
        thread: Some(thread),
        total,
    })
}
