//! Streak astrometry in the two formats orbit-determination users read.
//!
//! Size: the writers are about 500 lines; the TDM and IOD parsers (about 600, used by the tests
//! to read back what gpustar writes, as stvid and sattools read it) and this file's own UTC
//! type move out with issue 23's single time type.
//!
//! * CCSDS Tracking Data Message (503.0-B-2), KVN: the agency and SST standard (ESA,
//!   GSOC SMARTnet, APPARILLO). One RADEC segment per track, then an AZEL segment when
//!   every observation of the track has a station azimuth/elevation.
//! * IOD 80-column lines (G. Lewis 1998, clarified 2002; satobs.org): the open standard
//!   that stvid, sattools, Find_Orb and TruSat read. gpustar writes angle format 2
//!   (RA `HHMMmmm`, Dec `+DDMMmm`) with epoch code 5 (J2000).
//!
//! Inputs are the UTC strings gpustar produces elsewhere (`YYYY-MM-DDThh:mm:ss.sss`) and
//! ICRS degrees. The writers check their input and refuse it rather than write a line a
//! reader would misread; the parsers never panic and say where a line is wrong.

use std::io;

// ------------------------------------------------------------------------------------
// UTC time strings
// ------------------------------------------------------------------------------------

/// A UTC instant in calendar fields, to the millisecond (the resolution of both formats'
/// time tags as gpustar writes them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Utc {
    year: u32,
    month: u32,
    day: u32,
    hour: u32,
    minute: u32,
    second: u32,
    milli: u32,
}

fn days_in_month(year: u32, month: u32) -> u32 {
    match month {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if (year.is_multiple_of(4) && !year.is_multiple_of(100)) || year.is_multiple_of(400) => {
            29
        }
        2 => 28,
        _ => 0,
    }
}

impl Utc {
    /// Checks the calendar; second 60 is accepted only at 23:59 (a leap second).
    fn checked(self) -> Result<Utc, String> {
        if !(1..=12).contains(&self.month) {
            return Err(format!("month {} is not 1-12", self.month));
        }
        let dim = days_in_month(self.year, self.month);
        if !(1..=dim).contains(&self.day) {
            return Err(format!(
                "day {} is not 1-{dim} in {:04}-{:02}",
                self.day, self.year, self.month
            ));
        }
        if self.hour > 23 {
            return Err(format!("hour {} is not 0-23", self.hour));
        }
        if self.minute > 59 {
            return Err(format!("minute {} is not 0-59", self.minute));
        }
        let leap_ok = self.second == 60 && self.hour == 23 && self.minute == 59;
        if self.second > 59 && !leap_ok {
            return Err(format!(
                "second {} is not 0-59 (60 only at 23:59, a leap second)",
                self.second
            ));
        }
        Ok(self)
    }

    /// Adds one second, carrying through minutes, hours, days, months and years. The
    /// carry knows no leap-second table: 23:59:59 + 1 s is the next day's 00:00:00.
    fn add_second(&mut self) -> Result<(), String> {
        self.second += 1;
        if self.second < 60 {
            return Ok(());
        }
        self.second = 0;
        self.minute += 1;
        if self.minute < 60 {
            return Ok(());
        }
        self.minute = 0;
        self.hour += 1;
        if self.hour < 24 {
            return Ok(());
        }
        self.hour = 0;
        self.day += 1;
        if self.day <= days_in_month(self.year, self.month) {
            return Ok(());
        }
        self.day = 1;
        self.month += 1;
        if self.month <= 12 {
            return Ok(());
        }
        self.month = 1;
        self.year += 1;
        if self.year > 9999 {
            return Err("rounding to milliseconds passes year 9999".to_string());
        }
        Ok(())
    }

    /// `YYYY-MM-DDThh:mm:ss.sss`, the form gpustar uses everywhere.
    fn iso(&self) -> String {
        format!(
            "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:03}",
            self.year, self.month, self.day, self.hour, self.minute, self.second, self.milli
        )
    }
}

/// The value of a run of 1-9 ASCII digits; `None` for anything else.
fn digits_value(b: &[u8]) -> Option<u32> {
    if b.is_empty() || b.len() > 9 || !b.iter().all(u8::is_ascii_digit) {
        return None;
    }
    Some(b.iter().fold(0, |acc, &d| acc * 10 + u32::from(d - b'0')))
}

/// Parses `YYYY-MM-DDThh:mm:ss[.f…][Z]`, rounding the fraction half-up to milliseconds
/// (with the carry) so that any precision a caller has is accepted.
fn parse_utc(s: &str) -> Result<Utc, String> {
    let bad = || {
        format!(
            "time '{}' is not UTC as YYYY-MM-DDThh:mm:ss[.sss]",
            s.escape_default()
        )
    };
    let b = s.as_bytes();
    let separators = [(4, b'-'), (7, b'-'), (10, b'T'), (13, b':'), (16, b':')];
    if b.len() < 19 || separators.iter().any(|&(i, c)| b[i] != c) {
        return Err(bad());
    }
    let (Some(year), Some(month), Some(day), Some(hour), Some(minute), Some(second)) = (
        digits_value(&b[0..4]),
        digits_value(&b[5..7]),
        digits_value(&b[8..10]),
        digits_value(&b[11..13]),
        digits_value(&b[14..16]),
        digits_value(&b[17..19]),
    ) else {
        return Err(bad());
    };
    let mut rest = &b[19..];
    if let [head @ .., b'Z'] = rest {
        rest = head;
    }
    let mut milli = 0;
    let mut round_up = false;
    if !rest.is_empty() {
        let frac = match rest {
            [b'.', f @ ..] if !f.is_empty() && f.iter().all(u8::is_ascii_digit) => f,
            _ => return Err(bad()),
        };
        for i in 0..3 {
            milli = milli * 10 + frac.get(i).map_or(0, |&d| u32::from(d - b'0'));
        }
        round_up = frac.get(3).is_some_and(|&d| d >= b'5');
    }
    let mut t = Utc {
        year,
        month,
        day,
        hour,
        minute,
        second,
        milli,
    }
    .checked()
    .map_err(|e| format!("time '{s}': {e}"))?;
    if round_up {
        t.milli += 1;
        if t.milli == 1000 {
            t.milli = 0;
            t.add_second().map_err(|e| format!("time '{s}': {e}"))?;
        }
    }
    Ok(t)
}

// ------------------------------------------------------------------------------------
// CCSDS TDM (KVN)
// ------------------------------------------------------------------------------------

/// One angle measurement of a streak end or midpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct AngleObs {
    /// UTC, ISO 8601 `YYYY-MM-DDThh:mm:ss.sss` (more or fewer fraction digits, or a
    /// trailing `Z`, are accepted and rounded to milliseconds).
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
    if t.len() > 200 {
        return Err(format!(
            "{what} is {} characters; TDM lines are limited to 254",
            t.len()
        ));
    }
    Ok(t.to_string())
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

/// The whole TDM as text, or why the input cannot be written.
pub(crate) fn tdm_text(
    creation_date_utc: &str,
    originator: &str,
    tracks: &[Track],
) -> Result<String, String> {
    let created = parse_utc(creation_date_utc).map_err(|e| format!("CREATION_DATE: {e}"))?;
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
            let epoch = parse_utc(&o.time_utc)
                .map_err(|e| format!("{at}: {e}"))?
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
/// a header-only TDM with a COMMENT saying so, which [`parse_tdm`] reads as no segments.
pub fn write_tdm(
    out: &mut impl io::Write,
    creation_date_utc: &str,
    originator: &str,
    tracks: &[Track],
) -> io::Result<()> {
    let text = tdm_text(creation_date_utc, originator, tracks)
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e))?;
    out.write_all(text.as_bytes())
}

/// A parsed TDM: the header and the segments, in file order.
#[derive(Debug, Clone, PartialEq)]
pub struct Tdm {
    /// Header keyword/value pairs (`CCSDS_TDM_VERS`, `CREATION_DATE`, `ORIGINATOR`,
    /// `MESSAGE_ID`), COMMENT lines included as `("COMMENT", text)`.
    pub header: Vec<(String, String)>,
    /// One per META_START … DATA_STOP.
    pub segments: Vec<TdmSegment>,
}

/// One metadata section and the data section after it.
#[derive(Debug, Clone, PartialEq)]
pub struct TdmSegment {
    /// Metadata keyword/value pairs in file order, COMMENT lines included as
    /// `("COMMENT", text)`; values are trimmed but otherwise as written.
    pub meta: Vec<(String, String)>,
    /// COMMENT lines of the data section.
    pub data_comments: Vec<String>,
    /// The tracking data records, in file order.
    pub data: Vec<TdmRecord>,
}

