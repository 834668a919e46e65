//! Stage `streak_filter`: the streak mask, in two kernels, on the frame binned 2×2.
//!
//! `streak_rows` sums each 2×2 block of pixels less four times the local background at its
//! first pixel (the tiles of stage `threshold`, interpolated in integers exactly as
//! `threshold::background_at`) and sums each block's row neighbours with the binomial weights
//! 1 4 6 4 1; `streak_filter` sums five of those row sums down the column with the same weights
//! and sets a mask bit where the result exceeds k_streak noise sigmas of the smoothed image.
//! Binning keeps a streak (its profile is σ ≈ 1–1.5 px, long along the track) and quarters the
//! work; the 5×5 kernel on the blocks is a Gaussian of σ ≈ 2 px, and a streak of PSF σ 1.2 px
//! comes out about 3.6 times its per-pixel SNR (peak 0.5 of the profile's, noise 0.14 of a
//! pixel's): a streak of peak SNR 3 stands at about 11 sigmas and stays connected. Stars stay
//! compact. Everything is integer arithmetic: the GPU twins (`shaders/streak_rows.wgsl`,
//! `shaders/streak_filter.wgsl`) give the same bits.

use super::threshold::{DetectParams, Run, TileStats, axis_weight};
use bytemuck::{Pod, Zeroable};

/// The binomial weights of one axis (sum 16; Σw² = 70).
pub const BINOMIAL: [i32; 5] = [1, 4, 6, 4, 1];

/// Noise of the smoothed sum in pixel sigmas: a block of four pixels has 2σ, and
/// sqrt(Σ_ij (b_i b_j)²) = 70 of them add up, so 140σ.
pub const SMOOTHED_NOISE: f32 = 140.0;

/// Side of the blocks the mask is made of (pixels).
pub const BIN: u32 = 2;

/// The binned grid of a `p`-sized frame: blocks across and down (the frame's size halved,
/// rounded down: an odd last column or row is left out).
pub fn grid(p: &DetectParams) -> (u32, u32) {
    ((p.width / BIN).max(1), (p.height / BIN).max(1))
}

/// Parameters of the streak mask. Keep in sync with `shaders/shared/streak.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct StreakParams {
    /// A block is set where its smoothed sum exceeds `offset · level_num / level_den`, with
    /// `offset` the detection offset (k_sigma noise sigmas) of its first pixel's tile:
    /// k_streak · 140 · σ.
    pub level_num: u32,
    pub level_den: u32,
    /// The binned grid ([`grid`]) and its mask words (32 blocks each) per frame.
    pub width: u32,
    pub height: u32,
    pub words: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

impl StreakParams {
    /// The mask of a `p`-sized frame at `k_streak` noise sigmas of the smoothed image, for
    /// tiles made with the detection threshold `k_sigma` (the tiles carry
    /// `ceil(k_sigma · 1.4826 · MAD)` as their offset).
    pub fn new(p: &DetectParams, k_streak: f32, k_sigma: f32) -> StreakParams {
        const DEN: u32 = 16;
        // offset ≤ 2^19 (k_sigma · 1.4826 · 65535 for k_sigma ≤ 5.4); the product must fit
        // u32, so the ratio is capped at 2^12 / 16 = 256 (k_streak/k_sigma ≤ 1.8).
        let ratio = (k_streak * SMOOTHED_NOISE / k_sigma.max(0.1)).clamp(0.0, 256.0);
        let (width, height) = grid(p);
        StreakParams {
            level_num: ((ratio * DEN as f32).round() as u32).clamp(1, 4096),
            level_den: DEN,
            width,
            height,
            words: (width * height).div_ceil(32),
            _pad0: 0,
            _pad1: 0,
            _pad2: 0,
        }
    }

    /// The level the smoothed sum must exceed in a tile with this detection offset.
    #[inline]
    pub fn level(&self, offset: u32) -> i32 {
        (offset.min(1 << 19) * self.level_num / self.level_den) as i32
    }
}

/// Kernel `streak_rows`: per block, Σ_i b_i · (block − 4 · background) over the row
/// neighbours x − 2 … x + 2 (clamped at the grid's edges).
pub fn streak_rows(
    pixels: &[u16],
    tiles: &[TileStats],
    p: &DetectParams,
    sp: &StreakParams,
) -> Vec<i32> {
    let w = sp.width as usize;
    let mut r = RowSums::new(tiles, p, sp);
    let mut rows = vec![0i32; w * sp.height as usize];
    for (y, out) in rows.chunks_mut(w).enumerate() {
        r.row(pixels, y as u32, out);
    }
    rows
}

