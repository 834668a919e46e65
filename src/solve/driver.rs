//! The identification flow of one frame on the CPU: the scale-free pass, the walk of passes
//! and their fallbacks, and the detection retry.

use super::detect::{self, Detection};
use super::identify;
use super::radial::Method;
use super::scale_free::{Checked, rows_cpu};
use super::solver::{Outcome, Solution, Solver};
use crate::io::frame::Frame;
use std::time::Instant;

impl Solver {
    /// Identify the stars of a detection list, voting on the CPU: the passes in turn until
    /// one solves.
    pub fn identify(&self, detections: Vec<Detection>, epoch: Option<f64>) -> Solution {
        if let Some(o) = self.identify_scale_free(&detections, epoch) {
            return Solution {
                detections,
                outcome: o,
                epoch,
            };
        }
        self.identify_walk(detections, epoch)
    }

    /// The passes of identification after the scale-free pass: the vote (or radial features,
    /// or triangles) at each scale of the walk, then the triangle fallbacks of the passes whose
    /// vote failed, in the same order ([`Solver::fallback`]).
    pub fn identify_walk(&self, detections: Vec<Detection>, epoch: Option<f64>) -> Solution {
        let mut outcome = self.unsolved_before_walk(&detections);
        let mut fallbacks = Vec::new();
        for h in 0..self.passes.len() {
            let Some(p) = self.prepare(&detections, h) else {
                continue;
            };
            let band = &self.bands[p.band];
            outcome = match (p.method, &band.radial) {
                (Method::Triangle, _) => self.finish_triangle_method(&detections, &p, epoch),
                (Method::Radial, Some(t)) => {
                    let image = crate::solve::radial::image_features(&p.vectors[..p.n_vote], t);
                    let found = crate::solve::radial::candidates_cpu(
                        t,
                        &image,
                        crate::solve::radial::CANDIDATES,
                    );
                    self.finish_radial(&detections, &p, &found, epoch)
                }
                _ => {
                    let voted =
                        identify::vote_cpu(band.table(), &p.ranges, p.n_vote, band.refs.len(), p.k);
                    let o = self.finish(&detections, &p, &voted, epoch);
                    if !matches!(o, Outcome::Solved(..)) && Self::falls_back(&p) {
                        fallbacks.push((h, p));
                    }
                    o
                }
            };
            if matches!(outcome, Outcome::Solved(..)) {
                tracing::debug!("solved by pass {h} ({:?})", self.passes[h].kind);
                return Solution {
                    detections,
                    outcome,
                    epoch,
                };
            }
        }
        if let Some(o) = self.fall_back(&detections, &fallbacks, epoch) {
            outcome = o;
        }
        Solution {
            detections,
            outcome,
            epoch,
        }
    }

    /// Solve a decoded frame on the CPU.
    pub fn solve_frame(&self, frame: &Frame) -> (Solution, f64, f64) {
        self.solve_frame_at(frame, None)
    }

    /// Solve a decoded frame on the CPU, with its own observation epoch if it has one.
    pub fn solve_frame_at(&self, frame: &Frame, epoch: Option<f64>) -> (Solution, f64, f64) {
        if self.scale_free_first() {
            return self.solve_frame_scale_free_first(frame, self, epoch);
        }
        self.solve_frame_with(frame, |dets| self.identify(dets, epoch))
    }

    /// Detect, identify with `identify`, and detect again with the matched filter when that
    /// does not solve (the detection retry), identifying again when that finds a star the
    /// first detection did not ([`detect::adds_stars`]). Returns the solution, detection and
    /// identification times (ms).
    pub fn solve_frame_with(
        &self,
        frame: &Frame,
        identify: impl Fn(Vec<Detection>) -> Solution,
    ) -> (Solution, f64, f64) {
        let t0 = Instant::now();
        let detector = detect::Detector::new(frame, &self.settings.detect);
        let dets = detector.detect();
        let t1 = Instant::now();
        let sol = identify(dets);
        let t2 = Instant::now();
        let (mut detect_ms, identify_ms) = ((t1 - t0).as_secs_f64(), (t2 - t1).as_secs_f64());
        if matches!(sol.outcome, Outcome::Unsolved(_)) && self.detection_stages() > 1 {
            let t3 = Instant::now();
            let filtered = detector.detect_filtered();
            detect_ms += t3.elapsed().as_secs_f64();
            if !detect::adds_stars(&sol.detections, &filtered) {
                return (sol, detect_ms * 1e3, identify_ms * 1e3);
            }
            let t4 = Instant::now();
            let again = identify(filtered);
            let identify_ms = identify_ms + t4.elapsed().as_secs_f64();
            if matches!(again.outcome, Outcome::Solved(..)) {
                return (again, detect_ms * 1e3, identify_ms * 1e3);
            }
            return (sol, detect_ms * 1e3, identify_ms * 1e3);
        }
        (sol, detect_ms * 1e3, identify_ms * 1e3)
    }

