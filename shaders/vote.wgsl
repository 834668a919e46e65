// Stage vote (CPU twin: src/cpu/vote.rs): every table row in an image-star pair's key range
// adds a vote for both catalog stars to both image stars. u32 atomicAdd counts are exact in any
// order. The rows of each range are found on the CPU (PairTable::range, as the twin does); the
// table's pairs come in slices of at most one binding, one dispatch per slice, and a catalog
// too deep for all stars' counters is counted a window of voting stars at a time.
// Dispatch (blocks, 1); threads stride over all pairs of all images. Padding spans are empty.

@group(0) @binding(0) var<uniform> u: VoteUniform;
// Rows row_lo .. row_hi of the table: the two reference-star ids of each.
@group(0) @binding(1) var<storage, read> pairs: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read> spans: array<RowSpan>;
@group(0) @binding(3) var<storage, read_write> votes: array<atomic<u32>>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let total = u.images * u.pairs_per_image;
    for (var t = gid.x; t < total; t += nwg.x * 256u) {
        let s = spans[t];
        let start = max(s.start, u.row_lo);
        let end = min(s.end, u.row_hi);
        // Unsigned wrap: a star below star_lo is counted as out of the window too.
        let count_i = s.i - u.star_lo < u.stars;
        let count_j = s.j - u.star_lo < u.stars;
        if (start >= end || !(count_i || count_j)) {
            continue;
        }
        let img = t / u.pairs_per_image;
        let vi = (img * u.stars + (s.i - u.star_lo)) * u.refs;
        let vj = (img * u.stars + (s.j - u.star_lo)) * u.refs;
        for (var row = start; row < end; row++) {
            let p = pairs[row - u.row_lo];
            if (count_i) {
                atomicAdd(&votes[vi + p.x], 1u);
                atomicAdd(&votes[vi + p.y], 1u);
            }
            if (count_j) {
                atomicAdd(&votes[vj + p.x], 1u);
                atomicAdd(&votes[vj + p.y], 1u);
            }
        }
    }
}
