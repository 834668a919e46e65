//! Streak astrometry in the two formats orbit-determination users read: the writers.
//!
//! * CCSDS Tracking Data Message (503.0-B-2), KVN: the agency and SST standard (ESA,
//!   GSOC SMARTnet, APPARILLO). One RADEC segment per track, then an AZEL segment when
//!   every observation of the track has a station azimuth/elevation.
//! * IOD 80-column lines (G. Lewis 1998, clarified 2002; satobs.org): the open standard
//!   that stvid, sattools, Find_Orb and TruSat read. gpustar writes angle format 2
//!   (RA `HHMMmmm`, Dec `+DDMMmm`) with epoch code 5 (J2000).
//!
//! Inputs are the UTC strings gpustar produces elsewhere (`YYYY-MM-DDThh:mm:ss.sss`), read
//! by the crate's one time type ([`Utc`]), and ICRS degrees. The writers check their input
//! and refuse it rather than write a line a reader would misread. The TDM and IOD parsers
//! that read back what gpustar writes (as stvid and sattools read it) are test code, in
//! `tests/it/common/formats.rs`.

use crate::sky::Utc;
use std::io;

/// (year, month, day, [hour, minute, second, millisecond]) as [`Utc::calendar_ms`] gives them.
type CalendarMs = (i32, i32, i32, [i32; 4]);

/// A UTC time string as both formats write it: parsed by [`Utc::parse`], rounded to the
/// millisecond (SOFA d2dtf, which carries through the calendar and knows leap seconds), with
/// a four-digit year. Returns the instant and its calendar fields ([`Utc::calendar_ms`]).
fn utc_ms(s: &str) -> Result<(Utc, CalendarMs), String> {
    let what = || format!("time '{}'", s.escape_default());
    let t = Utc::parse(s).map_err(|e| format!("{}: {e}", what()))?;
    let cal = t
        .calendar_ms()
        .ok_or_else(|| format!("{} cannot be put in calendar form", what()))?;
    if !(0..=9999).contains(&cal.0) {
        return Err(format!(
            "{} has year {}, which does not fit the formats' four digits",
            what(),
            cal.0
        ));
    }
    Ok((t, cal))
}

// ------------------------------------------------------------------------------------
// CCSDS TDM (KVN)
// ------------------------------------------------------------------------------------

/// One angle measurement of a streak end or midpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct AngleObs {
    /// UTC, ISO 8601 `YYYY-MM-DDThh:mm:ss.sss` as [`Utc::parse`] reads it (more or fewer
    /// fraction digits, or a trailing `Z`, are accepted and rounded to milliseconds).
    pub time_utc: String,
    /// Right ascension, ICRS, degrees (any value; written wrapped into [0, 360)).
    pub ra_deg: f64,
    /// Declination, ICRS, degrees, in [-90, 90].
    pub dec_deg: f64,
    /// Topocentric azimuth from north through east, degrees; `None` without a station.
    pub az_deg: Option<f64>,
    /// Topocentric elevation, degrees, airless; `None` without a station.
    pub el_deg: Option<f64>,
}

/// One streak's observations (its ends with times, or its midpoint), from one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    /// PARTICIPANT_2: the object, e.g. `UNKNOWN` or the input file stem.
    pub object: String,
    /// PARTICIPANT_1: the station, e.g. `GPUSTAR` or a COSPAR 4-digit code.
    pub station: String,
    /// In any order; the writer sorts them by time (TDM data must be chronological).
    pub observations: Vec<AngleObs>,
}

/// Says what the RADEC angles are, since TDM has no keyword for "astrometric". The plate
/// maps the field onto catalogue positions, so the stars' annual aberration is taken out
/// of the satellite too; gpustar does not put it back (CORRECTION_ABERRATION_YEARLY would
/// be the keyword if it did).
const RADEC_COMMENTS: [&str; 4] = [
    "Astrometric ICRS RA/Dec from a star-referenced plate solution: the satellite's",
    "direction reduced as a star's would be, so the stars' annual aberration is taken out",
    "of it too. No aberration correction is applied: re-apply annual aberration (ICRS to",
    "GCRS as for a star) for the satellite's true topocentric direction.",
];

/// Says how the AZEL angles were reduced (spec/INTERFACE.md, "Streaks").
const AZEL_COMMENTS: [&str; 2] = [
    "Azimuth from north through east, elevation airless (no refraction): the RADEC",
    "direction reduced as a star's at the station (IAU 2006/2000A, annual aberration, UT1).",
];

