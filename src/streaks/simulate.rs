//! `gpustar simulate --streaks`: star frames as `simulate` makes them, with satellite streaks
//! of known ends drawn in, written as FITS with the exposure's times (DATE-BEG, DATE-END,
//! EXPTIME, TIMESYS) and the station (OBSGEO-B/L/H) in the header, and a truth file whose
//! records add each streak's ends.
//!
//! A streak is a point moving uniformly from `p0` (exposure start) to `p1` (exposure end)
//! through the same Gaussian PSF as the stars: the analytic image of the blurred segment,
//! in electrons, with Poisson noise of its own added as a Gaussian of the same variance (the
//! star frame's noise is already in its pixels; the sum of Poisson counts is Poisson).

use crate::catalog::Catalog;
use crate::error::{Context, Error, IntoKind, Result, fail};
use crate::simulate::{SimSettings, Truth, render};
use crate::sky::{Station, Utc};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// What the streaks of a simulated set are like.
#[derive(Clone, Copy, Debug)]
pub struct StreakSim {
    /// The exposure of frame 0 starts here (UTC); frame k starts k × `cadence_s` later.
    pub start: Utc,
    pub cadence_s: f64,
    pub exposure_s: f64,
    pub station: Station,
    /// Peak SNR per pixel of the streaks, drawn uniformly in this range.
    pub snr: (f64, f64),
    /// Streak lengths (pixels), drawn log-uniformly in this range.
    pub length_px: (f64, f64),
}

/// A streak in a truth record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthStreak {
    /// Where the object was at the exposure's start and end (pixels; may be off the frame).
    pub p0: [f64; 2],
    pub p1: [f64; 2],
    /// That end is off the frame.
    pub edge0: bool,
    pub edge1: bool,
    pub peak_snr: f64,
}

/// A truth record of a streak frame: the star truth, the times and the streaks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StreakTruth {
    #[serde(flatten)]
    pub stars: Truth,
    pub date_beg_utc: String,
    pub date_end_utc: String,
    pub station: [f64; 3],
    pub streaks: Vec<TruthStreak>,
}

/// The name of frame k of a streak set.
pub fn frame_name(index: usize) -> String {
    format!("sim_{index:05}.fits")
}

/// Render frame k: its pixels and truth. Every fifth frame has no streak; the others one or
/// two, placed so that many cross the frame's edge.
pub fn render_streaks(
    catalog: &Catalog,
    s: &SimSettings,
    st: &StreakSim,
    index: usize,
) -> Result<(Vec<u16>, StreakTruth)> {
    if s.bits != 16 {
        fail!(
            Config,
            "simulate --streaks writes 16-bit FITS: give --bits 16"
        );
    }
    let (mut pixels, mut truth) = render(catalog, s, index)?;
    truth.file = frame_name(index);
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed ^ 0x5354_5245_414B);
    rng.set_stream(index as u64);
    let (w, h) = (truth.width as f64, truth.height as f64);
    let count = match index % 5 {
        4 => 0,
        _ if rng.random_bool(0.3) => 2,
        _ => 1,
    };
    let gain = 65535.0 / s.full_well_e;
    let noise_e = (s.sky_e + s.read_noise_e * s.read_noise_e).sqrt();
    let mut streaks = Vec::new();
    while streaks.len() < count {
        let (l0, l1) = st.length_px;
        let len = (l0.ln() + rng.random::<f64>() * (l1 / l0).ln()).exp();
        let th = rng.random::<f64>() * std::f64::consts::TAU;
        // The centre anywhere within a margin of the frame: a long streak often crosses.
        let (cx, cy) = (
            rng.random_range(-0.1 * w..1.1 * w),
            rng.random_range(-0.1 * h..1.1 * h),
        );
        let p0 = [cx - 0.5 * len * th.cos(), cy - 0.5 * len * th.sin()];
        let p1 = [cx + 0.5 * len * th.cos(), cy + 0.5 * len * th.sin()];
        let inside = |p: [f64; 2]| p[0] >= 3.0 && p[1] >= 3.0 && p[0] <= w - 4.0 && p[1] <= h - 4.0;
        let off = |p: [f64; 2]| p[0] < -0.5 || p[1] < -0.5 || p[0] > w - 0.5 || p[1] > h - 0.5;
        // Ends either well inside or off the frame (none on the border's last pixels), and
        // at least 40 px of it in the frame.
        if !(inside(p0) || off(p0)) || !(inside(p1) || off(p1)) || visible(p0, p1, w, h) < 40.0 {
            continue;
        }
        let snr = rng.random_range(st.snr.0..st.snr.1);
        draw(
            &mut pixels,
            truth.width,
            p0,
            p1,
            snr * noise_e,
            s.psf_sigma_px,
            gain,
            &mut rng,
        );
        streaks.push(TruthStreak {
            p0,
            p1,
            edge0: off(p0),
            edge1: off(p1),
            peak_snr: snr,
        });
    }
    let t0 = st.start.add_seconds(index as f64 * st.cadence_s);
    Ok((
        pixels,
        StreakTruth {
            stars: truth,
            date_beg_utc: t0.iso(),
            date_end_utc: t0.add_seconds(st.exposure_s).iso(),
            station: [st.station.lat_deg, st.station.lon_deg, st.station.height_m],
            streaks,
        },
    ))
}

