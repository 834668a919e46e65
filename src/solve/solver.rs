//! The lost-in-space pipeline for one frame: detect → vote → select → verify → attitude →
//! refine → accept, producing one result record.
//!
//! Size: about 1,050 lines: the solver's set-up (catalog selection, tables, scale bands) and
//! the identification passes and retries that share its state; issue 23's layout step puts the
//! passes in a `pipeline/` folder of their own.

use crate::camera::Camera;
use crate::catalog::table::{self, PairTable, TableOrigin};
use crate::catalog::{Catalog, DoubleStars, RefCatalog, Selection, vector_to_radec};
use crate::error::Result;
use crate::io::frame::Frame;
use crate::record::{MatchRecord, Record, Status, Timing};
use crate::solve::attitude::{pointing, wahba};
use crate::solve::detect::{self, DetectSettings, Detection};
use crate::solve::identify::{self, IdentifySettings};
use crate::solve::refine::{self, RefineSettings, Refined};
use crate::solve::triangle;
use nalgebra::Vector3;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Everything that shapes a run besides the camera.
#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Observation epoch (Julian year) for proper motion.
    pub epoch: f64,
    /// Faintest catalog magnitude used; None = from the field of view (see [`auto_mag_limit`]).
    pub mag_limit: Option<f64>,
    pub double_stars: DoubleStars,
    /// Stars closer than this many pixels count as one (double-star rule).
    pub double_star_px: f64,
    pub detect: DetectSettings,
    pub identify: IdentifySettings,
    pub refine: RefineSettings,
    /// Use the on-disk cache of distance tables.
    pub table_cache: bool,
    /// When the scale is uncertain: the range of the true focal length relative to the
    /// camera's, (lower, upper). The solver tries scales across it.
    pub scale_range: Option<(f64, f64)>,
    /// Frames that do not solve are tried again: with more voting stars
    /// ([`RETRY_VOTE_STARS`]), with voters spread over the frame ([`SPREAD_CELLS`]), then
    /// with wide tolerances ([`WIDE_PAIR_TOL_PX`], [`WIDE_MATCH_RADIUS_PX`]).
    pub retry: bool,
    /// Frames that do not solve are detected again with the matched filter (fainter stars)
    /// and tried again, when the filter is not on already and `retry` is.
    pub detect_retry: bool,
    /// How stars are identified: the vote, or radial features + triangles.
    pub method: crate::solve::radial::Method,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            epoch: 2000.0,
            mag_limit: None,
            double_stars: DoubleStars::Merge,
            double_star_px: 2.0,
            detect: DetectSettings::default(),
            identify: IdentifySettings::default(),
            refine: RefineSettings::default(),
            table_cache: true,
            scale_range: None,
            retry: true,
            detect_retry: true,
            method: crate::solve::radial::Method::Vote,
        }
    }
}

/// Average number of catalog stars in the field that [`auto_mag_limit`] aims at.
pub const AUTO_STARS_IN_VIEW: f64 = 40.0;

/// The faintest magnitude at which the catalog holds on average [`AUTO_STARS_IN_VIEW`] stars
/// in the camera's field (at least 5.0, at most the catalog's faintest).
pub fn auto_mag_limit(catalog: &Catalog, camera: &Camera) -> f64 {
    mag_limit_for(catalog, camera, AUTO_STARS_IN_VIEW).max(5.0)
}

/// The faintest magnitude at which the catalog holds on average `stars` stars in the camera's
/// field (to a tenth; at most the catalog's faintest).
pub fn mag_limit_for(catalog: &Catalog, camera: &Camera, stars: f64) -> f64 {
    let fov_sr = (camera.fov_x_deg() * camera.fov_y_deg())
        .to_radians()
        .to_radians();
    let fraction = fov_sr / (4.0 * std::f64::consts::PI);
    let mut mags: Vec<f64> = catalog.stars.iter().map(|s| s.mag).collect();
    mags.sort_by(f64::total_cmp);
    let n = ((stars / fraction).round() as usize).clamp(1, mags.len());
    (mags[n - 1] * 10.0).round() / 10.0
}

/// Average number of catalog stars in the field of the shallow pass's selection: a sensor that
/// shows 4 to 8 stars (a 10° field to Hp 6) leaves them among 40 catalog stars in view of the
/// automatic selection, whose pairs crowd the vote and whose count weakens the false-match
/// test; voting against the brightest 12 in view gives those stars a catalog they can match.
pub const SHALLOW_STARS_IN_VIEW: f64 = 12.0;

