//! gpustar's Python bindings: a thin layer over the gpustar crate's library. Options become
//! the library's `Settings` and `Solvers` (as the command line's options do), numpy arrays
//! become `Frame`s through `Frame::from_samples`, and every record is the library's `Record`,
//! handed to Python in a `RecordHandle` whose JSON line is `Record::to_json_line`, so that
//! `to_dict()` is the command line's record exactly (and whose solution's camera gives the
//! WCS `--wcs-dir` writes). The pure-Python part (python/gpustar/) wraps these.

use gpustar::batch::{self, RunOptions};
use gpustar::choice::Choice;
use gpustar::config::sidecar::{self, Sidecar};
use gpustar::config::{RunConfig, ValueOrRange, check_fov};
use gpustar::io::array::Samples;
use gpustar::io::dark::Darks;
use gpustar::io::inputs::{self, Shard};
use gpustar::io::output::{self, Format, RecordWriter};
use gpustar::pipeline::Counts;
use gpustar::pipeline::{Backend, BackendChoice, CameraSource, Decoded, Solvers};
use gpustar::products::Products;
use gpustar::sequence::{Detected, SequenceOptions, Sequencer};
use gpustar::solve::detect::Detection;
use gpustar::streaks::export::{Exports, NO_SITE};
use gpustar::{Camera, Catalog, Frame, Record, Settings};
use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyList, PyString};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

create_exception!(_gpustar, Error, PyException, "Every error gpustar raises.");
create_exception!(
    _gpustar,
    InputError,
    Error,
    "An input cannot be used: an array, an image file, a directory of inputs."
);
create_exception!(
    _gpustar,
    CatalogError,
    Error,
    "The star catalog or its distance table."
);
create_exception!(
    _gpustar,
    ConfigError,
    Error,
    "A camera model or an option out of its range."
);
create_exception!(
    _gpustar,
    OutputError,
    Error,
    "An output file gpustar refuses to write or resume."
);
create_exception!(
    _gpustar,
    GpuError,
    Error,
    "The GPU: no adapter, a kernel that does not build, a lost device."
);
create_exception!(
    _gpustar,
    IoError,
    Error,
    "Reading or writing a file failed."
);

/// The library's error as the Python exception of its kind, with the command line's message.
fn py_err(e: gpustar::Error) -> PyErr {
    let m = e.to_string();
    match e {
        gpustar::Error::Input(_) => InputError::new_err(m),
        gpustar::Error::Catalog(_) => CatalogError::new_err(m),
        gpustar::Error::Config(_) => ConfigError::new_err(m),
        gpustar::Error::Output(_) => OutputError::new_err(m),
        gpustar::Error::Gpu(_) => GpuError::new_err(m),
        _ => IoError::new_err(m),
    }
}

fn config(m: impl Into<String>) -> PyErr {
    ConfigError::new_err(m.into())
}

/// Everything a `Solver` or a `batch` run is built from, read from keyword options.
struct Built {
    solvers: Solvers,
    /// The run configuration the solvers were made from (kept beside a batch's output).
    config: RunConfig,
    backend: BackendChoice,
    threads: usize,
    batch_size: usize,
}

/// The options' names (with [`STREAK_OPTIONS`]), for the message that refuses any other.
const OPTIONS: &[&str] = &[
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
const STREAK_OPTIONS: &[&str] = &[
    "station",
    "astrometry",
    "dut1",
    "streak_sigma",
    "tle",
    "tle_cross",
    "tle_along",
];

/// Keyword options, each taken once; the command line's ranges, with its messages.
struct Opts<'py> {
    dict: Option<Bound<'py, PyDict>>,
}

