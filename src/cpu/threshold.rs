//! Stage `threshold`: local background and noise per tile, and the k·σ mask.
//!
//! Background = the median of a tile, noise = 1.4826 · MAD of the tile (robust to the stars in
//! it; both from every other row; a MAD of a few counts read from the grouped deviations, see
//! [`noise_offset`]); both are interpolated bilinearly between tile centres, so gradients and
//! vignetting do not leave steps at tile edges. Everything after the per-tile `offset` is
//! integer arithmetic, so the GPU twin reproduces the mask bit for bit.
//!
//! About 700 lines: the CPU twins of both threshold kernels (the pixel and the matched filter)
//! and the filter's noise gain share the tile levels and their interpolation, kept in one place.

use bytemuck::{Pod, Zeroable};

/// Parameters of the detection stages. Keep in sync with `shaders/shared/detect.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct DetectParams {
    pub width: u32,
    pub height: u32,
    /// Tile side in pixels (4..=64: the interpolation weights fit u32 up to 64).
    pub tile: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// Pixels at or above this value are saturated.
    pub saturation: u32,
    /// k · 1.4826, where k is the threshold in noise sigmas: offset = ceil(k_mad · MAD).
    pub k_mad: f32,
    /// [`FILTER_NONE`], or the matched filter's noise gain ([`WHITE_GAIN`] to [`MAX_GAIN`]):
    /// the threshold applies to the frame smoothed by the matched filter (see
    /// [`threshold_filtered`]), at the tile's offset times this gain (1/16 ADU).
    pub matched: u32,
}

/// The mask compares each pixel with its level.
pub const FILTER_NONE: u32 = 0;
/// The matched filter's gain for white noise: the 3×3 binomial ([1 2 1]ᵀ[1 2 1], weights
/// summing to 16) multiplies its σ by √(Σw²) = 6 in 1/16 ADU.
pub const WHITE_GAIN: u32 = 6;
/// ... and for noise alike over the 3×3 (Σw = 16): the largest gain, which keeps every level
/// below 2²⁵ (see [`filtered_level_at`]).
pub const MAX_GAIN: u32 = 16;

impl DetectParams {
    pub fn new(width: u32, height: u32, tile: u32, k_sigma: f32, saturation: u32) -> Self {
        let tile = tile.clamp(4, 64);
        DetectParams {
            width,
            height,
            tile,
            tiles_x: width.div_ceil(tile),
            tiles_y: height.div_ceil(tile),
            saturation,
            k_mad: k_sigma * 1.4826,
            matched: FILTER_NONE,
        }
    }

    /// The same with the matched filter on (for white noise) or off.
    pub fn with_filter(self, on: bool) -> Self {
        self.with_filter_gain(if on { WHITE_GAIN } else { FILTER_NONE })
    }

    /// The same with the matched filter at `gain` ([`filter_gain`]; [`FILTER_NONE`]: off).
    pub fn with_filter_gain(self, gain: u32) -> Self {
        DetectParams {
            matched: if gain == FILTER_NONE {
                FILTER_NONE
            } else {
                gain.clamp(WHITE_GAIN, MAX_GAIN)
            },
            ..self
        }
    }
}

/// Background and threshold offset of one tile. Keep in sync with `shaders/shared/detect.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct TileStats {
    /// Median pixel value.
    pub background: u32,
    /// ceil(k · 1.4826 · max(MAD, 1)), the MAD grouped when small ([`noise_offset`]): how far
    /// above the background a pixel must be.
    pub offset: u32,
}

/// MADs of up to this many counts are read from the grouped deviations ([`noise_offset`]):
/// there, whole counts put the MAD up to an eighth of it or more off; above, less than its own
/// scatter over a tile's 512 values.
pub const GROUPED_MAD_MAX: u32 = 4;