/// The row sums of `streak_rows`, one row of blocks at a time.
struct RowSums<'a> {
    tiles: &'a [TileStats],
    p: &'a DetectParams,
    /// Per block column: lower and upper tile column and the weight of the upper, at the
    /// block's first pixel.
    xs: Vec<(usize, usize, u32)>,
    /// The rounding division by s² as a shift, for the usual power-of-two tiles.
    shift: Option<u32>,
    col: Vec<u32>,
    /// A row's residuals with two clamped copies of the edge blocks on each side.
    d: Vec<i32>,
}

impl<'a> RowSums<'a> {
    fn new(tiles: &'a [TileStats], p: &'a DetectParams, sp: &StreakParams) -> Self {
        let s2 = 4 * p.tile * p.tile;
        RowSums {
            tiles,
            p,
            xs: (0..sp.width)
                .map(|xb| {
                    let (tx, wx) = axis_weight(BIN * xb, p.tile, p.tiles_x);
                    (tx as usize, (tx + 1).min(p.tiles_x - 1) as usize, wx)
                })
                .collect(),
            shift: s2.is_power_of_two().then(|| s2.trailing_zeros()),
            col: vec![0; p.tiles_x as usize],
            d: vec![0; sp.width as usize + 4],
        }
    }

    /// Block row yb's sums into `out`. The background at each block's first pixel is found
    /// separably: between tile rows once per tile column, then between columns per block; the
    /// products distribute exactly, so these are `background_at`'s values.
    fn row(&mut self, pixels: &[u16], yb: u32, out: &mut [i32]) {
        let (p, w) = (self.p, self.p.width as usize);
        let s = 2 * p.tile;
        let s2 = s * s;
        let y = BIN * yb;
        let (ty, wy) = axis_weight(y, p.tile, p.tiles_y);
        let ty1 = (ty + 1).min(p.tiles_y - 1);
        for (tx, c) in self.col.iter_mut().enumerate() {
            let a = self.tiles[(ty * p.tiles_x) as usize + tx].background;
            let b = self.tiles[(ty1 * p.tiles_x) as usize + tx].background;
            *c = (s - wy) * a + wy * b;
        }
        let (r0, r1) = (
            &pixels[y as usize * w..][..w],
            &pixels[(y as usize + 1) * w..][..w],
        );
        let d = &mut self.d;
        let n = out.len();
        for (xb, &(t0, t1, wx)) in self.xs.iter().enumerate() {
            let v = (s - wx) * self.col[t0] + wx * self.col[t1] + s2 / 2;
            let bg = match self.shift {
                Some(k) => v >> k,
                None => v / s2,
            };
            let x = 2 * xb;
            let block = r0[x] as i32 + r0[x + 1] as i32 + r1[x] as i32 + r1[x + 1] as i32;
            d[xb + 2] = block - 4 * bg as i32;
        }
        (d[0], d[1]) = (d[2], d[2]);
        (d[n + 2], d[n + 3]) = (d[n + 1], d[n + 1]);
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
    let (w, h) = (sp.width as usize, sp.height as usize);
    let mut sums = RowSums::new(tiles, p, sp);
    let mut ring = vec![0i32; 5 * w];
    let mut words = vec![0u32; sp.words as usize];
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

/// Kernel `streak_filter`: the mask as words of 32 blocks in raster order of the binned grid
/// (bit i of word k is block 32k + i), set where Σ_j b_j · rows(x, y + j − 2) (rows clamped)
/// exceeds the level of the block's first pixel's tile.
pub fn streak_filter(
    rows: &[i32],
    tiles: &[TileStats],
    p: &DetectParams,
    sp: &StreakParams,
) -> Vec<u32> {
    let (w, h) = (sp.width as usize, sp.height as usize);
    let mut words = vec![0u32; sp.words as usize];
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
    let (w, tile) = (sp.width as usize, p.tile as usize);
    let tile_row = (BIN as usize * y / tile) * p.tiles_x as usize;
    for tx in 0..p.tiles_x as usize {
        // The blocks whose first pixel, column 2·xb, lies in tile column tx.
        let (x0, x1) = (
            (tx * tile).div_ceil(2).min(w),
            ((tx + 1) * tile).div_ceil(2).min(w),
        );
        let level = sp.level(tiles[tile_row + tx].offset);
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