impl<'py> Opts<'py> {
    fn new(dict: Option<Bound<'py, PyDict>>) -> PyResult<Opts<'py>> {
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

    fn get<T: FromPyObjectOwned<'py>>(&self, key: &str) -> PyResult<Option<T>> {
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

    fn count(&self, key: &str, lo: usize, hi: usize) -> PyResult<Option<usize>> {
        match self.get::<usize>(key)? {
            Some(v) if !(lo..=hi).contains(&v) => {
                Err(config(format!("{key}: {v} is outside {lo} to {hi}")))
            }
            v => Ok(v),
        }
    }

    /// One of a library enum's names ([`Choice`]), as the command line takes them.
    fn choice<T: Choice>(&self, key: &str) -> PyResult<Option<T>> {
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
fn camera_file(camera: &Bound<'_, PyAny>) -> PyResult<(Camera, Option<f64>, Option<PathBuf>)> {
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
fn run_config(
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

fn build(
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
    let mut solvers = Solvers::new(cat, c.settings(&choice), choice.0);
    if let Some(h) = &c.hint {
        solvers = solvers.with_hints(gpustar::sky::hint::parse_hint(h).map_err(py_err)?);
    }
    // Read before solving, as the command line does: a bad TLE file fails the constructor.
    solvers.streaks = c.streak_options().map_err(py_err)?;
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

/// A 2-D numpy array of uint8, uint16 or float32, borrowed read-only (numpy's flag keeps
/// other Rust code from writing it meanwhile).
enum Held<'py> {
    U8(PyReadonlyArray2<'py, u8>),
    U16(PyReadonlyArray2<'py, u16>),
    F32(PyReadonlyArray2<'py, f32>),
}

impl Held<'_> {
    /// The frame of the array: a C-contiguous uint16 array is borrowed where it lies (solved
    /// without a copy), other dtypes are converted, other strides (any, negative too)
    /// gathered row by row into pixels of the frame's own.
    fn frame(&self) -> gpustar::Result<(Frame<'_>, Vec<String>)> {
        fn take<'a, T: numpy::Element + Copy>(
            a: &'a PyReadonlyArray2<'_, T>,
            wrap: impl for<'b> Fn(&'b [T]) -> Samples<'b>,
        ) -> gpustar::Result<(Frame<'a>, Vec<String>)> {
            let (h, w) = (a.shape()[0], a.shape()[1]);
            let (w32, h32) = (u32::try_from(w), u32::try_from(h));
            let (Ok(w32), Ok(h32)) = (w32, h32) else {
                return Err(gpustar::Error::Input(format!(
                    "the image is {w}x{h} pixels: too large"
                )));
            };
            // ndarray's as_slice is Some only in row-major order (numpy's `as_slice` also
            // takes Fortran order, whose memory is the transpose).
            let view = a.as_array();
            match view.to_slice() {
                Some(s) => Frame::from_samples(w32, h32, wrap(s)),
                None => {
                    let v: Vec<T> = view.iter().copied().collect();
                    Frame::from_samples(w32, h32, wrap(&v)).map(|(f, w)| (f.into_owned(), w))
                }
            }
        }
        match self {
            Held::U8(a) => take(a, |s| Samples::U8(s)),
            Held::U16(a) => take(a, |s| Samples::U16(s)),
            Held::F32(a) => take(a, |s| Samples::F32(s)),
        }
    }
}

/// The array held for reading, or `InputError` saying why gpustar cannot take it.
fn held<'py>(image: &Bound<'py, PyAny>) -> PyResult<Held<'py>> {
    let refuse = |what: String| {
        InputError::new_err(format!(
            "{what}: gpustar takes a 2-D numpy array (height, width) of uint8, uint16 or \
             float32"
        ))
    };
    // The common case first, without looking at attributes.
    if let Ok(a) = image.cast::<PyArray2<u16>>() {
        return Ok(Held::U16(a.try_readonly()?));
    }
    if !image.hasattr("ndim")? || !image.hasattr("dtype")? {
        return Err(refuse(format!(
            "got a {}",
            image
                .get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_default()
        )));
    }
    let ndim: usize = image.getattr("ndim")?.extract()?;
    let dtype: String = image.getattr("dtype")?.str()?.to_string();
    if ndim != 2 {
        return Err(refuse(format!("the array has {ndim} dimensions")));
    }
    Ok(match dtype.as_str() {
        "uint8" => Held::U8(image.extract()?),
        "uint16" => Held::U16(image.extract()?),
        "float32" => Held::F32(image.extract()?),
        other => return Err(refuse(format!("the array's dtype is {other}"))),
    })
}

/// The frame of `held` under `name`. An array refused for its values raises; `strict` = false
/// makes it an error record instead (`solve_many`, where one bad frame must not lose the
/// others' records).
fn decoded_of<'a>(
    held: &'a Held<'_>,
    name: &str,
    epoch: Option<f64>,
    header: Option<BTreeMap<String, String>>,
    strict: bool,
) -> PyResult<Decoded<'a>> {
    let frame = held.frame();
    if strict && let Err(e) = frame {
        return Err(py_err(e));
    }
    Ok(Decoded::in_memory(
        name,
        frame,
        epoch,
        header.unwrap_or_default(),
    ))
}

/// A record handed to Python: its JSON line is made only when asked for (most callers of
/// `solve` read a few fields, or none), and a field read alone is taken from the record's
/// JSON value without writing and parsing the whole line.
#[pyclass(frozen, module = "gpustar._gpustar")]
struct RecordHandle {
    record: Record,
    value: std::sync::OnceLock<serde_json::Value>,
}

impl RecordHandle {
    fn new(record: Record) -> RecordHandle {
        RecordHandle {
            record,
            value: std::sync::OnceLock::new(),
        }
    }
}

/// A JSON value as the Python object `json.loads` makes of it.
fn value_to_py(py: Python<'_>, v: &serde_json::Value) -> PyResult<Py<PyAny>> {
    use serde_json::Value;
    Ok(match v {
        Value::Null => py.None(),
        Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any().unbind(),
        Value::Number(n) => match (n.as_i64(), n.as_u64()) {
            (Some(i), _) => i.into_pyobject(py)?.into_any().unbind(),
            (None, Some(u)) => u.into_pyobject(py)?.into_any().unbind(),
            _ => n
                .as_f64()
                .unwrap_or(f64::NAN)
                .into_pyobject(py)?
                .into_any()
                .unbind(),
        },
        Value::String(s) => PyString::new(py, s).into_any().unbind(),
        Value::Array(a) => {
            let l = PyList::empty(py);
            for x in a {
                l.append(value_to_py(py, x)?)?;
            }
            l.into_any().unbind()
        }
        Value::Object(m) => {
            let d = PyDict::new(py);
            for (k, x) in m {
                d.set_item(k, value_to_py(py, x)?)?;
            }
            d.into_any().unbind()
        }
    })
}

#[pymethods]
impl RecordHandle {
    /// "solved", "unsolved" or "error".
    #[getter]
    fn status(&self) -> &'static str {
        match self.record.status {
            gpustar::record::Status::Solved => "solved",
            gpustar::record::Status::Unsolved => "unsolved",
            gpustar::record::Status::Error => "error",
        }
    }

    /// The record's JSON line (`gpustar batch`'s, field for field).
    fn json(&self) -> String {
        self.record.to_json_line()
    }

    /// One field of the record as `json.loads` of its line gives it; None when the record
    /// has no such field.
    fn get(&self, py: Python<'_>, name: &str) -> PyResult<Py<PyAny>> {
        let v = self
            .value
            .get_or_init(|| serde_json::to_value(&self.record).expect("records serialise"));
        match v.get(name) {
            Some(x) => value_to_py(py, x),
            None => Ok(py.None()),
        }
    }

    /// The FITS WCS header of the solution, as `--wcs-dir` writes it: its cards (80
    /// characters each, `END` last, no padding); None for a record that is not solved.
    fn wcs_cards(&self) -> Option<Vec<String>> {
        let (camera, r) = self.solution()?;
        Some(gpustar::io::wcs::wcs_header(camera, &r))
    }

    /// RA, Dec (degrees, ICRS; RA in [0, 360)) of pixels (x, y), through the solution's camera
    /// model (distortion included); None for a record that is not solved.
    fn pixel_to_sky<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray1<'py, f64>,
        y: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Option<Coords<'py>>> {
        let Some((camera, r)) = self.solution() else {
            return Ok(None);
        };
        let (x, y) = (x.as_array(), y.as_array());
        same_length(x.len(), y.len(), "x", "y")?;
        let (ra, dec): (Vec<f64>, Vec<f64>) = x
            .iter()
            .zip(y.iter())
            .map(|(&x, &y)| {
                if !(x.is_finite() && y.is_finite()) {
                    return (f64::NAN, f64::NAN);
                }
                let v = r.transpose() * camera.pixel_to_vector(x, y);
                gpustar::catalog::vector_to_radec(&v)
            })
            .unzip();
        Ok(Some((
            PyArray1::from_vec(py, ra),
            PyArray1::from_vec(py, dec),
        )))
    }

