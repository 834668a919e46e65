// Stage select (CPU twin: src/cpu/select.rs): the k best candidates of each image star, as
// 64-bit keys (min(votes, 0xFFFF) << 32) | (0xFFFFFFFF − id) stored as vec2 (low word, high
// word), best first; ties go to the lowest id.
// One workgroup per (star, image):
//  1. radix select (high byte, low byte of the saturated votes) finds T, the votes of the
//     m-th best candidate (m = min(k, nonzero counts));
//  2. candidates above T are gathered (fewer than m, any order), ties at T are taken in id
//     order (a per-thread count and prefix over contiguous id chunks), up to m in all;
//  3. thread 0 sorts the m keys (they are distinct) and writes them, zero-padded to k.

@group(0) @binding(0) var<uniform> u: VoteUniform;
@group(0) @binding(1) var<storage, read> votes: array<u32>;
@group(0) @binding(2) var<storage, read_write> candidates: array<vec2<u32>>;

const MAX_K: u32 = 64u;

var<workgroup> hist: array<atomic<u32>, 256>;
// (bin, entries in higher bins) of the rank being selected.
var<workgroup> pick: vec2<u32>;
var<workgroup> total: atomic<u32>;
var<workgroup> above: atomic<u32>;
var<workgroup> chosen: array<vec2<u32>, MAX_K>;
var<workgroup> tie_prefix: array<u32, 256>;

fn saturated(v: u32) -> u32 {
    return min(v, 0xFFFFu);
}

// The candidate key of (votes, id): the 64-bit (votes << 32) | (0xFFFFFFFF − id) as (low, high).
fn key_of(v: u32, id: u32) -> vec2<u32> {
    return vec2<u32>(0xFFFFFFFFu - id, v);
}

// Whether key a orders before key b (more votes, then the lower id).
fn before(a: vec2<u32>, b: vec2<u32>) -> bool {
    return a.y > b.y || (a.y == b.y && a.x > b.x);
}

// Thread 0: the bin holding rank `rank` counted from the top, into `pick`.
fn find_bin_from_top(rank: u32) {
    var higher = 0u;
    for (var b = 255i; b >= 0i; b--) {
        let n = atomicLoad(&hist[b]);
        if (higher + n > rank) {
            pick = vec2<u32>(u32(b), higher);
            return;
        }
        higher += n;
    }
    pick = vec2<u32>(0u, higher);
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let star = wg.x;
    let img = wg.y;
    let base = (img * u.stars + star) * u.refs;
    let k = min(u.k, MAX_K);
    // 1. High byte.
    atomicStore(&hist[lid], 0u);
    if (lid == 0u) {
        atomicStore(&total, 0u);
        atomicStore(&above, 0u);
    }
    workgroupBarrier();
    for (var id = lid; id < u.refs; id += 256u) {
        let v = saturated(votes[base + id]);
        if (v > 0u) {
            atomicAdd(&hist[v >> 8u], 1u);
            atomicAdd(&total, 1u);
        }
    }
    workgroupBarrier();
    let m = min(k, atomicLoad(&total));
    if (lid == 0u) {
        find_bin_from_top(max(m, 1u) - 1u);
    }
    let first = workgroupUniformLoad(&pick);
    // Low byte within that bin.
    atomicStore(&hist[lid], 0u);
    workgroupBarrier();
    for (var id = lid; id < u.refs; id += 256u) {
        let v = saturated(votes[base + id]);
        if (v > 0u && (v >> 8u) == first.x) {
            atomicAdd(&hist[v & 0xFFu], 1u);
        }
    }
    workgroupBarrier();
    if (lid == 0u) {
        find_bin_from_top(max(m, 1u) - 1u - first.y);
    }
    let second = workgroupUniformLoad(&pick);
    let threshold = (first.x << 8u) | second.x;
    // 2. Candidates above the threshold, in any order (fewer than m of them).
    for (var id = lid; id < u.refs; id += 256u) {
        let v = saturated(votes[base + id]);
        if (m > 0u && v > threshold) {
            chosen[atomicAdd(&above, 1u)] = key_of(v, id);
        }
    }
    // Ties at the threshold, in id order: this thread's contiguous chunk of ids.
    let chunk = (u.refs + 255u) / 256u;
    let start = min(lid * chunk, u.refs);
    let end = min(start + chunk, u.refs);
    var ties = 0u;
    for (var id = start; id < end; id++) {
        let v = saturated(votes[base + id]);
        if (m > 0u && v == threshold) {
            ties++;
        }
    }
    tie_prefix[lid] = ties;
    workgroupBarrier();
    if (lid == 0u) {
        var acc = 0u;
        for (var t = 0u; t < 256u; t++) {
            let c = tie_prefix[t];
            tie_prefix[t] = acc;
            acc += c;
        }
    }
    workgroupBarrier();
    let n_above = atomicLoad(&above);
    var slot = n_above + tie_prefix[lid];
    for (var id = start; id < end; id++) {
        let v = saturated(votes[base + id]);
        if (m > 0u && v == threshold && slot < m) {
            chosen[slot] = key_of(v, id);
            slot++;
        }
    }
    workgroupBarrier();
    // 3. Sort best first and write.
    if (lid == 0u) {
        for (var a = 1u; a < m; a++) {
            let key = chosen[a];
            var b = a;
            while (b > 0u && before(key, chosen[b - 1u])) {
                chosen[b] = chosen[b - 1u];
                b--;
            }
            chosen[b] = key;
        }
        let out = (img * u.stars + star) * u.k;
        for (var r = 0u; r < u.k; r++) {
            candidates[out + r] = select(vec2<u32>(0u), chosen[r], r < m);
        }
    }
}
