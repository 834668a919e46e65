// Stage threshold, kernel 2 of 2 (CPU twin: src/cpu/threshold.rs threshold): the mask
// pixel · s² > interpolated (background + offset) · s², in integers; with the matched filter
// (matched = its noise gain, 6..16; twin threshold_filtered) the pixel and its 3x3 binomial
// smoothing both above the filter's level. One invocation per 32
// pixels (in raster order) writes one mask word; each set pixel starts as its own label and
// its index is appended to the set list, which the later kernels walk instead of the frame
// (the list's order does not matter to them). Dispatch (blocks, images), striding.

@group(0) @binding(0) var<uniform> u: DetectUniform;
@group(0) @binding(1) var<storage, read> pixels: array<u32>;
@group(0) @binding(2) var<storage, read> tiles: array<TileStats>;
@group(0) @binding(3) var<storage, read_write> mask: array<u32>;
@group(0) @binding(4) var<storage, read_write> labels: array<u32>;
@group(0) @binding(5) var<storage, read_write> set_list: array<u32>;
@group(0) @binding(6) var<storage, read_write> set_count: array<atomic<u32>>;

fn pixel(img: u32, i: u32) -> u32 {
    let w = pixels[img * u.b.words_per_image + i / 2u];
    return (w >> ((i & 1u) * 16u)) & 0xFFFFu;
}

fn level(img: u32, tx: u32, ty: u32) -> u32 {
    let t = tiles[img * u.b.tiles_per_image + ty * u.p.tiles_x + tx];
    return min(t.background + t.offset, 65536u);
}

// The matched filter's tile level in 1/16 ADU (src/cpu/threshold.rs filtered_tile_level).
fn flevel(img: u32, tx: u32, ty: u32) -> u32 {
    let t = tiles[img * u.b.tiles_per_image + ty * u.p.tiles_x + tx];
    return 16u * t.background + u.p.matched * min(t.offset, 1u << 20u);
}

// The 3x3 binomial sum at (x, y), edges repeated (src/cpu/threshold.rs binomial3).
fn binomial3(img: u32, x: u32, y: u32) -> u32 {
    let w = u.p.width;
    let xl = select(x - 1u, 0u, x == 0u);
    let xr = min(x + 1u, w - 1u);
    let yu = select(y - 1u, 0u, y == 0u);
    let yd = min(y + 1u, u.p.height - 1u);
    let ru = yu * w;
    let rc = y * w;
    let rd = yd * w;
    let up = pixel(img, ru + xl) + 2u * pixel(img, ru + x) + pixel(img, ru + xr);
    let mid = pixel(img, rc + xl) + 2u * pixel(img, rc + x) + pixel(img, rc + xr);
    let down = pixel(img, rd + xl) + 2u * pixel(img, rd + x) + pixel(img, rd + xr);
    return up + 2u * mid + down;
}

// The position of a coordinate among the tile centres, kept as the doubled offset o from the
// first centre and its floor division by 2·tile, so that stepping to the next pixel needs no
// division; `axis_value` then gives exactly axis_weight (shared/detect.wgsl).
struct Axis {
    o: i32,
    t: u32,
    f: u32,
}

fn axis_start(x: u32, tile: u32) -> Axis {
    let o = 2 * i32(x) - (i32(tile) - 1);
    if (o <= 0) {
        return Axis(o, 0u, 0u);
    }
    return Axis(o, u32(o) / (2u * tile), u32(o) % (2u * tile));
}

fn axis_next(a: Axis, tile: u32) -> Axis {
    let o = a.o + 2;
    if (o <= 0) {
        return Axis(o, 0u, 0u);
    }
    if (a.o <= 0) {
        return Axis(o, 0u, u32(o));
    }
    let f = a.f + 2u;
    if (f >= 2u * tile) {
        return Axis(o, a.t + 1u, f - 2u * tile);
    }
    return Axis(o, a.t, f);
}

fn axis_value(a: Axis, tiles: u32) -> vec2<u32> {
    if (a.o <= 0) {
        return vec2<u32>(0u, 0u);
    }
    if (a.t + 1u >= tiles) {
        return vec2<u32>(tiles - 1u, 0u);
    }
    return vec2<u32>(a.t, a.f);
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = u.p;
    let img = gid.y;
    let s = 2u * p.tile;
    for (var w = gid.x; w < u.b.mask_words; w += nwg.x * 256u) {
        var bits = 0u;
        let first = w * 32u;
        let last = min(first + 32u, u.b.pixels_per_image);
        var x = first % p.width;
        var y = first / p.width;
        var ax = axis_start(x, p.tile);
        var ay = axis_value(axis_start(y, p.tile), p.tiles_y);
        var ty1 = min(ay.x + 1u, p.tiles_y - 1u);
        for (var i = first; i < last; i++) {
            let a = axis_value(ax, p.tiles_x);
            let tx1 = min(a.x + 1u, p.tiles_x - 1u);
            if (p.matched != 0u) {
                // The matched filter: floored interpolation between rows, then columns.
                let c0 = ((s - ay.y) * flevel(img, a.x, ay.x) + ay.y * flevel(img, a.x, ty1)) / s;
                let c1 = ((s - ay.y) * flevel(img, tx1, ay.x) + ay.y * flevel(img, tx1, ty1)) / s;
                let lvl = ((s - a.y) * c0 + a.y * c1) / s;
                if (16u * pixel(img, i) > lvl && binomial3(img, x, y) > lvl) {
                    bits |= 1u << (i - first);
                }
            } else {
                let lvl = bilinear(level(img, a.x, ay.x), level(img, tx1, ay.x),
                                   level(img, a.x, ty1), level(img, tx1, ty1), a.y, ay.y, s);
                if (pixel(img, i) * s * s > lvl) {
                    bits |= 1u << (i - first);
                }
            }
            x++;
            if (x == p.width) {
                x = 0u;
                y++;
                ax = axis_start(0u, p.tile);
                ay = axis_value(axis_start(y, p.tile), p.tiles_y);
                ty1 = min(ay.x + 1u, p.tiles_y - 1u);
            } else {
                ax = axis_next(ax, p.tile);
            }
        }
        mask[img * u.b.mask_words + w] = bits;
        if (bits != 0u) {
            let at = atomicAdd(&set_count[img], countOneBits(bits));
            var b = bits;
            var k = at;
            while (b != 0u) {
                let i = first + firstTrailingBit(b);
                labels[img * u.b.pixels_per_image + i] = i;
                if (k < u.b.max_set) {
                    set_list[img * u.b.max_set + k] = i;
                }
                k++;
                b &= b - 1u;
            }
        }
    }
}
