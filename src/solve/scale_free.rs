//! The scale-free first pass (issue 25): when the field of view is searched (`--fov-deg
//! LOW..HIGH`, `--fov-tolerance`), quads of the frame's brightest stars are looked up once in
//! the pattern index (`catalog::patterns`, keyed by edge ratios, which do not depend on the
//! focal length) instead of voting at every scale step. Each catalog quad found gives a focal
//! length (its chords against the image's) and an attitude (Wahba on its four stars); the
//! first that refinement accepts, with the false-match test counting every quad hypothesis of
//! the frame, is the solution. A frame it does not solve goes on to the scale walk (the vote
//! at each scale) where the range is within ±5 % (or `--fov-walk` asks); a wider range's frame
//! is left unsolved (docs/speed.md, "The end of the walk").
//!
//! A known scale goes through the pass first too, as a shortcut for easy frames: its own small
//! share of the budget, its first two rounds, a few refinements, and a solution that matches
//! at least half the stars it could (see [`PassLimits`]);
//! every other frame goes on to the vote, which stays the identifier for known scales.
//!
//! Frame side: the image quads' keys come from the stars' directions under the shortest and
//! longest focal lengths of the range; the true ratios lie between (they change with the focal
//! length only at second order in the field's angle), widened by the pair tolerance over each
//! edge's length in pixels. Every key bin the interval touches is a query (at most
//! [`MAX_QUERIES`] per quad: quads of short edges are too vague to look up).

use super::bands::Band;
use super::bands::{SCALE_STEP, WALK_MAX_RATIO, scaled};
use super::detect::{self, Detection};
use super::refine::{self, CameraFit};
use super::{Outcome, Prepared, Settings, Solution, Solver};
use crate::camera::Camera;
use crate::catalog::Catalog;
use crate::catalog::patterns::{self, BINS, PatternIndex};
use crate::cpu::pattern::{Buckets, Rows};
use crate::error::Result;
use crate::io::frame::Frame;
use nalgebra::Vector3;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

mod check;
pub use check::Hypothesis;
use check::permutations;

/// The rounds of the pass: round r looks up the quads of the brightest `ROUND_STARS[r]`
/// detections not looked up before (210, then 1155, 3480 and 22,560 more). False stars (satellites,
/// glints) can outshine most real ones: on 18° frames with 25 false stars the brightest 10
/// detections held too few real stars for a quad of the catalog's. Each round is judged
/// against its share of the false-match budget, so a frame that solves in the first pays
/// nothing for the others' hypotheses, and the chance that any round accepts a wrong attitude
/// stays within the whole.
pub const ROUND_STARS: [usize; 4] = [10, 15, 20, detect::QUAD_STARS];

/// The pass takes half of the false-match budget and the scale walk's passes share the other
/// half (`Solver::passes_for`): counted as one more of the walk's thousands of passes, its
/// share would be a few thousandths, and a frame of few stars, whose right quad matches 7 of
/// its 10 stars, would go on to the walk (seconds) to be solved there.
pub const SCALE_FREE_SHARE: u64 = 2;

/// With a known scale the pass comes first as well, for its speed: the quads of an easy frame's
/// brightest stars are looked up in microseconds where the vote scans thousands of table rows
/// per pair. There the vote is the stronger identifier on frames of few stars, and today's
/// verdicts should stand: the pass takes only `1 / KNOWN_SCALE_SHARE` of the budget, so a
/// vote's verdict moves only where its false-match probability lay within 0.0015 % of the
/// bound. On 1,400 simulated frames the pass still took 96 % of the frames it took with 1/64
/// (a share which had lost a sparse 10° frame, 0.5 % from the bound); the others go on to
/// the vote.
pub const KNOWN_SCALE_SHARE: u64 = 1 << 16;

/// With a known scale, a solution of the pass must match at least this share of the stars it
/// could (the fewer of the catalog stars in view and the detections); one that passes the test
/// with fewer is not an easy frame, and the pass leaves it to the vote and its retries. On 18°
/// frames with 1.5 px of centroid noise the pass had accepted solutions matching 8 of 27 stars
/// (the default match radius misses most): identities right, attitudes 0.1° off in roll, where
/// the wide retry matches 29. Clean frames' solutions match 55 % or more (docs/speed.md).
pub const KNOWN_SCALE_MIN_COMPLETENESS: f64 = 0.5;

