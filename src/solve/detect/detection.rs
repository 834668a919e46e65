//! What detection gives the identification: a detected star, and how many of the brightest
//! the quads are taken from.

use serde::Serialize;

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
    /// The position's 1σ per axis (pixels) from the PSF fit's Fisher information (rms of x's
    /// and y's); None for a centre of gravity.
    pub sigma_px: Option<f64>,
}

/// The brightest detections the scale-free pass takes its quads from (its last round,
/// `scale_free::ROUND_STARS`): where captions (`drop_caption_rows`) and blends
/// (`point_sources`) are looked for.
pub const QUAD_STARS: usize = 30;
