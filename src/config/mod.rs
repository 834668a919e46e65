//! One run configuration: every option that shapes a run's records, with its type, range and
//! default stated once ([`RunConfig`], [`DEFAULTS`], the bounds below). The command line takes
//! its defaults and ranges from here and maps its options onto it, as do a config file
//! (`--config run.toml`, the command line's names with `_` for `-`) and the Python package;
//! the library maps it onto [`Settings`] and the other stages' options. A run's configuration
//! is kept beside its output ([`sidecar`]), and `--resume` refuses a run whose configuration
//! differs.
//!
//! Options that shape only where output goes (`-o`, `--wcs-dir`, `--format`, `--quiet`, …) or
//! which inputs a run takes (`-r`, `--shard`) stay the command line's.

pub mod sidecar;

use crate::camera::Camera;
use crate::catalog::Catalog;
use crate::catalog::DoubleStars;
use crate::error::{Error, Result};
use crate::io::dark::Darks;
use crate::pipeline::{BackendChoice, CameraSource, DEFAULT_MAX_PIXELS, Solvers};
use crate::solve::detect::Centroid;
use crate::solve::radial::Method;
use crate::solve::refine::CameraFit;
use crate::solve::{Parity, Settings};
use crate::streaks::identify::IdentifySettings as TleSettings;
use crate::streaks::reduce::Astrometry;
use crate::streaks::{StreakOptions, StreakSettings};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The inclusive range a number option takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds<T> {
    pub min: T,
    pub max: T,
}

impl<T> Bounds<T> {
    pub const fn new(min: T, max: T) -> Bounds<T> {
        Bounds { min, max }
    }
}

pub const EPOCH: Bounds<f64> = Bounds::new(1000.0, 3000.0);
pub const MAG_LIMIT: Bounds<f64> = Bounds::new(-2.0, 20.0);
pub const DOUBLE_STAR_PX: Bounds<f64> = Bounds::new(0.0, 100.0);
pub const PIXEL_ASPECT: Bounds<f64> = Bounds::new(0.5, 2.0);
pub const SIGMA: Bounds<f64> = Bounds::new(0.5, 100.0);
pub const VOTE_STARS: Bounds<usize> = Bounds::new(4, 200);
pub const PAIR_TOL_PX: Bounds<f64> = Bounds::new(0.01, 5.0);
pub const SCALE_TOL: Bounds<f64> = Bounds::new(0.0, 0.05);
pub const MATCH_RADIUS_PX: Bounds<f64> = Bounds::new(0.1, 20.0);
pub const MAX_FALSE_PROB: Bounds<f64> = Bounds::new(1e-300, 0.5);
pub const BATCH_SIZE: Bounds<usize> = Bounds::new(1, 4096);
pub const MAX_MEGAPIXELS: Bounds<f64> = Bounds::new(1e-6, 4300.0);
pub const DUT1: Bounds<f64> = Bounds::new(-1.0, 1.0);
pub const STREAK_SIGMA: Bounds<f64> = Bounds::new(0.5, 100.0);
pub const TLE_CROSS: Bounds<f64> = Bounds::new(1.0, 36_000.0);
pub const TLE_ALONG: Bounds<f64> = Bounds::new(0.01, 600.0);
pub const FRAME_INTERVAL: Bounds<f64> = Bounds::new(1e-9, 1e9);

/// The focal-length factors searched around a header's scale, unless `fov_tolerance` says.
pub const HEADER_SCALE_RANGE: (f64, f64) = (0.97, 1.03);

/// A number checked against its bounds, with the message every front end gives.
pub fn check_within<T: PartialOrd + std::fmt::Display + Copy>(
    name: &str,
    v: T,
    b: Bounds<T>,
) -> std::result::Result<T, String> {
    // NaN compares false with both ends, and so is refused too.
    if b.min <= v && v <= b.max {
        Ok(v)
    } else {
        Err(format!("{name}: {v} is outside {} to {}", b.min, b.max))
    }
}