/// The tile's offset, ceil(k_mad · m), from its MAD `mad` (the deviation of rank `rank`),
/// with `below` deviations under it and `at` equal to it. Pixel values are whole counts, and
/// with noise of a count or two (8-bit frames) the MAD takes one of a few values: 8-bit JPEGs
/// whose noise is 2.1 counts have a MAD of 1 in nine tiles of ten, so a 5σ threshold stood at
/// 3.7σ and put a few noise pairs into every frame. For MADs of 1 to [`GROUPED_MAD_MAX`], m
/// is therefore the grouped median, each deviation d spread evenly over [d − ½, d + ½):
/// m = mad − ½ + (rank + ½ − below) / at, at least 1 as before. Exact in integers and
/// products of f32 that are exact (both twins, bit for bit): the least o with
/// o · 2at ≥ fl(k_mad · ((2·mad − 1)·at + 2(rank − below) + 1)).
pub fn noise_offset(k_mad: f32, mad: u32, below: u32, at: u32, rank: u32) -> u32 {
    let whole = |m: u32| (k_mad * m.max(1) as f32).ceil() as u32;
    if mad == 0 || mad > GROUPED_MAD_MAX || at == 0 {
        return whole(mad);
    }
    let num = (2 * mad - 1) * at + 2 * (rank - below) + 1;
    let den = 2 * at;
    if num <= den {
        return whole(1);
    }
    let t = k_mad * num as f32;
    let mut o = (t / den as f32).ceil() as u32;
    while (o as f32) * (den as f32) < t {
        o += 1;
    }
    while o > 0 && ((o - 1) as f32) * (den as f32) >= t {
        o -= 1;
    }
    o
}

/// Per-tile median and MAD (lower medians: element (n−1)/2 of the sorted values) of the
/// tile's even rows (rows y0, y0 + 2, ...).
pub fn tile_stats(pixels: &[u16], p: &DetectParams) -> Vec<TileStats> {
    crate::simd::fast!(tile_stats_in(pixels: &[u16], p: &DetectParams) -> Vec<TileStats>)
}

/// [`tile_stats`], compiled where it is inlined (see [`crate::simd`]).
#[inline(always)]
fn tile_stats_in(pixels: &[u16], p: &DetectParams) -> Vec<TileStats> {
    let mut out = Vec::with_capacity((p.tiles_x * p.tiles_y) as usize);
    let mut vals: Vec<u16> = Vec::with_capacity((p.tile * p.tile) as usize);
    // Where each search starts: the tile before in the row, or the row above's first tile at
    // a row's start (neighbouring sky tiles differ by a value or two).
    let (mut guess, mut row_first) = ((0u16, 0u16), (0u16, 0u16));
    for ty in 0..p.tiles_y {
        for tx in 0..p.tiles_x {
            let (x0, y0) = (tx * p.tile, ty * p.tile);
            let (x1, y1) = ((x0 + p.tile).min(p.width), (y0 + p.tile).min(p.height));
            vals.clear();
            // Every other row of the tile: half the work, and a median and MAD of hundreds of
            // pixels are as good as of a thousand.
            for y in (y0..y1).step_by(2) {
                let row = (y * p.width) as usize;
                let r = &pixels[row + x0 as usize..row + x1 as usize];
                // A row of the default tile side is copied inline, not by a call.
                match <&[u16; 32]>::try_from(r) {
                    Ok(r) => vals.extend_from_slice(r),
                    Err(_) => vals.extend_from_slice(r),
                }
            }
            if tx == 0 {
                guess = row_first;
            }
            let (median, mad) = median_mad(&mut vals, guess);
            guess = (median, mad);
            if tx == 0 {
                row_first = guess;
            }
            let mad = u32::from(mad);
            let rank = (vals.len() as u32 - 1) / 2;
            // `vals` holds the deviations now; their counts about a small MAD.
            let (below, at) = match mad {
                1..=GROUPED_MAD_MAX => {
                    let below = count_at_most(&vals, (mad - 1) as u16) as u32;
                    (below, count_at_most(&vals, mad as u16) as u32 - below)
                }
                _ => (0, 0),
            };
            out.push(TileStats {
                background: median as u32,
                offset: noise_offset(p.k_mad, mad, below, at, rank),
            });
        }
    }
    out
}

/// Median and MAD (lower medians) of `v`, each searched for by counting from its `guess`;
/// `v` is left holding the deviations.
#[inline(always)]
fn median_mad(v: &mut [u16], guess: (u16, u16)) -> (u16, u16) {
    let rank = (v.len() - 1) / 2;
    let median = value_of_rank(v, rank, guess.0);
    for x in v.iter_mut() {
        *x = x.abs_diff(median);
    }
    (median, value_of_rank(v, rank, guess.1))
}

