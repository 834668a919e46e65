//! Centroid noise: `simulate --centroid-noise-px` draws stars off their true places and keeps the
//! truth; the retries solve frames whose centroids are off by a pixel or more, which the
//! default tolerances (tuned for sub-pixel centroids) reject, without wrong answers; the wide
//! retry takes frames of enough stars only.

use crate::common;

use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::io::frame::Frame;
use gpustar::simulate::{SimSettings, Truth};
use gpustar::solve::radial::Method;
use gpustar::solve::{PassKind, Settings, Solver, WIDE_MIN_STARS};

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
    let (with, without) = (solve(true, &set), solve(false, &set));
    common::assert_retry_adds(
        "1.5 px centroid noise",
        "the retries",
        12,
        11,
        with,
        without,
    );
}

/// With the scale searched, the wide retry steps through it on its own coarser grid
/// (`solve::WIDE_SCALE_STEP`, ten times the first passes' step as its tolerance is ten times
/// theirs): frames with 1.5 px centroid noise, taken with a focal length 0.7 % off the one
/// believed and searched ±2.5 %, solve as they do at the right scale.
#[test]
fn the_wide_retry_searches_the_scale_on_its_own_grid() {
    let set = common::rendered(&sim(1.5), 12);
    let settings = Settings {
        mag_limit: Some(6.0),
        table_cache: false,
        scale_range: Some((0.975, 1.025)),
        // The walk's own retry is what is tested here.
        scale_free: false,
        ..Settings::default()
    };
    let believed = Camera::from_fov(1024, 1024, 18.0 * 1.007).unwrap();
    let solver = Solver::new(&Catalog::builtin(), believed, settings).unwrap();
    let count = |kind| solver.passes.iter().filter(|p| p.kind == kind).count();
    let (first, wide) = (count(PassKind::First), count(PassKind::Wide));
    assert!(
        first >= 50 && wide <= first / 5,
        "{first} first passes, {wide} wide"
    );
    let (solved, wrong) = common::solved_and_wrong(&solver, &set, 1.0);
    println!("±2.5 % search, 1.5 px noise: {solved}/12 solved ({first} scales, {wide} wide)");
    assert_eq!(wrong, 0);
    assert!(solved >= 11, "{solved}/12 solved");
}

/// The wide retry only takes frames of `wide_min_stars` detections or more, and the
/// false-match test counts its hypotheses only for them; 0 tries it on every frame.
#[test]
fn the_wide_retry_needs_its_stars() {
    let solver_with = |wide_min_stars| {
        let settings = Settings {
            mag_limit: Some(6.0),
            table_cache: false,
            wide_min_stars,
            ..Settings::default()
        };
        let camera = Camera::from_fov(1024, 1024, 18.0).unwrap();
        Solver::new(&Catalog::builtin(), camera, settings).unwrap()
    };
    let solver = solver_with(WIDE_MIN_STARS);
    let set = common::rendered(&sim(1.5), 1);
    let dets = gpustar::solve::detect::detect(&set[0].0, &solver.settings.detect);
    assert!(dets.len() > WIDE_MIN_STARS, "{} detections", dets.len());
    let wide = (solver.passes.iter())
        .position(|p| p.kind == PassKind::Wide)
        .unwrap();
    let (few, enough) = (&dets[..WIDE_MIN_STARS - 1], &dets[..WIDE_MIN_STARS]);
    assert!(solver.prepare(few, wide).is_none());
    assert!(solver.prepare(enough, wide).is_some());
    let passes = |s: &Solver, n| s.passes_for(n, Method::Vote);
    assert_eq!(
        passes(&solver, few.len()) + 1,
        passes(&solver, enough.len())
    );
    let every = solver_with(0);
    assert!(every.prepare(few, wide).is_some());
    assert_eq!(passes(&every, few.len()), passes(&every, enough.len()));
}
