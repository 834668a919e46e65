// Stage streak_filter, kernel 1 of 2 (CPU twin: src/cpu/streak_filter.rs streak_rows): on the
// frame binned 2×2, per block Σ_i b_i · (block − 4 · background) over the row neighbours
// x − 2 … x + 2 (clamped at the grid's edges), b = 1 4 6 4 1; the background is the tiles'
// bilinear interpolation at the block's first pixel rounded to an integer, as threshold.rs
// background_at. One invocation per run of 32 blocks of a row, striding; dispatch (runs,
// images).

@group(0) @binding(0) var<uniform> u: StreakUniform;
@group(0) @binding(1) var<storage, read> pixels: array<u32>;
@group(0) @binding(2) var<storage, read> tiles: array<TileStats>;
@group(0) @binding(3) var<storage, read_write> rows: array<i32>;

fn pixel(img: u32, i: u32) -> u32 {
    let w = pixels[img * u.b.words_per_image + i / 2u];
    return (w >> ((i & 1u) * 16u)) & 0xFFFFu;
}

fn background(img: u32, tx: u32, ty: u32) -> u32 {
    return tiles[img * u.b.tiles_per_image + ty * u.p.tiles_x + tx].background;
}

// Block (xb, yb): its four pixels less four times the background at its first pixel, in
// integers.
fn residual(img: u32, xb: u32, yb: u32) -> i32 {
    let p = u.p;
    let s = 2u * p.tile;
    let x = 2u * xb;
    let y = 2u * yb;
    let ax = axis_weight(x, p.tile, p.tiles_x);
    let ay = axis_weight(y, p.tile, p.tiles_y);
    let tx1 = min(ax.x + 1u, p.tiles_x - 1u);
    let ty1 = min(ay.x + 1u, p.tiles_y - 1u);
    let v = bilinear(background(img, ax.x, ay.x), background(img, tx1, ay.x),
                     background(img, ax.x, ty1), background(img, tx1, ty1), ax.y, ay.y, s);
    let bg = (v + s * s / 2u) / (s * s);
    let i = y * p.width + x;
    let block = pixel(img, i) + pixel(img, i + 1u) + pixel(img, i + p.width)
        + pixel(img, i + p.width + 1u);
    return i32(block) - 4 * i32(bg);
}

// Blocks per invocation, along a row: their residuals are computed once for the five sums
// that use each (the bilinear background is most of the work).
const RUN: u32 = 32u;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let img = gid.y;
    let w = u.s.width;
    let runs_per_row = (w + RUN - 1u) / RUN;
    for (var k = gid.x; k < runs_per_row * u.s.height; k += nwg.x * 256u) {
        let y = k / runs_per_row;
        let x0 = (k % runs_per_row) * RUN;
        let n = min(RUN, w - x0);
        // Residuals of block columns x0 − 2 … x0 + n + 1, clamped to the grid.
        var d: array<i32, 36>;
        for (var j = 0u; j < n + 4u; j++) {
            let x = u32(clamp(i32(x0 + j) - 2, 0, i32(w) - 1));
            d[j] = residual(img, x, y);
        }
        for (var j = 0u; j < n; j++) {
            rows[img * w * u.s.height + y * w + x0 + j] =
                d[j] + 4 * d[j + 1u] + 6 * d[j + 2u] + 4 * d[j + 3u] + d[j + 4u];
        }
    }
}
