//! Stage `tile_clip` (CPU twins of `shaders/tile_clip_sky.wgsl` and `shaders/tile_clip.wgsl`):
//! a bloated star's tiles take the sky about them. A tile's median is the sky's while stars cover
//! less than half of it; a photographic plate's bloated stars (20–150 px across with their
//! halos) fill whole tiles, whose median and MAD are then the star's own level and slope: the
//! star stays under its own threshold, or only a crescent of its halo passes it, and its fainter
//! neighbours (a double exposure's fainter copies) become the brightest detections.
//!
//! The sky about a tile is the lower medians of the backgrounds and offsets of the 7 × 7 tiles
//! about it. A tile *stands out* when its level (background + offset) is more than
//! [`CLIP_OFFSETS`] of its sky's offsets above its sky's level; it is a star's *body* when its
//! median is more than [`BODY_OFFSETS`] of them above its sky's background. Neither margin
//! exceeds half the headroom between the sky and saturation ([`margin`]): on a grainy 8-bit
//! scan (σ ≈ 12 ADU, sky 117) 20σ above the sky is past 255, and the saturated flat tops of the
//! brightest stars would be no body, their tiles' thresholds above their own peaks. A tile that stands
//! out takes its sky when it or one of its 8 neighbours is a body: the body and its rim, whose
//! MAD the star's slope inflates. The edge of a lit tree or roof stands out by its spread, but
//! is no body, and keeps its statistics. Integers only: the GPU computes the same.

use super::threshold::{DetectParams, TileStats, tile_stats};

/// Tiles on each side of a tile that make its neighbourhood (7 × 7 tiles): a star whose halo
/// covers up to 4 × 4 tiles (130 px at the default 32) leaves most of the 49 to the sky, its
/// central tiles included.
pub const CLIP_REACH: i32 = 3;

/// How many of the neighbourhood's offsets (each about 5σ) a tile's level may stand above the
/// neighbourhood's before it is clipped: 3, about 15σ, which sky under a gradient (amp glow,
/// twilight, vignetting) does not climb within two tiles, and which a faint nebula's tiles do
/// not reach in one exposure.
pub const CLIP_OFFSETS: u32 = 3;

/// How many of its sky's offsets a tile's median must stand above its sky for the tile to be
/// a star's body.
pub const BODY_OFFSETS: u32 = 4;

/// The sky about each tile: the lower medians of the backgrounds and of the offsets of the
/// tiles within [`CLIP_REACH`] (those inside the frame). Kernel 1 of the stage.
pub fn tile_clip_sky(tiles: &[TileStats], p: &DetectParams) -> Vec<TileStats> {
    let mut scratch = Scratch::default();
    (0..p.tiles_y as i32)
        .flat_map(|y| (0..p.tiles_x as i32).map(move |x| (x, y)))
        .map(|(x, y)| sky_about(tiles, p, x, y, &mut scratch))
        .collect()
}

#[derive(Default)]
struct Scratch {
    bg: Vec<u32>,
    off: Vec<u32>,
}

/// The sky about tile (x, y): [`tile_clip_sky`]'s value for it.
fn sky_about(tiles: &[TileStats], p: &DetectParams, x: i32, y: i32, s: &mut Scratch) -> TileStats {
    let (tx, ty) = (p.tiles_x as i32, p.tiles_y as i32);
    s.bg.clear();
    s.off.clear();
    for ny in (y - CLIP_REACH).max(0)..=(y + CLIP_REACH).min(ty - 1) {
        for nx in (x - CLIP_REACH).max(0)..=(x + CLIP_REACH).min(tx - 1) {
            let t = tiles[(ny * tx + nx) as usize];
            s.bg.push(t.background);
            s.off.push(t.offset);
        }
    }
    // The lower median by selection: the value sorting would put there, in linear time.
    let k = (s.bg.len() - 1) / 2;
    TileStats {
        background: *s.bg.select_nth_unstable(k).1,
        offset: *s.off.select_nth_unstable(k).1,
    }
}

