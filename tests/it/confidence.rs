//! The false-match test of refinement: stars matched among the brightest detections are
//! stronger evidence than the same stars matched among many faint ones, and frames of false
//! stars alone are never accepted.

use crate::common;

use gpustar::solve::detect::Detection;
use gpustar::solve::refine::{RefineSettings, refine, stars_in_view};
use nalgebra::Rotation3;
use rand::{Rng, SeedableRng};

fn detection(x: f64, y: f64, flux: f64) -> Detection {
    Detection {
        x,
        y,
        flux,
        area: 5,
        peak: flux as u32,
        saturated: false,
        sigma_px: None,
    }
}

/// Six catalog stars and 94 noise detections; the same positions, once with the stars the
/// brightest, once with them the faintest. Only the order differs, and only the first is
/// accepted (1e-6): six matches among 100 detections are what chance gives to one of a million
/// hypotheses, six among the brightest ten are not.
#[test]
fn six_stars_among_the_brightest_are_accepted_and_among_the_faintest_not() {
    let solver = common::solver(10.0, (1024, 1024));
    let r = Rotation3::from_euler_angles(0.3, -0.2, 1.1).into_inner();
    let refs = &solver.bands[0].refs;
    let mut view = stars_in_view(&r, refs, &solver.camera);
    assert!(view.len() >= 10, "{} stars in view", view.len());
    view.sort_by(|a, b| {
        let mag = |id: u32| refs.star(id as usize).mag;
        mag(a.0).total_cmp(&mag(b.0))
    });
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut jitter = || 0.6 * (rng.random::<f64>() - 0.5);
    let stars: Vec<Detection> = view[..6]
        .iter()
        .map(|&(_, x, y)| detection(x + jitter(), y + jitter(), 1000.0))
        .collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
    let noise: Vec<Detection> = (0..94)
        .map(|i| {
            let (x, y) = (rng.random::<f64>() * 1024.0, rng.random::<f64>() * 1024.0);
            detection(x, y, 100.0 - i as f64)
        })
        .collect();
    let prob = |dets: &[Detection]| {
        let s = RefineSettings::default();
        let refined = refine(r, dets, refs, &solver.camera, 1_000_000, 3, &s).unwrap();
        assert_eq!(refined.matches.len(), 6);
        refined.false_match_prob
    };
    let brightest = prob(&[stars.clone(), noise.clone()].concat());
    let faintest = prob(&[noise, stars].concat());
    println!("false-match probability: stars brightest {brightest:.2e}, faintest {faintest:.2e}");
    assert!(brightest <= 1e-6, "{brightest:e}");
    assert!(faintest > 1e-6, "{faintest:e}");
}

/// Frames with false stars and hot pixels alone (no catalog star drawn) at the density where
/// real frames still solve (60 + 20 per 18° frame; the study: 77 % at 50 false stars) go
/// through every pass, the vote's and the triangles', and none is accepted.
#[test]
fn frames_of_false_stars_alone_are_never_solved() {
    let sim = gpustar::simulate::SimSettings {
        mag_limit: -3.0,
        false_stars: 60,
        hot_pixels: 20,
        seed: 5,
        ..Default::default()
    };
    let frames = common::rendered(&sim, 30);
    let solver = common::solver(sim.fov_x_deg, (sim.width, sim.height));
    let mut detected = 0;
    for (frame, truth) in &frames {
        assert!(truth.stars.is_empty());
        let (sol, _, _) = solver.solve_frame(frame);
        detected += sol.detections.len();
        assert!(
            matches!(sol.outcome, gpustar::solve::Outcome::Unsolved(_)),
            "a frame without stars was solved"
        );
    }
    // The false stars are there to be matched: most of them are detected.
    assert!(detected >= 30 * 50, "{detected} detections in 30 frames");
}
