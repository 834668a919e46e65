//! Stage `threshold` (CPU twin) on hand-made inputs.

use crate::common;

use gpustar::cpu::threshold::*;

#[test]
fn flat_tiles_interpolate_exactly() {
    let p = DetectParams::new(100, 70, 16, 5.0, 255);
    let tiles = vec![
        TileStats {
            background: 10,
            offset: 3
        };
        (p.tiles_x * p.tiles_y) as usize
    ];
    for (x, y) in [(0, 0), (99, 69), (50, 33), (7, 8)] {
        assert_eq!(background_at(&tiles, &p, x, y), 10);
        assert_eq!(level_scaled(&tiles, &p, x, y), 13 * 4 * 16 * 16);
    }
}

#[test]
fn gradient_is_followed_between_tile_centres() {
    // Two tiles side by side with backgrounds 0 and 64: halfway between their centres
    // (x = 7.5 + 8 = 15.5) the background is 32.
    let p = DetectParams::new(32, 16, 16, 5.0, 255);
    let tiles = [
        TileStats {
            background: 0,
            offset: 0,
        },
        TileStats {
            background: 64,
            offset: 0,
        },
    ];
    assert_eq!(background_at(&tiles, &p, 7, 0), 0);
    assert_eq!(background_at(&tiles, &p, 24, 0), 64);
    let mid = (interpolate(&tiles, &p, 15, 0, |t| t.background)
        + interpolate(&tiles, &p, 16, 0, |t| t.background)) as f64
        / 2.0
        / (4.0 * 16.0 * 16.0);
    assert!((mid - 32.0).abs() < 1e-9);
}

#[test]
fn median_and_mad_ignore_a_bright_star() {
    let p = DetectParams::new(8, 8, 8, 5.0, 255);
    let mut px: Vec<u16> = (0..64).map(|i| 100 + (i % 5) as u16).collect();
    // A star on row 2, one of the rows the statistics sample.
    px[19] = 250;
    px[20] = 240;
    let t = tile_stats(&px, &p);
    assert_eq!(t[0].background, 102);
    // |v − 102| over 0..4 cycles: MAD 1, 7 deviations below it and 13 at it, grouped
    // 0.5 + (15.5 − 7) / 13 = 1.154 → offset ceil(5 · 1.4826 · 1.154) = 9.
    assert_eq!(t[0].offset, 9);
    let runs = threshold(&px, &t, &p);
    assert_eq!(runs, vec![Run { y: 2, x0: 3, x1: 5 }]);
    assert_eq!(dense_mask(&runs, 8, 8).iter().sum::<u32>(), 2);
}

/// Pseudo-random 8-bit pixels and tile statistics for the frame of `p`.
fn random_pixels_and_tiles(p: &DetectParams, seed: u32) -> (Vec<u16>, Vec<TileStats>) {
    let mut seed = seed;
    let mut next = || {
        seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
        seed >> 16
    };
    let px: Vec<u16> = (0..p.width * p.height)
        .map(|_| (next() % 256) as u16)
        .collect();
    let tiles: Vec<TileStats> = (0..p.tiles_x * p.tiles_y)
        .map(|_| TileStats {
            background: next() % 200,
            offset: next() % 40,
        })
        .collect();
    (px, tiles)
}

#[test]
fn row_wise_runs_equal_the_per_pixel_definition() {
    // Pseudo-random pixels and tile statistics: the runs must mark exactly the pixels with
    // pixel · (2·tile)² > level_scaled(x, y), the definition the GPU kernel evaluates.
    let (w, h) = (77u32, 51u32);
    let p = DetectParams::new(w, h, 8, 3.0, 255);
    let (px, tiles) = random_pixels_and_tiles(&p, 12345);
    let mask = dense_mask(&threshold(&px, &tiles, &p), w, h);
    let s2 = 4 * p.tile * p.tile;
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let want = (px[i] as u32 * s2 > level_scaled(&tiles, &p, x, y)) as u32;
            assert_eq!(mask[i], want, "pixel ({x}, {y})");
        }
    }
}