/// A camera with its catalog selections and distance tables, ready to solve frames.
pub struct Solver {
    pub camera: Camera,
    pub settings: Settings,
    /// One, unless a scale search spans more than [`BAND_RATIO`].
    pub bands: Vec<Band>,
    /// Focal-length factors tried, nearest to the camera's first (just 1.0 for a known scale).
    pub scales: Vec<f64>,
    /// The hypotheses tried in turn until one solves: every scale with the settings, then
    /// (when `retry`) every scale with more voting stars, with voters spread over the frame,
    /// and with wide tolerances.
    pub passes: Vec<Pass>,
    /// When the scale is searched and the magnitude limit left to the solver: the catalog,
    /// to check each solution against as deep a selection as its fitted field calls for.
    deeper: Option<Deeper>,
    /// The band of the shallow pass, when there is one (the last of `bands`).
    pub shallow_band: Option<usize>,
}

/// Widest ratio of focal lengths one band of a scale search covers. A band's reference stars
/// are those for its middle field (about [`AUTO_STARS_IN_VIEW`] in view there, from 27 to 60
/// across a band of 1.5): one selection for a search over 5° to 40° would leave 8 in view of a
/// 10° frame, too few to vote with. cedar-solve's 13 frames with `--fov-deg 5..40`: 9 solved
/// with one band, 13 with bands.
pub const BAND_RATIO: f64 = 1.5;

/// The focal-length factors a scale search covers, in bands of at most [`BAND_RATIO`]
/// (equal on a log scale), from the shortest; just (1, 1) for a known scale.
pub fn scale_bands(range: Option<(f64, f64)>) -> Vec<(f64, f64)> {
    let Some((lo, hi)) = range else {
        return vec![(1.0, 1.0)];
    };
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    let n = ((hi / lo).ln() / BAND_RATIO.ln()).ceil().max(1.0) as i32;
    let edge = |k: i32| lo * (hi / lo).powf(k as f64 / n as f64);
    (0..n).map(|k| (edge(k), edge(k + 1))).collect()
}

/// The reference stars and distance table of the focal lengths `lo`..`hi` (relative to the
/// solver's camera).
pub struct Band {
    pub lo: f64,
    pub hi: f64,
    pub refs: Arc<RefCatalog>,
    pub table: PairTable,
    pub table_origin: TableOrigin,
    /// The reference stars' radial features (`--method radial`), from `table`.
    pub radial: Option<crate::solve::radial::RadialTable>,
    /// `refs` moved to the epochs of frames that carry their own date, by day.
    epochs: Mutex<HashMap<i64, Arc<RefCatalog>>>,
}

impl Band {
    /// The stars for the field of focal-length factor `middle` (unless the settings fix the
    /// magnitude limit), and their pairs out to the diagonal of the widest field, `lo`.
    fn new(
        catalog: &Catalog,
        camera: &Camera,
        settings: &Settings,
        (lo, hi): (f64, f64),
        middle: f64,
        mag_limit: Option<f64>,
    ) -> Result<Band> {
        let middle = scaled(camera, middle);
        let selection = Selection {
            epoch: settings.epoch,
            mag_limit: mag_limit
                .or(settings.mag_limit)
                .unwrap_or_else(|| auto_mag_limit(catalog, &middle)),
            double_stars: settings.double_stars,
            double_sep_rad: settings.double_star_px * middle.ifov_rad(),
        };
        let refs = RefCatalog::select(catalog, selection)?;
        let (table, table_origin) = table::load_or_build(
            &refs,
            catalog.content_hash,
            scaled(camera, lo).diagonal_rad(),
            settings.table_cache,
        );
        let radial = (settings.method == crate::solve::radial::Method::Radial).then(|| {
            let s = &settings.identify;
            crate::solve::radial::RadialTable::load_or_build(
                &refs,
                &table,
                table::cache_key(&refs, catalog.content_hash, table.max_sep_rad),
                s.pair_tol_px * middle.ifov_rad(),
                s.scale_tol,
                settings.table_cache,
            )
            .0
        });
        Ok(Band {
            lo,
            hi,
            refs: Arc::new(refs),
            table,
            table_origin,
            radial,
            epochs: Mutex::new(HashMap::new()),
        })
    }

    /// The reference stars at a frame's own epoch (`refs` when it has none, or the same).
    pub fn refs_at(&self, epoch: Option<f64>) -> Arc<RefCatalog> {
        let Some(e) = epoch.filter(|e| (e - self.refs.selection.epoch).abs() > SAME_EPOCH_YEARS)
        else {
            return self.refs.clone();
        };
        let mut map = self.epochs.lock().unwrap_or_else(|p| p.into_inner());
        let day = epoch_day(e);
        // At the day's own epoch, not the first frame's of that day: the positions (and the
        // records' epoch) must not depend on which frame of the day a thread reached first.
        map.entry(day)
            .or_insert_with(|| Arc::new(self.refs.at_epoch(day_epoch(day))))
            .clone()
    }
}

