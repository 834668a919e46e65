//! How deep a catalog selection a field gets: the magnitude at which the catalog holds a given
//! number of stars in view on average, over the whole sky or over the cone of a hinted region.

use crate::camera::Camera;
use crate::catalog::Catalog;

/// Average number of catalog stars in the field that [`auto_mag_limit`] aims at.
pub const AUTO_STARS_IN_VIEW: f64 = 40.0;

/// The faintest magnitude at which the catalog holds on average [`AUTO_STARS_IN_VIEW`] stars
/// in the camera's field (at least 5.0, at most the catalog's faintest).
pub fn auto_mag_limit(catalog: &Catalog, camera: &Camera) -> f64 {
    auto_mag_limit_in(catalog, camera, FULL_SKY_SR)
}

/// [`auto_mag_limit`] for a catalog that covers `sky_sr` steradians (a hinted region's cone).
pub fn auto_mag_limit_in(catalog: &Catalog, camera: &Camera, sky_sr: f64) -> f64 {
    mag_limit_in(catalog, camera, AUTO_STARS_IN_VIEW, sky_sr).max(5.0)
}

/// The faintest magnitude at which the catalog holds on average `stars` stars in the camera's
/// field (to a tenth; at most the catalog's faintest).
pub fn mag_limit_for(catalog: &Catalog, camera: &Camera, stars: f64) -> f64 {
    mag_limit_in(catalog, camera, stars, FULL_SKY_SR)
}

/// The solid angle of the whole sky.
pub const FULL_SKY_SR: f64 = 4.0 * std::f64::consts::PI;

/// [`mag_limit_for`] for a catalog that covers `sky_sr` steradians.
pub fn mag_limit_in(catalog: &Catalog, camera: &Camera, stars: f64, sky_sr: f64) -> f64 {
    let fraction = field_share(camera.fov_x_deg(), camera.fov_y_deg(), sky_sr);
    let n = ((stars / fraction).round() as usize).max(1);
    (catalog.mag_of_rank(n) * 10.0).round() / 10.0
}

/// Fewer catalog stars than this in a field on average, and the sparse parts of the sky show
/// too few to identify lost in space: at 4° the built-in catalog (Hp ≤ 8) holds 15 on average,
/// and the frames of docs/radial.md's sets that no identifier solves show 3 or 4.
pub const FEW_STARS_IN_VIEW: f64 = 20.0;

/// The average number of the catalog's stars in a field of `fov_x_deg` × `fov_y_deg`.
pub fn stars_in_view(catalog: &Catalog, fov_x_deg: f64, fov_y_deg: f64) -> f64 {
    catalog.stars.len() as f64 * field_share(fov_x_deg, fov_y_deg, FULL_SKY_SR)
}

/// The share of `sky_sr` steradians a field of `fov_x_deg` × `fov_y_deg` covers (at most 1).
fn field_share(fov_x_deg: f64, fov_y_deg: f64, sky_sr: f64) -> f64 {
    let fov_sr = (fov_x_deg * fov_y_deg).to_radians().to_radians();
    (fov_sr / sky_sr).min(1.0)
}

/// Average number of catalog stars in the field of the shallow pass's selection: a sensor that
/// shows 4 to 8 stars (a 10° field to Hp 6) leaves them among 40 catalog stars in view of the
/// automatic selection, whose pairs crowd the vote and whose count weakens the false-match
/// test; voting against the brightest 12 in view gives those stars a catalog they can match.
pub const SHALLOW_STARS_IN_VIEW: f64 = 12.0;
