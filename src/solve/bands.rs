//! Scale bands (one distance table per band of focal-length factors), the passes and retries
//! of identification, and the order detections are tried in.

use super::detect::Detection;
use super::mag_limit::auto_mag_limit_in;
use super::settings::Settings;
pub use super::settings::{WALK_MAX_RATIO, WIDE_MIN_STARS};
use crate::camera::Camera;
use crate::catalog::table::{self, PairTable, TableOrigin};
use crate::catalog::{Catalog, RefCatalog, Selection};
use crate::error::Result;
use nalgebra::Vector3;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

/// Widest ratio of focal lengths one band of a scale search covers. A band's reference stars
/// are those for its middle field (about [`AUTO_STARS_IN_VIEW`](super::AUTO_STARS_IN_VIEW) in view there, from 27 to 60
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
    /// The distance table and how it was obtained: loaded when the band is made, or (with a
    /// scale-free pass, which solves most frames without it) when first asked for.
    table: OnceLock<(PairTable, TableOrigin)>,
    /// What the table is made from: the catalog's content hash, the largest separation, and
    /// whether the cache is used.
    table_from: (u64, f64, bool),
    /// The reference stars' radial features (`--method radial`), from `table`.
    pub radial: Option<crate::solve::radial::RadialTable>,
    /// `refs`' directions by id, packed: made when the triangles first ask for them.
    directions: OnceLock<Vec<Vector3<f64>>>,
}

