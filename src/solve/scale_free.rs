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
use super::bands::{WALK_MAX_RATIO, scaled};
use super::detect::{self, Detection};
use super::settings::Settings;
use crate::camera::Camera;
use crate::catalog::Catalog;
use crate::catalog::patterns::{self, BINS, PatternIndex};
use crate::cpu::pattern::{Buckets, Rows};
use crate::error::Result;
use nalgebra::{Matrix3, Vector3};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};

mod check;
mod stage;

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

/// Where a frame's scale-free pass stands between lookups, so that it ends the same whether its
/// rounds are looked up one at a time (the CPU) or all at once (the GPU).
#[derive(Clone, Copy, Debug, Default)]
pub struct Checked {
    /// The catalog patterns checked so far ([`MAX_PATTERNS`]).
    pub patterns: u64,
    /// Quad hypotheses refined so far ([`PassLimits::max_refined`]).
    pub refined: usize,
    /// The pass is over: a round was left unchecked, the hypotheses it may refine are spent, or
    /// a solution matched too few stars and left the frame to the vote.
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

/// A quad hypothesis that passed the geometric checks: image stars `stars[i]` are reference
/// stars `refs[i]` at focal-length factor `scale`, attitude `r`, the image a mirror image
/// relative to the camera when `mirrored` (only where the parity is left open).
#[derive(Clone, Copy, Debug)]
pub struct Hypothesis {
    pub stars: [usize; 4],
    pub refs: [u32; 4],
    pub scale: f64,
    pub r: Matrix3<f64>,
    pub mirrored: bool,
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
    use super::check::permutations;
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
