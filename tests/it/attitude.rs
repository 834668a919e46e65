//! Attitude from known vectors (Wahba by SVD) and the record's pointing quantities.

use gpustar::camera::Camera;
use gpustar::solve::attitude::*;
use nalgebra::{Matrix3, Rotation3, Vector3};

#[test]
fn wahba_recovers_a_known_rotation_from_noisy_vectors() {
    let truth = Rotation3::from_euler_angles(0.3, -1.1, 2.0).into_inner();
    let icrs: Vec<Vector3<f64>> = [
        (0.1, 0.2, 1.0),
        (-0.2, 0.1, 1.0),
        (0.05, -0.15, 1.0),
        (0.12, 0.01, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vector3::new(x, y, z).normalize())
    .collect();
    let cam: Vec<Vector3<f64>> = icrs.iter().map(|v| truth * v).collect();
    let r = wahba(&cam, &icrs).unwrap();
    assert!(attitude_error(&r, &truth) < 1e-12);
    assert!((r.determinant() - 1.0).abs() < 1e-12);
    // 1e-6 rad of noise moves the answer by about that much, not more.
    let noisy: Vec<Vector3<f64>> = cam
        .iter()
        .enumerate()
        .map(|(k, v)| (v + Vector3::new(1e-6 * (k as f64 - 1.5), -1e-6, 0.0)).normalize())
        .collect();
    let r = wahba(&noisy, &icrs).unwrap();
    assert!(attitude_error(&r, &truth) < 2e-5);
    assert!(wahba(&cam[..1], &icrs[..1]).is_none());
}

#[test]
fn quaternion_round_trip_has_positive_scalar() {
    let r = Rotation3::from_euler_angles(2.9, 0.4, -2.5).into_inner();
    let q = quaternion(&r);
    assert!(q[0] >= 0.0);
    assert!(attitude_error(&matrix_of_quaternion(q), &r) < 1e-12);
}

#[test]
fn pointing_of_an_identity_like_attitude() {
    // Camera rows = ICRS axes arranged so the boresight is RA 0, Dec 0 and image up is north:
    // X (right) = west = −y_icrs (east is left when looking out), Y (down) = south = −z_icrs,
    // Z = +x_icrs.
    let r: Matrix3<f64> = Matrix3::new(0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0);
    assert!((r.determinant() - 1.0).abs() < 1e-12);
    let cam = Camera::from_fov(101, 101, 10.0).unwrap();
    let p = pointing(&r, &cam);
    assert!(p.ra_deg.abs() < 1e-9 || (p.ra_deg - 360.0).abs() < 1e-9);
    assert!(p.dec_deg.abs() < 1e-9);
    assert!(p.roll_deg.abs() < 1e-6 || (p.roll_deg - 360.0).abs() < 1e-6);
}

#[test]
fn attitude_error_is_accurate_for_tiny_angles_and_rounded_matrices() {
    let a = Rotation3::from_euler_angles(0.3, -1.1, 2.0).into_inner();
    let tiny = Rotation3::from_axis_angle(&Vector3::y_axis(), 1e-6).into_inner();
    let b = tiny * a;
    assert!((attitude_error(&b, &a) - 1e-6).abs() < 1e-12);
    // Rounded to 9 decimals, as truth files are: still within 0.01 arcsec.
    let rounded = b.map(|x| (x * 1e9).round() / 1e9);
    let err = attitude_error(&rounded, &a);
    assert!((err - 1e-6).abs() < 5e-8, "{err}");
    assert!(
        (attitude_error(
            &a,
            &(Rotation3::from_axis_angle(&Vector3::x_axis(), 2.5).into_inner() * a)
        ) - 2.5)
            .abs()
            < 1e-12
    );
}

#[test]
fn roll_is_measured_on_the_sky_also_with_non_square_pixels() {
    // Swarm's star tracker: 752×290 pixels of 88.9″ × 171.4″. The identity-like attitude of
    // the test above, turned by 30° about the line of sight.
    let mut cam = Camera::from_fov(752, 290, 18.4).unwrap();
    cam.fy = cam.fx * 88.9 / 171.4;
    let r0: Matrix3<f64> = Matrix3::new(0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0);
    let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians()).into_inner();
    let r = turn * r0;
    // North in the camera frame; up is −y and left is −x on the sky at the boresight.
    let n = r * Vector3::z();
    let on_sky = (-n.x).atan2(-n.y).to_degrees().rem_euclid(360.0);
    let in_pixels = (-n.x * cam.fx)
        .atan2(-n.y * cam.fy)
        .to_degrees()
        .rem_euclid(360.0);
    assert!((on_sky - in_pixels).abs() > 10.0, "{on_sky} vs {in_pixels}");
    let p = pointing(&r, &cam);
    assert!(
        (p.roll_deg - on_sky).abs() < 1e-6,
        "{} vs {on_sky}",
        p.roll_deg
    );
    assert!(p.ra_deg.abs() < 1e-9 || (p.ra_deg - 360.0).abs() < 1e-9);
    assert!(p.dec_deg.abs() < 1e-9);
}

/// Records carry the attitude's 1σ and the rotation matrix's orthonormality: on simulated
/// frames (centroid noise 0.3 px) the errors against the truth are of the size the 1σ says
/// (median error / 1σ near a Rayleigh's 0.83 across the line of sight, |N|'s 0.67 in roll), and
/// ‖RRᵀ − I‖ is at rounding level.
#[test]
fn records_carry_a_calibrated_attitude_sigma_and_orthonormality() {
    let catalog = gpustar::catalog::Catalog::builtin();
    let s = gpustar::simulate::SimSettings {
        centroid_noise_px: 0.3,
        frames: 20,
        seed: 9,
        ..Default::default()
    };
    let camera = s.camera().unwrap();
    let solver = gpustar::solve::Solver::new(
        &catalog,
        camera.clone(),
        gpustar::solve::Settings::default(),
    )
    .unwrap();
    let (mut across, mut roll) = (Vec::new(), Vec::new());
    for k in 0..s.frames {
        let (pixels, truth) = gpustar::simulate::render(&catalog, &s, k).unwrap();
        let frame = gpustar::io::frame::Frame {
            width: camera.width,
            height: camera.height,
            pixels: pixels.into(),
            saturation: 255,
        };
        let (sol, _, _) = solver.solve_frame_at(&frame, None);
        let rec = solver.record("f", &sol, Default::default(), "cpu");
        let Some(sigma) = rec.attitude_sigma_arcsec else {
            continue;
        };
        assert!(rec.orthogonality_error.unwrap() < 1e-12, "{rec:?}");
        assert!((rec.determinant.unwrap() - 1.0).abs() < 1e-12);
        let m = |a: [[f64; 3]; 3]| nalgebra::Matrix3::from_fn(|i, j| a[i][j]);
        let d = m(rec.rotation_matrix.unwrap()) * m(truth.rotation_matrix).transpose();
        let w = nalgebra::Vector3::new(
            d[(2, 1)] - d[(1, 2)],
            d[(0, 2)] - d[(2, 0)],
            d[(1, 0)] - d[(0, 1)],
        ) / 2.0
            * 206_264.8;
        across.push(w.x.hypot(w.y) / sigma.boresight);
        roll.push(w.z.abs() / sigma.roll);
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    assert!(across.len() >= 18, "{} solved", across.len());
    let (a, r) = (median(across), median(roll));
    assert!(
        (0.4..1.6).contains(&a) && (0.3..1.4).contains(&r),
        "across {a}, roll {r}"
    );
}
