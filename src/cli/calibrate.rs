//! `gpustar calibrate`: fit the camera to the frames of a directory.

use super::args::*;
use super::solve::*;
use anyhow::{Context, Result, bail};
use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::io::inputs::{self};
use gpustar::pipeline::{Backend, CameraSource, Pipeline};
use gpustar::record::Record;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The largest 1σ (pixels) of a fitted principal point that calibration keeps.
pub(crate) const CALIBRATE_CENTRE_SD_PX: f64 = 1.0;

/// `gpustar calibrate`: solve DIR, fit the camera to every solved frame's identified stars,
/// re-identify with the fitted camera and fit again, then write the camera file.
pub(crate) fn calibrate_cmd(
    dir: &Path,
    camera_path: &Path,
    fov_tolerance: Option<f64>,
    recursive: bool,
    opts: gpustar::calibrate::FitOptions,
    out: &Path,
    c: &CatalogOpts,
) -> Result<ExitCode> {
    use gpustar::calibrate::{self, FrameStars, Star};
    let inputs: Vec<(PathBuf, String)> = inputs::list(dir, recursive)?
        .into_iter()
        .map(|i| (i.path, i.name))
        .collect();
    if inputs.is_empty() {
        bail!("{}: no image files to calibrate with", dir.display());
    }
    let (start, camera_mag) = Camera::from_toml_file(camera_path)?;
    let catalog = Catalog::load(c.catalog.as_deref())?;
    let solve = |camera: &Camera, search: bool| -> Result<Vec<Record>> {
        let mut s = settings(c, camera_mag);
        if search && let Some(t) = fov_tolerance {
            if !(t > 0.0 && t < 0.5) {
                bail!("--fov-tolerance must be between 0 and 0.5");
            }
            s.scale_range = Some((1.0 - t, 1.0 + t));
        }
        let mut p = Pipeline::new(
            catalog.clone(),
            s,
            CameraSource::Fixed(camera.clone()),
            Backend::Cpu,
        );
        Ok(p.process_batch(&inputs))
    };
    let stars_of = |records: &[Record]| -> Vec<FrameStars> {
        records
            .iter()
            .filter_map(|r| {
                let m = r.rotation_matrix?;
                let stars = r
                    .matches
                    .as_ref()?
                    .iter()
                    .map(|m| Star {
                        x: m.x,
                        y: m.y,
                        v: gpustar::catalog::radec_to_vector(m.ra_deg, m.dec_deg),
                    })
                    .collect();
                Some(FrameStars {
                    name: r.file.clone(),
                    r: nalgebra::Matrix3::from_fn(|i, j| m[i][j]),
                    stars,
                })
            })
            .collect()
    };
    let summary = |what: &str, records: &[Record]| {
        let solved: Vec<&Record> = records
            .iter()
            .filter(|r| r.status == gpustar::record::Status::Solved)
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
    };
    let before = solve(&start, true)?;
    summary("with the camera given", &before);
    // k2 only where the field is wide enough to tell it from k1 (r⁴ at the corner ≥ 1 % of
    // r²'s reach: a half-diagonal of about 18°); the principal point only where the frames
    // fix it to a pixel (a narrow field trades it for the attitudes).
    let corner = (start.diagonal_rad() / 2.0).tan().powi(2);
    let mut opts = calibrate::FitOptions {
        fit_k2: opts.fit_k2 && corner >= 0.1,
        ..opts
    };
    let mut first = calibrate::fit(&start, &stars_of(&before), &opts)?;
    let centre_sd = first
        .fitted
        .iter()
        .zip(&first.sigmas)
        .filter(|(n, _)| **n == "cx" || **n == "cy")
        .map(|(_, sd)| *sd)
        .fold(0.0, f64::max);
    if centre_sd > CALIBRATE_CENTRE_SD_PX {
        eprintln!(
            "gpustar: the principal point is only known to {centre_sd:.1} px from these frames: \
             kept where the camera file puts it"
        );
        opts.fit_principal_point = false;
        first = calibrate::fit(&start, &stars_of(&before), &opts)?;
    }
    // Edge stars a rough camera missed come in with the fitted one: fit again.
    let again = solve(&first.camera, false)?;
    let fit = calibrate::fit(&first.camera, &stars_of(&again), &opts)?;
    let after = solve(&fit.camera, false)?;
    summary("with the fitted camera", &after);
    for (name, (v, sd)) in fit.fitted.iter().zip(
        fit.fitted
            .iter()
            .map(|n| match *n {
                "fx" => fit.camera.fx,
                "fy" => fit.camera.fy,
                "cx" => fit.camera.cx,
                "cy" => fit.camera.cy,
                "k1" => fit.camera.k1,
                _ => fit.camera.k2,
            })
            .zip(&fit.sigmas),
    ) {
        eprintln!("  {name} = {v:.6} ± {sd:.2e}");
    }
    eprintln!(
        "  pixel residuals rms: {:.3} px with the camera given (its frames' stars, each \
         frame's attitude fitted alone), {:.3} px fitted; {} stars used, {} rejected, {} frames",
        first.rms_before_px,
        fit.rms_after_px,
        fit.stars_used,
        fit.stars_rejected,
        fit.rotations.len()
    );
    let k = &fit.camera;
    let mut text = format!(
        "# written by gpustar calibrate from {} solved frames of {} ({} stars; rms {:.3} px)\n\
         width = {}\nheight = {}\nfx_px = {}\nfy_px = {}\ncx_px = {}\ncy_px = {}\nk1 = {}\n\
         k2 = {}\nmirrored = {}\n",
        fit.rotations.len(),
        dir.display(),
        fit.stars_used,
        fit.rms_after_px,
        k.width,
        k.height,
        k.fx,
        k.fy,
        k.cx,
        k.cy,
        k.k1,
        k.k2,
        k.mirrored
    );
    if let Some(m) = camera_mag {
        text.push_str(&format!("mag_limit = {m}\n"));
    }
    std::fs::write(out, text).with_context(|| format!("cannot write {}", out.display()))?;
    eprintln!("gpustar: wrote {}", out.display());
    Ok(ExitCode::SUCCESS)
}