/// The catalog, and the selections made from it for solutions' fields.
struct Deeper {
    catalog: Catalog,
    selections: Mutex<HashMap<SelectionKey, Option<Arc<RefCatalog>>>>,
}

/// (magnitude limit in tenths, epoch in days) of a selection; its value None = the selection
/// failed (too many stars for 16-bit ids).
type SelectionKey = (i64, i64);

/// Frames dated within this many years of the run's epoch use the run's star positions
/// (about a day: proper motions move no star by a milliarcsecond in that time).
const SAME_EPOCH_YEARS: f64 = 0.003;

/// The day of an epoch (Julian year): what star positions are cached by.
fn epoch_day(epoch: f64) -> i64 {
    (epoch * 365.25).round() as i64
}

/// The epoch star positions are computed at for a day (within half a day of any frame of it:
/// proper motions move no star by a microarcsecond in that time).
fn day_epoch(day: i64) -> f64 {
    day as f64 / 365.25
}

/// Relative spacing of the focal-length factors of a scale search: each covers ±0.05 %, which
/// the pair tolerance absorbs.
pub const SCALE_STEP: f64 = 0.001;

/// The wide retry's scale step: its pair tolerance is ten times the default's, and so is its
/// step, which then takes the same share of a pair's range (finer, neighbouring scales would
/// test nearly the same hypotheses again). When it came in, a frame that cannot solve took 0.57
/// of the time: 26 s instead of 45 s with `--fov-deg 10..30`, 6.5 s instead of 11.5 s with `16..20`.
pub const WIDE_SCALE_STEP: f64 = 0.01;

/// The focal-length factors covering [lo, hi] at most `step` apart (relative), from the one
/// nearest 1 outward.
pub fn scale_hypotheses(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    let n = ((hi / lo).ln() / (1.0 + step).ln()).ceil().max(0.0) as i64;
    let mut v: Vec<f64> = (0..=n)
        .map(|k| lo * (hi / lo).powf(if n == 0 { 0.5 } else { k as f64 / n as f64 }))
        .collect();
    v.sort_by(|a, b| a.ln().abs().total_cmp(&b.ln().abs()));
    v
}

/// One way of trying a frame: a focal-length factor, the band it falls in, and what the vote
/// is given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pass {
    pub scale: f64,
    pub band: usize,
    pub kind: PassKind,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PassKind {
    /// The settings as given.
    First,
    /// Up to [`RETRY_VOTE_STARS`] stars vote (only for frames with more than `vote_stars`).
    MoreStars,
    /// The voters are the brightest of each cell of a grid over the frame, then the second
    /// brightest, and so on (only for frames with more than `vote_stars`).
    Spread,
    /// Wide pair tolerance and match radius.
    Wide,
    /// The vote against a shallow selection ([`SHALLOW_STARS_IN_VIEW`] stars in view), for
    /// frames that show few stars; the solution is then refined against the automatic one.
    Shallow,
}

impl PassKind {
    /// Relative spacing of this kind's focal lengths in a scale search.
    fn scale_step(self) -> f64 {
        match self {
            PassKind::Wide => WIDE_SCALE_STEP,
            _ => SCALE_STEP,
        }
    }
}

/// Voting stars of the first retry. Many false stars (satellites, debris, glints) can outshine
/// most real ones, so that the brightest `vote_stars` hold too few stars to outvote chance:
/// voting with more of the faint stars brings the real ones back. Not the default because the
/// vote's cost grows with the square of its stars. From the study (`scripts/study.py`): at 40
/// false stars per 18° frame, 50 % of frames solve with 40 voting stars, 99 % with this retry.
pub const RETRY_VOTE_STARS: usize = 60;

/// The wide retry's pair tolerance and match radius (pixels): for frames whose centroids are
/// off by a pixel or more (blur, defocus, coarse centroiding), which the settings' tolerances
/// (tuned for sub-pixel centroids) reject. A frame gets them only after failing with those;
/// the false-match test counts the extra hypotheses. From the study's centroid-noise sweep:
/// at 1.5 px noise 34 % of frames solve without the retries, 99.5 % with them (97 % with a
/// 3 px pair tolerance).
pub const WIDE_PAIR_TOL_PX: f64 = 4.0;
pub const WIDE_MATCH_RADIUS_PX: f64 = 5.0;