/// A horizontal field of view, degrees: above 0 and below 170.
pub fn check_fov(x: f64) -> std::result::Result<f64, String> {
    if x > 0.0 && x < 170.0 {
        Ok(x)
    } else {
        Err(format!(
            "field of view must be between 0 and 170 degrees, got {x}"
        ))
    }
}

/// A pixel scale, arcseconds: above 0 and at most 36000 (10° a pixel).
pub fn check_scale(x: f64) -> std::result::Result<f64, String> {
    if x > 0.0 && x <= 36_000.0 {
        Ok(x)
    } else {
        Err(format!(
            "pixel scale must be above 0 and at most 36000 arcsec, got {x}"
        ))
    }
}

/// `fov_deg` or `scale_arcsec`: one value, or a range LOW..HIGH to search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ValueOrRange {
    Exact(f64),
    Range(f64, f64),
}

impl ValueOrRange {
    /// `12.5` or `8..20`, each value checked by `num`.
    pub fn parse(
        s: &str,
        num: impl Fn(f64) -> std::result::Result<f64, String>,
    ) -> std::result::Result<ValueOrRange, String> {
        let read = |v: &str| match v.trim().parse::<f64>() {
            Ok(x) => num(x),
            Err(_) => Err(format!("{v:?} is not a number")),
        };
        match s.split_once("..") {
            Some((a, b)) => ValueOrRange::range(read(a)?, read(b)?),
            None => Ok(ValueOrRange::Exact(read(s)?)),
        }
    }

    /// A range, LOW < HIGH.
    pub fn range(lo: f64, hi: f64) -> std::result::Result<ValueOrRange, String> {
        if lo < hi {
            Ok(ValueOrRange::Range(lo, hi))
        } else {
            Err(format!("expected LOW..HIGH, got {lo}..{hi}"))
        }
    }

    fn check(self, num: impl Fn(f64) -> std::result::Result<f64, String>) -> Result<()> {
        let r = match self {
            ValueOrRange::Exact(x) => num(x).map(|_| ()),
            ValueOrRange::Range(a, b) => num(a)
                .and(num(b))
                .and(ValueOrRange::range(a, b).map(|_| ())),
        };
        r.map_err(Error::Config)
    }
}

impl Serialize for ValueOrRange {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            ValueOrRange::Exact(x) => s.serialize_f64(*x),
            ValueOrRange::Range(a, b) => s.serialize_str(&format!("{a}..{b}")),
        }
    }
}

impl<'de> Deserialize<'de> for ValueOrRange {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Number(f64),
            Text(String),
            Pair([f64; 2]),
        }
        match Raw::deserialize(d)? {
            Raw::Number(x) => Ok(ValueOrRange::Exact(x)),
            Raw::Text(s) => ValueOrRange::parse(&s, Ok).map_err(serde::de::Error::custom),
            Raw::Pair([a, b]) => ValueOrRange::range(a, b).map_err(serde::de::Error::custom),
        }
    }
}

crate::choice! {
    /// Whether a frame may be a mirror image of the sky (`parity`).
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum ParityChoice {
        Either = "either", "Each frame takes the parity its stars fit",
        Camera = "camera", "As the camera file's `mirrored` says",
    }
}

crate::choice! {
    /// Detection's matched filter (`detect_filter`).
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum DetectFilter {
        None = "none", "The pixels alone are thresholded (with --sequence, the filter's \
            sources apart from theirs are added)",
        Binomial = "binomial", "Each pixel's 3x3 binomial smoothing is thresholded as well",
    }
}

