// Stage tile_clip, kernel 1 of 2 (CPU twin: src/cpu/tile_clip.rs tile_clip_sky): the sky about
// each tile, the lower medians of the backgrounds and of the offsets of the 7 x 7 tiles about
// it (those inside the frame). One invocation per tile; dispatch (tiles, images), striding.

@group(0) @binding(0) var<uniform> u: DetectUniform;
@group(0) @binding(1) var<storage, read> tiles_raw: array<TileStats>;
@group(0) @binding(2) var<storage, read_write> sky: array<TileStats>;

const CLIP_REACH: i32 = 3;

// Element (n - 1) / 2 of the first n of v sorted: the lower median (insertion sort of <= 49).
fn lower_median(v: ptr<function, array<u32, 49>>, n: u32) -> u32 {
    for (var i = 1u; i < n; i++) {
        let x = (*v)[i];
        var j = i;
        while (j > 0u && (*v)[j - 1u] > x) {
            (*v)[j] = (*v)[j - 1u];
            j--;
        }
        (*v)[j] = x;
    }
    return (*v)[(n - 1u) / 2u];
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let base = gid.y * u.b.tiles_per_image;
    let tx = i32(u.p.tiles_x);
    let ty = i32(u.p.tiles_y);
    for (var t = gid.x; t < u.b.tiles_per_image; t += nwg.x * 256u) {
        let x = i32(t % u.p.tiles_x);
        let y = i32(t / u.p.tiles_x);
        var bg: array<u32, 49>;
        var off: array<u32, 49>;
        var n = 0u;
        for (var ny = max(y - CLIP_REACH, 0); ny <= min(y + CLIP_REACH, ty - 1); ny++) {
            for (var nx = max(x - CLIP_REACH, 0); nx <= min(x + CLIP_REACH, tx - 1); nx++) {
                let s = tiles_raw[base + u32(ny * tx + nx)];
                bg[n] = s.background;
                off[n] = s.offset;
                n++;
            }
        }
        sky[base + t] = TileStats(lower_median(&bg, n), lower_median(&off, n));
    }
}