/// Pixels at or just below their own level (by up to `below`), a few just above it, and some
/// bright spots, on tiles of varied levels: the frame `scan` passes over block by block, with
/// most blocks at or below the least level of their tiles and many pixels between that and
/// their own. 16-bit levels (`level(x, y)`, in ADU) from `level_of`; spots every 97 px and on
/// block edges.
fn pixels_hugging_the_levels(
    p: &DetectParams,
    seed: u32,
    below: i64,
    level_of: impl Fn(u32, u32) -> u32,
) -> Vec<u16> {
    let mut seed = seed;
    let (w, h) = (p.width, p.height);
    (0..w * h)
        .map(|i| {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            let (x, y) = (i % w, i / w);
            let level = level_of(x, y) as i64;
            let r = (seed >> 16) % 100;
            let v = match r {
                0 => level + 1 + (seed >> 8) as i64 % 3,
                1..=39 => level,
                _ => level - 1 - (seed >> 20) as i64 % below,
            };
            let spot = (x % 97 == 5 || [31, 32, 63, 64].contains(&x) || x + 1 == w) && y % 7 == 3;
            (if spot { v + 500 } else { v }).clamp(0, 65535) as u16
        })
        .collect()
}

/// Tile statistics for [`runs_passed_over_by_blocks_equal_the_per_pixel_definition`].
#[derive(Clone, Copy, Debug)]
enum Tiles {
    /// Background 2500, offset 20 everywhere.
    Flat,
    /// Backgrounds 2000..3000 and offsets 5..60 from tile to tile, a third of them as `Flat`.
    Varied,
    /// One level per tile row, falling 150 a row: a floor kept from the rows above would pass
    /// over set pixels.
    Falling,
}

fn tiles_of(p: &DetectParams, seed: u32, kind: Tiles) -> Vec<TileStats> {
    let mut seed = seed;
    let flat = TileStats {
        background: 2500,
        offset: 20,
    };
    (0..p.tiles_x * p.tiles_y)
        .map(|i| {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            match kind {
                Tiles::Flat => flat,
                Tiles::Varied if i % 3 == 0 => flat,
                Tiles::Varied => TileStats {
                    background: 2000 + (seed >> 16) % 1000,
                    offset: 5 + (seed >> 8) % 56,
                },
                Tiles::Falling => TileStats {
                    background: 3000 - 150 * (i / p.tiles_x).min(15),
                    offset: 20,
                },
            }
        })
        .collect()
}

#[test]
fn runs_passed_over_by_blocks_equal_the_per_pixel_definition() {
    // `scan` passes over 32 columns at a time against floors taken per pair of tile rows and
    // per row; on frames whose pixels hug their levels, over tiles of one level, of varied
    // ones and of levels falling down the frame, with widths that are and are not multiples of 32 and tiles of 8 to 64, the runs
    // must still be exactly the definition's, with and without the matched filter.
    let mut blocks_passed = 0;
    for (case, &(w, h, tile, kind)) in [
        (1000u32, 70u32, 32u32, Tiles::Varied),
        (1000, 70, 32, Tiles::Flat),
        (333, 97, 16, Tiles::Varied),
        (333, 97, 16, Tiles::Falling),
        (64, 40, 8, Tiles::Varied),
        (31, 33, 8, Tiles::Varied),
        (160, 130, 64, Tiles::Varied),
        (200, 50, 16, Tiles::Flat),
    ]
    .iter()
    .enumerate()
    {
        let case = case as u32;
        let p = DetectParams::new(w, h, tile, 5.0, 65535);
        let tiles = tiles_of(&p, 100 + case, kind);
        let s2 = 4 * tile * tile;
        let px = pixels_hugging_the_levels(&p, 200 + case, 40, |x, y| {
            level_scaled(&tiles, &p, x, y) / s2
        });
        let mask = dense_mask(&threshold(&px, &tiles, &p), w, h);
        let mut set = 0;
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                let want = (px[i] as u32 * s2 > level_scaled(&tiles, &p, x, y)) as u32;
                assert_eq!(
                    mask[i], want,
                    "{kind:?} {w}×{h}, tile {tile}: pixel ({x}, {y})"
                );
                set += want;
            }
            // Blocks of 32 wholly at or below the least level of the tiles.
            let least = tiles.iter().map(|t| t.background + t.offset).min().unwrap();
            blocks_passed += px[(y * w) as usize..((y + 1) * w) as usize]
                .chunks_exact(32)
                .filter(|b| b.iter().all(|&v| (v as u32) <= least))
                .count();
        }
        assert!(set > 5 && set < w * h / 10, "{w}×{h}: {set} set");

        let pf = p.with_filter(true);
        // Closer to the level: many binomial sums just above it or just below (the filter's
        // blocks are passed over by their sums).
        let px = pixels_hugging_the_levels(&pf, 300 + case, 2, |x, y| {
            filtered_level_at(&tiles, &pf, x, y) / 16
        });
        let what = format!("filtered {kind:?} {w}×{h}, tile {tile}");
        let set = assert_filtered_mask_is_the_definition(&px, &tiles, &pf, &what);
        assert!(set > 0, "{what}: none set");
    }
    assert!(
        blocks_passed > 500,
        "{blocks_passed} blocks at or below every level"
    );
}