/// One tracking data record: `KEYWORD = epoch value`.
#[derive(Debug, Clone, PartialEq)]
pub struct TdmRecord {
    /// `ANGLE_1`, `ANGLE_2`, `MAG`, …
    pub keyword: String,
    /// The time tag as written (either CCSDS calendar or day-of-year form).
    pub epoch: String,
    /// The measurement.
    pub value: f64,
}

fn first_value<'a>(pairs: &'a [(String, String)], key: &str) -> Option<&'a str> {
    pairs
        .iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
}

impl Tdm {
    /// The header value of `key` (e.g. `ORIGINATOR`), if present.
    pub fn header_value(&self, key: &str) -> Option<&str> {
        first_value(&self.header, key)
    }
}

impl TdmSegment {
    /// The metadata value of `key` (e.g. `ANGLE_TYPE`), if present.
    pub fn meta_value(&self, key: &str) -> Option<&str> {
        first_value(&self.meta, key)
    }

    /// The (epoch, value) pairs of one data keyword, in file order.
    pub fn values(&self, keyword: &str) -> Vec<(&str, f64)> {
        self.data
            .iter()
            .filter(|r| r.keyword == keyword)
            .map(|r| (r.epoch.as_str(), r.value))
            .collect()
    }
}

/// Whether `s` is a CCSDS time (503.0-B-2 4.3.9): `YYYY-MM-DDThh:mm:ss[.d…][Z]` or
/// `YYYY-DDDThh:mm:ss[.d…][Z]`.
fn is_ccsds_time(s: &str) -> bool {
    let b = s.as_bytes();
    let b = b.strip_suffix(b"Z").unwrap_or(b);
    let Some(t) = b.iter().position(|&c| c == b'T') else {
        return false;
    };
    let (date, time) = (&b[..t], &b[t + 1..]);
    let date_ok = match date {
        [y @ .., b'-', m1, m2, b'-', d1, d2] if y.len() == 4 => {
            digits_value(y).is_some()
                && digits_value(&[*m1, *m2]).is_some_and(|m| (1..=12).contains(&m))
                && digits_value(&[*d1, *d2]).is_some_and(|d| (1..=31).contains(&d))
        }
        [y @ .., b'-', d1, d2, d3] if y.len() == 4 => {
            digits_value(y).is_some()
                && digits_value(&[*d1, *d2, *d3]).is_some_and(|d| (1..=366).contains(&d))
        }
        _ => false,
    };
    let (hms, frac) = match time.iter().position(|&c| c == b'.') {
        Some(p) => (&time[..p], Some(&time[p + 1..])),
        None => (time, None),
    };
    let time_ok = match hms {
        [h1, h2, b':', m1, m2, b':', s1, s2] => {
            digits_value(&[*h1, *h2]).is_some_and(|h| h < 24)
                && digits_value(&[*m1, *m2]).is_some_and(|m| m < 60)
                && digits_value(&[*s1, *s2]).is_some_and(|s| s <= 60)
        }
        _ => false,
    };
    let frac_ok = frac.is_none_or(|f| !f.is_empty() && f.iter().all(u8::is_ascii_digit));
    date_ok && time_ok && frac_ok
}

/// `KEYWORD = value` split and checked (4.2.5-4.2.8, 4.3.1).
fn kvn_pair(line: &str, n: usize) -> Result<(String, String), String> {
    let Some((k, v)) = line.split_once('=') else {
        return Err(format!(
            "line {n}: expected 'KEYWORD = value', found '{}'",
            line.escape_default()
        ));
    };
    let (k, v) = (k.trim(), v.trim());
    if k.is_empty()
        || !k
            .bytes()
            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == b'_')
    {
        return Err(format!(
            "line {n}: keyword '{}' must be upper-case letters, digits and '_'",
            k.escape_default()
        ));
    }
    if v.is_empty() {
        return Err(format!("line {n}: {k} has an empty value"));
    }
    Ok((k.to_string(), v.to_string()))
}

/// A data line `KEYWORD = epoch value` (a trailing `[unit]` is tolerated).
fn data_record(line: &str, n: usize) -> Result<TdmRecord, String> {
    let (keyword, v) = kvn_pair(line, n)?;
    let mut tokens = v.split_whitespace();
    let (Some(epoch), Some(value)) = (tokens.next(), tokens.next()) else {
        return Err(format!(
            "line {n}: {keyword} needs 'epoch value', found '{}'",
            v.escape_default()
        ));
    };
    if let Some(extra) = tokens
        .next()
        .filter(|x| !(x.starts_with('[') && x.ends_with(']')))
    {
        return Err(format!(
            "line {n}: {keyword} has '{}' after its value; a data line is 'KEYWORD = epoch value'",
            extra.escape_default()
        ));
    }
    if tokens.next().is_some() {
        return Err(format!(
            "line {n}: {keyword} has extra fields; a data line is 'KEYWORD = epoch value'"
        ));
    }
    if !is_ccsds_time(epoch) {
        return Err(format!(
            "line {n}: {keyword} epoch '{}' is not a CCSDS time (YYYY-MM-DDThh:mm:ss[.d…] or YYYY-DDDThh:mm:ss[.d…])",
            epoch.escape_default()
        ));
    }
    let value = match value.parse::<f64>() {
        Ok(x) if x.is_finite() => x,
        _ => {
            return Err(format!(
                "line {n}: {keyword} value '{}' is not a finite number",
                value.escape_default()
            ));
        }
    };
    Ok(TdmRecord {
        keyword,
        epoch: epoch.to_string(),
        value,
    })
}

/// The text of a COMMENT line, or `None` when the line is not one.
fn comment_text(line: &str) -> Option<String> {
    let rest = line.strip_prefix("COMMENT")?;
    if rest.is_empty() {
        return Some(String::new());
    }
    let mut chars = rest.chars();
    match chars.next() {
        Some(c) if c.is_whitespace() => Some(chars.as_str().to_string()),
        _ => None,
    }
}

/// Where the parser is between lines.
enum TdmState {
    Header,
    Meta { opened: usize },
    AwaitData { closed: usize },
    Data { opened: usize },
    Between,
}

const SECTION_WORDS: [&str; 4] = ["META_START", "META_STOP", "DATA_START", "DATA_STOP"];