    /// Pixels (x, y) of directions (RA, Dec in degrees, ICRS), through the solution's camera
    /// model; NaN for a direction behind the camera; None for a record that is not solved.
    fn sky_to_pixel<'py>(
        &self,
        py: Python<'py>,
        ra_deg: PyReadonlyArray1<'py, f64>,
        dec_deg: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Option<Coords<'py>>> {
        let Some((camera, r)) = self.solution() else {
            return Ok(None);
        };
        let (ra, dec) = (ra_deg.as_array(), dec_deg.as_array());
        same_length(ra.len(), dec.len(), "ra", "dec")?;
        let (x, y): (Vec<f64>, Vec<f64>) = ra
            .iter()
            .zip(dec.iter())
            .map(|(&ra, &dec)| {
                let v = r * gpustar::catalog::radec_to_vector(ra, dec);
                match camera.vector_to_pixel(&v) {
                    Some(p) if ra.is_finite() && dec.is_finite() => p,
                    _ => (f64::NAN, f64::NAN),
                }
            })
            .unzip();
        Ok(Some((PyArray1::from_vec(py, x), PyArray1::from_vec(py, y))))
    }
}

impl RecordHandle {
    /// The solution's camera and rotation (ICRS into the camera frame): those `--wcs-dir`
    /// writes the header of. None unless the record is solved.
    fn solution(&self) -> Option<(&Camera, nalgebra::Matrix3<f64>)> {
        let camera = self.record.camera.as_ref()?;
        let m = self.record.rotation_matrix?;
        Some((camera, nalgebra::Matrix3::from_fn(|i, j| m[i][j])))
    }
}

/// Two coordinate arrays of one length: (RA, Dec) or (x, y).
type Coords<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

/// `InputError` unless two coordinate arrays are of one length.
fn same_length(a: usize, b: usize, what_a: &str, what_b: &str) -> PyResult<()> {
    if a == b {
        Ok(())
    } else {
        Err(InputError::new_err(format!(
            "{a} {what_a} and {b} {what_b}: give one of each per point"
        )))
    }
}

/// Where a solver's kernels run.
enum Engine {
    Cpu,
    /// The GPU context (always `Backend::Gpu`) is used by one call at a time.
    Gpu(Mutex<Backend>),
}

/// A solver built once (catalog, distance tables, GPU context) and reused; shareable
/// between threads.
#[pyclass(frozen, module = "gpustar._gpustar")]
struct Solver {
    solvers: Arc<Solvers>,
    engine: Arc<Engine>,
    backend: String,
    threads: usize,
    batch_size: usize,
}

impl Solver {
    /// One frame's record, on the caller's thread (CPU) or as a batch of one (GPU).
    fn solve_one(&self, d: Decoded<'_>) -> Record {
        match self.engine.as_ref() {
            Engine::Cpu => self.solvers.solve_cpu(d),
            Engine::Gpu(b) => match &mut *b.lock().unwrap_or_else(|e| e.into_inner()) {
                Backend::Gpu(g) => g.solve(&self.solvers, vec![d]).remove(0),
                Backend::Cpu => self.solvers.solve_cpu(d),
            },
        }
    }
}

