//! Stage `centroid` (with `threshold` and `components` in front): sub-pixel accuracy on
//! simulated spots.

use crate::common;

use gpustar::io::frame::Frame;
use gpustar::simulate::add_spot;
use gpustar::solve::detect::{DetectSettings, detect};

/// A 64×64 frame with a flat background of 100 and one Gaussian spot (noise free).
fn spot_frame(x: f64, y: f64, flux: f64, sigma: f64) -> Frame<'static> {
    let (w, h) = (64u32, 64u32);
    let mut signal = vec![0.0; (w * h) as usize];
    add_spot(&mut signal, w, h, x, y, flux, sigma);
    Frame {
        width: w,
        height: h,
        pixels: signal.iter().map(|s| (100.0 + s).round() as u16).collect(),
        saturation: 65535,
    }
}

#[test]
fn centroid_is_sub_pixel_on_simulated_spots() {
    let settings = DetectSettings::default();
    let mut worst: f64 = 0.0;
    for k in 0..25 {
        let (fx, fy) = ((k % 5) as f64 / 5.0, (k / 5) as f64 / 5.0);
        let (x, y) = (30.0 + fx, 31.0 + fy);
        let stars = detect(&spot_frame(x, y, 20000.0, 1.0), &settings);
        assert_eq!(stars.len(), 1, "one star at ({x}, {y})");
        let err = (stars[0].x - x).hypot(stars[0].y - y);
        worst = worst.max(err);
    }
    // Centre of mass over the thresholded pixels (seed 000 eq. 3) is biased toward the pixel
    // centre by the pixels cut off below the threshold; for a bright spot it stays small.
    println!("worst centroid error: {worst:.4} px");
    assert!(worst < 0.02, "worst centroid error {worst} px");
}

#[test]
fn faint_spot_centroid_error_is_bounded() {
    // A spot only ~15 sigma above a noiseless background: fewer pixels, larger bias.
    let stars = detect(
        &spot_frame(20.3, 40.7, 1500.0, 1.0),
        &DetectSettings::default(),
    );
    assert_eq!(stars.len(), 1);
    let err = (stars[0].x - 20.3).hypot(stars[0].y - 40.7);
    println!("faint spot centroid error: {err:.4} px");
    assert!(err < 0.15, "centroid error {err} px");
}

#[test]
fn single_hot_pixel_is_rejected_and_saturation_flagged() {
    let mut f = spot_frame(32.0, 32.0, 2_000_000.0, 1.0);
    for p in f.pixels.to_mut().iter_mut() {
        *p = (*p).min(4000);
    }
    f.saturation = 4000;
    f.pixels.to_mut()[5 * 64 + 5] = 3000; // a hot pixel
    let stars = detect(&f, &DetectSettings::default());
    assert_eq!(stars.len(), 1, "the hot pixel is not a star");
    assert!(stars[0].saturated);
    assert!((stars[0].x - 32.0).abs() < 0.01 && (stars[0].y - 32.0).abs() < 0.01);
}

#[test]
fn gpu_moments_equal_cpu_on_saturated_faint_and_edge_spots() {
    let Some(g) = common::gpu("gpu_moments_equal_cpu_on_saturated_faint_and_edge_spots") else {
        return;
    };
    let mut bright = spot_frame(32.0, 32.0, 2_000_000.0, 1.0);
    for p in bright.pixels.to_mut().iter_mut() {
        *p = (*p).min(4000);
    }
    bright.saturation = 4000;
    let frames = [
        bright,
        spot_frame(20.3, 40.7, 1500.0, 1.0),
        spot_frame(0.2, 63.0, 30000.0, 1.5),
        spot_frame(63.4, 0.0, 30000.0, 0.7),
    ];
    for f in &frames {
        // Each frame alone: they differ in saturation level.
        assert_eq!(
            common::assert_detect_stages_equal(&g, std::slice::from_ref(f), 16),
            1
        );
    }
}
