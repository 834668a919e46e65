//! Orbital elements (`--tle`): TLE (2- or 3-line) and OMM (XML or JSON) files read into SGP4
//! propagators (the `sgp4` crate), and the chain from SGP4's TEME frame to a station's
//! topocentric direction.
//!
//! TEME → ITRS is Vallado et al. (2006, AIAA 2006-6753), as astropy's `TEME` frame does it:
//! a rotation by GMST (IAU 1982, from UT1) about the pole, then polar motion (SOFA `pom00`,
//! without the TIO locator). The station's ITRS position is its WGS-84 geodetic place (SOFA
//! `gd2gc`); the direction from it is split into east, north and up of the geodetic vertical,
//! so the Az/El are geometric and airless, as the streaks' Az/El are.
//!
//! A whole night against a full catalog: `TleCatalog::coarse` propagates every object once
//! per [`COARSE_STEP_S`] of frame time (cached, shared by the frames of that time) and the
//! frames interpolate those states (cubic Hermite in position and velocity: a few metres off
//! for low orbits), which is only a prefilter; the few objects it keeps near a streak are
//! propagated exactly.

use super::{Station, Utc};
use crate::error::Result;
use std::sync::{Arc, Mutex};

/// Spacing of the coarse propagation (seconds of UTC).
pub const COARSE_STEP_S: f64 = 120.0;

/// Coarse states kept (each is every object's at one step).
const COARSE_KEPT: usize = 16;

/// Light-seconds per km: the object is seen where it was range/c earlier.
const C_KM_S: f64 = 299_792.458;

/// Elements further than this from a frame's time get a warning (once a run): SGP4 from
/// month-old elements of a low orbit is off by tens of kilometres along the track.
pub const MAX_ELEMENT_AGE_DAYS: f64 = 30.0;

/// The satellites with each NORAD id once: the newest elements of an id (the first of those
/// at the same epoch), in the file's order; a warning names how many were left out and the
/// first id. Files concatenated from several downloads repeat objects, and the older elements
/// predict worse.
fn newest_of_each(satellites: Vec<Satellite>, what: &str) -> Vec<Satellite> {
    let mut newest: std::collections::HashMap<u64, usize> = std::collections::HashMap::new();
    for (i, s) in satellites.iter().enumerate() {
        let k = newest.entry(s.norad).or_insert(i);
        if s.epoch_jd > satellites[*k].epoch_jd {
            *k = i;
        }
    }
    let left_out = satellites.len() - newest.len();
    if left_out == 0 {
        return satellites;
    }
    let first = satellites
        .iter()
        .enumerate()
        .find(|(i, s)| newest[&s.norad] != *i)
        .map_or(0, |(_, s)| s.norad);
    tracing::warn!(
        "{what}: {left_out} element sets repeat an object's NORAD id (the first: {first}); \
         the newest of each is used"
    );
    satellites
        .into_iter()
        .enumerate()
        .filter(|(i, s)| newest[&s.norad] == *i)
        .map(|(_, s)| s)
        .collect()
}

/// One object of the file.
pub struct Satellite {
    pub norad: u64,
    /// OBJECT_NAME, the 3-line TLE's name line; empty when the file gives none.
    pub name: String,
    /// The international designator as given (`98067A` in TLEs, `1998-067A` in OMM).
    pub intl_des: Option<String>,
    constants: sgp4::Constants,
    /// The elements' epoch as a UTC Julian date.
    epoch_jd: f64,
}

impl Satellite {
    /// Days from the elements' epoch to `t` (either way).
    pub fn age_days(&self, t: &Utc) -> f64 {
        (t.jd1 + t.jd2 - self.epoch_jd).abs()
    }

    /// The propagator of a set of elements, with the WGS-72 constants that TLEs and the OMMs
    /// made from them are fitted with (as Vallado's and python-sgp4's default; the crate's
    /// `from_elements` takes WGS-84, tens of metres apart).
    pub fn from_elements(e: &sgp4::Elements) -> std::result::Result<Satellite, String> {
        let deg = std::f64::consts::PI / 180.0;
        let orbit = sgp4::Orbit::from_kozai_elements(
            &sgp4::WGS72,
            e.inclination * deg,
            e.right_ascension * deg,
            e.eccentricity,
            e.argument_of_perigee * deg,
            e.mean_anomaly * deg,
            e.mean_motion * (std::f64::consts::PI / 720.0),
        )
        .map_err(|err| err.to_string())?;
        let constants = sgp4::Constants::new(
            sgp4::WGS72,
            sgp4::iau_epoch_to_sidereal_time,
            e.epoch(),
            e.drag_term,
            orbit,
        )
        .map_err(|err| err.to_string())?;
        Ok(Satellite {
            norad: e.norad_id,
            name: e.object_name.clone().unwrap_or_default().trim().to_string(),
            intl_des: e
                .international_designator
                .clone()
                .map(|d| d.trim().to_string())
                .filter(|d| !d.is_empty()),
            constants,
            // Julian years of 365.25 days since J2000 (UTC), as the crate counts them.
            epoch_jd: 2_451_545.0 + e.epoch() * 365.25,
        })
    }