/// How far above its sky a tile must stand, for `offsets` of the sky's offsets: that many, but
/// no more than half the headroom from the sky's background to `saturation`, so that a flat
/// top at the format's ceiling is a body however noisy the sky. Nondecreasing in the sky's
/// background and offset (`tile_clip`'s early bounds rely on it). Backgrounds ≤ 65535 and
/// offsets ≤ 7.42 · 65535: no sum here overflows.
pub fn margin(offsets: u32, sky: TileStats, saturation: u32) -> u32 {
    (offsets * sky.offset).min(saturation.saturating_sub(sky.background) / 2)
}

/// Whether a tile's level stands more than [`CLIP_OFFSETS`] of its sky's offsets (at most
/// half the headroom, [`margin`]) above its sky's level.
fn stands_out(t: TileStats, sky: TileStats, saturation: u32) -> bool {
    t.background + t.offset > sky.background + sky.offset + margin(CLIP_OFFSETS, sky, saturation)
}

/// Whether a tile is a bloated star's body: its median, more than half its pixels, stands
/// [`BODY_OFFSETS`] of its sky's offsets (about 20σ; at most half the headroom, [`margin`])
/// above its sky. A lit tree's or roof's edge stands out by its spread more than by its median.
fn body(t: TileStats, sky: TileStats, saturation: u32) -> bool {
    t.background > sky.background + margin(BODY_OFFSETS, sky, saturation)
}

/// The tiles of one frame, clipped (see the module documentation): a tile that stands out
/// takes its sky when it, or one of the 8 tiles about it, is a star's body (a body's rim,
/// whose MAD the star's slope inflates). `tiles` in row order, `p.tiles_x` × `p.tiles_y`;
/// `sky` from [`tile_clip_sky`]. Kernel 2 of the stage.
pub fn tile_clip_with(tiles: &[TileStats], sky: &[TileStats], p: &DetectParams) -> Vec<TileStats> {
    let (tx, ty) = (p.tiles_x as i32, p.tiles_y as i32);
    let at = |x: i32, y: i32| (y * tx + x) as usize;
    let mut out = tiles.to_vec();
    for y in 0..ty {
        for x in 0..tx {
            let i = at(x, y);
            if !stands_out(tiles[i], sky[i], p.saturation) {
                continue;
            }
            let near_body = ((y - 1).max(0)..=(y + 1).min(ty - 1)).any(|ny| {
                ((x - 1).max(0)..=(x + 1).min(tx - 1))
                    .any(|nx| body(tiles[at(nx, ny)], sky[at(nx, ny)], p.saturation))
            });
            if near_body {
                out[i] = sky[i];
            }
        }
    }
    out
}

/// The stage: the tiles [`tile_clip_with`] makes of [`tile_clip_sky`]'s, with the sky taken
/// only about the tiles that could use it. Every tile's sky is at least the frame's least
/// background and least offset (a lower median of values no lower), so a tile whose level is
/// within that least sky's clip bound neither stands out nor is a body; on a star field that is
/// nearly every tile, and the 49-tile medians were a fifth of a frame's CPU time.
pub fn tile_clip(tiles: &[TileStats], p: &DetectParams) -> Vec<TileStats> {
    let (tx, ty) = (p.tiles_x as i32, p.tiles_y as i32);
    let at = |x: i32, y: i32| (y * tx + x) as usize;
    let least = TileStats {
        background: tiles.iter().map(|t| t.background).min().unwrap_or(0),
        offset: tiles.iter().map(|t| t.offset).min().unwrap_or(0),
    };
    let sat = p.saturation;
    let clip_bound = least.background + least.offset + margin(CLIP_OFFSETS, least, sat);
    let body_bound = least.background + margin(BODY_OFFSETS, least, sat);
    let mut sky: Vec<Option<TileStats>> = vec![None; tiles.len()];
    let mut scratch = Scratch::default();
    let mut sky_at = |x: i32, y: i32| {
        *sky[at(x, y)].get_or_insert_with(|| sky_about(tiles, p, x, y, &mut scratch))
    };
    let mut out = tiles.to_vec();
    for y in 0..ty {
        for x in 0..tx {
            let t = tiles[at(x, y)];
            if t.background + t.offset <= clip_bound || !stands_out(t, sky_at(x, y), sat) {
                continue;
            }
            let mut near_body = false;
            'around: for ny in (y - 1).max(0)..=(y + 1).min(ty - 1) {
                for nx in (x - 1).max(0)..=(x + 1).min(tx - 1) {
                    let n = tiles[at(nx, ny)];
                    if n.background > body_bound && body(n, sky_at(nx, ny), sat) {
                        near_body = true;
                        break 'around;
                    }
                }
            }
            if near_body {
                out[at(x, y)] = sky_at(x, y);
            }
        }
    }
    out
}