/// The value of rank `rank` in `v` (0 = the least): the least t with more than `rank` values
/// at or below it. Counted, not sorted or binned: each count is a pass of vector compares (a
/// histogram's scattered increments cost more), stepping outward from `guess` in doubling
/// steps until the value is bracketed, then halving the bracket; two passes when the guess is
/// right.
#[inline(always)]
fn value_of_rank(v: &[u16], rank: usize, guess: u16) -> u16 {
    let above = |t: i32| count_at_most(v, t as u16) > rank;
    // The value lies in (lo, hi]: lo = −1 is below every value, and u16::MAX has them all.
    let g = i32::from(guess);
    let (mut lo, mut hi) = (-1, i32::from(u16::MAX));
    let mut step = 1;
    if above(g) {
        hi = g;
        while g - step >= 0 {
            if !above(g - step) {
                lo = g - step;
                break;
            }
            hi = g - step;
            step *= 2;
        }
    } else {
        lo = g;
        while g + step < hi {
            if above(g + step) {
                hi = g + step;
                break;
            }
            lo = g + step;
            step *= 2;
        }
    }
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if above(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi as u16
}

/// How many of `v` are at most `t`: 16-bit counts per chunk, so that the compares stay 16
/// lanes wide.
#[inline(always)]
fn count_at_most(v: &[u16], t: u16) -> usize {
    v.chunks(u16::MAX as usize)
        .map(|c| c.iter().fold(0u16, |n, &x| n + u16::from(x <= t)) as usize)
        .sum()
}

/// Bilinear position of coordinate `x` among the tile centres of one axis: the lower tile and
/// the weight of the upper one, in units of 1/(2·tile). Centres sit at `t·tile + (tile−1)/2`;
/// doubling the coordinates keeps everything integer.
#[inline]
pub fn axis_weight(x: u32, tile: u32, tiles: u32) -> (u32, u32) {
    let off = 2 * x as i64 - (tile as i64 - 1);
    if off <= 0 {
        return (0, 0);
    }
    let t0 = (off / (2 * tile as i64)) as u32;
    if t0 + 1 >= tiles {
        return (tiles - 1, 0);
    }
    (t0, (off % (2 * tile as i64)) as u32)
}

/// A tile quantity interpolated at pixel (x, y), scaled by (2·tile)².
#[inline]
pub fn interpolate(
    tiles: &[TileStats],
    p: &DetectParams,
    x: u32,
    y: u32,
    f: impl Fn(&TileStats) -> u32,
) -> u32 {
    let (tx, wx) = axis_weight(x, p.tile, p.tiles_x);
    let (ty, wy) = axis_weight(y, p.tile, p.tiles_y);
    let s = 2 * p.tile;
    let tx1 = (tx + 1).min(p.tiles_x - 1);
    let ty1 = (ty + 1).min(p.tiles_y - 1);
    let at = |tx: u32, ty: u32| f(&tiles[(ty * p.tiles_x + tx) as usize]);
    (s - wx) * (s - wy) * at(tx, ty)
        + wx * (s - wy) * at(tx1, ty)
        + (s - wx) * wy * at(tx, ty1)
        + wx * wy * at(tx1, ty1)
}

/// The level a pixel must exceed, scaled by (2·tile)². Capped at 65536 per tile so the
/// products stay inside u32 (no u16 pixel can exceed the cap anyway).
#[inline]
pub fn level_scaled(tiles: &[TileStats], p: &DetectParams, x: u32, y: u32) -> u32 {
    interpolate(tiles, p, x, y, |t| (t.background + t.offset).min(65536))
}

/// Background at a pixel, rounded to an integer.
#[inline]
pub fn background_at(tiles: &[TileStats], p: &DetectParams, x: u32, y: u32) -> u32 {
    let s2 = 4 * p.tile * p.tile;
    (interpolate(tiles, p, x, y, |t| t.background) + s2 / 2) / s2
}

/// A run of consecutive mask pixels in one row: columns `x0..x1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Run {
    pub y: u32,
    pub x0: u32,
    pub x1: u32,
}

/// The mask, `pixel > background + offset` (both interpolated), as runs in raster order.
/// The GPU writes the same mask densely; [`dense_mask`] converts for comparison.
///
/// Per row, the level is interpolated between tile rows once per tile column, then between
/// columns per pixel: the same integers as `level_scaled`, since the products distribute
/// exactly. Between two tile centres the level is at least `s · min` of the two column levels
/// (a convex combination), so pixels at or below that bound are passed over without computing
/// their level: most of a star field is.
pub fn threshold(pixels: &[u16], tiles: &[TileStats], p: &DetectParams) -> Vec<Run> {
    crate::simd::fast!(threshold_in(pixels: &[u16], tiles: &[TileStats], p: &DetectParams) -> Vec<Run>)
}

/// [`threshold`], compiled where it is inlined (see [`crate::simd`]).
#[inline(always)]
fn threshold_in(pixels: &[u16], tiles: &[TileStats], p: &DetectParams) -> Vec<Run> {
    if p.matched != FILTER_NONE {
        return threshold_filtered_in(pixels, tiles, p);
    }
    scan(pixels, tiles, p, &Plain::new(p))
}

