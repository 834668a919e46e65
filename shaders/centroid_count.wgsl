// Stage centroid, kernel 1 of 3 (CPU twin: src/cpu/centroid.rs): mark the roots (set pixels
// whose label is their own index) in a bit per pixel, eight words per block of 256 pixels.
// The count → prefix sum → scatter that follows gives every component a slot in label order.
// Dispatch (blocks, images); threads stride over the image's set list. root_bits starts zeroed.

@group(0) @binding(0) var<uniform> u: DetectUniform;
@group(0) @binding(1) var<storage, read> labels: array<u32>;
@group(0) @binding(2) var<storage, read_write> root_bits: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read> set_list: array<u32>;
@group(0) @binding(4) var<storage, read> set_count: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let img = gid.y;
    let count = min(set_count[img], u.b.max_set);
    for (var t = gid.x; t < count; t += nwg.x * 256u) {
        let i = set_list[img * u.b.max_set + t];
        if (labels[img * u.b.pixels_per_image + i] == i) {
            atomicOr(&root_bits[img * u.b.blocks_per_image * 8u + i / 32u], 1u << (i % 32u));
        }
    }
}
