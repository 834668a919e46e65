//! Attitude: Wahba's problem by SVD in f64, and the quantities of the result record.

use crate::camera::Camera;
use crate::catalog::vector_to_radec;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// The rotation R with v_cam = R · v_icrs that best maps `icrs[k]` onto `cam[k]` (least squares,
/// equal weights): R = U diag(1, 1, det U · det V) Vᵀ for B = Σ cam·icrsᵀ = U S Vᵀ.
/// None when fewer than two distinct directions are given.
pub fn wahba(cam: &[Vector3<f64>], icrs: &[Vector3<f64>]) -> Option<Matrix3<f64>> {
    wahba_weighted(cam, icrs, &vec![1.0; cam.len()])
}

/// As [`wahba`], with weights: B = Σ w·cam·icrsᵀ (weights 1/σ² make it the maximum-likelihood
/// attitude for independent isotropic errors; Shuster's QUEST model).
pub fn wahba_weighted(
    cam: &[Vector3<f64>],
    icrs: &[Vector3<f64>],
    weights: &[f64],
) -> Option<Matrix3<f64>> {
    if cam.len() < 2 || cam.len() != icrs.len() || weights.len() != cam.len() {
        return None;
    }
    let b: Matrix3<f64> = cam
        .iter()
        .zip(icrs)
        .zip(weights)
        .map(|((c, r), w)| c * r.transpose() * *w)
        .sum();
    let svd = b.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let d = (u.determinant() * v_t.determinant()).signum();
    let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t;
    let r = polish(r, cam, icrs, weights);
    r.iter().all(|x| x.is_finite()).then_some(r)
}

/// The attitude of matched directions when the image may be a mirror image of the sky: the
/// better of Wahba's fits to `cam` as it is and to `cam` mirrored (camera y negated, which is
/// what [`Camera::mirrored`] does to a pixel's direction), by the sum of squared residuals, and
/// whether it is the mirrored one. Only with `either`; otherwise `cam` as it is. The vote, its
/// verification and the pattern keys see distances only, which a mirror keeps: the parity is
/// first decided here, from the matched stars' arrangement.
pub fn wahba_parity(
    cam: &[Vector3<f64>],
    icrs: &[Vector3<f64>],
    either: bool,
) -> Option<(Matrix3<f64>, bool)> {
    let direct = wahba(cam, icrs);
    if !either {
        return direct.map(|r| (r, false));
    }
    let flipped: Vec<_> = cam.iter().map(|v| Vector3::new(v.x, -v.y, v.z)).collect();
    let mirror = wahba(&flipped, icrs);
    let loss = |r: &Matrix3<f64>, c: &[Vector3<f64>]| -> f64 {
        c.iter()
            .zip(icrs)
            .map(|(c, v)| (c - r * v).norm_squared())
            .sum()
    };
    match (direct, mirror) {
        (Some(a), Some(b)) if loss(&b, &flipped) < loss(&a, cam) => Some((b, true)),
        (Some(a), _) => Some((a, false)),
        (None, Some(b)) => Some((b, true)),
        (None, None) => None,
    }
}

/// Gauss–Newton steps on Wahba's own loss Σ w |cam − R·icrs|² from the SVD's rotation. On a
/// narrow field B is nearly of rank one (its small singular values are θ² of its large one,
/// 2·10⁻⁵ at 0.5°), and the SVD resolves the rotation about the boresight only to about 10⁻⁶
/// rad: two backends' centroids 3·10⁻⁷ px apart gave rolls 0.8″ apart. The step
/// δ = [Σ w (I − p pᵀ)]⁻¹ Σ w p × c (p = R·icrs) keeps the roll's information, which is in
/// the differences c − p. A step below [`POLISH_MIN_STEP`] leaves R as it is: on wide fields
/// the SVD is within 2·10⁻¹¹ rad, and their records stay as they were.
fn polish(
    mut r: Matrix3<f64>,
    cam: &[Vector3<f64>],
    icrs: &[Vector3<f64>],
    weights: &[f64],
) -> Matrix3<f64> {
    for _ in 0..POLISH_STEPS {
        let (mut h, mut g) = (Matrix3::zeros(), Vector3::zeros());
        for ((c, v), &w) in cam.iter().zip(icrs).zip(weights) {
            let p = r * v;
            h += (Matrix3::identity() - p * p.transpose()) * w;
            g += p.cross(c) * w;
        }
        let Some(step) = h.lu().solve(&g) else {
            break;
        };
        if step.norm().is_nan() || step.norm() <= POLISH_MIN_STEP {
            break;
        }
        r = Rotation3::new(step).matrix() * r;
    }
    r
}

/// Most Gauss–Newton steps of [`polish`] (each gains many digits: the loss is quadratic).
const POLISH_STEPS: usize = 4;
/// A step (radians) below which the rotation is left as it is: 2·10⁻⁵″.
const POLISH_MIN_STEP: f64 = 1e-10;

