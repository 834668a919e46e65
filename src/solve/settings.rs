//! The settings of a run that shape identification, besides the camera.

use super::detect::DetectSettings;
use super::identify::IdentifySettings;
use super::mag_limit::FULL_SKY_SR;
use super::radial::Method;
use super::refine::RefineSettings;
use crate::catalog::DoubleStars;

/// Everything that shapes a run besides the camera.
#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Observation epoch (Julian year) for proper motion.
    pub epoch: f64,
    /// Faintest catalog magnitude used; None = from the field of view (see
    /// [`auto_mag_limit`](super::auto_mag_limit)).
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
    /// Look the frame's star quads up in a pattern index first (`scale_free.rs`; the vote
    /// only): the passes then take only the frames that does not solve.
    pub scale_free: bool,
    /// Walk a searched scale wider than [`WALK_MAX_RATIO`] too, when the scale-free pass does
    /// not solve a frame (`--fov-walk`).
    pub walk_wide: bool,
    /// Frames that do not solve are tried again: with more voting stars
    /// ([`RETRY_VOTE_STARS`]), with voters spread over the frame (`SPREAD_CELLS`), then
    /// with wide tolerances ([`WIDE_PAIR_TOL_PX`], [`WIDE_MATCH_RADIUS_PX`]).
    pub retry: bool,
    /// The wide retry (with `retry`) only for frames of at least this many detections
    /// ([`WIDE_MIN_STARS`]).
    pub wide_min_stars: usize,
    /// Frames that do not solve are detected again with the matched filter (fainter stars)
    /// and tried again, when the filter is not on already and `retry` is, and it finds a star
    /// the first detection did not ([`detect::adds_stars`]).
    pub detect_retry: bool,
    /// How stars are identified: the vote, or radial features + triangles.
    pub method: crate::solve::radial::Method,
    /// Solid angle the catalog covers: the whole sky, or a hinted region's cone (what the
    /// automatic magnitude limit counts stars per field against).
    pub sky_sr: f64,
    /// Searches of one frame that share the false-match budget, each judged against its share:
    /// 2 when a pointing hint's regional search may be followed by lost-in-space.
    pub searches: u64,
    /// Whether a frame may be a mirror image of the sky relative to the camera.
    pub parity: Parity,
}

/// The parity of the frames relative to the camera model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Parity {
    /// As the camera says ([`Camera::mirrored`]).
    AsCamera,
    /// Either: each hypothesis takes the parity its matched stars fit (a FITS image stored
    /// the conventional way is a mirror image in row-0-first order, a photograph or a star
    /// tracker's frame is not; with `--fov-deg` gpustar is not told which). Each hypothesis
    /// then stands for two attitudes, and the false-match test counts both.
    Either,
}

impl Settings {
    /// The defaults (`Default`), as a constant: the run configuration's (`config`) come
    /// from here.
    pub const DEFAULT: Settings = Settings {
        epoch: 2000.0,
        mag_limit: None,
        double_stars: DoubleStars::Merge,
        double_star_px: 2.0,
        detect: DetectSettings::DEFAULT,
        identify: IdentifySettings::DEFAULT,
        refine: RefineSettings::DEFAULT,
        table_cache: true,
        scale_range: None,
        scale_free: true,
        walk_wide: false,
        retry: true,
        wide_min_stars: WIDE_MIN_STARS,
        detect_retry: true,
        method: Method::Vote,
        sky_sr: FULL_SKY_SR,
        searches: 1,
        parity: Parity::AsCamera,
    };
}

impl Default for Settings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl Settings {
    /// Whether frames go through the scale-free pass first (`scale_free`).
    pub fn scale_free_on(&self) -> bool {
        self.scale_free && self.method == Method::Vote
    }

    /// Whether a frame the scale-free pass does not solve is voted scale by scale (the walk):
    /// always without the pass; with it, where the scale is known or searched within
    /// [`WALK_MAX_RATIO`], or where `walk_wide` asks.
    pub fn walks(&self) -> bool {
        !self.scale_free_on()
            || self.walk_wide
            || self
                .scale_range
                .is_none_or(|(lo, hi)| hi / lo <= WALK_MAX_RATIO)
    }
}

/// The widest searched scale (`hi / lo` of the focal-length range, here ±5 %: about 100 steps
/// of [`SCALE_STEP`]) that is walked, scale by scale, when the scale-free pass does not solve
/// a frame. A wider one (`--fov-deg LOW..HIGH`) is walked only when asked (`--fov-walk`): the
/// walk of 8..20° takes 7 s to a minute a frame, and on the frames of docs/speed.md ("The end
/// of the walk") it solved none that the pass had not.
pub const WALK_MAX_RATIO: f64 = 1.05 / 0.95;

/// The wide retry needs this many detections (`Settings::wide_min_stars`, `--wide-min-stars`).
/// Its 4 px sides match thousands of catalog triangles in a sparse frame, which its triangle
/// fallback enumerates and refines: 20-170 ms a frame. On 1,200 independent frames (ten sets
/// of 8-18°, two with 1-1.5 px of position noise) and the 60 real ones it ran 156 times on
/// frames of 8 detections or fewer and solved none; on frames of 9 or more it solved 178 of
/// 213 (docs/speed.md, "The wide retry's stars"). Fewer detections than this are not tried
/// with it, and the false-match test no longer counts its hypotheses for them.
pub const WIDE_MIN_STARS: usize = 9;
