//! The observing station: from `--station` or from FITS header keywords.

use super::keyword::{parse_number, value};
use sofars::coords::gc2gd;

/// Station heights accepted, metres: below the Dead Sea shore to airborne.
pub(crate) const HEIGHT_RANGE_M: (f64, f64) = (-1_000.0, 20_000.0);

/// An observing station: geodetic WGS-84 latitude and east-positive longitude (degrees) and
/// height above the ellipsoid (metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Station {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub height_m: f64,
}

/// A station with ranges checked and longitude brought into (-180, 180].
pub(crate) fn checked_station(
    lat_deg: f64,
    lon_deg: f64,
    height_m: f64,
) -> Result<Station, String> {
    if !(lat_deg.is_finite() && (-90.0..=90.0).contains(&lat_deg)) {
        return Err(format!("latitude {lat_deg} deg is outside -90..90"));
    }
    if !(lon_deg.is_finite() && (-180.0..=360.0).contains(&lon_deg)) {
        return Err(format!("longitude {lon_deg} deg is outside -180..360"));
    }
    if !(height_m.is_finite() && (HEIGHT_RANGE_M.0..=HEIGHT_RANGE_M.1).contains(&height_m)) {
        return Err(format!(
            "height {height_m:.1} m is outside {}..{} m",
            HEIGHT_RANGE_M.0, HEIGHT_RANGE_M.1
        ));
    }
    let lon_deg = if lon_deg > 180.0 {
        lon_deg - 360.0
    } else {
        lon_deg
    };
    Ok(Station {
        lat_deg,
        lon_deg,
        height_m,
    })
}

/// `--station LAT,LON,HEIGHT_M`: geodetic degrees (decimal, or sexagesimal such as 35:42:00),
/// east longitude positive, metres above the WGS-84 ellipsoid; checks ranges.
pub fn parse_station(s: &str) -> crate::Result<Station> {
    let usage = || format!("--station expects LAT,LON,HEIGHT_M (degrees east, metres), got '{s}'");
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [lat, lon, h] = parts[..] else {
        return Err(crate::Error::Config(usage()));
    };
    let (Some(lat), Some(lon), Some(h)) = (
        parse_angle(lat, 'N', 'S'),
        parse_angle(lon, 'E', 'W'),
        parse_number(h),
    ) else {
        return Err(crate::Error::Config(usage()));
    };
    checked_station(lat, lon, h).map_err(|e| crate::Error::Config(format!("--station '{s}': {e}")))
}

/// Degrees as a number or sexagesimal ("+43:12:34.5", "43 12 34.5", "43:12.5"), optionally
/// with a hemisphere letter (`pos`: N or E, `neg`: S or W) instead of a sign.
pub(crate) fn parse_angle(s: &str, pos: char, neg: char) -> Option<f64> {
    let s = s.trim();
    // Plain decimal only: a Fortran "D" exponent would read "0d30" as 0.
    if let Some(v) = s.parse::<f64>().ok().filter(|v| v.is_finite()) {
        return Some(v);
    }
    let upper = s.to_ascii_uppercase();
    let (body, letter_sign) = match upper.chars().last() {
        Some(c) if c == pos => (&upper[..upper.len() - 1], Some(1.0)),
        Some(c) if c == neg => (&upper[..upper.len() - 1], Some(-1.0)),
        _ => (&upper[..], None),
    };
    let body = body.trim();
    let (body, sign) = match (body.strip_prefix('-'), body.strip_prefix('+'), letter_sign) {
        (Some(rest), _, None) => (rest, -1.0),
        (_, Some(rest), None) => (rest, 1.0),
        (None, None, Some(sign)) => (body, sign),
        (None, None, None) => (body, 1.0),
        _ => return None, // a sign and a hemisphere letter together
    };
    let fields: Vec<&str> = body.split([':', ' ']).filter(|f| !f.is_empty()).collect();
    if !(2..=3).contains(&fields.len()) {
        return None;
    }
    let mut value = 0.0;
    for (i, f) in fields.iter().enumerate() {
        if !f.chars().all(|c| c.is_ascii_digit() || c == '.') {
            return None;
        }
        let v: f64 = f.parse().ok()?;
        let last = i + 1 == fields.len();
        if (i > 0 && v >= 60.0) || (!last && v.fract() != 0.0) {
            return None;
        }
        value += v / 60f64.powi(i as i32);
    }
    Some(sign * value)
}

