//! Tracking mode: identification from a predicted attitude (tetra3rs's `attitude_hint`, LOST's
//! `--prev-attitude`). The catalog stars within the uncertainty cone of each bright detection's
//! predicted direction are its only candidates; the hypotheses are the prediction itself and
//! the pairs of candidates whose separation matches that of their detections. Each is refined
//! and judged by the lost-in-space false-match test, which counts every hypothesis the cone
//! admits (and the lost-in-space pass that follows a failure, as [`STAGES`] does there).

use crate::camera::Camera;
use crate::catalog::RefCatalog;
use crate::solve::attitude::wahba;
use crate::solve::detect::Detection;
use crate::solve::refine::{self, Refined};
use crate::solve::{STAGES, Solver};
use nalgebra::{Matrix3, Vector3};
use std::sync::Arc;

/// Tracking's settings.
#[derive(Clone, Copy, Debug)]
pub struct TrackSettings {
    /// The brightest this many detections make the pair hypotheses.
    pub stars: usize,
    /// Pair separation tolerance (pixels at the principal point).
    pub pair_tol_px: f64,
    /// At most this many hypotheses are refined before tracking gives up.
    pub max_tries: usize,
}

impl Default for TrackSettings {
    fn default() -> Self {
        TrackSettings {
            stars: 12,
            pair_tol_px: 1.0,
            max_tries: 2000,
        }
    }
}

/// The attitude the previous frames predict for this one.
#[derive(Clone, Debug)]
pub struct Prediction {
    /// ICRS → camera.
    pub r: Matrix3<f64>,
    /// The camera as the last solution fitted it (its scale and distortion, when fitted).
    pub camera: Camera,
    /// How far (radians) a star may be from where the prediction puts it.
    pub cone_rad: f64,
}

/// Identify `dets` (brightest first, particles left out) from a prediction: the first hypothesis
/// whose refinement passes the false-match test with at least 3 stars, or None (the frame then
/// goes to lost-in-space).
pub fn identify(
    solver: &Solver,
    dets: &[Detection],
    pred: &Prediction,
    epoch: Option<f64>,
    s: &TrackSettings,
) -> Option<(Refined, Arc<RefCatalog>)> {
    if dets.len() < 3 {
        return None;
    }
    let band = solver.band_of(pred.camera.fx / solver.camera.fx);
    let refs = solver.bands[band].refs_at(epoch);
    let camera = &pred.camera;
    let cone = pred.cone_rad.max(0.0);
    let n = dets.len().min(s.stars);
    let cam: Vec<Vector3<f64>> = dets[..n]
        .iter()
        .map(|d| camera.pixel_to_vector(d.x, d.y))
        .collect();
    // The catalog stars that can be in view, then each detection's candidates, nearest first.
    let boresight = pred.r.transpose() * camera.centre_vector();
    let reach = (camera.diagonal_rad() / 2.0 + cone + 0.01).min(std::f64::consts::PI);
    let near = refs.within(&boresight, reach);
    let tol = s.pair_tol_px * camera.ifov_rad();
    let candidates: Vec<Vec<u32>> = cam
        .iter()
        .map(|u| {
            let sky = pred.r.transpose() * u;
            let mut c: Vec<(f64, u32)> = near
                .iter()
                .map(|&id| (refs.v(id as usize).angle(&sky), id))
                .filter(|(a, _)| *a <= cone + tol)
                .collect();
            c.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            c.into_iter().map(|(_, id)| id).collect()
        })
        .collect();
    // Every hypothesis the cone admits, counted before any is tried.
    let mut pairs: Vec<(usize, usize, u32, u32)> = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            let sep = cam[i].angle(&cam[j]);
            for &a in &candidates[i] {
                for &b in &candidates[j] {
                    let d = refs.v(a as usize).angle(&refs.v(b as usize));
                    if a != b && (d - sep).abs() <= tol + solver.settings.identify.scale_tol * sep {
                        pairs.push((i, j, a, b));
                    }
                }
            }
        }
    }
    let hypotheses = (1 + pairs.len() as u64).saturating_mul(STAGES);
    let rs = &solver.settings.refine;
    let accept =
        |r: Refined| (r.false_match_prob <= rs.max_false_prob && r.matches.len() >= 3).then_some(r);
    let from = |r0: Matrix3<f64>, fixed: usize| {
        refine::refine(r0, dets, &refs, camera, hypotheses, fixed, rs).and_then(accept)
    };
    // The prediction is one more hypothesis; refinement fits the attitude to its matches, and
    // any two stars can be fitted exactly: they count as fixed, as for a pair.
    let accepted = from(pred.r, 2).or_else(|| {
        pairs.iter().take(s.max_tries).find_map(|&(i, j, a, b)| {
            let icrs = [refs.v(a as usize), refs.v(b as usize)];
            let r0 = wahba(&[cam[i], cam[j]], &icrs)?;
            from(r0, 2)
        })
    })?;
    // As lost-in-space does after a scale search: checked against the catalog as deep as the
    // fitted field calls for.
    Some(
        solver
            .deepen(&accepted, dets, band, rs, epoch)
            .unwrap_or((accepted, refs)),
    )
}
