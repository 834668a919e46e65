//! Satellite streaks in optical-tracking frames (seed 004): found in the frame, measured to
//! sub-pixel ends, kept out of star detection, and reduced to RA/Dec and topocentric Az/El.
//!
//! The pipeline: `streak_filter` (the pixel stage, a GPU kernel with its CPU twin in
//! `cpu::streak_filter`: background-subtracted pixels smoothed by a 5×5 binomial kernel,
//! thresholded at k noise sigmas) → [`segments`] (components of that mask, lines by a coarse
//! Hough vote per component, collinear pieces joined) → [`fit`] (least squares of a
//! PSF-blurred segment for the ends, width, flux) → the tests below that keep stars, chains of
//! stars, hot or bleeding columns and noise out → [`sky`] (times, station, Az/El) and
//! [`formats`] (CCSDS TDM, IOD).

pub mod fit;
pub mod segments;

use crate::cpu::centroid::Blob;
use crate::cpu::streak_filter::{StreakParams, mask_runs, streak_filter, streak_rows};
use crate::cpu::threshold::{DetectParams, TileStats, background_at, tile_stats};
use crate::frame::Frame;
use fit::StreakFit;
use segments::{SegmentSettings, segments};

/// Settings of streak detection.
#[derive(Clone, Copy, Debug)]
pub struct StreakSettings {
    /// The mask's threshold, in noise sigmas of the smoothed image.
    pub k_sigma: f32,
    /// Shortest streak reported (pixels between its ends in the frame).
    pub min_length_px: f64,
    /// Smallest matched-filter SNR reported.
    pub min_snr: f64,
    /// Narrowest profile (Gaussian σ, pixels) taken for a streak: a defective column is a
    /// pixel wide (σ ≈ 0.3), anything the optics drew is as wide as the PSF.
    pub min_sigma_px: f64,
    /// Largest share of a track's clear 4 px bins that may fall short of the fit (chains of
    /// stars have gaps between the stars, streaks none).
    pub max_gap_fraction: f64,
}

impl Default for StreakSettings {
    fn default() -> Self {
        StreakSettings {
            k_sigma: 3.5,
            min_length_px: 25.0,
            min_snr: 10.0,
            min_sigma_px: 0.5,
            max_gap_fraction: 0.25,
        }
    }
}

impl StreakSettings {
    /// The mask parameters for tiles made with detection threshold `k_detect`.
    pub fn params(&self, k_detect: f32) -> StreakParams {
        StreakParams::new(self.k_sigma, k_detect)
    }
}

/// Lines closer to a frame axis than this (degrees) are suspects: bad columns and rows, and
/// charge bleeding from saturated stars, run exactly along the axes.
const AXIS_DEG: f64 = 0.5;

/// Find the streaks of a frame on the CPU: the pixel stage's twins, then [`measure`].
pub fn find_cpu(
    frame: &Frame,
    p: &DetectParams,
    s: &StreakSettings,
    k_detect: f32,
) -> Vec<StreakFit> {
    let tiles = tile_stats(&frame.pixels, p);
    let rows = streak_rows(&frame.pixels, &tiles, p);
    let mask = streak_filter(&rows, &tiles, p, &s.params(k_detect));
    measure(frame, &tiles, &mask, p, s)
}

/// From a streak mask (words, as `streak_filter` writes them, on the CPU or the GPU) to the
/// streaks: segments, fits, and the tests that keep everything else out. Ordered by SNR,
/// brightest first (ties by position), so the order does not depend on the backend.
pub fn measure(
    frame: &Frame,
    tiles: &[TileStats],
    mask: &[u32],
    p: &DetectParams,
    s: &StreakSettings,
) -> Vec<StreakFit> {
    let runs = mask_runs(mask, p.width, p.height);
    let segs = segments(&runs, p.width, &SegmentSettings::default());
    let d = |x: u32, y: u32| {
        frame.pixels[(y * p.width + x) as usize] as f64 - background_at(tiles, p, x, y) as f64
    };
    let mut out: Vec<StreakFit> = Vec::new();
    for seg in &segs {
        let Some(f) = fit::fit(&d, p.width, p.height, seg) else {
            continue;
        };
        if !accept(&f, frame, s) {
            continue;
        }
        // One streak is one fit: pieces that were not joined can converge on the same line.
        if out.iter().any(|g| same_line(g, &f)) {
            continue;
        }
        out.push(f);
    }
    out.sort_by(|a, b| {
        b.snr
            .total_cmp(&a.snr)
            .then(a.ends[0].0.total_cmp(&b.ends[0].0))
            .then(a.ends[0].1.total_cmp(&b.ends[0].1))
    });
    out
}

