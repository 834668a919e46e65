// Stage centroid, kernel 2 of 3 (CPU twin: src/cpu/centroid.rs): exclusive prefix sum of the
// roots per block, and the number of components of each image. One workgroup per image.

@group(0) @binding(0) var<uniform> u: DetectUniform;
@group(0) @binding(1) var<storage, read> root_bits: array<u32>;
@group(0) @binding(2) var<storage, read_write> block_offsets: array<u32>;
@group(0) @binding(3) var<storage, read_write> blob_counts: array<u32>;

var<workgroup> partial: array<u32, 256>;

fn roots_in_block(img: u32, blk: u32) -> u32 {
    let w = (img * u.b.blocks_per_image + blk) * 8u;
    var n = 0u;
    for (var k = 0u; k < 8u; k++) {
        n += countOneBits(root_bits[w + k]);
    }
    return n;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let img = wg.x;
    let blocks = u.b.blocks_per_image;
    let chunk = (blocks + 255u) / 256u;
    let start = min(lid * chunk, blocks);
    let end = min(start + chunk, blocks);
    var sum = 0u;
    for (var b = start; b < end; b++) {
        sum += roots_in_block(img, b);
    }
    partial[lid] = sum;
    workgroupBarrier();
    if (lid == 0u) {
        var acc = 0u;
        for (var t = 0u; t < 256u; t++) {
            let v = partial[t];
            partial[t] = acc;
            acc += v;
        }
        blob_counts[img] = acc;
    }
    workgroupBarrier();
    var acc = partial[lid];
    for (var b = start; b < end; b++) {
        block_offsets[img * blocks + b] = acc;
        acc += roots_in_block(img, b);
    }
}
