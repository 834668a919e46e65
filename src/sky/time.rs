//! The one time type, [`Utc`] (SOFA's two-part Julian date, leap seconds included), the one
//! ISO 8601 parser ([`parse_iso`]), time scales, and the plausibility rule for times read
//! from files ([`plausible_mjd`]).

use sofars::cal::{cal2jd, jd2cal};
use sofars::ts;

/// MJD zero point (JD 2400000.5).
pub(crate) const DJM0: f64 = 2_400_000.5;
pub(crate) const DAYSEC: f64 = 86_400.0;
/// TAI - GPS time, seconds (fixed since 1980).
pub(crate) const TAI_MINUS_GPS_S: f64 = 19.0;

/// A UTC instant as SOFA's two-part quasi Julian date (jd1 + jd2), leap seconds handled as SOFA
/// does: jd1 is 0h of the UTC day and jd2 the fraction of that day, whose length may be 86401 s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Utc {
    pub jd1: f64,
    pub jd2: f64,
}

impl Utc {
    /// A UTC calendar instant; `sec` may reach 60.999... only in a leap second. Via SOFA dtf2d.
    pub fn from_calendar(y: i32, mo: i32, d: i32, h: i32, mi: i32, sec: f64) -> crate::Result<Utc> {
        let (jd1, jd2) = calendar_jd("UTC", y, mo, d, h, mi, sec).map_err(crate::Error::Input)?;
        Ok(Utc { jd1, jd2 })
    }

    /// An ISO 8601 UTC time, "YYYY-MM-DDThh:mm:ss[.fff]" (a date alone is 0h).
    pub fn parse(s: &str) -> crate::Result<Utc> {
        let ((y, mo, d), hms) = parse_iso(s.trim())?;
        let (h, mi, sec) = hms.unwrap_or((0, 0, 0.0));
        Utc::from_calendar(y, mo, d, h, mi, sec)
    }

    /// "YYYY-MM-DDThh:mm:ss.sss", rounded to the millisecond (23:59:60.xxx in a leap second).
    pub fn iso(&self) -> String {
        match ts::d2dtf("UTC", 3, self.jd1, self.jd2) {
            Ok((y, mo, d, [h, mi, s, ms])) => {
                format!("{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{s:02}.{ms:03}")
            }
            Err(_) => format!("(invalid UTC, JD {} + {})", self.jd1, self.jd2),
        }
    }

    /// The calendar fields of [`Utc::iso`]: (year, month, day, [hour, minute, second,
    /// millisecond]), rounded to the millisecond by the same SOFA d2dtf call (second 60 in a
    /// leap second); `None` where SOFA cannot convert the date.
    pub fn calendar_ms(&self) -> Option<(i32, i32, i32, [i32; 4])> {
        ts::d2dtf("UTC", 3, self.jd1, self.jd2).ok()
    }

    /// The instant `s` SI seconds later (or earlier, when negative), counted through TAI so
    /// that a leap second in between is one second like any other.
    pub fn add_seconds(&self, s: f64) -> Utc {
        self.tai()
            .and_then(|(t1, t2)| utc_from_tai(t1, t2 + s / DAYSEC))
            .unwrap_or(Utc {
                jd1: self.jd1,
                jd2: self.jd2 + s / DAYSEC,
            })
    }

    /// SI seconds from `other` to `self` (positive when `self` is later), through TAI.
    pub fn seconds_since(&self, other: &Utc) -> f64 {
        match (self.tai(), other.tai()) {
            (Some(a), Some(b)) => ((a.0 - b.0) + (a.1 - b.1)) * DAYSEC,
            _ => ((self.jd1 - other.jd1) + (self.jd2 - other.jd2)) * DAYSEC,
        }
    }

    /// TAI as a two-part JD.
    pub(crate) fn tai(&self) -> Option<(f64, f64)> {
        ts::utctai(self.jd1, self.jd2).ok()
    }

