//! Detection: threshold → components → centroid, then the star list (brightest first).

use crate::cpu;
use crate::cpu::centroid::Blob;
use crate::cpu::threshold::DetectParams;
use crate::frame::Frame;
use serde::Serialize;

/// Settings of detection.
#[derive(Clone, Copy, Debug)]
pub struct DetectSettings {
    /// Tile side for background and noise (pixels, 4–64).
    pub tile: u32,
    /// Threshold above the local background, in noise sigmas.
    pub k_sigma: f32,
    /// Smallest component kept (pixels): 2 rejects single hot pixels.
    pub min_area: u32,
    /// How many of the brightest stars go on to identification.
    pub max_stars: usize,
    /// Threshold the frame smoothed by the matched filter (3×3 binomial) as well as the pixel:
    /// fainter stars (see `cpu::threshold::threshold_filtered`).
    pub matched_filter: bool,
    /// How each star's position is measured.
    pub centroid: Centroid,
}

/// How a star's position is measured (`--centroid`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Centroid {
    /// Centre of gravity of the component's background-subtracted pixels (seed 000 eq. 3).
    Cog,
    /// Maximum-likelihood fit of a pixel-integrated Gaussian on a 9×9 window
    /// (`cpu::psf_fit`); the centre of gravity where the fit does not settle.
    Ml,
}

impl Default for DetectSettings {
    fn default() -> Self {
        DetectSettings {
            tile: 32,
            k_sigma: 5.0,
            min_area: 2,
            max_stars: 100,
            matched_filter: false,
            centroid: Centroid::Cog,
        }
    }
}

/// A detected star.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Detection {
    pub x: f64,
    pub y: f64,
    /// Background-subtracted sum of the component (ADU).
    pub flux: f64,
    pub area: u32,
    pub peak: u32,
    /// Some pixel reached the format's maximum: the centroid is less certain.
    pub saturated: bool,
}

/// The stage parameters for a frame under these settings.
pub fn params(frame: &Frame, s: &DetectSettings) -> DetectParams {
    DetectParams::new(
        frame.width,
        frame.height,
        s.tile,
        s.k_sigma,
        frame.saturation as u32,
    )
    .with_filter(s.matched_filter)
}

/// Run the CPU twins of the detection kernels: the blobs in label order.
pub fn blobs_cpu(frame: &Frame, p: &DetectParams) -> Vec<Blob> {
    let tiles = cpu::threshold::tile_stats(&frame.pixels, p);
    let runs = cpu::threshold::threshold(&frame.pixels, &tiles, p);
    let labels = cpu::components::components(&runs, p.width);
    cpu::centroid::centroid(&frame.pixels, &runs, &labels, &tiles, p)
}

/// Smallest component kept with the matched filter: a star of peak SNR 4 sets about five
/// pixels, a hot pixel one (two with one noisy neighbour).
pub const MIN_AREA_FILTERED: u32 = 3;

/// Turn blobs into the star list: drop those smaller than `min_area` (hot pixels), order by
/// flux (ties by label, so the order is total), keep the brightest `max_stars`.
pub fn star_list(blobs: &[Blob], s: &DetectSettings) -> Vec<Detection> {
    // With the matched filter a hot pixel's neighbours need only reach 0.375 k sigmas to join
    // it (a few per cent of them do by chance); two of them rarely.
    let min_area = if s.matched_filter {
        s.min_area.max(MIN_AREA_FILTERED)
    } else {
        s.min_area
    };
    let mut kept: Vec<&Blob> = blobs.iter().filter(|b| b.area >= min_area).collect();
    kept.sort_by(|a, b| b.m0.cmp(&a.m0).then(a.label.cmp(&b.label)));
    kept.truncate(s.max_stars);
    kept.iter()
        .map(|b| {
            let (x, y) = b.centre();
            Detection {
                x,
                y,
                flux: b.m0 as f64,
                area: b.area,
                peak: b.peak,
                saturated: b.saturated > 0,
            }
        })
        .collect()
}

/// The star list of a frame's blobs, with each position measured as the settings say.
pub fn stars(frame: &Frame, blobs: &[Blob], s: &DetectSettings) -> Vec<Detection> {
    let mut list = star_list(blobs, s);
    if s.centroid == Centroid::Ml {
        for d in &mut list {
            let fit = cpu::psf_fit::psf_fit(&frame.pixels, frame.width, frame.height, d.x, d.y);
            if let Some(f) = fit.filter(|_| !d.saturated) {
                (d.x, d.y) = (f.x, f.y);
            }
        }
    }
    list
}

/// Detect stars in a frame on the CPU.
pub fn detect(frame: &Frame, s: &DetectSettings) -> Vec<Detection> {
    stars(frame, &blobs_cpu(frame, &params(frame, s)), s)
}
