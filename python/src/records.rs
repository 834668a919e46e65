//! Records handed to Python: the command line's record, its JSON made only when asked for.

use crate::arrays::{Coords, same_length};
use gpustar::{Camera, Record};
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyList, PyString};

/// A record handed to Python: its JSON line is made only when asked for (most callers of
/// `solve` read a few fields, or none), and a field read alone is taken from the record's
/// JSON value without writing and parsing the whole line.
#[pyclass(frozen, module = "gpustar._gpustar")]
pub(crate) struct RecordHandle {
    pub(crate) record: Record,
    pub(crate) value: std::sync::OnceLock<serde_json::Value>,
}

impl RecordHandle {
    pub(crate) fn new(record: Record) -> RecordHandle {
        RecordHandle {
            record,
            value: std::sync::OnceLock::new(),
        }
    }
}

/// A JSON value as the Python object `json.loads` makes of it.
pub(crate) fn value_to_py(py: Python<'_>, v: &serde_json::Value) -> PyResult<Py<PyAny>> {
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
            gpustar::Status::Solved => "solved",
            gpustar::Status::Unsolved => "unsolved",
            gpustar::Status::Error => "error",
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
        Some(gpustar::front::wcs_header(camera, &r))
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
                gpustar::front::vector_to_radec(&v)
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
                let v = r * gpustar::front::radec_to_vector(ra, dec);
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
    pub(crate) fn solution(&self) -> Option<(&Camera, nalgebra::Matrix3<f64>)> {
        let camera = self.record.camera.as_ref()?;
        let m = self.record.rotation_matrix?;
        Some((camera, nalgebra::Matrix3::from_fn(|i, j| m[i][j])))
    }
}
