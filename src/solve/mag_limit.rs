//! How deep a catalog selection a field gets: the magnitude at which the catalog holds a given
//! number of stars in view on average, over the whole sky or over the cone of a hinted region.

use crate::camera::Camera;
use crate::catalog::Catalog;

/// Average number of catalog stars in the field that [`auto_mag_limit`] aims at.
pub const AUTO_STARS_IN_VIEW: f64 = 40.0;

/// The faintest magnitude at which the catalog holds on average [`AUTO_STARS_IN_VIEW`] stars
/// in the camera's field (at least 5.0, at most the catalog's faintest); no fainter than the
/// catalog's complete part ([`Catalog::complete_mag`]) while that holds
/// [`FEW_STARS_IN_VIEW`] or more: beyond it the stars a frame shows are more and more often
/// not in the catalog, and a 6° star tracker's frames lost a solution to them.
pub fn auto_mag_limit(catalog: &Catalog, camera: &Camera) -> f64 {
    auto_mag_limit_in(catalog, camera, FULL_SKY_SR)
}

/// [`auto_mag_limit`] for a catalog that covers `sky_sr` steradians (a hinted region's cone).
pub fn auto_mag_limit_in(catalog: &Catalog, camera: &Camera, sky_sr: f64) -> f64 {
    let aim = mag_limit_in(catalog, camera, AUTO_STARS_IN_VIEW, sky_sr);
    let complete = catalog.complete_mag;
    let limit = if aim > complete && complete_in_view(catalog, camera, sky_sr) >= FEW_STARS_IN_VIEW
    {
        complete
    } else {
        aim
    };
    limit.max(5.0)
}

/// The average number of the catalog's stars to its complete magnitude in the camera's field.
fn complete_in_view(catalog: &Catalog, camera: &Camera, sky_sr: f64) -> f64 {
    let mags = catalog.sorted_mags();
    let n = mags.partition_point(|&m| m <= catalog.complete_mag);
    n as f64 * field_share(camera.fov_x_deg(), camera.fov_y_deg(), sky_sr)
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
/// too few to identify lost in space: to Hp 8 a 4° field held 15 on average, and the frames of
/// docs/radial.md's sets that no identifier solved with it showed 3 or 4 (the built-in catalog,
/// to Hp 9, holds 30 there and 17 at 3°).
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The built-in catalog's selection stops at its complete magnitude while that leaves
    /// enough stars in view, and goes deeper where it does not; a catalog with no complete
    /// magnitude gives the plain aim everywhere.
    #[test]
    fn the_automatic_limit_stops_at_the_complete_part_while_it_holds_enough() {
        let builtin = Catalog::builtin();
        let open = builtin.clone().complete_to(f64::INFINITY);
        let limit =
            |c: &Catalog, fov: f64| auto_mag_limit(c, &Camera::from_fov(1024, 1024, fov).unwrap());
        // 6°: Hp 8 holds 33 in view; the aim of 40 would be Hp 8.2.
        assert!(limit(&open, 6.0) > 8.1);
        assert_eq!(limit(&builtin, 6.0), 8.0);
        // 4°: Hp 8 holds 15, fewer than FEW_STARS_IN_VIEW: the whole catalog, to Hp 9.
        assert_eq!(limit(&builtin, 4.0), limit(&open, 4.0));
        assert_eq!(limit(&builtin, 4.0), 9.0);
        // 18°: the aim is brighter than Hp 8 either way.
        assert_eq!(limit(&builtin, 18.0), limit(&open, 18.0));
        assert!(limit(&builtin, 18.0) < 7.0);
    }
}
