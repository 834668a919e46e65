//! `gpustar evaluate`: compare result records with a truth file (simulated or real): how many
//! frames are solved correctly, how many wrongly, the attitude errors and false star IDs.

use crate::attitude::attitude_error;
use crate::camera::Camera;
use crate::catalog::radec_to_vector;
use crate::record::{Record, Status};
use crate::simulate::Truth;
use anyhow::{Context, Result};
use nalgebra::Matrix3;
use serde::Serialize;
use std::collections::HashMap;
use std::path::Path;

/// Per-frame verdict.
#[derive(Clone, Debug, Serialize)]
pub struct FrameVerdict {
    pub file: String,
    pub status: Status,
    /// Solved within the tolerance.
    pub correct: bool,
    /// Attitude error (arcsec), for solved frames.
    pub error_arcsec: Option<f64>,
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
                v.correct = err <= tol_deg;
                if v.correct {
                    s.correct += 1;
                    errors.push(err * 3600.0);
                } else {
                    s.wrong += 1;
                }
                let cam = truth_camera(t);
                let truth_r = matrix(&t.rotation_matrix);
                for m in rec.matches.iter().flatten() {
                    s.matched_ids += 1;
                    // A star of the truth list must be where the truth says; another star must
                    // be where the truth attitude puts its catalog position.
                    let ok = match t.stars.iter().find(|ts| ts.hip == m.hip) {
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

/// Read result records (JSON Lines).
pub fn read_records(path: &Path) -> Result<Vec<Record>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read results {}", path.display()))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(n, l)| {
            serde_json::from_str(l)
                .with_context(|| format!("{}: line {}: not a result record", path.display(), n + 1))
        })
        .collect()
}