/// What [`scan`] compares against: a tile's level, its interpolation between tile rows, a
/// floor under the pixels' levels between two tile columns, the comparison of one pixel, and
/// of a whole block. Methods, not closures, so that they are compiled into the AVX2 copy with
/// the scan (a closure the compiler kept out of line was built for the baseline only).
trait Rule {
    fn tile_level(&self, t: &TileStats) -> u32;
    fn between_rows(&self, a: u32, b: u32, wy: u32) -> u32;
    fn floor(&self, c0: u32, c1: u32) -> u16;
    fn set(&self, x: u32, y: u32, v: u16, wx: u32, c0: u32, c1: u32) -> bool;
    fn quiet(&self, row: &[u16], x: usize, y: u32, floor: u16) -> bool;
}

/// The plain mask: `pixel · (2·tile)² > level_scaled`.
struct Plain {
    /// Twice the tile side (the interpolation weights' denominator), and its square.
    s: u32,
    s2: u32,
}

impl Plain {
    fn new(p: &DetectParams) -> Plain {
        let s = 2 * p.tile;
        Plain { s, s2: s * s }
    }
}

impl Rule for Plain {
    #[inline(always)]
    fn tile_level(&self, t: &TileStats) -> u32 {
        (t.background + t.offset).min(65536)
    }
    #[inline(always)]
    fn between_rows(&self, a: u32, b: u32, wy: u32) -> u32 {
        (self.s - wy) * a + wy * b
    }
    /// Pixels at or below this are below every level between the two columns.
    #[inline(always)]
    fn floor(&self, c0: u32, c1: u32) -> u16 {
        (self.s * c0.min(c1) / self.s2).min(65535) as u16
    }
    #[inline(always)]
    fn set(&self, _: u32, _: u32, v: u16, wx: u32, c0: u32, c1: u32) -> bool {
        v as u32 * self.s2 > (self.s - wx) * c0 + wx * c1
    }
    #[inline(always)]
    fn quiet(&self, row: &[u16], x: usize, _: u32, floor: u16) -> bool {
        !block_above(row, x, floor)
    }
}

