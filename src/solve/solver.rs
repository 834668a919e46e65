//! A camera's [`Solver`]: its bands, passes and pattern index, built once, and the stages of a
//! pass after its kernel (verify → attitude → refine → accept, the triangle fallback, the
//! deeper check), which share the [`Prepared`] state and the false-match budget. Which frames
//! go through which pass, and in what order, is the driver's (`driver.rs`).
//!
//! Scale bands and passes are in `bands.rs`, the automatic magnitude limits in `mag_limit.rs`,
//! the record of a solution in `report.rs`, the scale-free pass in `scale_free.rs` and
//! `scale_free/stage.rs`.

use super::attitude::wahba_parity;
use super::bands::{
    Band, Deeper, Pass, PassKind, RETRY_VOTE_STARS, SCALE_STEP, SPREAD_TRIANGLE_STARS, STAGES,
    WIDE_MATCH_RADIUS_PX, WIDE_PAIR_TOL_PX, band_for, scale_bands, scale_hypotheses, scaled,
    spread_order,
};
use super::detect::Detection;
use super::identify::{self, IdentifySettings};
use super::mag_limit::{SHALLOW_STARS_IN_VIEW, mag_limit_in};
use super::outcome::{Outcome, Unsolved};
use super::refine::{self, RefineSettings, Refined};
use super::settings::{Parity, Settings};
use super::triangle;
use crate::camera::Camera;
use crate::catalog::{Catalog, RefCatalog};
use crate::error::Result;
use crate::solve::radial::Method;
use nalgebra::Vector3;
use std::sync::Arc;

/// A camera with its catalog selections and distance tables, ready to solve frames.
pub struct Solver {
    pub camera: Camera,
    pub settings: Settings,
    /// One, unless a scale search spans more than `BAND_RATIO`.
    pub bands: Vec<Band>,
    /// Focal-length factors tried, nearest to the camera's first (just 1.0 for a known scale).
    pub scales: Vec<f64>,
    /// The hypotheses tried in turn until one solves: every scale with the settings, then
    /// (when `retry`) every scale with more voting stars, with voters spread over the frame,
    /// the shallow pass (when there is one), and with wide tolerances; all of these for each
    /// of the method's identifiers in turn (`--method radial`: radial features, then the
    /// vote). Empty when the scale-free pass searches a scale wider than [`WALK_MAX_RATIO`]
    /// alone (see [`Settings::walks`]).
    pub passes: Vec<Pass>,
    /// When the scale is searched and the magnitude limit left to the solver: the catalog,
    /// to check each solution against as deep a selection as its fitted field calls for.
    deeper: Option<Deeper>,
    /// The band of the shallow pass, when there is one (the last of `bands`).
    pub shallow_band: Option<usize>,
    /// When the scale is searched: the pattern index of the scale-free first pass.
    pub scale_free: Option<super::scale_free::ScaleFree>,
}

/// A frame's input to the vote.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// The camera at the scale tried.
    pub camera: Camera,
    /// The band of that scale (an index into `Solver::bands`): its table votes.
    pub band: usize,
    /// Camera-frame direction of every detection, in the pass's voting order (brightness,
    /// or spread over the frame): the first `n_vote` vote.
    pub vectors: Vec<Vector3<f64>>,
    /// Pair ranges of the first `n_vote` of `vectors`.
    pub ranges: Vec<crate::cpu::vote::PairRange>,
    pub n_vote: usize,
    /// Candidates kept per star.
    pub k: usize,
    /// The first this many of `vectors` form the triangle fallback's triangles (fewer than 4:
    /// no fallback).
    pub triangle_stars: usize,
    /// The identification settings of this pass (tolerances).
    pub identify: IdentifySettings,
    /// Refinement settings of this pass (match radius, what is fitted).
    pub refine: RefineSettings,
    /// The identifier of this pass.
    pub method: Method,
}

