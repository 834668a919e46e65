//! Stage `streak_filter`: the streak mask, in two kernels.
//!
//! `streak_rows` subtracts the local background (the tiles of stage `threshold`, interpolated
//! bilinearly in integers exactly as `threshold::background_at`) and sums each pixel's row
//! neighbours with the binomial weights 1 4 6 4 1; `streak_filter` sums five of those row sums
//! down the column with the same weights and sets a mask bit where the result exceeds
//! k_streak noise sigmas of the smoothed image. The 5×5 kernel is a Gaussian of σ = 1 px: on
//! a streak whose profile has σ ≈ 1.2 px it raises the per-pixel SNR about 2.8 times (peak
//! 0.77 of the profile's, noise 70/256 of the pixels'), so a streak of peak SNR 3 stands at
//! about 8 noise sigmas and stays connected. Everything is integer arithmetic: the GPU twins
//! (`shaders/streak_rows.wgsl`, `shaders/streak_filter.wgsl`) give the same bits.

use super::threshold::{DetectParams, Run, TileStats, axis_weight};
use bytemuck::{Pod, Zeroable};

/// The binomial weights of one axis (sum 16; Σw² = 70).
pub const BINOMIAL: [i32; 5] = [1, 4, 6, 4, 1];

/// Noise of the smoothed sum in pixel sigmas: sqrt(Σ_ij (b_i b_j)²) = 70.
pub const SMOOTHED_NOISE: f32 = 70.0;

/// Parameters of the streak mask. Keep in sync with `shaders/shared/streak.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct StreakParams {
    /// A pixel is set where its smoothed sum exceeds `offset · level_num / level_den`, with
    /// `offset` its tile's detection offset (k_sigma noise sigmas): k_streak · 70 · σ.
    pub level_num: u32,
    pub level_den: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}

impl StreakParams {
    /// The mask at `k_streak` noise sigmas of the smoothed image, for tiles made with the
    /// detection threshold `k_sigma` (the tiles carry `ceil(k_sigma · σ)` as their offset).
    pub fn new(k_streak: f32, k_sigma: f32) -> StreakParams {
        const DEN: u32 = 16;
        // offset ≤ 2^19 (k_sigma · 1.4826 · 65535 for k_sigma ≤ 5.4); the product must fit
        // u32, so the ratio is capped at 2^12 / 16 = 256 (k_streak/k_sigma ≤ 3.6).
        let ratio = (k_streak * SMOOTHED_NOISE / k_sigma.max(0.1)).clamp(0.0, 256.0);
        StreakParams {
            level_num: ((ratio * DEN as f32).round() as u32).clamp(1, 4096),
            level_den: DEN,
            _pad0: 0,
            _pad1: 0,
        }
    }

    /// The level the smoothed sum must exceed in a tile with this detection offset.
    #[inline]
    pub fn level(&self, offset: u32) -> i32 {
        (offset.min(1 << 19) * self.level_num / self.level_den) as i32
    }
}

/// Kernel `streak_rows`: per pixel, Σ_i b_i · (pixel − background) over the row neighbours
/// x − 2 … x + 2 (clamped at the frame's edges).
pub fn streak_rows(pixels: &[u16], tiles: &[TileStats], p: &DetectParams) -> Vec<i32> {
    let (w, h) = (p.width as usize, p.height as usize);
    let s = 2 * p.tile;
    let s2 = s * s;
    // Background per pixel, separably: between tile rows once per tile column, then between
    // columns per pixel. The products distribute exactly, so these are background_at's values.
    let xs: Vec<(usize, usize, u32)> = (0..p.width)
        .map(|x| {
            let (tx, wx) = axis_weight(x, p.tile, p.tiles_x);
            (tx as usize, (tx + 1).min(p.tiles_x - 1) as usize, wx)
        })
        .collect();
    let mut col = vec![0u32; p.tiles_x as usize];
    let mut d = vec![0i32; w];
    let mut rows = vec![0i32; w * h];
    for y in 0..p.height {
        let (ty, wy) = axis_weight(y, p.tile, p.tiles_y);
        let ty1 = (ty + 1).min(p.tiles_y - 1);
        for (tx, c) in col.iter_mut().enumerate() {
            let a = tiles[(ty * p.tiles_x) as usize + tx].background;
            let b = tiles[(ty1 * p.tiles_x) as usize + tx].background;
            *c = (s - wy) * a + wy * b;
        }
        let row = &pixels[y as usize * w..][..w];
        for (x, &(t0, t1, wx)) in xs.iter().enumerate() {
            let bg = ((s - wx) * col[t0] + wx * col[t1] + s2 / 2) / s2;
            d[x] = row[x] as i32 - bg as i32;
        }
        let out = &mut rows[y as usize * w..][..w];
        for (x, o) in out.iter_mut().enumerate() {
            let at = |k: isize| d[(x as isize + k).clamp(0, w as isize - 1) as usize];
            *o = at(-2) + 4 * at(-1) + 6 * at(0) + 4 * at(1) + at(2);
        }
    }
    rows
}

/// Kernel `streak_filter`: the mask as words of 32 pixels in raster order (bit i of word k is
/// pixel 32k + i), set where Σ_j b_j · rows(x, y + j − 2) (rows clamped) exceeds the level of
/// the pixel's tile.
pub fn streak_filter(
    rows: &[i32],
    tiles: &[TileStats],
    p: &DetectParams,
    sp: &StreakParams,
) -> Vec<u32> {
    let (w, h) = (p.width as usize, p.height as usize);
    let mut words = vec![0u32; (w * h).div_ceil(32)];
    for y in 0..h {
        let r = |k: isize| &rows[(y as isize + k).clamp(0, h as isize - 1) as usize * w..][..w];
        let (r0, r1, r2, r3, r4) = (r(-2), r(-1), r(0), r(1), r(2));
        let tile_row = (y as u32 / p.tile * p.tiles_x) as usize;
        for x in 0..w {
            let sum = r0[x] + 4 * r1[x] + 6 * r2[x] + 4 * r3[x] + r4[x];
            let level = sp.level(tiles[tile_row + x / p.tile as usize].offset);
            if sum > level {
                let i = y * w + x;
                words[i / 32] |= 1 << (i % 32);
            }
        }
    }
    words
}

/// The mask words as runs in raster order, as `components` takes them.
pub fn mask_runs(words: &[u32], width: u32, height: u32) -> Vec<Run> {
    let mut runs = Vec::new();
    let w = width as usize;
    for y in 0..height as usize {
        let mut start: Option<u32> = None;
        for x in 0..w {
            let i = y * w + x;
            let set = words[i / 32] >> (i % 32) & 1 == 1;
            match (set, start) {
                (true, None) => start = Some(x as u32),
                (false, Some(x0)) => {
                    runs.push(Run {
                        y: y as u32,
                        x0,
                        x1: x as u32,
                    });
                    start = None;
                }
                _ => {}
            }
        }
        if let Some(x0) = start {
            runs.push(Run {
                y: y as u32,
                x0,
                x1: width,
            });
        }
    }
    runs
}