/// Every option that shapes a run's records. Field names are the command line's long options
/// with `_` for `-`; a config file sets any of them, and the others keep [`DEFAULTS`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunConfig {
    // Camera and sky.
    pub camera: Option<PathBuf>,
    pub fov_deg: Option<ValueOrRange>,
    pub scale_arcsec: Option<ValueOrRange>,
    pub pixel_aspect: Option<f64>,
    pub fov_tolerance: Option<f64>,
    pub fov_walk: bool,
    pub fit: CameraFit,
    pub parity: Option<ParityChoice>,
    pub catalog: Option<PathBuf>,
    pub epoch: f64,
    pub mag_limit: Option<f64>,
    pub double_stars: DoubleStars,
    pub double_star_px: f64,
    pub no_cache: bool,
    pub hint: Option<String>,
    // Detection and identification.
    pub sigma: f64,
    pub detect_filter: DetectFilter,
    pub centroid: Centroid,
    pub method: Method,
    pub vote_stars: usize,
    pub pair_tol_px: f64,
    pub no_retry: bool,
    pub wide_min_stars: usize,
    pub scale_tol: f64,
    pub match_radius_px: f64,
    pub max_false_prob: f64,
    pub dark: Option<PathBuf>,
    pub dark_median: bool,
    // Input and run.
    pub xyls: bool,
    pub image_size: Option<(u32, u32)>,
    pub backend: BackendChoice,
    pub batch_size: usize,
    pub max_megapixels: f64,
    // Sequences.
    pub sequence: bool,
    pub frame_interval: Option<f64>,
    // Streaks.
    pub streaks: bool,
    pub station: Option<String>,
    pub astrometry: Astrometry,
    pub dut1: Option<f64>,
    pub streak_sigma: f64,
    pub tle: Option<PathBuf>,
    pub tle_cross: f64,
    pub tle_along: f64,
}

/// Every option's default: the library's own ([`Settings::DEFAULT`] and the stages'), so that
/// each is stated once.
pub const DEFAULTS: RunConfig = RunConfig {
    camera: None,
    fov_deg: None,
    scale_arcsec: None,
    pixel_aspect: None,
    fov_tolerance: None,
    fov_walk: Settings::DEFAULT.walk_wide,
    fit: Settings::DEFAULT.refine.fit,
    parity: None,
    catalog: None,
    epoch: Settings::DEFAULT.epoch,
    mag_limit: Settings::DEFAULT.mag_limit,
    double_stars: Settings::DEFAULT.double_stars,
    double_star_px: Settings::DEFAULT.double_star_px,
    no_cache: !Settings::DEFAULT.table_cache,
    hint: None,
    sigma: Settings::DEFAULT.detect.k_sigma as f64,
    detect_filter: DetectFilter::None,
    centroid: Settings::DEFAULT.detect.centroid,
    method: Settings::DEFAULT.method,
    vote_stars: Settings::DEFAULT.identify.vote_stars,
    pair_tol_px: Settings::DEFAULT.identify.pair_tol_px,
    no_retry: !Settings::DEFAULT.retry,
    wide_min_stars: Settings::DEFAULT.wide_min_stars,
    scale_tol: Settings::DEFAULT.identify.scale_tol,
    match_radius_px: Settings::DEFAULT.refine.match_radius_px,
    max_false_prob: Settings::DEFAULT.refine.max_false_prob,
    dark: None,
    dark_median: false,
    xyls: false,
    image_size: None,
    backend: BackendChoice::Auto,
    batch_size: 32,
    max_megapixels: DEFAULT_MAX_PIXELS as f64 / 1e6,
    sequence: false,
    frame_interval: None,
    streaks: false,
    station: None,
    astrometry: Astrometry::Auto,
    dut1: None,
    streak_sigma: StreakSettings::DEFAULT.k_sigma as f64,
    tle: None,
    tle_cross: TleSettings::DEFAULT.cross_arcsec,
    tle_along: TleSettings::DEFAULT.along_s,
};

impl Default for RunConfig {
    fn default() -> Self {
        DEFAULTS
    }
}