/// The stages that can accept a frame, the vote and the triangle fallback, share the
/// false-match budget (`max_false_prob`) evenly: each judges its own hypotheses against half
/// of it, so the chance that either accepts a wrong attitude stays within the whole. A
/// triangle is then weighed against the thousands of triangles that matched, not against the
/// millions of pairs the vote scanned too. openstartracker's img7.png, 6 of its stars above
/// the noise: its triangle's false-match probability is 6.8e-5 so judged, 0.052 before
/// (3.4e-7 and 2.6e-4 with `refine::brightest_first`). The vote's path pays a factor of 2.
pub const STAGES: u64 = 2;

/// About how many cells the spread retry divides a frame into (square cells, as many as fit
/// the frame's shape). A bright cluster of false stars (lit foliage, a roof edge, a nebula, a
/// hot corner) can fill the brightest `vote_stars` by itself and leave too few real stars in
/// the vote; taking the stars round the cells in turn, as astrometry.net's `uniformize` does,
/// lets each part of the sky put its own brightest forward. cedar-solve's `tree.jpg` (tree
/// branches lit in a third of the frame) holds 4 of its stars among its 40 brightest
/// detections and 9 among 40 taken this way, 7 among the first 12.
pub const SPREAD_CELLS: u32 = 16;

/// The spread retry's triangle fallback forms triangles among this many of its first stars
/// (220 triangles; [`triangle::TRIANGLE_STARS`] otherwise): the brightest star of each cell
/// is more often a real one, and in a dense part of the sky (the Milky Way) triangles confirmed
/// by a fourth star find what the vote's counts cannot single out.
pub const SPREAD_TRIANGLE_STARS: usize = 12;

/// The detections (brightest first) in the spread retry's order: the brightest of each of
/// about [`SPREAD_CELLS`] square cells over a `width`×`height` frame, in brightness order,
/// then the second brightest of each, and so on.
pub fn spread_order(detections: &[Detection], width: u32, height: u32) -> Vec<usize> {
    let (w, h) = (width.max(1) as f64, height.max(1) as f64);
    let side = (w * h / SPREAD_CELLS as f64).sqrt();
    let (nx, ny) = ((w / side).round().max(1.0), (h / side).round().max(1.0));
    let cell = |d: &Detection| {
        let cx = ((d.x + 0.5) / w * nx).floor().clamp(0.0, nx - 1.0);
        let cy = ((d.y + 0.5) / h * ny).floor().clamp(0.0, ny - 1.0);
        (cy * nx + cx) as usize
    };
    let mut seen = vec![0usize; (nx * ny) as usize];
    let mut round: Vec<(usize, usize)> = detections
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let c = cell(d);
            seen[c] += 1;
            (seen[c] - 1, i)
        })
        .collect();
    round.sort_unstable();
    round.into_iter().map(|(_, i)| i).collect()
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
}

/// What the identification of one frame found (before it becomes a record).
#[derive(Clone, Debug)]
pub struct Solution {
    pub detections: Vec<Detection>,
    pub outcome: Outcome,
    /// The frame's own observation epoch (FITS DATE-OBS), if it has one.
    pub epoch: Option<f64>,
}

