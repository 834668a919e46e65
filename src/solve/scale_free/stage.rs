//! The scale-free pass as a stage of a [`Solver`]: the rounds of a frame's quads looked up,
//! checked, refined and judged against the pass's share of the false-match budget.

use super::super::bands::scaled;
use super::super::detect::Detection;
use super::super::outcome::Outcome;
use super::super::refine::{self, CameraFit, RefineSettings};
use super::super::solver::Solver;
use super::check::permutations;
use super::{
    Checked, Hypothesis, Lookup, MAX_PATTERNS, MAX_REFINED, Quad, ScaleFree, lookup, rounds_for,
};
use crate::camera::Camera;
use crate::catalog::patterns;
use crate::cpu::pattern::Rows;

/// How a round of the pass ended.
enum RoundEnd {
    Solved(Box<Outcome>),
    /// A solution passed the test but matched too few stars: the frame is left to the vote.
    LeftToVote,
    Nothing,
}

impl Solver {
    /// The rounds of the pass for a frame of `n` detections (see [`rounds_for`],
    /// [`PassLimits::rounds`]).
    pub fn scale_free_rounds(&self, n: usize) -> usize {
        let most = self
            .scale_free
            .as_ref()
            .map_or(usize::MAX, |sf| sf.limits.rounds);
        rounds_for(n).min(most)
    }

    /// Whether a frame goes through the scale-free pass on both detection stages (and on its
    /// point sources) before any scale walk (the driver's step 3): with a searched scale, whose
    /// walk takes seconds. A known scale's passes take milliseconds: each detection stage has
    /// the pass and then the vote.
    pub fn scale_free_first(&self) -> bool {
        self.scale_free.is_some()
            && self.settings.scale_range.is_some()
            && self.detection_stages() > 1
    }

    /// The queries of a frame's `rounds` of the scale-free pass; None when the solver has no
    /// pattern index (a known scale) or the frame has too few stars.
    pub fn scale_free_lookup(
        &self,
        detections: &[Detection],
        rounds: std::ops::Range<usize>,
    ) -> Option<Lookup> {
        if self.scale_free.is_none() || detections.len() < 4 {
            return None;
        }
        // The focal-length factors looked up for: the searched range, or the camera's own.
        let range = self.settings.scale_range.unwrap_or((1.0, 1.0));
        Some(lookup(
            detections,
            &self.camera,
            range,
            self.settings.identify.pair_tol_px,
            rounds,
        ))
    }

    /// The scale-free pass after the lookup (`rows[q]` answers `lookup.queries[q]`): round
    /// by round (those the lookup holds: some or all of the frame's), the quad hypotheses that
    /// pass the geometric checks, each refined in turn (the first [`MAX_REFINED`] of a round);
    /// the first accepted concludes as the vote's solutions do. `checked` is what the frame's
    /// earlier lookups checked and refined ([`MAX_PATTERNS`], `max_refined`). None when none
    /// is accepted.
    pub fn finish_scale_free(
        &self,
        detections: &[Detection],
        lookup: &Lookup,
        rows: &[Rows],
        epoch: Option<f64>,
        checked: &mut Checked,
    ) -> Option<Outcome> {
        let rounds = self.scale_free_rounds(detections.len());
        let sf = self.scale_free.as_ref()?;
        if checked.spent {
            return None;
        }
        for round in 0..rounds {
            let mut quads = lookup.quads.iter().filter(|q| q.round == round).peekable();
            if quads.peek().is_none() {
                continue;
            }
            if checked.refined >= sf.limits.max_refined {
                checked.spent = true;
                break;
            }
            let found: u64 = (quads.clone())
                .flat_map(|q| &rows[q.queries.clone()])
                .map(|r| u64::from(r.end.saturating_sub(r.start)))
                .sum();
            if checked.patterns.saturating_add(found) > MAX_PATTERNS {
                tracing::debug!(
                    "scale-free pass stopped: round {round}'s {found} patterns after {} checked",
                    checked.patterns
                );
                checked.spent = true;
                break;
            }
            checked.patterns += found;
            tracing::debug!("scale-free round {round}: {found} patterns found");
            let end = self.scale_free_round(sf, detections, quads, rows, (rounds, checked), epoch);
            match end {
                RoundEnd::Solved(o) => return Some(*o),
                RoundEnd::LeftToVote => {
                    checked.spent = true;
                    return None;
                }
                RoundEnd::Nothing => {}
            }
        }
        None
    }