#[pymethods]
impl Solver {
    #[new]
    #[pyo3(signature = (camera=None, fov_deg=None, catalog=None, backend="auto", options=None))]
    fn new(
        py: Python<'_>,
        camera: Option<Bound<'_, PyAny>>,
        fov_deg: Option<Bound<'_, PyAny>>,
        catalog: Option<PathBuf>,
        backend: &str,
        options: Option<Bound<'_, PyDict>>,
    ) -> PyResult<Solver> {
        let b = build(camera.as_ref(), fov_deg.as_ref(), catalog, backend, options)?;
        let (engine, name) = py
            .detach(|| -> gpustar::Result<(Engine, String)> {
                let (backend, _note) = Backend::open(b.backend)?;
                let name = backend.name();
                Ok(match backend {
                    Backend::Cpu => (Engine::Cpu, name),
                    gpu => (Engine::Gpu(Mutex::new(gpu)), name),
                })
            })
            .map_err(py_err)?;
        Ok(Solver {
            solvers: Arc::new(b.solvers),
            engine: Arc::new(engine),
            backend: name,
            threads: b.threads,
            batch_size: b.batch_size,
        })
    }

    /// The records' `backend` field: "cpu" or the GPU adapter's name.
    #[getter]
    fn backend(&self) -> String {
        self.backend.clone()
    }

    /// Build the distance table for frames of this size now rather than on the first solve.
    fn prepare(&self, py: Python<'_>, width: u32, height: u32) -> PyResult<()> {
        let s = py.detach(|| self.solvers.get(width, height));
        match s.as_ref() {
            Ok(_) => Ok(()),
            Err(e) => Err(config(e.clone())),
        }
    }

    /// One frame: its record (a C-contiguous uint16 array is solved where it lies).
    #[pyo3(signature = (image, name, epoch=None, header=None))]
    fn solve(
        &self,
        py: Python<'_>,
        image: Bound<'_, PyAny>,
        name: &str,
        epoch: Option<f64>,
        header: Option<BTreeMap<String, String>>,
    ) -> PyResult<RecordHandle> {
        let held = held(&image)?;
        let d = decoded_of(&held, name, epoch, header, true)?;
        let record = py.detach(|| self.solve_one(d));
        Ok(RecordHandle::new(record))
    }

    /// Read and solve one image file as `gpustar solve FILE` does (its record's `file` is the
    /// path as given; a file that cannot be read gets an error record, not an exception).
    fn solve_file(&self, py: Python<'_>, path: PathBuf) -> PyResult<RecordHandle> {
        let name = path.display().to_string();
        let record = py.detach(|| self.solve_one(self.solvers.decode(&path, &name)));
        Ok(RecordHandle::new(record))
    }

    /// Start solving frames streamed in with `ManyRun.put` (worker threads on the CPU, GPU
    /// batches of `batch_size`), as `batch` streams files.
    #[pyo3(signature = (batch_size=None))]
    fn start_many(&self, batch_size: Option<usize>) -> PyResult<ManyRun> {
        let opts = RunOptions {
            threads: self.threads,
            batch_size: batch_size.unwrap_or(self.batch_size).clamp(1, 4096),
            flush_every: std::time::Duration::from_millis(250),
            sequence: None,
            tracklets: false,
            star_lists: None,
        };
        let (frames_tx, frames_rx) = crossbeam_channel::unbounded::<Decoded<'static>>();
        let (records_tx, records_rx) = crossbeam_channel::unbounded::<Record>();
        let stop = Arc::new(AtomicBool::new(false));
        let (solvers, engine, stop2) = (self.solvers.clone(), self.engine.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            let send = |r: &Record, _: &Counts| {
                let _ = records_tx.send(r.clone());
            };
            match engine.as_ref() {
                Engine::Cpu => batch::run_frames(
                    frames_rx.into_iter(),
                    &solvers,
                    &mut Backend::Cpu,
                    opts,
                    &stop2,
                    send,
                ),
                Engine::Gpu(b) => {
                    let mut b = b.lock().unwrap_or_else(|e| e.into_inner());
                    batch::run_frames(frames_rx.into_iter(), &solvers, &mut b, opts, &stop2, send)
                }
            }
        });
        // Frames in flight: enough that the workers never wait for Python (at least one
        // GPU batch, or two frames per CPU thread), as many as `batch` would have, and within
        // a memory budget.
        let least = match self.engine.as_ref() {
            Engine::Cpu => 2 * opts.threads.max(1),
            Engine::Gpu(_) => opts.batch_size,
        };
        Ok(ManyRun {
            frames: Some(frames_tx),
            records: records_rx,
            stop,
            thread: Some(thread),
            window: (least, opts.window().max(least)),
        })
    }

    /// The Rust path's time (ms) of each of `reps` solves of this image, the frame made
    /// beforehand and no Python in between: what scripts/bench_python.py sets the per-call
    /// cost of `solve` against (the same name and epoch as the `solve` it is set against).
    #[pyo3(signature = (image, reps, name="x", epoch=None))]
    fn _library_call_ms(
        &self,
        py: Python<'_>,
        image: Bound<'_, PyAny>,
        reps: usize,
        name: &str,
        epoch: Option<f64>,
    ) -> PyResult<Vec<f64>> {
        let held = held(&image)?;
        let (frame, _) = held.frame().map_err(py_err)?;
        let frame = frame.into_owned();
        Ok(py.detach(|| {
            (0..reps)
                .map(|_| {
                    let d = Decoded::in_memory(
                        name,
                        Ok((frame.clone(), Vec::new())),
                        epoch,
                        BTreeMap::new(),
                    );
                    let t0 = std::time::Instant::now();
                    let r = self.solve_one(d);
                    let ms = t0.elapsed().as_secs_f64() * 1e3;
                    drop(r);
                    ms
                })
                .collect()
        }))
    }

    /// Stars the caller detected: x, y (pixels) and fluxes (or brightest first when None).
    #[pyo3(signature = (x, y, width, height, fluxes=None, name="centroids", epoch=None))]
    #[allow(clippy::too_many_arguments)]
    fn solve_centroids(
        &self,
        py: Python<'_>,
        x: PyReadonlyArray1<'_, f64>,
        y: PyReadonlyArray1<'_, f64>,
        width: u32,
        height: u32,
        fluxes: Option<PyReadonlyArray1<'_, f64>>,
        name: &str,
        epoch: Option<f64>,
    ) -> PyResult<RecordHandle> {
        let (x, y) = (x.as_array(), y.as_array());
        let n = x.len();
        let f: Vec<f64> = match &fluxes {
            Some(f) => f.as_array().to_vec(),
            None => (0..n).map(|i| (n - i) as f64).collect(),
        };
        if y.len() != n || f.len() != n {
            return Err(InputError::new_err(format!(
                "{n} x, {} y and {} fluxes: give one of each per star",
                y.len(),
                f.len()
            )));
        }
        let mut stars = Vec::with_capacity(n);
        for i in 0..n {
            let (sx, sy, sf) = (x[i], y[i], f[i]);
            if !(sx.is_finite() && sy.is_finite() && sf.is_finite()) {
                return Err(InputError::new_err(format!(
                    "star {i} has a NaN or infinite x, y or flux"
                )));
            }
            stars.push(Detection {
                x: sx,
                y: sy,
                flux: sf,
                area: 1,
                peak: 0,
                saturated: false,
                sigma_px: None,
            });
        }
        let r = py.detach(|| {
            self.solvers
                .solve_detections(name, (width, height), stars, epoch)
        });
        Ok(RecordHandle::new(r))
    }
}