    /// Position and velocity in TEME (km, km/s) at `t`; `None` where SGP4 fails (a decayed
    /// orbit, or far from the elements' epoch).
    pub fn teme(&self, t: &Utc) -> Option<([f64; 3], [f64; 3])> {
        self.teme_at_jd(t.jd1 + t.jd2)
    }

    /// The elements' epoch, UTC Julian date (for the fuzz suite).
    #[cfg(test)]
    pub(crate) fn epoch_jd(&self) -> f64 {
        self.epoch_jd
    }

    /// [`Satellite::teme`] at a UTC Julian date.
    pub(crate) fn teme_at_jd(&self, jd: f64) -> Option<([f64; 3], [f64; 3])> {
        let minutes = (jd - self.epoch_jd) * 1440.0;
        let p = self
            .constants
            .propagate(sgp4::MinutesSinceEpoch(minutes))
            .ok()?;
        let ok = p.position.iter().chain(&p.velocity).all(|v| v.is_finite());
        ok.then_some((p.position, p.velocity))
    }
}

/// Every object's TEME state at one coarse step; `None` where SGP4 failed.
type Coarse = Arc<Vec<Option<([f64; 3], [f64; 3])>>>;

/// The objects of a `--tle` file, and the coarse states the frames share.
pub struct TleCatalog {
    pub satellites: Vec<Satellite>,
    coarse: Mutex<Vec<(i64, Coarse)>>,
    /// Whether [`TleCatalog::age_warning`] has been given.
    age_warned: std::sync::atomic::AtomicBool,
}

impl std::fmt::Debug for TleCatalog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TleCatalog({} objects)", self.satellites.len())
    }
}

impl TleCatalog {
    /// Read a TLE (2- or 3-line) or OMM (XML, or JSON as CelesTrak and Space-Track write it)
    /// file. Objects whose elements SGP4 refuses are skipped with a warning; a file with no
    /// usable object is an error.
    pub fn load(path: &std::path::Path) -> Result<TleCatalog> {
        let text = crate::files::read_regular_text(path, "--tle")?;
        TleCatalog::from_text(&text, &format!("--tle {}", path.display()))
    }

    /// [`TleCatalog::load`] of a file's text; `what` names it in messages.
    pub fn from_text(text: &str, what: &str) -> Result<TleCatalog> {
        let (elements, mut skipped) =
            parse(text).map_err(|e| crate::Error::Input(format!("{what}: {e}")))?;
        let mut satellites = Vec::with_capacity(elements.len());
        for e in elements {
            match Satellite::from_elements(&e) {
                Ok(sat) => satellites.push(sat),
                Err(err) => skipped.push(format!("{}: {err}", e.norad_id)),
            }
        }
        if !skipped.is_empty() {
            tracing::warn!(
                "{what}: {} objects skipped ({}{})",
                skipped.len(),
                skipped[..skipped.len().min(3)].join("; "),
                if skipped.len() > 3 { "; …" } else { "" }
            );
        }
        if satellites.is_empty() {
            return Err(crate::Error::Input(format!(
                "{what}: no object with usable elements"
            )));
        }
        let satellites = newest_of_each(satellites, what);
        Ok(TleCatalog::new(satellites))
    }

    pub fn new(satellites: Vec<Satellite>) -> TleCatalog {
        TleCatalog {
            satellites,
            coarse: Mutex::new(Vec::new()),
            age_warned: std::sync::atomic::AtomicBool::new(false),
        }
    }

    /// The first time frames at `t` use elements more than [`MAX_ELEMENT_AGE_DAYS`] from their
    /// epoch: a warning naming how many and the first (later frames: None, so that a night of
    /// frames logs it once). SGP4's errors grow by kilometres a day, so such predictions may
    /// be far off and a streak they do not name may be the object all the same.
    pub fn age_warning(&self, t: &Utc) -> Option<String> {
        use std::sync::atomic::Ordering;
        if self.age_warned.load(Ordering::Relaxed) {
            return None;
        }
        let jd = t.jd1 + t.jd2;
        let old: Vec<&Satellite> = self
            .satellites
            .iter()
            .filter(|s| {
                !(-MAX_ELEMENT_AGE_DAYS..=MAX_ELEMENT_AGE_DAYS).contains(&(jd - s.epoch_jd))
            })
            .collect();
        let first = old.first()?;
        if self.age_warned.swap(true, Ordering::Relaxed) {
            return None;
        }
        Some(format!(
            "--tle: {} of {} objects have elements more than {MAX_ELEMENT_AGE_DAYS} days from \
             the frame time {} (the first, NORAD {}: {:.0} days): their predicted positions \
             may be far off; use elements of the night",
            old.len(),
            self.satellites.len(),
            t.iso(),
            first.norad,
            (jd - first.epoch_jd).abs()
        ))
    }

