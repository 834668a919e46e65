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
