//! Stage `psf_fit` (`--centroid ml`): on simulated frames (pixel-integrated Gaussian PSF σ 1.2
//! px, Poisson and read noise) the fitted positions are closer to the truth than the centres
//! of gravity, and the fit reports a plausible 1σ.

mod common;

use gpustar::detect::{self, Centroid, DetectSettings};
use gpustar::simulate::{SimSettings, render};

#[test]
fn ml_positions_beat_the_centre_of_gravity() {
    let catalog = gpustar::catalog::Catalog::builtin();
    let s = SimSettings {
        psf_sigma_px: 1.2,
        bits: 16,
        full_well_e: 65535.0 * 2.0,
        frames: 6,
        seed: 31,
        ..Default::default()
    };
    let (mut cog, mut ml) = (Vec::new(), Vec::new());
    for k in 0..s.frames {
        let (pixels, truth) = render(&catalog, &s, k).unwrap();
        let frame = gpustar::frame::Frame {
            width: truth.width,
            height: truth.height,
            pixels,
            saturation: 65535,
        };
        let errors = |c: Centroid| -> Vec<f64> {
            let ds = DetectSettings {
                centroid: c,
                ..Default::default()
            };
            let dets = detect::detect(&frame, &ds);
            truth
                .stars
                .iter()
                .filter_map(|t| {
                    dets.iter()
                        .map(|d| (d.x - t.x).hypot(d.y - t.y))
                        .filter(|e| *e < 1.5)
                        .min_by(f64::total_cmp)
                })
                .collect()
        };
        cog.extend(errors(Centroid::Cog));
        ml.extend(errors(Centroid::Ml));
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (n, m) = (cog.len(), ml.len());
    let (c, f) = (median(cog), median(ml));
    println!(
        "psf_fit: median error {f:.4} px against the centre of gravity's {c:.4} ({m} / {n} stars)"
    );
    assert!(m >= n && n > 100, "{m} and {n} stars");
    assert!(f <= 0.8 * c, "ML {f} against CoG {c}");
}