impl Solver {
    pub fn new(catalog: &Catalog, camera: Camera, settings: Settings) -> Result<Solver> {
        let mut edges = scale_bands(settings.scale_range);
        if settings.mag_limit.is_some() {
            // The magnitude limit given holds for every scale: one band.
            edges = vec![(edges[0].0, edges[edges.len() - 1].1)];
        }
        // One band takes the camera given as its middle; more take their own.
        let middle = |(lo, hi): (f64, f64)| {
            if edges.len() == 1 {
                1.0
            } else {
                (lo * hi).sqrt()
            }
        };
        // With a scale-free pass most frames never vote: the bands' tables are loaded when the
        // first frame does (the pattern index is about a fifth of their size).
        let scale_free_on = settings.scale_free_on();
        let mut bands = edges
            .iter()
            .map(|&e| {
                Band::new(
                    catalog,
                    &camera,
                    &settings,
                    e,
                    middle(e),
                    None,
                    scale_free_on,
                )
            })
            .collect::<Result<Vec<Band>>>()?;
        // The shallow pass's band: with a known scale and the magnitude limit left to the
        // solver, when it is shallower than the automatic one by half a magnitude or more.
        let shallow_mag = mag_limit_in(catalog, &camera, SHALLOW_STARS_IN_VIEW, settings.sky_sr);
        let shallow = (settings.retry
            && settings.scale_range.is_none()
            && settings.mag_limit.is_none()
            && shallow_mag <= bands[0].refs.selection.mag_limit - 0.5)
            .then(|| {
                Band::new(
                    catalog,
                    &camera,
                    &settings,
                    (1.0, 1.0),
                    1.0,
                    Some(shallow_mag),
                    false,
                )
            })
            .transpose()?;
        let main_bands = bands.len();
        bands.extend(shallow);
        let band_of = |scale: f64| band_for(&bands[..main_bands], scale);
        let scales_at = |step| match settings.scale_range {
            Some((lo, hi)) => scale_hypotheses(lo, hi, step),
            None => vec![1.0],
        };
        let scales = scales_at(SCALE_STEP);
        let kinds = [
            PassKind::First,
            PassKind::MoreStars,
            PassKind::Spread,
            PassKind::Wide,
        ];
        let mut passes: Vec<Pass> = kinds[..if settings.retry { kinds.len() } else { 1 }]
            .iter()
            .flat_map(|&kind| {
                scales_at(kind.scale_step())
                    .into_iter()
                    .map(move |scale| Pass {
                        scale,
                        band: band_of(scale),
                        kind,
                        method: settings.method,
                    })
            })
            .collect();
        if bands.len() > main_bands {
            // First, by what each pass costs and buys (docs/speed.md, "Fail fast" and
            // "Triangles after the votes, the shallow pass first"): its table is a twelfth of
            // the first pass's and loaded with the solver, its vote takes a fraction of a
            // millisecond, and once each pass's triangles wait for every vote it solved all 67
            // of 300 independent 10° frames that a vote solves, 25 of which the first pass
            // solved before it (the same stars, the same attitudes within 1.3"). A frame it
            // does not solve goes on to the others as before; the false-match test counts the
            // same passes either way.
            passes.insert(
                0,
                Pass {
                    scale: 1.0,
                    band: main_bands,
                    kind: PassKind::Shallow,
                    method: settings.method,
                },
            );
        }
        // The walk again for each fallback identifier, after every pass of the one before.
        let passes: Vec<Pass> = settings
            .method
            .identifiers()
            .iter()
            .flat_map(|&method| passes.iter().map(move |&p| Pass { method, ..p }))
            .collect();
        let passes = if settings.walks() { passes } else { Vec::new() };
        let shallow_band = (bands.len() > main_bands).then_some(main_bands);
        let scale_free = if scale_free_on {
            // The quads name the stars of the narrowest field's band, the deepest.
            super::scale_free::ScaleFree::build(
                catalog,
                &camera,
                &settings,
                &bands,
                main_bands - 1,
            )?
        } else {
            None
        };
        Ok(Solver {
            scale_free,
            camera,
            settings,
            shallow_band,
            bands,
            scales,
            passes,
            deeper: (settings.scale_range.is_some() && settings.mag_limit.is_none())
                .then(|| Deeper::new(catalog)),
        })
    }

