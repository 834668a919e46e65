//! Stage `threshold` (CPU twin) on hand-made inputs.

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
    px[27] = 250;
    px[28] = 240;
    let t = tile_stats(&px, &p);
    assert_eq!(t[0].background, 102);
    // |v − 102| over 0..4 cycles: MAD 1 → offset ceil(5 · 1.4826) = 8.
    assert_eq!(t[0].offset, 8);
    let mask = threshold(&px, &t, &p);
    assert_eq!(mask.iter().map(|&m| m as u32).sum::<u32>(), 2);
}
