//! The kernels the identification flow (`driver`) runs on, for a batch of frames of
//! one size: the CPU twins ([`CpuKernels`]) or the GPU's (`pipeline::gpu_runner`). The flow
//! itself — which frames go through which pass, fallbacks, budgets, retries — is written once,
//! in the driver; a backend only says how a batch's lookups, votes and detections are computed.

use super::detect::{DetectSettings, Detection, Detector};
use super::identify::{self, VoteResult};
use super::radial;
use super::scale_free::{Lookup, rows_cpu};
use super::solver::{Prepared, Solver};
use crate::cpu::pattern::Rows;
use crate::io::frame::Frame;
use std::convert::Infallible;
use std::time::Instant;

/// One backend's kernels over a batch of frames (indices into the batch).
pub trait Kernels {
    /// What a kernel can fail with: nothing on the CPU, a GPU error on the GPU (the runner
    /// then moves the rest of the run to the CPU).
    type Error;

    /// Frames `which` of the batch detected again under `s` (the matched filter of the
    /// detection retry).
    fn detect_filtered(
        &mut self,
        which: &[usize],
        s: &DetectSettings,
    ) -> Result<Vec<Vec<Detection>>, Self::Error>;

    /// How many rounds of the scale-free pass one lookup holds: the CPU looks a round up only
    /// when the rounds before it did not solve; the GPU looks them all up in one submission.
    fn rounds_per_lookup(&self) -> usize;

    /// The rows of every query of each lookup in `solver`'s pattern index.
    fn pattern(
        &mut self,
        solver: &Solver,
        lookups: &[&Lookup],
    ) -> Result<Vec<Vec<Rows>>, Self::Error>;

    /// The vote of band `band`'s distance table for each prepared frame.
    fn vote(
        &mut self,
        solver: &Solver,
        band: usize,
        jobs: &[&Prepared],
    ) -> Result<Vec<VoteResult>, Self::Error>;

    /// The candidates of band `band`'s radial features for each prepared frame.
    fn radial(
        &mut self,
        solver: &Solver,
        band: usize,
        jobs: &[&Prepared],
    ) -> Result<Vec<VoteResult>, Self::Error>;
}

/// The CPU twins. A frame's tile statistics are kept between its two detection stages; the
/// default has no frames (star lists: nothing to detect again).
#[derive(Default)]
pub struct CpuKernels<'f> {
    detectors: Vec<Detector<'f>>,
    /// Milliseconds spent in [`Kernels::detect_filtered`].
    pub detect_ms: f64,
}

impl<'f> CpuKernels<'f> {
    /// Kernels for `frames`, and each frame's detections under `s` (the first stage).
    pub fn detect(frames: &[&'f Frame<'f>], s: &DetectSettings) -> (Self, Vec<Vec<Detection>>) {
        let detectors: Vec<Detector> = frames.iter().map(|f| Detector::new(f, s)).collect();
        let first = detectors.iter().map(Detector::detect).collect();
        (
            Self {
                detectors,
                ..Self::default()
            },
            first,
        )
    }
}

impl Kernels for CpuKernels<'_> {
    type Error = Infallible;

    fn detect_filtered(
        &mut self,
        which: &[usize],
        s: &DetectSettings,
    ) -> Result<Vec<Vec<Detection>>, Infallible> {
        let t = Instant::now();
        let out = which
            .iter()
            .map(|&i| self.detectors[i].detect_with(s))
            .collect();
        self.detect_ms += t.elapsed().as_secs_f64() * 1e3;
        Ok(out)
    }

    fn rounds_per_lookup(&self) -> usize {
        1
    }

    fn pattern(
        &mut self,
        solver: &Solver,
        lookups: &[&Lookup],
    ) -> Result<Vec<Vec<Rows>>, Infallible> {
        Ok(match &solver.scale_free {
            Some(sf) => lookups.iter().map(|l| rows_cpu(sf, l)).collect(),
            None => vec![Vec::new(); lookups.len()],
        })
    }

    fn vote(
        &mut self,
        solver: &Solver,
        band: usize,
        jobs: &[&Prepared],
    ) -> Result<Vec<VoteResult>, Infallible> {
        let b = &solver.bands[band];
        Ok(jobs
            .iter()
            .map(|p| identify::vote_cpu(b.table(), &p.ranges, p.n_vote, b.refs.len(), p.k))
            .collect())
    }

    fn radial(
        &mut self,
        solver: &Solver,
        band: usize,
        jobs: &[&Prepared],
    ) -> Result<Vec<VoteResult>, Infallible> {
        let Some(t) = &solver.bands[band].radial else {
            return Ok(Vec::new());
        };
        Ok(jobs
            .iter()
            .map(|p| {
                let image = radial::image_features(&p.vectors[..p.n_vote], t);
                radial::candidates_cpu(t, &image, radial::CANDIDATES)
            })
            .collect())
    }
}