    /// What the vote needs from a detection list for pass `h` (an index into `passes`): the
    /// stars' directions and the pair ranges of the brightest; None when there are too few
    /// stars to identify, or the pass would add no star to the vote.
    pub fn prepare(&self, detections: &[Detection], h: usize) -> Option<Prepared> {
        let pass = self.passes[h];
        let mut s = self.settings.identify;
        let mut rs = self.settings.refine;
        if detections.len() < 3 {
            return None;
        }
        if let Some(l) = self.scale_free.as_ref().map(|sf| sf.limits)
            && !l.rest_by_count
        {
            // The pass took 1 / share of the budget: the passes keep the rest.
            rs.max_false_prob *= 1.0 - 1.0 / l.share as f64;
        }
        if !self.runs_on(pass.kind, detections.len()) {
            return None;
        }
        if pass.kind == PassKind::MoreStars {
            s.vote_stars = RETRY_VOTE_STARS;
        }
        let camera = scaled(&self.camera, pass.scale);
        if self.scales.len() > 1 {
            // Each hypothesis stands for half a step either side of its focal length, and
            // the refinement fits the scale.
            s.scale_tol += pass.kind.scale_step() / 2.0;
            if rs.fit == refine::CameraFit::None {
                rs.fit = refine::CameraFit::Scale;
            }
        }
        if pass.kind == PassKind::Wide {
            s.pair_tol_px = s.pair_tol_px.max(WIDE_PAIR_TOL_PX);
            rs.match_radius_px = rs.match_radius_px.max(WIDE_MATCH_RADIUS_PX);
        }
        let order = match pass.kind {
            PassKind::Spread => spread_order(detections, camera.width, camera.height),
            _ => (0..detections.len()).collect(),
        };
        let vectors: Vec<Vector3<f64>> = order
            .iter()
            .map(|&i| camera.pixel_to_vector(detections[i].x, detections[i].y))
            .collect();
        let n_vote = vectors.len().min(s.vote_stars);
        Some(Prepared {
            ranges: identify::pair_ranges(&vectors[..n_vote], &camera, &s),
            n_vote,
            k: s.candidates_per_star(n_vote),
            triangle_stars: match pass.kind {
                PassKind::Spread => SPREAD_TRIANGLE_STARS,
                // The same brightest stars with the same tolerances as the first pass at this
                // scale: the same triangles, already refused.
                PassKind::MoreStars => 0,
                _ => triangle::TRIANGLE_STARS,
            }
            .min(n_vote),
            vectors,
            camera,
            band: pass.band,
            identify: s,
            refine: rs,
            method: pass.method,
        })
    }

    /// Whether a pass of `kind` runs on a frame of `n` detections: the retries with more
    /// voting stars and with voters spread over the frame need more detections than vote
    /// (spreading would vote with the same stars), the wide retry `wide_min_stars`.
    fn runs_on(&self, kind: PassKind, n: usize) -> bool {
        let vote = self.settings.identify.vote_stars;
        match kind {
            PassKind::MoreStars => n > vote && vote < RETRY_VOTE_STARS,
            PassKind::Spread => n > vote,
            PassKind::Wide => n >= self.settings.wide_min_stars,
            _ => true,
        }
    }

    /// How many passes of identifier `method` a frame of `n` detections can be tried with
    /// (those it runs on, `Solver::runs_on`: the others add no hypothesis to it).
    pub fn passes_for(&self, n: usize, method: Method) -> usize {
        self.passes
            .iter()
            .filter(|p| p.method == method && self.runs_on(p.kind, n))
            .count()
    }

    /// What the false-match test multiplies the hypotheses of one stage of a pass of
    /// identifier `method` by, for a frame of `n` detections: the budget (`max_false_prob`) is
    /// shared evenly by the searches of the frame (a hint's region, lost-in-space), its
    /// detection stages, the method's identifiers (radial features and the vote that falls
    /// back from them take half each), the identifier's passes, and the stages of a pass that
    /// can accept (the vote and its triangle fallback, see `STAGES`; radial features alone).
    /// So the chance that any of them accepts a wrong attitude stays within the whole. The
    /// triangle method, the vote's fallback stage on its own, keeps that stage's share. With the
    /// scale-free pass, which takes `1 / share` of the budget, the passes keep the rest
    /// (`PassLimits`): a searched scale's count twice (the
    /// pass takes half); a known scale's have `prepare` scale their `max_false_prob` instead.
    pub fn hypothesis_factor(&self, n: usize, method: Method) -> u64 {
        let stages = match method {
            Method::Radial => 1,
            Method::Vote | Method::Triangle => STAGES,
        };
        let factor = stages
            * self.settings.method.identifiers().len() as u64
            * self.settings.searches
            * self.detection_stages()
            * self.passes_for(n, method) as u64;
        match self.scale_free.as_ref().map(|sf| sf.limits) {
            Some(l) if l.rest_by_count => factor * l.share / (l.share - 1),
            _ => factor,
        }
    }

    /// The attitudes a vote's or a quad's hypothesis stands for: 2 when the parity is left open
    /// (a triangle's hypotheses are counted for each hand, see [`Solver::triangles_either`]).
    pub fn parities(&self) -> u64 {
        match self.settings.parity {
            Parity::AsCamera => 1,
            Parity::Either => 2,
        }
    }

