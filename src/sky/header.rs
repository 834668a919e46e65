//! Exposure start and end from FITS header keywords, in any time scale TIMESYS names.

use super::keyword::{parse_number, value};
use super::{Hms, Scale, Utc, parse_hms, parse_iso, plausible_mjd};

/// Exposure start and end in UTC (shutter open and close: where a streak's ends are).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exposure {
    pub start: Utc,
    pub end: Utc,
}

impl Exposure {
    /// Length in SI seconds.
    pub fn duration_s(&self) -> f64 {
        self.end.seconds_since(&self.start)
    }

    /// Mid-exposure, the time of a streak's midpoint.
    pub fn mid(&self) -> Utc {
        self.start.add_seconds(0.5 * self.duration_s())
    }
}

/// Keywords that may hold the time of day when DATE-OBS is a date alone.
pub(crate) const TIME_KEYS: [&str; 4] = ["TIME-OBS", "UTSTART", "UT", "UTC"];
/// Keywords for the exposure length, seconds, in order of preference.
pub(crate) const LENGTH_KEYS: [&str; 3] = ["EXPTIME", "XPOSURE", "TELAPSE"];

/// The longest exposure taken as such (EXPTIME and the like): a day.
pub(crate) const MAX_EXPOSURE_S: f64 = 86_400.0;

/// Reads one instant from the header; warnings go to `warn`.
pub(crate) struct Reader<'a> {
    get: &'a dyn Fn(&str) -> Option<String>,
    scale: Scale,
    warn: Vec<String>,
}

impl Reader<'_> {
    /// A start or end instant from an ISO keyword (DATE-OBS may take its time from TIME_KEYS).
    fn date(&mut self, key: &str) -> Option<Utc> {
        let v = value(self.get, key)?;
        let (ymd, time) = match parse_iso(&v) {
            Ok(parsed) => parsed,
            Err(e) => {
                self.warn.push(format!("{key} = '{v}': {e}; not used"));
                return None;
            }
        };
        let (hms, source) = match time {
            Some(hms) => {
                if key == "DATE-OBS" {
                    self.compare_time_obs(&v, hms);
                }
                (hms, format!("{key} = '{v}'"))
            }
            None if key == "DATE-OBS" => self.time_of_day(&v)?,
            None => {
                self.warn
                    .push(format!("{key} = '{v}' has no time of day; not used"));
                return None;
            }
        };
        match self.scale.calendar(ymd, hms) {
            Ok(t) => self.plausible(key, &v, t),
            Err(e) => {
                self.warn.push(format!("{source}: {e}; not used"));
                None
            }
        }
    }

    /// The time of day for a DATE-OBS that is a date alone.
    fn time_of_day(&mut self, date: &str) -> Option<(Hms, String)> {
        for key in TIME_KEYS {
            let Some(v) = value(self.get, key) else {
                continue;
            };
            match parse_hms(v.strip_suffix('Z').unwrap_or(&v), false) {
                Ok(hms) => return Some((hms, format!("DATE-OBS = '{date}' + {key} = '{v}'"))),
                Err(e) => self.warn.push(format!("{key} = '{v}': {e}; not used")),
            }
        }
        self.warn.push(format!(
            "DATE-OBS = '{date}' is a date without a time of day, and no {} gives one; not used",
            TIME_KEYS.join("/")
        ));
        None
    }

    /// A TIME-OBS beside a full DATE-OBS that disagrees with it (some write it at the end).
    fn compare_time_obs(&mut self, date: &str, hms: Hms) {
        let Some(v) = value(self.get, "TIME-OBS") else {
            return;
        };
        let Ok((h, m, s)) = parse_hms(v.strip_suffix('Z').unwrap_or(&v), false) else {
            return;
        };
        let secs = |h: i32, m: i32, s: f64| f64::from(h * 3600 + m * 60) + s;
        let diff = secs(h, m, s) - secs(hms.0, hms.1, hms.2);
        if diff.abs() > 0.5 {
            self.warn.push(format!(
                "TIME-OBS = '{v}' differs from DATE-OBS = '{date}' by {diff:+.3} s; DATE-OBS used"
            ));
        }
    }

    /// An instant from an MJD keyword.
    fn mjd(&mut self, key: &str) -> Option<Utc> {
        let v = value(self.get, key)?;
        match parse_number(&v).and_then(|mjd| self.scale.mjd(mjd)) {
            Some(t) => self.plausible(key, &v, t),
            None => {
                self.warn
                    .push(format!("{key} = '{v}' is not a number; not used"));
                None
            }
        }
    }

    /// An exposure length in seconds from the first usable one of LENGTH_KEYS, and its key.
    fn length(&mut self) -> Option<(f64, &'static str)> {
        for key in LENGTH_KEYS {
            let Some(v) = value(self.get, key) else {
                continue;
            };
            match parse_number(&v) {
                Some(s) if s > 0.0 && s <= MAX_EXPOSURE_S => return Some((s, key)),
                Some(_) => self.warn.push(format!(
                    "{key} = '{v}' is not a plausible exposure length (more than 0 s, at most \
                     {MAX_EXPOSURE_S} s); not used"
                )),
                None => self
                    .warn
                    .push(format!("{key} = '{v}' is not a number (s); not used")),
            }
        }
        None
    }

    /// `t` unless it lies outside 1960..2100 (a JD in an MJD keyword, a wrong century).
    fn plausible(&mut self, key: &str, v: &str, t: Utc) -> Option<Utc> {
        let mjd = t.mjd();
        if plausible_mjd(mjd) {
            Some(t)
        } else {
            self.warn.push(format!(
                "{key} = '{v}' is outside 1960-2100 (MJD {mjd:.1}); not a plausible exposure time"
            ));
            None
        }
    }
}

