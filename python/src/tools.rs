//! `simulate` and `calibrate`, as the commands of those names.

use crate::{InputError, config, py_err};
use gpustar::front::inputs;
use gpustar::{Camera, Catalog, Settings};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};
use std::path::PathBuf;

/// Synthetic frames and their truths (`gpustar simulate`'s model): (pixels as native-endian
/// u16 row-major bytes, truth as JSON) per frame.
#[pyfunction]
#[pyo3(signature = (n, size, fov_deg, seed, mag_limit=None, bits=16, false_stars=None, catalog=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn simulate(
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
    use gpustar::front::{SimSettings, render};
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
pub(crate) fn calibrate(
    py: Python<'_>,
    directory: PathBuf,
    camera: PathBuf,
    fov_tolerance: Option<f64>,
    recursive: bool,
    catalog: Option<PathBuf>,
    fit_k2: bool,
    fixed_centre: bool,
) -> PyResult<Py<PyDict>> {
    use gpustar::front::{FitOptions, calibrate as calibrate_dir, camera_file};
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
            calibrate_dir(
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
        camera_file(fit, &directory.display().to_string(), mag),
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