impl Band {
    /// The stars for the field of focal-length factor `middle` (unless the settings fix the
    /// magnitude limit), and their pairs out to the diagonal of the widest field, `lo`.
    pub(crate) fn new(
        catalog: &Catalog,
        camera: &Camera,
        settings: &Settings,
        (lo, hi): (f64, f64),
        middle: f64,
        mag_limit: Option<f64>,
        lazy: bool,
    ) -> Result<Band> {
        let middle = scaled(camera, middle);
        if mag_limit.or(settings.mag_limit).is_none() {
            crate::catalog::load_sorted_mags(catalog, settings.table_cache);
        }
        let selection = Selection {
            epoch: settings.epoch,
            mag_limit: mag_limit
                .or(settings.mag_limit)
                .unwrap_or_else(|| auto_mag_limit_in(catalog, &middle, settings.sky_sr)),
            double_stars: settings.double_stars,
            double_sep_rad: settings.double_star_px * middle.ifov_rad(),
        };
        let refs = crate::catalog::load_or_select(catalog, selection, settings.table_cache)?;
        check_table_size(&refs, scaled(camera, lo).diagonal_rad())?;
        let table_from = (
            catalog.content_hash,
            scaled(camera, lo).diagonal_rad(),
            settings.table_cache,
        );
        let table = OnceLock::new();
        let radial = settings.method == crate::solve::radial::Method::Radial;
        if !lazy || radial {
            let _ = table.set(load_table(&refs, table_from));
        }
        let radial = radial.then(|| {
            let s = &settings.identify;
            let table = &table.get().expect("loaded above").0;
            crate::solve::radial::RadialTable::load_or_build(
                &refs,
                table,
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
            table_from,
            radial,
            directions: OnceLock::new(),
        })
    }

    /// The distance table (loaded or built now if it was not yet).
    pub fn table(&self) -> &PairTable {
        &self.loaded().0
    }

    /// How the distance table was obtained (loading it now if it was not yet).
    pub fn table_origin(&self) -> &TableOrigin {
        &self.loaded().1
    }

    fn loaded(&self) -> &(PairTable, TableOrigin) {
        self.table
            .get_or_init(|| load_table(&self.refs, self.table_from))
    }

    /// The reference stars' directions by id, at the selection's epoch (the table's), packed:
    /// the triangle fallback reads tens of thousands of them at random, and packing them for
    /// each search (2 MB of a 10° camera's deep band, read out of 88-byte stars) was a tenth of
    /// its time (docs/speed.md, "Cached tables mapped").
    pub fn directions(&self) -> &[Vector3<f64>] {
        self.directions
            .get_or_init(|| (0..self.refs.len()).map(|id| self.refs.v(id)).collect())
    }

    /// The reference stars at a frame's own epoch (`refs` when it has none, or the same).
    pub fn refs_at(&self, epoch: Option<f64>) -> Arc<RefCatalog> {
        refs_at(&self.refs, epoch)
    }
}

/// `refs` at a frame's own epoch: `refs` itself when the frame has none or one within
/// [`SAME_EPOCH_YEARS`] of the selection's, else `refs` at the frame's day (the stars shared,
/// see [`RefCatalog::at_epoch`]).
fn refs_at(refs: &Arc<RefCatalog>, epoch: Option<f64>) -> Arc<RefCatalog> {
    match epoch.filter(|e| (e - refs.selection.epoch).abs() > SAME_EPOCH_YEARS) {
        // At the day's own epoch, not the frame's: the positions (and the records' epoch) are
        // those of every frame of that day, whichever a thread reached first.
        Some(e) => Arc::new(refs.at_epoch(day_epoch(epoch_day(e)))),
        None => refs.clone(),
    }
}

fn load_table(
    refs: &RefCatalog,
    (hash, max_sep, cache): (u64, f64, bool),
) -> (PairTable, TableOrigin) {
    table::load_or_build(refs, hash, max_sep, cache)
}

/// The most pairs a lost-in-space distance table may be expected to hold: 500 million rows
/// take 6 GB (a key and two ids each). A deeper selection (Tycho-2 at 2°: 2 billion pairs) is
/// refused before it is built, with what to do instead, rather than exhausting the memory;
/// frames with a `--hint` still solve from their regions.
pub const MAX_TABLE_ROWS: f64 = 5e8;

/// Refuse a selection whose table would hold more than [`MAX_TABLE_ROWS`] pairs closer than
/// `max_sep_rad`, estimated as for stars spread evenly over the sky: n²/2 · (1 − cos θ)/2.
fn check_table_size(refs: &RefCatalog, max_sep_rad: f64) -> Result<()> {
    let n = refs.len() as f64;
    let rows = n * n / 2.0 * (1.0 - max_sep_rad.cos()) / 2.0;
    if rows > MAX_TABLE_ROWS {
        crate::error::fail!(
            Catalog,
            "{} catalog stars to magnitude {} make a lost-in-space table of about {:.0} million \
             pairs ({:.0} GB) for this field: give the pointing (--hint), or a brighter \
             --mag-limit",
            refs.len(),
            refs.selection.mag_limit,
            rows / 1e6,
            rows * 12.0 / 1e9
        );
    }
    Ok(())
}

/// The catalog, and the selections made from it for solutions' fields: at the run's epoch, by
/// magnitude limit in tenths (None = the selection failed: fewer than 3 stars), each moved to
/// frames' own days as a band's stars are. Selected once per limit, not once per frame's
/// date: a frame that carries its own date used to make its own selection (sorting the
/// catalog), a fifth of a 12-degree frame's time with the field searched, and kept it.
pub(crate) struct Deeper {
    catalog: Catalog,
    selections: Mutex<HashMap<i64, Option<Arc<RefCatalog>>>>,
}

impl Deeper {
    pub(crate) fn new(catalog: &Catalog) -> Deeper {
        Deeper {
            catalog: catalog.clone(),
            selections: Mutex::new(HashMap::new()),
        }
    }