    /// Every object's TEME state at coarse step `k` (UTC JD `k · COARSE_STEP_S / 86400`),
    /// computed once and kept while frames near it come.
    fn coarse(&self, k: i64) -> Coarse {
        let mut kept = self.coarse.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((_, c)) = kept.iter().find(|(j, _)| *j == k) {
            return c.clone();
        }
        let jd = k as f64 * COARSE_STEP_S / 86_400.0;
        let c: Coarse = Arc::new(self.satellites.iter().map(|s| s.teme_at_jd(jd)).collect());
        if kept.len() >= COARSE_KEPT {
            kept.remove(0);
        }
        kept.push((k, c.clone()));
        c
    }

    /// Every object's TEME position (km) at `t` interpolated between the coarse steps around
    /// it (cubic Hermite); `None` where either step failed.
    pub fn coarse_positions(&self, t: &Utc) -> Vec<Option<[f64; 3]>> {
        let step_days = COARSE_STEP_S / 86_400.0;
        // Whole days and the fraction apart, so that the step index keeps its precision.
        let x = (t.jd1 / step_days).floor();
        let rest = (t.jd1 - x * step_days + t.jd2) / step_days;
        let k = x as i64 + rest.floor() as i64;
        let s = rest - rest.floor();
        let (a, b) = (self.coarse(k), self.coarse(k + 1));
        let h = COARSE_STEP_S;
        let (h00, h10) = (
            2.0 * s.powi(3) - 3.0 * s * s + 1.0,
            s.powi(3) - 2.0 * s * s + s,
        );
        let (h01, h11) = (-2.0 * s.powi(3) + 3.0 * s * s, s.powi(3) - s * s);
        a.iter()
            .zip(b.iter())
            .map(|(p, q)| {
                let ((p0, v0), (p1, v1)) = ((*p)?, (*q)?);
                Some(
                    [0, 1, 2]
                        .map(|i| h00 * p0[i] + h10 * h * v0[i] + h01 * p1[i] + h11 * h * v1[i]),
                )
            })
            .collect()
    }
}

/// What a file holds: its elements, and the objects that could not be read (why).
fn parse(text: &str) -> std::result::Result<(Vec<sgp4::Elements>, Vec<String>), String> {
    let t = text.trim_start_matches('\u{feff}').trim_start();
    if t.starts_with('<') {
        omm_xml(t)
    } else if t.starts_with('[') || t.starts_with('{') {
        omm_json(t)
    } else {
        Ok(tle_lines(t))
    }
}

/// 2- or 3-line TLEs: a line starting `1 ` followed by one starting `2 ` is a pair; a line
/// before the pair that is neither is its name (a leading `0 ` taken off).
fn tle_lines(text: &str) -> (Vec<sgp4::Elements>, Vec<String>) {
    let lines: Vec<&str> = text
        .lines()
        .map(str::trim_end)
        .filter(|l| !l.is_empty())
        .collect();
    let (mut out, mut bad) = (Vec::new(), Vec::new());
    let mut i = 0;
    while i < lines.len() {
        let is1 = |l: &str| l.starts_with("1 ") && l.len() >= 69;
        let is2 = |l: &str| l.starts_with("2 ") && l.len() >= 69;
        if is1(lines[i]) && i + 1 < lines.len() && is2(lines[i + 1]) {
            let name = (i > 0 && !is1(lines[i - 1]) && !is2(lines[i - 1])).then(|| {
                let n = lines[i - 1].trim();
                n.strip_prefix("0 ").unwrap_or(n).to_string()
            });
            // The crate reads the checksum column as a digit unchecked (an overflow on
            // anything else) and indexes fixed columns: check them first, and keep a panic
            // of its parser on a line gpustar did not foresee to that object.
            let digit = |l: &str| l.as_bytes().get(68).is_some_and(u8::is_ascii_digit);
            let (l1, l2) = (lines[i], lines[i + 1]);
            if !(digit(l1) && digit(l2) && l1.is_ascii() && l2.is_ascii()) {
                bad.push(format!("line {}: not TLE columns", i + 1));
            } else {
                let parsed = std::panic::catch_unwind(|| {
                    sgp4::Elements::from_tle(name, l1.as_bytes(), l2.as_bytes())
                });
                match parsed {
                    Ok(Ok(e)) => out.push(e),
                    Ok(Err(e)) => bad.push(format!("line {}: {e}", i + 1)),
                    Err(_) => bad.push(format!("line {}: unreadable", i + 1)),
                }
            }
            i += 2;
        } else {
            i += 1;
        }
    }
    (out, bad)
}