/// Header keywords: `get(key)` returns the card's value with string quotes removed and trimmed,
/// or None. Returns the exposure (or None) and warnings a person can act on, each naming the
/// keyword and its value.
///
/// Start: DATE-BEG, else DATE-OBS (a date alone takes its time from TIME-OBS, UTSTART, UT or
/// UTC), else MJD-BEG, else MJD-OBS. End: DATE-END, else MJD-END, else the start plus EXPTIME,
/// XPOSURE or TELAPSE (seconds). The first usable keyword wins; an unusable one is warned
/// about and skipped. TIMESYS: UTC when absent, TT and TAI (and GPS = TAI - 19 s) converted,
/// anything else gives no exposure. A start alone is no exposure (the warning says so).
pub fn exposure_from_header(
    get: &dyn Fn(&str) -> Option<String>,
) -> (Option<Exposure>, Vec<String>) {
    let timesys = value(get, "TIMESYS");
    let Some(scale) = Scale::from_timesys(timesys.as_deref()) else {
        let v = timesys.unwrap_or_default();
        let warning = format!(
            "TIMESYS = '{v}' is not a supported time scale (UTC, TT, TAI, GPS); no exposure time"
        );
        return (None, vec![warning]);
    };
    let mut r = Reader {
        get,
        scale,
        warn: Vec::new(),
    };
    let start = [
        ("DATE-BEG", true),
        ("DATE-OBS", true),
        ("MJD-BEG", false),
        ("MJD-OBS", false),
    ]
    .into_iter()
    .find_map(|(key, iso)| {
        let t = if iso { r.date(key) } else { r.mjd(key) };
        t.map(|t| (t, key))
    });
    let Some((start, start_key)) = start else {
        if value(get, "DATE-OBS").is_none() {
            for key in TIME_KEYS {
                if let Some(v) = value(get, key) {
                    r.warn.push(format!(
                        "{key} = '{v}' is a time without a date (no DATE-OBS); not used"
                    ));
                }
            }
        }
        r.warn.push(
            "no exposure start: no usable DATE-BEG, DATE-OBS (+TIME-OBS), MJD-BEG or MJD-OBS"
                .to_string(),
        );
        return (None, r.warn);
    };
    let start_v = value(get, start_key).unwrap_or_default();
    let end = [("DATE-END", true), ("MJD-END", false)]
        .into_iter()
        .find_map(|(key, iso)| {
            let t = if iso { r.date(key) } else { r.mjd(key) };
            t.map(|t| (t, key))
        });
    if let Some((end, end_key)) = end {
        if end.seconds_since(&start) > 0.0 {
            return (Some(Exposure { start, end }), r.warn);
        }
        let end_v = value(get, end_key).unwrap_or_default();
        r.warn.push(format!(
            "{end_key} = '{end_v}' is not after {start_key} = '{start_v}'; no exposure time"
        ));
        return (None, r.warn);
    }
    match r.length() {
        Some((s, key)) => {
            let end = start.add_seconds(s);
            // A start within 1960-2100 may end past 2100, where SOFA's ephemeris ends.
            if end.plausible().is_err() {
                let v = value(get, key).unwrap_or_default();
                r.warn.push(format!(
                    "{start_key} = '{start_v}' + {key} = '{v}' ends at {}, outside 1960-2100 \
                     (the times gpustar reduces: SOFA's Earth ephemeris ends in 2100); no \
                     exposure time",
                    end.iso()
                ));
                return (None, r.warn);
            }
            (Some(Exposure { start, end }), r.warn)
        }
        None => {
            r.warn.push(format!(
                "{start_key} = '{start_v}' gives the start only: the exposure length is missing \
                 (no usable DATE-END, MJD-END, {}); no exposure time",
                LENGTH_KEYS.join(", ")
            ));
            (None, r.warn)
        }
    }
}