    /// One round of the pass: its quads' hypotheses that pass the geometric checks, judged
    /// against the round's share of the false-match budget, of the frame's `rounds`; refined
    /// while `checked.refined` is within the pass's limit (and counted there).
    fn scale_free_round<'a>(
        &self,
        sf: &ScaleFree,
        detections: &[Detection],
        quads: impl Iterator<Item = &'a Quad> + Clone,
        rows: &[Rows],
        (rounds, checked): (usize, &mut Checked),
        epoch: Option<f64>,
    ) -> RoundEnd {
        let perms = permutations();
        let share = sf.limits.share;
        let (lo, hi) = self.settings.scale_range.unwrap_or((1.0, 1.0));
        let refs = &self.bands[sf.band].refs;
        let mut hyps: Vec<Hypothesis> = Vec::new();
        for quad in quads.clone() {
            // The image's chords at the camera's focal length, once a quad has a candidate.
            let mut img1: Option<[f64; 6]> = None;
            for r in &rows[quad.queries.clone()] {
                for row in r.start as usize..(r.end as usize).min(sf.index.len()) {
                    let ids = sf.index.quads[row];
                    let img1 = *img1.get_or_insert_with(|| {
                        let c = &self.camera;
                        patterns::chords(
                            &quad
                                .stars
                                .map(|i| c.pixel_to_vector(detections[i].x, detections[i].y)),
                        )
                    });
                    if let Some(h) =
                        self.check_quad(detections, quad.stars, &img1, ids, refs, (lo, hi), &perms)
                    {
                        hyps.push(h);
                    }
                }
            }
        }
        tracing::debug!(
            "scale-free round: {} quads, {} hypotheses pass the checks",
            quads.count(),
            hyps.len()
        );
        if hyps.is_empty() {
            return RoundEnd::Nothing;
        }
        // Every hypothesis of the round, times its rounds, judged against the pass's share of
        // the budget (of each search and detection stage of the frame, as the vote's are).
        let hypotheses = (hyps.len() as u64).saturating_mul(
            rounds as u64
                * share
                * self.settings.searches
                * self.detection_stages()
                * self.parities(),
        );
        let refinable = sf.limits.max_refined.saturating_sub(checked.refined);
        for h in hyps.iter().take(MAX_REFINED.min(refinable)) {
            checked.refined += 1;
            let (mut camera, band, rs) = self.scale_free_camera(h.scale);
            camera.mirrored ^= h.mirrored;
            let refs = self.bands[band].refs_at(epoch);
            let Some(refined) = refine::refine(h.r, detections, &refs, &camera, hypotheses, 4, &rs)
            else {
                continue;
            };
            tracing::debug!(
                "scale-free quad {:?} = {:?} at scale {:.4}: {} matched of {} in view, P(false) {:.1e}",
                h.stars,
                h.refs,
                h.scale,
                refined.matches.len(),
                refined.in_view,
                refined.false_match_prob
            );
            if refined.false_match_prob <= self.settings.refine.max_false_prob {
                let could = refined.in_view.min(detections.len());
                if (refined.matches.len() as f64) < sf.limits.min_completeness * could as f64 {
                    tracing::debug!(
                        "scale-free: {} of {could} stars matched, left to the vote",
                        refined.matches.len()
                    );
                    return RoundEnd::LeftToVote;
                }
                return RoundEnd::Solved(Box::new(
                    self.conclude(detections, band, &rs, refined, epoch),
                ));
            }
        }
        RoundEnd::Nothing
    }

    /// A quad's focal length as the scale walk's pass at that scale takes it: the camera, its
    /// band, and the refinement settings (the focal length fitted when the scale is searched).
    fn scale_free_camera(&self, scale: f64) -> (Camera, usize, RefineSettings) {
        let mut rs = self.settings.refine;
        if self.settings.scale_range.is_some() && rs.fit == CameraFit::None {
            rs.fit = CameraFit::Scale;
        }
        (scaled(&self.camera, scale), self.band_of(scale), rs)
    }
}