/// How a round of the pass ended.
enum RoundEnd {
    Solved(Box<Outcome>),
    /// A solution passed the test but matched too few stars: the frame is left to the vote.
    LeftToVote,
    Nothing,
}

/// The catalog patterns a frame's scale-free pass has checked ([`MAX_PATTERNS`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct Checked {
    pub patterns: u64,
    /// A round was left unchecked: the pass is over.
    pub spent: bool,
}

/// Queries (key bins) one image quad may take; a quad whose ratios are vaguer is not looked up.
pub const MAX_QUERIES: usize = 32;

/// At most this many quad hypotheses are refined per frame (the first, in brightness order);
/// the false-match test counts them all.
pub const MAX_REFINED: usize = 100;

/// Catalog patterns a frame's pass checks at most, over its rounds: a round that would take
/// it past this is not checked. The pass checks about two million a second; a frame that
/// needs more has no quad the index knows among its brightest stars. On 35 real frames of
/// 0.2–4.5° against Tycho-2 the solved ones took at most 1.9 million (2MASS J, in its fourth
/// round), while a 200-pixel crop with 94 detections went on to 23 million (12.7 s) unsolved.
pub const MAX_PATTERNS: u64 = 4_000_000;

/// With a known scale, at most this many quad hypotheses are refined per frame, over all
/// rounds: an easy frame's first quads are right, and one whose first are not (false stars
/// among the brightest) is the vote's. Refining up to [`MAX_REFINED`] a round had cost 18° frames
/// with 25 false stars 20 ms each before the vote solved them in 4.
pub const KNOWN_SCALE_MAX_REFINED: usize = 8;

/// With a known scale the pass has only its first two rounds (the quads of the brightest
/// [`ROUND_STARS`]`[1]` detections): the later rounds are for false stars that outshine the
/// real ones, which the vote's retries handle at a known scale in milliseconds, and they had
/// cost those frames 20 ms each.
pub const KNOWN_SCALE_ROUNDS: usize = 2;

/// What the pass may spend and accept: chosen once, for a searched scale (the pass stands for a
/// walk of seconds) or a known one (a shortcut before the vote).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PassLimits {
    /// The pass takes `1 / share` of the false-match budget; the passes after it, the rest.
    pub share: u64,
    /// How the passes after it keep the rest: their hypotheses counted `share / (share − 1)`
    /// times (exact for half), or their `max_false_prob` scaled by `1 − 1 / share` (a count
    /// would be rounded up, by 5 % for a frame of few passes).
    pub rest_by_count: bool,
    /// Rounds at most (see [`ROUND_STARS`]).
    pub rounds: usize,
    /// Quad hypotheses refined per frame at most, over all rounds.
    pub max_refined: usize,
    /// A solution must match at least this share of the stars it could (the fewer of the
    /// catalog stars in view and the detections), or the frame is left to the vote.
    pub min_completeness: f64,
}

impl PassLimits {
    pub const SEARCHED: PassLimits = PassLimits {
        share: SCALE_FREE_SHARE,
        rest_by_count: true,
        rounds: ROUND_STARS.len(),
        max_refined: usize::MAX,
        min_completeness: 0.0,
    };
    pub const KNOWN: PassLimits = PassLimits {
        share: KNOWN_SCALE_SHARE,
        rest_by_count: false,
        rounds: KNOWN_SCALE_ROUNDS,
        max_refined: KNOWN_SCALE_MAX_REFINED,
        min_completeness: KNOWN_SCALE_MIN_COMPLETENESS,
    };

    /// The limits for `settings`' scale: searched or known.
    pub fn for_settings(settings: &Settings) -> PassLimits {
        if settings.scale_range.is_some() {
            PassLimits::SEARCHED
        } else {
            PassLimits::KNOWN
        }
    }
}