/// Parses a KVN TDM (version 1.x or 2.x): the header and every segment's metadata and
/// data records. Tolerated beyond the letter of the standard: blank lines and COMMENT
/// lines anywhere (outside a section they join the next segment's metadata), any
/// whitespace around keywords and `=`, metadata keywords in any order, CR/LF/CRLF line
/// ends. Checked: the header comes first with CREATION_DATE and ORIGINATOR; sections open
/// and close in order; metadata has TIME_SYSTEM and PARTICIPANT_1 and no keyword twice;
/// data lines are `KEYWORD = epoch value` with a CCSDS time and a finite number. Errors
/// name the line (counted from 1) and what is wrong there.
pub fn parse_tdm(text: &str) -> Result<Tdm, String> {
    let text = text
        .replace("\r\n", "\n")
        .replace("\n\r", "\n")
        .replace('\r', "\n");
    let mut tdm = Tdm {
        header: Vec::new(),
        segments: Vec::new(),
    };
    let mut state = TdmState::Header;
    let mut seg = TdmSegment {
        meta: Vec::new(),
        data_comments: Vec::new(),
        data: Vec::new(),
    };
    let mut pending_comments: Vec<(String, String)> = Vec::new();
    let mut last_line = 0;

    for (i, raw) in text.split('\n').enumerate() {
        let n = i + 1;
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        last_line = n;
        if let Some(c) = comment_text(line) {
            match state {
                TdmState::Header => tdm.header.push(("COMMENT".to_string(), c)),
                TdmState::Meta { .. } => seg.meta.push(("COMMENT".to_string(), c)),
                TdmState::AwaitData { .. } | TdmState::Data { .. } => seg.data_comments.push(c),
                TdmState::Between => pending_comments.push(("COMMENT".to_string(), c)),
            }
            continue;
        }
        match state {
            TdmState::Header => {
                let has_version = first_value(&tdm.header, "CCSDS_TDM_VERS").is_some();
                if line == "META_START" {
                    if !has_version {
                        return Err(format!(
                            "line {n}: META_START before CCSDS_TDM_VERS; this is not a TDM"
                        ));
                    }
                    for key in ["CREATION_DATE", "ORIGINATOR"] {
                        if first_value(&tdm.header, key).is_none() {
                            return Err(format!(
                                "line {n}: META_START but the header has no {key}"
                            ));
                        }
                    }
                    state = TdmState::Meta { opened: n };
                    continue;
                }
                if SECTION_WORDS.contains(&line) {
                    return Err(format!("line {n}: {line} without META_START"));
                }
                let (k, v) = kvn_pair(line, n)?;
                if !has_version && k != "CCSDS_TDM_VERS" {
                    return Err(format!(
                        "line {n}: expected CCSDS_TDM_VERS first, found {k}; this is not a TDM"
                    ));
                }
                match k.as_str() {
                    "CCSDS_TDM_VERS" => {
                        let ok = v.split_once('.').is_some_and(|(a, b)| {
                            digits_value(a.as_bytes()).is_some()
                                && digits_value(b.as_bytes()).is_some()
                        });
                        if !ok {
                            return Err(format!(
                                "line {n}: CCSDS_TDM_VERS '{}' is not a version like 2.0",
                                v.escape_default()
                            ));
                        }
                    }
                    "CREATION_DATE" if !is_ccsds_time(&v) => {
                        return Err(format!(
                            "line {n}: CREATION_DATE '{}' is not a CCSDS time",
                            v.escape_default()
                        ));
                    }
                    "CREATION_DATE" | "ORIGINATOR" | "MESSAGE_ID" => {}
                    _ => {
                        return Err(format!(
                            "line {n}: {k} is not a TDM header keyword (CCSDS_TDM_VERS, \
                             CREATION_DATE, ORIGINATOR, MESSAGE_ID, COMMENT); missing META_START?"
                        ));
                    }
                }
                if first_value(&tdm.header, &k).is_some() {
                    return Err(format!("line {n}: {k} appears twice in the header"));
                }
                tdm.header.push((k, v));
            }
            TdmState::Meta { opened } => {
                if line == "META_STOP" {
                    for key in ["TIME_SYSTEM", "PARTICIPANT_1"] {
                        if seg.meta_value(key).is_none() {
                            return Err(format!(
                                "line {n}: the metadata section opened at line {opened} has no {key}"
                            ));
                        }
                    }
                    state = TdmState::AwaitData { closed: n };
                    continue;
                }
                if SECTION_WORDS.contains(&line) {
                    return Err(format!(
                        "line {n}: {line} inside the metadata section opened at line {opened} \
                         (missing META_STOP?)"
                    ));
                }
                let (k, v) = kvn_pair(line, n)?;
                if seg.meta_value(&k).is_some() {
                    return Err(format!(
                        "line {n}: {k} appears twice in the metadata section opened at line {opened}"
                    ));
                }
                if (k == "START_TIME" || k == "STOP_TIME") && !is_ccsds_time(&v) {
                    return Err(format!(
                        "line {n}: {k} '{}' is not a CCSDS time",
                        v.escape_default()
                    ));
                }
                seg.meta.push((k, v));
            }
            TdmState::AwaitData { closed } => {
                if line != "DATA_START" {
                    return Err(format!(
                        "line {n}: expected DATA_START after META_STOP (line {closed}), found '{}'",
                        line.escape_default()
                    ));
                }
                state = TdmState::Data { opened: n };
            }
            TdmState::Data { opened } => {
                if line == "DATA_STOP" {
                    tdm.segments.push(std::mem::replace(
                        &mut seg,
                        TdmSegment {
                            meta: Vec::new(),
                            data_comments: Vec::new(),
                            data: Vec::new(),
                        },
                    ));
                    state = TdmState::Between;
                    continue;
                }
                if SECTION_WORDS.contains(&line) {
                    return Err(format!(
                        "line {n}: {line} inside the data section opened at line {opened} \
                         (missing DATA_STOP?)"
                    ));
                }
                seg.data.push(data_record(line, n)?);
            }
            TdmState::Between => {
                if line != "META_START" {
                    return Err(format!(
                        "line {n}: expected META_START or the end after DATA_STOP, found '{}'",
                        line.escape_default()
                    ));
                }
                seg.meta.append(&mut pending_comments);
                state = TdmState::Meta { opened: n };
            }
        }
    }

    match state {
        TdmState::Header => {
            if first_value(&tdm.header, "CCSDS_TDM_VERS").is_none() {
                return Err("no CCSDS_TDM_VERS line: the input is empty or not a TDM".to_string());
            }
            for key in ["CREATION_DATE", "ORIGINATOR"] {
                if first_value(&tdm.header, key).is_none() {
                    return Err(format!(
                        "line {last_line}: the input ends; the header has no {key}"
                    ));
                }
            }
        }
        TdmState::Meta { opened } => {
            return Err(format!(
                "line {last_line}: the input ends inside the metadata section opened at line \
                 {opened} (missing META_STOP)"
            ));
        }
        TdmState::AwaitData { closed } => {
            return Err(format!(
                "line {last_line}: the input ends after META_STOP (line {closed}) without a data section"
            ));
        }
        TdmState::Data { opened } => {
            return Err(format!(
                "line {last_line}: the input ends inside the data section opened at line \
                 {opened} (missing DATA_STOP)"
            ));
        }
        TdmState::Between => {}
    }
    Ok(tdm)
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
    /// at most 9 characters, may be empty. The parser trims trailing blanks.
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

/// The value of an MX field; NaN when blank.
fn mx_decode(field: &str, cols: &str, what: &str) -> Result<f64, String> {
    if field.trim().is_empty() {
        return Ok(f64::NAN);
    }
    match field.as_bytes() {
        [m, x] if m.is_ascii_digit() && x.is_ascii_digit() => {
            Ok(f64::from(m - b'0') * 10f64.powi(i32::from(x - b'0') - 8))
        }
        _ => Err(format!(
            "columns {cols}: {what} '{field}' is not MX (two digits, M·10^(X−8)) or blank"
        )),
    }
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

/// Does this text look like IOD lines (each starts with a 5-digit object number and a blank,
/// at most 80 columns)? Used before replacing a file: only one gpustar could have written.
pub fn iod_like(text: &str) -> bool {
    text.lines().filter(|l| !l.is_empty()).all(|l| {
        let b = l.as_bytes();
        b.len() <= 80 && b.len() > 6 && b[..5].iter().all(u8::is_ascii_digit) && b[5] == b' '
    })
}

/// The IOD line of `o`: angle format 2, epoch code 5 (J2000), magnitude and flash
/// columns blank, right-trimmed (no trailing blanks: 66 characters with a behaviour
/// code, 61-64 without), as stvid writes it. Errors name the field that cannot be written:
/// NORAD > 99999, station > 9999, a designation over 9 characters or not ASCII, a bad
/// time, Dec outside [-90, 90], an uncertainty that is negative or above the format's
/// largest code (90 s; 90′).
pub fn iod_line(o: &IodObs) -> Result<String, String> {
    if o.norad > 99_999 {
        return Err(format!(
            "NORAD number {} does not fit IOD's 5 digits",
            o.norad
        ));
    }
    if o.station > 9999 {
        return Err(format!("station {} does not fit IOD's 4 digits", o.station));
    }
    if o.intl_des.len() > 9
        || !o
            .intl_des
            .bytes()
            .all(|c| c == b' ' || c.is_ascii_graphic())
    {
        return Err(format!(
            "international designation '{}' must be at most 9 ASCII characters (YY NNNPPP)",
            o.intl_des.escape_default()
        ));
    }
    let status = check_code(o.status, "station status")?;
    let behaviour = check_code(o.behaviour, "optical behaviour code")?;
    let t = parse_utc(&o.time_utc)?;
    if !o.ra_deg.is_finite() {
        return Err(format!("RA {} is not a number", o.ra_deg));
    }
    if !(-90.0..=90.0).contains(&o.dec_deg) {
        return Err(format!("Dec {} is not in [-90, 90]", o.dec_deg));
    }
    let time_mx = if o.time_unc_s.is_nan() {
        "  ".to_string()
    } else {
        mx_encode(o.time_unc_s).ok_or_else(|| {
            format!(
                "time uncertainty {} s is not in [0, 90], the range of IOD's MX code",
                o.time_unc_s
            )
        })?
    };
    let pos_mx = if o.pos_unc_deg.is_nan() {
        "  ".to_string()
    } else {
        mx_encode(o.pos_unc_deg * 60.0).ok_or_else(|| {
            format!(
                "position uncertainty {}° is not in [0, 1.5°] (90′, IOD's largest MX code in format 2)",
                o.pos_unc_deg
            )
        })?
    };
    let line = format!(
        "{:05} {:<9} {:04} {} {:04}{:02}{:02}{:02}{:02}{:02}{:03} {} 25 {}{} {} {}",
        o.norad,
        o.intl_des,
        o.station,
        status,
        t.year,
        t.month,
        t.day,
        t.hour,
        t.minute,
        t.second,
        t.milli,
        time_mx,
        ra_hhmmmmm(o.ra_deg),
        dec_sddmmmm(o.dec_deg),
        pos_mx,
        behaviour
    );
    Ok(line.trim_end().to_string())
}

/// Digits left-aligned in a fixed field, trailing blanks standing for zeros (IOD lets
/// observers truncate a field to their precision). At least `min` digits; a blank
/// followed by a digit, or any other character, gives `None`.
fn truncated_digits(field: &str, min: usize) -> Option<Vec<u32>> {
    let b = field.as_bytes();
    let n = b.iter().take_while(|c| c.is_ascii_digit()).count();
    if n < min || !b[n..].iter().all(|&c| c == b' ') {
        return None;
    }
    Some(
        b.iter()
            .map(|&c| if c == b' ' { 0 } else { u32::from(c - b'0') })
            .collect(),
    )
}

fn number(d: &[u32]) -> u32 {
    d.iter().fold(0, |acc, &x| acc * 10 + x)
}

/// RA and Dec (degrees) from the angle columns in RA/Dec format 1, 2, 3 or 7, with
/// trailing truncation allowed.
fn iod_radec(format: u8, ra: &str, sign: char, dec: &str) -> Result<(f64, f64), String> {
    let r = truncated_digits(ra, 2).ok_or_else(|| {
        format!(
            "columns 48-54: RA '{ra}' must be 7 digits (trailing ones may be blank, for \
             lower precision)"
        )
    })?;
    let negative = match sign {
        '+' => false,
        '-' => true,
        _ => {
            return Err(format!(
                "column 55: declination sign '{sign}' must be '+' or '-'"
            ));
        }
    };
    let d = truncated_digits(dec, 2).ok_or_else(|| {
        format!(
            "columns 56-61: Dec '{dec}' must be 6 digits (trailing ones may be blank, for \
             lower precision)"
        )
    })?;
    let (hh, rm) = (number(&r[0..2]), number(&r[2..4]));
    if hh > 23 || rm > 59 {
        return Err(format!(
            "columns 48-54: RA '{ra}' has {hh} h {rm} min (hours 0-23, minutes 0-59)"
        ));
    }
    let ra_min = match format {
        1 | 7 => {
            let ss = number(&r[4..6]);
            if ss > 59 {
                return Err(format!(
                    "columns 48-54: RA '{ra}' has {ss} s (0-59) in format {format} (HHMMSSs)"
                ));
            }
            f64::from(rm) + (f64::from(ss) + f64::from(r[6]) / 10.0) / 60.0
        }
        _ => f64::from(rm) + f64::from(number(&r[4..7])) / 1000.0,
    };
    let dd = number(&d[0..2]);
    let dec_abs = match format {
        3 | 7 => f64::from(dd) + f64::from(number(&d[2..6])) / 10_000.0,
        _ => {
            let dm = number(&d[2..4]);
            if dm > 59 {
                return Err(format!(
                    "columns 56-61: Dec '{dec}' has {dm}′ (arcminutes 0-59)"
                ));
            }
            let fine = if format == 1 {
                let ds = number(&d[4..6]);
                if ds > 59 {
                    return Err(format!(
                        "columns 56-61: Dec '{dec}' has {ds}″ (arcseconds 0-59) in format 1"
                    ));
                }
                f64::from(ds) / 60.0
            } else {
                f64::from(number(&d[4..6])) / 100.0
            };
            f64::from(dd) + (f64::from(dm) + fine) / 60.0
        }
    };
    if dec_abs > 90.0 {
        return Err(format!("columns 55-61: Dec {sign}{dec} is beyond 90°"));
    }
    let ra_deg = (f64::from(hh) + ra_min / 60.0) * 15.0;
    Ok((ra_deg, if negative { -dec_abs } else { dec_abs }))
}

/// Parses one IOD line, padded to 80 columns or right-trimmed (trailing blanks, CR/LF
/// ignored). Reads RA/Dec angle formats 1, 2, 3 and 7 with epoch code 5 (J2000) and
/// converts the position uncertainty to degrees by the format's unit; accepts fields
/// truncated with trailing blanks (time down to HH, angles down to HH and DD) as the
/// format allows. Columns 67-80 (magnitude, flash period) are not read. Refused, with
/// the columns named: non-ASCII or over-long lines, misaligned fields (a separator
/// column not blank), Az/El formats 4-6, epochs other than J2000, out-of-range values.
pub fn parse_iod_line(line: &str) -> Result<IodObs, String> {
    let line = line.trim_end();
    if !line.is_ascii() {
        return Err("the line has non-ASCII characters; IOD columns are ASCII".to_string());
    }
    if line.len() > 80 {
        return Err(format!(
            "the line is {} characters long; IOD lines have 80 columns",
            line.len()
        ));
    }
    let p = format!("{line:<80}");
    let cols = |first: usize, last: usize| &p[first - 1..last];
    let col = |c: usize| char::from(p.as_bytes()[c - 1]);

    for c in [6, 16, 21, 23, 41, 44, 47, 62, 65] {
        if col(c) != ' ' {
            return Err(format!(
                "column {c} is '{}' but must be blank; the fields are misaligned (check \
                 widths: NORAD 5, designation 9, station 4)",
                col(c)
            ));
        }
    }
    let norad = digits_value(cols(1, 5).as_bytes()).ok_or_else(|| {
        format!(
            "columns 1-5: NORAD number '{}' is not 5 digits (99999 or 00000 when unknown)",
            cols(1, 5)
        )
    })?;
    let intl_des = cols(7, 15).trim_end().to_string();
    let station = digits_value(cols(17, 20).as_bytes())
        .ok_or_else(|| format!("columns 17-20: station '{}' is not 4 digits", cols(17, 20)))?
        .try_into()
        .map_err(|_| "columns 17-20: station out of range".to_string())?;
    let status = col(22);

    let date = cols(24, 31);
    let time = cols(32, 40);
    let date_ok = digits_value(date.as_bytes()).is_some();
    let t = truncated_digits(time, 2);
    let (Some(t), true) = (t, date_ok) else {
        return Err(format!(
            "columns 24-40: '{date}{time}' is not a UTC date YYYYMMDD and time HHMMSSsss \
             (the time may be truncated, down to HH)"
        ));
    };
    let day = digits_value(date.as_bytes()).unwrap_or(0);
    let utc = Utc {
        year: day / 10_000,
        month: day / 100 % 100,
        day: day % 100,
        hour: number(&t[0..2]),
        minute: number(&t[2..4]),
        second: number(&t[4..6]),
        milli: number(&t[6..9]),
    }
    .checked()
    .map_err(|e| format!("columns 24-40: '{date}{time}': {e}"))?;
    let time_unc_s = mx_decode(cols(42, 43), "42-43", "time uncertainty")?;

    let format = match col(45) {
        c @ ('1' | '2' | '3' | '7') => c as u8 - b'0',
        c @ ('4' | '5' | '6') => {
            return Err(format!(
                "column 45: angle format {c} is azimuth/elevation; only the RA/Dec formats \
                 1, 2, 3 and 7 are read"
            ));
        }
        ' ' => {
            return Err(
                "column 45: no angle format, so no position (a report without angles)".to_string(),
            );
        }
        c => return Err(format!("column 45: angle format '{c}' is not 1-7")),
    };
    if col(46) != '5' {
        return Err(format!(
            "column 46: epoch code '{}' is not 5 (J2000); other equinoxes would need \
             precession, which this reader does not do",
            col(46)
        ));
    }
    let (ra_deg, dec_deg) = iod_radec(format, cols(48, 54), col(55), cols(56, 61))?;
    let unit_deg = match format {
        1 => 1.0 / 3600.0,
        2 => 1.0 / 60.0,
        _ => 1.0,
    };
    let pos_unc_deg = mx_decode(cols(63, 64), "63-64", "position uncertainty")? * unit_deg;

    Ok(IodObs {
        norad,
        intl_des,
        station,
        status,
        time_utc: utc.iso(),
        time_unc_s,
        ra_deg,
        dec_deg,
        pos_unc_deg,
        behaviour: col(66),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    // ---------------------------------------------------------------- time

    #[test]
    fn utc_parses_normalises_and_carries() {
        let iso = |s: &str| parse_utc(s).map(|t| t.iso());
        assert_eq!(
            iso("2026-04-15T07:37:12.322").unwrap(),
            "2026-04-15T07:37:12.322"
        );
        assert_eq!(
            iso("2026-04-15T07:37:12").unwrap(),
            "2026-04-15T07:37:12.000"
        );
        assert_eq!(
            iso("2026-04-15T07:37:12.3Z").unwrap(),
            "2026-04-15T07:37:12.300"
        );
        assert_eq!(
            iso("2026-04-15T07:37:12.32249").unwrap(),
            "2026-04-15T07:37:12.322"
        );
        assert_eq!(
            iso("2026-04-15T07:37:12.3225").unwrap(),
            "2026-04-15T07:37:12.323"
        );
        // The carry runs through the calendar, including a leap day and the year.
        assert_eq!(
            iso("2024-02-28T23:59:59.9996").unwrap(),
            "2024-02-29T00:00:00.000"
        );
        assert_eq!(
            iso("2023-12-31T23:59:59.99951").unwrap(),
            "2024-01-01T00:00:00.000"
        );
        // An explicit leap second is kept.
        assert_eq!(
            iso("2016-12-31T23:59:60.500").unwrap(),
            "2016-12-31T23:59:60.500"
        );
        for bad in [
            "",
            "2026-04-15 07:37:12",
            "2026-13-15T07:37:12",
            "2023-02-29T07:37:12",
            "2026-04-15T24:00:00",
            "2026-04-15T07:60:00",
            "2026-04-15T07:37:60",
            "2026-04-15T07:37:12.",
            "2026-04-15T07:37:12,5",
            "2026-04-15T07:37:1x",
            "2026-04-15T07:37:12.5ZZ",
            "２026-04-15T07:37:12",
        ] {
            let e = parse_utc(bad).unwrap_err();
            assert!(e.contains("time"), "{bad:?}: {e}");
        }
    }

    // ---------------------------------------------------------------- TDM

    fn obs(t: &str, ra: f64, dec: f64, azel: Option<(f64, f64)>) -> AngleObs {
        AngleObs {
            time_utc: t.to_string(),
            ra_deg: ra,
            dec_deg: dec,
            az_deg: azel.map(|a| a.0),
            el_deg: azel.map(|a| a.1),
        }
    }

    fn sample_tracks() -> Vec<Track> {
        vec![
            Track {
                object: "frame_0001".to_string(),
                station: "GPUSTAR".to_string(),
                // Out of order on purpose: the writer sorts by time.
                observations: vec![
                    obs(
                        "2026-04-15T07:37:42.322",
                        15.123456789,
                        -0.0000000004,
                        Some((359.9999999999, 45.5)),
                    ),
                    obs(
                        "2026-04-15T07:37:12.322",
                        359.9999999996,
                        -89.987654321,
                        Some((120.25, -0.5)),
                    ),
                ],
            },
            Track {
                object: "UNKNOWN".to_string(),
                station: "4353".to_string(),
                observations: vec![
                    obs("2026-04-15T07:38:00.000", -10.5, 45.0, Some((10.0, 20.0))),
                    obs("2026-04-15T07:38:30.5", 720.25, 89.999999999, None),
                ],
            },
        ]
    }

    fn write(tracks: &[Track]) -> String {
        let mut out = Vec::new();
        write_tdm(&mut out, "2026-04-16T10:00:00.000", "GPUSTAR", tracks).unwrap();
        String::from_utf8(out).unwrap()
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9
    }

    /// The angle `expected` as the TDM holds it, wrapped into [0, 360).
    fn close_360(a: f64, expected: f64) -> bool {
        let d = (a - expected.rem_euclid(360.0)).rem_euclid(360.0);
        d.min(360.0 - d) <= 1e-9
    }

    #[test]
    fn tdm_round_trip() {
        let tracks = sample_tracks();
        let text = write(&tracks);
        let tdm = parse_tdm(&text).unwrap();
        assert_eq!(tdm.header_value("CCSDS_TDM_VERS"), Some("2.0"));
        assert_eq!(
            tdm.header_value("CREATION_DATE"),
            Some("2026-04-16T10:00:00.000")
        );
        assert_eq!(tdm.header_value("ORIGINATOR"), Some("GPUSTAR"));
        // Track 1: RADEC + AZEL; track 2: RADEC only (one observation lacks az/el).
        assert_eq!(tdm.segments.len(), 3);
        let types: Vec<_> = tdm
            .segments
            .iter()
            .map(|s| s.meta_value("ANGLE_TYPE"))
            .collect();
        assert_eq!(types, [Some("RADEC"), Some("AZEL"), Some("RADEC")]);

        let expect = [(&tracks[0], false), (&tracks[0], true), (&tracks[1], false)];
        for (seg, (track, azel)) in tdm.segments.iter().zip(expect) {
            let m = |k| seg.meta_value(k);
            assert_eq!(m("TIME_SYSTEM"), Some("UTC"));
            assert_eq!(m("PARTICIPANT_1"), Some(track.station.as_str()));
            assert_eq!(m("PARTICIPANT_2"), Some(track.object.as_str()));
            assert_eq!(m("MODE"), Some("SEQUENTIAL"));
            assert_eq!(m("PATH"), Some("2,1"));
            assert_eq!(m("REFERENCE_FRAME"), if azel { None } else { Some("ICRF") });
            assert!(seg.meta.iter().any(|(k, _)| k == "COMMENT"));

            let mut want: Vec<_> = track
                .observations
                .iter()
                .map(|o| (parse_utc(&o.time_utc).unwrap().iso(), o))
                .collect();
            want.sort_by(|a, b| a.0.cmp(&b.0));
            assert_eq!(m("START_TIME"), Some(want[0].0.as_str()));
            assert_eq!(m("STOP_TIME"), Some(want[want.len() - 1].0.as_str()));
            let a1 = seg.values("ANGLE_1");
            let a2 = seg.values("ANGLE_2");
            assert_eq!(a1.len(), want.len());
            assert_eq!(a2.len(), want.len());
            for ((t, o), ((t1, v1), (t2, v2))) in want.iter().zip(a1.iter().zip(&a2)) {
                assert_eq!(*t1, t.as_str());
                assert_eq!(*t2, t.as_str());
                assert!((0.0..360.0).contains(v1), "{v1}");
                let (e1, e2) = if azel {
                    (o.az_deg.unwrap(), o.el_deg.unwrap())
                } else {
                    (o.ra_deg, o.dec_deg)
                };
                assert!(close_360(*v1, e1), "{v1} vs {e1}");
                assert!(close(*v2, e2), "{v2} vs {e2}");
            }
        }
        // The writer's fixed forms: RA rounding to 360 wraps to 0, no "-0".
        assert!(text.contains("ANGLE_1 = 2026-04-15T07:37:12.322 0.000000000\n"));
        assert!(text.contains("ANGLE_2 = 2026-04-15T07:37:42.322 0.000000000\n"));
        assert!(text.contains("ANGLE_1 = 2026-04-15T07:38:30.500 0.250000000\n"));
        assert!(text.contains("ANGLE_1 = 2026-04-15T07:38:00.000 349.500000000\n"));
        assert!(!text.contains("-0.000000000"));
        assert!(text.lines().all(|l| l.len() <= 254 && l.is_ascii()));
    }

    #[test]
    fn tdm_without_tracks_is_a_header() {
        let text = write(&[]);
        let tdm = parse_tdm(&text).unwrap();
        assert!(tdm.segments.is_empty());
        assert_eq!(tdm.header_value("ORIGINATOR"), Some("GPUSTAR"));
        assert_eq!(tdm.header_value("COMMENT"), Some("No streak observations."));
    }

    #[test]
    fn tdm_writer_refuses_bad_input_and_writes_nothing() {
        let good = sample_tracks();
        let cases: Vec<(Vec<Track>, &str)> = vec![
            (
                {
                    let mut t = good.clone();
                    t[0].observations.clear();
                    t
                },
                "no observations",
            ),
            (
                {
                    let mut t = good.clone();
                    t[1].observations[0].time_utc = "2026-04-15 07:38".to_string();
                    t
                },
                "track 2 (object 'UNKNOWN'), observation 1: time",
            ),
            (
                {
                    let mut t = good.clone();
                    t[0].observations[1].dec_deg = 90.5;
                    t
                },
                "Dec 90.5",
            ),
            (
                {
                    let mut t = good.clone();
                    t[0].observations[1].ra_deg = f64::NAN;
                    t
                },
                "RA NaN",
            ),
            (
                {
                    let mut t = good.clone();
                    t[0].observations[0].el_deg = Some(f64::NAN);
                    t
                },
                "elevation",
            ),
            (
                {
                    let mut t = good.clone();
                    t[1].observations[1].time_utc = "2026-04-15T07:38:00.0001".to_string();
                    t
                },
                "two observations at 2026-04-15T07:38:00.000",
            ),
            (
                {
                    let mut t = good.clone();
                    t[0].object = "a\nMETA_STOP".to_string();
                    t
                },
                "object",
            ),
            (
                {
                    let mut t = good.clone();
                    t[0].station = "  ".to_string();
                    t
                },
                "station is empty",
            ),
        ];
        for (tracks, needle) in cases {
            let mut out = Vec::new();
            let e = write_tdm(&mut out, "2026-04-16T10:00:00", "GPUSTAR", &tracks).unwrap_err();
            assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
            assert!(e.to_string().contains(needle), "{e} lacks {needle:?}");
            assert!(out.is_empty());
        }
        let mut out = Vec::new();
        assert!(write_tdm(&mut out, "yesterday", "GPUSTAR", &good).is_err());
        assert!(write_tdm(&mut out, "2026-04-16T10:00:00", "", &good).is_err());
        assert!(out.is_empty());
    }

    /// Hand-written in the style of the optical examples of CCSDS 503.0-B-2 Annex E
    /// (values invented), with the liberties the parser allows: comments, blank lines,
    /// indentation, uneven spacing, metadata out of table order, CRLF line ends, a
    /// day-of-year epoch form and a MAG data type.
    const ANNEX_E_STYLE: &str = "\
CCSDS_TDM_VERS = 2.0
COMMENT Optical observations of two uncatalogued GEO objects.
COMMENT All angles are free of aberration effects.
CREATION_DATE = 2021-03-15T06:00:00
ORIGINATOR = TESTOBS

META_START
   COMMENT first object
   TIME_SYSTEM    =    UTC
   PARTICIPANT_2 = TRACK NUMBER 001
   PARTICIPANT_1 = TESTOBS-T1
   START_TIME = 2021-03-14T21:10:05.10
   STOP_TIME = 2021-03-14T21:14:19.10
   MODE = SEQUENTIAL
   PATH = 2,1
   REFERENCE_FRAME = EME2000
   ANGLE_TYPE = RADEC
META_STOP

DATA_START
COMMENT three frames, 127 s apart
ANGLE_1 = 2021-03-14T21:10:05.10   41.2265417
ANGLE_2 = 2021-03-14T21:10:05.10   -3.4018222
MAG     = 2021-03-14T21:10:05.10   12.7
ANGLE_1=2021-03-14T21:12:12.10 41.7459583
ANGLE_2=2021-03-14T21:12:12.10 -3.2864306
MAG=2021-03-14T21:12:12.10 12.9
\tANGLE_1 = 2021-03-14T21:14:19.10 42.2655000
\tANGLE_2 = 2021-03-14T21:14:19.10 -3.1699139
\tMAG = 2021-03-14T21:14:19.10 13.0
DATA_STOP

META_START
TIME_SYSTEM = UTC
START_TIME = 2021-073T21:30:00Z
STOP_TIME = 2021-073T21:30:00Z
PARTICIPANT_1 = TESTOBS-T1
PARTICIPANT_2 = TRACK NUMBER 002
MODE = SEQUENTIAL
PATH = 2,1
ANGLE_TYPE = RADEC
REFERENCE_FRAME = EME2000
META_STOP
DATA_START
ANGLE_1 = 2021-073T21:30:00Z 300.0000001
ANGLE_2 = 2021-073T21:30:00Z +1.5E-01
DATA_STOP
";

    #[test]
    fn tdm_parses_annex_e_style_example() {
        let text = ANNEX_E_STYLE.replace('\n', "\r\n");
        let tdm = parse_tdm(&text).unwrap();
        assert_eq!(tdm.header_value("ORIGINATOR"), Some("TESTOBS"));
        let comments: Vec<_> = tdm.header.iter().filter(|(k, _)| k == "COMMENT").collect();
        assert_eq!(comments.len(), 2);
        assert_eq!(comments[1].1, "All angles are free of aberration effects.");
        assert_eq!(tdm.segments.len(), 2);

        let s = &tdm.segments[0];
        assert_eq!(
            s.meta[0],
            ("COMMENT".to_string(), "first object".to_string())
        );
        assert_eq!(s.meta_value("TIME_SYSTEM"), Some("UTC"));
        assert_eq!(s.meta_value("PARTICIPANT_2"), Some("TRACK NUMBER 001"));
        assert_eq!(s.meta_value("REFERENCE_FRAME"), Some("EME2000"));
        assert_eq!(s.data_comments, ["three frames, 127 s apart"]);
        assert_eq!(s.data.len(), 9);
        let ra = s.values("ANGLE_1");
        let dec = s.values("ANGLE_2");
        let mag = s.values("MAG");
        assert_eq!(ra[1], ("2021-03-14T21:12:12.10", 41.7459583));
        assert_eq!(dec[2], ("2021-03-14T21:14:19.10", -3.1699139));
        assert_eq!(
            mag.iter().map(|m| m.1).collect::<Vec<_>>(),
            [12.7, 12.9, 13.0]
        );

        let s = &tdm.segments[1];
        assert_eq!(s.meta_value("START_TIME"), Some("2021-073T21:30:00Z"));
        assert_eq!(s.values("ANGLE_1"), [("2021-073T21:30:00Z", 300.0000001)]);
        assert_eq!(s.values("ANGLE_2"), [("2021-073T21:30:00Z", 0.15)]);
    }

    #[test]
    fn tdm_parse_errors_name_the_line() {
        let good = ANNEX_E_STYLE;
        // (edit of the good text, expected words in the message)
        let cases: Vec<(String, &str)> = vec![
            (String::new(), "no CCSDS_TDM_VERS"),
            (good.replace("CCSDS_TDM_VERS", "CCSDS_OEM_VERS"), "line 1: expected CCSDS_TDM_VERS"),
            (good.replace("ORIGINATOR = TESTOBS\n", ""), "has no ORIGINATOR"),
            (good.replacen("   TIME_SYSTEM    =    UTC\n", "", 1), "line 17: the metadata section opened at line 7 has no TIME_SYSTEM"),
            (good.replacen("META_STOP\n", "", 1), "line 19: DATA_START inside the metadata section opened at line 7"),
            (good.replacen("DATA_STOP\n", "", 1), "line 32: META_START inside the data section opened at line 20"),
            (good.replacen("   41.2265417", " 41.22x65417", 1), "line 22: ANGLE_1 value '41.22x65417' is not a finite number"),
            (good.replacen("   41.2265417", " NaN", 1), "line 22: ANGLE_1 value 'NaN'"),
            (good.replacen("2021-03-14T21:10:05.10   41", "41", 1), "line 22: ANGLE_1 needs 'epoch value'"),
            (good.replacen("2021-03-14T21:10:05.10   41", "2021-03-14T25:10:05.10 41", 1), "line 22: ANGLE_1 epoch"),
            (good.replacen("ANGLE_2 = 2021-03-14T21:10:05.10   -3.4018222", "ANGLE_2 = 2021-03-14T21:10:05.10 -3.4 7", 1), "line 23: ANGLE_2 has '7' after its value"),
            (good.replacen("   MODE = SEQUENTIAL", "   mode = SEQUENTIAL", 1), "line 14: keyword 'mode' must be upper-case"),
            (good.replacen("   MODE = SEQUENTIAL", "   PATH = 1,2", 1), "line 15: PATH appears twice"),
            (good.replacen("   MODE = SEQUENTIAL", "   MODE =", 1), "line 14: MODE has an empty value"),
            (good.replacen("   MODE = SEQUENTIAL", "   MODE SEQUENTIAL", 1), "line 14: expected 'KEYWORD = value'"),
            (good.replacen("DATA_START\nCOMMENT three", "ANGLE_1 = 2021-03-14T21:10:05.10 1\nCOMMENT three", 1), "line 20: expected DATA_START after META_STOP (line 18)"),
            (good.replacen("\nMETA_START\nTIME_SYSTEM", "\nANGLE_1 = 2021-03-14T21:10:05.10 1\nTIME_SYSTEM", 1), "line 33: expected META_START or the end after DATA_STOP"),
            (good.replacen("ORIGINATOR = TESTOBS", "ORIGINATOR = TESTOBS\nPARTICIPANT_1 = X", 1), "line 6: PARTICIPANT_1 is not a TDM header keyword"),
            (good.replacen("CREATION_DATE = 2021-03-15T06:00:00", "CREATION_DATE = 15/03/2021", 1), "line 4: CREATION_DATE"),
            (good.replacen("   START_TIME = 2021-03-14T21:10:05.10", "   START_TIME = soon", 1), "line 12: START_TIME 'soon'"),
            (good.strip_suffix("DATA_STOP\n").unwrap().to_string(), "missing DATA_STOP"),
            (good.split("\nDATA_START\nANGLE_1 = 2021-073").next().unwrap().to_string(), "without a data section"),
            ("CCSDS_TDM_VERS = 2.0\nCREATION_DATE = 2021-03-15T06:00:00\nORIGINATOR = X\nMETA_START\nTIME_SYSTEM = UTC\n".to_string(), "line 5: the input ends inside the metadata section opened at line 4"),
            ("CCSDS_TDM_VERS = two\n".to_string(), "line 1: CCSDS_TDM_VERS 'two'"),
            ("DATA_STOP\n".to_string(), "line 1: DATA_STOP without META_START"),
        ];
        for (text, needle) in cases {
            let e = parse_tdm(&text).unwrap_err();
            assert!(e.contains(needle), "{e:?} lacks {needle:?}");
        }
    }

    // ---------------------------------------------------------------- IOD

    const EXAMPLE: &str =
        "25544 98 067A   4353 F 20160720013132250 17 25 1918175+113996 56 S-030 10";

    fn close_to(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn iod_columns_of_the_satobs_example() {
        let o = parse_iod_line(EXAMPLE).unwrap();
        assert_eq!(o.norad, 25544);
        assert_eq!(o.intl_des, "98 067A");
        assert_eq!(o.station, 4353);
        assert_eq!(o.status, 'F');
        assert_eq!(o.time_utc, "2016-07-20T01:31:32.250");
        assert!(close_to(o.time_unc_s, 0.1, 1e-15));
        // RA 19h18.175m, Dec +11°39.96′.
        assert!(close_to(o.ra_deg, (19.0 + 18.175 / 60.0) * 15.0, 1e-12));
        assert!(close_to(o.dec_deg, 11.0 + 39.96 / 60.0, 1e-12));
        // "56" in format 2 is 5e-2 arcmin.
        assert!(close_to(o.pos_unc_deg, 0.05 / 60.0, 1e-15));
        assert_eq!(o.behaviour, 'S');
        // Written back: identical up to column 66 (magnitude columns are not carried).
        let line = iod_line(&o).unwrap();
        assert_eq!(line, EXAMPLE[..66]);
        // Padded to 80 columns, or with CRLF, it reads the same.
        assert_eq!(parse_iod_line(&format!("{EXAMPLE:<80}")).unwrap(), o);
        assert_eq!(parse_iod_line(&format!("{EXAMPLE}\r\n")).unwrap(), o);
    }

    #[test]
    fn iod_writes_what_stvid_writes() {
        // stvid: "%05d %-9s %04d G %s 17 25 %s 37 S"
        let stvid = format!(
            "{:05} {:<9} {:04} G {} 17 25 {} 37 S",
            1328, "65 034C", 4171, "20240102030405678", "0512345-012345"
        );
        let o = IodObs {
            norad: 1328,
            intl_des: "65 034C".to_string(),
            station: 4171,
            status: 'G',
            time_utc: "2024-01-02T03:04:05.678".to_string(),
            time_unc_s: 0.1,
            ra_deg: (5.0 + 12.345 / 60.0) * 15.0,
            dec_deg: -(1.0 + 23.45 / 60.0),
            pos_unc_deg: 0.3 / 60.0,
            behaviour: 'S',
        };
        assert_eq!(iod_line(&o).unwrap(), stvid);
        let back = parse_iod_line(&stvid).unwrap();
        assert_eq!(back.time_utc, o.time_utc);
        assert!(close_to(back.ra_deg, o.ra_deg, 1e-12));
        assert!(close_to(back.dec_deg, o.dec_deg, 1e-12));
        assert!(close_to(back.pos_unc_deg, o.pos_unc_deg, 1e-15));
        assert!(close_to(back.time_unc_s, 0.1, 1e-15));
        // The column layout stvid's format implies.
        assert_eq!(&stvid[44..46], "25");
        assert_eq!(&stvid[47..61], "0512345-012345");
        assert_eq!(&stvid[62..64], "37");
        assert_eq!(stvid.len(), 66);
    }

    fn sample_obs(ra: f64, dec: f64) -> IodObs {
        IodObs {
            norad: 99999,
            intl_des: String::new(),
            station: 9999,
            status: ' ',
            time_utc: "2026-04-15T07:37:12.322".to_string(),
            time_unc_s: f64::NAN,
            ra_deg: ra,
            dec_deg: dec,
            pos_unc_deg: f64::NAN,
            behaviour: ' ',
        }
    }

    fn angles(ra: f64, dec: f64) -> String {
        iod_line(&sample_obs(ra, dec)).unwrap()[47..61].to_string()
    }

    #[test]
    fn iod_round_trip_within_resolution() {
        // A fixed pseudo-random sequence (64-bit LCG): reproducible without a crate.
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let ra_tol = 0.0005 / 60.0 * 15.0 + 1e-12; // half of 0.001 min of time
        let dec_tol = 0.005 / 60.0 + 1e-12; // half of 0.01 arcmin
        for i in 0..5000 {
            let o = IodObs {
                norad: (next() * 99_999.0) as u32,
                intl_des: format!("{:02} {:03}A", i % 100, i % 1000),
                station: (next() * 9999.0) as u16,
                status: ['E', 'G', 'F', 'P', 'B', 'T', ' '][i % 7],
                time_utc: format!(
                    "20{:02}-{:02}-{:02}T{:02}:{:02}:{:02}.{:03}",
                    i % 100,
                    1 + i % 12,
                    1 + i % 28,
                    i % 24,
                    (i * 7) % 60,
                    (i * 13) % 60,
                    (i * 37) % 1000
                ),
                time_unc_s: 1e-3 + next() * 10.0,
                ra_deg: next() * 360.0,
                dec_deg: next() * 180.0 - 90.0,
                pos_unc_deg: next() * 1.5,
                behaviour: ['S', 'I', ' '][i % 3],
            };
            let line = iod_line(&o).unwrap();
            assert!(line.len() <= 80 && line == line.trim_end(), "{line:?}");
            let b = parse_iod_line(&line).unwrap();
            assert_eq!(b.norad, o.norad);
            assert_eq!(b.intl_des, o.intl_des);
            assert_eq!(b.station, o.station);
            assert_eq!(b.status, o.status);
            assert_eq!(b.time_utc, o.time_utc);
            assert_eq!(b.behaviour, o.behaviour);
            let dra = (b.ra_deg - o.ra_deg).rem_euclid(360.0);
            assert!(
                dra.min(360.0 - dra) <= ra_tol,
                "{line}: RA {} vs {}",
                b.ra_deg,
                o.ra_deg
            );
            assert!(close_to(b.dec_deg, o.dec_deg, dec_tol), "{line}: Dec");
            // MX never understates, and is within one step of M.
            assert!(b.time_unc_s >= o.time_unc_s * (1.0 - 1e-9));
            assert!(b.time_unc_s <= o.time_unc_s * 2.0 + 1e-12);
            assert!(b.pos_unc_deg >= o.pos_unc_deg * (1.0 - 1e-9));
            assert!(b.pos_unc_deg <= o.pos_unc_deg * 2.0 + 1e-12);
            // What was read writes the same line again.
            assert_eq!(iod_line(&b).unwrap(), line);
        }
    }

    #[test]
    fn iod_rounding_carries_and_signs() {
        let ra = |h: f64, m: f64| (h + m / 60.0) * 15.0;
        let dec = |d: f64, m: f64| d + m / 60.0;
        assert_eq!(angles(ra(19.0, 18.175), dec(11.0, 39.96)), "1918175+113996");
        // 59.9995 min and above rounds into the next hour; 24h wraps to 0.
        assert_eq!(angles(ra(5.0, 59.99951), 0.0), "0600000+000000");
        assert_eq!(angles(ra(5.0, 59.99949), 0.0), "0559999+000000");
        assert_eq!(angles(ra(23.0, 59.9996), 0.0), "0000000+000000");
        assert_eq!(angles(360.0, 0.0), "0000000+000000");
        assert_eq!(angles(-15.0, 0.0), "2300000+000000");
        assert_eq!(angles(375.0, 0.0), "0100000+000000");
        // Dec minutes 59.995 and above round into the next degree.
        assert_eq!(angles(0.0, dec(11.0, 59.996)), "0000000+120000");
        assert_eq!(angles(0.0, -dec(11.0, 59.996)), "0000000-120000");
        assert_eq!(angles(0.0, dec(89.0, 59.999)), "0000000+900000");
        assert_eq!(angles(0.0, -90.0), "0000000-900000");
        // Between 0 and -1 degree the sign stays.
        assert_eq!(angles(0.0, -0.5), "0000000-003000");
        assert_eq!(angles(0.0, -0.01), "0000000-000060");
        assert_eq!(angles(0.0, -0.0001), "0000000-000001");
        // Only a value that rounds to zero loses it.
        assert_eq!(angles(0.0, -0.00001), "0000000+000000");
        assert_eq!(angles(0.0, -0.0), "0000000+000000");
        for (s, want) in [("-003000", -0.5), ("-000060", -0.01), ("+000000", 0.0)] {
            let mut line = iod_line(&sample_obs(0.0, 0.0)).unwrap();
            line.replace_range(54..61, s);
            assert!(close_to(
                parse_iod_line(&line).unwrap().dec_deg,
                want,
                1e-12
            ));
        }
    }

    #[test]
    fn iod_mx_codes() {
        assert_eq!(mx_encode(0.1).as_deref(), Some("17"));
        assert_eq!(mx_encode(0.3).as_deref(), Some("37"));
        assert_eq!(mx_encode(0.05).as_deref(), Some("56"));
        assert_eq!(mx_encode(0.31).as_deref(), Some("47"));
        assert_eq!(mx_encode(1.0).as_deref(), Some("18"));
        assert_eq!(mx_encode(1.0001).as_deref(), Some("28"));
        assert_eq!(mx_encode(9.5).as_deref(), Some("19"));
        assert_eq!(mx_encode(0.0).as_deref(), Some("10"));
        assert_eq!(mx_encode(90.0).as_deref(), Some("99"));
        assert_eq!(mx_encode(90.1), None);
        assert_eq!(mx_encode(-0.1), None);
        // Every code decodes to a value that encodes back to it.
        for x in 0..=9 {
            for m in 1..=9 {
                let code = format!("{m}{x}");
                let v = mx_decode(&code, "", "").unwrap();
                assert_eq!(mx_encode(v), Some(code));
            }
        }
        let mut o = sample_obs(0.0, 0.0);
        o.time_unc_s = 100.0;
        assert!(iod_line(&o).unwrap_err().contains("time uncertainty"));
        o.time_unc_s = 0.1;
        o.pos_unc_deg = 2.0;
        assert!(iod_line(&o).unwrap_err().contains("position uncertainty"));
        o.pos_unc_deg = f64::NAN;
        o.time_unc_s = f64::NAN;
        // Blank uncertainties and codes trim the line after the angles.
        assert_eq!(iod_line(&o).unwrap().len(), 61);
    }

    #[test]
    fn iod_reads_other_formats_and_truncated_fields() {
        // From the examples of the IOD description (epoch changed to 5 where needed).
        let o = parse_iod_line(
            "12345 98 123A   2007 P 200811221122334   27 35 11223  +112    27 S+070 10",
        )
        .unwrap();
        assert_eq!(o.time_utc, "2008-11-22T11:22:33.400");
        assert!(close_to(o.time_unc_s, 0.2, 1e-15));
        assert!(close_to(o.ra_deg, (11.0 + 22.3 / 60.0) * 15.0, 1e-12));
        assert!(close_to(o.dec_deg, 11.2, 1e-12)); // format 3: DD.dddd
        assert!(close_to(o.pos_unc_deg, 0.2, 1e-15)); // format 3: degrees

        let o = parse_iod_line(
            "12345 98 123A   2007 F 2008112211223344  56 25 1122   +1122   28 R+05  1",
        )
        .unwrap();
        assert_eq!(o.time_utc, "2008-11-22T11:22:33.440");
        assert!(close_to(o.ra_deg, (11.0 + 22.0 / 60.0) * 15.0, 1e-12));
        assert!(close_to(o.dec_deg, 11.0 + 22.0 / 60.0, 1e-12));
        assert!(close_to(o.pos_unc_deg, 2.0 / 60.0, 1e-15));
        assert_eq!(o.behaviour, 'R');

        // Format 1 (HHMMSSs+DDMMSS, arcsec) and 7 (HHMMSSs+DDdddd, degrees).
        let o = parse_iod_line(
            "23794 96 010A   2701 G 20040506012614270 17 15 0047196-603829 38 I+020 10",
        )
        .unwrap();
        assert!(close_to(
            o.ra_deg,
            (0.0 + 47.0 / 60.0 + 19.6 / 3600.0) * 15.0,
            1e-12
        ));
        assert!(close_to(
            o.dec_deg,
            -(60.0 + 38.0 / 60.0 + 29.0 / 3600.0),
            1e-12
        ));
        assert!(close_to(o.pos_unc_deg, 3e0 / 3600.0, 1e-15));
        let o = parse_iod_line("23794 96 010A   2701 G 20040506012614270 17 75 2047449+293762 38")
            .unwrap();
        assert!(close_to(
            o.ra_deg,
            (20.0 + 47.0 / 60.0 + 44.9 / 3600.0) * 15.0,
            1e-12
        ));
        assert!(close_to(o.dec_deg, 29.3762, 1e-12));
        assert!(close_to(o.pos_unc_deg, 3.0, 1e-15));

        // Time truncated to hours; angles truncated to HH and DD; no uncertainties.
        let mut l = format!("{:<80}", "12345 98 123A   2007 E 2008112211");
        l.replace_range(44..46, "25");
        l.replace_range(47..49, "18");
        l.replace_range(54..57, "-08");
        let o = parse_iod_line(&l).unwrap();
        assert_eq!(o.time_utc, "2008-11-22T11:00:00.000");
        assert!(o.time_unc_s.is_nan() && o.pos_unc_deg.is_nan());
        assert!(close_to(o.ra_deg, 18.0 * 15.0, 1e-12));
        assert!(close_to(o.dec_deg, -8.0, 1e-12));
        assert_eq!(o.status, 'E');
        assert_eq!(o.behaviour, ' ');
    }

    #[test]
    fn iod_parse_errors_say_where() {
        let good = EXAMPLE;
        let edit = |at: usize, s: &str| {
            let mut l = good.to_string();
            l.replace_range(at..at + s.len(), s);
            l
        };
        let cases: Vec<(String, &str)> = vec![
            (edit(0, "2554x"), "columns 1-5"),
            (format!(" {good}"), "column 6"),
            (edit(15, "X"), "column 16"),
            (edit(16, "43a3"), "columns 17-20"),
            (edit(23, "20161320"), "month 13"),
            (edit(23, "20160230"), "day 30"),
            (edit(31, "2513"), "hour 25"),
            (edit(31, "01 1"), "columns 24-40"),
            (edit(31, "         "), "columns 24-40"),
            (edit(41, "1x"), "columns 42-43"),
            (edit(44, "5"), "azimuth/elevation"),
            (edit(44, " "), "no angle format"),
            (edit(44, "8"), "angle format '8'"),
            (edit(45, "4"), "epoch code '4'"),
            (edit(47, "2518175"), "columns 48-54"),
            (edit(47, "1960175"), "columns 48-54"),
            (edit(47, "19 8175"), "columns 48-54"),
            (edit(47, " 918175"), "columns 48-54"),
            (edit(54, " "), "column 55"),
            (edit(55, "116996"), "columns 56-61"),
            (edit(54, "+910000"), "beyond 90"),
            (edit(62, "5x"), "columns 63-64"),
            (format!("{good:<80}x"), "80 columns"),
            (good.replacen('S', "§", 1), "non-ASCII"),
            (String::new(), "column"),
        ];
        for (line, needle) in cases {
            let e = parse_iod_line(&line).unwrap_err();
            assert!(e.contains(needle), "{line:?}: {e:?} lacks {needle:?}");
        }
    }

    #[test]
    fn iod_writer_refuses_what_does_not_fit() {
        let base = sample_obs(10.0, 10.0);
        let cases: Vec<(IodObs, &str)> = vec![
            (
                IodObs {
                    norad: 100_000,
                    ..base.clone()
                },
                "NORAD",
            ),
            (
                IodObs {
                    station: 10_000,
                    ..base.clone()
                },
                "station",
            ),
            (
                IodObs {
                    intl_des: "98 067ABCD".to_string(),
                    ..base.clone()
                },
                "designation",
            ),
            (
                IodObs {
                    intl_des: "98\t067A".to_string(),
                    ..base.clone()
                },
                "designation",
            ),
            (
                IodObs {
                    status: 'É',
                    ..base.clone()
                },
                "station status",
            ),
            (
                IodObs {
                    behaviour: '\n',
                    ..base.clone()
                },
                "behaviour",
            ),
            (
                IodObs {
                    time_utc: "2026-04-15".to_string(),
                    ..base.clone()
                },
                "time",
            ),
            (
                IodObs {
                    dec_deg: -90.01,
                    ..base.clone()
                },
                "Dec",
            ),
            (
                IodObs {
                    ra_deg: f64::INFINITY,
                    ..base.clone()
                },
                "RA",
            ),
            (
                IodObs {
                    time_unc_s: -1.0,
                    ..base.clone()
                },
                "time uncertainty",
            ),
        ];
        for (o, needle) in cases {
            let e = iod_line(&o).unwrap_err();
            assert!(e.contains(needle), "{e:?} lacks {needle:?}");
        }
    }

    #[test]
    fn parsers_never_panic_on_mangled_input() {
        let line = format!("{EXAMPLE:<80}");
        let replacements = [' ', '0', '9', '+', '-', 'x', '.', 'é'];
        for i in 0..line.len() {
            let _ = parse_iod_line(&line[..i]);
            for r in replacements {
                let mut l: String = line.chars().take(i).collect();
                l.push(r);
                l.extend(line.chars().skip(i + 1));
                let _ = parse_iod_line(&l);
            }
        }
        let tdm = ANNEX_E_STYLE;
        for (i, _) in tdm.char_indices() {
            let _ = parse_tdm(&tdm[..i]);
            let mut t = tdm.to_string();
            t.replace_range(i..i + 1, "=");
            let _ = parse_tdm(&t);
        }
    }
}