    /// A triangle search (`search`: hypotheses with the handedness of the directions given,
    /// and how many it counts) for the parity the settings allow: with the parity left open,
    /// for the mirror image too (camera y negated), its hypotheses after the others' and both
    /// counts summed. [`Solver::first_attitude`] then finds each hypothesis's parity.
    pub(crate) fn triangles_either(
        &self,
        vectors: &[Vector3<f64>],
        search: impl Fn(&[Vector3<f64>]) -> (Vec<triangle::Triangle>, u64),
    ) -> (Vec<triangle::Triangle>, u64) {
        let (mut hyps, mut matched) = search(vectors);
        if self.settings.parity == Parity::Either {
            let mirrored: Vec<_> = vectors
                .iter()
                .map(|v| Vector3::new(v.x, -v.y, v.z))
                .collect();
            let (more, n) = search(&mirrored);
            hyps.extend(more);
            matched = matched.saturating_add(n);
        }
        (hyps, matched)
    }

    /// The first attitude of matched directions (`cam` as `camera` sees them) and the camera
    /// it holds for: `camera`, or its mirror image when the parity is left open and the
    /// matched stars fit that better (see [`wahba_parity`]).
    pub(crate) fn first_attitude(
        &self,
        cam: &[Vector3<f64>],
        icrs: &[Vector3<f64>],
        camera: &Camera,
    ) -> Option<(nalgebra::Matrix3<f64>, Camera)> {
        let (r, flipped) = wahba_parity(cam, icrs, self.settings.parity == Parity::Either)?;
        let mut camera = camera.clone();
        camera.mirrored ^= flipped;
        Some((r, camera))
    }

    /// A frame's outcome before any pass of the walk: no consistent match when the scale-free
    /// pass looked it up (four stars or more), too few stars otherwise.
    pub fn unsolved_before_walk(&self, detections: &[Detection]) -> Outcome {
        if self.scale_free.is_some() && detections.len() >= 4 {
            Outcome::Unsolved(Unsolved::NoConsistentMatch)
        } else {
            Outcome::Unsolved(Unsolved::TooFewStars)
        }
    }

    /// Verification, attitude, refinement and acceptance after the vote; refinement uses the
    /// star positions at the frame's `epoch` when it has one. The pass's triangle fallback is
    /// not run here: see [`Solver::fallback`].
    pub fn finish(
        &self,
        detections: &[Detection],
        p: &Prepared,
        voted: &identify::VoteResult,
        epoch: Option<f64>,
    ) -> Outcome {
        let refs = self.bands[p.band].refs_at(epoch);
        match self.finish_vote(detections, p, voted, &refs) {
            Ok(accepted) => self.conclude(detections, p.band, &p.refine, accepted, epoch),
            Err(reason) => Outcome::Unsolved(reason),
        }
    }

    /// Whether a pass whose vote found no solution has a triangle fallback.
    pub fn falls_back(p: &Prepared) -> bool {
        p.triangle_stars >= 4
    }

    /// The triangle fallback of a pass whose vote found no solution (see [`Solver::finish`]),
    /// run once the votes of every pass have failed: a sparse frame's triangles cost several
    /// times its votes, and a later pass's vote (most often the shallow selection's) solves
    /// most frames that an earlier pass's triangles would (docs/speed.md, "Triangles after the
    /// votes, the shallow pass first"). Each stage keeps its share of the false-match budget
    /// whatever the order. None when no triangle is accepted.
    pub fn fallback(
        &self,
        detections: &[Detection],
        p: &Prepared,
        epoch: Option<f64>,
    ) -> Option<Outcome> {
        if !Self::falls_back(p) {
            return None;
        }
        let refs = self.bands[p.band].refs_at(epoch);
        let accepted = self.finish_triangles(detections, p, &refs)?;
        Some(self.conclude(detections, p.band, &p.refine, accepted, epoch))
    }

    /// The triangle fallbacks of the passes whose vote failed (`fallbacks`: each pass's index
    /// and input, in pass order), once no vote has solved the frame: the first accepted.
    pub fn fall_back(
        &self,
        detections: &[Detection],
        fallbacks: &[(usize, Prepared)],
        epoch: Option<f64>,
    ) -> Option<Outcome> {
        fallbacks.iter().find_map(|(h, p)| {
            let o = self.fallback(detections, p, epoch)?;
            tracing::debug!(
                "solved by the triangles of pass {h} ({:?})",
                self.passes[*h].kind
            );
            Some(o)
        })
    }

