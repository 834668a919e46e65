//! Header keyword values as FITS writes them, shared by the time, station and hint readers.

/// A header keyword's value, None when absent or blank.
pub(crate) fn value(get: &dyn Fn(&str) -> Option<String>, key: &str) -> Option<String> {
    get(key)
        .map(|v| v.trim().to_string())
        .filter(|v| !v.is_empty())
}

/// A FITS number ("30", "3.0E1", Fortran "3.0D1"); None unless finite.
pub(crate) fn parse_number(s: &str) -> Option<f64> {
    let v: f64 = s.trim().replace(['D', 'd'], "E").parse().ok()?;
    v.is_finite().then_some(v)
}