/// Frames of sequences fed one by one, in order (as `--sequence` takes a directory's).
#[pyclass(module = "gpustar._gpustar")]
struct Sequence {
    seq: Mutex<Sequencer<'static>>,
    solvers: Arc<Solvers>,
    opts: SequenceOptions,
}

#[pymethods]
impl Sequence {
    #[new]
    #[pyo3(signature = (solver, frame_interval_s=None))]
    fn new(solver: &Solver, frame_interval_s: Option<f64>) -> PyResult<Sequence> {
        if frame_interval_s.is_some_and(|s| !(s.is_finite() && s > 0.0)) {
            return Err(config(
                "frame_interval_s must be a positive number of seconds",
            ));
        }
        let opts = SequenceOptions {
            frame_interval_s,
            ..SequenceOptions::default()
        };
        Ok(Sequence {
            seq: Mutex::new(Sequencer::shared(solver.solvers.clone(), opts)),
            solvers: solver.solvers.clone(),
            opts,
        })
    }

    /// The next frame's record; `name`'s directory part names its sequence.
    #[pyo3(signature = (image, name, header=None))]
    fn add(
        &self,
        py: Python<'_>,
        image: Bound<'_, PyAny>,
        name: &str,
        header: Option<BTreeMap<String, String>>,
    ) -> PyResult<RecordHandle> {
        let held = held(&image)?;
        let d = decoded_of(&held, name, None, header, true)?;
        // The sequence keeps frames between calls: their pixels are its own.
        let d = Decoded {
            frame: d.frame.map(Frame::into_owned),
            ..d
        };
        let r = py.detach(|| {
            let detected: Detected = self.solvers.detect_cpu(d, self.opts.detect_stars);
            let mut s = self.seq.lock().unwrap_or_else(|e| e.into_inner());
            s.next(detected)
        });
        Ok(RecordHandle::new(r))
    }
}

/// A `batch` run on a thread of its own, its records handed over in input order.
#[pyclass(module = "gpustar._gpustar")]
struct BatchRun {
    records: crossbeam_channel::Receiver<Record>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<gpustar::Result<batch::RunSummary>>>,
    total: usize,
}

#[pymethods]
impl BatchRun {
    /// Inputs this run solves (after shard and resume).
    #[getter]
    fn total(&self) -> usize {
        self.total
    }

    /// The next record, or None when the run is over (then its error, if any, is raised).
    fn next_record(&mut self, py: Python<'_>) -> PyResult<Option<RecordHandle>> {
        let rx = self.records.clone();
        match py.detach(move || rx.recv()) {
            Ok(record) => Ok(Some(RecordHandle::new(record))),
            Err(_) => {
                if let Some(t) = self.thread.take() {
                    let summary = py
                        .detach(|| t.join())
                        .map_err(|_| Error::new_err("the batch run's thread panicked"))?
                        .map_err(py_err)?;
                    if let Some(e) = summary.write_error {
                        return Err(OutputError::new_err(e));
                    }
                }
                Ok(None)
            }
        }
    }

    /// Start no new input; the run ends after those in flight.
    fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
    }
}

impl Drop for BatchRun {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            // Drain so that the writer is never blocked on a full channel.
            while self.records.recv().is_ok() {}
            let _ = t.join();
        }
    }
}

/// Frames streamed to a solver's workers (`Solver.solve_many`): `put` hands one over,
/// `next_record` takes the records in the order put.
#[pyclass(module = "gpustar._gpustar")]
struct ManyRun {
    frames: Option<crossbeam_channel::Sender<Decoded<'static>>>,
    records: crossbeam_channel::Receiver<Record>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<gpustar::Result<batch::RunSummary>>>,
    /// The least and the most frames in flight.
    window: (usize, usize),
}

/// The pixels `solve_many` holds in flight at most (beyond the least window): 256 MiB.
const MANY_BUDGET_BYTES: usize = 256 << 20;

