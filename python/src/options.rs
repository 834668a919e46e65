//! Keyword options and the constructor's arguments, mapped onto the library's one run
//! configuration (`gpustar::config`), and what a solver or a batch run is built from.

use crate::{config, py_err};
use gpustar::front::Choice;
use gpustar::front::{BackendChoice, Solvers};
use gpustar::front::{RunConfig, ValueOrRange, check_fov};
use gpustar::{Camera, Catalog};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Everything a `Solver` or a `batch` run is built from, read from keyword options.
pub(crate) struct Built {
    pub(crate) solvers: Solvers,
    /// The run configuration the solvers were made from (kept beside a batch's output).
    pub(crate) config: RunConfig,
    pub(crate) backend: BackendChoice,
    pub(crate) threads: usize,
    pub(crate) batch_size: usize,
}

/// The options' names (with [`STREAK_OPTIONS`]), for the message that refuses any other.
pub(crate) const OPTIONS: &[&str] = &[
    "fov_tolerance",
    "pixel_aspect",
    "fov_walk",
    "fit",
    "mag_limit",
    "epoch",
    "centroid",
    "method",
    "detect_filter",
    "sigma",
    "vote_stars",
    "pair_tol_px",
    "scale_tol",
    "match_radius_px",
    "max_false_prob",
    "retry",
    "wide_min_stars",
    "double_stars",
    "double_star_px",
    "cache",
    "hint",
    "parity",
    "streaks",
    "threads",
    "batch_size",
];

/// The options that only `streaks=True` takes.
pub(crate) const STREAK_OPTIONS: &[&str] = &[
    "station",
    "astrometry",
    "dut1",
    "streak_sigma",
    "tle",
    "tle_cross",
    "tle_along",
];

/// Keyword options, each taken once; the command line's ranges, with its messages.
pub(crate) struct Opts<'py> {
    pub(crate) dict: Option<Bound<'py, PyDict>>,
}

impl<'py> Opts<'py> {
    pub(crate) fn new(dict: Option<Bound<'py, PyDict>>) -> PyResult<Opts<'py>> {
        if let Some(d) = &dict {
            for k in d.keys() {
                let k: String = k.extract()?;
                if !OPTIONS.contains(&k.as_str()) && !STREAK_OPTIONS.contains(&k.as_str()) {
                    return Err(config(format!(
                        "unknown option {k:?}; the options are {}, {}",
                        OPTIONS.join(", "),
                        STREAK_OPTIONS.join(", ")
                    )));
                }
            }
        }
        Ok(Opts { dict })
    }

    pub(crate) fn get<T: FromPyObjectOwned<'py>>(&self, key: &str) -> PyResult<Option<T>> {
        let Some(d) = &self.dict else { return Ok(None) };
        match d.get_item(key)? {
            None => Ok(None),
            Some(v) if v.is_none() => Ok(None),
            Some(v) => v.extract::<T>().map(Some).map_err(|_| {
                PyTypeError::new_err(format!(
                    "option {key}: {} is not a {}",
                    v.repr().map(|r| r.to_string()).unwrap_or_default(),
                    std::any::type_name::<T>()
                ))
            }),
        }
    }

    pub(crate) fn count(&self, key: &str, lo: usize, hi: usize) -> PyResult<Option<usize>> {
        match self.get::<usize>(key)? {
            Some(v) if !(lo..=hi).contains(&v) => {
                Err(config(format!("{key}: {v} is outside {lo} to {hi}")))
            }
            v => Ok(v),
        }
    }

    /// One of a library enum's names ([`Choice`]), as the command line takes them.
    pub(crate) fn choice<T: Choice>(&self, key: &str) -> PyResult<Option<T>> {
        match self.get::<String>(key)? {
            None => Ok(None),
            Some(s) => T::parse_name(&s)
                .map(Some)
                .map_err(|e| config(format!("{key}: {e}"))),
        }
    }
}

/// A camera file's camera and magnitude limit, from `camera`: a path (also returned), or the
/// file's TOML text.
pub(crate) fn camera_file(
    camera: &Bound<'_, PyAny>,
) -> PyResult<(Camera, Option<f64>, Option<PathBuf>)> {
    let (text, path): (String, _) = match camera.extract::<PathBuf>() {
        Ok(p) if !camera.extract::<String>().is_ok_and(|s| s.contains('=')) => {
            let text = std::fs::read_to_string(&p).map_err(|e| {
                py_err(gpustar::Error::Io {
                    context: format!("cannot read {}", p.display()),
                    error: e,
                })
            })?;
            (text, Some(p))
        }
        _ => (camera.extract()?, None),
    };
    let (cam, mag) = Camera::from_toml(&text).map_err(py_err)?;
    Ok((cam, mag, path))
}

