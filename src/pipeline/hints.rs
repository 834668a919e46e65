//! Pointing hints in a run (`--hint`): which frames have one, the solver of each hint's
//! region, and identification that tries the region before lost-in-space, whose solver is
//! built only when a frame needs it.

use super::{Decoded, SharedSolver, Solvers};
use crate::io::fits::scale::PixelScale;
use crate::io::frame::Frame;
use crate::record::Record;
use crate::sky::hint::{Hint, HintSource, header_hint};
use crate::solve::detect::Detection;
use crate::solve::hinted::regional_solver;
use crate::solve::{Outcome, Solution, Solver};

impl Solvers {
    /// Use pointing hints: a frame with one is solved within its region first, and
    /// lost-in-space after; both searches then share the false-match budget.
    pub fn with_hints(mut self, hint: HintSource) -> Solvers {
        self.hint = Some(hint);
        self.settings.searches = 2;
        self
    }

    /// The pointing hint of a frame, if the run uses hints and the frame has one.
    pub fn hint_of(&self, d: &Decoded, frame: &Frame) -> Option<Hint> {
        self.hint_and_notes(d, frame).0
    }

    /// [`Solvers::hint_of`], and with `--hint header` why the frame's pointing keywords that
    /// were not used were not (for its record's warnings).
    pub fn hint_and_notes(&self, d: &Decoded, frame: &Frame) -> (Option<Hint>, Vec<String>) {
        match self.hint {
            None => (None, Vec::new()),
            Some(HintSource::Fixed(h)) => (Some(h), Vec::new()),
            Some(HintSource::Header { radius_deg }) => header_hint(
                &|k| d.keywords.get(k).cloned(),
                (frame.width, frame.height),
                radius_deg,
            ),
        }
    }

    /// The solver of a frame's hinted region, if it has a hint (None also when the region
    /// holds too few catalog stars: the frame is then solved lost-in-space alone).
    pub fn regional(&self, d: &Decoded, frame: &Frame) -> Option<Solver> {
        let hint = self.hint_of(d, frame)?;
        let scale = self.header_scale(d);
        let camera = self
            .camera
            .camera_for(frame.width, frame.height, scale.as_ref())
            .ok()?;
        match regional_solver(&self.catalog, &camera, &self.settings, &hint) {
            Ok(s) => Some(s),
            Err(e) => {
                tracing::debug!(
                    "{}: no search within the hint ({}): {e:#}",
                    d.name,
                    hint.source
                );
                None
            }
        }
    }
}

/// A frame's lost-in-space solver: at hand, or the size's, built when first needed.
pub(crate) enum Global<'a> {
    Ready(&'a Solver),
    Lazy(&'a Solvers, (u32, u32), Option<PixelScale>),
}

impl Global<'_> {
    /// The solver when it is at hand (not built on demand).
    pub(crate) fn ready(&self) -> Option<&Solver> {
        match self {
            Global::Ready(s) => Some(s),
            Global::Lazy(..) => None,
        }
    }

    /// The solver, built now if it is lazy and was not yet; None when the size has none (the
    /// catalog or camera cannot make one: the message is in the records of frames without a
    /// hint).
    pub(crate) fn solver(&self) -> Option<GlobalSolver<'_>> {
        match self {
            Global::Ready(s) => Some(GlobalSolver::Borrowed(s)),
            Global::Lazy(solvers, (w, h), scale) => {
                let shared = solvers.get_scaled(*w, *h, scale.as_ref());
                match shared.as_ref() {
                    Ok(_) => Some(GlobalSolver::Shared(shared)),
                    Err(e) => {
                        tracing::debug!("no lost-in-space search after the hint's: {e}");
                        None
                    }
                }
            }
        }
    }
}

/// A lost-in-space solver at hand: borrowed, or the size's shared one (only ever a built one).
pub(crate) enum GlobalSolver<'a> {
    Borrowed(&'a Solver),
    Shared(SharedSolver),
}

impl std::ops::Deref for GlobalSolver<'_> {
    type Target = Solver;

    fn deref(&self) -> &Solver {
        match self {
            GlobalSolver::Borrowed(s) => s,
            GlobalSolver::Shared(shared) => shared
                .as_ref()
                .as_ref()
                .expect("Global::solver wraps built solvers only"),
        }
    }
}

/// Identify within a frame's hinted region first (when it has one), then lost-in-space.
pub(crate) fn identify_hinted(
    regional: Option<&Solver>,
    global: &Global,
    detections: Vec<Detection>,
    epoch: Option<f64>,
) -> Solution {
    // The detections are copied only for a frame that has a region.
    let in_region = match regional {
        Some(r) => {
            let sol = r.identify(detections.clone(), epoch);
            if matches!(sol.outcome, Outcome::Solved(..)) {
                return sol;
            }
            Some(sol)
        }
        None => None,
    };
    match global.solver() {
        Some(g) => g.identify(detections, epoch),
        None => in_region.unwrap_or_else(|| unsolved(detections, epoch)),
    }
}

fn unsolved(detections: Vec<Detection>, epoch: Option<f64>) -> Solution {
    Solution {
        detections,
        outcome: Outcome::Unsolved("no_consistent_match"),
        epoch,
    }
}

/// A record's account of the hint its frame had: where, from which keywords, and how far the
/// solution lies from it.
pub(super) fn hint_record(h: &Hint, r: &Record) -> crate::record::HintRecord {
    let offset_deg = r.ra_deg.zip(r.dec_deg).map(|(ra, dec)| {
        let a = crate::catalog::radec_to_vector(ra, dec);
        let b = crate::catalog::radec_to_vector(h.ra_deg, h.dec_deg);
        crate::camera::angle(&a, &b).to_degrees()
    });
    crate::record::HintRecord {
        ra_deg: h.ra_deg,
        dec_deg: h.dec_deg,
        radius_deg: h.radius_deg,
        source: h.source.to_string(),
        offset_deg,
    }
}