/// The mask's runs, row by row ([`Rule`]): `tile_level` of the tiles interpolated between tile
/// rows by `between_rows(upper, lower, wy)` for each tile column; within each segment of
/// columns that share a pair of tile columns (levels c0, c1), pixels at or below
/// `floor(c0, c1)` cannot be set; `set(x, y, pixel, wx, c0, c1)` decides the others.
///
/// Most of a star field is passed over [`BLOCK`] columns at a time, without computing the
/// row's levels: between two tile rows a column's level is at least `between_rows(m, m, ·)`,
/// m the least level of its four tiles (both interpolations are convex combinations), so a
/// block whose pixels are all at or below the least such floor of the segments it meets holds
/// no set pixel. That floor is taken once per pair of tile rows. A block above it is tested
/// again against the row's own floors, and only then pixel by pixel. (So `between_rows` must
/// not fall as either level rises, and give `m` the same level at every `wy`: both callers'
/// do; `tests/it/threshold.rs` holds the runs to the per-pixel definition.) `quiet(row, x, y,
/// f)` says whether the whole block at column x of row y holds no set pixel when every
/// pixel's floor is at least f: at the least, when no pixel is above f ([`block_above`]).
#[inline(always)]
fn scan(pixels: &[u16], tiles: &[TileStats], p: &DetectParams, rule: &impl Rule) -> Vec<Run> {
    let w = p.width as usize;
    // Segments of columns with the same pair of tile columns (lower, upper), the segment of
    // each column, and its weight between the two.
    let mut segments: Vec<(usize, usize)> = Vec::new();
    let mut segment_of = Vec::with_capacity(w);
    let mut weights = Vec::with_capacity(w);
    for x in 0..p.width {
        let (tx, wx) = axis_weight(x, p.tile, p.tiles_x);
        let pair = (tx as usize, (tx + 1).min(p.tiles_x - 1) as usize);
        if segments.last() != Some(&pair) {
            segments.push(pair);
        }
        segment_of.push(segments.len() as u32 - 1);
        weights.push(wx);
    }
    let mut ends = vec![0; segments.len()];
    for (x, &s) in segment_of.iter().enumerate() {
        ends[s as usize] = x + 1;
    }
    // The segments each block of columns meets (first, last).
    let blocks: Vec<(usize, usize)> = (0..w.div_ceil(BLOCK))
        .map(|b| {
            let (x0, x1) = (b * BLOCK, ((b + 1) * BLOCK).min(w) - 1);
            (segment_of[x0] as usize, segment_of[x1] as usize)
        })
        .collect();
    let least =
        |f: &[u16], (s0, s1): (usize, usize)| f[s0..=s1].iter().fold(u16::MAX, |m, &v| m.min(v));
    let full = w / BLOCK * BLOCK;
    let level_at = |tx: usize, ty: u32| rule.tile_level(&tiles[(ty * p.tiles_x) as usize + tx]);
    let mut band = None;
    let mut band_floors = vec![0u16; segments.len()];
    let mut band_block_floors = vec![0u16; blocks.len()];
    let mut col_level = vec![0u32; p.tiles_x as usize];
    let mut levels = vec![(0u32, 0u32); segments.len()];
    let mut floors = vec![0u16; segments.len()];
    let mut runs = Vec::new();
    for y in 0..p.height {
        let (ty, wy) = axis_weight(y, p.tile, p.tiles_y);
        let ty1 = (ty + 1).min(p.tiles_y - 1);
        if band != Some(ty) {
            for (f, &(t0, t1)) in band_floors.iter_mut().zip(&segments) {
                let m = [(t0, ty), (t1, ty), (t0, ty1), (t1, ty1)]
                    .map(|(tx, ty)| level_at(tx, ty))
                    .into_iter()
                    .fold(u32::MAX, u32::min);
                let c = rule.between_rows(m, m, 0);
                *f = rule.floor(c, c);
            }
            for (f, &b) in band_block_floors.iter_mut().zip(&blocks) {
                *f = least(&band_floors, b);
            }
            band = Some(ty);
        }
        let row = &pixels[y as usize * w..(y as usize + 1) * w];
        let mut row_ready = false;
        let mut start: Option<u32> = None;
        let mut x = 0;
        while x < w {
            if start.is_none() && x % BLOCK == 0 {
                // A loop, not an iterator adapter: it stays inlined in the AVX2 copy.
                while x < full && rule.quiet(row, x, y, band_block_floors[x / BLOCK]) {
                    x += BLOCK;
                }
                if x == w {
                    break;
                }
            }
            if !row_ready {
                for (tx, c) in col_level.iter_mut().enumerate() {
                    *c = rule.between_rows(level_at(tx, ty), level_at(tx, ty1), wy);
                }
                for (i, &(t0, t1)) in segments.iter().enumerate() {
                    levels[i] = (col_level[t0], col_level[t1]);
                    floors[i] = rule.floor(col_level[t0], col_level[t1]);
                }
                row_ready = true;
            }
            if start.is_none()
                && x % BLOCK == 0
                && x < full
                && rule.quiet(row, x, y, least(&floors, blocks[x / BLOCK]))
            {
                x += BLOCK;
                continue;
            }
            let segment = segment_of[x] as usize;
            if start.is_none() {
                // To the first pixel above the floor, in this segment and block.
                let end = ends[segment].min((x / BLOCK + 1) * BLOCK);
                match row[x..end].iter().position(|&v| v > floors[segment]) {
                    Some(k) => x += k,
                    None => {
                        x = end;
                        continue;
                    }
                }
            }
            let (c0, c1) = levels[segment];
            match (rule.set(x as u32, y, row[x], weights[x], c0, c1), start) {
                (true, None) => start = Some(x as u32),
                (false, Some(r0)) => {
                    runs.push(Run {
                        y,
                        x0: r0,
                        x1: x as u32,
                    });
                    start = None;
                }
                _ => {}
            }
            x += 1;
        }
        if let Some(x0) = start {
            runs.push(Run { y, x0, x1: p.width });
        }
    }
    runs
}

/// The columns [`scan`] passes over at a time: 32 u16, two AVX2 registers.
const BLOCK: usize = 32;

/// Whether any pixel of the block at column `x` of `row` (the block whole) is above `floor`:
/// their saturating excesses OR-ed, without a branch per pixel.
#[inline(always)]
fn block_above(row: &[u16], x: usize, floor: u16) -> bool {
    let block: &[u16; BLOCK] = row[x..x + BLOCK].try_into().expect("BLOCK pixels");
    block.iter().fold(0, |m, &v| m | v.saturating_sub(floor)) != 0
}

