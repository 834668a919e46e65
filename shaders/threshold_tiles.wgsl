// Stage threshold, kernel 1 of 2 (CPU twin: src/cpu/threshold.rs tile_stats): the median and
// MAD of each tile's even rows, and the offset from them (noise_offset: a MAD of a few counts
// read from the grouped deviations). 8-bit frames: one 256-bin histogram of the values gives both (the MAD by
// walking outward from the median). Deeper frames: a two-level radix select (high byte, then
// low byte) for each. Histograms live in workgroup memory. The CPU twin counts instead (one
// thread: vector compares beat scattered increments); the order statistics are the same.
// One workgroup of 64 per tile: (tiles_x, tiles_y, images).

@group(0) @binding(0) var<uniform> u: DetectUniform;
@group(0) @binding(1) var<storage, read> pixels: array<u32>;
@group(0) @binding(2) var<storage, read_write> tiles: array<TileStats>;

var<workgroup> hist: array<atomic<u32>, 256>;
// (bin, elements in lower bins) of the rank being selected.
var<workgroup> pick: vec2<u32>;
// (deviations below the MAD, deviations equal to it), for noise_offset.
var<workgroup> ties: vec2<u32>;

fn pixel(img: u32, i: u32) -> u32 {
    let w = pixels[img * u.b.words_per_image + i / 2u];
    return (w >> ((i & 1u) * 16u)) & 0xFFFFu;
}

// The pixel at column c of the tile's r-th sampled row (rows y0, y0 + 2, ...), or its
// distance from `centre` when `dev` is set.
fn tile_value(img: u32, x0: u32, y0: u32, c: u32, r: u32, centre: u32, dev: bool) -> u32 {
    let v = pixel(img, (y0 + 2u * r) * u.p.width + x0 + c);
    if (dev) {
        return select(centre - v, v - centre, v >= centre);
    }
    return v;
}

// A thread's walk over the tile: elements lid, lid + WG, ... as (column, row), stepped without
// division.
struct Walk {
    c: u32,
    r: u32,
}

fn walk_start(lid: u32, tw: u32) -> Walk {
    return Walk(lid % tw, lid / tw);
}

fn walk_next(w: Walk, tw: u32) -> Walk {
    var c = w.c + WG % tw;
    var r = w.r + WG / tw;
    if (c >= tw) {
        c -= tw;
        r += 1u;
    }
    return Walk(c, r);
}

const WG: u32 = 64u;

fn clear_hist(lid: u32) {
    for (var b = lid; b < 256u; b += WG) {
        atomicStore(&hist[b], 0u);
    }
    workgroupBarrier();
}

// Thread 0: the bin holding `rank`, into `pick`.
fn find_bin(rank: u32) {
    var below = 0u;
    for (var b = 0u; b < 256u; b++) {
        let n = atomicLoad(&hist[b]);
        if (below + n > rank) {
            pick = vec2<u32>(b, below);
            return;
        }
        below += n;
    }
}

// The value of rank `rank` among the n tile values (or their distances from `centre`).
fn radix_select(img: u32, x0: u32, y0: u32, tw: u32, n: u32, rank: u32, centre: u32, dev: bool, lid: u32) -> u32 {
    clear_hist(lid);
    var at = walk_start(lid, tw);
    for (var k = lid; k < n; k += WG) {
        atomicAdd(&hist[tile_value(img, x0, y0, at.c, at.r, centre, dev) >> 8u], 1u);
        at = walk_next(at, tw);
    }
    workgroupBarrier();
    if (lid == 0u) {
        find_bin(rank);
    }
    let first = workgroupUniformLoad(&pick);
    clear_hist(lid);
    at = walk_start(lid, tw);
    for (var k = lid; k < n; k += WG) {
        let v = tile_value(img, x0, y0, at.c, at.r, centre, dev);
        if ((v >> 8u) == first.x) {
            atomicAdd(&hist[v & 0xFFu], 1u);
        }
        at = walk_next(at, tw);
    }
    workgroupBarrier();
    if (lid == 0u) {
        find_bin(rank - first.y);
        ties = vec2<u32>(first.y + pick.y, atomicLoad(&hist[pick.x]));
    }
    let second = workgroupUniformLoad(&pick);
    return (first.x << 8u) | second.x;
}

// Thread 0, 8-bit: median and MAD from the value histogram, into `pick` (the MAD's ties into
// `ties`).
fn median_mad_8bit(rank: u32) {
    find_bin(rank);
    let median = pick.x;
    var seen = atomicLoad(&hist[median]);
    var below = 0u;
    var d = 0u;
    while (seen <= rank) {
        below = seen;
        d++;
        if (median + d < 256u) {
            seen += atomicLoad(&hist[median + d]);
        }
        if (d <= median) {
            seen += atomicLoad(&hist[median - d]);
        }
    }
    pick = vec2<u32>(median, d);
    ties = vec2<u32>(below, seen - below);
}

// The tile's offset (CPU twin: src/cpu/threshold.rs noise_offset, which says why): ceil(k_mad
// · max(MAD, 1)), a MAD of 1 to GROUPED_MAD_MAX counts taken as the grouped median. Integer
// counts and exact f32 products only: the same on every GPU as on the CPU.
const GROUPED_MAD_MAX: u32 = 4u;

fn whole_offset(k_mad: f32, mad: u32) -> u32 {
    return u32(ceil(k_mad * f32(max(mad, 1u))));
}

fn noise_offset(k_mad: f32, mad: u32, below: u32, at: u32, rank: u32) -> u32 {
    if (mad == 0u || mad > GROUPED_MAD_MAX || at == 0u) {
        return whole_offset(k_mad, mad);
    }
    let num = (2u * mad - 1u) * at + 2u * (rank - below) + 1u;
    let den = 2u * at;
    if (num <= den) {
        return whole_offset(k_mad, 1u);
    }
    let t = k_mad * f32(num);
    var o = u32(ceil(t / f32(den)));
    while (f32(o) * f32(den) < t) {
        o++;
    }
    while (o > 0u && f32(o - 1u) * f32(den) >= t) {
        o--;
    }
    return o;
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = u.p;
    let x0 = wg.x * p.tile;
    let y0 = wg.y * p.tile;
    let tw = min(x0 + p.tile, p.width) - x0;
    // Every other row: half the work, and as good a median and MAD.
    let n = tw * ((min(y0 + p.tile, p.height) - y0 + 1u) / 2u);
    let rank = (n - 1u) / 2u;
    var stats: vec2<u32>;
    if (p.saturation <= 255u) {
        clear_hist(lid);
        var at = walk_start(lid, tw);
        for (var k = lid; k < n; k += WG) {
            atomicAdd(&hist[tile_value(wg.z, x0, y0, at.c, at.r, 0u, false) & 0xFFu], 1u);
            at = walk_next(at, tw);
        }
        workgroupBarrier();
        if (lid == 0u) {
            median_mad_8bit(rank);
        }
        stats = workgroupUniformLoad(&pick);
    } else {
        let median = radix_select(wg.z, x0, y0, tw, n, rank, 0u, false, lid);
        stats = vec2<u32>(median, radix_select(wg.z, x0, y0, tw, n, rank, median, true, lid));
    }
    let counts = workgroupUniformLoad(&ties);
    if (lid == 0u) {
        let t = wg.z * u.b.tiles_per_image + wg.y * p.tiles_x + wg.x;
        tiles[t] = TileStats(stats.x, noise_offset(p.k_mad, stats.y, counts.x, counts.y, rank));
    }
}
