//! Stage `threshold`: local background and noise per tile, and the k·σ mask.
//!
//! Background = the median of a tile, noise = 1.4826 · MAD of the tile (robust to the stars in
//! it); both are interpolated bilinearly between tile centres, so gradients and vignetting do
//! not leave steps at tile edges. Everything after the per-tile `offset` is integer arithmetic,
//! so the GPU twin reproduces the mask bit for bit.

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
    pub _pad: u32,
}

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
            _pad: 0,
        }
    }
}

/// Background and threshold offset of one tile. Keep in sync with `shaders/shared/detect.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct TileStats {
    /// Median pixel value.
    pub background: u32,
    /// ceil(k · 1.4826 · max(MAD, 1)): how far above the background a pixel must be.
    pub offset: u32,
}

/// Per-tile median and MAD (lower medians: element (n−1)/2 of the sorted values).
pub fn tile_stats(pixels: &[u16], p: &DetectParams) -> Vec<TileStats> {
    let mut out = Vec::with_capacity((p.tiles_x * p.tiles_y) as usize);
    let mut vals: Vec<u16> = Vec::with_capacity((p.tile * p.tile) as usize);
    for ty in 0..p.tiles_y {
        for tx in 0..p.tiles_x {
            vals.clear();
            let (x0, y0) = (tx * p.tile, ty * p.tile);
            let (x1, y1) = ((x0 + p.tile).min(p.width), (y0 + p.tile).min(p.height));
            for y in y0..y1 {
                let row = (y * p.width) as usize;
                vals.extend_from_slice(&pixels[row + x0 as usize..row + x1 as usize]);
            }
            let median = lower_median(&mut vals);
            for v in vals.iter_mut() {
                *v = v.abs_diff(median);
            }
            let mad = lower_median(&mut vals).max(1);
            out.push(TileStats {
                background: median as u32,
                offset: (p.k_mad * mad as f32).ceil() as u32,
            });
        }
    }
    out
}

fn lower_median(v: &mut [u16]) -> u16 {
    let mid = (v.len() - 1) / 2;
    *v.select_nth_unstable(mid).1
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

/// The mask: 1 where `pixel > background + offset` (both interpolated), else 0.
pub fn threshold(pixels: &[u16], tiles: &[TileStats], p: &DetectParams) -> Vec<u8> {
    let s2 = 4 * p.tile * p.tile;
    let mut mask = vec![0u8; pixels.len()];
    for y in 0..p.height {
        for x in 0..p.width {
            let i = (y * p.width + x) as usize;
            mask[i] = (pixels[i] as u32 * s2 > level_scaled(tiles, p, x, y)) as u8;
        }
    }
    mask
}
