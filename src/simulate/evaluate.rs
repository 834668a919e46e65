//! `gpustar evaluate`: compare result records with a truth file (simulated or real): how many
//! frames are solved correctly, how many wrongly, the attitude errors and false star IDs.

use crate::camera::Camera;
use crate::catalog::radec_to_vector;
use crate::record::{MatchRecord, Record, Status};
use crate::simulate::{Truth, TruthStar};
use crate::solve::attitude::attitude_error;
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;
use std::collections::HashMap;

/// Per-frame verdict.
#[derive(Clone, Debug, Serialize)]
pub struct FrameVerdict {
    pub file: String,
    pub status: Status,
    /// Solved within the tolerance.
    pub correct: bool,
    /// Attitude error (arcsec), for solved frames: the angle of the rotation between the
    /// record's and the truth's rotation matrices.
    pub error_arcsec: Option<f64>,
    /// The record's image-centre RA/Dec against the truth's (arcsec), for solved frames.
    pub centre_error_arcsec: Option<f64>,
    /// The record's `roll_deg` (angle from image up to north on the sky, tetra3's `Roll`) minus
    /// the truth's `roll_tetra3_deg` (arcsec, within ±180°), for solved frames that are not
    /// mirrored. The truth's matrix follows its image x axis and its roll
    /// the y axis: where the truth's WCS leaves them off perpendicular (stars in part of the
    /// frame) the two disagree, and this says how far the record is from the roll.
    pub roll_error_arcsec: Option<f64>,
    /// Matches whose HIP is not a truth star of this frame within `id_tol_px` of the centroid.
    pub false_ids: usize,
    /// The other matches: stars identified correctly.
    pub correct_ids: usize,
    /// The record's identification time (ms).
    pub identify_ms: f64,
    /// Catalog stars whose centre falls on the frame (from the truth file).
    pub stars_in_view: usize,
}

/// Totals over a set.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Summary {
    pub frames: usize,
    pub solved: usize,
    pub correct: usize,
    pub wrong: usize,
    pub unsolved: usize,
    pub errors: usize,
    /// Frames with a truth line but no record.
    pub missing: usize,
    pub median_error_arcsec: Option<f64>,
    pub p90_error_arcsec: Option<f64>,
    pub max_error_arcsec: Option<f64>,
    /// Correct solutions with at least one false star ID.
    pub frames_with_false_ids: usize,
    pub false_ids: usize,
    pub matched_ids: usize,
}

/// The pinhole camera a truth line describes (its FOVs give fx and fy).
fn truth_camera(t: &Truth) -> Camera {
    let mut cam = Camera::from_fov(
        t.width.max(1),
        t.height.max(1),
        t.fov_x_deg.clamp(0.01, 160.0),
    )
    .expect("clamped to a valid camera");
    if t.fov_y_deg > 0.0 {
        cam.fy = t.height as f64 / 2.0 / (t.fov_y_deg.to_radians() / 2.0).tan();
    }
    cam.mirrored = t.mirrored;
    cam
}

/// Fewest truth-list stars that [`truth_lens`] fits from.
const TRUTH_LENS_MIN_STARS: usize = 5;

/// Largest relative change of the focal lengths, and of the radius at the frame's corners,
/// that [`truth_lens`] accepts (virgo.jpg's: 0.6 % and 2.3 %).
const TRUTH_LENS_MAX: f64 = 0.05;

/// Whether a truth star is a record's match: by catalog id where both carry one (truth files
/// of other tools and older records do not), else by HIP.
fn same_star(ts: &TruthStar, m: &MatchRecord) -> bool {
    match &ts.catalog_id {
        Some(id) if !m.catalog_id.is_empty() => *id == m.catalog_id,
        _ => ts.hip.is_some() && ts.hip == m.hip,
    }
}

