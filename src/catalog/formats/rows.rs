//! The rows of an imported catalog, kept or counted out (out of range, repeated ids), and the
//! number fields they are read from.

use crate::catalog::{Star, StarId};
use crate::error::{Result, fail};
use std::collections::HashSet;
use std::f64::consts::FRAC_PI_2;

/// The largest proper motion a row may hold, each component (mas/yr): ten times the fastest
/// known star's, Barnard's (10 400).
pub const MAX_PM_MAS_YR: f64 = 100_000.0;

/// The epochs a row may hold (Julian years): any catalog made or to be made (Hipparcos
/// 1991.25, Gaia 2016.0, plate catalogs back to the 1890s).
pub const EPOCHS: std::ops::RangeInclusive<f64> = 1000.0..=3000.0;

/// The magnitudes a row may hold: the Sun is −26.7, the faintest catalogued objects near 30.
pub const MAGS: std::ops::RangeInclusive<f64> = -30.0..=40.0;

/// Why a star's values are not a star's, or None; a right ascension within one turn of
/// [0°, 360°) is wrapped into it (−180..180 and 360 for 0 are conventions some files use),
/// one beyond that is refused: no catalog writes it, and at 1e300 there are no digits left
/// of the angle to wrap.
pub fn out_of_range(s: &mut Star) -> Option<String> {
    let (ra, dec) = (s.ra_rad.to_degrees(), s.dec_rad.to_degrees());
    // Degrees as the file wrote them, not as radians and back (95.00000000000001).
    let shown = |deg: f64| {
        if deg.abs() < 1e6 {
            (deg * 1e9).round() / 1e9
        } else {
            deg
        }
    };
    if !(-360.0..720.0).contains(&ra) {
        return Some(format!(
            "RA {}° is not within one turn of 0..360",
            shown(ra)
        ));
    }
    // In radians, as stored: ±90° read from a file is exactly ±π/2 there.
    if !(-FRAC_PI_2..=FRAC_PI_2).contains(&s.dec_rad) {
        return Some(format!("Dec {}° is outside ±90", shown(dec)));
    }
    for (what, pm) in [("pmRA", s.pmra_mas_yr), ("pmDec", s.pmdec_mas_yr)] {
        if !(-MAX_PM_MAS_YR..=MAX_PM_MAS_YR).contains(&pm) {
            return Some(format!(
                "{what} {pm} mas/yr is beyond ±{MAX_PM_MAS_YR} (Barnard's star: 10 400)"
            ));
        }
    }
    if !EPOCHS.contains(&s.epoch) {
        return Some(format!(
            "epoch {} is outside {}..{}",
            s.epoch,
            EPOCHS.start(),
            EPOCHS.end()
        ));
    }
    if !MAGS.contains(&s.mag) {
        return Some(format!(
            "magnitude {} is outside {}..{}",
            s.mag,
            MAGS.start(),
            MAGS.end()
        ));
    }
    if !(0.0..std::f64::consts::TAU).contains(&s.ra_rad) {
        let w = s.ra_rad.rem_euclid(std::f64::consts::TAU);
        // rem_euclid of a tiny negative angle rounds up to a whole turn.
        s.ra_rad = if w < std::f64::consts::TAU { w } else { 0.0 };
    }
    None
}

/// Why rows are left out, as the warnings say.
pub(crate) const OUT_OF_RANGE: &str = "a value out of its physical range";

pub(crate) const REPEATED: &str = "repeating an earlier row's id, whose first row is kept";

/// Rows left out for one reason: how many, and the first (its line or record, and why).
#[derive(Default)]
pub(crate) struct Tally {
    pub count: usize,
    first: Option<(usize, String)>,
}

impl Tally {
    /// One warning naming the count and the first: "rows left out for `why`".
    pub(crate) fn warn(&self, source: &str, unit: &str, why: &str) {
        if let Some((at, what)) = &self.first {
            tracing::warn!(
                "{source}: {} rows left out for {why} (the first: {unit} {at}, {what})",
                self.count
            );
        }
    }

    pub(crate) fn add(&mut self, at: usize, why: impl FnOnce() -> String) {
        self.count += 1;
        if self.first.is_none() {
            self.first = Some((at, why()));
        }
    }
}

/// The stars a reader keeps, in the file's order: rows whose values are out of their physical
/// range ([`out_of_range`]) and rows repeating an earlier row's id are left out and counted,
/// with one warning each naming the count and the first. A repeated id keeps its first row,
/// as astrometry.net's and tetra3's catalog builders keep every row without refusing the file:
/// a merged or concatenated catalog repeats rows, and one repeat should not cost the rest.
pub(crate) struct Rows {
    stars: Vec<Star>,
    names: Vec<String>,
    ids: HashSet<StarId>,
    named: HashSet<String>,
    /// What `at` counts: "line" for text formats, "record" or "star" for the others.
    pub(crate) unit: &'static str,
    pub out_of_range: Tally,
    pub repeated: Tally,
}

impl Rows {
    /// Rows counted in `unit`s (`Format::row_unit`).
    pub(crate) fn new(unit: &'static str) -> Rows {
        Rows {
            stars: Vec::new(),
            names: Vec::new(),
            ids: HashSet::new(),
            named: HashSet::new(),
            unit,
            out_of_range: Tally::default(),
            repeated: Tally::default(),
        }
    }

    /// Keep `star` of line (or record) `at` unless it is out of range or its id repeats.
    pub(crate) fn push(&mut self, mut star: Star, at: usize) {
        if let Some(why) = out_of_range(&mut star) {
            self.out_of_range.add(at, || why);
        } else if !self.ids.insert(star.id) {
            self.repeated
                .add(at, || format!("id {}", star.id.display(&self.names)));
        } else {
            self.stars.push(star);
        }
    }

    /// [`Rows::push`] for a user catalog's star, whose id is `name` (its `id` is set here).
    pub(crate) fn push_named(&mut self, mut star: Star, name: &str, at: usize) -> Result<()> {
        if let Some(why) = out_of_range(&mut star) {
            self.out_of_range.add(at, || why);
        } else if self.named.contains(name) {
            self.repeated.add(at, || format!("id {name:?}"));
        } else {
            let Ok(index) = u32::try_from(self.names.len()) else {
                fail!(Catalog, "more than 2^32 stars");
            };
            star.id = StarId::Name(index);
            self.named.insert(name.to_string());
            self.names.push(name.to_string());
            self.stars.push(star);
        }
        Ok(())
    }

    /// The stars and names kept, after warning of what was left out.
    pub(crate) fn finish(self, source: &str) -> (Vec<Star>, Vec<String>) {
        let unit = self.unit;
        self.out_of_range.warn(source, unit, OUT_OF_RANGE);
        self.repeated.warn(source, unit, REPEATED);
        (self.stars, self.names)
    }
}

/// A number in a field, or a message naming the line and column.
pub(crate) fn number(field: &str, what: &str, source: &str, line: usize) -> Result<f64> {
    match field.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => fail!(
            Catalog,
            "{source}: line {line}: bad {what} {:?}",
            field.trim()
        ),
    }
}

/// A number, or `default` for an empty field.
pub(crate) fn number_or(
    field: &str,
    default: f64,
    what: &str,
    source: &str,
    line: usize,
) -> Result<f64> {
    if field.trim().is_empty() {
        Ok(default)
    } else {
        number(field, what, source, line)
    }
}