/// OMM in JSON: one object or an array of them (the `sgp4` crate's serde names, CelesTrak's).
fn omm_json(text: &str) -> std::result::Result<(Vec<sgp4::Elements>, Vec<String>), String> {
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| format!("OMM JSON: {e}"))?;
    let items = match v {
        serde_json::Value::Array(a) => a,
        o => vec![o],
    };
    let (mut out, mut bad) = (Vec::new(), Vec::new());
    for (k, item) in items.into_iter().enumerate() {
        match serde_json::from_value::<sgp4::Elements>(item) {
            Ok(e) => out.push(e),
            Err(e) => bad.push(format!("object {}: {e}", k + 1)),
        }
    }
    Ok((out, bad))
}

/// The OMM fields SGP4 uses (CCSDS 502.0-B-2/3, `<omm>` … `<data>`).
const OMM_FIELDS: [&str; 15] = [
    "OBJECT_NAME",
    "OBJECT_ID",
    "NORAD_CAT_ID",
    "CLASSIFICATION_TYPE",
    "EPOCH",
    "MEAN_MOTION_DOT",
    "MEAN_MOTION_DDOT",
    "BSTAR",
    "ELEMENT_SET_NO",
    "INCLINATION",
    "RA_OF_ASC_NODE",
    "ECCENTRICITY",
    "ARG_OF_PERICENTER",
    "MEAN_ANOMALY",
    "MEAN_MOTION",
];

/// OMM in XML (an `<ndm>` of `<omm>`s, or one `<omm>`): each `<omm>`'s fields by their tags,
/// read as the JSON form is. Only what SGP4 needs is read; the rest of the XML is not checked.
fn omm_xml(text: &str) -> std::result::Result<(Vec<sgp4::Elements>, Vec<String>), String> {
    let (mut out, mut bad) = (Vec::new(), Vec::new());
    let mut rest = text;
    let mut k = 0;
    while let Some(start) = find_tag(rest, "omm") {
        let body = &rest[start..];
        let end = body
            .find("</omm>")
            .ok_or("OMM XML: an <omm> without </omm>")?;
        let omm = &body[..end];
        rest = &body[end + 6..];
        k += 1;
        let mut map = serde_json::Map::new();
        for f in OMM_FIELDS {
            if let Some(v) = tag_text(omm, f) {
                map.insert(f.to_string(), serde_json::Value::String(v));
            }
        }
        // JSON's defaults where an XML file leaves them out.
        for (f, v) in [
            ("CLASSIFICATION_TYPE", "U"),
            ("ELEMENT_SET_NO", "999"),
            ("MEAN_MOTION_DDOT", "0"),
        ] {
            map.entry(f).or_insert(serde_json::Value::String(v.into()));
        }
        // The crate reads the others as numbers or strings of numbers; these only as numbers.
        for f in ["ELEMENT_SET_NO", "REV_AT_EPOCH", "EPHEMERIS_TYPE"] {
            let n = tag_text(omm, f)
                .or_else(|| map.get(f).and_then(|v| v.as_str().map(str::to_string)))
                .and_then(|s| s.trim().parse::<u64>().ok())
                .unwrap_or(0);
            map.insert(f.to_string(), serde_json::Value::from(n));
        }
        match serde_json::from_value::<sgp4::Elements>(serde_json::Value::Object(map)) {
            Ok(e) => out.push(e),
            Err(e) => bad.push(format!("<omm> {k}: {e}")),
        }
    }
    if k == 0 {
        return Err("XML without an <omm> element".into());
    }
    Ok((out, bad))
}

/// Where the content of the first `<tag>` or `<tag attr…>` starts.
fn find_tag(s: &str, tag: &str) -> Option<usize> {
    let mut from = 0;
    while let Some(i) = s[from..].find(&format!("<{tag}")) {
        let at = from + i + tag.len() + 1;
        let next = s[at..].chars().next()?;
        if next == '>' || next.is_whitespace() {
            return Some(at + s[at..].find('>')? + 1);
        }
        from = at;
    }
    None
}

/// The trimmed text of the first `<tag>…</tag>` (entities `&amp;` `&lt;` `&gt;` decoded).
fn tag_text(s: &str, tag: &str) -> Option<String> {
    let start = find_tag(s, tag)?;
    let end = s[start..].find(&format!("</{tag}>"))?;
    let v = s[start..start + end]
        .trim()
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&apos;", "'")
        .replace("&amp;", "&");
    Some(v)
}