/// A KVN text value: trimmed, printable ASCII on one line (503.0-B-2 4.2.1), short
/// enough that its line stays under the 254-character limit.
fn kvn_value(v: &str, what: &str) -> Result<String, String> {
    let t = v.trim();
    if t.is_empty() {
        return Err(format!("{what} is empty"));
    }
    if let Some(c) = t.chars().find(|c| !(' '..='~').contains(c)) {
        return Err(format!(
            "{what} '{}' contains {c:?}; TDM values are printable ASCII on one line",
            t.escape_default()
        ));
    }
    if t.len() > KVN_VALUE_MAX {
        return Err(format!(
            "{what} is {} characters; TDM lines are limited to 254",
            t.len()
        ));
    }
    Ok(t.to_string())
}

/// The longest KVN text value gpustar writes (503.0-B-2 limits a line to 254 characters).
const KVN_VALUE_MAX: usize = 200;

/// Any name as a KVN text value [`tdm_text`] accepts: characters outside printable ASCII,
/// and the backslash, written as Rust's `escape_default` writes them (`é` → `\u{e9}`, a
/// newline → `\n`, `\` → `\\`), so that the original can be told back; blanks at the ends
/// kept as `\u{20}`; a value over 200 characters shortened in the middle (`...`); an empty
/// one written `(unnamed)`.
pub fn kvn_escape(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    let last = name.chars().count().saturating_sub(1);
    for (i, c) in name.chars().enumerate() {
        if c == ' ' && (i == 0 || i == last) {
            out.push_str("\\u{20}");
        } else if c == '\\' || !(' '..='~').contains(&c) {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    if out.is_empty() {
        return "(unnamed)".to_string();
    }
    if out.len() > KVN_VALUE_MAX {
        // All ASCII now: byte indices are character indices.
        let keep = (KVN_VALUE_MAX - 3) / 2;
        out = format!("{}...{}", &out[..keep], &out[out.len() - keep..]);
    }
    out
}

/// Degrees with 9 decimals (3.6 µas, far below 0.001″), never `-0.000000000` (the TDM
/// forbids `-0`).
fn fmt_deg(v: f64) -> String {
    let s = format!("{v:.9}");
    if s.bytes().all(|c| matches!(c, b'-' | b'0' | b'.')) {
        "0.000000000".to_string()
    } else {
        s
    }
}

/// An angle wrapped into [0, 360) after rounding to the 9 decimals written, so that
/// 359.9999999999 becomes 0 rather than 360.
fn fmt_deg_360(v: f64) -> String {
    let s = fmt_deg(v.rem_euclid(360.0));
    if s == "360.000000000" {
        "0.000000000".to_string()
    } else {
        s
    }
}

/// One TDM segment to write: its metadata that differ by angle type, and its rows.
struct SegmentOut<'a> {
    comments: &'a [&'a str],
    angle_type: &'a str,
    reference_frame: Option<&'a str>,
    station: &'a str,
    object: &'a str,
    /// (epoch, ANGLE_1, ANGLE_2), chronological, epochs unique.
    rows: Vec<(&'a str, String, String)>,
}

fn push_segment(lines: &mut Vec<String>, seg: &SegmentOut) {
    let (Some(first), Some(last)) = (seg.rows.first(), seg.rows.last()) else {
        return;
    };
    lines.push(String::new());
    lines.push("META_START".to_string());
    for c in seg.comments {
        lines.push(format!("COMMENT {c}"));
    }
    lines.push("TIME_SYSTEM = UTC".to_string());
    lines.push(format!("START_TIME = {}", first.0));
    lines.push(format!("STOP_TIME = {}", last.0));
    lines.push(format!("PARTICIPANT_1 = {}", seg.station));
    lines.push(format!("PARTICIPANT_2 = {}", seg.object));
    lines.push("MODE = SEQUENTIAL".to_string());
    lines.push("PATH = 2,1".to_string());
    lines.push(format!("ANGLE_TYPE = {}", seg.angle_type));
    if let Some(frame) = seg.reference_frame {
        lines.push(format!("REFERENCE_FRAME = {frame}"));
    }
    lines.push("META_STOP".to_string());
    lines.push("DATA_START".to_string());
    for (epoch, a1, a2) in &seg.rows {
        lines.push(format!("ANGLE_1 = {epoch} {a1}"));
        lines.push(format!("ANGLE_2 = {epoch} {a2}"));
    }
    lines.push("DATA_STOP".to_string());
}

/// The whole TDM as text, or why the input cannot be written: what [`write_tdm`] writes,
/// for a caller that wants to check a track (or hold the text) before writing anything.
pub fn tdm_text(
    creation_date_utc: &str,
    originator: &str,
    tracks: &[Track],
) -> crate::Result<String> {
    tdm_checked(creation_date_utc, originator, tracks).map_err(crate::Error::Output)
}

/// [`tdm_text`], its message as text.
fn tdm_checked(
    creation_date_utc: &str,
    originator: &str,
    tracks: &[Track],
) -> Result<String, String> {
    let (created, _) = utc_ms(creation_date_utc).map_err(|e| format!("CREATION_DATE: {e}"))?;
    let originator = kvn_value(originator, "ORIGINATOR")?;
    let mut lines = vec!["CCSDS_TDM_VERS = 2.0".to_string()];
    if tracks.is_empty() {
        lines.push("COMMENT No streak observations.".to_string());
    }
    lines.push(format!("CREATION_DATE = {}", created.iso()));
    lines.push(format!("ORIGINATOR = {originator}"));

    for (i, track) in tracks.iter().enumerate() {
        let what = format!(
            "track {} (object '{}')",
            i + 1,
            track.object.escape_default()
        );
        let object = kvn_value(&track.object, &format!("{what}: object"))?;
        let station = kvn_value(&track.station, &format!("{what}: station"))?;
        if track.observations.is_empty() {
            return Err(format!(
                "{what} has no observations; a TDM segment needs data"
            ));
        }
        let mut obs = Vec::with_capacity(track.observations.len());
        for (j, o) in track.observations.iter().enumerate() {
            let at = format!("{what}, observation {}", j + 1);
            let epoch = utc_ms(&o.time_utc)
                .map_err(|e| format!("{at}: {e}"))?
                .0
                .iso();
            if !o.ra_deg.is_finite() {
                return Err(format!("{at}: RA {} is not a number", o.ra_deg));
            }
            if !(-90.0..=90.0).contains(&o.dec_deg) {
                return Err(format!("{at}: Dec {} is not in [-90, 90]", o.dec_deg));
            }
            if let Some(az) = o.az_deg.filter(|az| !az.is_finite()) {
                return Err(format!("{at}: azimuth {az} is not a number"));
            }
            if let Some(el) = o.el_deg.filter(|el| !(-90.0..=90.0).contains(el)) {
                return Err(format!("{at}: elevation {el} is not in [-90, 90]"));
            }
            obs.push((epoch, o));
        }
        obs.sort_by(|a, b| a.0.cmp(&b.0));
        if let Some(w) = obs.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(format!(
                "{what} has two observations at {}; TDM epochs must differ within a keyword",
                w[0].0
            ));
        }
        let radec = obs
            .iter()
            .map(|(t, o)| (t.as_str(), fmt_deg_360(o.ra_deg), fmt_deg(o.dec_deg)))
            .collect();
        push_segment(
            &mut lines,
            &SegmentOut {
                comments: &RADEC_COMMENTS,
                angle_type: "RADEC",
                reference_frame: Some("ICRF"),
                station: &station,
                object: &object,
                rows: radec,
            },
        );
        let azel: Option<Vec<_>> = obs
            .iter()
            .map(|(t, o)| {
                let (az, el) = o.az_deg.zip(o.el_deg)?;
                Some((t.as_str(), fmt_deg_360(az), fmt_deg(el)))
            })
            .collect();
        if let Some(rows) = azel {
            push_segment(
                &mut lines,
                &SegmentOut {
                    comments: &AZEL_COMMENTS,
                    angle_type: "AZEL",
                    reference_frame: None,
                    station: &station,
                    object: &object,
                    rows,
                },
            );
        }
    }
    let mut text = lines.join("\n");
    text.push('\n');
    Ok(text)
}