/// The record's view of an attitude.
#[derive(Clone, Copy, Debug)]
pub struct Pointing {
    pub ra_deg: f64,
    pub dec_deg: f64,
    pub roll_deg: f64,
    /// [w, x, y, z], Hamilton, w ≥ 0.
    pub quaternion: [f64; 4],
}

/// Quaternion [w, x, y, z] (w ≥ 0) of a rotation matrix.
pub fn quaternion(r: &Matrix3<f64>) -> [f64; 4] {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.w, s * q.i, s * q.j, s * q.k]
}

/// Rotation matrix of a quaternion [w, x, y, z].
pub fn matrix_of_quaternion(q: [f64; 4]) -> Matrix3<f64> {
    let uq = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
    *uq.to_rotation_matrix().matrix()
}

/// RA/Dec of the image centre pixel and the roll: the angle on the sky at the centre from
/// image up (toward row 0) to celestial north, counter-clockwise as displayed (toward image
/// left); tetra3's `Roll`. Measured on the sky, not in pixels, so that non-square pixels
/// (Swarm's 88.9″ × 171.4″) give the rotation about the line of sight, as the truth files'
/// `roll_tetra3_deg` does; for square pixels at the principal point the two are the same.
pub fn pointing(r: &Matrix3<f64>, camera: &Camera) -> Pointing {
    let (xc, yc) = camera.centre_pixel();
    let centre_cam = camera.centre_vector();
    let centre = r.transpose() * centre_cam;
    let (ra_deg, dec_deg) = vector_to_radec(&centre);
    // Directions in the camera frame, in the tangent plane at the centre.
    let tangent = |v: Vector3<f64>| v - centre_cam * v.dot(&centre_cam);
    let mut north = tangent(r * Vector3::z());
    if north.norm() < 1e-12 {
        // At a pole every direction is south; use the direction of RA 0 instead.
        north = tangent(r * Vector3::x());
    }
    // Image up, and image left made perpendicular to it (off the principal point,
    // distortion can bend the pixel axes).
    let up = tangent(camera.pixel_to_vector(xc, yc - 1.0)).normalize();
    let left = tangent(camera.pixel_to_vector(xc - 1.0, yc));
    let left = (left - up * left.dot(&up)).normalize();
    let roll_deg = north
        .dot(&left)
        .atan2(north.dot(&up))
        .to_degrees()
        .rem_euclid(360.0);
    Pointing {
        ra_deg,
        dec_deg,
        roll_deg,
        quaternion: quaternion(r),
    }
}

/// Angle of the rotation between two attitudes (radians): atan2 of the skew part (sin θ) and
/// the trace (cos θ) of A·Bᵀ, accurate at small angles even for matrices rounded to 9 digits,
/// where acos of the trace alone loses arcseconds.
pub fn attitude_error(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    let d = a * b.transpose();
    let sin = Vector3::new(
        d[(2, 1)] - d[(1, 2)],
        d[(0, 2)] - d[(2, 0)],
        d[(1, 0)] - d[(0, 1)],
    )
    .norm()
        / 2.0;
    sin.atan2((d.trace() - 1.0) / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stars within `radius` (radians) of the boresight of `r`, on a spiral (no randomness),
    /// as (camera, ICRS) unit vectors.
    fn narrow_field(
        r: &Matrix3<f64>,
        radius: f64,
        n: usize,
    ) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
        (0..n)
            .map(|k| {
                let (t, a) = (radius * (k as f64 + 1.0) / n as f64, 2.4 * k as f64);
                let cam = Vector3::new(t * a.cos(), t * a.sin(), 1.0).normalize();
                (cam, r.transpose() * cam)
            })
            .unzip()
    }

    /// Issue 24: on a half-degree field the SVD alone leaves the roll uncertain to about 10⁻⁶
    /// rad; with the Gauss–Newton polish the exact rotation comes back to rounding, and
    /// centroids 10⁻¹² rad apart give rotations 10⁻¹⁰ rad apart at most.
    #[test]
    fn narrow_fields_keep_their_roll() {
        let truth = *Rotation3::from_euler_angles(0.3, -1.1, 2.0).matrix();
        let (cam, icrs) = narrow_field(&truth, 0.26f64.to_radians(), 13);
        let w: Vec<f64> = (0..cam.len())
            .map(|k| 10.0 + 500.0 * (k % 4) as f64)
            .collect();
        let r = wahba_weighted(&cam, &icrs, &w).unwrap();
        assert!(
            attitude_error(&r, &truth) < 1e-11,
            "{}",
            attitude_error(&r, &truth)
        );
        let nudged: Vec<Vector3<f64>> = cam
            .iter()
            .enumerate()
            .map(|(k, c)| (c + Vector3::new(1e-12, -1e-12, 0.0) * (k % 3) as f64).normalize())
            .collect();
        let r2 = wahba_weighted(&nudged, &icrs, &w).unwrap();
        assert!(
            attitude_error(&r, &r2) < 1e-10,
            "{}",
            attitude_error(&r, &r2)
        );
    }
}
