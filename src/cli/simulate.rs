//! `gpustar simulate`: synthetic frames and their truth.

use super::args::SimulateArgs;
use anyhow::Result;
use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::simulate::hints::HintSim;
use gpustar::simulate::{self, SimSettings};
use std::process::ExitCode;
use std::time::Instant;

pub(crate) fn simulate_cmd(a: SimulateArgs) -> Result<ExitCode> {
    let catalog = Catalog::load(a.catalog.as_deref())?;
    let s = SimSettings {
        width: a.size.0,
        height: a.size.1,
        fov_x_deg: a.fov_deg,
        mag_limit: a.mag_limit,
        frames: a.frames,
        seed: a.seed,
        epoch: a.epoch,
        psf_sigma_px: a.psf_sigma,
        sky_e: a.sky,
        read_noise_e: a.read_noise,
        vignetting: a.vignetting,
        bits: a.bits,
        false_stars: a.false_stars,
        hot_pixels: a.hot_pixels,
        centroid_noise_px: a.centroid_noise_px,
        camera: match &a.camera {
            Some(p) => Some(Camera::from_toml_file(p)?.0),
            None => None,
        },
        limit_snr: a.limit_snr,
        pointing: a.pointing,
        hints: a.hint_offset_deg.map(|offset_deg| HintSim {
            offset_deg,
            exposure_s: a.exposure,
        }),
        ..SimSettings::default()
    };
    // Stars the frames cannot show, with the camera file saying they are there, make a set
    // that a solver is wrongly blamed for.
    let faint = s.peak_snr(s.mag_limit);
    if a.limit_snr.is_none() && faint < 5.0 {
        eprintln!(
            "gpustar: warning: stars of --mag-limit {} peak at SNR {faint:.1} at the default \
             zero point; --limit-snr 8 makes every star to the limit visible",
            s.mag_limit
        );
    }
    let t0 = Instant::now();
    if a.streaks {
        let start = gpustar::sky::Utc::parse(&a.start_utc)
            .map_err(|e| anyhow::anyhow!("--start-utc: {e}"))?;
        let st = gpustar::streaks::simulate::StreakSim {
            start,
            cadence_s: 60.0,
            exposure_s: a.exposure,
            station: a.station,
            snr: a.streak_snr,
            length_px: (40.0, 1.5 * f64::from(a.size.0.max(a.size.1))),
        };
        // The stars where they are on the frames' date.
        let s = SimSettings {
            bits: 16,
            epoch: gpustar::sky::julian_year(&a.start_utc).unwrap_or(a.epoch),
            ..s
        };
        gpustar::streaks::simulate::write_set(&catalog, &s, &st, &a.out)?;
        eprintln!(
            "gpustar: wrote {} FITS frames with streaks, truth.jsonl and camera.toml to {} in {:.1} s",
            a.frames,
            a.out.display(),
            t0.elapsed().as_secs_f64()
        );
        return Ok(ExitCode::SUCCESS);
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    if a.sequence {
        let q = gpustar::sequence::simulate::SequenceSim {
            sequences: a.sequences,
            frames: a.frames,
            interval_s: a.frame_interval,
            rate_deg_s: a.turn_rate,
            particle_ratio: a.particle_ratio,
            particle_speed_arcmin_s: a.particle_speed,
            particle_mag: a.particle_mag,
            start: gpustar::sky::Utc::parse(&a.start_utc)
                .map_err(|e| anyhow::anyhow!("--start-utc: {e}"))?,
            ..Default::default()
        };
        let s = SimSettings {
            epoch: gpustar::sky::julian_year(&a.start_utc).unwrap_or(a.epoch),
            ..s
        };
        gpustar::sequence::simulate::write_set(&catalog, &s, &q, &a.out, threads)?;
        eprintln!(
            "gpustar: wrote {} sequences of {} FITS frames, truth.jsonl and camera.toml to {} \
             in {:.1} s",
            a.sequences,
            a.frames,
            a.out.display(),
            t0.elapsed().as_secs_f64()
        );
        return Ok(ExitCode::SUCCESS);
    }
    let s = SimSettings {
        // FITS frames with hints are 16-bit, as --streaks's.
        bits: if s.hints.is_some() { 16 } else { s.bits },
        ..s
    };
    simulate::write_set(&catalog, &s, &a.out, threads, |_| {})?;
    eprintln!(
        "gpustar: wrote {} {}, truth.jsonl and camera.toml to {} in {:.1} s",
        a.frames,
        if s.hints.is_some() {
            "FITS frames with pointing hints"
        } else {
            "frames"
        },
        a.out.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(ExitCode::SUCCESS)
}