/// Whether any 3×3 binomial sum ([`binomial3`]) of the block at column `x` of row `y` is above
/// `16 · floor`; true (cannot tell) for a block on the frame's edge, where the sums repeat
/// edge pixels. Sums of columns first, then along the row, in u32 lanes the compiler
/// vectorises.
#[inline(always)]
fn block_binomial_above(pixels: &[u16], p: &DetectParams, x: usize, y: u32, floor: u16) -> bool {
    let (w, h) = (p.width as usize, p.height as usize);
    let y = y as usize;
    if x == 0 || x + BLOCK >= w || y == 0 || y + 1 >= h {
        return true;
    }
    let row = |y: usize| -> &[u16; BLOCK + 2] {
        let start = y * w + x - 1;
        pixels[start..start + BLOCK + 2]
            .try_into()
            .expect("BLOCK + 2 pixels")
    };
    let (up, mid, down) = (row(y - 1), row(y), row(y + 1));
    let cols: [u32; BLOCK + 2] =
        std::array::from_fn(|t| up[t] as u32 + 2 * mid[t] as u32 + down[t] as u32);
    let limit = 16 * floor as u32;
    (0..BLOCK).fold(0, |m, t| {
        m | (cols[t] + 2 * cols[t + 1] + cols[t + 2]).saturating_sub(limit)
    }) != 0
}

/// A tile's level for the matched filter, in 1/16 ADU: 16 · background + gain · offset. The
/// 3×3 binomial multiplies the noise's σ by the gain in the same units ([`WHITE_GAIN`] for
/// white noise, more where neighbours correlate, [`filter_gain`]): the offset of k raw sigmas
/// becomes k sigmas of the smoothed frame.
#[inline]
pub fn filtered_tile_level(t: &TileStats, gain: u32) -> u32 {
    16 * t.background + gain * t.offset.min(1 << 20)
}

/// The matched filter's noise gain for a frame: the σ of its 3×3 binomial sums over the σ of
/// its pixels, rounded, from [`WHITE_GAIN`] to [`MAX_GAIN`]. Each σ is the MAD of differences
/// 4 px apart along the rows (a sky's level and gradients cancel; stars are few of them; the
/// sums 4 px apart share no pixel, so their differences hold twice the sums' variance as the
/// pixels' do theirs): those of consecutive samples every 4th column of every 16th row, the
/// MAD of whole counts read as the median of grouped data as in [`noise_offset`]. White noise
/// gives 6.0; JPEG's (q 90 on docs/speed.md's f8 set) 9–10: at 6 the filter's threshold stood
/// near 3σ of its own noise and passed noise as stars (docs/speed.md, "The matched filter's
/// noise, measured"). Computed on the CPU for either backend, from the pixels alone.
pub fn filter_gain(pixels: &[u16], width: u32, height: u32) -> u32 {
    const LAG: u32 = 4;
    if width < 2 + LAG + 2 || height < 3 {
        return WHITE_GAIN;
    }
    let (mut raw, mut sums) = (Vec::new(), Vec::new());
    for y in (1..height - 1).step_by(16) {
        let row = (y * width) as usize;
        // Each sample once: (pixel, binomial sum) at x = 1, 1 + LAG, ... ≤ width − 2.
        let samples: Vec<(u16, u32)> = (1..width - 1)
            .step_by(LAG as usize)
            .map(|x| {
                (
                    pixels[row + x as usize],
                    binomial3(pixels, width, height, x, y),
                )
            })
            .collect();
        for pair in samples.windows(2) {
            raw.push(u32::from(pair[0].0.abs_diff(pair[1].0)));
            sums.push(pair[0].1.abs_diff(pair[1].1));
        }
    }
    let (r, s) = (grouped_median(&mut raw), grouped_median(&mut sums));
    if r < 0.5 {
        return WHITE_GAIN;
    }
    ((s / r).round() as u32).clamp(WHITE_GAIN, MAX_GAIN)
}

/// The median of whole numbers read as grouped data: m − ½ + (n/2 − below)/at, where `at`
/// values equal the median m and `below` are less.
fn grouped_median(v: &mut [u32]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let half = v.len() / 2;
    let (_, &mut m, _) = v.select_nth_unstable(half);
    let below = v.iter().filter(|&&x| x < m).count();
    let at = v.iter().filter(|&&x| x == m).count();
    f64::from(m) - 0.5 + (v.len() as f64 / 2.0 - below as f64) / at as f64
}

