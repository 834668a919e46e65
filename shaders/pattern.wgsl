// Stage pattern (CPU twin: src/cpu/pattern.rs): for each query key, the rows [start, end) of
// the sorted pattern keys equal to it, as the lower bounds of the key and of the key + 1
// (binary searches). Integers only: GPU = CPU exactly. One thread a query; threads stride
// over the queries.

// Keep in sync with src/gpu/pattern.rs (PatternUniform).
struct PatternUniform {
    queries: u32,
    keys: u32,
    pad0: u32,
    pad1: u32,
}

// Keep in sync with src/cpu/pattern.rs (Rows).
struct Rows {
    start: u32,
    end: u32,
}

@group(0) @binding(0) var<uniform> u: PatternUniform;
@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read> queries: array<u32>;
@group(0) @binding(3) var<storage, read_write> rows: array<Rows>;

fn lower_bound(key: u32) -> u32 {
    var lo = 0u;
    var hi = u.keys;
    while lo < hi {
        let mid = lo + (hi - lo) / 2u;
        if keys[mid] < key {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    for (var q = gid.x; q < u.queries; q += nwg.x * 64u) {
        let key = queries[q];
        let start = lower_bound(key);
        var end = u.keys;
        if key != 0xffffffffu {
            end = lower_bound(key + 1u);
        }
        rows[q] = Rows(start, end);
    }
}