    /// `--method radial` after stages radial and select: triangles among the candidates
    /// (`radial::triangles`), each refined in turn; the first that passes the false-match
    /// test, which counts every triangle found (for every pass this frame can be tried with,
    /// as the vote's does) and three stars as fixed. Then as the vote's solutions.
    pub fn finish_radial(
        &self,
        detections: &[Detection],
        p: &Prepared,
        found: &identify::VoteResult,
        epoch: Option<f64>,
    ) -> Outcome {
        let refs = self.bands[p.band].refs_at(epoch);
        let vectors = &p.vectors[..p.n_vote];
        let (triangles, _) = self.triangles_either(vectors, |v| {
            let t = crate::solve::radial::triangles(
                &found.candidates,
                found.k,
                &p.ranges,
                v,
                &self.bands[p.band].refs,
                crate::solve::radial::TRIANGLE_STARS,
            );
            let n = t.len() as u64;
            (t, n)
        });
        if triangles.is_empty() {
            return Outcome::Unsolved(Unsolved::NoConsistentMatch);
        }
        match self.first_accepted(detections, p, &refs, &triangles, triangles.len() as u64) {
            Some(a) => self.conclude(detections, p.band, &p.refine, a, epoch),
            None => Outcome::Unsolved(Unsolved::LowConfidence),
        }
    }

    /// `--method triangle`: the triangle fallback's hypotheses on their own (no vote).
    pub fn finish_triangle_method(
        &self,
        detections: &[Detection],
        p: &Prepared,
        epoch: Option<f64>,
    ) -> Outcome {
        match self.fallback(detections, p, epoch) {
            Some(o) => o,
            None if !Self::falls_back(p) => Outcome::Unsolved(Unsolved::TooFewStars),
            None => Outcome::Unsolved(Unsolved::NoConsistentMatch),
        }
    }

    /// An accepted solution, refined again against the deeper selection its field calls for
    /// (or from the shallow band against the main one).
    pub(crate) fn conclude(
        &self,
        detections: &[Detection],
        band: usize,
        rs: &RefineSettings,
        accepted: Refined,
        epoch: Option<f64>,
    ) -> Outcome {
        let again = if Some(band) == self.shallow_band {
            // Found against the shallow selection: the automatic one matches the fainter stars
            // too.
            refine_again(&accepted, detections, self.bands[0].refs_at(epoch), rs)
        } else {
            self.deepen(&accepted, detections, band, rs, epoch)
        };
        match again {
            Some((refined, refs)) => Outcome::Solved(refined, refs),
            None => Outcome::Solved(accepted, self.bands[band].refs_at(epoch)),
        }
    }

    /// After a scale search the reference stars were chosen for the middle of a band, and a
    /// frame at its narrow end holds fewer of them (27 instead of [`AUTO_STARS_IN_VIEW`] for a
    /// band of [`BAND_RATIO`]; 8 at 10° with one selection for 5° to 40°). The accepted
    /// attitude is refined again against the selection its fitted field calls for (see
    /// [`refine_again`]); None = nothing deeper to check against, or the accepted solution
    /// stands.
    pub(crate) fn deepen(
        &self,
        accepted: &Refined,
        detections: &[Detection],
        band: usize,
        rs: &RefineSettings,
        epoch: Option<f64>,
    ) -> Option<(Refined, Arc<RefCatalog>)> {
        let refs = self.deeper.as_ref()?.refs_for(
            &accepted.camera,
            self.settings.sky_sr,
            self.bands[band].refs.selection,
            epoch,
        )?;
        refine_again(accepted, detections, refs, rs)
    }