/// A solver's pattern index and the band whose reference stars its quads name.
pub struct ScaleFree {
    pub index: PatternIndex,
    pub band: usize,
    pub limits: PassLimits,
    /// Built now (false: read from the cache), and the seconds that took.
    pub built: bool,
    pub seconds: f64,
    /// The CPU lookup's table of key prefixes, made once the queries looked up without it
    /// would have paid for it ([`rows_cpu`]).
    buckets: OnceLock<Buckets>,
    /// Queries looked up so far without `buckets`.
    unbucketed: AtomicUsize,
}

impl ScaleFree {
    /// The pattern index of `settings.scale_range` (or the camera's own scale), from the stars
    /// of `bands[band]` (loaded from the cache or built); None when it would be larger than
    /// gpustar builds ([`patterns::MAX_INDEX_BYTES`], [`patterns::MAX_DISCS`]) and the frames
    /// can do without it (a known scale, or one searched within [`WALK_MAX_RATIO`], is
    /// walked). A range wider than that has no other way in: it is refused, with what would
    /// serve.
    pub(crate) fn build(
        catalog: &Catalog,
        camera: &Camera,
        settings: &Settings,
        bands: &[Band],
        band: usize,
    ) -> Result<Option<ScaleFree>> {
        let range = settings.scale_range.unwrap_or((1.0, 1.0));
        let levels = patterns::levels_for(short_side(camera, range.1), short_side(camera, range.0));
        let (discs, bytes) = patterns::estimate(&bands[band].refs, &levels, settings.sky_sr);
        if discs > patterns::MAX_DISCS || bytes > patterns::MAX_INDEX_BYTES {
            let what = format!(
                "a pattern index for fields of {:.3}° ({} stars of {}, magnitude {:.1} and \
                 brighter) would visit {discs:.1e} sky discs and hold about {:.1} GB",
                short_side(camera, range.1).to_degrees(),
                bands[band].refs.len(),
                if settings.sky_sr < 4.0 * std::f64::consts::PI - 1e-9 {
                    "a hint's region"
                } else {
                    "the whole sky"
                },
                bands[band].refs.selection.mag_limit,
                bytes / 1e9
            );
            if range.1 / range.0 > WALK_MAX_RATIO && !settings.walk_wide {
                // Discs grow as the field narrows whatever the catalog; bytes with its depth.
                let brighter = if discs > patterns::MAX_DISCS {
                    ""
                } else {
                    ", or a brighter --mag-limit"
                };
                crate::error::fail!(
                    Config,
                    "{what}, more than gpustar builds ({:.0} GB, {:.0e} discs): give a \
                     pointing hint (--hint) so that only its region is searched, a narrower \
                     scale range (within ±5 %, which is walked){brighter}",
                    patterns::MAX_INDEX_BYTES / 1e9,
                    patterns::MAX_DISCS
                );
            }
            tracing::warn!("{what}: frames are voted scale by scale without it");
            return Ok(None);
        }
        let (index, built, seconds) = patterns::load_or_build(
            &bands[band].refs,
            catalog.content_hash,
            &levels,
            settings.table_cache,
        );
        Ok(Some(ScaleFree {
            index,
            band,
            limits: PassLimits::for_settings(settings),
            built,
            seconds,
            buckets: OnceLock::new(),
            unbucketed: AtomicUsize::new(0),
        }))
    }
}

/// The angle the shorter side of `camera`'s frame spans at focal-length factor `scale`.
fn short_side(camera: &Camera, scale: f64) -> f64 {
    let half =
        (camera.width as f64 / (2.0 * camera.fx)).min(camera.height as f64 / (2.0 * camera.fy));
    2.0 * (half / scale).atan()
}

/// An image quad (detection indices, brightest first) and its queries: `queries[range]`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Quad {
    pub stars: [usize; 4],
    /// The round it belongs to (see [`ROUND_STARS`]).
    pub round: usize,
    pub queries: std::ops::Range<usize>,
}

/// A frame's quads and the keys they look up.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Lookup {
    pub quads: Vec<Quad>,
    pub queries: Vec<u32>,
}