/// The station from OBSGEO-B/L/H (degrees, metres), else OBSGEO-X/Y/Z (ITRS metres, WGS-84),
/// else SITELAT/SITELONG (degrees: numbers or sexagesimal strings) and SITEELEV (metres).
/// Longitudes are east-positive as FITS defines them (some observatories write SITELONG
/// west-positive: pass --station for those). A missing height is taken as 0 with a warning;
/// an unusable set is warned about and the next is tried.
pub fn station_from_header(get: &dyn Fn(&str) -> Option<String>) -> (Option<Station>, Vec<String>) {
    let mut warn = Vec::new();
    let height = |key: &str, warn: &mut Vec<String>| match value(get, key) {
        None => {
            warn.push(format!("{key} is missing: station height taken as 0 m"));
            Some(0.0)
        }
        Some(v) => {
            let h = parse_number(&v);
            if h.is_none() {
                warn.push(format!(
                    "{key} = '{v}' is not a number (m); station not used"
                ));
            }
            h
        }
    };
    let number = |key: &str, warn: &mut Vec<String>| {
        let v = value(get, key)?;
        let n = parse_number(&v);
        if n.is_none() {
            warn.push(format!("{key} = '{v}' is not a number; station not used"));
        }
        n
    };

    // OBSGEO-B/L/H
    if value(get, "OBSGEO-B").is_some() || value(get, "OBSGEO-L").is_some() {
        let b = number("OBSGEO-B", &mut warn);
        let l = number("OBSGEO-L", &mut warn);
        match (b, l) {
            (Some(b), Some(l)) => {
                if let Some(h) = height("OBSGEO-H", &mut warn) {
                    match checked_station(b, l, h) {
                        Ok(s) => return (Some(s), warn),
                        Err(e) => warn.push(format!(
                            "OBSGEO-B/L/H = {b}, {l}, {h}: {e}; station not used"
                        )),
                    }
                }
            }
            (b, l) => {
                if b.is_some() || l.is_some() {
                    warn.push(
                        "OBSGEO-B and OBSGEO-L must both be given; station not used".to_string(),
                    );
                }
            }
        }
    }

    // OBSGEO-X/Y/Z
    let keys = ["OBSGEO-X", "OBSGEO-Y", "OBSGEO-Z"];
    if keys.iter().any(|k| value(get, k).is_some()) {
        let xyz: Vec<Option<f64>> = keys.iter().map(|k| number(k, &mut warn)).collect();
        if let [Some(x), Some(y), Some(z)] = xyz[..] {
            match gc2gd(1, [x, y, z]) {
                Ok((elong, phi, h)) => {
                    match checked_station(phi.to_degrees(), elong.to_degrees(), h) {
                        Ok(s) => return (Some(s), warn),
                        Err(e) => warn.push(format!(
                            "OBSGEO-X/Y/Z = {x}, {y}, {z} m: {e} (kilometres instead of metres?); \
                         station not used"
                        )),
                    }
                }
                Err(_) => warn.push(format!(
                    "OBSGEO-X/Y/Z = {x}, {y}, {z} m: no geodetic position"
                )),
            }
        } else {
            warn.push(
                "OBSGEO-X, OBSGEO-Y and OBSGEO-Z must all be numbers; station not used".to_string(),
            );
        }
    }

    // SITELAT/SITELONG/SITEELEV
    let lat = value(get, "SITELAT");
    let lon = value(get, "SITELONG");
    if lat.is_some() || lon.is_some() {
        let angle = |key: &str, v: &Option<String>, pos, neg, warn: &mut Vec<String>| {
            let Some(v) = v else {
                warn.push(format!("{key} is missing; station not used"));
                return None;
            };
            let a = parse_angle(v, pos, neg);
            if a.is_none() {
                warn.push(format!(
                    "{key} = '{v}' is not an angle (degrees, or d:m:s / d m s); station not used"
                ));
            }
            a
        };
        let la = angle("SITELAT", &lat, 'N', 'S', &mut warn);
        let lo = angle("SITELONG", &lon, 'E', 'W', &mut warn);
        let h = match (la, lo) {
            (Some(_), Some(_)) => height("SITEELEV", &mut warn),
            _ => None,
        };
        if let (Some(la), Some(lo), Some(h)) = (la, lo, h) {
            match checked_station(la, lo, h) {
                Ok(s) => return (Some(s), warn),
                Err(e) => warn.push(format!(
                    "SITELAT/SITELONG/SITEELEV = '{}', '{}', {h}: {e}; station not used",
                    lat.unwrap_or_default(),
                    lon.unwrap_or_default()
                )),
            }
        }
    }
    if warn.is_empty() {
        warn.push(
            "no station in the header (OBSGEO-B/L/H, OBSGEO-X/Y/Z, SITELAT/SITELONG): \
             pass --station LAT,LON,HEIGHT_M"
                .to_string(),
        );
    }
    (None, warn)
}