/// Is this fit a streak, and not a star, a chain of stars, a defect or noise?
fn accept(f: &StreakFit, frame: &Frame, s: &StreakSettings) -> bool {
    let len = length(f);
    if len < s.min_length_px || f.snr < s.min_snr || f.sigma_px < s.min_sigma_px {
        return false;
    }
    if f.gap_fraction > s.max_gap_fraction {
        return false;
    }
    if f.axis_angle_deg < AXIS_DEG {
        // Along a frame axis: a defective column or row is narrow; a bleed trail holds
        // saturated pixels.
        if f.sigma_px < 0.7 || touches_saturation(f, frame) {
            return false;
        }
    }
    true
}

/// The length between the ends in the frame (pixels).
pub fn length(f: &StreakFit) -> f64 {
    let [(x0, y0), (x1, y1)] = f.ends;
    ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt()
}

fn same_line(a: &StreakFit, b: &StreakFit) -> bool {
    let cos = (a.dir.0 * b.dir.0 + a.dir.1 * b.dir.1).abs();
    let mid = |f: &StreakFit| {
        (
            0.5 * (f.ends[0].0 + f.ends[1].0),
            0.5 * (f.ends[0].1 + f.ends[1].1),
        )
    };
    let (m, n) = (mid(b), mid(a));
    let across = (-(m.0 - n.0) * a.dir.1 + (m.1 - n.1) * a.dir.0).abs();
    cos > 2f64.to_radians().cos() && across < 3.0 && distance_to(a, m.0, m.1) < 3.0
}

/// Does any pixel within 2σ of the track reach saturation?
fn touches_saturation(f: &StreakFit, frame: &Frame) -> bool {
    let len = length(f).max(1.0);
    let r = (2.0 * f.sigma_px).max(1.5);
    let [(x0, y0), (x1, y1)] = f.ends;
    let steps = len.ceil() as usize;
    (0..=steps).any(|k| {
        let t = k as f64 / steps as f64;
        let (x, y) = (x0 + t * (x1 - x0), y0 + t * (y1 - y0));
        let (xa, xb) = ((x - r).floor().max(0.0) as u32, (x + r).ceil() as u32);
        let (ya, yb) = ((y - r).floor().max(0.0) as u32, (y + r).ceil() as u32);
        (ya..=yb.min(frame.height - 1)).any(|yy| {
            (xa..=xb.min(frame.width - 1))
                .any(|xx| frame.pixels[(yy * frame.width + xx) as usize] >= frame.saturation)
        })
    })
}

/// Distance of (x, y) from the streak's segment between its ends (pixels).
pub fn distance_to(f: &StreakFit, x: f64, y: f64) -> f64 {
    let [(x0, y0), (x1, y1)] = f.ends;
    let (dx, dy) = (x1 - x0, y1 - y0);
    let l2 = (dx * dx + dy * dy).max(1e-12);
    let t = (((x - x0) * dx + (y - y0) * dy) / l2).clamp(0.0, 1.0);
    ((x - x0 - t * dx).powi(2) + (y - y0 - t * dy).powi(2)).sqrt()
}

/// The blobs of star detection that do not lie on a streak (to star detection a streak is
/// one bright "star", or a row of them): those farther than 3σ + 2 px from every segment.
pub fn off_streaks(blobs: &[Blob], streaks: &[StreakFit]) -> Vec<Blob> {
    blobs
        .iter()
        .filter(|b| {
            let (x, y) = b.centre();
            !streaks
                .iter()
                .any(|f| distance_to(f, x, y) <= 3.0 * f.sigma_px + 2.0)
        })
        .copied()
        .collect()
}