/// Writes a CCSDS TDM 2.0 (KVN) holding `tracks`: per track a RADEC segment
/// (REFERENCE_FRAME = ICRF, with COMMENTs saying the angles are astrometric, annual
/// aberration not removed) and, when every observation has both azimuth and elevation,
/// an AZEL segment. Epochs are UTC to the millisecond, angles have 9 decimals, RA and
/// azimuth are wrapped into [0, 360).
///
/// The text is built and checked before anything is written, so on an `InvalidInput`
/// error (bad time, Dec outside [-90, 90], a track without observations or with two at
/// the same epoch, a name that is not printable ASCII) `out` is untouched. No tracks give
/// a header-only TDM with a COMMENT saying so, which a TDM reader reads as no segments.
pub fn write_tdm(
    out: &mut impl io::Write,
    creation_date_utc: &str,
    originator: &str,
    tracks: &[Track],
) -> crate::Result<()> {
    let text = tdm_text(creation_date_utc, originator, tracks)?;
    Ok(out.write_all(text.as_bytes())?)
}

// ------------------------------------------------------------------------------------
// IOD 80-column lines
// ------------------------------------------------------------------------------------

/// One IOD observation (one line). Columns as in G. Lewis's IOD format description:
///
/// ```text
/// 1-5 NORAD  7-15 intl. designation  17-20 station  22 status  24-31 YYYYMMDD
/// 32-40 HHMMSSsss  42-43 time uncertainty MX  45 angle format  46 epoch
/// 48-54 RA  55 Dec sign  56-61 Dec  63-64 position uncertainty MX  66 behaviour
/// ```
///
/// MX means M·10^(X−8). The position uncertainty's unit depends on the angle format
/// (1: arcsec, 2: arcmin, 3 and 7: degrees); this struct holds it in degrees.
#[derive(Debug, Clone, PartialEq)]
pub struct IodObs {
    /// NORAD catalogue number, 0-99999 (99999 or 0 when unknown).
    pub norad: u32,
    /// International designation as in columns 7-15, e.g. `98 067A` (`YY NNNPPP`);
    /// at most 9 characters, may be empty (written padded with blanks to 9).
    pub intl_des: String,
    /// COSPAR station number, 0-9999.
    pub station: u16,
    /// Sky/station code: E G F P B T (excellent … terrible), C, O; `' '` for none.
    pub status: char,
    /// UTC `YYYY-MM-DDThh:mm:ss.sss`. Written to the millisecond; a truncated time read
    /// from a line has its missing digits as zeros.
    pub time_utc: String,
    /// Time uncertainty, seconds; NaN when not given (blank columns 42-43).
    pub time_unc_s: f64,
    /// Right ascension J2000 (= ICRS at this resolution), degrees.
    pub ra_deg: f64,
    /// Declination J2000, degrees.
    pub dec_deg: f64,
    /// Position uncertainty, degrees; NaN when not given (blank columns 63-64). Written
    /// in arcminutes, the unit of angle format 2, so at most 90′ (1.5°).
    pub pos_unc_deg: f64,
    /// Optical behaviour code (column 66), e.g. `'S'` steady, `'I'` irregular; `' '` for
    /// none (gpustar does not judge the light curve).
    pub behaviour: char,
}

