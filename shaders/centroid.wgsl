// Stage centroid, kernel 3 of 3 (CPU twin: src/cpu/centroid.rs): each set pixel (from the set
// list) adds its
// background-subtracted value w to the integer moments of its component's slot (slot = roots
// before its root: the block offset plus the root bits below it). u32 atomics with carries
// give exact 64-bit sums in any order. Slots beyond max_blobs are skipped; the host sees the
// true count in blob_counts and retries with more room. Dispatch (blocks, images), striding.

@group(0) @binding(0) var<uniform> u: DetectUniform;
@group(0) @binding(1) var<storage, read> pixels: array<u32>;
@group(0) @binding(2) var<storage, read> tiles: array<TileStats>;
@group(0) @binding(3) var<storage, read> labels: array<u32>;
@group(0) @binding(4) var<storage, read> root_bits: array<u32>;
@group(0) @binding(5) var<storage, read> block_offsets: array<u32>;
@group(0) @binding(6) var<storage, read_write> blobs: array<BlobAtomic>;
@group(0) @binding(7) var<storage, read> set_list: array<u32>;
@group(0) @binding(8) var<storage, read> set_count: array<u32>;

// Add v to moment k of blob b, a 64-bit sum kept as (lo, hi): the carry makes the total exact
// in any order.
fn add64(b: u32, k: u32, v: u32) {
    let old = atomicAdd(&blobs[b].moments[2u * k], v);
    if (old > 0xFFFFFFFFu - v) {
        atomicAdd(&blobs[b].moments[2u * k + 1u], 1u);
    }
}

fn pixel(img: u32, i: u32) -> u32 {
    let w = pixels[img * u.b.words_per_image + i / 2u];
    return (w >> ((i & 1u) * 16u)) & 0xFFFFu;
}

fn background(img: u32, tx: u32, ty: u32) -> u32 {
    return tiles[img * u.b.tiles_per_image + ty * u.p.tiles_x + tx].background;
}

// As src/cpu/threshold.rs background_at: interpolated and rounded.
fn background_at(img: u32, x: u32, y: u32) -> u32 {
    let p = u.p;
    let s = 2u * p.tile;
    let ax = axis_weight(x, p.tile, p.tiles_x);
    let ay = axis_weight(y, p.tile, p.tiles_y);
    let tx1 = min(ax.x + 1u, p.tiles_x - 1u);
    let ty1 = min(ay.x + 1u, p.tiles_y - 1u);
    let b = bilinear(background(img, ax.x, ay.x), background(img, tx1, ay.x),
                     background(img, ax.x, ty1), background(img, tx1, ty1), ax.y, ay.y, s);
    return (b + s * s / 2u) / (s * s);
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let img = gid.y;
    let w = u.p.width;
    let count = min(set_count[img], u.b.max_set);
    for (var t = gid.x; t < count; t += nwg.x * 256u) {
        let i = set_list[img * u.b.max_set + t];
        let r = labels[img * u.b.pixels_per_image + i];
        let blk = r / BLOCK;
        let bit = r % BLOCK;
        let words = (img * u.b.blocks_per_image + blk) * 8u;
        var rank = 0u;
        for (var k = 0u; k < bit / 32u; k++) {
            rank += countOneBits(root_bits[words + k]);
        }
        rank += countOneBits(root_bits[words + bit / 32u] & ((1u << (bit % 32u)) - 1u));
        let slot = block_offsets[img * u.b.blocks_per_image + blk] + rank;
        if (slot >= u.b.max_blobs) {
            continue;
        }
        let b = img * u.b.max_blobs + slot;
        let x = i % w;
        let y = i / w;
        let v = pixel(img, i);
        let bg = background_at(img, x, y);
        let wt = max(select(0u, v - bg, v > bg), 1u);
        if (i == r) {
            blobs[b].label = r;
        }
        atomicAdd(&blobs[b].area, 1u);
        atomicMax(&blobs[b].peak, v);
        if (v >= u.p.saturation) {
            atomicAdd(&blobs[b].saturated, 1u);
        }
        add64(b, 0u, wt);
        add64(b, 1u, wt * x);
        add64(b, 2u, wt * y);
    }
}