#[pymethods]
impl ManyRun {
    /// Frames of `width` × `height` to put ahead of the records taken, at most.
    fn window_for(&self, width: usize, height: usize) -> usize {
        let (least, most) = self.window;
        (MANY_BUDGET_BYTES / (2 * width * height).max(1)).clamp(least, most)
    }

    /// Hand over the next frame (its pixels copied: the workers solve it while Python goes
    /// on). An array refused for its values becomes an error record; what is not an array
    /// raises `InputError`.
    #[pyo3(signature = (image, name, epoch=None))]
    fn put(
        &mut self,
        py: Python<'_>,
        image: Bound<'_, PyAny>,
        name: &str,
        epoch: Option<f64>,
    ) -> PyResult<()> {
        let held = held(&image)?;
        let d = decoded_of(&held, name, epoch, None, false)?;
        let d = Decoded {
            frame: d.frame.map(Frame::into_owned),
            ..d
        };
        match &self.frames {
            Some(tx) if tx.send(d).is_ok() => Ok(()),
            // The run has ended: its error, if it failed.
            _ => {
                self.finish(py)?;
                Err(Error::new_err("the run is closed"))
            }
        }
    }

    /// No more frames: the run ends when those put are solved.
    fn close(&mut self) {
        self.frames = None;
    }

    /// The next record in the order put; with `wait` false, None when it is not done yet.
    /// None when the run is over (then its error, if any, is raised).
    fn next_record(&mut self, py: Python<'_>, wait: bool) -> PyResult<Option<RecordHandle>> {
        let rx = self.records.clone();
        let got = if wait {
            py.detach(move || rx.recv().ok())
        } else {
            match rx.try_recv() {
                Ok(r) => Some(r),
                Err(crossbeam_channel::TryRecvError::Empty) => return Ok(None),
                Err(crossbeam_channel::TryRecvError::Disconnected) => None,
            }
        };
        if let Some(record) = got {
            return Ok(Some(RecordHandle::new(record)));
        }
        self.finish(py)?;
        Ok(None)
    }
}

impl ManyRun {
    /// Wait for the run's thread to end; its error, if it failed.
    fn finish(&mut self, py: Python<'_>) -> PyResult<()> {
        if let Some(t) = self.thread.take() {
            py.detach(|| t.join())
                .map_err(|_| Error::new_err("the solving thread panicked"))?
                .map_err(py_err)?;
        }
        Ok(())
    }
}

impl Drop for ManyRun {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        self.frames = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Start `gpustar batch DIRECTORY` with these options.
#[pyfunction]
#[pyo3(signature = (directory, camera=None, fov_deg=None, catalog=None, backend="auto",
    output=None, resume=false, retry_errors=false, shard=None, recursive=false, sequence=false,
    frame_interval_s=None, options=None, format="jsonl", dark=None, dark_median=false,
    wcs_dir=None, annotate_dir=None, tdm=None, iod=None, iod_station=NO_SITE, overwrite=false))]