/// The run configuration of the constructor's arguments: `camera` (a camera file's path or
/// its TOML text) or `fov_deg` (a number, or a (low, high) range to search), and the keyword
/// options, which keep the command line's names (`retry` and `cache` for `--no-retry` and
/// `--no-cache`). The library checks the ranges and maps it onto the run's settings.
pub(crate) fn run_config(
    fov_deg: Option<&Bound<'_, PyAny>>,
    catalog: Option<PathBuf>,
    backend: &str,
    o: &Opts,
) -> PyResult<RunConfig> {
    let mut c = RunConfig {
        catalog,
        backend: BackendChoice::parse_name(backend).map_err(|e| config(format!("backend: {e}")))?,
        ..RunConfig::default()
    };
    if let Some(f) = fov_deg {
        c.fov_deg = Some(match f.extract::<(f64, f64)>() {
            Ok((lo, hi)) => ValueOrRange::Range(
                check_fov(lo).map_err(config)?,
                check_fov(hi).map_err(config)?,
            ),
            Err(_) => ValueOrRange::Exact(f.extract()?),
        });
    }
    macro_rules! set {
        ($($field:ident),+ $(,)?) => {$(
            if let Some(v) = o.get(stringify!($field))? {
                c.$field = v;
            }
        )+};
    }
    macro_rules! set_some {
        ($($field:ident),+ $(,)?) => {$(
            c.$field = o.get(stringify!($field))?.or(c.$field.take());
        )+};
    }
    macro_rules! choose {
        ($($field:ident),+ $(,)?) => {$(
            if let Some(v) = o.choice(stringify!($field))? {
                c.$field = v;
            }
        )+};
    }
    set!(
        fov_walk,
        epoch,
        double_star_px,
        sigma,
        vote_stars,
        wide_min_stars,
        pair_tol_px
    );
    set!(
        scale_tol,
        match_radius_px,
        max_false_prob,
        batch_size,
        streaks
    );
    set!(streak_sigma, tle_cross, tle_along);
    set_some!(
        fov_tolerance,
        pixel_aspect,
        mag_limit,
        hint,
        station,
        dut1,
        tle
    );
    choose!(
        fit,
        double_stars,
        centroid,
        method,
        detect_filter,
        astrometry
    );
    c.parity = o.choice("parity")?;
    c.no_retry = !o.get::<bool>("retry")?.unwrap_or(true);
    c.no_cache = !o.get::<bool>("cache")?.unwrap_or(true);
    c.validate().map_err(py_err)?;
    Ok(c)
}

pub(crate) fn build(
    camera: Option<&Bound<'_, PyAny>>,
    fov_deg: Option<&Bound<'_, PyAny>>,
    catalog: Option<PathBuf>,
    backend: &str,
    options: Option<Bound<'_, PyDict>>,
) -> PyResult<Built> {
    let o = Opts::new(options)?;
    let mut c = run_config(fov_deg, catalog, backend, &o)?;
    if c.pixel_aspect.is_some() && fov_deg.is_none() {
        return Err(config(
            "pixel_aspect goes with fov_deg (a camera file gives fx_px and fy_px)",
        ));
    }
    let fixed = match camera {
        Some(cam) => {
            let (camera, mag, path) = camera_file(cam)?;
            c.camera = path;
            Some((camera, mag))
        }
        None if fov_deg.is_none() => {
            return Err(config("give the camera: camera=FILE or fov_deg=DEG"));
        }
        None => None,
    };
    if !c.streaks {
        for &k in STREAK_OPTIONS {
            if o.get::<Bound<'_, PyAny>>(k)?.is_some() {
                return Err(config(format!("{k} is an option of streaks=True")));
            }
        }
    }
    let choice = c.camera_source(fixed).map_err(py_err)?;
    let cat = Catalog::load(c.catalog.as_deref()).map_err(py_err)?;
    // The TLE file is read now, as the command line does: a bad one fails the constructor.
    let streaks = c.streak_options().map_err(py_err)?;
    let solvers = c.solvers(cat, choice, streaks).map_err(py_err)?;
    let threads = o
        .count("threads", 1, 4096)?
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    Ok(Built {
        solvers,
        backend: c.backend,
        threads,
        batch_size: c.batch_size,
        config: c,
    })
}
