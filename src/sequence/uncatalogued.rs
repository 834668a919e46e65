//! Detections the catalog says are not stars (issue 49): in a solved frame, a detection
//! bright enough that the reference stars would hold it, with none of them near it, or far
//! brighter than any of them near it.
//!
//! A particle that moves slowly against the stars, or has just come into view at the edge,
//! shows its motion only after several frames: the step test ([`super::particles`]) calls it
//! a star within a frame or two, and the drift test needs two pixels of motion. Its brightness
//! tells sooner. The matched stars give the frame's photometric zero point, and with it the
//! magnitude of every detection; the reference selection holds every star down to its limit
//! (the faintest in view, at most the selection's own), so a detection [`MARGIN_MAG`] brighter
//! than that with no reference star within [`RADIUS_PX`] is no star. Nor is one [`MARGIN_MAG`]
//! brighter than the brightest reference star within that radius: a particle passing over a
//! faint star, whose blend is the particle's light at the particle's place (matched, it would
//! put a particle among the identified stars). Its track becomes a particle, as the step test
//! would call it after steps it has not yet taken.
//!
//! What it cannot be is a star; what it is the frame does not say: a planet in the field is
//! called a particle too. Stars the selection dropped (`--double-stars drop`) leave it holes,
//! so the test is not made there.

use crate::catalog::{DoubleStars, RefCatalog};
use crate::solve::detect::Detection;
use crate::solve::refine::{self, Refined};

/// How much brighter than any reference star that could be it a detection must be: the
/// catalog's band and the sensor's differ by star colour (Hp against a bare silicon sensor,
/// a few tenths for most stars), and a component's flux by how much of a wide PSF clears the
/// threshold.
pub const MARGIN_MAG: f64 = 1.5;
/// A reference star this close (pixels) leaves a detection to the motion tests: a star whose
/// centroid a passing particle pulled aside is not a missing star.
pub const RADIUS_PX: f64 = 6.0;
/// Fewest matched stars for the zero point.
pub const MIN_MATCHES: usize = 5;

