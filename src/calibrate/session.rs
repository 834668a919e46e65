//! `gpustar calibrate`'s loop on a set of frames: solve them with the camera given, fit the
//! camera to every solved frame's identified stars, solve again with the fitted camera (edge
//! stars a rough camera missed come in) and fit again.

use super::fit::{Fit, FitOptions, FrameStars, Star, fit};
use crate::camera::Camera;
use crate::catalog::{Catalog, radec_to_vector};
use crate::error::{Result, fail};
use crate::pipeline::{Backend, CameraSource, Pipeline};
use crate::record::Record;
use crate::solve::Settings;
use std::path::PathBuf;

/// The largest 1σ (pixels) of a fitted principal point that calibration keeps.
pub const CENTRE_SD_PX: f64 = 1.0;
/// A looser principal point further than this many of its 1σ from where the camera given puts
/// it is one the frames disagree with: said, with `--fit-centre` to fit it (a lens 23 px off
/// centre, its stars in the upper 40 % of 50° frames: 1.4 px, 19σ away; kept, fx, k1 and k2
/// bend to make up for it and the fit's rms doubles; fitted, every attitude turns with it,
/// as the camera frame is defined through it: on swarm-a's heads by 0.33–0.71° from the truth
/// frames, their image centres unmoved).
pub const CENTRE_SHIFT_SIGMAS: f64 = 3.0;

/// What a calibration found, and the records it was made from.
pub struct Calibration {
    /// The frames solved with the camera given.
    pub before: Vec<Record>,
    /// The first fit, to the stars of `before`: its `rms_before_px` is the camera given's.
    pub first: Fit,
    /// The principal point's 1σ (px) when it was too loose to fit (over [`CENTRE_SD_PX`]) and
    /// was kept where the camera given puts it.
    pub centre_kept_sd_px: Option<f64>,
    /// The final fit, to the stars identified with the first fit's camera.
    pub fit: Fit,
    /// The frames solved with the final camera.
    pub after: Vec<Record>,
}

/// What [`calibrate`] tells its caller as it goes (a failing fit still leaves these said).
pub enum Step<'a> {
    /// The frames solved with the camera given (`fitted` false) or with the final camera.
    Solved { fitted: bool, records: &'a [Record] },
    /// The principal point was too loose to fit (1σ in px) and is kept as given, though the
    /// frames put it `shift_sigmas` of that 1σ away.
    CentreKept { sd_px: f64, shift_sigmas: f64 },
    /// The principal point is looser than [`CENTRE_SD_PX`] (1σ in px) and fitted all the same
    /// (`--fit-centre`), `shift_sigmas` from where the camera given puts it.
    CentreLoose { sd_px: f64, shift_sigmas: f64 },
}

/// Calibrate `start` on `inputs` (path, record name): solve, fit, solve, fit, solve. With
/// `fov_tolerance` the first solve searches focal lengths within ±that fraction.
pub fn calibrate(
    start: &Camera,
    catalog: &Catalog,
    settings: Settings,
    inputs: &[(PathBuf, String)],
    fov_tolerance: Option<f64>,
    opts: FitOptions,
    on_step: &mut dyn FnMut(Step),
) -> Result<Calibration> {
    if let Some(t) = fov_tolerance
        && !(t > 0.0 && t < 0.5)
    {
        fail!(Config, "--fov-tolerance must be between 0 and 0.5");
    }
    let solve = |camera: &Camera, search: bool| -> Vec<Record> {
        let mut s = settings;
        if search && let Some(t) = fov_tolerance {
            s.scale_range = Some((1.0 - t, 1.0 + t));
        }
        let mut p = Pipeline::new(
            catalog.clone(),
            s,
            CameraSource::Fixed(camera.clone()),
            Backend::Cpu,
        );
        p.process_batch(inputs)
    };
    let before = solve(start, true);
    on_step(Step::Solved {
        fitted: false,
        records: &before,
    });
    // k2 only where the field is wide enough to tell it from k1 (r⁴ at the corner ≥ 1 % of
    // r²'s reach: a half-diagonal of about 18°); the principal point only where the frames
    // fix it to a pixel (a narrow field trades it for the attitudes), unless told to.
    let corner = (start.diagonal_rad() / 2.0).tan().powi(2);
    let mut opts = FitOptions {
        fit_k2: opts.fit_k2 && corner >= 0.1,
        ..opts
    };
    let mut first = fit(start, &stars_of(&before), &opts)?;
    let sd_of = |name: &str| {
        first
            .fitted
            .iter()
            .zip(&first.sigmas)
            .find(|(n, _)| **n == name)
            .map_or(0.0, |(_, sd)| *sd)
    };
    let mut centre_kept_sd_px = None;
    if let Some((sd_px, shift_sigmas)) = centre_step(
        (start.cx, start.cy),
        (first.camera.cx, first.camera.cy),
        (sd_of("cx"), sd_of("cy")),
    ) {
        if opts.keep_loose_centre {
            centre_kept_sd_px = Some(sd_px);
            on_step(Step::CentreKept {
                sd_px,
                shift_sigmas,
            });
            opts.fit_principal_point = false;
            first = fit(start, &stars_of(&before), &opts)?;
        } else {
            on_step(Step::CentreLoose {
                sd_px,
                shift_sigmas,
            });
        }
    }
    let again = solve(&first.camera, false);
    let fitted = fit(&first.camera, &stars_of(&again), &opts)?;
    let after = solve(&fitted.camera, false);
    on_step(Step::Solved {
        fitted: true,
        records: &after,
    });
    Ok(Calibration {
        before,
        first,
        centre_kept_sd_px,
        fit: fitted,
        after,
    })
}

/// A fitted principal point (`fitted`, 1σ `sd` per axis, 0 where not fitted) looser than
/// [`CENTRE_SD_PX`]: its 1σ (the worse axis's) and how many of its 1σ it lies from the one
/// `given` (the worse axis); None when it is fixed to a pixel or not fitted.
pub fn centre_step(given: (f64, f64), fitted: (f64, f64), sd: (f64, f64)) -> Option<(f64, f64)> {
    let sd_px = sd.0.max(sd.1);
    if sd_px <= CENTRE_SD_PX {
        return None;
    }
    let sigmas = |d: f64, s: f64| if s > 0.0 { (d / s).abs() } else { 0.0 };
    Some((
        sd_px,
        sigmas(fitted.0 - given.0, sd.0).max(sigmas(fitted.1 - given.1, sd.1)),
    ))
}

/// Each solved frame's identified stars, with its attitude.
fn stars_of(records: &[Record]) -> Vec<FrameStars> {
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
                    v: radec_to_vector(m.ra_deg, m.dec_deg),
                })
                .collect();
            Some(FrameStars {
                name: r.file.clone(),
                r: nalgebra::Matrix3::from_fn(|i, j| m[i][j]),
                stars,
            })
        })
        .collect()
}

/// The camera file of a fit (the TOML `Camera::from_toml_file` reads), with a comment line
/// saying where it came from.
pub fn camera_file(fit: &Fit, source: &str, mag_limit: Option<f64>) -> String {
    let k = &fit.camera;
    let mut text = format!(
        "# written by gpustar calibrate from {} solved frames of {} ({} stars; rms {:.3} px)\n\
         width = {}\nheight = {}\nfx_px = {}\nfy_px = {}\ncx_px = {}\ncy_px = {}\nk1 = {}\n\
         k2 = {}\nmirrored = {}\n",
        fit.rotations.len(),
        source,
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
    if let Some(m) = mag_limit {
        text.push_str(&format!("mag_limit = {m}\n"));
    }
    text
}