/// MX for the smallest M·10^(X−8) (M 1-9, X 0-9) that is at least `v`; `None` when `v`
/// is negative or above 90, the largest code (`99`). The comparison allows 1e-9 relative
/// so that 0.3 (held as 0.299999…) still gives `37`.
fn mx_encode(v: f64) -> Option<String> {
    if !(0.0..=90.0 * (1.0 + 1e-9)).contains(&v) {
        return None;
    }
    for x in 0..=9 {
        for m in 1..=9 {
            if f64::from(m) * 10f64.powi(x - 8) >= v * (1.0 - 1e-9) {
                return Some(format!("{m}{x}"));
            }
        }
    }
    None
}

/// Pieces an unidentified object's designation can have in a day: the launch-piece letters
/// A-Z without I and O (24), then two of them (576). sattools reads the designation's second
/// part into 6 bytes (`%s` into `char buf2[6]`), so three letters would overflow it.
pub const PIECES_PER_DAY: usize = 24 + 24 * 24;

/// The `k`-th piece (0-based, below [`PIECES_PER_DAY`]): A, B, … Z, AA, AB, … ZZ.
fn piece_letters(k: usize) -> String {
    const L: &[u8; 24] = b"ABCDEFGHJKLMNPQRSTUVWXYZ";
    if k < 24 {
        (L[k] as char).to_string()
    } else {
        let k = (k - 24) % (24 * 24);
        format!("{}{}", L[k / 24] as char, L[k % 24] as char)
    }
}

/// stvid's international designation for an unidentified object (stvid/extract.py,
/// `get_cospar`): the two-digit year, the day of year + 500 (never a real launch number),
/// and a piece, here the `piece`-th of that UTC day (taken modulo [`PIECES_PER_DAY`]):
/// `26 835A` for the first of 2026-12-01. Columns 7-15 of the IOD line.
pub fn unidentified_designation(time_utc: &str, piece: usize) -> crate::Result<String> {
    let (_, (year, month, day, _)) = utc_ms(time_utc).map_err(crate::Error::Output)?;
    const BEFORE: [i32; 12] = [0, 31, 59, 90, 120, 151, 181, 212, 243, 273, 304, 334];
    let leap = year % 4 == 0 && (year % 100 != 0 || year % 400 == 0);
    let doy = BEFORE[(month - 1) as usize] + day + i32::from(leap && month > 2);
    Ok(format!(
        "{:02} {}{}",
        year % 100,
        doy + 500,
        piece_letters(piece % PIECES_PER_DAY)
    ))
}