    /// The UTC calendar day (year, month, day) that holds this instant.
    pub(crate) fn day(&self) -> Option<Ymd> {
        jd2cal(self.jd1, self.jd2)
            .ok()
            .map(|(y, m, d, _)| (y, m, d))
    }

    /// Quasi-MJD, for range checks only.
    pub(crate) fn mjd(&self) -> f64 {
        (self.jd1 - DJM0) + self.jd2
    }

    /// `Err` naming this time unless [`plausible_mjd`] holds: the guard before SOFA's ICRS <->
    /// observed chain (atco13, atoc13), whose Earth ephemeris (epv00) ends at
    /// 2100-01-01T12:00 TT, where sofars panics.
    pub(crate) fn plausible(&self) -> Result<(), String> {
        let mjd = self.mjd();
        if plausible_mjd(mjd) {
            Ok(())
        } else {
            Err(format!(
                "{} (MJD {mjd:.3}) is outside 1960-2100, the times gpustar reduces",
                self.iso()
            ))
        }
    }
}

/// UTC from a two-part TAI JD, with whole days moved into jd1 (keeps jd1 at 0h of the day).
pub(crate) fn utc_from_tai(tai1: f64, tai2: f64) -> Option<Utc> {
    let (jd1, jd2) = ts::taiutc(tai1, tai2).ok()?;
    let whole = jd2.floor();
    Some(Utc {
        jd1: jd1 + whole,
        jd2: jd2 - whole,
    })
}

/// Calendar date and time in a SOFA scale ("UTC", "TT", "TAI") to a two-part JD, with the
/// checks SOFA leaves as warnings: seconds >= 60 only in a UTC leap second.
pub(crate) fn calendar_jd(
    scale: &str,
    y: i32,
    mo: i32,
    d: i32,
    h: i32,
    mi: i32,
    sec: f64,
) -> Result<(f64, f64), String> {
    let what = || format!("{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{sec:06.3}");
    if !sec.is_finite() {
        return Err(format!("seconds are not a number ({sec})"));
    }
    let (jd1, jd2) = ts::dtf2d(scale, y, mo, d, h, mi, sec).map_err(|code| {
        let field = match code {
            -1 => "year",
            -2 => "month",
            -3 => "day",
            -4 => "hour",
            -5 => "minute",
            _ => "seconds",
        };
        format!("no such {scale} time {} (bad {field})", what())
    })?;
    // dtf2d scales the fraction by the day's length (86401 s on a leap-second day), so a
    // fraction below 1 after 23:59 means the seconds fall inside that day.
    let leap_ok = scale == "UTC" && h == 23 && mi == 59 && jd2 < 1.0;
    if (sec >= 60.0 && !leap_ok) || jd2 >= 1.0 {
        return Err(format!(
            "no such {scale} time {} (seconds out of range)",
            what()
        ));
    }
    Ok((jd1, jd2))
}

/// The time now, "YYYY-MM-DDThh:mm:ss.sss" UTC (from the system clock's Unix time, which
/// counts UTC days of 86400 s), for creation dates of output files.
pub fn now_utc_iso() -> String {
    let s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64());
    let days = (s / DAYSEC).floor();
    Utc {
        jd1: 2_440_587.5 + days,
        jd2: (s - days * DAYSEC) / DAYSEC,
    }
    .iso()
}

/// A time scale the header's times may be in (`TIMESYS`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Scale {
    Utc,
    Tt,
    Tai,
    Gps,
}

impl Scale {
    /// `TIMESYS`: UTC when absent; GMT is UTC (FITS 4.0 Table 30) and TDT, IAT are old names
    /// of TT and TAI.
    pub(crate) fn from_timesys(v: Option<&str>) -> Option<Scale> {
        match v.map(str::to_ascii_uppercase).as_deref() {
            None | Some("UTC" | "GMT") => Some(Scale::Utc),
            Some("TT" | "TDT") => Some(Scale::Tt),
            Some("TAI" | "IAT") => Some(Scale::Tai),
            Some("GPS") => Some(Scale::Gps),
            _ => None,
        }
    }