/// The rotation from TEME to ITRS at `t`, and the station's place and local axes in TEME:
/// what turns TEME positions into topocentric directions at one instant.
#[derive(Clone, Copy, Debug)]
pub struct Topocentre {
    /// The station in TEME, km.
    pub station_km: [f64; 3],
    /// East, north and up at the station, unit vectors in TEME.
    pub enu: [[f64; 3]; 3],
}

impl Topocentre {
    /// At UTC `t` with UT1 − UTC `dut1_s` and polar motion `xp`, `yp` (radians, as
    /// [`super::earth_orientation`] gives them).
    pub fn new(t: &Utc, station: &Station, dut1_s: f64, xp: f64, yp: f64) -> Option<Topocentre> {
        let (u1, u2) = sofars::ts::utcut1(t.jd1, t.jd2, dut1_s).ok()?;
        let gst = sofars::erst::gmst82(u1, u2);
        let pom = sofars::pnp::pom00(xp, yp, 0.0);
        let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        // ITRS = m · TEME, so TEME = mᵀ · ITRS.
        let m = sofars::pnp::c2tcio(&identity, gst, &pom);
        let to_teme = |v: [f64; 3]| [0, 1, 2].map(|i| (0..3).map(|j| m[j][i] * v[j]).sum());
        let (lat, lon) = (station.lat_deg.to_radians(), station.lon_deg.to_radians());
        let xyz = sofars::coords::gd2gc(1, lon, lat, station.height_m).ok()?;
        let (sl, cl, sp, cp) = (lon.sin(), lon.cos(), lat.sin(), lat.cos());
        Some(Topocentre {
            station_km: to_teme(xyz.map(|v| v / 1000.0)),
            enu: [
                to_teme([-sl, cl, 0.0]),
                to_teme([-sp * cl, -sp * sl, cp]),
                to_teme([cp * cl, cp * sl, sp]),
            ],
        })
    }

    /// The unit vector (east, north, up) from the station to a TEME position, and the range
    /// (km).
    pub fn direction(&self, r_km: &[f64; 3]) -> ([f64; 3], f64) {
        let d = [0, 1, 2].map(|i| r_km[i] - self.station_km[i]);
        let range = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let e = self
            .enu
            .map(|a| (a[0] * d[0] + a[1] * d[1] + a[2] * d[2]) / range);
        (e, range)
    }
}

/// Azimuth (from north through east, [0, 360)) and elevation, degrees, of an (east, north, up)
/// unit vector.
pub fn az_el_of(enu: &[f64; 3]) -> (f64, f64) {
    let az = enu[0].atan2(enu[1]).to_degrees().rem_euclid(360.0);
    (
        if az >= 360.0 { 0.0 } else { az },
        enu[2].clamp(-1.0, 1.0).asin().to_degrees(),
    )
}

/// The (east, north, up) unit vector of an azimuth and elevation in degrees.
pub fn enu_of(az_deg: f64, el_deg: f64) -> [f64; 3] {
    let (a, e) = (az_deg.to_radians(), el_deg.to_radians());
    [e.cos() * a.sin(), e.cos() * a.cos(), e.sin()]
}