/// Every 4-subset of `n` stars in brightness order: by the sum of the places, then
/// lexicographically.
pub fn quad_order(n: usize) -> Vec<[usize; 4]> {
    let mut out = Vec::new();
    for a in 0..n {
        for b in a + 1..n {
            for c in b + 1..n {
                for d in c + 1..n {
                    out.push([a, b, c, d]);
                }
            }
        }
    }
    out.sort_by_key(|q| (q.iter().sum::<usize>(), *q));
    out
}

/// How many rounds a frame of `n` detections has: those that bring in a quad.
pub fn rounds_for(n: usize) -> usize {
    let mut before = 0;
    ROUND_STARS
        .iter()
        .take_while(|&&k| {
            let more = n.min(k) > before && n.min(k) >= 4;
            before = k;
            more
        })
        .count()
}

/// The image quads of `rounds` (see [`ROUND_STARS`]), in order, and their query keys, for
/// focal-length factors `lo..hi` of `camera` and a centroid tolerance of `tol_px` per edge.
pub fn lookup(
    detections: &[Detection],
    camera: &Camera,
    (lo, hi): (f64, f64),
    tol_px: f64,
    rounds: std::ops::Range<usize>,
) -> Lookup {
    let n = detections.len().min(ROUND_STARS[ROUND_STARS.len() - 1]);
    let ends = [scaled(camera, lo), scaled(camera, hi)];
    // A known scale's two ends are one: its ratios are computed once.
    let n_ends = if lo == hi { 1 } else { 2 };
    let vectors: Vec<[Vector3<f64>; 2]> = detections[..n]
        .iter()
        .map(|d| ends.clone().map(|c| c.pixel_to_vector(d.x, d.y)))
        .collect();
    let mut out = Lookup::default();
    let rounds = rounds.filter(|&r| r < rounds_for(n)).flat_map(|round| {
        let before = if round == 0 {
            0
        } else {
            ROUND_STARS[round - 1]
        };
        quad_order(n.min(ROUND_STARS[round]))
            .into_iter()
            .filter(move |q| q[3] >= before)
            .map(move |q| (round, q))
    });
    // Each pair's chords (at each end) and length in pixels, once: a star is in hundreds of
    // the quads.
    let pair = |i: usize, j: usize| i * n + j;
    let mut chords = vec![[0.0; 2]; n * n];
    let mut lengths = vec![0.0; n * n];
    for i in 0..n {
        for j in i + 1..n {
            for e in 0..n_ends {
                chords[pair(i, j)][e] = patterns::chord(&vectors[i][e], &vectors[j][e]);
            }
            let (a, b) = (&detections[i], &detections[j]);
            lengths[pair(i, j)] = (a.x - b.x).hypot(a.y - b.y);
        }
    }
    for (round, stars) in rounds {
        // The quad's edges (its stars are in ascending order), as `patterns::chords` orders them.
        let edges = patterns::QUAD_EDGES.map(|(a, b)| pair(stars[a], stars[b]));
        // Pixel lengths of the edges, sorted as the chords are (nearly: the order of two
        // edges of almost equal length does not matter to their sorted values).
        let mut px = edges.map(|e| lengths[e]);
        px.sort_by(f64::total_cmp);
        if px[0] <= 2.0 * tol_px {
            continue;
        }
        let mut r_lo = [f64::MAX; 5];
        let mut r_hi = [f64::MIN; 5];
        // The ratios through the shortest and the longest focal length.
        let ends = (0..n_ends).map(|e| patterns::ratios(&edges.map(|k| chords[k][e])));
        for r in ends {
            for i in 0..5 {
                r_lo[i] = r_lo[i].min(r[i]);
                r_hi[i] = r_hi[i].max(r[i]);
            }
        }
        // Each ratio's bins: first, and how many.
        let mut bins = [(0u32, 0usize); 5];
        let mut count = 1usize;
        for i in 0..5 {
            let slack = r_hi[i] * tol_px * (1.0 / px[i] + 1.0 / px[5]);
            let first = patterns::bin(r_lo[i] - slack);
            bins[i] = (first, (patterns::bin(r_hi[i] + slack) - first) as usize + 1);
            count *= bins[i].1;
        }
        if count > MAX_QUERIES {
            continue;
        }
        let start = out.queries.len();
        let mut cell = [0u32; 5];
        for k in 0..count {
            let mut rest = k;
            for i in 0..5 {
                let (first, width) = bins[i];
                cell[i] = first + (rest % width) as u32;
                rest /= width;
            }
            out.queries.push(patterns::key_of(&cell));
        }
        debug_assert!(cell.iter().all(|&b| b < BINS));
        out.quads.push(Quad {
            stars,
            round,
            queries: start..out.queries.len(),
        });
    }
    out
}

