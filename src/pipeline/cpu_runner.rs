//! The CPU side of a batch: one frame at a time, on any thread. The GPU runner ends in the same
//! `solve_with` and `Solvers::record`, so both build the same records.

use super::camera_source::CameraSource;
use super::hints::hint_record;
use super::solvers::{BACKEND_CPU, Decoded, Global, Solvers};
use crate::error::error;
use crate::io::frame::Frame;
use crate::record::{Record, Timing};
use crate::solve::detect;
use crate::solve::driver::{identify_list_cpu, solve_frame_cpu};
use crate::solve::{Outcome, Solution, Solver, Unsolved};
use crate::streaks::{self, fit::StreakFit};
use std::time::Instant;

impl Solvers {
    /// The record of a solved or unsolved frame (with its streaks under `--streaks`), and its
    /// products when asked for.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn record(
        &self,
        solver: Option<&Solver>,
        d: &Decoded,
        frame: &Frame,
        sol: &Solution,
        found: Option<&[StreakFit]>,
        timing: Timing,
        backend: &str,
    ) -> Record {
        let mut r = match solver {
            Some(s) => s.record(&d.name, sol, timing, backend),
            // No camera: the outcome is unsolved, said as Solver::record says it.
            None => Record {
                reason: match sol.outcome {
                    Outcome::Unsolved(reason) => Some(reason.to_string()),
                    Outcome::Solved(..) => None,
                },
                stars_detected: Some(sol.detections.len()),
                timing_ms: timing,
                ..Record::empty(&d.name, backend)
            },
        };
        r.warnings.extend(d.warnings.iter().cloned());
        let (hint, notes) = self.hint_and_notes(d, frame);
        r.warnings.extend(notes);
        r.hint = hint.map(|h| hint_record(&h, &r));
        // A solved frame's catalog says which tracks are chains of its stars.
        let found = found.map(|f| streaks::catalog_chain::off_catalog_chains(f, sol));
        let found = found.as_deref();
        if let (Some(opts), Some(found)) = (&self.streaks, found) {
            let size = (frame.width, frame.height);
            let (records, warnings) = streaks::reduce::records(found, sol, &d.keywords, size, opts);
            for w in &warnings {
                tracing::warn!("{}: {w}", d.name);
            }
            r.warnings.extend(warnings);
            r.streaks = Some(records);
        }
        let drawn = found.unwrap_or_default();
        if let Err(e) = self.products.write(&d.name, &d.path, frame, sol, drawn) {
            // The solution stands; the user learns which file is missing and why.
            tracing::warn!("{}: {e:#}", d.name);
            r.warnings.push(format!("{e:#}"));
        }
        r
    }

    /// Solve a decoded frame on the CPU: one record.
    pub fn solve_cpu(&self, d: Decoded) -> Record {
        let frame = match &d.frame {
            Ok(f) => f,
            Err(e) => return self.error_record(&d.name, e, BACKEND_CPU),
        };
        if matches!(self.camera, CameraSource::None) {
            return self.streaks_only(&d, frame);
        }
        // A frame with a hint needs the lost-in-space solver (its distance table: for a deep
        // catalog the largest thing a run builds) only when its region does not solve it.
        let scale = self.header_scale(&d);
        let mut record = if let Some(r) = self.regional(&d, frame) {
            let global = Global::Lazy(self, (frame.width, frame.height), scale.clone());
            solve_with(self, Some(&r), &global, &d)
        } else {
            match self.get_scaled(frame.width, frame.height, scale.as_ref()) {
                Ok(s) => solve_with(self, None, &Global::Ready(s), &d),
                Err(e) => self.error_record(&d.name, &e, BACKEND_CPU),
            }
        };
        record.pixel_scale = scale.map(|s| crate::record::PixelScaleRecord {
            arcsec_per_px: s.arcsec_per_px,
            pixel_aspect: s.pixel_aspect,
            source: s.keywords.to_string(),
        });
        record
    }

    /// Identify stars the caller detected in a `width` × `height` frame (`stars`: pixel
    /// positions with fluxes; sorted here brightest first, as detection hands them on): the
    /// record the frame would get with these detections, without hints, streaks or products,
    /// which need the pixels.
    pub fn solve_detections(
        &self,
        name: &str,
        size: (u32, u32),
        stars: Vec<detect::Detection>,
        epoch: Option<f64>,
    ) -> Record {
        self.identify_detections(name, size, stars, epoch, 0.0).0
    }

    /// [`Solvers::solve_detections`], with the solution (None when there is no solver for
    /// the size: the record is an error); `read_ms` is the time the stars took to read.
    pub(crate) fn identify_detections(
        &self,
        name: &str,
        (width, height): (u32, u32),
        mut stars: Vec<detect::Detection>,
        epoch: Option<f64>,
        read_ms: f64,
    ) -> (Record, Option<Solution>) {
        let solver = match self.get(width, height) {
            Ok(s) => s,
            Err(e) => return (self.error_record(name, &e, BACKEND_CPU), None),
        };
        let t0 = Instant::now();
        stars.sort_by(|a, b| b.flux.total_cmp(&a.flux));
        let sol = solver.identify(stars, epoch);
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let timing = Timing::of(read_ms, 0.0, ms);
        (solver.record(name, &sol, timing, BACKEND_CPU), Some(sol))
    }

    /// A frame without a camera: its streaks through the header's WCS, its stars detected
    /// (and kept off the streaks) but not identified.
    fn streaks_only(&self, d: &Decoded, frame: &Frame) -> Record {
        let t0 = Instant::now();
        let s = &self.settings.detect;
        let p = detect::params(frame, s);
        let (blobs, found) = match &self.streaks {
            Some(o) => streaks::detect_cpu(frame, &p, &o.settings, s.k_sigma),
            None => (detect::blobs_cpu(frame, &p), Vec::new()),
        };
        let sol = Solution {
            detections: detect::stars(frame, &blobs, s),
            outcome: Outcome::Unsolved(Unsolved::NoCamera),
            epoch: d.epoch,
        };
        let detect_ms = t0.elapsed().as_secs_f64() * 1e3;
        let timing = Timing::of(d.decode_ms, detect_ms, 0.0);
        self.record(None, d, frame, &sol, Some(&found), timing, BACKEND_CPU)
    }
}