    /// The SOFA scale name for calendar conversion (GPS, like TAI, has uniform days).
    pub(crate) fn sofa(self) -> &'static str {
        match self {
            Scale::Utc => "UTC",
            Scale::Tt => "TT",
            Scale::Tai | Scale::Gps => "TAI",
        }
    }

    /// A two-part JD in this scale to UTC.
    pub(crate) fn to_utc(self, jd1: f64, jd2: f64) -> Option<Utc> {
        match self {
            Scale::Utc => Some(Utc { jd1, jd2 }),
            Scale::Tai => utc_from_tai(jd1, jd2),
            Scale::Gps => utc_from_tai(jd1, jd2 + TAI_MINUS_GPS_S / DAYSEC),
            Scale::Tt => ts::tttai(jd1, jd2)
                .ok()
                .and_then(|(a, b)| utc_from_tai(a, b)),
        }
    }

    /// A calendar date and time in this scale to UTC.
    pub(crate) fn calendar(self, date: Ymd, time: Hms) -> Result<Utc, String> {
        let (jd1, jd2) = calendar_jd(self.sofa(), date.0, date.1, date.2, time.0, time.1, time.2)?;
        self.to_utc(jd1, jd2)
            .ok_or_else(|| "cannot convert to UTC".to_string())
    }

    /// An MJD in this scale to UTC (in UTC, SOFA's quasi-JD convention on leap-second days).
    pub(crate) fn mjd(self, mjd: f64) -> Option<Utc> {
        let whole = mjd.floor();
        self.to_utc(DJM0 + whole, mjd - whole)
    }
}

/// A calendar date: year, month, day.
pub type Ymd = (i32, i32, i32);
/// A time of day: hour, minute, seconds.
pub type Hms = (i32, i32, f64);

/// "YYYY-MM-DD" with an optional "Thh:mm:ss[.fff]" (or a space for the T) and trailing 'Z': the
/// one ISO 8601 parser. Seconds are required: FITS writes them, and an exposure time to the
/// minute would put a streak's ends 30 s out.
pub fn parse_iso(s: &str) -> crate::Result<(Ymd, Option<Hms>)> {
    parse_iso_as(s, false).map_err(crate::Error::Input)
}

/// [`parse_iso`], with `minute_ok` also taking "Thh:mm" as the start of that minute (for the
/// epoch of proper motion, which a minute does not move).
fn parse_iso_as(s: &str, minute_ok: bool) -> Result<(Ymd, Option<Hms>), String> {
    let (date, time) = match s.find(['T', ' ']) {
        Some(i) => (&s[..i], Some(s[i + 1..].trim())),
        None => (s, None),
    };
    let fields: Vec<&str> = date.split(['-', '/', '.']).collect();
    let digits = |f: &str| !f.is_empty() && f.chars().all(|c| c.is_ascii_digit());
    if fields.len() == 3 && fields.iter().all(|f| digits(f) && f.len() <= 2) {
        return Err(
            "a two-digit year (old dd/mm/yy or yy/mm/dd form): the century and the field \
                    order are unknown; give the date as YYYY-MM-DD"
                .to_string(),
        );
    }
    if date.contains(':') {
        return Err("a time without a date".to_string());
    }
    let ok = date.is_ascii()
        && date.len() == 10
        && date.as_bytes()[4] == b'-'
        && date.as_bytes()[7] == b'-'
        && digits(&date[..4])
        && digits(&date[5..7])
        && digits(&date[8..]);
    if !ok {
        return Err("not a YYYY-MM-DD date".to_string());
    }
    let num = |f: &str| f.parse::<i32>().unwrap_or(0);
    let ymd = (num(&date[..4]), num(&date[5..7]), num(&date[8..]));
    match time {
        None => Ok((ymd, None)),
        Some(t) => Ok((
            ymd,
            Some(parse_hms(t.strip_suffix('Z').unwrap_or(t), minute_ok)?),
        )),
    }
}