#[allow(clippy::too_many_arguments)]
fn start_batch(
    py: Python<'_>,
    directory: PathBuf,
    camera: Option<Bound<'_, PyAny>>,
    fov_deg: Option<Bound<'_, PyAny>>,
    catalog: Option<PathBuf>,
    backend: &str,
    output: Option<PathBuf>,
    resume: bool,
    retry_errors: bool,
    shard: Option<String>,
    recursive: bool,
    sequence: bool,
    frame_interval_s: Option<f64>,
    options: Option<Bound<'_, PyDict>>,
    format: &str,
    dark: Option<PathBuf>,
    dark_median: bool,
    wcs_dir: Option<PathBuf>,
    annotate_dir: Option<PathBuf>,
    tdm: Option<PathBuf>,
    iod: Option<PathBuf>,
    iod_station: u16,
    overwrite: bool,
) -> PyResult<BatchRun> {
    let format = Format::parse_name(format).map_err(|e| config(format!("format: {e}")))?;
    if format == Format::Csv && output.is_none() {
        return Err(config(
            "format is the output file's: give output=FILE (the records come as results)",
        ));
    }
    if dark.is_some() && dark_median {
        return Err(config("dark and dark_median do not go together: give one"));
    }
    if iod_station > NO_SITE {
        return Err(config(format!(
            "iod_station: {iod_station} is outside 0 to {NO_SITE}"
        )));
    }
    if (resume || retry_errors) && output.is_none() {
        return Err(config(
            "resume needs output=FILE: the records of an earlier run",
        ));
    }
    if retry_errors && !resume {
        return Err(config("retry_errors goes with resume=True"));
    }
    let catalog_path = catalog.clone();
    let mut b = build(camera.as_ref(), fov_deg.as_ref(), catalog, backend, options)?;
    // The batch's own options that shape the records, as the command line's configuration has
    // them.
    b.config.sequence = sequence;
    b.config.frame_interval = frame_interval_s.filter(|_| sequence);
    b.config.dark = dark.clone();
    b.config.dark_median = dark_median;
    if b.solvers.streaks.is_none() {
        for (k, given) in [("tdm", tdm.is_some()), ("iod", iod.is_some())] {
            if given {
                return Err(config(format!("{k} is an option of streaks=True")));
            }
        }
    }
    // As `--dark`, `--dark-median`, `--wcs-dir`, `--annotate-dir`, `--tdm`, `--iod`: the
    // library's own.
    b.solvers.darks = match (&dark, dark_median) {
        (Some(p), _) => {
            // A camera file fixes the frames' size, and so the dark's.
            let expect = match &b.solvers.camera {
                CameraSource::Fixed(c) => Some((c.width, c.height)),
                _ => None,
            };
            Darks::from_file(p, expect).map_err(py_err)?
        }
        (None, true) => Darks::directory_median(),
        (None, false) => Darks::None,
    };
    let mut exports = Exports::new(tdm, iod, iod_station);
    let mut products = Products {
        wcs_dir,
        annotate_dir,
        overwrite,
        ..Products::default()
    };
    if sequence && b.solvers.streaks.is_some() {
        return Err(config(
            "sequence and streaks do not go together yet: run the sequences and the streak \
             frames separately",
        ));
    }
    let shard: Option<Shard> = match shard {
        Some(s) => Some(s.parse().map_err(config)?),
        None => None,
    };
    let mut list = inputs::list(&directory, recursive).map_err(py_err)?;
    if let Some(shard) = shard {
        // A sequence goes to one shard whole, as on the command line.
        list.retain(|i| {
            shard.takes(if sequence {
                gpustar::sequence::sequence_of(&i.name)
            } else {
                &i.name
            })
        });
    }
    // Every output checked before any work, and before `output` is emptied (as the command
    // line does).
    let read: Vec<(&std::path::Path, &'static str)> =
        [(&catalog_path, "the catalog"), (&dark, "the dark frame")]
            .into_iter()
            .filter_map(|(p, w)| p.as_deref().map(|p| (p, w)))
            .collect();
    gpustar::batch::claims::check_outputs(
        &gpustar::batch::claims::RunFiles {
            dirs: vec![(&directory, recursive)],
            inputs: &list,
            read,
            records: output.as_deref(),
            stdout: false,
            resume,
        },
        &exports,
        &mut products,
    )
    .map_err(py_err)?;
    b.solvers.products = products;
    let mut retried_order: Option<(PathBuf, Vec<String>)> = None;
    // As the command line: the configuration kept beside the records, and a resumed run's
    // checked against it before the records are touched.
    let side = Sidecar::new(&b.config, &b.solvers.catalog);
    if let Some(p) = &output {
        sidecar::check(p).map_err(py_err)?;
        if resume {
            sidecar::check_resume(p, &side).map_err(py_err)?;
        }
    }
    let (out, header): (Box<dyn std::io::Write + Send>, bool) = match &output {
        Some(p) => {
            let opened = output::open_output(p, format, resume, retry_errors).map_err(py_err)?;
            sidecar::write(p, &side).map_err(py_err)?;
            // Redone error records are put back in their places when the run ends.
            if opened.previous.retried > 0 {
                retried_order = Some((p.clone(), list.iter().map(|i| i.name.clone()).collect()));
            }
            list = batch::resumed_inputs(list, &opened.previous.done, sequence);
            // The exports are written whole at the end, with the streaks already recorded.
            if resume && exports.wanted() {
                for r in &opened.previous.streaks {
                    exports.add(r);
                }
            }
            (Box::new(opened.file), !opened.previous.has_header)
        }
        None => (Box::new(std::io::sink()), true),
    };
    let total = list.iter().filter(|i| !i.replay).count();
    let (mut backend, _) = py.detach(|| Backend::open(b.backend)).map_err(py_err)?;
    let opts = RunOptions {
        threads: b.threads,
        batch_size: b.batch_size,
        flush_every: std::time::Duration::from_millis(250),
        sequence: sequence.then(|| SequenceOptions {
            frame_interval_s,
            ..SequenceOptions::default()
        }),
        // As the command line: with streaks, a directory's frames are linked into tracklets.
        tracklets: b.solvers.streaks.is_some(),
        star_lists: None,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = crossbeam_channel::bounded::<Record>(4 * b.batch_size.max(b.threads));
    let solvers = b.solvers;
    let stop2 = stop.clone();
    let thread = std::thread::spawn(move || {
        let mut writer = RecordWriter::new(out, format, header);
        let summary = batch::run(
            list,
            &solvers,
            &mut backend,
            &mut writer,
            opts,
            &stop2,
            |r, _| {
                exports.add(r);
                // A closed receiver (the iterator dropped) has set the stop flag.
                let _ = tx.send(r.clone());
            },
        )?;
        if let (Some((path, order)), None, false) =
            (&retried_order, &summary.write_error, summary.interrupted)
        {
            writer.flush()?;
            output::restore_input_order(path, format, order)?;
        }
        if exports.wanted() && summary.write_error.is_none() {
            exports.finish(&gpustar::sky::now_utc_iso())?;
        }
        Ok(summary)
    });
    Ok(BatchRun {
        records: rx,
        stop,
        thread: Some(thread),
        total,
    })
}

/// Synthetic frames and their truths (`gpustar simulate`'s model): (pixels as native-endian
/// u16 row-major bytes, truth as JSON) per frame.
#[pyfunction]
#[pyo3(signature = (n, size, fov_deg, seed, mag_limit=None, bits=16, false_stars=None, catalog=None))]
#[allow(clippy::too_many_arguments)]
fn simulate(
    py: Python<'_>,
    n: usize,
    size: (u32, u32),
    fov_deg: f64,
    seed: u64,
    mag_limit: Option<f64>,
    bits: u8,
    false_stars: Option<usize>,
    catalog: Option<PathBuf>,
) -> PyResult<Vec<(Py<PyBytes>, String)>> {
    use gpustar::simulate::{SimSettings, render};
    if bits != 8 && bits != 16 {
        return Err(config(format!("bits: {bits}; 8 or 16")));
    }
    if !(fov_deg > 0.0 && fov_deg < 170.0) {
        return Err(config(format!(
            "field of view must be between 0 and 170 degrees, got {fov_deg}"
        )));
    }
    if size.0 < 16 || size.1 < 16 || size.0 > 32768 || size.1 > 32768 {
        return Err(config(format!(
            "size {}x{}: 16 to 32768 a side",
            size.0, size.1
        )));
    }
    let cat = Catalog::load(catalog.as_deref()).map_err(py_err)?;
    let mut s = SimSettings {
        width: size.0,
        height: size.1,
        fov_x_deg: fov_deg,
        frames: n,
        seed,
        bits,
        ..SimSettings::default()
    };
    if let Some(m) = mag_limit {
        s.mag_limit = m;
    }
    if let Some(f) = false_stars {
        s.false_stars = f;
    }
    let frames = py
        .detach(|| {
            (0..n)
                .map(|i| {
                    let (pixels, truth) = render(&cat, &s, i)?;
                    let t = serde_json::to_string(&truth)
                        .map_err(|e| gpustar::Error::Output(format!("truth: {e}")))?;
                    let bytes: Vec<u8> = pixels.iter().flat_map(|p| p.to_ne_bytes()).collect();
                    Ok((bytes, t))
                })
                .collect::<gpustar::Result<Vec<_>>>()
        })
        .map_err(py_err)?;
    Ok(frames
        .into_iter()
        .map(|(b, t)| (PyBytes::new(py, &b).unbind(), t))
        .collect())
}

/// `gpustar calibrate`: fit the camera to the solvable frames of a directory. Returns the
/// camera file's text, the fitted parameters with their 1σ, and the residuals.
#[pyfunction]
#[pyo3(signature = (directory, camera, fov_tolerance=None, recursive=false, catalog=None, fit_k2=true, fixed_centre=false))]
#[allow(clippy::too_many_arguments)]
fn calibrate(
    py: Python<'_>,
    directory: PathBuf,
    camera: PathBuf,
    fov_tolerance: Option<f64>,
    recursive: bool,
    catalog: Option<PathBuf>,
    fit_k2: bool,
    fixed_centre: bool,
) -> PyResult<Py<PyDict>> {
    use gpustar::calibrate::{self as cal, FitOptions};
    let inputs: Vec<(PathBuf, String)> = inputs::list(&directory, recursive)
        .map_err(py_err)?
        .into_iter()
        .map(|i| (i.path, i.name))
        .collect();
    if inputs.is_empty() {
        return Err(InputError::new_err(format!(
            "{}: no image files to calibrate with",
            directory.display()
        )));
    }
    let (start, mag) = Camera::from_toml_file(&camera).map_err(py_err)?;
    let cat = Catalog::load(catalog.as_deref()).map_err(py_err)?;
    let settings = Settings {
        mag_limit: mag,
        ..Settings::default()
    };
    let opts = FitOptions {
        fit_k2,
        fit_principal_point: !fixed_centre,
        ..FitOptions::default()
    };
    let found = py
        .detach(|| {
            cal::calibrate(
                &start,
                &cat,
                settings,
                &inputs,
                fov_tolerance,
                opts,
                &mut |_| {},
            )
        })
        .map_err(py_err)?;
    let fit = &found.fit;
    let d = PyDict::new(py);
    d.set_item(
        "camera_file",
        cal::camera_file(fit, &directory.display().to_string(), mag),
    )?;
    let k = &fit.camera;
    let values = PyDict::new(py);
    for (name, v) in [
        ("fx", k.fx),
        ("fy", k.fy),
        ("cx", k.cx),
        ("cy", k.cy),
        ("k1", k.k1),
        ("k2", k.k2),
    ] {
        values.set_item(name, v)?;
    }
    d.set_item("camera", values)?;
    let sig = PyDict::new(py);
    for (n, s) in fit.fitted.iter().zip(&fit.sigmas) {
        sig.set_item(*n, *s)?;
    }
    d.set_item("sigmas", sig)?;
    d.set_item("rms_before_px", found.first.rms_before_px)?;
    d.set_item("rms_after_px", fit.rms_after_px)?;
    d.set_item("stars_used", fit.stars_used)?;
    d.set_item("stars_rejected", fit.stars_rejected)?;
    d.set_item("frames", fit.rotations.len())?;
    let records = PyList::empty(py);
    for r in &found.after {
        records.append(r.to_json_line())?;
    }
    d.set_item("records", records)?;
    Ok(d.unbind())
}

#[pymodule]
fn _gpustar(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("Error", py.get_type::<Error>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("CatalogError", py.get_type::<CatalogError>())?;
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add("OutputError", py.get_type::<OutputError>())?;
    m.add("GpuError", py.get_type::<GpuError>())?;
    m.add("IoError", py.get_type::<IoError>())?;
    m.add_class::<Solver>()?;
    m.add_class::<Sequence>()?;
    m.add_class::<BatchRun>()?;
    m.add_class::<ManyRun>()?;
    m.add_class::<RecordHandle>()?;
    m.add_function(wrap_pyfunction!(start_batch, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // Every field a record can have, so that a misspelt attribute raises instead of reading
    // as an absent field.
    m.add("RECORD_FIELDS", gpustar::Record::field_names().to_vec())?;
    Ok(())
}