    /// The stars a solution's fitted field `camera` calls for (about
    /// [`AUTO_STARS_IN_VIEW`](super::AUTO_STARS_IN_VIEW) in view), at the frame's `epoch`;
    /// None when that is no deeper than `voted_with`, the selection the frame was identified
    /// with, or the selection fails.
    pub(crate) fn refs_for(
        &self,
        camera: &Camera,
        sky_sr: f64,
        voted_with: Selection,
        epoch: Option<f64>,
    ) -> Option<Arc<RefCatalog>> {
        let mag_limit = auto_mag_limit_in(&self.catalog, camera, sky_sr);
        if mag_limit <= voted_with.mag_limit {
            return None;
        }
        let selected = self
            .selections
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .entry((mag_limit * 10.0).round() as i64)
            .or_insert_with(|| {
                let selection = Selection {
                    mag_limit,
                    ..voted_with
                };
                RefCatalog::select(&self.catalog, selection)
                    .ok()
                    .map(Arc::new)
            })
            .clone()?;
        Some(refs_at(&selected, epoch))
    }
}

/// Frames dated within this many years of the run's epoch use the run's star positions
/// (about a day: proper motions move no star by a milliarcsecond in that time).
pub(crate) const SAME_EPOCH_YEARS: f64 = 0.003;

/// The day of an epoch (Julian year): frames of one day share their stars' positions.
pub(crate) fn epoch_day(epoch: f64) -> i64 {
    (epoch * 365.25).round() as i64
}

/// The epoch star positions are computed at for a day (within half a day of any frame of it:
/// proper motions move no star by a microarcsecond in that time).
pub(crate) fn day_epoch(day: i64) -> f64 {
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

/// One way of trying a frame: a focal-length factor, the band it falls in, what the vote
/// is given, and the identifier that runs (one of the method's
/// `identifiers`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pass {
    pub scale: f64,
    pub band: usize,
    pub kind: PassKind,
    pub method: crate::solve::radial::Method,
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
    /// The vote against a shallow selection ([`SHALLOW_STARS_IN_VIEW`](super::SHALLOW_STARS_IN_VIEW) stars in view), for
    /// frames that show few stars; the solution is then refined against the automatic one.
    Shallow,
}

impl PassKind {
    /// Relative spacing of this kind's focal lengths in a scale search.
    pub(crate) fn scale_step(self) -> f64 {
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
/// (220 triangles; [`triangle::TRIANGLE_STARS`](super::triangle::TRIANGLE_STARS) otherwise): the brightest star of each cell
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

/// The band of `bands` (in increasing focal length) that focal-length factor `scale` falls in:
/// the first whose upper end reaches it, else the last.
pub(crate) fn band_for(bands: &[Band], scale: f64) -> usize {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalog::DoubleStars;
    use crate::solve::Settings;
    use crate::solve::radial::Method;

    /// The walk runs for a known scale and a range within ±5 %, not for a wider one unless
    /// asked, and always without the scale-free pass.
    #[test]
    fn only_narrow_ranges_are_walked_after_the_scale_free_pass() {
        let at = |range: Option<(f64, f64)>| Settings {
            scale_range: range,
            ..Settings::default()
        };
        assert!(at(None).walks());
        assert!(at(Some((0.99, 1.01))).walks());
        assert!(at(Some((0.951, 1.049))).walks());
        let wide = at(Some((0.8, 1.25)));
        assert!(!wide.walks());
        assert!(
            Settings {
                walk_wide: true,
                ..wide
            }
            .walks()
        );
        for off in [
            Settings {
                scale_free: false,
                ..wide
            },
            Settings {
                method: Method::Radial,
                ..wide
            },
        ] {
            assert!(off.walks());
        }
    }

    /// One selection serves frames of every date: moved to each frame's day (the same day's
    /// frames read the same positions), its stars shared rather than copied.
    #[test]
    fn a_selection_moves_to_frames_days() {
        let selection = Selection {
            epoch: 2025.0,
            mag_limit: 4.0,
            double_stars: DoubleStars::Keep,
            double_sep_rad: 0.0,
        };
        let refs = Arc::new(RefCatalog::select(&Catalog::builtin(), selection).unwrap());
        assert!(Arc::ptr_eq(&refs_at(&refs, None), &refs));
        assert!(Arc::ptr_eq(&refs_at(&refs, Some(2025.001)), &refs));
        let (morning, evening) = (2016.2568, 2016.2571);
        let a = refs_at(&refs, Some(morning));
        let b = refs_at(&refs, Some(evening));
        assert_eq!(a.selection.epoch, day_epoch(epoch_day(morning)));
        assert_eq!(b.selection.epoch, a.selection.epoch);
        assert_eq!(a.len(), refs.len());
        let dt = a.selection.epoch - 2025.0;
        let mut moved = 0;
        for id in 0..refs.len() {
            let s = refs.star(id);
            // Bit for bit what a moved copy of every star held.
            assert_eq!(a.v(id), (s.v + s.motion * dt).normalize());
            assert_eq!(b.v(id), a.v(id));
            moved += (a.v(id) != s.v) as usize;
        }
        assert!(moved * 2 > refs.len(), "{moved} of {} moved", refs.len());
    }
}