/// Length of the part of p0–p1 inside the frame's pixel-centre box.
fn visible(p0: [f64; 2], p1: [f64; 2], w: f64, h: f64) -> f64 {
    let (dx, dy) = (p1[0] - p0[0], p1[1] - p0[1]);
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for (p, d, max) in [(p0[0], dx, w - 1.0), (p0[1], dy, h - 1.0)] {
        if d.abs() < 1e-12 {
            if p < 0.0 || p > max {
                return 0.0;
            }
            continue;
        }
        let (a, b) = (-p / d, (max - p) / d);
        lo = lo.max(a.min(b));
        hi = hi.min(a.max(b));
    }
    (hi - lo).max(0.0) * (dx * dx + dy * dy).sqrt()
}

/// Add the blurred segment p0–p1 of peak `peak_e` electrons per pixel, with its Poisson noise.
#[allow(clippy::too_many_arguments)]
fn draw(
    pixels: &mut [u16],
    width: u32,
    p0: [f64; 2],
    p1: [f64; 2],
    peak_e: f64,
    sigma: f64,
    gain: f64,
    rng: &mut ChaCha8Rng,
) {
    let height = pixels.len() as u32 / width;
    let (dx, dy) = (p1[0] - p0[0], p1[1] - p0[1]);
    let len = (dx * dx + dy * dy).sqrt();
    let (ux, uy) = (dx / len, dy / len);
    let k = 1.0 / (std::f64::consts::SQRT_2 * sigma);
    let reach = 5.0 * sigma;
    let (x0, x1) = (p0[0].min(p1[0]) - reach, p0[0].max(p1[0]) + reach);
    let (y0, y1) = (p0[1].min(p1[1]) - reach, p0[1].max(p1[1]) + reach);
    let unit = Normal::new(0.0, 1.0).expect("a unit normal");
    for y in (y0.floor().max(0.0) as u32)..=(y1.ceil().min(height as f64 - 1.0).max(0.0) as u32) {
        for x in (x0.floor().max(0.0) as u32)..=(x1.ceil().min(width as f64 - 1.0).max(0.0) as u32)
        {
            let (px, py) = (x as f64 - p0[0], y as f64 - p0[1]);
            let (t, d) = (px * ux + py * uy, -px * uy + py * ux);
            if d.abs() > reach || t < -reach || t > len + reach {
                continue;
            }
            let e = peak_e
                * (-d * d / (2.0 * sigma * sigma)).exp()
                * 0.5
                * (libm::erf(t * k) - libm::erf((t - len) * k));
            let e = e + e.sqrt() * unit.sample(rng);
            let i = (y * width + x) as usize;
            pixels[i] = (pixels[i] as f64 + e * gain).round().clamp(0.0, 65535.0) as u16;
        }
    }
}

/// Write the set: FITS frames, `truth.jsonl`, `camera.toml`.
pub fn write_set(catalog: &Catalog, s: &SimSettings, st: &StreakSim, out: &Path) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let mut truth_file = std::io::BufWriter::new(
        std::fs::File::create(out.join("truth.jsonl")).context("cannot create truth.jsonl")?,
    );
    for k in 0..s.frames {
        let (pixels, truth) = render_streaks(catalog, s, st, k)?;
        let q = |v: &str| format!("'{v}'");
        let cards = [
            ("DATE-OBS", q(&truth.date_beg_utc)),
            ("DATE-BEG", q(&truth.date_beg_utc)),
            ("DATE-END", q(&truth.date_end_utc)),
            ("EXPTIME", format!("{}", st.exposure_s)),
            ("TIMESYS", q("UTC")),
            ("OBSGEO-B", format!("{}", st.station.lat_deg)),
            ("OBSGEO-L", format!("{}", st.station.lon_deg)),
            ("OBSGEO-H", format!("{}", st.station.height_m)),
        ]
        .map(|(k, v)| crate::io::fits::card(k, &v));
        let bytes =
            crate::io::fits::encode_u16(truth.stars.width, truth.stars.height, &pixels, &cards);
        let path = out.join(&truth.stars.file);
        std::fs::write(&path, bytes).with_context(|| format!("cannot write {}", path.display()))?;
        writeln!(
            truth_file,
            "{}",
            serde_json::to_string(&truth).into_kind(Error::Output)?
        )?;
    }
    truth_file.flush()?;
    let text = format!(
        "# written by gpustar simulate --streaks\nwidth = {}\nheight = {}\nfov_x_deg = {}\n",
        s.width, s.height, s.fov_x_deg
    );
    std::fs::write(out.join("camera.toml"), text).context("cannot write camera.toml")?;
    Ok(())
}
