// Stage tile_clip, kernel 2 of 2 (CPU twin: src/cpu/tile_clip.rs tile_clip_with): a tile whose
// level (background + offset) stands more than CLIP_OFFSETS of its sky's offsets above its
// sky's level takes its sky when it, or one of the 8 tiles about it, is a bloated star's body
// (median more than BODY_OFFSETS of its sky's offsets above its sky); neither margin more than
// half the headroom between the sky and saturation. One invocation per tile;
// dispatch (tiles, images), striding.

@group(0) @binding(0) var<uniform> u: DetectUniform;
@group(0) @binding(1) var<storage, read> tiles_raw: array<TileStats>;
@group(0) @binding(2) var<storage, read> sky: array<TileStats>;
@group(0) @binding(3) var<storage, read_write> tiles: array<TileStats>;

const CLIP_OFFSETS: u32 = 3u;
const BODY_OFFSETS: u32 = 4u;

// At most half the headroom from the sky to saturation (CPU twin: margin).
fn margin(offsets: u32, s: TileStats) -> u32 {
    var headroom = 0u;
    if (u.p.saturation > s.background) {
        headroom = u.p.saturation - s.background;
    }
    return min(offsets * s.offset, headroom / 2u);
}

fn stands_out(t: TileStats, s: TileStats) -> bool {
    return t.background + t.offset > s.background + s.offset + margin(CLIP_OFFSETS, s);
}

fn body(t: TileStats, s: TileStats) -> bool {
    return t.background > s.background + margin(BODY_OFFSETS, s);
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let base = gid.y * u.b.tiles_per_image;
    let tx = i32(u.p.tiles_x);
    let ty = i32(u.p.tiles_y);
    for (var t = gid.x; t < u.b.tiles_per_image; t += nwg.x * 256u) {
        let x = i32(t % u.p.tiles_x);
        let y = i32(t / u.p.tiles_x);
        var out = tiles_raw[base + t];
        if (stands_out(out, sky[base + t])) {
            var near_body = false;
            for (var ny = max(y - 1, 0); ny <= min(y + 1, ty - 1); ny++) {
                for (var nx = max(x - 1, 0); nx <= min(x + 1, tx - 1); nx++) {
                    let i = base + u32(ny * tx + nx);
                    near_body = near_body || body(tiles_raw[i], sky[i]);
                }
            }
            if (near_body) {
                out = sky[base + t];
            }
        }
        tiles[base + t] = out;
    }
}
