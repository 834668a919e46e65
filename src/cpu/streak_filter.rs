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
    let w = p.width as usize;
    let mut r = RowSums::new(tiles, p);
    let mut rows = vec![0i32; w * p.height as usize];
    for (y, out) in rows.chunks_mut(w).enumerate() {
        r.row(pixels, y as u32, out);
    }
    rows
}

/// The row sums of `streak_rows`, one row at a time.
struct RowSums<'a> {
    tiles: &'a [TileStats],
    p: &'a DetectParams,
    /// Per column: lower and upper tile column and the weight of the upper.
    xs: Vec<(usize, usize, u32)>,
    /// The rounding division by s² as a shift, for the usual power-of-two tiles.
    shift: Option<u32>,
    col: Vec<u32>,
    /// A row's residuals with two clamped copies of the edge pixels on each side.
    d: Vec<i32>,
}

impl<'a> RowSums<'a> {
    fn new(tiles: &'a [TileStats], p: &'a DetectParams) -> Self {
        let s2 = 4 * p.tile * p.tile;
        RowSums {
            tiles,
            p,
            xs: (0..p.width)
                .map(|x| {
                    let (tx, wx) = axis_weight(x, p.tile, p.tiles_x);
                    (tx as usize, (tx + 1).min(p.tiles_x - 1) as usize, wx)
                })
                .collect(),
            shift: s2.is_power_of_two().then(|| s2.trailing_zeros()),
            col: vec![0; p.tiles_x as usize],
            d: vec![0; p.width as usize + 4],
        }
    }

    /// Row y's sums into `out`. The background per pixel is found separably: between tile
    /// rows once per tile column, then between columns per pixel; the products distribute
    /// exactly, so these are `background_at`'s values.
    fn row(&mut self, pixels: &[u16], y: u32, out: &mut [i32]) {
        let (p, w) = (self.p, self.p.width as usize);
        let s = 2 * p.tile;
        let s2 = s * s;
        let (ty, wy) = axis_weight(y, p.tile, p.tiles_y);
        let ty1 = (ty + 1).min(p.tiles_y - 1);
        for (tx, c) in self.col.iter_mut().enumerate() {
            let a = self.tiles[(ty * p.tiles_x) as usize + tx].background;
            let b = self.tiles[(ty1 * p.tiles_x) as usize + tx].background;
            *c = (s - wy) * a + wy * b;
        }
        let row = &pixels[y as usize * w..][..w];
        let d = &mut self.d;
        for (x, &(t0, t1, wx)) in self.xs.iter().enumerate() {
            let v = (s - wx) * self.col[t0] + wx * self.col[t1] + s2 / 2;
            let bg = match self.shift {
                Some(k) => v >> k,
                None => v / s2,
            };
            d[x + 2] = row[x] as i32 - bg as i32;
        }
        (d[0], d[1]) = (d[2], d[2]);
        (d[w + 2], d[w + 3]) = (d[w + 1], d[w + 1]);
        for (x, o) in out.iter_mut().enumerate() {
            let k = &d[x..x + 5];
            *o = k[0] + 4 * k[1] + 6 * k[2] + 4 * k[3] + k[4];
        }
    }
}

/// Both kernels at once, as the CPU backend runs them: the row sums are kept for five rows
/// only (a frame's worth would be written and read back once for nothing). The same mask as
/// `streak_filter(streak_rows(..))`.
pub fn streak_mask(
    pixels: &[u16],
    tiles: &[TileStats],
    p: &DetectParams,
    sp: &StreakParams,
) -> Vec<u32> {
    let (w, h) = (p.width as usize, p.height as usize);
    let mut sums = RowSums::new(tiles, p);
    let mut ring = vec![0i32; 5 * w];
    let mut words = vec![0u32; (w * h).div_ceil(32)];
    let mut filled: Option<usize> = None;
    for y in 0..h {
        // Rows y − 2 … y + 2 (clamped) in the ring, at slot row % 5.
        let want = (y + 2).min(h - 1);
        let from = filled.map_or(0, |f| f + 1);
        for r in from..=want {
            sums.row(pixels, r as u32, &mut ring[(r % 5) * w..][..w]);
        }
        filled = Some(want);
        let at = |k: isize| {
            let r = (y as isize + k).clamp(0, h as isize - 1) as usize;
            &ring[(r % 5) * w..][..w]
        };
        filter_row(
            y,
            [at(-2), at(-1), at(0), at(1), at(2)],
            tiles,
            p,
            sp,
            &mut words,
        );
    }
    words
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
        filter_row(
            y,
            [r(-2), r(-1), r(0), r(1), r(2)],
            tiles,
            p,
            sp,
            &mut words,
        );
    }
    words
}

/// Row y of the mask from the row sums of rows y − 2 … y + 2.
fn filter_row(
    y: usize,
    r: [&[i32]; 5],
    tiles: &[TileStats],
    p: &DetectParams,
    sp: &StreakParams,
    words: &mut [u32],
) {
    let (w, tile) = (p.width as usize, p.tile as usize);
    let tile_row = (y / tile) * p.tiles_x as usize;
    for (tx, x0) in (0..w).step_by(tile).enumerate() {
        let level = sp.level(tiles[tile_row + tx].offset);
        let x1 = (x0 + tile).min(w);
        let cols = r[0][x0..x1]
            .iter()
            .zip(&r[1][x0..x1])
            .zip(&r[2][x0..x1])
            .zip(&r[3][x0..x1])
            .zip(&r[4][x0..x1]);
        for (k, ((((a, b), c), d), e)) in cols.enumerate() {
            if a + 4 * b + 6 * c + 4 * d + e > level {
                let i = y * w + x0 + k;
                words[i / 32] |= 1 << (i % 32);
            }
        }
    }
}

/// The mask words as runs in raster order, as `components` takes them.
pub fn mask_runs(words: &[u32], width: u32, height: u32) -> Vec<Run> {
    let mut runs = Vec::new();
    let w = width as usize;
    for y in 0..height as usize {
        let mut start: Option<u32> = None;
        let mut x = 0;
        while x < w {
            let i = y * w + x;
            // Most of the frame is empty: step over whole empty words.
            if start.is_none() && i.is_multiple_of(32) && words[i / 32] == 0 {
                x += 32;
                continue;
            }
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
            x += 1;
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
