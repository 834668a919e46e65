//! One catalog star, its direction at an epoch, and the conversions and hash the catalog
//! files share.

use super::id::StarId;
use nalgebra::Vector3;

/// Epoch of the Hipparcos-2 positions (Julian year).
pub const HIPPARCOS_EPOCH: f64 = 1991.25;

const MAS_TO_RAD: f64 = std::f64::consts::PI / (180.0 * 3600.0 * 1000.0);

/// One catalog star as stored: ICRS position at its own epoch and proper motion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Star {
    /// Its identity in the catalog it came from (records print it as `catalog_id`).
    pub id: StarId,
    /// Its Hipparcos number, where it has one (every Hipparcos star; Tycho-2 and Gaia stars
    /// that the catalog cross-identifies).
    pub hip: Option<u32>,
    /// Right ascension at `epoch`, radians.
    pub ra_rad: f64,
    /// Declination at `epoch`, radians.
    pub dec_rad: f64,
    /// Proper motion in RA·cos(Dec), mas/yr.
    pub pmra_mas_yr: f64,
    /// Proper motion in Dec, mas/yr.
    pub pmdec_mas_yr: f64,
    /// The catalog's own magnitude: Hp (Hipparcos), G (Gaia), V from BT/VT (Tycho-2), or a
    /// user catalog's.
    pub mag: f64,
    /// Julian year of the position (1991.25 for Hipparcos-2, 2016.0 for Gaia DR3).
    pub epoch: f64,
}

impl Star {
    /// Unit vector (ICRS) at `epoch` (Julian year), propagated from the star's own epoch
    /// linearly along the tangent plane and renormalised. Neglects radial velocity and
    /// parallax: for a few decades the error stays far below an arcsecond (it grows as
    /// (μ·Δt)²/2).
    pub fn vector_at(&self, epoch: f64) -> Vector3<f64> {
        self.vector_and_motion_at(epoch).0
    }

    /// [`Star::vector_at`] and [`Star::motion`] from one evaluation of the trigonometry (a
    /// catalog selection makes both for every star it keeps).
    pub fn vector_and_motion_at(&self, epoch: f64) -> (Vector3<f64>, Vector3<f64>) {
        let (sa, ca) = self.ra_rad.sin_cos();
        let (sd, cd) = self.dec_rad.sin_cos();
        let motion = Self::motion_from((sa, ca), (sd, cd), self.pmra_mas_yr, self.pmdec_mas_yr);
        let v = (Vector3::new(cd * ca, cd * sa, sd) + motion * (epoch - self.epoch)).normalize();
        (v, motion)
    }

    /// Unit vector (ICRS) at the star's own epoch.
    pub fn position(&self) -> Vector3<f64> {
        let (sa, ca) = self.ra_rad.sin_cos();
        let (sd, cd) = self.dec_rad.sin_cos();
        Vector3::new(cd * ca, cd * sa, sd)
    }

    /// Proper motion as a tangent vector of the unit sphere, radians per year.
    pub fn motion(&self) -> Vector3<f64> {
        let ra = self.ra_rad.sin_cos();
        let dec = self.dec_rad.sin_cos();
        Self::motion_from(ra, dec, self.pmra_mas_yr, self.pmdec_mas_yr)
    }

    fn motion_from(
        (sa, ca): (f64, f64),
        (sd, cd): (f64, f64),
        pmra_mas_yr: f64,
        pmdec_mas_yr: f64,
    ) -> Vector3<f64> {
        let e_ra = Vector3::new(-sa, ca, 0.0);
        let e_dec = Vector3::new(-sd * ca, -sd * sa, cd);
        (e_ra * pmra_mas_yr + e_dec * pmdec_mas_yr) * MAS_TO_RAD
    }
}

/// Unit vector of (RA, Dec) in degrees.
pub fn radec_to_vector(ra_deg: f64, dec_deg: f64) -> Vector3<f64> {
    let (sa, ca) = ra_deg.to_radians().sin_cos();
    let (sd, cd) = dec_deg.to_radians().sin_cos();
    Vector3::new(cd * ca, cd * sa, sd)
}

/// (RA in [0, 360), Dec) in degrees of a unit vector.
pub fn vector_to_radec(v: &Vector3<f64>) -> (f64, f64) {
    let ra = v.y.atan2(v.x).to_degrees().rem_euclid(360.0);
    let dec = v.z.clamp(-1.0, 1.0).asin().to_degrees();
    (ra, dec)
}

/// 64-bit FNV-1a: a stable hash for cache keys (std's hasher may change between releases).
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}