/// Where `sat` is seen from the station at `t`: the topocentric (east, north, up) direction,
/// light time taken off (the light seen left range/c earlier: 1–40 ms, up to a few arcsec
/// for a low orbit).
pub fn seen(sat: &Satellite, t: &Utc, topo: &Topocentre) -> Option<[f64; 3]> {
    let (r, v) = sat.teme(t)?;
    let (_, range) = topo.direction(&r);
    let lt = range / C_KM_S;
    // Over a light time the orbit is a straight line to well under a metre.
    let r = [0, 1, 2].map(|i| r[i] - v[i] * lt);
    Some(topo.direction(&r).0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// python-sgp4 (TEME) and astropy TEME -> ITRS -> AltAz (pressure 0), printed by
    /// `scripts/tle_astropy.py`: (label, line 1, line 2, lat, lon, height_m, utc, TEME km,
    /// az_deg, el_deg, range_km, astropy's dut1_s, xp_rad, yp_rad).
    #[allow(clippy::type_complexity)]
    #[rustfmt::skip]
    const ASTROPY: [(&str, &str, &str, f64, f64, f64, &str, [f64; 3], f64, f64, f64, f64, f64, f64); 6] = [
        // python-sgp4 2.27, astropy 8.0.2, numpy 2.4.6
        ("LEO 51.6 deg, Graz", "1 25544U          24075.00000000  .00000000  00000-0  10000-3 0    05", "2 25544  51.6400 247.4600 0006703 130.5000 325.0000 15.50000000    07", 47.0678, 15.4933, 493.0, "2024-03-15T03:42:00.000", [-1744.984727876678, 4843.603187587832, -4442.826172441071], 264.30915733217813, -72.98473287633921, 12627.313257209536, -0.009084749166666666, -4.4905160192819145e-08, 1.467068500466787e-06),
        ("LEO polar, Siding Spring", "1 43013U          25152.50000000  .00000000  00000-0  10000-3 0    08", "2 43013  98.7000  10.0000 0012000  90.0000 200.0000 14.20000000    09", -31.2733, 149.0644, 1165.0, "2025-06-02T08:15:00.000", [1122.5753091250042, 1307.6406274692824, -7010.484349603042], 193.80376427859093, -26.978819911034233, 7374.390727583243, 0.029004084375, 5.554389141051676e-07, 2.124170086122813e-06),
        ("MEO GNSS, Tenerife", "1 40105U          24325.25000000  .00000000  00000-0  10000-3 0    00", "2 40105  55.0000 120.0000 0050000  30.0000  10.0000  2.00560000    07", 28.3, -16.51, 2390.0, "2024-11-21T12:00:00.000", [18788.810135849293, -11898.358238933119, -14764.794099922243], 116.03514526929082, -36.51477951151866, 29984.48179357422, 0.05234225, 9.837499847497928e-07, 1.6417148720675994e-06),
        ("GEO, Mauna Kea", "1 41866U          26010.00000000  .00000000  00000-0  10000-3 0    01", "2 41866   0.0500  80.0000 0002000 250.0000 100.0000  1.00273000    03", 19.8207, -155.4681, 4205.0, "2026-01-12T02:30:00.000", [-14152.744721951049, 39724.69333204728, 32.261734585105415], 80.55644186564864, -31.706515565684025, 45174.882335000424, 0.07138025208333333, 4.859489531461341e-07, 1.6487822435039739e-06),
        ("Molniya, Svalbard", "1 40296U          25033.00000000  .00000000  00000-0  10000-3 0    01", "2 40296  63.4000 300.0000 7200000 270.0000  45.0000  2.00600000    04", 78.2297, 15.4077, 520.0, "2025-02-02T07:06:00.000", [7434.523169782458, 20127.651792134424, 32957.33699717239], 3.8003760636412465, 37.85516809635465, 35109.11622369603, 0.04667137958333333, 4.906695637585277e-07, 1.4977703772526908e-06),
        ("LEO, leap day near zenith check", "1 28654U          24059.91666667  .00000000  00000-0  10000-3 0    09", "2 28654  85.0000  33.0000 0009000  15.0000  80.0000 14.90000000    03", -24.6272, -70.4042, 2635.0, "2024-02-29T04:00:00.000", [5865.60744400072, 3722.6640699343366, -609.3331975311855], 253.7606454604784, -53.63698327237065, 11000.282210327727, -0.0031636, 3.6445868477409374e-08, 1.3003712955860069e-06),
    ];

    fn separation_arcsec(a: &[f64; 3], b: &[f64; 3]) -> f64 {
        let c = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        let s = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        s.atan2(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
            .to_degrees()
            * 3600.0
    }

    #[test]
    fn teme_to_topocentric_matches_astropy() {
        for (label, l1, l2, lat, lon, h, utc, teme, az, el, range, dut1, xp, yp) in ASTROPY {
            let (e, _) = tle_lines(&format!("{l1}\n{l2}\n"));
            let e = &e[0];
            let sat = Satellite::from_elements(e).unwrap();
            let t = Utc::parse(utc).unwrap();
            let (r, _) = sat.teme(&t).unwrap();
            let dr =
                ((r[0] - teme[0]).powi(2) + (r[1] - teme[1]).powi(2) + (r[2] - teme[2]).powi(2))
                    .sqrt();
            // Two SGP4 implementations of one model: metres apart at most.
            assert!(
                dr < 0.01,
                "{label}: TEME {r:?} vs python-sgp4 {teme:?}: {dr} km"
            );
            let st = Station {
                lat_deg: lat,
                lon_deg: lon,
                height_m: h,
            };
            let topo = Topocentre::new(&t, &st, dut1, xp, yp).unwrap();
            let (d, got_range) = topo.direction(&teme);
            let sep = separation_arcsec(&d, &enu_of(az, el));
            println!(
                "{label}: TEME {:.1e} m from python-sgp4; direction {sep:.1e} arcsec, range {:.1e} m from astropy",
                dr * 1e3,
                (got_range - range) * 1e3
            );
            assert!(
                sep < 0.05,
                "{label}: {:?} vs astropy ({az}, {el}): {sep} arcsec",
                az_el_of(&d)
            );
            assert!(
                (got_range - range).abs() < 0.005,
                "{label}: range {got_range} vs {range}"
            );
        }
    }

    /// One object written as a 3-line TLE, as OMM JSON and as OMM XML reads back the same.
    #[test]
    fn tle_and_omm_read_alike() {
        let tle = "ISS (ZARYA)\n1 25544U 98067A   08264.51782528 -.00002182  00000-0 -11606-4 0  2927\n\
                   2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.72125391563537\n";
        let json = r#"[{"OBJECT_NAME": "ISS (ZARYA)", "OBJECT_ID": "1998-067A",
            "EPOCH": "2008-09-20T12:25:40.104192", "MEAN_MOTION": 15.72125391,
            "ECCENTRICITY": 0.0006703, "INCLINATION": 51.6416, "RA_OF_ASC_NODE": 247.4627,
            "ARG_OF_PERICENTER": 130.536, "MEAN_ANOMALY": 325.0288, "EPHEMERIS_TYPE": 0,
            "CLASSIFICATION_TYPE": "U", "NORAD_CAT_ID": 25544, "ELEMENT_SET_NO": 292,
            "REV_AT_EPOCH": 56353, "BSTAR": -1.1606e-5, "MEAN_MOTION_DOT": -2.182e-5,
            "MEAN_MOTION_DDOT": 0}]"#;
        let xml = "<?xml version=\"1.0\"?><ndm><omm id=\"CCSDS_OMM_VERS\" version=\"2.0\"><body><segment>\
            <metadata><OBJECT_NAME>ISS (ZARYA)</OBJECT_NAME><OBJECT_ID>1998-067A</OBJECT_ID></metadata>\
            <data><meanElements><EPOCH>2008-09-20T12:25:40.104192</EPOCH><MEAN_MOTION>15.72125391</MEAN_MOTION>\
            <ECCENTRICITY>.0006703</ECCENTRICITY><INCLINATION>51.6416</INCLINATION>\
            <RA_OF_ASC_NODE>247.4627</RA_OF_ASC_NODE><ARG_OF_PERICENTER>130.5360</ARG_OF_PERICENTER>\
            <MEAN_ANOMALY>325.0288</MEAN_ANOMALY></meanElements><tleParameters>\
            <NORAD_CAT_ID>25544</NORAD_CAT_ID><ELEMENT_SET_NO>292</ELEMENT_SET_NO>\
            <REV_AT_EPOCH>56353</REV_AT_EPOCH><BSTAR>-.11606E-4</BSTAR>\
            <MEAN_MOTION_DOT>-.00002182</MEAN_MOTION_DOT><MEAN_MOTION_DDOT>0</MEAN_MOTION_DDOT>\
            </tleParameters></data></segment></body></omm></ndm>";
        let t = Utc::parse("2008-09-21T03:00:00").unwrap();
        let mut at = Vec::new();
        for text in [tle, json, xml] {
            let (e, bad) = parse(text).unwrap();
            assert!(bad.is_empty(), "{bad:?}");
            assert_eq!((e.len(), e[0].norad_id), (1, 25544));
            assert_eq!(e[0].object_name.as_deref(), Some("ISS (ZARYA)"));
            let s = Satellite::from_elements(&e[0]).unwrap();
            at.push(s.teme(&t).unwrap().0);
        }
        for r in &at[1..] {
            let d: f64 = (0..3)
                .map(|i| (r[i] - at[0][i]).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(d < 0.5, "{r:?} vs {:?}: {d} km", at[0]);
        }
        // Not elements at all: an error, never a panic.
        assert!(parse("<ndm></ndm>").is_err());
        assert!(parse("[{\"NORAD_CAT_ID\": 1}]").unwrap().1.len() == 1);
        assert!(tle_lines("1 2\n2 3\n").0.is_empty());
        // Lines of the right shape with anything in their columns, and cut OMM: refused or
        // read, never a panic.
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(26);
        let good = tle.lines().collect::<Vec<_>>();
        for _ in 0..3000 {
            let mut pair: Vec<Vec<u8>> = good[1..].iter().map(|l| l.as_bytes().to_vec()).collect();
            for _ in 0..rng.random_range(1..6) {
                let (k, c) = (rng.random_range(0..2), rng.random_range(2..69));
                pair[k][c] = rng.random_range(b' '..=b'~');
            }
            let text = format!(
                "{}\n{}\n",
                String::from_utf8_lossy(&pair[0]),
                String::from_utf8_lossy(&pair[1])
            );
            let _ = parse(&text);
            // Elements of any size: refused, or propagated to a finite state or none.
            let mut v = |a: f64, b: f64| {
                if rng.random_bool(0.2) {
                    [0.0, -1.0, 1e12, f64::MIN_POSITIVE][rng.random_range(0..4)]
                } else {
                    rng.random_range(a..b)
                }
            };
            let omm = format!(
                r#"{{"OBJECT_NAME": "X", "OBJECT_ID": "2000-001A", "EPOCH": "2024-01-01T00:00:00",
                "MEAN_MOTION": {}, "ECCENTRICITY": {}, "INCLINATION": {}, "RA_OF_ASC_NODE": {},
                "ARG_OF_PERICENTER": {}, "MEAN_ANOMALY": {}, "EPHEMERIS_TYPE": 0,
                "CLASSIFICATION_TYPE": "U", "NORAD_CAT_ID": 1, "ELEMENT_SET_NO": 1,
                "REV_AT_EPOCH": 1, "BSTAR": {}, "MEAN_MOTION_DOT": 0, "MEAN_MOTION_DDOT": 0}}"#,
                v(0.5, 17.0),
                v(0.0, 0.99),
                v(0.0, 180.0),
                v(0.0, 360.0),
                v(0.0, 360.0),
                v(0.0, 360.0),
                v(-1e-3, 1e-3)
            );
            if let Ok((e, _)) = parse(&omm)
                && let Some(Ok(s)) = e.first().map(Satellite::from_elements)
            {
                let t = Utc::parse("2024-01-03T00:00:00").unwrap();
                if let Some((r, v)) = s.teme(&t) {
                    assert!(r.iter().chain(&v).all(|x| x.is_finite()));
                }
            }
            let cut = rng.random_range(0..xml.len());
            if xml.is_char_boundary(cut) {
                let _ = parse(&xml[..cut]);
            }
        }
    }

    /// Issue 45, item 2: a file that starts with a UTF-8 byte-order mark is read as without
    /// it; an object given twice is kept once, with its newest elements.
    #[test]
    fn a_bom_is_read_past_and_a_repeated_object_keeps_its_newest_elements() {
        let (l1, l2) = (ASTROPY[0].1, ASTROPY[0].2);
        // The same object at an epoch a day later, its checksum made right again.
        let mut newer = l1.replace("24075.00000000", "24076.00000000");
        let sum: u32 = newer[..68]
            .chars()
            .map(|c| c.to_digit(10).unwrap_or((c == '-') as u32))
            .sum();
        newer.replace_range(68.., &(sum % 10).to_string());
        let other = (ASTROPY[1].1, ASTROPY[1].2);
        for text in [
            format!("\u{feff}{l1}\n{l2}\n"),
            format!("\u{feff}ISS\n{l1}\n{l2}\n"),
        ] {
            let c = TleCatalog::from_text(&text, "t").unwrap();
            assert_eq!(c.satellites.len(), 1, "{text:?}");
        }
        let text = format!(
            "{l1}\n{l2}\n{}\n{}\n{newer}\n{l2}\n{l1}\n{l2}\n",
            other.0, other.1
        );
        let c = TleCatalog::from_text(&text, "t").unwrap();
        let ids: Vec<u64> = c.satellites.iter().map(|s| s.norad).collect();
        assert_eq!(ids, [43013, 25544]);
        // 2024 day 76.0 (the newer set) is JD 2460385.5.
        let jd = c.satellites[1].epoch_jd;
        assert!((jd - 2_460_385.5).abs() < 1e-6, "{jd}");
    }

    /// Issue 45, item 2: elements far from the frame time are warned of once a run.
    #[test]
    fn old_elements_are_warned_of_once() {
        let (e, _) = tle_lines(&format!("{}\n{}\n", ASTROPY[0].1, ASTROPY[0].2));
        let cat = TleCatalog::new(vec![Satellite::from_elements(&e[0]).unwrap()]);
        let epoch = Utc::parse("2024-03-15T00:00:00").unwrap();
        assert_eq!(cat.age_warning(&epoch.add_seconds(29.0 * 86_400.0)), None);
        let w = cat
            .age_warning(&epoch.add_seconds(-45.0 * 86_400.0))
            .unwrap();
        assert!(
            w.contains("1 of 1 objects") && w.contains("NORAD 25544: 45 days"),
            "{w}"
        );
        assert!(w.contains("may be far off"), "{w}");
        assert_eq!(cat.age_warning(&epoch.add_seconds(-90.0 * 86_400.0)), None);
    }

    /// The coarse prefilter's interpolation stays within metres of SGP4 itself.
    #[test]
    fn coarse_positions_follow_sgp4() {
        let (e, _) = tle_lines(&format!("{}\n{}\n", ASTROPY[0].1, ASTROPY[0].2));
        let sat = Satellite::from_elements(&e[0]).unwrap();
        let cat = TleCatalog::new(vec![sat]);
        for s in [0.0, 17.3, 59.9, 119.99, 250.5] {
            let t = Utc::parse(ASTROPY[0].6).unwrap().add_seconds(s);
            let p = cat.coarse_positions(&t)[0].unwrap();
            let (q, _) = cat.satellites[0].teme(&t).unwrap();
            let d: f64 = (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt();
            assert!(d < 0.05, "{s} s: {d} km");
        }
    }
}