/// The truth camera `cam` (a pinhole of the truth's fields of view) with the focal lengths and
/// radial distortion k1 that the truth's own star list implies: its stars' pixel positions
/// against their catalog directions through the truth attitude, by least squares (the catalog
/// directions are those of the record's matches of those stars). A truth made with a
/// distorted lens (cedar-solve's virgo.jpg: up to 8 px from a pinhole) puts a star that is not
/// on its list where this camera does, not where the pinhole does (whose fields of view the
/// distortion has also bent). `cam` as it is with fewer than [`TRUTH_LENS_MIN_STARS`] such
/// stars, or when the fit is not a plausible lens (focal lengths or corner distortion more
/// than [`TRUTH_LENS_MAX`] off: an ill-conditioned fit, e.g. stars only near the centre).
fn truth_lens(t: &Truth, cam: &Camera, r: &Matrix3<f64>, matches: &[MatchRecord]) -> Camera {
    // Normalised coordinates (u, w) of the pinhole and (ou, ow) observed:
    // ou = u (1 + ex + k1 ρ²), ow = w (1 + ey + k1 ρ²), ρ² = u² + w²; unknowns (ex, ey, k1).
    let mut a = Matrix3::<f64>::zeros();
    let mut b = Vector3::<f64>::zeros();
    let mut n = 0;
    for m in matches {
        let Some(ts) = t.stars.iter().find(|ts| same_star(ts, m)) else {
            continue;
        };
        let Some((px, py)) = cam.vector_to_pixel(&(r * radec_to_vector(m.ra_deg, m.dec_deg)))
        else {
            continue;
        };
        let (u, w) = ((px - cam.cx) / cam.fx, (py - cam.cy) / cam.fy);
        let (ou, ow) = ((ts.x - cam.cx) / cam.fx, (ts.y - cam.cy) / cam.fy);
        let r2 = u * u + w * w;
        for (row, resid) in [
            (Vector3::new(u, 0.0, u * r2), ou - u),
            (Vector3::new(0.0, w, w * r2), ow - w),
        ] {
            a += row * row.transpose();
            b += row * resid;
        }
        n += 1;
    }
    let mut lens = cam.clone();
    let Some(x) = (n >= TRUTH_LENS_MIN_STARS)
        .then(|| a.lu().solve(&b))
        .flatten()
    else {
        return lens;
    };
    let corner2 = (cam.cx.max(cam.width as f64 - cam.cx) / cam.fx).powi(2)
        + (cam.cy.max(cam.height as f64 - cam.cy) / cam.fy).powi(2);
    if x[0].abs().max(x[1].abs()).max((x[2] * corner2).abs()) > TRUTH_LENS_MAX {
        return lens;
    }
    // ou = u (1 + ex) (1 + k1' ρ²) to first order in k1 ρ², with k1' = k1 / (1 + ex).
    lens.fx *= 1.0 + x[0];
    lens.fy *= 1.0 + x[1];
    lens.k1 = x[2] / (1.0 + 0.5 * (x[0] + x[1]));
    lens
}

fn matrix(m: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| m[i][j])
}