    /// The vote's path: the consistent set of candidates, Wahba, refinement. The accepted
    /// solution, or why there is none.
    fn finish_vote(
        &self,
        detections: &[Detection],
        p: &Prepared,
        voted: &identify::VoteResult,
        refs: &RefCatalog,
    ) -> Result<Refined, Unsolved> {
        let vectors = &p.vectors;
        let n_vote = voted.candidates.len() / voted.k.max(1);
        let ids = identify::verify(
            voted,
            &vectors[..n_vote],
            &self.bands[p.band].refs,
            &p.camera,
            &p.identify,
        );
        if ids.len() < 2 {
            return Err(Unsolved::NoConsistentMatch);
        }
        let cam: Vec<_> = ids.iter().map(|m| vectors[m.star]).collect();
        let icrs: Vec<_> = ids.iter().map(|m| refs.v(m.ref_id as usize)).collect();
        let (r0, camera) = self
            .first_attitude(&cam, &icrs, &p.camera)
            .ok_or(Unsolved::NoConsistentMatch)?;
        // Every pass this frame can be tried with multiplies the hypotheses a chance match could
        // come from; the vote has half the pass's error budget (see `STAGES`).
        let hypotheses = voted
            .hypotheses
            .saturating_mul(self.hypothesis_factor(detections.len(), p.method) * self.parities());
        let refined = refine::refine(r0, detections, refs, &camera, hypotheses, 2, &p.refine)
            .ok_or(Unsolved::NoConsistentMatch)?;
        if refined.false_match_prob > p.refine.max_false_prob {
            tracing::debug!(
                "low confidence: {} of {} catalog stars in view matched, false-match \
                 probability {:.2e} (scale {:.4})",
                refined.matches.len(),
                refined.in_view,
                refined.false_match_prob,
                p.camera.fx / self.camera.fx
            );
            return Err(Unsolved::LowConfidence);
        }
        Ok(refined)
    }

    /// The triangle fallback (see [`triangle`]): the first confirmed triangle, in brightness
    /// order, whose refined attitude passes the false-match test. That test counts every
    /// triangle that matched, for every pass tried, with its half of the error budget (see
    /// `STAGES`), and three stars as fixed.
    fn finish_triangles(
        &self,
        detections: &[Detection],
        p: &Prepared,
        refs: &RefCatalog,
    ) -> Option<Refined> {
        let band = &self.bands[p.band];
        let (hyps, matched) = self.triangles_either(&p.vectors[..p.triangle_stars], |v| {
            triangle::triangles(band.table(), &p.ranges, v, band.directions())
        });
        self.first_accepted(detections, p, refs, &hyps, matched)
    }

    /// The first triangle hypothesis whose refined attitude passes the false-match test, which
    /// counts `matched` triangles for every pass this frame can be tried with (with its share
    /// of the error budget, see [`Solver::hypothesis_factor`]) and three stars as fixed.
    fn first_accepted(
        &self,
        detections: &[Detection],
        p: &Prepared,
        refs: &RefCatalog,
        hyps: &[triangle::Triangle],
        matched: u64,
    ) -> Option<Refined> {
        let vectors = &p.vectors[..p.n_vote];
        let hypotheses = matched.saturating_mul(self.hypothesis_factor(detections.len(), p.method));
        hyps.iter().find_map(|t| {
            let cam = t.stars.map(|i| vectors[i]);
            let icrs = t.refs.map(|id| refs.v(id as usize));
            let (r0, camera) = self.first_attitude(&cam, &icrs, &p.camera)?;
            let refined = refine::refine(r0, detections, refs, &camera, hypotheses, 3, &p.refine)?;
            (refined.false_match_prob <= p.refine.max_false_prob).then_some(refined)
        })
    }

    /// How many detections a frame may be identified from: 2 when a frame that does not solve
    /// is detected again with the matched filter. Each judges its hypotheses against its share
    /// of the false-match budget, so the chance that either accepts a wrong attitude stays
    /// within the whole.
    pub fn detection_stages(&self) -> u64 {
        let s = &self.settings;
        if s.retry && s.detect_retry && !s.detect.matched_filter {
            2
        } else {
            1
        }
    }

    /// The band (of the scale search; never the shallow pass's) a focal-length factor falls in.
    pub fn band_of(&self, scale: f64) -> usize {
        band_for(
            &self.bands[..self.shallow_band.unwrap_or(self.bands.len())],
            scale,
        )
    }
}

/// An accepted solution refined again against `refs`, judged by the same false-match test with
/// the same hypotheses and fixed stars: None when it matched fewer stars or failed the test
/// (the accepted one then stands).
fn refine_again(
    accepted: &Refined,
    detections: &[Detection],
    refs: Arc<RefCatalog>,
    rs: &RefineSettings,
) -> Option<(Refined, Arc<RefCatalog>)> {
    let (h, fixed) = (accepted.hypotheses, accepted.fixed);
    let refined = refine::refine(
        accepted.r,
        detections,
        &refs,
        &accepted.camera,
        h,
        fixed,
        rs,
    )?;
    (refined.matches.len() >= accepted.matches.len()
        && refined.false_match_prob <= rs.max_false_prob)
        .then_some((refined, refs))
}
