// Stage threshold, kernel 2 of 2 (CPU twin: src/cpu/threshold.rs threshold): the mask
// pixel · s² > interpolated (background + offset) · s², in integers. One invocation per 32
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

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = u.p;
    let img = gid.y;
    let s = 2u * p.tile;
    for (var w = gid.x; w < u.b.mask_words; w += nwg.x * 256u) {
        var bits = 0u;
        let first = w * 32u;
        let last = min(first + 32u, u.b.pixels_per_image);
        for (var i = first; i < last; i++) {
            let x = i % p.width;
            let y = i / p.width;
            let ax = axis_weight(x, p.tile, p.tiles_x);
            let ay = axis_weight(y, p.tile, p.tiles_y);
            let tx1 = min(ax.x + 1u, p.tiles_x - 1u);
            let ty1 = min(ay.x + 1u, p.tiles_y - 1u);
            let lvl = bilinear(level(img, ax.x, ay.x), level(img, tx1, ay.x), level(img, ax.x, ty1),
                               level(img, tx1, ty1), ax.y, ay.y, s);
            if (pixel(img, i) * s * s > lvl) {
                bits |= 1u << (i - first);
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