impl Solver {
    /// The share of the false-match budget the scale-free pass takes is `1 / share`; None
    /// without the pass.
    pub fn scale_free_share(&self) -> Option<u64> {
        self.scale_free.as_ref().map(|sf| sf.limits.share)
    }

    /// The rounds of the pass for a frame of `n` detections (see [`rounds_for`],
    /// [`PassLimits::rounds`]).
    pub fn scale_free_rounds(&self, n: usize) -> usize {
        let most = self
            .scale_free
            .as_ref()
            .map_or(usize::MAX, |sf| sf.limits.rounds);
        rounds_for(n).min(most)
    }

    /// The focal-length factors the pass looks quads up for: the searched range, or the
    /// camera's own (1, 1).
    fn pattern_range(&self) -> (f64, f64) {
        self.settings.scale_range.unwrap_or((1.0, 1.0))
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

    /// Whether a frame goes through the scale-free pass on both detection stages before any
    /// scale walk ([`Solver::solve_frame_scale_free_first`]): with a searched scale, whose walk
    /// takes seconds. A known scale's passes take milliseconds: each detection stage has the
    /// pass and then the vote, as `solve_frame_with` runs them.
    pub fn scale_free_first(&self) -> bool {
        self.scale_free.is_some()
            && self.settings.scale_range.is_some()
            && self.detection_stages() > 1
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

    /// The queries of a frame's `rounds` of the scale-free pass; None when the solver has no
    /// pattern index (a known scale) or the frame has too few stars.
    pub fn scale_free_lookup(
        &self,
        detections: &[Detection],
        rounds: std::ops::Range<usize>,
    ) -> Option<Lookup> {
        self.scale_free.as_ref()?;
        let range = self.pattern_range();
        if detections.len() < 4 {
            return None;
        }
        Some(lookup(
            detections,
            &self.camera,
            range,
            self.settings.identify.pair_tol_px,
            rounds,
        ))
    }

    /// The scale-free pass after the lookup (`rows[q]` answers `lookup.queries[q]`): round
    /// by round (those the lookup holds), the quad hypotheses that pass the geometric checks, each refined in turn
    /// (the first [`MAX_REFINED`] of a round); the first accepted concludes as the vote's
    /// solutions do. None when none is accepted.
    pub fn finish_scale_free(
        &self,
        detections: &[Detection],
        lookup: &Lookup,
        rows: &[Rows],
        epoch: Option<f64>,
    ) -> Option<Outcome> {
        self.finish_scale_free_within(detections, lookup, rows, epoch, &mut Checked::default())
    }

    /// [`Solver::finish_scale_free`] of a lookup holding some of a frame's rounds, `checked`
    /// counting the patterns its earlier rounds checked ([`MAX_PATTERNS`]).
    pub fn finish_scale_free_within(
        &self,
        detections: &[Detection],
        lookup: &Lookup,
        rows: &[Rows],
        epoch: Option<f64>,
        checked: &mut Checked,
    ) -> Option<Outcome> {
        let perms = permutations();
        let rounds = self.scale_free_rounds(detections.len());
        let sf = self.scale_free.as_ref()?;
        let mut refinable = sf.limits.max_refined;
        for round in 0..rounds {
            let mut quads = lookup.quads.iter().filter(|q| q.round == round).peekable();
            if quads.peek().is_none() {
                continue;
            }
            if refinable == 0 {
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
            match self.scale_free_round(
                detections,
                quads,
                rows,
                (rounds, &mut refinable),
                epoch,
                &perms,
            ) {
                RoundEnd::Solved(o) => return Some(*o),
                RoundEnd::LeftToVote => return None,
                RoundEnd::Nothing => {}
            }
        }
        None
    }

    /// One round of the pass: its quads' hypotheses that pass the geometric checks, judged
    /// against the round's share of the false-match budget; at most `refinable` of them
    /// refined (and counted off it), of the frame's `rounds`.
    fn scale_free_round<'a>(
        &self,
        detections: &[Detection],
        quads: impl Iterator<Item = &'a Quad> + Clone,
        rows: &[Rows],
        (rounds, refinable): (usize, &mut usize),
        epoch: Option<f64>,
        perms: &[[usize; 4]],
    ) -> RoundEnd {
        let Some(sf) = self.scale_free.as_ref() else {
            return RoundEnd::Nothing;
        };
        let share = sf.limits.share;
        let (lo, hi) = self.pattern_range();
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
                        self.check_quad(detections, quad.stars, &img1, ids, refs, (lo, hi), perms)
                    {
                        hyps.push(h);
                    }
                }
            }
        }
        let found: u64 = quads
            .clone()
            .flat_map(|q| &rows[q.queries.clone()])
            .map(|r| u64::from(r.end.saturating_sub(r.start)))
            .sum();
        tracing::debug!(
            "scale-free round: {} quads, {found} patterns found, {} pass the checks",
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
        for h in hyps.iter().take(MAX_REFINED.min(*refinable)) {
            *refinable -= 1;
            let mut p = self.scale_free_prepared(h.scale);
            p.camera.mirrored ^= h.mirrored;
            let refs = self.bands[p.band].refs_at(epoch);
            let Some(refined) =
                refine::refine(h.r, detections, &refs, &p.camera, hypotheses, 4, &p.refine)
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
                return RoundEnd::Solved(Box::new(self.conclude(
                    detections,
                    &p,
                    (refined, hypotheses, 4),
                    epoch,
                )));
            }
        }
        RoundEnd::Nothing
    }

    /// The pass settings at a quad's focal length, as the scale walk's at that scale: its
    /// band, the scale step's tolerance, the focal length fitted (a searched scale), or the
    /// vote's (a known one).
    fn scale_free_prepared(&self, scale: f64) -> Prepared {
        let mut s = self.settings.identify;
        let mut rs = self.settings.refine;
        if self.settings.scale_range.is_some() {
            s.scale_tol += SCALE_STEP / 2.0;
            if rs.fit == CameraFit::None {
                rs.fit = CameraFit::Scale;
            }
        }
        Prepared {
            camera: scaled(&self.camera, scale),
            band: self.band_of(scale),
            vectors: Vec::new(),
            ranges: Vec::new(),
            n_vote: 0,
            k: 0,
            triangle_stars: 0,
            identify: s,
            refine: rs,
            method: crate::solve::radial::Method::Vote,
        }
    }
}