#[test]
fn tile_stats_are_the_median_and_mad_of_each_tile_s_even_rows() {
    // Tiles of 16 over a 100 × 70 frame (edge tiles cut short, odd counts), with a gradient
    // (each tile's search starts from its neighbour's values) and bright stars; 8-bit and
    // 16-bit values, the latter spanning 0..65535.
    let (w, h) = (100u32, 70u32);
    let mut seed = 99u32;
    let mut next = || {
        seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
        seed >> 16
    };
    let eight: Vec<u16> = (0..w * h)
        .map(|i| {
            let star = if i % 97 == 0 { 200 } else { 0 };
            (next() as u16 % 23 + (i % w) as u16 / 3 + star).min(255)
        })
        .collect();
    let sixteen: Vec<u16> = (0..w * h)
        .map(|i| match i % 211 {
            0 => u16::MAX,
            1 => 0,
            _ => (next() as u16 % 400).saturating_add((i / w) as u16 * 600),
        })
        .collect();
    // Noise of a count or two (MADs 0 to 3, read grouped), 8-bit and 16-bit.
    let quiet = |base: u16| -> Vec<u16> {
        let mut seed = 5u32;
        (0..w * h)
            .map(|i| {
                seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
                let spread = 1 + (i % w) / 15;
                base + ((seed >> 16) % (2 * spread + 1)) as u16
            })
            .collect()
    };
    let (quiet8, quiet16) = (quiet(12), quiet(3000));
    for (px, saturation) in [
        (&eight, 255),
        (&sixteen, 65535),
        (&quiet8, 255),
        (&quiet16, 65535),
    ] {
        let p = DetectParams::new(w, h, 16, 5.0, saturation);
        let got = tile_stats(px, &p);
        let mut offsets = std::collections::BTreeSet::new();
        for ty in 0..p.tiles_y {
            for tx in 0..p.tiles_x {
                let (x0, y0) = (tx * 16, ty * 16);
                let mut v: Vec<u16> = (y0..(y0 + 16).min(h))
                    .step_by(2)
                    .flat_map(|y| (x0..(x0 + 16).min(w)).map(move |x| (y * w + x) as usize))
                    .map(|i| px[i])
                    .collect();
                let rank = (v.len() - 1) / 2;
                v.sort_unstable();
                let median = v[rank];
                let mut dev: Vec<u16> = v.iter().map(|x| x.abs_diff(median)).collect();
                dev.sort_unstable();
                let want = TileStats {
                    background: median as u32,
                    offset: grouped_offset(p.k_mad, &dev),
                };
                assert_eq!(
                    got[(ty * p.tiles_x + tx) as usize],
                    want,
                    "{saturation} {tx} {ty}"
                );
                offsets.insert(want.offset);
            }
        }
        assert!(offsets.len() > 3, "varied tiles: {offsets:?}");
    }
}

/// The offset of a tile with sorted deviations `dev`, computed as the definition reads (in
/// f64): ceil(k_mad · max(m, 1)), m the MAD, or for a MAD of 1 to `GROUPED_MAD_MAX` the grouped
/// median mad − ½ + (rank + ½ − below) / at.
fn grouped_offset(k_mad: f32, dev: &[u16]) -> u32 {
    let rank = (dev.len() - 1) / 2;
    let mad = dev[rank];
    let m = if (1..=GROUPED_MAD_MAX as u16).contains(&mad) {
        let below = dev.iter().filter(|&&d| d < mad).count() as f64;
        let at = dev.iter().filter(|&&d| d == mad).count() as f64;
        (mad as f64 - 0.5 + (rank as f64 + 0.5 - below) / at).max(1.0)
    } else {
        mad.max(1) as f64
    };
    (k_mad as f64 * m).ceil() as u32
}

