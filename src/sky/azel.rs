//! Topocentric Az/El of an ICRS direction: the IAU 2006/2000A chain through sofars.

use super::{Station, Utc, checked_station};
use sofars::astro::atco13;

/// Topocentric azimuth (from north through east, [0,360)) and elevation (degrees) of an ICRS
/// direction, airless (no refraction): the IAU 2006/2000A chain with annual aberration and
/// Earth rotation from UT1, as astropy's ICRS->AltAz with pressure = 0. Via sofars atco13 with
/// phpa = 0. `dut1_s` is UT1-UTC (|dut1| < 1 s) and `xp_rad`, `yp_rad` polar motion in radians,
/// e.g. from [`earth_orientation`](super::earth_orientation).
pub fn az_el(
    ra_deg: f64,
    dec_deg: f64,
    t: &Utc,
    station: &Station,
    dut1_s: f64,
    xp_rad: f64,
    yp_rad: f64,
) -> crate::Result<(f64, f64)> {
    if !(ra_deg.is_finite() && dec_deg.is_finite() && (-90.0..=90.0).contains(&dec_deg)) {
        return Err(crate::Error::Input(format!(
            "no such direction: RA {ra_deg} deg, Dec {dec_deg} deg"
        )));
    }
    t.plausible().map_err(crate::Error::Input)?;
    let Station {
        lat_deg,
        lon_deg,
        height_m,
    } = *station;
    checked_station(lat_deg, lon_deg, height_m)
        .map_err(|e| crate::Error::Input(format!("station: {e}")))?;
    if dut1_s.is_nan() || dut1_s.abs() >= 1.0 {
        return Err(crate::Error::Input(format!(
            "UT1-UTC {dut1_s} s is not within +-1 s"
        )));
    }
    // Polar motion stays below 1 arcsec; larger values are arcsec passed as radians.
    let pm_limit = 1e-4;
    if [xp_rad, yp_rad]
        .iter()
        .any(|p| p.is_nan() || p.abs() >= pm_limit)
    {
        return Err(crate::Error::Input(format!(
            "polar motion ({xp_rad}, {yp_rad}) rad is not below {pm_limit} rad"
        )));
    }
    let (aob, zob, ..) = atco13(
        ra_deg.to_radians(),
        dec_deg.to_radians(),
        0.0,
        0.0,
        0.0,
        0.0,
        t.jd1,
        t.jd2,
        dut1_s,
        lon_deg.to_radians(),
        lat_deg.to_radians(),
        height_m,
        xp_rad,
        yp_rad,
        0.0,
        0.0,
        0.0,
        0.55,
    )
    .map_err(|code| {
        crate::Error::Input(format!(
            "SOFA atco13 failed (status {code}) for {}",
            t.iso()
        ))
    })?;
    let az = aob.to_degrees().rem_euclid(360.0);
    let az = if az >= 360.0 { 0.0 } else { az };
    Ok((az, 90.0 - zob.to_degrees()))
}