/// The matched filter's level at (x, y), in 1/16 ADU: interpolated between tile rows, floored,
/// then between tile columns, floored (so that every product fits u32: levels below
/// 16 · 2^16 + 16 · 2^20 < 2^25 times weights ≤ 128).
#[inline]
pub fn filtered_level_at(tiles: &[TileStats], p: &DetectParams, x: u32, y: u32) -> u32 {
    let (tx, wx) = axis_weight(x, p.tile, p.tiles_x);
    let (ty, wy) = axis_weight(y, p.tile, p.tiles_y);
    let s = 2 * p.tile;
    let tx1 = (tx + 1).min(p.tiles_x - 1);
    let ty1 = (ty + 1).min(p.tiles_y - 1);
    let at =
        |tx: u32, ty: u32| filtered_tile_level(&tiles[(ty * p.tiles_x + tx) as usize], p.matched);
    let c0 = ((s - wy) * at(tx, ty) + wy * at(tx, ty1)) / s;
    let c1 = ((s - wy) * at(tx1, ty) + wy * at(tx1, ty1)) / s;
    ((s - wx) * c0 + wx * c1) / s
}

/// The 3×3 binomial sum at (x, y) (weights 1 2 1 / 2 4 2 / 1 2 1; the edge pixels repeated
/// beyond the frame): 16 times the smoothed value.
#[inline]
pub fn binomial3(pixels: &[u16], width: u32, height: u32, x: u32, y: u32) -> u32 {
    let (xl, xr) = (x.saturating_sub(1), (x + 1).min(width - 1));
    let (yu, yd) = (y.saturating_sub(1), (y + 1).min(height - 1));
    let row = |y: u32| {
        let r = (y * width) as usize;
        let px = |x: u32| pixels[r + x as usize] as u32;
        px(xl) + 2 * px(x) + px(xr)
    };
    row(yu) + 2 * row(y) + row(yd)
}

/// The mask with the matched filter (the threshold kernel with `matched` set): a pixel is
/// set when both its 3×3 binomial smoothing (a filter of about the size of a star's PSF, which
/// raises a star's peak SNR about twofold for PSF σ ≈ 1 px) is above its tile level at k
/// sigmas of the smoothed noise, and the pixel itself is above the same level (k · gain/16:
/// 0.4 k of its own sigmas for white noise): a lone hot pixel lifts its smoothed neighbours but
/// not their pixels, so it stays one pixel and `min_area` drops it. Integer arithmetic
/// throughout: the GPU's mask is the same bit for bit.
pub fn threshold_filtered(pixels: &[u16], tiles: &[TileStats], p: &DetectParams) -> Vec<Run> {
    crate::simd::fast!(threshold_filtered_in(pixels: &[u16], tiles: &[TileStats], p: &DetectParams) -> Vec<Run>)
}

/// [`threshold_filtered`], compiled where it is inlined (see [`crate::simd`]).
#[inline(always)]
fn threshold_filtered_in(pixels: &[u16], tiles: &[TileStats], p: &DetectParams) -> Vec<Run> {
    let s = 2 * p.tile;
    scan(pixels, tiles, p, &Filtered { pixels, p, s })
}

/// The matched filter's mask (see [`threshold_filtered`]), in 1/16 ADU.
struct Filtered<'a> {
    pixels: &'a [u16],
    p: &'a DetectParams,
    /// Twice the tile side: the interpolation weights' denominator.
    s: u32,
}

impl Rule for Filtered<'_> {
    #[inline(always)]
    fn tile_level(&self, t: &TileStats) -> u32 {
        filtered_tile_level(t, self.p.matched)
    }
    #[inline(always)]
    fn between_rows(&self, a: u32, b: u32, wy: u32) -> u32 {
        ((self.s - wy) * a + wy * b) / self.s
    }
    /// The level is at least min(c0, c1): a pixel at or below a sixteenth of it is below.
    #[inline(always)]
    fn floor(&self, c0: u32, c1: u32) -> u16 {
        (c0.min(c1) / 16).min(65535) as u16
    }
    #[inline(always)]
    fn set(&self, x: u32, y: u32, v: u16, wx: u32, c0: u32, c1: u32) -> bool {
        let level = ((self.s - wx) * c0 + wx * c1) / self.s;
        16 * v as u32 > level && binomial3(self.pixels, self.p.width, self.p.height, x, y) > level
    }
    /// A set pixel is above its level's sixteenth and its binomial sum above the level (at
    /// least 16 · floor): a block whose pixels or whose sums are all below cannot hold one.
    /// Most of the sky passes by its sums (the smoothed noise is 6/16 of the pixels').
    #[inline(always)]
    fn quiet(&self, row: &[u16], x: usize, y: u32, floor: u16) -> bool {
        !block_above(row, x, floor) || !block_binomial_above(self.pixels, self.p, x, y, floor)
    }
}

