//! Earth orientation (UT1-UTC, polar motion) from the bundled IERS table.

use super::{DAYSEC, DJM0, Utc, parse_number};
use sofars::cal::jd2cal;
use sofars::ts;
use std::sync::OnceLock;

/// Earth rotation, arcsec of hour angle per second of UT1.
pub(crate) const ROTATION_ARCSEC_PER_S: f64 = 15.041;

/// One row of the Earth orientation table, at 0h UTC of its day.
#[derive(Clone, Copy, Debug)]
pub(crate) struct EopRow {
    /// TAI of the row as an MJD: the interpolation variable, continuous across leap seconds.
    pub(crate) tai_mjd: f64,
    /// UT1-TAI, seconds: smooth where UT1-UTC steps at leap seconds.
    pub(crate) ut1_tai: f64,
    /// UT1-UTC, seconds, as tabulated.
    pub(crate) dut1: f64,
    /// Polar motion, arcsec.
    pub(crate) xp: f64,
    pub(crate) yp: f64,
    /// The UTC MJD as tabulated.
    pub(crate) mjd: f64,
}

/// The bundled table (scripts/make_eop.py): IERS C04 every 5 days, then IERS-A (observed and predicted).
pub(crate) const EOP_CSV: &str =
    include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/catalog/eop.csv"));

/// Parses `mjd,ut1_minus_utc_s,xp_arcsec,yp_arcsec` rows ('#' comments, one header line).
pub(crate) fn parse_eop(text: &str) -> Result<Vec<EopRow>, String> {
    let mut rows: Vec<EopRow> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') || line.starts_with("mjd") {
            continue;
        }
        let bad = || format!("eop.csv line {}: '{line}'", n + 1);
        let v: Vec<f64> = line
            .split(',')
            .map(parse_number)
            .collect::<Option<_>>()
            .ok_or_else(bad)?;
        let [mjd, dut1, xp, yp] = v[..] else {
            return Err(bad());
        };
        let (y, m, d, _) = jd2cal(DJM0, mjd).map_err(|_| bad())?;
        let dat = ts::dat(y, m, d, 0.0).map_err(|_| bad())?;
        let row = EopRow {
            tai_mjd: mjd + dat / DAYSEC,
            ut1_tai: dut1 - dat,
            dut1,
            xp,
            yp,
            mjd,
        };
        if rows.last().is_some_and(|last| last.tai_mjd >= row.tai_mjd) {
            return Err(format!("{}: dates out of order", bad()));
        }
        rows.push(row);
    }
    if rows.len() < 2 {
        return Err("eop.csv has fewer than two rows".to_string());
    }
    Ok(rows)
}

/// The parsed table, once.
pub(crate) fn eop_table() -> &'static Result<Vec<EopRow>, String> {
    static TABLE: OnceLock<Result<Vec<EopRow>, String>> = OnceLock::new();
    TABLE.get_or_init(|| parse_eop(EOP_CSV))
}

/// Earth orientation at a UTC instant from the bundled table: (UT1-UTC seconds, xp, yp radians),
/// and a warning when the date is outside the table. Linear in UT1-TAI over TAI between rows,
/// then UT1-UTC with TAI-UTC at 0h of the instant's UTC day, as SOFA's utcut1 expects.
/// Outside the table: the nearest end's values.
pub fn earth_orientation(t: &Utc) -> (f64, f64, f64, Option<String>) {
    let table = match eop_table() {
        Ok(rows) => rows,
        Err(e) => {
            return (
                0.0,
                0.0,
                0.0,
                Some(format!("no Earth orientation ({e}): UT1-UTC taken as 0")),
            );
        }
    };
    let arcsec = |a: f64| a.to_radians() / 3600.0;
    let Some(((tai1, tai2), (y, m, d))) = t.tai().zip(t.day()) else {
        return (
            0.0,
            0.0,
            0.0,
            Some(format!(
                "no Earth orientation for {}: UT1-UTC taken as 0",
                t.iso()
            )),
        );
    };
    let tai_mjd = (tai1 - DJM0) + tai2;
    let (first, last) = (table[0], table[table.len() - 1]);
    let outside = |row: EopRow, days: f64, side: &str| {
        let warning = format!(
            "{} is {days:.1} days {side} the bundled Earth orientation table ({}); its values \
             are used (UT1-UTC {:+.4} s). UT1-UTC drifts by at most about 3 ms a day ({:.2} arcsec \
             of Earth rotation) and stays below 0.9 s ({:.1} arcsec), so that bounds the error; \
             newer IERS values can be passed in instead",
            t.iso(),
            mjd_date(row.mjd),
            row.dut1,
            0.003 * ROTATION_ARCSEC_PER_S,
            0.9 * ROTATION_ARCSEC_PER_S,
        );
        (row.dut1, arcsec(row.xp), arcsec(row.yp), Some(warning))
    };
    if tai_mjd < first.tai_mjd {
        return outside(first, first.tai_mjd - tai_mjd, "before the start of");
    }
    if tai_mjd > last.tai_mjd {
        return outside(last, tai_mjd - last.tai_mjd, "after the end of");
    }
    let i = table
        .partition_point(|r| r.tai_mjd <= tai_mjd)
        .clamp(1, table.len() - 1);
    let (a, b) = (table[i - 1], table[i]);
    let w = (tai_mjd - a.tai_mjd) / (b.tai_mjd - a.tai_mjd);
    let lerp = |p: f64, q: f64| p + w * (q - p);
    let dat = ts::dat(y, m, d, 0.0).unwrap_or(a.dut1 - a.ut1_tai);
    (
        lerp(a.ut1_tai, b.ut1_tai) + dat,
        arcsec(lerp(a.xp, b.xp)),
        arcsec(lerp(a.yp, b.yp)),
        None,
    )
}

/// "YYYY-MM-DD" of a UTC MJD.
pub(crate) fn mjd_date(mjd: f64) -> String {
    match jd2cal(DJM0, mjd) {
        Ok((y, m, d, _)) => format!("{y:04}-{m:02}-{d:02}"),
        Err(_) => format!("MJD {mjd}"),
    }
}