/// Compare records with truth by file name (the part after the last '/').
pub fn evaluate(
    truth: &[Truth],
    records: &[Record],
    tol_deg: f64,
    id_tol_px: f64,
) -> (Summary, Vec<FrameVerdict>) {
    let base = |f: &str| f.rsplit('/').next().unwrap_or(f).to_string();
    let by_name: HashMap<String, &Record> = records.iter().map(|r| (base(&r.file), r)).collect();
    let mut s = Summary::default();
    let mut verdicts = Vec::new();
    let mut errors = Vec::new();
    for t in truth {
        s.frames += 1;
        let Some(rec) = by_name.get(&base(&t.file)) else {
            s.missing += 1;
            continue;
        };
        let mut v = FrameVerdict {
            file: t.file.clone(),
            status: rec.status,
            correct: false,
            error_arcsec: None,
            centre_error_arcsec: None,
            roll_error_arcsec: None,
            false_ids: 0,
            correct_ids: 0,
            identify_ms: rec.timing_ms.identify,
            stars_in_view: t.stars.len(),
        };
        match rec.status {
            Status::Error => s.errors += 1,
            Status::Unsolved => s.unsolved += 1,
            Status::Solved => {
                s.solved += 1;
                let r = rec.rotation_matrix.map(|m| matrix(&m));
                let err = r
                    .map(|r| attitude_error(&r, &matrix(&t.rotation_matrix)).to_degrees())
                    .unwrap_or(f64::INFINITY);
                v.error_arcsec = Some(err * 3600.0);
                if let (Some(ra), Some(dec)) = (rec.ra_deg, rec.dec_deg) {
                    let centre = radec_to_vector(ra, dec)
                        .angle(&radec_to_vector(t.ra_deg, t.dec_deg))
                        .to_degrees();
                    v.centre_error_arcsec = Some(centre * 3600.0);
                }
                if let Some(roll) = rec.roll_deg.filter(|_| !t.mirrored) {
                    let d = (roll - t.roll_tetra3_deg + 180.0).rem_euclid(360.0) - 180.0;
                    v.roll_error_arcsec = Some(d * 3600.0);
                }
                v.correct = err <= tol_deg;
                if v.correct {
                    s.correct += 1;
                    errors.push(err * 3600.0);
                } else {
                    s.wrong += 1;
                }
                let truth_r = matrix(&t.rotation_matrix);
                let matches = rec.matches.as_deref().unwrap_or_default();
                let cam = truth_lens(t, &truth_camera(t), &truth_r, matches);
                for m in matches {
                    s.matched_ids += 1;
                    // A star of the truth list must be where the truth says; another star must
                    // be where the truth attitude puts its catalog position.
                    let ok = match t.stars.iter().find(|ts| same_star(ts, m)) {
                        Some(ts) => (ts.x - m.x).hypot(ts.y - m.y) <= id_tol_px,
                        None => {
                            let v = truth_r * radec_to_vector(m.ra_deg, m.dec_deg);
                            cam.vector_to_pixel(&v)
                                .is_some_and(|(x, y)| (x - m.x).hypot(y - m.y) <= id_tol_px)
                        }
                    };
                    if ok {
                        v.correct_ids += 1;
                    } else {
                        v.false_ids += 1;
                    }
                }
                s.false_ids += v.false_ids;
                if v.correct && v.false_ids > 0 {
                    s.frames_with_false_ids += 1;
                }
            }
        }
        verdicts.push(v);
    }
    errors.sort_by(f64::total_cmp);
    let q = |f: f64| {
        (!errors.is_empty()).then(|| errors[((errors.len() - 1) as f64 * f).round() as usize])
    };
    s.median_error_arcsec = q(0.5);
    s.p90_error_arcsec = q(0.9);
    s.max_error_arcsec = errors.last().copied();
    (s, verdicts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalog::vector_to_radec;
    use crate::simulate::TruthStar;

    /// A truth made through a lens with k1 = −0.5: eight listed stars and one
    /// off the list in a corner, where a pinhole puts it 5 px from where the lens does.
    #[test]
    fn a_star_off_the_truth_list_is_judged_with_the_distortion_the_list_implies() {
        let mut lens = Camera::from_fov(1920, 1080, 20.28).unwrap();
        lens.k1 = -0.5;
        let dirs: Vec<Vector3<f64>> = [
            (-700.0, -400.0),
            (600.0, -300.0),
            (-200.0, 350.0),
            (800.0, 450.0),
            (0.0, 0.0),
            (-850.0, 100.0),
            (300.0, 200.0),
            (-400.0, -100.0),
            (-950.0, 530.0), // off the list
        ]
        .iter()
        .map(|&(dx, dy)| lens.pixel_to_vector(lens.cx + dx, lens.cy + dy))
        .collect();
        let star = |k: usize| {
            let (x, y) = lens.vector_to_pixel(&dirs[k]).unwrap();
            (x, y, Some(1000 + k as u32))
        };
        let truth = Truth {
            file: "f.png".into(),
            ra_deg: 0.0,
            dec_deg: 0.0,
            roll_tetra3_deg: 0.0,
            rotation_matrix: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            quaternion: [1.0, 0.0, 0.0, 0.0],
            epoch: 2000.0,
            mirrored: false,
            width: 1920,
            height: 1080,
            fov_x_deg: lens.fov_x_deg(),
            fov_y_deg: lens.fov_y_deg(),
            stars: (0..8)
                .map(|k| {
                    let (x, y, hip) = star(k);
                    TruthStar {
                        hip,
                        catalog_id: None,
                        x,
                        y,
                        mag: 5.0,
                    }
                })
                .collect(),
            false_stars: Vec::new(),
            hint: None,
        };
        let mut rec = Record::empty("f.png", "cpu");
        rec.status = Status::Solved;
        rec.rotation_matrix = Some(truth.rotation_matrix);
        rec.matches = Some(
            (0..9)
                .map(|k| {
                    let (x, y, hip) = star(k);
                    let (ra_deg, dec_deg) = vector_to_radec(&dirs[k]);
                    MatchRecord {
                        x,
                        y,
                        hip,
                        ra_deg,
                        dec_deg,
                        mag: 5.0,
                        flux: 1.0,
                        residual_arcsec: 0.0,
                        sigma_px: None,
                        catalog_id: format!("HIP {}", hip.unwrap()),
                    }
                })
                .collect(),
        );
        let pinhole = truth_camera(&truth);
        let (px, py) = pinhole.vector_to_pixel(&dirs[8]).unwrap();
        let (x, y, _) = star(8);
        let off = (px - x).hypot(py - y);
        assert!(off > 3.0, "a pinhole puts it {off} px away");
        let fitted = truth_lens(
            &truth,
            &pinhole,
            &Matrix3::identity(),
            rec.matches.as_ref().unwrap(),
        );
        let (fx, fy) = fitted.vector_to_pixel(&dirs[8]).unwrap();
        let d = (fx - x).hypot(fy - y);
        assert!(d < 0.5, "the fitted lens puts it {d} px away");
        let (s, v) = evaluate(&[truth], &[rec], 0.1, 3.0);
        assert_eq!((s.correct, s.false_ids, v[0].correct_ids), (1, 0, 9));
    }
}
