// Shared by the detection kernels (threshold_tiles, tile_clip_sky, tile_clip, threshold,
// components_merge, components_compress, centroid_count, centroid_scan, centroid).

// Keep in sync with src/cpu/threshold.rs (DetectParams).
struct DetectParams {
    width: u32,
    height: u32,
    tile: u32,
    tiles_x: u32,
    tiles_y: u32,
    saturation: u32,
    k_mad: f32,
    // 0: the pixel against its level; else also its 3x3 binomial smoothing (the matched
    // filter), against 16 · background + matched · offset (matched: the filter's noise gain).
    matched: u32,
}

// How a batch of frames lies in the buffers. Keep in sync with src/gpu/detect.rs (BatchParams).
struct BatchParams {
    images: u32,
    pixels_per_image: u32,
    words_per_image: u32,
    blocks_per_image: u32,
    tiles_per_image: u32,
    max_blobs: u32,
    // Mask words (32 pixels each) per image.
    mask_words: u32,
    // Room for set-pixel indices per image.
    max_set: u32,
}

// Keep in sync with src/gpu/detect.rs (DetectUniform).
struct DetectUniform {
    p: DetectParams,
    b: BatchParams,
}

// Keep in sync with src/cpu/threshold.rs (TileStats).
struct TileStats {
    background: u32,
    offset: u32,
}

// src/cpu/centroid.rs (Blob) with each u64 moment as (lo, hi): the same bytes.
// Keep in sync with src/cpu/centroid.rs.
struct BlobAtomic {
    label: u32,
    area: atomic<u32>,
    peak: atomic<u32>,
    saturated: atomic<u32>,
    // m0, mx, my as (lo, hi) pairs.
    moments: array<atomic<u32>, 6>,
}

const NO_LABEL: u32 = 0xFFFFFFFFu;
// Pixels per block of the centroid compaction (eight words of root_bits).
const BLOCK: u32 = 256u;

// Bilinear position of x among the tile centres of one axis: (lower tile, weight of the upper
// one in units of 1/(2·tile)). As src/cpu/threshold.rs axis_weight.
fn axis_weight(x: u32, tile: u32, tiles: u32) -> vec2<u32> {
    let off = 2 * i32(x) - (i32(tile) - 1);
    if (off <= 0) {
        return vec2<u32>(0u, 0u);
    }
    let t0 = u32(off) / (2u * tile);
    if (t0 + 1u >= tiles) {
        return vec2<u32>(tiles - 1u, 0u);
    }
    return vec2<u32>(t0, u32(off) % (2u * tile));
}

// Four tile values combined with the weights, scaled by s² (s = 2·tile); exact in u32 for
// values up to 65536 and tiles up to 64.
fn bilinear(v00: u32, v10: u32, v01: u32, v11: u32, wx: u32, wy: u32, s: u32) -> u32 {
    return (s - wx) * (s - wy) * v00 + wx * (s - wy) * v10 + (s - wx) * wy * v01 + wx * wy * v11;
}
