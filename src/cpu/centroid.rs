//! Stage `centroid`: integer moments of each component on background-subtracted values
//! (seed 000 eq. 3: x = Σ xᵢ gᵢ / Σ gᵢ), compacted into a list in label order.
//!
//! Moments are integers so that the GPU, which has no float atomics, sums the same numbers in
//! any order. The list is in ascending label order, which is what the GPU's count → prefix
//! sum → scatter compaction gives.

use super::threshold::{DetectParams, Run, TileStats, background_at};
use bytemuck::{Pod, Zeroable};

/// Moments of one component. Keep in sync with `shaders/shared/detect.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Blob {
    /// The component's label (its smallest pixel index).
    pub label: u32,
    /// Number of pixels.
    pub area: u32,
    /// Largest raw pixel value.
    pub peak: u32,
    /// Number of pixels at or above saturation.
    pub saturated: u32,
    /// Σ w, Σ w·x, Σ w·y with w = pixel − background (≥ 1 inside the mask).
    pub m0: u64,
    pub mx: u64,
    pub my: u64,
}

impl Blob {
    /// Centroid (x, y) in pixels.
    pub fn centre(&self) -> (f64, f64) {
        (
            self.mx as f64 / self.m0 as f64,
            self.my as f64 / self.m0 as f64,
        )
    }
}

/// Moments of every component, in ascending label order.
pub fn centroid(
    pixels: &[u16],
    runs: &[Run],
    labels: &[u32],
    tiles: &[TileStats],
    p: &DetectParams,
) -> Vec<Blob> {
    let mut blobs: Vec<Blob> = Vec::new();
    // A component's first run comes first in raster order, so slots are handed out in label
    // order; `slot` maps a label to its slot.
    let mut slot: std::collections::HashMap<u32, usize> = Default::default();
    for (r, &label) in runs.iter().zip(labels) {
        let s = *slot.entry(label).or_insert_with(|| {
            blobs.push(Blob {
                label,
                ..Default::default()
            });
            blobs.len() - 1
        });
        let b = &mut blobs[s];
        for x in r.x0..r.x1 {
            let v = pixels[(r.y * p.width + x) as usize] as u32;
            let w = v.saturating_sub(background_at(tiles, p, x, r.y)).max(1) as u64;
            b.area += 1;
            b.peak = b.peak.max(v);
            b.saturated += (v >= p.saturation) as u32;
            b.m0 += w;
            b.mx += w * x as u64;
            b.my += w * r.y as u64;
        }
    }
    blobs
}