/// Which detections of the solved frame `r` (its matches index `dets`) are no star of `refs`:
/// matched ones too, whose matches are then blends.
pub fn uncatalogued(r: &Refined, refs: &RefCatalog, dets: &[Detection]) -> Vec<bool> {
    let mut flags = vec![false; dets.len()];
    if refs.selection.double_stars == DoubleStars::Drop || r.matches.len() < MIN_MATCHES {
        return flags;
    }
    let mut zero: Vec<f64> = r
        .matches
        .iter()
        .filter(|m| dets[m.det].flux > 0.0)
        .map(|m| refs.star(m.ref_id as usize).mag + 2.5 * dets[m.det].flux.log10())
        .collect();
    if zero.len() < MIN_MATCHES {
        return flags;
    }
    zero.sort_by(f64::total_cmp);
    let zero_point = zero[zero.len() / 2];
    let near = refine::stars_around_view(&r.r, refs, &r.camera, RADIUS_PX);
    let faintest = near
        .iter()
        .map(|&(id, _, _)| refs.star(id as usize).mag)
        .fold(f64::NEG_INFINITY, f64::max)
        .min(refs.selection.mag_limit);
    for (j, d) in dets.iter().enumerate() {
        if d.flux <= 0.0 {
            continue;
        }
        // The brightest star that could be this detection: a reference star near it (its
        // match's star among them), else one the selection is too shallow to hold.
        let own = r.matches.iter().filter(|m| m.det == j).map(|m| m.ref_id);
        let nearby = near
            .iter()
            .filter(|&&(_, x, y)| (x - d.x).hypot(y - d.y) <= RADIUS_PX)
            .map(|&(id, _, _)| id);
        let brightest = own
            .chain(nearby)
            .map(|id| refs.star(id as usize).mag)
            .reduce(f64::min)
            .unwrap_or(faintest);
        flags[j] = zero_point - 2.5 * d.flux.log10() <= brightest - MARGIN_MAG;
    }
    flags
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::catalog::{Catalog, Selection};
    use crate::solve::refine::Match;
    use rand::SeedableRng;

    fn detection(x: f64, y: f64, mag: f64) -> Detection {
        Detection {
            x,
            y,
            flux: 10f64.powf(-0.4 * (mag - 20.0)),
            area: 9,
            peak: 100,
            saturated: false,
            sigma_px: None,
        }
    }

    /// An 18° frame of the built-in catalog (Hp ≤ 6.5) with its stars detected, the brightest
    /// matched, and detections no star of the frame's list explains. Flagged: a bright one far
    /// from every star, and a matched star's detection 2.5 mag brighter than the star (a
    /// blend). Not flagged: one a magnitude brighter than the unmatched star 4 px from it (a
    /// star pulled aside, left to the motion tests), a faint one far from every star (the
    /// catalog need not hold it), and one on the border row by a bright star just beyond the
    /// edge (its light, clipped).
    #[test]
    fn a_bright_detection_the_catalog_lacks_is_no_star() {
        let refs = |double_stars| {
            let selection = Selection {
                epoch: 2025.0,
                mag_limit: 6.5,
                double_stars,
                double_sep_rad: 0.0,
            };
            RefCatalog::select(&Catalog::builtin(), selection).unwrap()
        };
        let keep = refs(DoubleStars::Keep);
        let camera = Camera::from_fov(1024, 1024, 18.0).unwrap();
        let mag = |id: u32| keep.star(id as usize).mag;
        // The border row's pixel nearest a star of Hp 4 or brighter within 3 px beyond the
        // edge, and the star's magnitude.
        let edge = |around: &[(u32, f64, f64)]| {
            around.iter().find_map(|&(id, x, y)| {
                let at = (x.clamp(0.0, 1023.0), y.clamp(0.0, 1023.0));
                let off = (x - at.0).hypot(y - at.1);
                (off > 0.5 && off <= 3.0 && mag(id) <= 4.0).then_some((at, mag(id)))
            })
        };
        let (r, around, edge) = (0..)
            .find_map(|seed| {
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
                let r = crate::simulate::random_rotation(&mut rng);
                let around = refine::stars_around_view(&r, &keep, &camera, RADIUS_PX);
                edge(&around).map(|at| (r, around, at))
            })
            .unwrap();
        let in_view = refine::stars_in_view(&r, &keep, &camera);
        let mut dets: Vec<Detection> = in_view
            .iter()
            .map(|&(id, x, y)| detection(x, y, mag(id)))
            .collect();
        let matches: Vec<Match> = (0..dets.len())
            .filter(|&j| mag(in_view[j].0) <= 5.0)
            .map(|j| Match {
                det: j,
                ref_id: in_view[j].0,
                residual_arcsec: 0.0,
                residual_px: 0.0,
                sigma_px: None,
            })
            .collect();
        assert!(matches.len() >= MIN_MATCHES, "{} matches", matches.len());
        // A place 40 px or more from every star.
        let clear = (0..1024 * 1024)
            .map(|i| (f64::from(i % 1024), f64::from(i / 1024)))
            .find(|&(x, y)| {
                (100.0..900.0).contains(&x)
                    && (100.0..900.0).contains(&y)
                    && around
                        .iter()
                        .all(|&(_, sx, sy)| (sx - x).hypot(sy - y) >= 40.0)
            })
            .unwrap();
        let unmatched = (0..dets.len()).find(|&j| mag(in_view[j].0) > 5.0).unwrap();
        let blend = matches[matches.len() / 2].det;
        dets[blend].flux *= 10.0;
        let first = dets.len();
        dets.push(detection(clear.0, clear.1, 3.0));
        let pulled = mag(in_view[unmatched].0) - 1.0;
        dets.push(detection(
            dets[unmatched].x + 4.0,
            dets[unmatched].y,
            pulled,
        ));
        dets.push(detection(clear.0 + 20.0, clear.1, 5.5));
        let ((x, y), edge_mag) = edge;
        dets.push(detection(x, y, edge_mag + 0.5));
        let refined = Refined {
            r,
            camera: camera.clone(),
            matches,
            in_view: in_view.len(),
            rmse_arcsec: 0.0,
            p90_arcsec: 0.0,
            max_arcsec: 0.0,
            false_match_prob: 0.0,
            hypotheses: 1,
            fixed: 2,
            sigma_floor_px: None,
        };
        let flags = uncatalogued(&refined, &keep, &dets);
        let flagged: Vec<usize> = (0..dets.len()).filter(|&j| flags[j]).collect();
        assert_eq!(flagged, vec![blend, first]);
        // Where the selection dropped stars it has holes: nothing is flagged.
        let drop = refs(DoubleStars::Drop);
        assert!(!uncatalogued(&refined, &drop, &dets).iter().any(|&f| f));
    }
}
