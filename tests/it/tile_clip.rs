//! Stage `tile_clip`: a bloated star (a photographic plate's, 90 px across with its halo)
//! fills its tiles, whose median and MAD become its own; clipped to the neighbourhood's sky it
//! is detected whole, at its centre.

use crate::common;

use gpustar::cpu::threshold::{DetectParams, tile_stats};
use gpustar::cpu::{centroid, components, threshold, tile_clip};
use gpustar::io::frame::Frame;
use gpustar::solve::detect::{DetectSettings, detect};

/// The bloated star's centre, off the tile grid.
const CENTRE: (f64, f64) = (251.3, 190.7);

/// Sky 1000 ± 20 (uniform noise), a bloated star flat-topped at the saturation of 60000 (a
/// Gaussian of σ 12 px and peak 100000, clipped), and three small stars.
fn plate() -> Frame<'static> {
    plate_with(1000.0, 60000.0, 65535, 1.0)
}

/// A grainy 8-bit scan (m44-1975-01-18.jpg of astrometry.net's demos): sky 117 ± 20, so that
/// 20σ above the sky is past the format's 255, the bloated star's top flat at 255 and the
/// small stars' peaks 120–200 ADU above the sky.
fn grainy_scan() -> Frame<'static> {
    plate_with(117.0, 255.0, 255, 0.04)
}

/// The plate's stars on a sky of `sky` ± 20, clipped at `top` in a format saturating at
/// `saturation`, the small stars' amplitudes times `small`.
fn plate_with(sky: f64, top: f64, saturation: u16, small: f64) -> Frame<'static> {
    let (w, h) = (512u32, 384u32);
    let mut state = 0x2545_f491u32;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state % 41) as f64 - 20.0
    };
    let stars = [
        (CENTRE.0, CENTRE.1, 100_000.0, 12.0),
        (60.2, 70.9, 5000.0 * small, 1.5),
        (420.6, 300.1, 3000.0 * small, 1.5),
        (400.4, 60.3, 4000.0 * small, 1.5),
    ];
    let pixels = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            let light: f64 = stars
                .iter()
                .map(|&(sx, sy, a, s)| {
                    a * (-((x - sx).powi(2) + (y - sy).powi(2)) / (2.0 * s * s)).exp()
                })
                .sum();
            (sky + noise() + light).min(top) as u16
        })
        .collect::<Vec<u16>>();
    Frame {
        width: w,
        height: h,
        pixels: pixels.into(),
        saturation,
    }
}

fn params(f: &Frame) -> DetectParams {
    DetectParams::new(f.width, f.height, 32, 5.0, f.saturation as u32)
}

/// The brightest blob's centre, thresholded against these tiles.
fn brightest(f: &Frame, tiles: &[gpustar::cpu::threshold::TileStats]) -> (f64, f64) {
    let p = params(f);
    let runs = threshold::threshold(&f.pixels, tiles, &p);
    let labels = components::components(&runs, p.width);
    let blobs = centroid::centroid(&f.pixels, &runs, &labels, tiles, &p);
    blobs.iter().max_by_key(|b| b.m0).unwrap().centre()
}

#[test]
fn a_bloated_star_is_detected_whole_at_its_centre() {
    let f = plate();
    let p = params(&f);
    let raw = tile_stats(&f.pixels, &p);
    let clipped = tile_clip::tile_clip(&raw, &p);
    let changed = raw.iter().zip(&clipped).filter(|(a, b)| a != b).count();
    assert!((4..=16).contains(&changed), "{changed} tiles clipped");
    // Against its own tiles only a lopsided ring of the star passes: its centre is off.
    let (x, y) = brightest(&f, &raw);
    let off = (x - CENTRE.0).hypot(y - CENTRE.1);
    assert!(off > 2.0, "unclipped: {off:.2} px from the centre");
    // Clipped, the star is whole, and detection puts it at its centre.
    let (x, y) = brightest(&f, &clipped);
    let off = (x - CENTRE.0).hypot(y - CENTRE.1);
    assert!(off < 0.3, "clipped: {off:.2} px from the centre");
    let d = detect(&f, &DetectSettings::default());
    assert_eq!(d.len(), 4, "{d:?}");
    assert!(
        (d[0].x - CENTRE.0).hypot(d[0].y - CENTRE.1) < 0.3,
        "{:?}",
        d[0]
    );
}

#[test]
fn a_grainy_scan_s_saturated_star_is_detected_whole() {
    // 20σ above this sky is past 255: only the margins' cap at half the headroom
    // (`tile_clip::margin`) makes the flat top a body. Without it the star's tiles keep
    // their own median, 255, and the star is not detected at all.
    let f = grainy_scan();
    let p = params(&f);
    let raw = tile_stats(&f.pixels, &p);
    assert!(
        raw.iter()
            .all(|t| t.background + 4 * t.offset > 255 || t.offset == 0)
    );
    assert_ne!(tile_clip::tile_clip(&raw, &p), raw, "some tiles clipped");
    let d = detect(&f, &DetectSettings::default());
    assert_eq!(d.len(), 4, "{d:?}");
    assert!(
        (d[0].x - CENTRE.0).hypot(d[0].y - CENTRE.1) < 0.6,
        "{:?}",
        d[0]
    );
    assert!(d[0].saturated && d[0].area > 1000, "{:?}", d[0]);
}

#[test]
fn gpu_equals_cpu_on_a_bloated_star() {
    let Some(g) = common::gpu("gpu_equals_cpu_on_a_bloated_star") else {
        return;
    };
    let f = plate();
    // Every stage, the clipped tiles included, equal; and 8-bit: the frame scaled down.
    let eight = Frame {
        pixels: f
            .pixels
            .iter()
            .map(|&v| v / 240)
            .collect::<Vec<u16>>()
            .into(),
        saturation: 255,
        ..f.clone()
    };
    for frame in [f, eight, grainy_scan()] {
        let p = params(&frame);
        let raw = tile_stats(&frame.pixels, &p);
        assert_ne!(tile_clip::tile_clip(&raw, &p), raw, "some tiles clipped");
        common::assert_detect_stages_equal(&g, &[frame], 32);
    }
}
