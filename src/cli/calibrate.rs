//! `gpustar calibrate`: fit the camera to the frames of a directory (the loop is
//! `gpustar::calibrate::calibrate`); this prints what it found and writes the camera file.

use super::args::CatalogOpts;
use super::config::catalog_config;
use anyhow::{Result, bail};
use gpustar::calibrate::{self, CENTRE_SHIFT_SIGMAS, FitOptions, Step};
use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::io::guard::{Claims, Kind, check_replaceable, write_atomically};
use gpustar::io::inputs;
use gpustar::pipeline::CameraSource;
use gpustar::record::{Record, Status};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `gpustar calibrate`: solve DIR, fit the camera to every solved frame's identified stars,
/// re-identify with the fitted camera and fit again, then write the camera file.
pub(crate) fn calibrate_cmd(
    dir: &Path,
    camera_path: &Path,
    fov_tolerance: Option<f64>,
    recursive: bool,
    opts: FitOptions,
    out: &Path,
    c: &CatalogOpts,
) -> Result<ExitCode> {
    let inputs: Vec<(PathBuf, String)> = inputs::list(dir, recursive)?
        .into_iter()
        .map(|i| (i.path, i.name))
        .collect();
    if inputs.is_empty() {
        bail!("{}: no image files to calibrate with", dir.display());
    }
    // The camera file is written at the end of a long fit: checked now (not an input, not a
    // file gpustar did not write, a directory that takes it).
    let mut claims = Claims::new();
    claims.input_dir(dir, recursive);
    for (path, _) in &inputs {
        claims.input(path, "a frame");
    }
    claims.input(camera_path, "the --camera file");
    if let Some(p) = &c.catalog {
        claims.input(p, "the --catalog");
    }
    claims.output(out, "-o")?;
    check_replaceable(out, Kind::Camera, false)?;
    let (start, camera_mag) = Camera::from_toml_file(camera_path)?;
    let catalog = Catalog::load(c.catalog.as_deref())?;
    let found = calibrate::calibrate(
        &start,
        &catalog,
        catalog_config(c)?.settings(&(CameraSource::Fixed(start.clone()), camera_mag, None)),
        &inputs,
        fov_tolerance,
        opts,
        &mut |step| match step {
            Step::Solved { fitted, records } => summary(
                if fitted {
                    "with the fitted camera"
                } else {
                    "with the camera given"
                },
                records,
            ),
            Step::CentreKept {
                sd_px,
                shift_sigmas,
            } => {
                eprintln!(
                    "gpustar: the principal point is only known to {sd_px:.1} px from these \
                     frames: kept where the camera file puts it"
                );
                if shift_sigmas > CENTRE_SHIFT_SIGMAS {
                    eprintln!(
                        "gpustar: the frames put it {shift_sigmas:.0}σ from there: --fit-centre \
                         fits it (the attitudes then turn with it)"
                    );
                }
            }
            Step::CentreLoose {
                sd_px,
                shift_sigmas,
            } => eprintln!(
                "gpustar: the principal point is only known to {sd_px:.1} px from these frames, \
                 {shift_sigmas:.0}σ from where the camera file puts it: fitted (--fit-centre)"
            ),
        },
    )?;
    let fit = &found.fit;
    for (name, sd) in fit.fitted.iter().zip(&fit.sigmas) {
        let k = &fit.camera;
        let v = match *name {
            "fx" => k.fx,
            "fy" => k.fy,
            "cx" => k.cx,
            "cy" => k.cy,
            "k1" => k.k1,
            _ => k.k2,
        };
        eprintln!("  {name} = {v:.6} ± {sd:.2e}");
    }
    eprintln!(
        "  pixel residuals rms: {:.3} px with the camera given (its frames' stars, each \
         frame's attitude fitted alone), {:.3} px fitted; {} stars used, {} rejected, {} frames",
        found.first.rms_before_px,
        fit.rms_after_px,
        fit.stars_used,
        fit.stars_rejected,
        fit.rotations.len()
    );
    let text = calibrate::camera_file(fit, &dir.display().to_string(), camera_mag);
    write_atomically(out, text.as_bytes())?;
    eprintln!("gpustar: wrote {}", out.display());
    Ok(ExitCode::SUCCESS)
}

/// One line on stderr: frames solved, stars identified, median rmse.
fn summary(what: &str, records: &[Record]) {
    let solved: Vec<&Record> = records
        .iter()
        .filter(|r| r.status == Status::Solved)
        .collect();
    let mut rmse: Vec<f64> = solved.iter().filter_map(|r| r.rmse_arcsec).collect();
    rmse.sort_by(f64::total_cmp);
    let stars: usize = solved.iter().filter_map(|r| r.stars_matched).sum();
    eprintln!(
        "gpustar: {what}: {} of {} frames solved, {stars} stars identified, median rmse {}",
        solved.len(),
        records.len(),
        rmse.get(rmse.len() / 2)
            .map_or("-".to_string(), |v| format!("{v:.2}\"")),
    );
}