/// The tiles detection thresholds against, as the GPU leaves them: [`tile_stats`] of the
/// pixels, then this stage.
pub fn clipped_tile_stats(pixels: &[u16], p: &DetectParams) -> Vec<TileStats> {
    tile_clip(&tile_stats(pixels, p), p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn the_stage_takes_the_sky_only_where_needed_and_gives_what_both_kernels_give() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut clipped = 0;
        for case in 0..200 {
            let (tx, ty) = (rng.random_range(1..12), rng.random_range(1..10));
            let p = params(tx, ty);
            // Sky with a gradient, scattered stars, bodies and flat (offset 0) tiles.
            let tiles: Vec<TileStats> = (0..tx * ty)
                .map(|i| {
                    let sky = 1000 + 15 * (i % tx) + rng.random_range(0..20);
                    match rng.random_range(0..10) {
                        0 => TileStats {
                            background: sky + rng.random_range(0..40000),
                            offset: rng.random_range(0..2000),
                        },
                        1 if case % 3 == 0 => TileStats {
                            background: rng.random_range(0..70000),
                            offset: 0,
                        },
                        _ => TileStats {
                            background: sky,
                            offset: rng.random_range(20..40),
                        },
                    }
                })
                .collect();
            let want = tile_clip_with(&tiles, &tile_clip_sky(&tiles, &p), &p);
            assert_eq!(tile_clip(&tiles, &p), want, "case {case}");
            clipped += usize::from(want != tiles);
        }
        assert!(clipped > 20, "only {clipped} cases clip a tile");
    }

    fn params(tx: u32, ty: u32) -> DetectParams {
        DetectParams::new(tx * 32, ty * 32, 32, 5.0, 65535)
    }

    #[test]
    fn a_bloated_star_s_tiles_take_the_sky_and_the_sky_is_left_alone() {
        let p = params(10, 8);
        // A gentle gradient, 20 ADU per tile across the frame: never clipped.
        let sky: Vec<TileStats> = (0..80)
            .map(|i| TileStats {
                background: 1000 + 20 * (i % 10) as u32,
                offset: 30,
            })
            .collect();
        assert_eq!(tile_clip(&sky, &p), sky);
        // A bloated star: a flat top of 2 × 2 tiles at its own level, a ring whose MAD its
        // slope inflates, one tile of faint halo.
        let mut tiles = sky.clone();
        for y in 2..6 {
            for x in 3..7 {
                let inner = (3..5).contains(&y) && (4..6).contains(&x);
                tiles[y * 10 + x] = if inner {
                    TileStats {
                        background: 40000,
                        offset: 40,
                    }
                } else {
                    TileStats {
                        background: sky[y * 10 + x].background + 300,
                        offset: 900,
                    }
                };
            }
        }
        tiles[2 * 10 + 3] = TileStats {
            background: 1090,
            offset: 60,
        };
        let clipped = tile_clip(&tiles, &p);
        for (i, (c, t)) in clipped.iter().zip(&tiles).enumerate() {
            if i == 23 || !(2..6).contains(&(i / 10)) || !(3..7).contains(&(i % 10)) {
                assert_eq!(c, t, "tile {i} kept");
            } else {
                assert!(
                    c.background < 1200 && c.offset == 30,
                    "tile {i} clipped: {c:?}"
                );
            }
        }
    }
}