/// The lookup on the CPU twin: rows of every query. The table of key prefixes reads every
/// key once to save each query a few cache misses: it is made once a thousandth as many
/// queries as keys have been looked up without it (a one-frame run against Tycho-2's 86
/// million patterns looks up a few thousand, and making the table took 0.15 s).
pub fn rows_cpu(sf: &ScaleFree, lookup: &Lookup) -> Vec<Rows> {
    let keys = &sf.index.keys;
    let queries = &lookup.queries;
    let done = sf.unbucketed.load(Ordering::Relaxed);
    let buckets = match sf.buckets.get() {
        Some(b) => Some(b),
        None if done.saturating_add(queries.len()) > keys.len() / 1024 => {
            Some(sf.buckets.get_or_init(|| Buckets::new(keys)))
        }
        None => {
            sf.unbucketed.fetch_add(queries.len(), Ordering::Relaxed);
            None
        }
    };
    crate::cpu::pattern::pattern(keys, buckets, queries)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quads_come_brightest_first_and_once_each() {
        let q = quad_order(6);
        assert_eq!(q.len(), 15);
        assert_eq!(q[0], [0, 1, 2, 3]);
        assert_eq!(q[1], [0, 1, 2, 4]);
        let mut sorted = q.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), 15);
        assert_eq!(permutations().len(), 24);
    }
}
