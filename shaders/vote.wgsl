// Stage vote (CPU twin: src/cpu/vote.rs): each image-star pair finds its key range in the
// sorted table (k-vector bin start, then a short scan) and every row in it adds a vote for both
// catalog stars to both image stars. u32 atomicAdd counts are exact in any order.
// Dispatch (blocks, 1); threads stride over all pairs of all images. Padding pairs have lo > hi.

@group(0) @binding(0) var<uniform> u: VoteUniform;
@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read> pairs: array<u32>;
@group(0) @binding(3) var<storage, read> kvector: array<u32>;
@group(0) @binding(4) var<storage, read> ranges: array<PairRange>;
@group(0) @binding(5) var<storage, read_write> votes: array<atomic<u32>>;
// Rows scanned per image, as (lo, hi) of a 64-bit count.
@group(0) @binding(6) var<storage, read_write> hypotheses: array<atomic<u32>>;

// First row with key >= `key` (src/table.rs lower_bound).
fn lower_bound(key: u32) -> u32 {
    let bin = key >> u.shift;
    if (bin >= u.kvector_len - 1u) {
        return u.rows;
    }
    var i = kvector[bin];
    let end = kvector[bin + 1u];
    while (i < end && keys[i] < key) {
        i++;
    }
    return i;
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let total = u.images * u.pairs_per_image;
    for (var t = gid.x; t < total; t += nwg.x * 256u) {
        let r = ranges[t];
        if (r.lo > r.hi) {
            continue;
        }
        let img = t / u.pairs_per_image;
        let start = lower_bound(r.lo);
        var end = u.rows;
        if (r.hi != 0xFFFFFFFFu) {
            end = lower_bound(r.hi + 1u);
        }
        end = max(end, start);
        let n = end - start;
        let old = atomicAdd(&hypotheses[2u * img], n);
        if (old > 0xFFFFFFFFu - n) {
            atomicAdd(&hypotheses[2u * img + 1u], 1u);
        }
        let vi = (img * u.stars + r.i) * u.refs;
        let vj = (img * u.stars + r.j) * u.refs;
        for (var row = start; row < end; row++) {
            let p = pairs[row];
            let a = p & 0xFFFFu;
            let b = p >> 16u;
            atomicAdd(&votes[vi + a], 1u);
            atomicAdd(&votes[vi + b], 1u);
            atomicAdd(&votes[vj + a], 1u);
            atomicAdd(&votes[vj + b], 1u);
        }
    }
}
