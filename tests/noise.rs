//! Centroid noise: `simulate --centroid-noise-px` draws stars off their true places and keeps the
//! truth; the retries solve frames whose centroids are off by a pixel or more, which the
//! default tolerances (tuned for sub-pixel centroids) reject, without wrong answers.

mod common;

use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::frame::Frame;
use gpustar::simulate::{SimSettings, Truth};
use gpustar::solve::{Settings, Solver};

fn sim(noise: f64) -> SimSettings {
    SimSettings {
        centroid_noise_px: noise,
        seed: 21,
        ..SimSettings::default()
    }
}

#[test]
fn noise_moves_the_stars_drawn_and_keeps_the_truth() {
    let cat = Catalog::builtin();
    let (clean, t0) = gpustar::simulate::render(&cat, &sim(0.0), 3).unwrap();
    let (noisy, t1) = gpustar::simulate::render(&cat, &sim(1.0), 3).unwrap();
    assert_eq!(
        t0, t1,
        "the truth is the same attitude and the true star places"
    );
    assert_ne!(clean, noisy, "the stars are drawn elsewhere");
}

/// (solved, wrong): wrong = attitude more than 1° from the truth (at 1.5 px noise a correct
/// solution's roll can be off by a few hundred arcseconds, so 0.1° would count imprecision).
fn solve(retry: bool, set: &[(Frame, Truth)]) -> (usize, usize) {
    let settings = Settings {
        mag_limit: Some(6.0),
        table_cache: false,
        retry,
        ..Settings::default()
    };
    let camera = Camera::from_fov(1024, 1024, 18.0).unwrap();
    let solver = Solver::new(&Catalog::builtin(), camera, settings).unwrap();
    common::solved_and_wrong(&solver, set, 1.0)
}

#[test]
fn the_retry_solves_frames_with_pixel_centroid_noise() {
    let set = common::rendered(&sim(1.5), 12);
    let (with, wrong_with) = solve(true, &set);
    let (without, wrong_without) = solve(false, &set);
    println!(
        "1.5 px centroid noise, 12 frames: {with} solved with the wide retry, {without} without"
    );
    assert_eq!((wrong_with, wrong_without), (0, 0));
    assert!(with >= 11, "{with}/12 solved with the wide retry");
    assert!(
        with >= without + 3,
        "{without}/12 solved without it: the retry adds little"
    );
}
