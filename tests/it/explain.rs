//! A solution must explain the frame's brightest detections (`solve/explain.rs`). A double
//! exposure (every star with a copy 1–2 mag fainter, 70–140 px away) has two attitudes that
//! match the catalog: the bright images' and the copies'. The copies' leaves a brighter
//! detection unmatched beside each star it matches, all at one offset, and is refused, where
//! before it was accepted with a false-match probability far below the threshold; the bright
//! images' is accepted; the whole solver, which may meet either, never reports the copies'.

use crate::common;

use gpustar::camera::Camera;
use gpustar::io::frame::Frame;
use gpustar::simulate::{SimSettings, Truth};
use gpustar::solve::attitude::{attitude_error, wahba};
use gpustar::solve::refine::refine;
use gpustar::solve::{Outcome, Solver};
use nalgebra::Matrix3;

/// `f` with a copy of its sky added, moved by (dx, dy) px and `dmag` fainter.
fn double_exposure(f: &Frame, dx: i64, dy: i64, dmag: f64) -> Frame<'static> {
    let (w, h) = (f.width as i64, f.height as i64);
    let mut sorted: Vec<u16> = f.pixels.to_vec();
    sorted.sort_unstable();
    let bg = sorted[sorted.len() / 2] as f64;
    let k = 10f64.powf(-0.4 * dmag);
    let mut out: Vec<u16> = f.pixels.to_vec();
    for y in 0..h {
        for x in 0..w {
            let (sx, sy) = (x - dx, y - dy);
            if sx < 0 || sy < 0 || sx >= w || sy >= h {
                continue;
            }
            let above = (f.pixels[(sy * w + sx) as usize] as f64 - bg).max(0.0);
            let p = &mut out[(y * w + x) as usize];
            *p = (*p as f64 + k * above).round().min(f.saturation as f64) as u16;
        }
    }
    Frame {
        width: f.width,
        height: f.height,
        pixels: out.into(),
        saturation: f.saturation,
    }
}

/// The attitude under which the truth's stars appear moved by (dx, dy) px.
fn moved_attitude(camera: &Camera, t: &Truth, dx: f64, dy: f64) -> Matrix3<f64> {
    let r = Matrix3::from_fn(|i, j| t.rotation_matrix[i][j]);
    let (cam, icrs): (Vec<_>, Vec<_>) = t
        .stars
        .iter()
        .map(|s| {
            let icrs = r.transpose() * camera.pixel_to_vector(s.x, s.y);
            (camera.pixel_to_vector(s.x + dx, s.y + dy), icrs)
        })
        .unzip();
    wahba(&cam, &icrs).unwrap()
}

/// A double-exposed frame, its truth (the bright images'), and the copy's (dx, dy, dmag).
type Double = (Frame<'static>, Truth, (i64, i64, f64));

fn set() -> (Solver, Vec<Double>) {
    let solver = common::solver(15.0, (1024, 1024));
    let s = SimSettings {
        width: 1024,
        height: 1024,
        fov_x_deg: 15.0,
        mag_limit: 7.0,
        seed: 81,
        ..Default::default()
    };
    let shifts = [
        (60, 40, 1.0),
        (-90, 70, 1.5),
        (120, -30, 2.0),
        (-50, -130, 1.25),
    ];
    let frames = common::rendered(&s, shifts.len())
        .into_iter()
        .zip(shifts)
        .map(|((f, t), d)| (double_exposure(&f, d.0, d.1, d.2), t, d))
        .collect();
    (solver, frames)
}

#[test]
fn the_copies_attitude_is_refused_and_the_bright_images_accepted() {
    let (solver, frames) = set();
    let refs = solver.bands[0].refs.clone();
    let rs = solver.settings.refine;
    for (frame, t, (dx, dy, dmag)) in &frames {
        let dets = gpustar::solve::detect::detect(frame, &solver.settings.detect);
        let truth = Matrix3::from_fn(|i, j| t.rotation_matrix[i][j]);
        let right = refine(truth, &dets, &refs, &solver.camera, 1_000_000, 2, &rs)
            .expect("the bright images' attitude refines");
        assert!(
            right.false_match_prob <= rs.max_false_prob,
            "the bright images' attitude: P(false) {:.1e}",
            right.false_match_prob
        );
        let copies = moved_attitude(&solver.camera, t, *dx as f64, *dy as f64);
        let (copied, p_copies) = {
            // What refinement from the copies' attitude matches, without the check: the
            // matches as the check sees them.
            let mut no_check = rs;
            no_check.max_false_prob = 0.0;
            let r = refine(
                copies,
                &dets,
                &refs,
                &solver.camera,
                1_000_000,
                2,
                &no_check,
            )
            .expect("the copies match the catalog");
            // Without the check it would have been accepted: chance does not explain it.
            assert!(
                r.false_match_prob <= rs.max_false_prob,
                "the copies' attitude: P(false) {:.1e}",
                r.false_match_prob
            );
            (
                (
                    gpustar::solve::explain::copied_matches(
                        &dets,
                        &r.matches.iter().map(|m| m.det).collect::<Vec<_>>(),
                    ),
                    r.matches.len(),
                ),
                r.false_match_prob,
            )
        };
        let refused = refine(copies, &dets, &refs, &solver.camera, 1_000_000, 2, &rs);
        println!(
            "shift ({dx}, {dy}) px, {dmag} mag: bright images {} matched, P(false) {:.1e}; \
             copies P(false) {p_copies:.1e}, {} of their {} matches with a brighter copy at \
             one offset: {}",
            right.matches.len(),
            right.false_match_prob,
            copied.0,
            copied.1,
            if refused.is_none() {
                "refused"
            } else {
                "ACCEPTED"
            }
        );
        assert!(
            refused.is_none(),
            "the copies' attitude was accepted ({dmag} mag fainter)"
        );
    }
}

#[test]
fn double_exposures_are_never_solved_at_the_copies_attitude() {
    let (solver, frames) = set();
    let mut solved = 0;
    for (frame, t, (dx, dy, _)) in &frames {
        if let Outcome::Solved(r, _) = solver.solve_frame(frame).0.outcome {
            let truth = Matrix3::from_fn(|i, j| t.rotation_matrix[i][j]);
            let err = attitude_error(&r.r, &truth).to_degrees() * 3600.0;
            assert!(
                err < 60.0,
                "shift ({dx}, {dy}): solved {err:.0}″ from the bright images' attitude"
            );
            solved += 1;
        }
    }
    println!(
        "double exposures: {solved} of {} solved, all at the bright images' attitude",
        frames.len()
    );
}
