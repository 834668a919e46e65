//! Solving within a pointing hint's region (issue 24, item 3): the catalog stars within the
//! hint's radius plus half the field's diagonal, their own magnitude cut and distance table
//! (a few hundred stars: built in about a millisecond), and the same vote, verification and
//! false-match test as lost-in-space. The test counts the region's own hypotheses and judges
//! them against half the error budget (`Settings::searches` = 2), the other half being left to
//! the lost-in-space search that follows when the region does not solve: a wrong hint cannot
//! turn a chance match into `solved` more often than the budget allows.

use super::{Settings, Solver};
use crate::camera::Camera;
use crate::catalog::Catalog;
use crate::error::Result;
use crate::sky::hint::Hint;

/// How much wider than the region the catalog's cone query reaches: positions are indexed at
/// each star's own epoch, and the fastest star (Barnard's, 10.4″/yr) moves 0.05° in 17 years.
const PROPER_MOTION_MARGIN_RAD: f64 = 0.05 * std::f64::consts::PI / 180.0;

/// The region a hint gives a camera: the cone its stars may come from, radians.
pub fn region_radius(hint: &Hint, camera: &Camera, settings: &Settings) -> f64 {
    // A scale search's shortest focal length is its widest field.
    let widest = settings.scale_range.map_or(1.0, |(lo, _)| lo.min(1.0));
    hint.radius_deg.to_radians() + camera.diagonal_rad() / 2.0 / widest
}

/// A solver for the frames of `camera` that point within `hint`: its catalog is the stars of
/// the hint's region. Fails when the region holds fewer stars than the vote needs.
pub fn regional_solver(
    catalog: &Catalog,
    camera: &Camera,
    settings: &Settings,
    hint: &Hint,
) -> Result<Solver> {
    let radius = region_radius(hint, camera, settings);
    let centre = crate::catalog::radec_to_vector(hint.ra_deg, hint.dec_deg);
    let stars = catalog.cone(&centre, radius + PROPER_MOTION_MARGIN_RAD);
    let region = catalog.subset(
        &stars,
        &format!(
            "{} within {:.3} deg of {:.4},{:.4}",
            catalog.source,
            radius.to_degrees(),
            hint.ra_deg,
            hint.dec_deg
        ),
    );
    let s = Settings {
        sky_sr: 2.0 * std::f64::consts::PI * (1.0 - radius.min(std::f64::consts::PI).cos()),
        searches: 2,
        table_cache: false,
        // A known scale's region is voted alone: its pattern index would be built for every
        // hint, and the region's vote is quick.
        scale_free: settings.scale_free && settings.scale_range.is_some(),
        ..*settings
    };
    Solver::new(&region, camera.clone(), s)
}