    /// The scale-free pass round by round: a round's lookup only when
    /// the ones before it did not solve (the GPU looks them all up at once; the records are
    /// the same). The outcome when it solved.
    pub fn identify_scale_free(
        &self,
        detections: &[Detection],
        epoch: Option<f64>,
    ) -> Option<Outcome> {
        let sf = self.scale_free.as_ref()?;
        let mut checked = Checked::default();
        for round in 0..self.scale_free_rounds(detections.len()) {
            let lookup = self.scale_free_lookup(detections, round..round + 1)?;
            let rows = rows_cpu(sf, &lookup);
            let found =
                self.finish_scale_free_within(detections, &lookup, &rows, epoch, &mut checked);
            if found.is_some() || checked.spent {
                return found;
            }
        }
        None
    }

    /// Detect with this solver's settings and identify with `id`, the scale-free pass first on
    /// both detection stages (a sparse frame the pass misses may be solved by it from the
    /// matched filter's detections, in milliseconds, where the walk takes seconds) and, where
    /// no walk follows (`Settings::walks`), on the first stage's point sources
    /// (`detect::point_sources`: blends left out), then the
    /// walk on each (on the matched filter's only when they hold a new star, as
    /// `solve_frame_with`). Solutions are those of `solve_frame_with` whenever the pass solves
    /// the first stage or nothing solves the frame. Returns the solution, detection and
    /// identification times (ms).
    pub fn solve_frame_scale_free_first(
        &self,
        frame: &Frame,
        id: &Solver,
        epoch: Option<f64>,
    ) -> (Solution, f64, f64) {
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        let detector = detect::Detector::new(frame, &self.settings.detect);
        let dets = detector.detect();
        let mut detect_ms = ms(t);
        let t = Instant::now();
        let found = id.identify_scale_free(&dets, epoch);
        let mut identify_ms = ms(t);
        if let Some(outcome) = found {
            let sol = Solution {
                detections: dets,
                outcome,
                epoch,
            };
            return (sol, detect_ms, identify_ms);
        }
        let t = Instant::now();
        let filtered = detector.detect_filtered();
        detect_ms += ms(t);
        let t = Instant::now();
        // Only where no walk follows: the stage is judged as the pass is, within the half of
        // the false-match budget that the walk would have had.
        let points = || {
            let s = &self.settings.detect;
            (!id.settings.walks())
                .then(|| detect::point_sources(&dets, frame.width, frame.height, s))
                .flatten()
        };
        let solution = match id.identify_scale_free(&filtered, epoch) {
            Some(outcome) => Solution {
                detections: filtered,
                outcome,
                epoch,
            },
            None => match points().and_then(|p| Some((id.identify_scale_free(&p, epoch)?, p))) {
                Some((outcome, points)) => Solution {
                    detections: points,
                    outcome,
                    epoch,
                },
                None => {
                    let adds = detect::adds_stars(&dets, &filtered);
                    let sol = id.identify_walk(dets, epoch);
                    if matches!(sol.outcome, Outcome::Solved(..)) || !adds {
                        sol
                    } else {
                        let again = id.identify_walk(filtered, epoch);
                        if matches!(again.outcome, Outcome::Solved(..)) {
                            again
                        } else {
                            sol
                        }
                    }
                }
            },
        };
        identify_ms += ms(t);
        (solution, detect_ms, identify_ms)
    }
}