/// The camera source, the camera file's magnitude limit, and the range of focal-length factors
/// to search.
pub type CameraChoice = (CameraSource, Option<f64>, Option<(f64, f64)>);

impl RunConfig {
    /// A config file's options (TOML, the names of [`RunConfig`]), checked.
    pub fn from_toml(text: &str, source: &Path) -> Result<RunConfig> {
        let c: RunConfig = toml::from_str(text)
            .map_err(|e| Error::Config(format!("{}: {}", source.display(), e.message())))?;
        c.validate()?;
        Ok(c)
    }

    /// Every option within its range, and the options that go together together.
    pub fn validate(&self) -> Result<()> {
        let f = |name, v, b| check_within(name, v, b).map(|_| ()).map_err(Error::Config);
        f("epoch", self.epoch, EPOCH)?;
        if let Some(m) = self.mag_limit {
            f("mag_limit", m, MAG_LIMIT)?;
        }
        f("double_star_px", self.double_star_px, DOUBLE_STAR_PX)?;
        if let Some(a) = self.pixel_aspect {
            f("pixel_aspect", a, PIXEL_ASPECT)?;
        }
        if let Some(t) = self.fov_tolerance
            && !(t > 0.0 && t < 0.5)
        {
            return Err(Error::Config(
                "fov_tolerance must be between 0 and 0.5".into(),
            ));
        }
        if let Some(v) = self.fov_deg {
            v.check(check_fov)?;
        }
        if let Some(v) = self.scale_arcsec {
            v.check(check_scale)?;
        }
        f("sigma", self.sigma, SIGMA)?;
        check_within("vote_stars", self.vote_stars, VOTE_STARS).map_err(Error::Config)?;
        f("pair_tol_px", self.pair_tol_px, PAIR_TOL_PX)?;
        f("scale_tol", self.scale_tol, SCALE_TOL)?;
        f("match_radius_px", self.match_radius_px, MATCH_RADIUS_PX)?;
        f("max_false_prob", self.max_false_prob, MAX_FALSE_PROB)?;
        check_within("batch_size", self.batch_size, BATCH_SIZE).map_err(Error::Config)?;
        f("max_megapixels", self.max_megapixels, MAX_MEGAPIXELS)?;
        if let Some(d) = self.dut1 {
            f("dut1", d, DUT1)?;
        }
        f("streak_sigma", self.streak_sigma, STREAK_SIGMA)?;
        f("tle_cross", self.tle_cross, TLE_CROSS)?;
        f("tle_along", self.tle_along, TLE_ALONG)?;
        if let Some(i) = self.frame_interval {
            f("frame_interval", i, FRAME_INTERVAL)?;
        }
        let given = [
            (self.camera.is_some(), "camera"),
            (self.fov_deg.is_some(), "fov_deg"),
            (self.scale_arcsec.is_some(), "scale_arcsec"),
        ];
        if given.iter().filter(|g| g.0).count() > 1 {
            return Err(Error::Config(
                "camera, fov_deg and scale_arcsec are one each: give one of them".into(),
            ));
        }
        if let Some(h) = &self.hint {
            crate::sky::hint::parse_hint(h)?;
        }
        if let Some(s) = &self.station {
            crate::sky::station::parse_station(s)?;
        }
        if self.dark.is_some() && self.dark_median {
            return Err(Error::Config(
                "dark and dark_median: give one of them".into(),
            ));
        }
        Ok(())
    }

