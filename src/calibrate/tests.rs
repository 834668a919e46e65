use super::*;
use crate::calibrate::centre_step;
use crate::solve::attitude::attitude_error;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    // Box–Muller; 1 − u keeps the logarithm finite.
    let (u, v): (f64, f64) = (rng.random(), rng.random());
    (-2.0 * (1.0 - u).ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
}

fn true_camera() -> Camera {
    let mut c = Camera::from_fov(1280, 960, 50.0).unwrap();
    c.fy = c.fx * 1.005;
    c.cx += 7.0;
    c.cy -= 5.0;
    c.k1 = -0.15;
    c.k2 = 0.02;
    c
}

/// The rough camera a user starts from: the right fx only.
fn rough(truth: &Camera) -> Camera {
    let mut c = Camera::from_fov(truth.width, truth.height, 50.0).unwrap();
    c.fx = truth.fx;
    c.fy = truth.fx;
    c
}

/// Frames at random attitudes with `per_frame` stars each, σ 0.2 px of noise, attitudes
/// perturbed by 0.3° as a rough solve would leave them; returns frames and true attitudes.
fn synthetic(
    cam: &Camera,
    n_frames: usize,
    per_frame: usize,
    seed: u64,
) -> (Vec<FrameStars>, Vec<Matrix3<f64>>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut frames = Vec::new();
    let mut truth = Vec::new();
    for f in 0..n_frames {
        let r = crate::simulate::random_rotation(&mut rng);
        let stars = (0..per_frame)
            .map(|_| {
                let x = rng.random::<f64>() * (cam.width as f64 - 1.0);
                let y = rng.random::<f64>() * (cam.height as f64 - 1.0);
                let v = r.transpose() * cam.pixel_to_vector(x, y);
                Star {
                    x: x + 0.2 * gauss(&mut rng),
                    y: y + 0.2 * gauss(&mut rng),
                    v,
                }
            })
            .collect();
        let axis = Vector3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)).normalize();
        let start = Rotation3::new(axis * 0.3f64.to_radians()).into_inner() * r;
        frames.push(FrameStars {
            name: format!("f{f:02}"),
            r: start,
            stars,
        });
        truth.push(r);
    }
    (frames, truth)
}

/// Worst over the frames of (attitude error, error of the sky direction of the image centre
/// pixel), for the fitted camera and attitudes and for the oracle: the true camera with each
/// attitude fitted alone — the floor the noise sets (radians).
fn attitude_errors(
    fit: &Fit,
    truth: &Camera,
    frames: &[FrameStars],
    rots: &[Matrix3<f64>],
) -> [f64; 4] {
    let (xc, yc) = truth.centre_pixel();
    let sky = |r: &Matrix3<f64>, c: &Camera| r.transpose() * c.pixel_to_vector(xc, yc);
    let mut w = [0.0f64; 4];
    for f in 0..frames.len() {
        let inl: Vec<bool> = (0..frames[f].stars.len())
            .map(|s| !fit.rejected.contains(&(f, s)))
            .collect();
        let oracle = refit_attitude(truth, &frames[f], &inl, &frames[f].r);
        let t = sky(&rots[f], truth);
        let e = [
            attitude_error(&fit.rotations[f], &rots[f]),
            sky(&fit.rotations[f], &fit.camera).angle(&t),
            attitude_error(&oracle, &rots[f]),
            sky(&oracle, truth).angle(&t),
        ];
        for k in 0..4 {
            w[k] = w[k].max(e[k]);
        }
    }
    w.map(|x| x.to_degrees() * 3600.0)
}

fn check_accuracy(fit: &Fit, truth: &Camera, frames: &[FrameStars], rots: &[Matrix3<f64>]) {
    let c = &fit.camera;
    assert!(
        (c.fx / truth.fx - 1.0).abs() < 5e-4,
        "fx {} vs {}",
        c.fx,
        truth.fx
    );
    assert!(
        (c.fy / truth.fy - 1.0).abs() < 5e-4,
        "fy {} vs {}",
        c.fy,
        truth.fy
    );
    assert!((c.cx - truth.cx).abs() < 0.5, "cx {} vs {}", c.cx, truth.cx);
    assert!((c.cy - truth.cy).abs() < 0.5, "cy {} vs {}", c.cy, truth.cy);
    let expected = 2f64.sqrt() * 0.2;
    assert!(
        fit.rms_after_px < 1.2 * expected,
        "rms after {}",
        fit.rms_after_px
    );
    assert!(
        fit.rms_before_px > 5.0 * fit.rms_after_px,
        "rms before {}",
        fit.rms_before_px
    );
    // 40 stars at 0.2 px and 150″/px leave each attitude uncertain by ~10″ across and ~15″
    // in roll even with the true camera, so the test is against that floor: where a frame
    // puts its image centre on the sky must be as good as the oracle's; the full rotation
    // also carries the principal point's error (0.5 px ≈ 75″ at most, by the check above).
    let [rot, centre, rot_oracle, centre_oracle] = attitude_errors(fit, truth, frames, rots);
    assert!(
        centre < 1.3 * centre_oracle + 1.0,
        "centre pixel {centre}″ vs oracle {centre_oracle}″"
    );
    assert!(
        rot < rot_oracle + 75.0,
        "attitude {rot}″ vs oracle {rot_oracle}″"
    );
}

