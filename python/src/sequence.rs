//! `Sequence`: frames of sequences fed one by one, as `--sequence` takes a directory's.

use crate::arrays::{decoded_of, held};
use crate::config;
use crate::records::RecordHandle;
use crate::solver::Solver;
use gpustar::Frame;
use gpustar::SequenceOptions;
use gpustar::front::{Decoded, Solvers};
use gpustar::front::{Detected, Sequencer};
use pyo3::prelude::*;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

/// Frames of sequences fed one by one, in order (as `--sequence` takes a directory's).
#[pyclass(module = "gpustar._gpustar")]
pub(crate) struct Sequence {
    pub(crate) seq: Mutex<Sequencer<'static>>,
    pub(crate) solvers: Arc<Solvers>,
    pub(crate) opts: SequenceOptions,
}

#[pymethods]
impl Sequence {
    #[new]
    #[pyo3(signature = (solver, frame_interval_s=None))]
    fn new(solver: &Solver, frame_interval_s: Option<f64>) -> PyResult<Sequence> {
        if frame_interval_s.is_some_and(|s| !(s.is_finite() && s > 0.0)) {
            return Err(config(
                "frame_interval_s must be a positive number of seconds",
            ));
        }
        let opts = SequenceOptions {
            frame_interval_s,
            ..SequenceOptions::default()
        };
        Ok(Sequence {
            seq: Mutex::new(Sequencer::shared(solver.solvers.clone(), opts)),
            solvers: solver.solvers.clone(),
            opts,
        })
    }

    /// The next frame's record; `name`'s directory part names its sequence.
    #[pyo3(signature = (image, name, header=None))]
    fn add(
        &self,
        py: Python<'_>,
        image: Bound<'_, PyAny>,
        name: &str,
        header: Option<BTreeMap<String, String>>,
    ) -> PyResult<RecordHandle> {
        let held = held(&image)?;
        let d = decoded_of(&held, name, None, header, true)?;
        // The sequence keeps frames between calls: their pixels are its own.
        let d = Decoded {
            frame: d.frame.map(Frame::into_owned),
            ..d
        };
        let r = py.detach(|| {
            let detected: Detected = self.solvers.detect_cpu(d, self.opts.detect_stars);
            let mut s = self.seq.lock().unwrap_or_else(|e| e.into_inner());
            s.next(detected)
        });
        Ok(RecordHandle::new(r))
    }
}