/// "hh:mm:ss[.fff]" (two digits each), or with `minute_ok` also "hh:mm".
pub(crate) fn parse_hms(s: &str, minute_ok: bool) -> Result<Hms, String> {
    let bad = || format!("'{s}' is not a hh:mm:ss[.fff] time");
    let b = s.as_bytes();
    let two = |i: usize| {
        b.get(i..i + 2)
            .filter(|p| p.iter().all(u8::is_ascii_digit))
            .map(|p| i32::from(p[0] - b'0') * 10 + i32::from(p[1] - b'0'))
    };
    // "hh:mm" alone: the start of that minute.
    if let (true, 5, Some(h), Some(b':'), Some(m)) = (minute_ok, b.len(), two(0), b.get(2), two(3))
    {
        return Ok((h, m, 0.0));
    }
    let (Some(h), Some(m), Some(_)) = (two(0), two(3), two(6)) else {
        return Err(bad());
    };
    if b.get(2) != Some(&b':') || b.get(5) != Some(&b':') {
        return Err(bad());
    }
    let frac = &s[8..];
    let frac_ok = frac.is_empty()
        || (frac.len() > 1
            && frac.starts_with('.')
            && frac[1..].chars().all(|c| c.is_ascii_digit()));
    let sec: f64 = if frac_ok {
        s[6..].parse().map_err(|_| bad())?
    } else {
        return Err(bad());
    };
    Ok((h, m, sec))
}

/// Plausible observation dates, MJD: 1960-01-01 (UTC begins) to 2100-01-01.
const MJD_PLAUSIBLE: (f64, f64) = (36_934.0, 88_069.0);

/// The one plausibility rule for a time read from a file, whatever it is used for (the epoch
/// of proper motion, exposure times): within 1960..2100, which a JD written into an MJD
/// keyword, a year 9999 placeholder or a wrong century are not.
pub fn plausible_mjd(mjd: f64) -> bool {
    (MJD_PLAUSIBLE.0..MJD_PLAUSIBLE.1).contains(&mjd)
}

/// The instant of a Julian year (2000.0 is 2000-01-01T12:00:00), as "YYYY-MM-DDThh:mm:ss.sss"
/// ([`Utc::iso`]): what [`julian_year`] reads back to the same year within a millisecond. The
/// time scale is not told apart, as in [`julian_year`].
pub fn iso_of_julian_year(year: f64) -> String {
    Utc {
        jd1: 2_451_545.0,
        jd2: (year - 2000.0) * 365.25,
    }
    .iso()
}

/// The Julian year of an ISO 8601 date and time as [`parse_iso`] reads it ("2019-07-29T20:47:26.5",
/// "2019-07-29", a trailing `Z`); None for anything else, an impossible calendar date among them.
/// The time is taken as is (UTC, or whatever TIMESYS says: seconds do not matter at this
/// precision).
pub fn julian_year(date_obs: &str) -> Option<f64> {
    let s = date_obs.trim();
    let ((year, month, day), time) = parse_iso_as(s.strip_suffix('Z').unwrap_or(s), true).ok()?;
    // SOFA checks the calendar date; its MJD at 0h gives the Julian day number.
    let (djm0, djm) = cal2jd(year, month, day).ok()?;
    let jdn = (djm0 + djm + 0.5) as i64;
    let seconds_of_day = match time {
        None => 0.0,
        Some((hour, minute, second)) => {
            if hour > 23 || minute > 59 || second >= 61.0 {
                return None;
            }
            f64::from(hour * 3600 + minute * 60) + second
        }
    };
    // JD − 2451545.0 kept as an integer part plus a fraction, so J2000.0 comes out exact.
    let days = (jdn - 2_451_545) as f64 + (seconds_of_day - 43_200.0) / 86_400.0;
    Some(2000.0 + days / 365.25)
}