/// Solve a decoded frame on the CPU: within its hinted region first when `regional` is given,
/// then lost-in-space through `global`.
pub(super) fn solve_with(
    solvers: &Solvers,
    regional: Option<&Solver>,
    global: &Global,
    d: &Decoded,
) -> Record {
    let frame = decoded_frame(d);
    // Either solver of the size gives detection's settings and makes the record (they share
    // the camera); a lazy global is only made when every frame has a region.
    let Some(solver) = regional.or(global.ready()) else {
        return solvers.error_record(&d.name, &error!(Internal, "no solver"), BACKEND_CPU);
    };
    let (sol, found, detect_ms, identify_ms) = match &solvers.streaks {
        None => {
            let (sol, detect_ms, identify_ms) = solve_frame_cpu(
                frame,
                &[regional],
                || global.solver(),
                &solver.settings.detect,
                d.epoch,
            );
            (sol, None, detect_ms, identify_ms)
        }
        Some(o) => {
            // Streaks are taken out of star detection first: no second detection stage.
            let t0 = Instant::now();
            let s = &solver.settings.detect;
            let p = detect::params(frame, s);
            let (blobs, found) = streaks::detect_cpu(frame, &p, &o.settings, s.k_sigma);
            let dets = detect::stars(frame, &blobs, s);
            let t1 = Instant::now();
            let sol = identify_list_cpu(regional, || global.solver(), dets, d.epoch);
            let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
            (sol, Some(found), ms(t0, t1), ms(t1, Instant::now()))
        }
    };
    let timing = Timing::of(d.decode_ms, detect_ms, identify_ms);
    solvers.record(
        Some(solver),
        d,
        frame,
        &sol,
        found.as_deref(),
        timing,
        BACKEND_CPU,
    )
}

/// The frame of a decoded input that was grouped for solving (only decoded ones are).
pub(super) fn decoded_frame<'d>(d: &'d Decoded) -> &'d Frame<'d> {
    d.frame.as_ref().expect("grouped frames decoded")
}
