// Stage streak_filter, kernel 2 of 2 (CPU twin: src/cpu/streak_filter.rs streak_filter): the
// streak mask on the binned grid. Σ_j b_j · rows(x, y + j − 2) (rows clamped at the grid's
// edges), b = 1 4 6 4 1, against the level of the tile of the block's first pixel,
// offset · level_num / level_den (k_streak noise sigmas of the smoothed image). One invocation
// per 32 blocks in raster order writes one mask word; dispatch (mask words, images), striding.

@group(0) @binding(0) var<uniform> u: StreakUniform;
@group(0) @binding(1) var<storage, read> rows: array<i32>;
@group(0) @binding(2) var<storage, read> tiles: array<TileStats>;
@group(0) @binding(3) var<storage, read_write> streak_mask: array<u32>;

fn row_sum(img: u32, x: u32, y: i32) -> i32 {
    let yc = u32(clamp(y, 0, i32(u.s.height) - 1));
    return rows[img * u.s.width * u.s.height + yc * u.s.width + x];
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = u.p;
    let img = gid.y;
    let blocks = u.s.width * u.s.height;
    for (var w = gid.x; w < u.s.words; w += nwg.x * 256u) {
        var bits = 0u;
        let first = w * 32u;
        let last = min(first + 32u, blocks);
        for (var i = first; i < last; i++) {
            let x = i % u.s.width;
            let y = i32(i / u.s.width);
            let sum = row_sum(img, x, y - 2) + 4 * row_sum(img, x, y - 1) + 6 * row_sum(img, x, y)
                + 4 * row_sum(img, x, y + 1) + row_sum(img, x, y + 2);
            // The tile of the block's first pixel (2x, 2y).
            let t = tiles[img * u.b.tiles_per_image + (2u * u32(y) / p.tile) * p.tiles_x
                + 2u * x / p.tile];
            let level = i32(min(t.offset, 1u << 19u) * u.s.level_num / u.s.level_den);
            if (sum > level) {
                bits |= 1u << (i - first);
            }
        }
        streak_mask[img * u.s.words + w] = bits;
    }
}