    /// The camera: from the camera file (read now), or `fixed` when the caller has read one
    /// already (Python takes the file's text too).
    pub fn camera_source(&self, fixed: Option<(Camera, Option<f64>)>) -> Result<CameraChoice> {
        let tolerance = self.fov_tolerance.map(|t| (1.0 - t, 1.0 + t));
        let aspect = self.pixel_aspect.unwrap_or(1.0);
        if self.pixel_aspect.is_some() && self.fov_deg.is_none() && self.scale_arcsec.is_none() {
            return Err(Error::Config(
                "pixel_aspect goes with fov_deg or scale_arcsec (a camera file gives fy_px)".into(),
            ));
        }
        let fov = |fov_x_deg| CameraSource::Fov {
            fov_x_deg,
            pixel_aspect: aspect,
        };
        let scale = |arcsec_per_px| CameraSource::Scale {
            arcsec_per_px,
            pixel_aspect: aspect,
        };
        // A range searches the scale around the camera of its middle value: focal lengths
        // scale as 1 / tan(FOV / 2), and as 1 / tan(pixel scale).
        let factors =
            |f: &dyn Fn(f64) -> f64, lo: f64, mid: f64, hi: f64| (f(hi) / f(mid), f(lo) / f(mid));
        let header_only = self.streaks && self.astrometry == Astrometry::Header;
        let fixed = match (fixed, &self.camera) {
            (Some(f), _) => Some(f),
            (None, Some(path)) => Some(Camera::from_toml_file(path)?),
            (None, None) => None,
        };
        Ok(match (fixed, self.fov_deg, self.scale_arcsec) {
            (Some((cam, mag)), ..) => (CameraSource::Fixed(cam), mag, tolerance),
            (None, Some(ValueOrRange::Exact(deg)), _) => (fov(deg), None, tolerance),
            (None, Some(ValueOrRange::Range(lo, hi)), _) => {
                let mid = (lo + hi) / 2.0;
                let f = |fov: f64| 1.0 / (fov.to_radians() / 2.0).tan();
                (fov(mid), None, Some(factors(&f, lo, mid, hi)))
            }
            (None, None, Some(ValueOrRange::Exact(s))) => (scale(s), None, tolerance),
            (None, None, Some(ValueOrRange::Range(lo, hi))) => {
                let mid = (lo + hi) / 2.0;
                let f = |s: f64| 1.0 / (s / 3600.0).to_radians().tan();
                (scale(mid), None, Some(factors(&f, lo, mid, hi)))
            }
            (None, None, None) if header_only => (CameraSource::None, None, None),
            // Nothing given: each frame's header states its scale, as ASTAP reads it; a
            // nominal focal length or pixel size is a few per cent off (the Seestar S50's: 1 %).
            (None, None, None) => (
                CameraSource::Header,
                None,
                tolerance.or(Some(HEADER_SCALE_RANGE)),
            ),
        })
    }

    /// The parity: as `parity` says, else open with a field of view, a pixel scale or a
    /// header's scale (which say nothing of it), the camera file's with a camera.
    pub fn parity_for(&self, source: &CameraSource) -> Parity {
        match (self.parity, source) {
            (Some(ParityChoice::Either), _)
            | (
                None,
                CameraSource::Fov { .. } | CameraSource::Scale { .. } | CameraSource::Header,
            ) => Parity::Either,
            _ => Parity::AsCamera,
        }
    }

    /// The identification settings of a run with this camera `choice`.
    pub fn settings(&self, choice: &CameraChoice) -> Settings {
        let (source, camera_mag, scale_range) = choice;
        let mut s = Settings::DEFAULT;
        s.epoch = self.epoch;
        s.mag_limit = self.mag_limit.or(*camera_mag);
        s.double_stars = self.double_stars;
        s.double_star_px = self.double_star_px;
        s.table_cache = !self.no_cache;
        // As the command line always read it: a number, then single precision.
        s.detect.k_sigma = self.sigma as f32;
        s.detect.matched_filter = self.detect_filter == DetectFilter::Binomial;
        s.detect.centroid = self.centroid;
        s.method = self.method;
        s.identify.vote_stars = self.vote_stars;
        s.retry = !self.no_retry;
        s.wide_min_stars = self.wide_min_stars;
        s.identify.pair_tol_px = self.pair_tol_px;
        s.identify.scale_tol = self.scale_tol;
        s.refine.match_radius_px = self.match_radius_px;
        s.refine.max_false_prob = self.max_false_prob;
        s.refine.fit = self.fit;
        s.scale_range = *scale_range;
        s.walk_wide = self.fov_walk;
        s.parity = self.parity_for(source);
        s
    }

