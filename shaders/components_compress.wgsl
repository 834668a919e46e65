// Stage components, kernel 2 of 2 (CPU twin: src/cpu/components.rs): every set pixel takes
// the root of its tree, the smallest pixel index of its component.
// Dispatch (blocks, images); threads stride over the image's set list.

@group(0) @binding(0) var<uniform> u: DetectUniform;
@group(0) @binding(1) var<storage, read_write> labels: array<atomic<u32>>;
@group(0) @binding(2) var<storage, read> set_list: array<u32>;
@group(0) @binding(3) var<storage, read> set_count: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let img = gid.y;
    let base = img * u.b.pixels_per_image;
    let count = min(set_count[img], u.b.max_set);
    for (var t = gid.x; t < count; t += nwg.x * 256u) {
        let i = set_list[img * u.b.max_set + t];
        var r = atomicLoad(&labels[base + i]);
        var parent = atomicLoad(&labels[base + r]);
        while (parent != r) {
            r = parent;
            parent = atomicLoad(&labels[base + r]);
        }
        atomicStore(&labels[base + i], r);
    }
}
