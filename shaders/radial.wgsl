// Stage radial (CPU twin: src/cpu/radial.rs): score = max(0, BITS * |A & B| - |A| * |B|) of
// each image star's radial feature A against every catalog star's B (seed 002's AND +
// popcount, less what chance gives for the bit counts). Integers only: GPU = CPU bit for bit.
// Dispatch (groups over catalog stars, image stars, images); threads stride over the catalog.
// The catalog is word-major (word w of star id at w * refs + id): neighbouring threads read
// neighbouring words.

// Keep in sync with src/gpu/radial.rs (RadialUniform).
struct RadialUniform {
    images: u32,
    stars: u32,
    refs: u32,
    // Slots per image star in `image` (FEATURE_STARS: each neighbour sets one word at most).
    words: u32,
}

// Keep in sync with src/cpu/radial.rs (BITS).
const BITS: u32 = 4096u;

@group(0) @binding(0) var<uniform> u: RadialUniform;
@group(0) @binding(1) var<storage, read> catalog: array<u32>;
// Rings set per catalog star.
@group(0) @binding(2) var<storage, read> counts: array<u32>;
// Each image star's set words as (word index, bits), `words` slots a star, unused ones
// (0, 0).
@group(0) @binding(3) var<storage, read> image: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> scores: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let star = gid.y;
    let frame = gid.z;
    let a0 = (frame * u.stars + star) * u.words;
    var na = 0u;
    for (var w = 0u; w < u.words; w++) {
        na += countOneBits(image[a0 + w].y);
    }
    for (var id = gid.x; id < u.refs; id += nwg.x * 64u) {
        var both = 0u;
        for (var w = 0u; w < u.words; w++) {
            let a = image[a0 + w];
            both += countOneBits(a.y & catalog[a.x * u.refs + id]);
        }
        let s = BITS * both;
        let chance = na * counts[id];
        scores[(frame * u.stars + star) * u.refs + id] = select(0u, s - chance, s > chance);
    }
}
