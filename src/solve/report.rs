//! A solution as a result record, with the attitude's 1σ and quality checks.

use super::attitude::pointing;
use super::refine;
use super::{Outcome, Solution, Solver};
use crate::catalog::{RefCatalog, StarId, vector_to_radec};
use crate::record::{MatchRecord, Record, Status, Timing};

impl Solver {
    /// The result record of a solution.
    pub fn record(&self, name: &str, sol: &Solution, timing_ms: Timing, backend: &str) -> Record {
        let mut rec = Record::empty(name, backend);
        rec.stars_detected = Some(sol.detections.len());
        rec.timing_ms = timing_ms;
        match &sol.outcome {
            Outcome::Unsolved(reason) => {
                rec.status = Status::Unsolved;
                rec.reason = Some(reason.to_string());
            }
            Outcome::Solved(r, refs) => {
                rec.epoch = Some(refs.selection.epoch);
                let p = pointing(&r.r, &r.camera);
                rec.status = Status::Solved;
                rec.ra_deg = Some(p.ra_deg);
                rec.dec_deg = Some(p.dec_deg);
                rec.roll_deg = Some(p.roll_deg);
                rec.quaternion = Some(p.quaternion);
                rec.rotation_matrix = Some(std::array::from_fn(|i| {
                    std::array::from_fn(|j| r.r[(i, j)])
                }));
                rec.fov_x_deg = Some(r.camera.fov_x_deg());
                rec.fov_y_deg = Some(r.camera.fov_y_deg());
                if self.settings.parity == super::Parity::Either || r.camera.mirrored {
                    rec.mirrored = Some(r.camera.mirrored);
                }
                if r.camera.k1 != self.camera.k1 {
                    rec.distortion_k1 = Some(r.camera.k1);
                }
                rec.camera = Some(r.camera.clone());
                rec.stars_matched = Some(r.matches.len());
                rec.rmse_arcsec = Some(r.rmse_arcsec);
                rec.p90_arcsec = Some(r.p90_arcsec);
                rec.max_arcsec = Some(r.max_arcsec);
                rec.false_match_prob = Some(r.false_match_prob);
                let (sigma, ortho, det) = attitude_quality(r, refs);
                rec.attitude_sigma_arcsec = sigma;
                rec.orthogonality_error = Some(ortho);
                rec.sigma_floor_px = r.sigma_floor_px;
                rec.determinant = Some(det);
                if ortho > ORTHOGONALITY_WARN || (det - 1.0).abs() > ORTHOGONALITY_WARN {
                    rec.warnings.push(format!(
                        "the rotation matrix is not orthonormal to 1e-9: ‖RRᵀ − I‖ = {ortho:.2e}, \
                         det = {det:.12}"
                    ));
                }
                let mut matches: Vec<(MatchRecord, StarId)> = r
                    .matches
                    .iter()
                    .map(|m| {
                        let d = &sol.detections[m.det];
                        let star = refs.star(m.ref_id as usize);
                        let (ra, dec) = vector_to_radec(&star.v);
                        let rec = MatchRecord {
                            x: d.x,
                            y: d.y,
                            hip: star.hip,
                            ra_deg: ra,
                            dec_deg: dec,
                            mag: star.mag,
                            flux: d.flux,
                            residual_arcsec: m.residual_arcsec,
                            sigma_px: d.sigma_px,
                            catalog_id: refs.catalog_id(m.ref_id as usize),
                        };
                        (rec, star.id)
                    })
                    .collect();
                // Brightest first; ties by catalog id (by HIP for Hipparcos, as always).
                matches.sort_by(|(a, ia), (b, ib)| b.flux.total_cmp(&a.flux).then(ia.cmp(ib)));
                rec.matches = Some(matches.into_iter().map(|(m, _)| m).collect());
            }
        }
        rec
    }
}

/// Beyond this ‖RRᵀ − I‖ or |det R − 1| a record warns (Wahba's SVD gives 1e-15).
pub const ORTHOGONALITY_WARN: f64 = 1e-9;

/// The attitude's 1σ from its matches (Shuster: P = [Σ (1/σ_i²)(I − b bᵀ)]⁻¹ in the camera frame,
/// b the matched stars' directions; σ_i each match's 1σ per axis (the PSF fit's with the frame's
/// floor, `refine::match_sigmas`, at the mean focal length), or without PSF fits the residuals'
/// rms per axis for all; boresight = √(Pxx + Pyy), roll = √Pzz), and ‖RRᵀ − I‖_F and det R. None
/// for the 1σ with fewer than 3 matches.
pub fn attitude_quality(
    r: &refine::Refined,
    refs: &RefCatalog,
) -> (Option<crate::record::AttitudeSigma>, f64, f64) {
    let ortho = (r.r * r.r.transpose() - nalgebra::Matrix3::identity()).norm();
    let det = r.r.determinant();
    if r.matches.len() < 3 {
        return (None, ortho, det);
    }
    // The residuals' rms is of 2-D angles: per axis it is 1/√2 of it.
    let rms = r.rmse_arcsec / std::f64::consts::SQRT_2 / 3600.0 * std::f64::consts::PI / 180.0;
    let focal = 0.5 * (r.camera.fx + r.camera.fy);
    let info: nalgebra::Matrix3<f64> = r
        .matches
        .iter()
        .map(|m| {
            let b = r.r * refs.v(m.ref_id as usize);
            let sigma = m.sigma_px.map_or(rms, |s| s / focal);
            (nalgebra::Matrix3::identity() - b * b.transpose()) / (sigma * sigma)
        })
        .sum();
    let Some(p) = info.try_inverse() else {
        return (None, ortho, det);
    };
    let arcsec = |v: f64| v.max(0.0).sqrt().to_degrees() * 3600.0;
    let s = crate::record::AttitudeSigma {
        boresight: arcsec(p[(0, 0)] + p[(1, 1)]),
        roll: arcsec(p[(2, 2)]),
    };
    (Some(s), ortho, det)
}