fn report(
    label: &str,
    fit: &Fit,
    truth: &Camera,
    frames: &[FrameStars],
    rots: &[Matrix3<f64>],
    secs: f64,
) {
    let c = &fit.camera;
    let [rot, centre, rot_o, centre_o] = attitude_errors(fit, truth, frames, rots);
    eprintln!(
        "{label}: fx {:.3} ({:.3}) fy {:.3} ({:.3}) cx {:.3} ({:.3}) cy {:.3} ({:.3}) k1 {:.5} ({}) k2 {:.5} ({}) \
         | rms {:.3} -> {:.3} px, used {} rejected {}, {} iterations, {:.1} ms | worst attitude {rot:.1}″ \
         (oracle {rot_o:.1}″), centre pixel on the sky {centre:.1}″ (oracle {centre_o:.1}″) | fitted {:?} σ {:?}",
        c.fx,
        truth.fx,
        c.fy,
        truth.fy,
        c.cx,
        truth.cx,
        c.cy,
        truth.cy,
        c.k1,
        truth.k1,
        c.k2,
        truth.k2,
        fit.rms_before_px,
        fit.rms_after_px,
        fit.stars_used,
        fit.stars_rejected,
        fit.iterations,
        secs * 1e3,
        fit.fitted,
        fit.sigmas
            .iter()
            .map(|s| format!("{s:.4}"))
            .collect::<Vec<_>>()
    );
}

#[test]
fn jacobian_matches_central_differences() {
    for mirrored in [false, true] {
        let mut cam = true_camera();
        cam.mirrored = mirrored;
        let c = Vector3::new(0.31, -0.22, 1.0);
        let (_, dcam, drot) = project(&cam, &c).unwrap();
        let steps = [1e-3 * cam.fx, 1e-3 * cam.fy, 1e-2, 1e-2, 1e-6, 1e-6];
        for q in 0..6 {
            let mut p = params_of(&cam);
            p[q] += steps[q];
            let hi = project(&camera_with(&cam, &p), &c).unwrap().0;
            p[q] -= 2.0 * steps[q];
            let lo = project(&camera_with(&cam, &p), &c).unwrap().0;
            for axis in 0..2 {
                let num = (hi[axis] - lo[axis]) / (2.0 * steps[q]);
                assert!(
                    (num - dcam[axis][q]).abs() < 1e-6 * (1.0 + num.abs()),
                    "cam {q} axis {axis}: {num} vs {}",
                    dcam[axis][q]
                );
            }
        }
        for k in 0..3 {
            let mut w = Vector3::zeros();
            w[k] = 1e-7;
            let hi = project(&cam, &(Rotation3::new(w).into_inner() * c))
                .unwrap()
                .0;
            let lo = project(&cam, &(Rotation3::new(-w).into_inner() * c))
                .unwrap()
                .0;
            for axis in 0..2 {
                let num = (hi[axis] - lo[axis]) / 2e-7;
                assert!(
                    (num - drot[axis][k]).abs() < 1e-4 * (1.0 + num.abs()),
                    "rot {k} axis {axis}: {num} vs {}",
                    drot[axis][k]
                );
            }
        }
    }
}

#[test]
fn recovers_a_synthetic_camera() {
    let truth = true_camera();
    let (frames, rots) = synthetic(&truth, 12, 40, 1);
    let t = std::time::Instant::now();
    let fit = fit(&rough(&truth), &frames, &FitOptions::default()).unwrap();
    report(
        "clean",
        &fit,
        &truth,
        &frames,
        &rots,
        t.elapsed().as_secs_f64(),
    );
    assert_eq!(fit.fitted, ["fx", "fy", "cx", "cy", "k1", "k2"]);
    assert_eq!(fit.stars_used + fit.stars_rejected, 480);
    assert!(fit.stars_rejected <= 1, "rejected {}", fit.stars_rejected);
    check_accuracy(&fit, &truth, &frames, &rots);
    assert!(
        (fit.camera.k1 - truth.k1).abs() < 0.01,
        "k1 {}",
        fit.camera.k1
    );
    assert_eq!(fit.per_frame_rms_px.len(), 12);
    // Deterministic.
    let again = super::fit(&rough(&truth), &frames, &FitOptions::default()).unwrap();
    assert_eq!(again.camera, fit.camera);
    assert_eq!(again.rotations, fit.rotations);
}