/// Whole counts put the MAD of noise of two counts at 1 in most tiles, and a 5σ threshold at
/// 3.8σ: the grouped MAD puts it back at 5σ. Noise of σ = 2.1 counts in whole counts (as an
/// 8-bit JPEG's sky): MAD 1, grouped 1.43, σ = 1.4826 · 1.43 = 2.12.
#[test]
fn a_mad_of_whole_counts_is_read_grouped() {
    // 512 sky values (a 32-pixel tile's even rows) with the shares of a Gaussian of σ 2.1
    // rounded to whole counts: deviations 0, ±1, ±2, ... from 12.
    let shares = [96, 172, 124, 70, 32, 12, 4, 2];
    assert_eq!(shares.iter().sum::<u32>(), 512);
    let mut px: Vec<u16> = Vec::new();
    for (d, &n) in shares.iter().enumerate() {
        for k in 0..n {
            let up = d == 0 || k % 2 == 0;
            px.push(if up { 12 + d as u16 } else { 12 - d as u16 });
        }
    }
    // One tile of 32 × 32 whose even rows hold those values (odd rows are not sampled).
    let mut frame = vec![12u16; 32 * 32];
    for (k, &v) in px.iter().enumerate() {
        frame[(k / 32) * 2 * 32 + k % 32] = v;
    }
    let p = DetectParams::new(32, 32, 32, 5.0, 255);
    let t = tile_stats(&frame, &p)[0];
    assert_eq!(t.background, 12);
    // Below the MAD: 96 zeros; at it: 172 ones. m = 0.5 + (255.5 − 96) / 172 = 1.427.
    let m: f64 = 0.5 + (255.5 - 96.0) / 172.0;
    assert_eq!(t.offset, (p.k_mad as f64 * m).ceil() as u32);
    // Whole counts gave ceil(7.413 · 1) = 8: a 3.8σ threshold for this noise.
    assert_eq!(t.offset, 11, "ceil(7.413 · 1.427)");
    assert_eq!(noise_offset(p.k_mad, 1, 96, 172, 255), 11);
    assert_eq!(
        noise_offset(p.k_mad, 1, 200, 300, 255),
        8,
        "grouped below 1: the floor"
    );
    assert_eq!(noise_offset(p.k_mad, 0, 0, 400, 255), 8, "MAD 0: the floor");
    assert_eq!(
        noise_offset(p.k_mad, 9, 200, 50, 255),
        67,
        "above GROUPED_MAD_MAX: whole"
    );
}