/// The mask as one value per pixel (1 = set), as the GPU stores it.
pub fn dense_mask(runs: &[Run], width: u32, height: u32) -> Vec<u32> {
    let mut m = vec![0u32; (width * height) as usize];
    for r in runs {
        let row = (r.y * width) as usize;
        m[row + r.x0 as usize..row + r.x1 as usize].fill(1);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Median and MAD by selection: what the counting search must find.
    fn by_selection(v: &mut [u16]) -> (u16, u16) {
        let rank = (v.len() - 1) / 2;
        let median = *v.select_nth_unstable(rank).1;
        for x in v.iter_mut() {
            *x = x.abs_diff(median);
        }
        (median, *v.select_nth_unstable(rank).1)
    }

    /// The counting search gives the order statistics selection gives, for narrow spans (sky
    /// tiles) and wide ones (a star in the tile), odd and even counts, values at both ends of
    /// the range, and guesses right, near, anywhere and at either end.
    #[test]
    fn counted_median_mad_equals_selection() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for case in 0..3000 {
            let n = rng.random_range(1..=600);
            let base: u16 = [0, rng.random_range(0..60_000), u16::MAX - 3][case % 3];
            let spread: u16 = [1, 3, 40, 800, 5000][case % 5];
            let mut v: Vec<u16> = (0..n)
                .map(|_| base.saturating_add(rng.random_range(0..=spread)))
                .collect();
            if case % 7 == 0 {
                v[0] = u16::MAX;
            }
            if case % 11 == 0 {
                v[n - 1] = 0;
            }
            let want = by_selection(&mut v.clone());
            let guess = match case % 4 {
                0 => want,
                1 => (want.0.saturating_add(2), want.1.saturating_sub(1)),
                2 => (rng.random(), rng.random()),
                _ => [(0, u16::MAX), (u16::MAX, 0)][case / 4 % 2],
            };
            assert_eq!(median_mad(&mut v, guess), want, "case {case}");
        }
    }

    /// Gaussian noise of σ `sigma` about `base`, 512 × 384, from `seed`; with `box2` each pixel
    /// the mean of a 2 × 2 box of it (neighbours correlate by ½ along each axis, and not at a
    /// distance of 2), rounded to whole counts.
    fn noise(sigma: f64, base: f64, box2: bool, seed: u64) -> Vec<u16> {
        let (w, h) = (512usize, 384usize);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let white: Vec<f64> = (0..(w + 1) * (h + 1))
            .map(|_| {
                // Box–Muller.
                let (u, v): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
                (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
            })
            .collect();
        let at = |x: usize, y: usize| white[y * (w + 1) + x];
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let n = if box2 {
                    // The mean of four has σ/2: times 2 keeps σ.
                    at(x, y) + at(x + 1, y) + at(x, y + 1) + at(x + 1, y + 1)
                } else {
                    at(x, y)
                };
                (base + sigma * n / if box2 { 2.0 } else { 1.0 }).round() as u16
            })
            .collect()
    }

    /// The gain is the binomial's on the noise itself: 6 for white noise, 16-bit or in whole
    /// counts of an 8-bit frame (σ 2 and 1.5: the grouped median; the plain one of σ 1.5's
    /// differences, 1 for 1.43, made it 9), and 10 where neighbours correlate by
    /// ½ (per axis 6 + 8ρ₁ + 2ρ₂ = 10 against 6, so the σ of the sums over that of the
    /// pixels is 10). A flat frame, or one too small, keeps the white-noise gain.
    #[test]
    fn the_filter_gain_is_the_noise_s_own() {
        let (w, h) = (512, 384);
        assert_eq!(filter_gain(&noise(40.0, 3000.0, false, 1), w, h), 6);
        assert_eq!(filter_gain(&noise(2.0, 12.0, false, 2), w, h), 6);
        assert_eq!(filter_gain(&noise(1.5, 12.0, false, 5), w, h), 6);
        assert_eq!(filter_gain(&noise(40.0, 3000.0, true, 3), w, h), 10);
        assert_eq!(filter_gain(&noise(3.0, 20.0, true, 4), w, h), 10);
        assert_eq!(filter_gain(&vec![500; (w * h) as usize], w, h), WHITE_GAIN);
        assert_eq!(filter_gain(&[1, 2, 3, 4, 5, 6], 3, 2), WHITE_GAIN);
    }
}