// One per frame, moved rarely: boxing the solution would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Outcome {
    /// The refined solution, and the reference stars its matches' ids index.
    Solved(refine::Refined, Arc<RefCatalog>),
    Unsolved(&'static str),
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
        let mut bands = edges
            .iter()
            .map(|&e| Band::new(catalog, &camera, &settings, e, middle(e), None))
            .collect::<Result<Vec<Band>>>()?;
        // The shallow pass's band: with a known scale and the magnitude limit left to the
        // solver, when it is shallower than the automatic one by half a magnitude or more.
        let shallow_mag = mag_limit_for(catalog, &camera, SHALLOW_STARS_IN_VIEW);
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
                    })
            })
            .collect();
        if bands.len() > main_bands {
            passes.push(Pass {
                scale: 1.0,
                band: main_bands,
                kind: PassKind::Shallow,
            });
        }
        let shallow_band = (bands.len() > main_bands).then_some(main_bands);
        Ok(Solver {
            camera,
            settings,
            shallow_band,
            bands,
            scales,
            passes,
            deeper: (settings.scale_range.is_some() && settings.mag_limit.is_none()).then(|| {
                Deeper {
                    catalog: catalog.clone(),
                    selections: Mutex::new(HashMap::new()),
                }
            }),
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
        if pass.kind == PassKind::MoreStars {
            if detections.len() <= s.vote_stars || s.vote_stars >= RETRY_VOTE_STARS {
                return None;
            }
            s.vote_stars = RETRY_VOTE_STARS;
        }
        // Without more stars than voters, spreading would vote with the same stars.
        if pass.kind == PassKind::Spread && detections.len() <= s.vote_stars {
            return None;
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
        })
    }

    /// How many passes a frame of `n` detections can be tried with: the retries with more
    /// voting stars and with voters spread over the frame need more detections than vote
    /// (`prepare` passes them over otherwise), so they add no hypothesis to such a frame.
    pub fn passes_for(&self, n: usize) -> usize {
        let vote = self.settings.identify.vote_stars;
        self.passes
            .iter()
            .filter(|p| match p.kind {
                PassKind::MoreStars => n > vote && vote < RETRY_VOTE_STARS,
                PassKind::Spread => n > vote,
                _ => true,
            })
            .count()
    }

    /// Identify the stars of a detection list, voting on the CPU: the passes in turn until
    /// one solves.
    pub fn identify(&self, detections: Vec<Detection>, epoch: Option<f64>) -> Solution {
        let mut outcome = Outcome::Unsolved("too_few_stars");
        for h in 0..self.passes.len() {
            let Some(p) = self.prepare(&detections, h) else {
                continue;
            };
            let band = &self.bands[p.band];
            outcome = match (self.settings.method, &band.radial) {
                (crate::solve::radial::Method::Triangle, _) => {
                    self.finish_triangle_method(&detections, &p, epoch)
                }
                (_, Some(t)) => {
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
                        identify::vote_cpu(&band.table, &p.ranges, p.n_vote, band.refs.len(), p.k);
                    self.finish(&detections, &p, &voted, epoch)
                }
            };
            if matches!(outcome, Outcome::Solved(..)) {
                break;
            }
        }
        Solution {
            detections,
            outcome,
            epoch,
        }
    }

    /// Verification, attitude, refinement and acceptance after the vote, and the triangle
    /// fallback when the vote's candidates hold no consistent set; refinement uses the star
    /// positions at the frame's `epoch` when it has one.
    pub fn finish(
        &self,
        detections: &[Detection],
        p: &Prepared,
        voted: &identify::VoteResult,
        epoch: Option<f64>,
    ) -> Outcome {
        let refs = self.bands[p.band].refs_at(epoch);
        let accepted = match self.finish_vote(detections, p, voted, &refs) {
            Ok(accepted) => accepted,
            Err(reason) if p.triangle_stars < 4 => return Outcome::Unsolved(reason),
            Err(reason) => match self.finish_triangles(detections, p, &refs) {
                Some(accepted) => accepted,
                None => return Outcome::Unsolved(reason),
            },
        };
        self.conclude(detections, p, accepted, epoch)
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
        let triangles = crate::solve::radial::triangles(
            &found.candidates,
            found.k,
            &p.ranges,
            vectors,
            &self.bands[p.band].refs,
            crate::solve::radial::TRIANGLE_STARS,
        );
        if triangles.is_empty() {
            return Outcome::Unsolved("no_consistent_match");
        }
        match self.first_accepted(detections, p, &refs, &triangles, triangles.len() as u64) {
            Some(a) => self.conclude(detections, p, a, epoch),
            None => Outcome::Unsolved("low_confidence"),
        }
    }

    /// `--method triangle`: the triangle fallback's hypotheses on their own (no vote).
    pub fn finish_triangle_method(
        &self,
        detections: &[Detection],
        p: &Prepared,
        epoch: Option<f64>,
    ) -> Outcome {
        if p.triangle_stars < 4 {
            return Outcome::Unsolved("too_few_stars");
        }
        let refs = self.bands[p.band].refs_at(epoch);
        match self.finish_triangles(detections, p, &refs) {
            Some(a) => self.conclude(detections, p, a, epoch),
            None => Outcome::Unsolved("no_consistent_match"),
        }
    }

    /// An accepted solution, refined again against the deeper selection its field calls for
    /// (or from the shallow band against the main one).
    fn conclude(
        &self,
        detections: &[Detection],
        p: &Prepared,
        accepted: (Refined, u64, usize),
        epoch: Option<f64>,
    ) -> Outcome {
        let refs = self.bands[p.band].refs_at(epoch);
        let (refined, hypotheses, fixed) = accepted;
        if Some(p.band) == self.shallow_band {
            // Found against the shallow selection: the automatic one matches the fainter stars
            // too, judged by the same test.
            let main = self.bands[0].refs_at(epoch);
            let s = &self.settings.refine;
            return match refine::refine(
                refined.r,
                detections,
                &main,
                &refined.camera,
                hypotheses,
                fixed,
                &p.refine,
            ) {
                Some(r)
                    if r.false_match_prob <= s.max_false_prob
                        && r.matches.len() >= refined.matches.len() =>
                {
                    Outcome::Solved(r, main)
                }
                _ => Outcome::Solved(refined, refs),
            };
        }
        match self.deepen(
            &refined, detections, p.band, &p.refine, epoch, hypotheses, fixed,
        ) {
            Some((deeper, deep_refs)) => Outcome::Solved(deeper, deep_refs),
            None => Outcome::Solved(refined, refs),
        }
    }

    /// After a scale search the reference stars were chosen for the middle of a band, and a
    /// frame at its narrow end holds fewer of them (27 instead of [`AUTO_STARS_IN_VIEW`] for a
    /// band of [`BAND_RATIO`]; 8 at 10° with one selection for 5° to 40°). The accepted
    /// attitude is refined again against the selection its fitted field calls for, judged by
    /// the same false-match test with the same hypotheses; None = nothing deeper to check
    /// against, or the deeper refinement matched fewer stars or failed the test (the accepted
    /// one then stands).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn deepen(
        &self,
        accepted: &Refined,
        detections: &[Detection],
        band: usize,
        rs: &RefineSettings,
        epoch: Option<f64>,
        hypotheses: u64,
        fixed: usize,
    ) -> Option<(Refined, Arc<RefCatalog>)> {
        let deeper = self.deeper.as_ref()?;
        let mag_limit = auto_mag_limit(&deeper.catalog, &accepted.camera);
        let voted_with = self.bands[band].refs.selection;
        if mag_limit <= voted_with.mag_limit {
            return None;
        }
        let epoch = match epoch {
            Some(e) if (e - voted_with.epoch).abs() > SAME_EPOCH_YEARS => day_epoch(epoch_day(e)),
            _ => voted_with.epoch,
        };
        let key = ((mag_limit * 10.0).round() as i64, epoch_day(epoch));
        let refs = deeper
            .selections
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .entry(key)
            .or_insert_with(|| {
                let selection = Selection {
                    epoch,
                    mag_limit,
                    ..voted_with
                };
                RefCatalog::select(&deeper.catalog, selection)
                    .map(Arc::new)
                    .ok()
            })
            .clone()?;
        let refined = refine::refine(
            accepted.r,
            detections,
            &refs,
            &accepted.camera,
            hypotheses,
            fixed,
            rs,
        )?;
        (refined.matches.len() >= accepted.matches.len()
            && refined.false_match_prob <= self.settings.refine.max_false_prob)
            .then_some((refined, refs))
    }

    /// The vote's path: the consistent set of candidates, Wahba, refinement. The accepted
    /// solution with the hypotheses and fixed stars its false-match test counted, or why
    /// there is none.
    fn finish_vote(
        &self,
        detections: &[Detection],
        p: &Prepared,
        voted: &identify::VoteResult,
        refs: &RefCatalog,
    ) -> Result<(Refined, u64, usize), &'static str> {
        let s = &self.settings;
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
            return Err("no_consistent_match");
        }
        let cam: Vec<_> = ids.iter().map(|m| vectors[m.star]).collect();
        let icrs: Vec<_> = ids
            .iter()
            .map(|m| refs.stars[m.ref_id as usize].v)
            .collect();
        let r0 = wahba(&cam, &icrs).ok_or("no_consistent_match")?;
        // Every pass this frame can be tried with multiplies the hypotheses a chance match could
        // come from; the vote has half the error budget (see `STAGES`).
        let hypotheses = voted.hypotheses.saturating_mul(
            STAGES * self.detection_stages() * self.passes_for(detections.len()) as u64,
        );
        let refined = refine::refine(r0, detections, refs, &p.camera, hypotheses, 2, &p.refine)
            .ok_or("no_consistent_match")?;
        if refined.false_match_prob > s.refine.max_false_prob {
            tracing::debug!(
                "low confidence: {} of {} catalog stars in view matched, false-match \
                 probability {:.2e} (scale {:.4})",
                refined.matches.len(),
                refined.in_view,
                refined.false_match_prob,
                p.camera.fx / self.camera.fx
            );
            return Err("low_confidence");
        }
        Ok((refined, hypotheses, 2))
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
    ) -> Option<(Refined, u64, usize)> {
        let band = &self.bands[p.band];
        let (hyps, matched) = triangle::triangles(
            &band.table,
            &p.ranges,
            &p.vectors[..p.triangle_stars],
            &band.refs,
        );
        self.first_accepted(detections, p, refs, &hyps, matched)
    }

    /// The first triangle hypothesis whose refined attitude passes the false-match test, which
    /// counts `matched` triangles for every pass this frame can be tried with (with its share
    /// of the error budget, see `STAGES`) and three stars as fixed.
    fn first_accepted(
        &self,
        detections: &[Detection],
        p: &Prepared,
        refs: &RefCatalog,
        hyps: &[triangle::Triangle],
        matched: u64,
    ) -> Option<(Refined, u64, usize)> {
        let vectors = &p.vectors[..p.n_vote];
        let hypotheses = matched.saturating_mul(
            STAGES * self.detection_stages() * self.passes_for(detections.len()) as u64,
        );
        hyps.iter().find_map(|t| {
            let cam = t.stars.map(|i| vectors[i]);
            let icrs = t.refs.map(|id| refs.stars[id as usize].v);
            let r0 = wahba(&cam, &icrs)?;
            let refined =
                refine::refine(r0, detections, refs, &p.camera, hypotheses, 3, &p.refine)?;
            (refined.false_match_prob <= self.settings.refine.max_false_prob)
                .then_some((refined, hypotheses, 3))
        })
    }

    /// Solve a decoded frame on the CPU.
    pub fn solve_frame(&self, frame: &Frame) -> (Solution, f64, f64) {
        self.solve_frame_at(frame, None)
    }

    /// Solve a decoded frame on the CPU, with its own observation epoch if it has one.
    pub fn solve_frame_at(&self, frame: &Frame, epoch: Option<f64>) -> (Solution, f64, f64) {
        let t0 = Instant::now();
        let dets = detect::detect(frame, &self.settings.detect);
        let t1 = Instant::now();
        let sol = self.identify(dets, epoch);
        let t2 = Instant::now();
        let (mut detect_ms, identify_ms) = ((t1 - t0).as_secs_f64(), (t2 - t1).as_secs_f64());
        if matches!(sol.outcome, Outcome::Unsolved(_)) && self.detection_stages() > 1 {
            let t3 = Instant::now();
            let filtered = self.detect_filtered(frame);
            detect_ms += t3.elapsed().as_secs_f64();
            let t4 = Instant::now();
            let again = self.identify(filtered, epoch);
            let identify_ms = identify_ms + t4.elapsed().as_secs_f64();
            if matches!(again.outcome, Outcome::Solved(..)) {
                return (again, detect_ms * 1e3, identify_ms * 1e3);
            }
            return (sol, detect_ms * 1e3, identify_ms * 1e3);
        }
        (sol, detect_ms * 1e3, identify_ms * 1e3)
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

    /// Detection's settings with the matched filter on (the detection retry).
    pub fn filtered_settings(&self) -> DetectSettings {
        DetectSettings {
            matched_filter: true,
            ..self.settings.detect
        }
    }

    /// The frame's detections with the matched filter (the detection retry).
    pub fn detect_filtered(&self, frame: &Frame) -> Vec<Detection> {
        detect::detect(frame, &self.filtered_settings())
    }

    /// The band (of the scale search; never the shallow pass's) a focal-length factor falls in.
    pub fn band_of(&self, scale: f64) -> usize {
        band_for(
            &self.bands[..self.shallow_band.unwrap_or(self.bands.len())],
            scale,
        )
    }

    /// The result record of a solution.
    pub fn record(&self, name: &str, sol: &Solution, timing_ms: Timing, backend: &str) -> Record {
        let mut rec = Record::empty(name, backend);
        rec.stars_detected = Some(sol.detections.len());
        rec.timing_ms = timing_ms;
        match &sol.outcome {
            Outcome::Unsolved(reason) => {
                rec.status = Status::Unsolved;
                rec.reason = Some(reason.to_string());
            }
            Outcome::Solved(r, refs) => {
                rec.epoch = Some(refs.selection.epoch);
                let p = pointing(&r.r, &r.camera);
                rec.status = Status::Solved;
                rec.ra_deg = Some(p.ra_deg);
                rec.dec_deg = Some(p.dec_deg);
                rec.roll_deg = Some(p.roll_deg);
                rec.quaternion = Some(p.quaternion);
                rec.rotation_matrix = Some(std::array::from_fn(|i| {
                    std::array::from_fn(|j| r.r[(i, j)])
                }));
                rec.fov_x_deg = Some(r.camera.fov_x_deg());
                rec.fov_y_deg = Some(r.camera.fov_y_deg());
                if r.camera.k1 != self.camera.k1 {
                    rec.distortion_k1 = Some(r.camera.k1);
                }
                rec.stars_matched = Some(r.matches.len());
                rec.rmse_arcsec = Some(r.rmse_arcsec);
                rec.p90_arcsec = Some(r.p90_arcsec);
                rec.max_arcsec = Some(r.max_arcsec);
                rec.false_match_prob = Some(r.false_match_prob);
                let (sigma, ortho, det) = attitude_quality(r, refs);
                rec.attitude_sigma_arcsec = sigma;
                rec.orthogonality_error = Some(ortho);
                rec.sigma_floor_px = r.sigma_floor_px;
                rec.determinant = Some(det);
                if ortho > ORTHOGONALITY_WARN || (det - 1.0).abs() > ORTHOGONALITY_WARN {
                    rec.warnings.push(format!(
                        "the rotation matrix is not orthonormal to 1e-9: ‖RRᵀ − I‖ = {ortho:.2e}, \
                         det = {det:.12}"
                    ));
                }
                let mut matches: Vec<MatchRecord> = r
                    .matches
                    .iter()
                    .map(|m| {
                        let d = &sol.detections[m.det];
                        let star = &refs.stars[m.ref_id as usize];
                        let (ra, dec) = vector_to_radec(&star.v);
                        MatchRecord {
                            x: d.x,
                            y: d.y,
                            hip: star.hip,
                            ra_deg: ra,
                            dec_deg: dec,
                            mag: star.mag,
                            flux: d.flux,
                            residual_arcsec: m.residual_arcsec,
                            sigma_px: d.sigma_px,
                        }
                    })
                    .collect();
                matches.sort_by(|a, b| b.flux.total_cmp(&a.flux).then(a.hip.cmp(&b.hip)));
                rec.matches = Some(matches);
            }
        }
        rec
    }
}

