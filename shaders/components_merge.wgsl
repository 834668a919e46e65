// Stage components, kernel 1 of 2 (CPU twin: src/cpu/components.rs): union-find over the set
// pixels. Each set pixel unites with its set W, NW, N and NE neighbours; a union hangs the
// larger root under the smaller with atomicMin, so every component ends with its smallest
// pixel index as root, whatever the scheduling (Playne & Hawick 2018).
// Dispatch (blocks, images); threads stride over the image's set list.

@group(0) @binding(0) var<uniform> u: DetectUniform;
@group(0) @binding(1) var<storage, read> mask: array<u32>;
@group(0) @binding(2) var<storage, read_write> labels: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read> set_list: array<u32>;
@group(0) @binding(4) var<storage, read> set_count: array<u32>;

fn is_set(img: u32, i: u32) -> bool {
    return (mask[img * u.b.mask_words + i / 32u] >> (i % 32u) & 1u) == 1u;
}

fn find(base: u32, x: u32) -> u32 {
    var r = x;
    var parent = atomicLoad(&labels[base + r]);
    while (parent != r) {
        r = parent;
        parent = atomicLoad(&labels[base + r]);
    }
    return r;
}

fn unite(base: u32, a0: u32, b0: u32) {
    var a = find(base, a0);
    var b = find(base, b0);
    loop {
        if (a == b) {
            return;
        }
        if (a < b) {
            let t = a;
            a = b;
            b = t;
        }
        // a > b: hang a under b, unless another union moved a first; then go on from there.
        let old = atomicMin(&labels[base + a], b);
        if (old == a) {
            return;
        }
        a = find(base, old);
        b = find(base, b);
    }
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let img = gid.y;
    let w = u.p.width;
    let base = img * u.b.pixels_per_image;
    let count = min(set_count[img], u.b.max_set);
    for (var t = gid.x; t < count; t += nwg.x * 256u) {
        let i = set_list[img * u.b.max_set + t];
        let x = i % w;
        let y = i / w;
        if (x > 0u && is_set(img, i - 1u)) {
            unite(base, i, i - 1u);
        }
        if (y > 0u) {
            let up = i - w;
            if (x > 0u && is_set(img, up - 1u)) {
                unite(base, i, up - 1u);
            }
            if (is_set(img, up)) {
                unite(base, i, up);
            }
            if (x + 1u < w && is_set(img, up + 1u)) {
                unite(base, i, up + 1u);
            }
        }
    }
}
