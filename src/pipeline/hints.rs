//! Pointing hints in a run (`--hint`): which frames have one, the solver of each hint's
//! region, and identification that tries the region before lost-in-space, whose solver is
//! built only when a frame needs it.

use super::solvers::{Decoded, Solvers};
use crate::io::frame::Frame;
use crate::record::Record;
use crate::sky::hint::{Hint, HintSource, header_hint};
use crate::solve::Solver;
use crate::solve::hinted::regional_solver;

impl Solvers {
    /// Use pointing hints: a frame with one is solved within its region first, and
    /// lost-in-space after; both searches then share the false-match budget.
    pub fn with_hints(mut self, hint: HintSource) -> Solvers {
        self.hint = Some(hint);
        self.settings.searches = 2;
        self
    }

    /// The pointing hint of a frame, if the run uses hints and the frame has one, and with
    /// `--hint header` why the frame's pointing keywords that were not used were not (for its
    /// record's warnings).
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
        let hint = self.hint_and_notes(d, frame).0?;
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
