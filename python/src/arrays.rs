//! numpy arrays in and out: 2-D frames held read-only while solved, coordinate pairs.

use crate::{InputError, py_err};
use gpustar::Frame;
use gpustar::front::Decoded;
use gpustar::front::Samples;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use std::collections::BTreeMap;

/// A 2-D numpy array of uint8, uint16 or float32, borrowed read-only (numpy's flag keeps
/// other Rust code from writing it meanwhile).
pub(crate) enum Held<'py> {
    U8(PyReadonlyArray2<'py, u8>),
    U16(PyReadonlyArray2<'py, u16>),
    F32(PyReadonlyArray2<'py, f32>),
}

impl Held<'_> {
    /// The frame of the array: a C-contiguous uint16 array is borrowed where it lies (solved
    /// without a copy), other dtypes are converted, other strides (any, negative too)
    /// gathered row by row into pixels of the frame's own.
    pub(crate) fn frame(&self) -> gpustar::Result<(Frame<'_>, Vec<String>)> {
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
pub(crate) fn held<'py>(image: &Bound<'py, PyAny>) -> PyResult<Held<'py>> {
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
pub(crate) fn decoded_of<'a>(
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

/// Two coordinate arrays of one length: (RA, Dec) or (x, y).
pub(crate) type Coords<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

/// `InputError` unless two coordinate arrays are of one length.
pub(crate) fn same_length(a: usize, b: usize, what_a: &str, what_b: &str) -> PyResult<()> {
    if a == b {
        Ok(())
    } else {
        Err(InputError::new_err(format!(
            "{a} {what_a} and {b} {what_b}: give one of each per point"
        )))
    }
}