    /// `streaks`: the streak options, the TLE file read now (a bad file stops the run before
    /// any frame); None without streaks, and an error for a streak option given without them.
    pub fn streak_options(&self) -> Result<Option<StreakOptions>> {
        if !self.streaks {
            let stray = [
                (self.station.is_some(), "station"),
                (self.dut1.is_some(), "dut1"),
                (self.tle.is_some(), "tle"),
            ];
            if let Some((_, name)) = stray.iter().find(|s| s.0) {
                return Err(Error::Config(format!("{name} is an option of streaks")));
            }
            return Ok(None);
        }
        let station = match &self.station {
            Some(s) => Some(crate::sky::station::parse_station(s)?),
            None => None,
        };
        let tle = match &self.tle {
            Some(p) => Some(std::sync::Arc::new(crate::sky::tle::TleCatalog::load(p)?)),
            None => None,
        };
        Ok(Some(StreakOptions {
            settings: StreakSettings {
                k_sigma: self.streak_sigma as f32,
                ..StreakSettings::DEFAULT
            },
            station,
            dut1_s: self.dut1,
            astrometry: self.astrometry,
            tle,
            identify: TleSettings {
                cross_arcsec: self.tle_cross,
                along_s: self.tle_along,
            },
        }))
    }

    /// `dark` or `dark_median`'s fixed-pattern removal; a camera file fixes the frames' size,
    /// and so the dark's.
    pub fn darks(&self, source: &CameraSource) -> Result<Darks> {
        let expect = match source {
            CameraSource::Fixed(c) => Some((c.width, c.height)),
            _ => None,
        };
        Ok(match (&self.dark, self.dark_median) {
            (Some(path), _) => Darks::from_file(path, expect).map_err(|e| e.context("--dark"))?,
            (None, true) => Darks::directory_median(),
            (None, false) => Darks::None,
        })
    }

    /// The solvers of a run over `catalog` with this camera `choice` and the `streaks` options
    /// ([`RunConfig::streak_options`], read before): settings, hints, darks and the largest
    /// frame. The products (files written per frame) are the front end's.
    pub fn solvers(
        &self,
        catalog: Catalog,
        choice: CameraChoice,
        streaks: Option<StreakOptions>,
    ) -> Result<Solvers> {
        let darks = self.darks(&choice.0)?;
        let settings = self.settings(&choice);
        let mut solvers = Solvers::new(catalog, settings, choice.0);
        solvers.max_pixels = (self.max_megapixels * 1e6) as u64;
        if let Some(h) = &self.hint {
            solvers = solvers.with_hints(crate::sky::hint::parse_hint(h)?);
        }
        solvers.darks = darks;
        solvers.streaks = streaks;
        Ok(solvers)
    }

    /// The options whose values differ from `other`'s, less those that cannot change a
    /// record (the backend: GPU = CPU; the GPU batch size).
    pub fn differences(&self, other: &RunConfig) -> Vec<String> {
        let (Ok(toml::Value::Table(a)), Ok(toml::Value::Table(b))) =
            (toml::Value::try_from(self), toml::Value::try_from(other))
        else {
            return vec!["(the configuration could not be compared)".into()];
        };
        let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
        keys.sort();
        keys.dedup();
        keys.into_iter()
            .filter(|k| !matches!(k.as_str(), "backend" | "batch_size"))
            .filter(|k| a.get(*k) != b.get(*k))
            .map(|k| {
                let show =
                    |v: Option<&toml::Value>| v.map_or("(not set)".to_string(), |v| v.to_string());
                format!("{k}: {} then, {} now", show(b.get(k)), show(a.get(k)))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests;
