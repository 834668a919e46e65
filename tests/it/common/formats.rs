//! Test-side TDM and IOD parsers that read back what gpustar's `streaks::formats` writes.

use gpustar::sky::Utc;
use gpustar::streaks::formats::IodObs;

/// The value of a run of 1-9 ASCII digits; `None` for anything else.
fn digits_value(b: &[u8]) -> Option<u32> {
    if b.is_empty() || b.len() > 9 || !b.iter().all(u8::is_ascii_digit) {
        return None;
    }
    Some(b.iter().fold(0, |acc, &d| acc * 10 + u32::from(d - b'0')))
}

// ------------------------------------------------------------------------------------
// CCSDS TDM (KVN)
// ------------------------------------------------------------------------------------

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

/// The value of an MX field (M·10^(X−8)); NaN when blank. `cols` and `what` name the field
/// in the error.
pub fn mx_decode(field: &str, cols: &str, what: &str) -> Result<f64, String> {
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
    let ymd = digits_value(date.as_bytes()).unwrap_or(0) as i32;
    let n = |d: &[u32]| number(d) as i32;
    let utc = Utc::from_calendar(
        ymd / 10_000,
        ymd / 100 % 100,
        ymd % 100,
        n(&t[0..2]),
        n(&t[2..4]),
        f64::from(number(&t[4..6])) + f64::from(number(&t[6..9])) / 1000.0,
    )
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

// ------------------------------------------------------------------------------------
// The readers orbit-determination users run, ported
// ------------------------------------------------------------------------------------

/// What sattools keeps of an IOD line: the fields `decode_iod_observation` reads.
#[derive(Debug, Clone, PartialEq)]
pub struct SattoolsObs {
    pub satno: u32,
    /// `%s %s` of columns 7 onward, joined (`24575A`).
    pub desig: String,
    pub site: u32,
    /// Time uncertainty, s (`p.st`).
    pub st: f64,
    /// Position uncertainty, degrees (`p.sr` after the format's unit).
    pub sr: f64,
    pub ra_deg: f64,
    pub dec_deg: f64,
}

/// C's `%1d` at `i`: skips white space, then one digit; the index after it.
fn c_1d(b: &[u8], mut i: usize) -> Option<(u32, usize)> {
    while i < b.len() && b[i].is_ascii_whitespace() {
        i += 1;
    }
    let d = *b.get(i)?;
    d.is_ascii_digit().then(|| (u32::from(d - b'0'), i + 1))
}

/// C's `%Nd`/`%Nlf` of digits at `i` (white space skipped first, at most `n` characters).
fn c_num(b: &[u8], mut i: usize, n: usize) -> Option<(f64, usize)> {
    while i < b.len() && b[i].is_ascii_whitespace() {
        i += 1;
    }
    let start = i;
    while i < b.len() && i - start < n && (b[i].is_ascii_digit() || b[i] == b'.') {
        i += 1;
    }
    let v = std::str::from_utf8(&b[start..i]).ok()?.parse().ok()?;
    Some((v, i))
}

/// A port of the column rules of sattools' IOD reader (cbassa/sattools, src/satfit.c,
/// `decode_iod_observation`, the same in residuals.c), for one line as `read_data` hands it
/// over (without its newline): `Err` says why sattools would drop or misread the line, where
/// the C sets `p.flag = 0` or reads a field from the wrong columns. Ported: the 64-character
/// minimum and the sign in column 55 (`strlen(iod_line)<64 || iod_line[54]!='+'...`); the
/// designation read by `sscanf(iod_line+6,"%s %s")` into 3 and 6 bytes (an empty one reads
/// the station; a longer one overflows); the station `%4d` looked up in the site list (9999
/// is none: `get_site` fails, flag 0); the time `%4d%2d%2d%2d%2d%5s`; the MX fields read with
/// `%1d%1d` at columns 42 and 63, which skip blanks, so a blank field takes digits from the
/// next columns (refused here rather than misread); format and epoch `%1d%1d` at column 45
/// (formats 1, 2, 3, 7; epochs 0, 4, 5); RA `%2lf%2lf%3lf` and Dec `%2lf%2lf%2s` with the
/// formats' units. Not ported: the precession to the date (epoch 5 read as J2000 here).
pub fn sattools_decode(line: &str) -> Result<SattoolsObs, String> {
    let b = line.as_bytes();
    if b.len() < 64 {
        return Err(format!("{} characters: strlen < 64, flag 0", b.len()));
    }
    if b[54] != b'+' && b[54] != b'-' {
        return Err("column 55 is not + or -: flag 0".into());
    }
    let satno = c_num(b, 0, 5).ok_or("no satno in columns 1-5")?.0 as u32;
    let mut words = line[6..].split_whitespace();
    let (w1, w2) = (words.next().unwrap_or(""), words.next().unwrap_or(""));
    if w1.len() > 2 || w2.len() > 5 {
        return Err(format!("designation '{w1} {w2}' overflows buf1[3]/buf2[6]"));
    }
    if w1.len() == 4 && w1.bytes().all(|c| c.is_ascii_digit()) {
        return Err("no designation: %s %s reads the station".into());
    }
    let site = c_num(b, 16, 4).ok_or("no station in columns 17-20")?.0 as u32;
    if site == 9999 {
        return Err("site 9999 is in no site list: flag 0".into());
    }
    for (i, n) in [(23, 4), (27, 2), (29, 2), (31, 2), (33, 2)] {
        if !b[i..i + n].iter().all(u8::is_ascii_digit) {
            return Err(format!("time columns {}-{} not digits", i + 1, i + n));
        }
    }
    let fixed = |i: usize, what: &str| -> Result<(u32, u32), String> {
        if !(b[i].is_ascii_digit() && b[i + 1].is_ascii_digit()) {
            return Err(format!(
                "{what} (columns {}-{}) not two digits: %1d%1d reads other columns",
                i + 1,
                i + 2
            ));
        }
        let (m, j) = c_1d(b, i).ok_or(what.to_string())?;
        Ok((m, c_1d(b, j).ok_or(what.to_string())?.0))
    };
    let (me, xe) = fixed(41, "time uncertainty")?;
    let st = f64::from(me) * 10f64.powi(xe as i32 - 8);
    let (format, epoch) = fixed(44, "format and epoch")?;
    let (mr, xr) = fixed(62, "position uncertainty")?;
    let mut sr = f64::from(mr) * 10f64.powi(xr as i32 - 8);
    let (h, i) = c_num(b, 47, 2).ok_or("RA hours")?;
    let (mm, i) = c_num(b, i, 2).ok_or("RA minutes")?;
    let (ss, _) = c_num(b, i, 3).ok_or("RA fraction")?;
    let (d, i) = c_num(b, 55, 2).ok_or("Dec degrees")?;
    let (dd, i) = c_num(b, i, 2).ok_or("Dec minutes")?;
    let ds_text: String = line[i..]
        .trim_start()
        .chars()
        .take(2)
        .take_while(|c| !c.is_whitespace())
        .collect();
    let mut ds: f64 = ds_text.parse().unwrap_or(0.0);
    if ds_text.len() == 1 {
        ds *= 10.0;
    }
    let sign = if b[54] == b'-' { -1.0 } else { 1.0 };
    let (ra_h, dec) = match format {
        1 => {
            sr /= 3600.0;
            (
                h + mm / 60.0 + ss / 36000.0,
                sign * (d + dd / 60.0 + ds / 3600.0),
            )
        }
        2 => {
            sr /= 60.0;
            (
                h + mm / 60.0 + ss / 60000.0,
                sign * (d + dd / 60.0 + ds / 6000.0),
            )
        }
        3 => (
            h + mm / 60.0 + ss / 60000.0,
            sign * (d + dd / 100.0 + ds / 10000.0),
        ),
        7 => (
            h + mm / 60.0 + ss / 36000.0,
            sign * (d + dd / 100.0 + ds / 10000.0),
        ),
        f => return Err(format!("IOD format {f} not implemented: flag 0")),
    };
    if ![0, 4, 5].contains(&epoch) {
        return Err(format!("epoch {epoch} not implemented: flag 0"));
    }
    Ok(SattoolsObs {
        satno,
        desig: format!("{w1}{w2}"),
        site,
        st,
        sr,
        ra_deg: ra_h * 15.0,
        dec_deg: dec,
    })
}

/// A port of TruSat's `format_test_iod` (PyPI `trusat` 0.9.0, trusat/iod.py,
/// `new_iod_format_re`), the regex its `parse_iod_lines` admits lines with, written out as
/// the regex walks a line (`regex` has no look-around):
/// `^(\d{5}\s\d{2}\s\d{3}(?=[A-Z]+\s*)[\D\s]{3}(?<!\s\w)\s|\s{16})` `[0-9A-HJ-NP-Z]{4}\s`
/// `[EGFPBTCO ]\s` `[\d+]{8}` then either `\d*\s*$` or `(?=.{9})\d*\s*?\s\d{2}\s` and
/// `[1-7][\s0-6]\s(?=[\d\s*]{7})\d+\s*?[+-](?=[\d\s*]{6})\d+\s*?\s\d{2}` or 20 blanks; the
/// optional behaviour and magnitude groups after it never make a match fail (no `$`).
/// Where `\d*` and `\s*?` could split a run of digits and blanks more than one way, this takes
/// digits first, blanks after, which is the only split for fields of digits then blanks.
pub fn trusat_format_test(line: &str) -> bool {
    let b = line.as_bytes();
    let at = |i: usize| b.get(i).copied();
    let ws = |c: Option<u8>| c.is_some_and(|c| c.is_ascii_whitespace());
    let digit = |c: Option<u8>| c.is_some_and(|c| c.is_ascii_digit());
    let word = |c: Option<u8>| c.is_some_and(|c| c.is_ascii_alphanumeric() || c == b'_');
    // NORAD / designation group, or 16 blanks.
    let i = if (0..16).all(|k| ws(at(k))) {
        16
    } else {
        let ok = (0..5).all(|k| digit(at(k)))
            && ws(at(5))
            && digit(at(6))
            && digit(at(7))
            && ws(at(8))
            && (9..12).all(|k| digit(at(k)))
            && at(12).is_some_and(|c| c.is_ascii_uppercase())
            && (12..15).all(|k| at(k).is_some_and(|c| !c.is_ascii_digit()))
            && !(ws(at(13)) && word(at(14)))
            && ws(at(15));
        if !ok {
            return false;
        }
        16
    };
    let station = |c: Option<u8>| {
        c.is_some_and(|c| c.is_ascii_digit() || (c.is_ascii_uppercase() && c != b'I' && c != b'O'))
    };
    if !((i..i + 4).all(|k| station(at(k))) && ws(at(i + 4))) {
        return false;
    }
    let i = i + 5;
    if !(at(i).is_some_and(|c| b"EGFPBTCO ".contains(&c) || c.is_ascii_whitespace())
        && ws(at(i + 1)))
    {
        return false;
    }
    let i = i + 2;
    if !(i..i + 8).all(|k| at(k).is_some_and(|c| c.is_ascii_digit() || c == b'+')) {
        return false;
    }
    let mut i = i + 8;
    // `\d*\s*$`: the record ends after the time.
    let mut j = i;
    while digit(at(j)) {
        j += 1;
    }
    while ws(at(j)) {
        j += 1;
    }
    if j == b.len() {
        return true;
    }
    // `(?=.{9})\d*\s*?\s\d{2}\s`
    if b.len() < i + 9 {
        return false;
    }
    while digit(at(i)) {
        i += 1;
    }
    while ws(at(i)) && ws(at(i + 1)) {
        i += 1;
    }
    if !(ws(at(i)) && digit(at(i + 1)) && digit(at(i + 2)) && ws(at(i + 3))) {
        return false;
    }
    let i = i + 4;
    if (i..i + 20).all(|k| ws(at(k))) {
        return true;
    }
    if !(at(i).is_some_and(|c| (b'1'..=b'7').contains(&c))
        && at(i + 1).is_some_and(|c| c.is_ascii_whitespace() || (b'0'..=b'6').contains(&c))
        && ws(at(i + 2)))
    {
        return false;
    }
    let angle = |mut i: usize, n: usize, end: &dyn Fn(Option<u8>) -> bool| -> Option<usize> {
        // (?=[\d\s*]{n})\d+\s*? then the terminator
        if !(i..i + n).all(|k| {
            at(k).is_some_and(|c| c.is_ascii_digit() || c.is_ascii_whitespace() || c == b'*')
        }) {
            return None;
        }
        if !digit(at(i)) {
            return None;
        }
        while digit(at(i)) {
            i += 1;
        }
        while !end(at(i)) && ws(at(i)) {
            i += 1;
        }
        end(at(i)).then_some(i)
    };
    let Some(i) = angle(i + 3, 7, &|c| c == Some(b'+') || c == Some(b'-')) else {
        return false;
    };
    let Some(i) = angle(i + 1, 6, &ws) else {
        return false;
    };
    // `\s\d{2}` (the lazy `\s*?` leaves the last blank before the two digits)
    let mut i = i;
    while ws(at(i + 1)) {
        i += 1;
    }
    ws(at(i)) && digit(at(i + 1)) && digit(at(i + 2))
}
