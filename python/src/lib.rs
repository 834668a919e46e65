//! gpustar's Python bindings: a thin layer over the gpustar crate's library. Options become
//! the library's `Settings` and `Solvers` (as the command line's options do), numpy arrays
//! become `Frame`s through `Frame::from_samples`, and every record is the library's `Record`,
//! handed to Python in a `RecordHandle` whose JSON line is `Record::to_json_line`, so that
//! `to_dict()` is the command line's record exactly (and whose solution's camera gives the
//! WCS `--wcs-dir` writes). The pure-Python part (python/gpustar/) wraps these.

mod arrays;
mod batch_run;
mod options;
mod records;
mod sequence;
mod solver;
mod tools;

use batch_run::{BatchRun, start_batch};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use records::RecordHandle;
use sequence::Sequence;
use solver::{ManyRun, Solver};
use tools::{calibrate, simulate};

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
pub(crate) fn py_err(e: gpustar::Error) -> PyErr {
    let m = e.to_string();
    match e {
        gpustar::Error::Input(_) => InputError::new_err(m),
        gpustar::Error::Catalog(_) => CatalogError::new_err(m),
        gpustar::Error::Config(_) => ConfigError::new_err(m),
        gpustar::Error::Output(_) => OutputError::new_err(m),
        gpustar::Error::Gpu(_) => GpuError::new_err(m),
        gpustar::Error::Io { .. } => IoError::new_err(m),
        _ => Error::new_err(m),
    }
}

pub(crate) fn config(m: impl Into<String>) -> PyErr {
    ConfigError::new_err(m.into())
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