/// The grouped MAD's offset is the least o with o · 2at ≥ fl(k_mad · num), exactly, for every
/// count a tile can hold (both twins compute it so).
#[test]
fn the_grouped_offset_is_exact() {
    for k_sigma in [3.0f32, 4.5, 5.0, 6.0] {
        let k_mad = k_sigma * 1.4826;
        for mad in 1..=GROUPED_MAD_MAX {
            for n in [1u32, 2, 7, 255, 256, 512, 1024, 2048] {
                let rank = (n - 1) / 2;
                for below in (0..=rank).step_by(7) {
                    for at in (rank + 1 - below..=n - below).step_by(5) {
                        let o = noise_offset(k_mad, mad, below, at, rank);
                        let num = (2 * mad - 1) * at + 2 * (rank - below) + 1;
                        let den = 2 * at;
                        if num <= den {
                            assert_eq!(o, (k_mad * 1.0).ceil() as u32);
                            continue;
                        }
                        let t = k_mad * num as f32;
                        assert!(o as f64 * den as f64 >= t as f64, "{mad} {below} {at}");
                        assert!(
                            ((o - 1) as f64) * (den as f64) < t as f64,
                            "{mad} {below} {at}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn gpu_equals_cpu_on_simulated_8_and_16_bit_frames() {
    let Some(g) = common::gpu("gpu_equals_cpu_on_simulated_8_and_16_bit_frames") else {
        return;
    };
    let n8 =
        common::assert_detect_stages_equal(&g, &common::sim_frames(4, (640, 480), 18.0, 8, 11), 32);
    let n16 = common::assert_detect_stages_equal(
        &g,
        &common::sim_frames(3, (500, 333), 10.0, 16, 12),
        32,
    );
    assert!(n8 > 50 && n16 > 20, "{n8} and {n16} blobs compared");
}

/// Quiet frames, whose tiles' MADs of 0 to 4 counts are read grouped: the GPU kernel's counts
/// about the MAD (from its 8-bit histogram, or its 16-bit radix select) and its offsets are the
/// CPU twin's.
#[test]
fn gpu_equals_cpu_where_the_mad_is_grouped() {
    let Some(g) = common::gpu("gpu_equals_cpu_where_the_mad_is_grouped") else {
        return;
    };
    let (w, h) = (256u32, 96u32);
    for (base, saturation) in [(12u16, 255u16), (3000, 65535)] {
        let mut seed = 17u32;
        let frames: Vec<gpustar::io::frame::Frame> = (0..2)
            .map(|k| {
                let pixels = (0..w * h)
                    .map(|i| {
                        seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
                        // Noise from 0 to 5 counts wide across the frame, a star now and then.
                        let spread = (i % w) / 40 + k;
                        let star = if i % 1013 == 0 { 90 } else { 0 };
                        base + ((seed >> 16) % (2 * spread + 1)) as u16 + star
                    })
                    .collect::<Vec<u16>>();
                gpustar::io::frame::Frame {
                    width: w,
                    height: h,
                    pixels: pixels.into(),
                    saturation,
                }
            })
            .collect();
        let p = DetectParams::new(w, h, 32, 5.0, saturation as u32);
        let grouped = tile_stats(&frames[0].pixels, &p)
            .iter()
            .filter(|t| t.offset % 8 != 0 && t.offset < 40)
            .count();
        assert!(grouped > 10, "{grouped} tiles with a grouped offset");
        common::assert_detect_stages_equal(&g, &frames, 32);
    }
}

#[test]
fn gpu_equals_cpu_on_odd_sizes_and_one_pixel_frames() {
    let Some(g) = common::gpu("gpu_equals_cpu_on_odd_sizes_and_one_pixel_frames") else {
        return;
    };
    // Sizes not multiples of the tile, of 32 (mask words) or of 2 (packed pixels).
    common::assert_detect_stages_equal(&g, &common::sim_frames(2, (333, 77), 12.0, 8, 5), 16);
    common::assert_detect_stages_equal(&g, &common::sim_frames(1, (97, 131), 12.0, 16, 6), 64);
    for (w, h, v) in [(1, 1, 7u16), (1, 5, 0), (3, 1, 65535)] {
        let f = gpustar::io::frame::Frame {
            width: w,
            height: h,
            pixels: vec![v; (w * h) as usize].into(),
            saturation: 65535,
        };
        common::assert_detect_stages_equal(&g, &[f], 4);
    }
}

/// The matched filter's mask of `px` marks exactly the pixels with 16·pixel > level and
/// binomial3 > level (level = filtered_level_at), the definition the GPU kernel evaluates.
/// Returns how many it marks.
fn assert_filtered_mask_is_the_definition(
    px: &[u16],
    tiles: &[TileStats],
    p: &DetectParams,
    what: &str,
) -> u32 {
    let (w, h) = (p.width, p.height);
    let mask = dense_mask(&threshold(px, tiles, p), w, h);
    let mut set = 0;
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let level = filtered_level_at(tiles, p, x, y);
            let want = (16 * px[i] as u32 > level && binomial3(px, w, h, x, y) > level) as u32;
            assert_eq!(mask[i], want, "{what}: pixel ({x}, {y})");
            set += want;
        }
    }
    set
}

#[test]
fn filtered_runs_equal_the_per_pixel_definition() {
    // Pseudo-random pixels and tile statistics, edges included.
    let (w, h) = (77u32, 51u32);
    let p = DetectParams::new(w, h, 8, 3.0, 255).with_filter(true);
    let (px, tiles) = random_pixels_and_tiles(&p, 4321);
    let set = assert_filtered_mask_is_the_definition(&px, &tiles, &p, "random");
    assert!(
        set > 100 && set < w * h - 100,
        "{set} set: both outcomes tested"
    );
}

#[test]
fn matched_filter_finds_a_faint_star_and_drops_a_hot_pixel() {
    // Flat sky 100 ± 4 (noise from a fixed pattern), a Gaussian star (σ 1.2 px) of peak 3.5σ
    // above it, and a hot pixel of 30σ: without the filter the star is missed; with it the star
    // is one blob of several pixels and the hot pixel a single pixel (dropped by min_area).
    let (w, h) = (64u32, 64u32);
    let mut seed = 7u32;
    let mut px: Vec<f64> = (0..w * h)
        .map(|_| {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            // Sum of 4 uniforms: roughly Gaussian, σ = 4.
            let u: f64 = (0..4)
                .map(|k| ((seed.rotate_left(8 * k) >> 16) as f64 / 65536.0) - 0.5)
                .sum();
            100.0 + u * 4.0 * (12.0f64 / 4.0).sqrt()
        })
        .collect();
    let (sx, sy, sigma) = (20.3, 30.6, 1.2);
    for y in 0..h {
        for x in 0..w {
            let r2 = (x as f64 - sx).powi(2) + (y as f64 - sy).powi(2);
            px[(y * w + x) as usize] += 3.5 * 4.0 * (-r2 / (2.0 * sigma * sigma)).exp();
        }
    }
    px[(40 * w + 45) as usize] += 120.0;
    let px: Vec<u16> = px.iter().map(|v| v.round() as u16).collect();
    let frame = gpustar::io::frame::Frame {
        width: w,
        height: h,
        pixels: px.into(),
        saturation: 255,
    };
    let detect = |filter: bool| {
        let s = gpustar::solve::detect::DetectSettings {
            tile: 16,
            matched_filter: filter,
            ..Default::default()
        };
        gpustar::solve::detect::detect(&frame, &s)
    };
    let near = |d: &[gpustar::solve::detect::Detection], x: f64, y: f64| {
        d.iter().any(|d| (d.x - x).hypot(d.y - y) < 1.5)
    };
    let raw = detect(false);
    let filtered = detect(true);
    assert!(!near(&raw, sx, sy), "{raw:?}");
    assert!(near(&filtered, sx, sy), "{filtered:?}");
    assert!(!near(&filtered, 45.0, 40.0), "the hot pixel: {filtered:?}");
    // The detector that keeps the tiles for the detection retry finds the same, both ways.
    let first = gpustar::solve::detect::DetectSettings {
        tile: 16,
        ..Default::default()
    };
    let detector = gpustar::solve::detect::Detector::new(&frame, &first);
    assert_eq!(detector.detect(), raw);
    assert_eq!(detector.detect_filtered(), filtered);
}

#[test]
fn gpu_equals_cpu_with_the_matched_filter() {
    let Some(g) = common::gpu("gpu_equals_cpu_with_the_matched_filter") else {
        return;
    };
    // At the white-noise gain, at the measured gain of noise that neighbours share, and at
    // the largest: the kernel takes its gain from the parameters.
    let frames8 = common::sim_frames(3, (640, 480), 18.0, 8, 21);
    let mut n8 = 0;
    for gain in [WHITE_GAIN, 10, MAX_GAIN] {
        n8 += common::assert_detect_stages_equal_with(&g, &frames8, 32, gain);
    }
    // ... and the masks those gains give differ.
    let set = |gain: u32| {
        let f = &frames8[0];
        let p = DetectParams::new(f.width, f.height, 32, 5.0, f.saturation as u32)
            .with_filter_gain(gain);
        let tiles = gpustar::cpu::tile_clip::clipped_tile_stats(&f.pixels, &p);
        threshold(&f.pixels, &tiles, &p)
            .iter()
            .map(|r| r.x1 - r.x0)
            .sum::<u32>()
    };
    let (at6, at10) = (set(WHITE_GAIN), set(10));
    assert!(at6 > at10, "pixels set at gains 6 and 10: {at6}, {at10}");
    let n16 = common::assert_detect_stages_equal_with(
        &g,
        &common::sim_frames(2, (333, 77), 10.0, 16, 22),
        16,
        WHITE_GAIN,
    );
    for (w, h, v) in [(1, 1, 7u16), (2, 5, 0), (3, 1, 65535)] {
        let f = gpustar::io::frame::Frame {
            width: w,
            height: h,
            pixels: vec![v; (w * h) as usize].into(),
            saturation: 65535,
        };
        common::assert_detect_stages_equal_with(&g, &[f], 4, WHITE_GAIN);
    }
    assert!(n8 > 50 && n16 > 5, "{n8} and {n16} blobs compared");
}