/// Beyond this ‖RRᵀ − I‖ or |det R − 1| a record warns (Wahba's SVD gives 1e-15).
pub const ORTHOGONALITY_WARN: f64 = 1e-9;

/// The attitude's 1σ from its matches (Shuster: P = [Σ (1/σ_i²)(I − b bᵀ)]⁻¹ in the camera frame,
/// b the matched stars' directions; σ_i each match's 1σ per axis (the PSF fit's with the frame's
/// floor, `refine::match_sigmas`, at the mean focal length), or without PSF fits the residuals'
/// rms per axis for all; boresight = √(Pxx + Pyy), roll = √Pzz), and ‖RRᵀ − I‖_F and det R. None
/// for the 1σ with fewer than 3 matches.
pub fn attitude_quality(
    r: &refine::Refined,
    refs: &RefCatalog,
) -> (Option<crate::record::AttitudeSigma>, f64, f64) {
    let ortho = (r.r * r.r.transpose() - nalgebra::Matrix3::identity()).norm();
    let det = r.r.determinant();
    if r.matches.len() < 3 {
        return (None, ortho, det);
    }
    // The residuals' rms is of 2-D angles: per axis it is 1/√2 of it.
    let rms = r.rmse_arcsec / std::f64::consts::SQRT_2 / 3600.0 * std::f64::consts::PI / 180.0;
    let focal = 0.5 * (r.camera.fx + r.camera.fy);
    let info: nalgebra::Matrix3<f64> = r
        .matches
        .iter()
        .map(|m| {
            let b = r.r * refs.stars[m.ref_id as usize].v;
            let sigma = m.sigma_px.map_or(rms, |s| s / focal);
            (nalgebra::Matrix3::identity() - b * b.transpose()) / (sigma * sigma)
        })
        .sum();
    let Some(p) = info.try_inverse() else {
        return (None, ortho, det);
    };
    let arcsec = |v: f64| v.max(0.0).sqrt().to_degrees() * 3600.0;
    let s = crate::record::AttitudeSigma {
        boresight: arcsec(p[(0, 0)] + p[(1, 1)]),
        roll: arcsec(p[(2, 2)]),
    };
    (Some(s), ortho, det)
}

/// The band of `bands` (in increasing focal length) that focal-length factor `scale` falls in:
/// the first whose upper end reaches it, else the last.
fn band_for(bands: &[Band], scale: f64) -> usize {
    bands
        .iter()
        .position(|b| scale <= b.hi * (1.0 + 1e-12))
        .unwrap_or(bands.len() - 1)
}

/// The camera with its focal lengths multiplied by `factor`.
pub fn scaled(camera: &Camera, factor: f64) -> Camera {
    let mut c = camera.clone();
    c.fx *= factor;
    c.fy *= factor;
    c
}