#[test]
fn rejects_gross_outliers() {
    let truth = true_camera();
    let (mut frames, rots) = synthetic(&truth, 12, 40, 2);
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    let mut planted = Vec::new();
    // 3 % of the stars moved 20 px in a random direction.
    while planted.len() < 480 * 3 / 100 {
        let (f, s) = (rng.random_range(0..12), rng.random_range(0..40));
        if planted.contains(&(f, s)) {
            continue;
        }
        let a: f64 = rng.random::<f64>() * std::f64::consts::TAU;
        frames[f].stars[s].x += 20.0 * a.cos();
        frames[f].stars[s].y += 20.0 * a.sin();
        planted.push((f, s));
    }
    planted.sort();
    let t = std::time::Instant::now();
    let fit = fit(&rough(&truth), &frames, &FitOptions::default()).unwrap();
    report(
        "outliers",
        &fit,
        &truth,
        &frames,
        &rots,
        t.elapsed().as_secs_f64(),
    );
    for p in &planted {
        assert!(fit.rejected.contains(p), "planted outlier {p:?} kept");
    }
    assert!(
        fit.stars_rejected <= planted.len() + 1,
        "rejected {}",
        fit.stars_rejected
    );
    check_accuracy(&fit, &truth, &frames, &rots);
}

#[test]
fn one_frame_keeps_the_principal_point() {
    let truth = true_camera();
    let (frames, rots) = synthetic(&truth, 1, 60, 3);
    let start = rough(&truth);
    let fit = fit(&start, &frames, &FitOptions::default()).unwrap();
    report("one frame", &fit, &truth, &frames, &rots, 0.0);
    assert_eq!(fit.fitted, ["fx", "fy", "k1", "k2"]);
    assert_eq!((fit.camera.cx, fit.camera.cy), (start.cx, start.cy));
    assert!(fit.rms_after_px < fit.rms_before_px);
}

#[test]
fn too_few_stars_is_an_error() {
    let truth = true_camera();
    let (frames, _) = synthetic(&truth, 2, 5, 4);
    let e = fit(&rough(&truth), &frames, &FitOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("at least 12") && e.contains("got 10 stars over 2 frames"),
        "{e}"
    );
    let e = fit(&rough(&truth), &[], &FitOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("got 0 stars over 0 frames"), "{e}");
}

#[test]
fn folding_distortion_is_rejected() {
    let mut cam = true_camera();
    check_monotonic(&cam).unwrap();
    cam.k1 = -1.5; // 1 − 4.5 r² vanishes at r ≈ 0.47, inside the corner (r_d ≈ 0.55)
    cam.k2 = 0.0;
    let e = check_monotonic(&cam).unwrap_err().to_string();
    assert!(e.contains("folds the image"), "{e}");
    cam.k1 = 0.3;
    cam.k2 = -3.0;
    assert!(check_monotonic(&cam).is_err());
    cam.k2 = 0.0;
    check_monotonic(&cam).unwrap();
}

/// A principal point fixed to a pixel is no step; a looser one is told with how many of its
/// 1σ it lies from the one given, on the worse axis (a lens 23 px off centre whose frames
/// show stars in their upper 40 % only: 1.4 px, about 16σ).
#[test]
fn a_loose_principal_point_is_told_with_its_shift() {
    let given = (511.5, 511.5);
    assert!(centre_step(given, (529.5, 497.5), (0.3, 0.3)).is_none());
    // Not fitted (0): no step.
    assert!(centre_step(given, given, (0.0, 0.0)).is_none());
    let (sd, shift) = centre_step(given, (513.0, 510.0), (1.4, 2.0)).unwrap();
    assert_eq!(sd, 2.0);
    assert!((shift - 1.5 / 1.4).abs() < 1e-9);
    // 18 px / 1.4 = 12.9σ in x, 14 px / 1.2 = 11.7σ in y: the worse axis.
    let (sd, shift) = centre_step(given, (529.5, 497.5), (1.4, 1.2)).unwrap();
    assert_eq!(sd, 1.4);
    assert!((shift - 18.0 / 1.4).abs() < 1e-9);
}