/// RA as `HHMMmmm` (hours, minutes, thousandths of a minute), rounded, 24h wrapping to 0.
fn ra_hhmmmmm(ra_deg: f64) -> String {
    const PER_DAY: i64 = 24 * 60 * 1000;
    let n = (ra_deg.rem_euclid(360.0) / 15.0 * 60_000.0).round() as i64 % PER_DAY;
    format!("{:02}{:02}{:03}", n / 60_000, n / 1000 % 60, n % 1000)
}

/// Dec as `±DDMMmm` (degrees, arcminutes, hundredths of an arcminute), rounded; the
/// sign is kept for -1° < Dec < 0 and dropped (`+`) only when the value rounds to zero.
fn dec_sddmmmm(dec_deg: f64) -> String {
    let n = (dec_deg.abs() * 6000.0).round() as i64;
    let sign = if dec_deg < 0.0 && n > 0 { '-' } else { '+' };
    format!("{sign}{:02}{:02}{:02}", n / 6000, n / 100 % 60, n % 100)
}

/// A code column: one printable ASCII character or a blank.
fn check_code(c: char, what: &str) -> Result<char, String> {
    if c == ' ' || c.is_ascii_graphic() {
        Ok(c)
    } else {
        Err(format!(
            "{what} {c:?} is not a printable ASCII character or a blank"
        ))
    }
}

/// The IOD line of `o`: angle format 2, epoch code 5 (J2000), magnitude and flash
/// columns blank, right-trimmed (no trailing blanks: 66 characters with a behaviour
/// code, 61-64 without), as stvid writes it. Errors name the field that cannot be written:
/// NORAD > 99999, station > 9999, a designation over 9 characters or not ASCII, a bad
/// time, Dec outside [-90, 90], an uncertainty that is negative or above the format's
/// largest code (90 s; 90′).
pub fn iod_line(o: &IodObs) -> crate::Result<String> {
    if o.norad > 99_999 {
        return Err(crate::Error::Output(format!(
            "NORAD number {} does not fit IOD's 5 digits",
            o.norad
        )));
    }
    if o.station > 9999 {
        return Err(crate::Error::Output(format!(
            "station {} does not fit IOD's 4 digits",
            o.station
        )));
    }
    if o.intl_des.len() > 9
        || !o
            .intl_des
            .bytes()
            .all(|c| c == b' ' || c.is_ascii_graphic())
    {
        return Err(crate::Error::Output(format!(
            "international designation '{}' must be at most 9 ASCII characters (YY NNNPPP)",
            o.intl_des.escape_default()
        )));
    }
    let status = check_code(o.status, "station status").map_err(crate::Error::Output)?;
    let behaviour =
        check_code(o.behaviour, "optical behaviour code").map_err(crate::Error::Output)?;
    let (_, (year, month, day, [hour, minute, second, milli])) =
        utc_ms(&o.time_utc).map_err(crate::Error::Output)?;
    if !o.ra_deg.is_finite() {
        return Err(crate::Error::Output(format!(
            "RA {} is not a number",
            o.ra_deg
        )));
    }
    if !(-90.0..=90.0).contains(&o.dec_deg) {
        return Err(crate::Error::Output(format!(
            "Dec {} is not in [-90, 90]",
            o.dec_deg
        )));
    }
    let time_mx = if o.time_unc_s.is_nan() {
        "  ".to_string()
    } else {
        mx_encode(o.time_unc_s).ok_or_else(|| {
            crate::Error::Output(format!(
                "time uncertainty {} s is not in [0, 90], the range of IOD's MX code",
                o.time_unc_s
            ))
        })?
    };
    let pos_mx = if o.pos_unc_deg.is_nan() {
        "  ".to_string()
    } else {
        mx_encode(o.pos_unc_deg * 60.0).ok_or_else(|| {
            crate::Error::Output(format!(
                "position uncertainty {}° is not in [0, 1.5°] (90′, IOD's largest MX code in format 2)",
                o.pos_unc_deg
            ))
        })?
    };
    let line = format!(
        "{:05} {:<9} {:04} {} {:04}{:02}{:02}{:02}{:02}{:02}{:03} {} 25 {}{} {} {}",
        o.norad,
        o.intl_des,
        o.station,
        status,
        year,
        month,
        day,
        hour,
        minute,
        second,
        milli,
        time_mx,
        ra_hhmmmmm(o.ra_deg),
        dec_sddmmmm(o.dec_deg),
        pos_mx,
        behaviour
    );
    Ok(line.trim_end().to_string())
}

#[cfg(test)]
mod tests;
