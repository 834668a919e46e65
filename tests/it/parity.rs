//! Parity: a frame stored as a mirror image of the sky (rows reversed, as a conventional FITS
//! image is in row-0-first order) solves when the parity is left open, on every path an
//! attitude is first found by (the scale-free pass, the vote, the triangle fallback), with the
//! truth's attitude and `mirrored` set; the same frames as they are solve unmirrored. With the
//! parity as the camera says, the mirrored frames do not solve (what was wrong before).

use crate::common;

use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::io::frame::Frame;
use gpustar::simulate::{SimSettings, Truth};
use gpustar::solve::radial::Method;
use gpustar::solve::{Outcome, Parity, Settings, Solver};

fn focal(fov_deg: f64) -> f64 {
    1.0 / (fov_deg.to_radians() / 2.0).tan()
}

fn frames(fov: f64, seed: u64, n: usize) -> Vec<(Frame<'static>, Truth)> {
    let s = SimSettings {
        width: 1024,
        height: 768,
        fov_x_deg: fov,
        mag_limit: 7.0,
        seed,
        ..Default::default()
    };
    common::rendered(&s, n)
}

/// The frame with its rows in reverse order.
fn mirrored(f: &Frame) -> Frame<'static> {
    let w = f.width as usize;
    let pixels: Vec<u16> = f.pixels.chunks_exact(w).rev().flatten().copied().collect();
    Frame {
        width: f.width,
        height: f.height,
        pixels: pixels.into(),
        saturation: f.saturation,
    }
}

fn solver(settings: Settings) -> Solver {
    let camera = Camera::from_fov(1024, 768, 15.0).unwrap();
    Solver::new(&Catalog::builtin(), camera, settings).unwrap()
}

/// Solved frames of `set` (as they are, or mirrored) and whether each came out mirrored; every
/// solution within 60″ of the truth.
fn solve_all(solver: &Solver, set: &[(Frame, Truth)], mirror: bool) -> Vec<bool> {
    let mut out = Vec::new();
    for (f, t) in set {
        let frame = if mirror { mirrored(f) } else { f.clone() };
        if let Outcome::Solved(r, _) = solver.solve_frame(&frame).0.outcome {
            let truth = nalgebra::Matrix3::from_fn(|i, j| t.rotation_matrix[i][j]);
            let err = gpustar::solve::attitude::attitude_error(&r.r, &truth).to_degrees() * 3600.0;
            assert!(err < 60.0, "solved {err}″ from the truth (mirror {mirror})");
            out.push(r.camera.mirrored);
        }
    }
    out
}

fn check(settings: Settings, label: &str) {
    let set = frames(15.0, 71, 4);
    let open = solver(Settings {
        parity: Parity::Either,
        ..settings
    });
    let as_is = solve_all(&open, &set, false);
    let flipped = solve_all(&open, &set, true);
    println!(
        "{label}: {} of {} solved as they are, {} mirrored",
        as_is.len(),
        set.len(),
        flipped.len()
    );
    assert_eq!(as_is.len(), set.len(), "{label}: frames as they are");
    assert_eq!(flipped.len(), set.len(), "{label}: mirrored frames");
    assert!(
        as_is.iter().all(|m| !m),
        "{label}: a frame as it is came out mirrored"
    );
    assert!(
        flipped.iter().all(|m| *m),
        "{label}: a mirrored frame came out as it is"
    );
    let fixed = solver(Settings {
        parity: Parity::AsCamera,
        ..settings
    });
    assert!(
        solve_all(&fixed, &set, true).is_empty(),
        "{label}: a mirror image solved with the camera's parity"
    );
}

fn base() -> Settings {
    Settings {
        mag_limit: Some(6.5),
        table_cache: false,
        ..Settings::default()
    }
}

#[test]
fn mirror_images_solve_in_the_scale_free_pass() {
    check(
        Settings {
            scale_range: Some((focal(18.0) / focal(15.0), focal(12.0) / focal(15.0))),
            ..base()
        },
        "scale-free pass, 12..18°",
    );
}

#[test]
fn mirror_images_solve_by_the_vote() {
    check(
        Settings {
            scale_free: false,
            ..base()
        },
        "vote, known scale",
    );
}

#[test]
fn mirror_images_solve_by_triangles() {
    check(
        Settings {
            scale_free: false,
            method: Method::Triangle,
            ..base()
        },
        "triangles, known scale",
    );
}

/// The parity left open doubles what the false-match test counts for a vote's or a quad's
/// hypothesis; the triangles' searches count each hand's triangles themselves.
#[test]
fn an_open_parity_counts_twice_the_hypotheses() {
    let a = solver(Settings {
        scale_free: false,
        ..base()
    });
    let b = solver(Settings {
        scale_free: false,
        parity: Parity::Either,
        ..base()
    });
    assert_eq!((a.parities(), b.parities()), (1, 2));
    assert_eq!(
        b.hypothesis_factor(20, Method::Vote),
        a.hypothesis_factor(20, Method::Vote)
    );
}
