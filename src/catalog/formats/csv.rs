//! CSV catalogs: a header row names the columns (any order), `#` lines are comments.
//! A user's catalog: `id`, `ra_deg`, `dec_deg`, `mag`, optional `pmra_mas_yr` (μα·cos δ),
//! `pmdec_mas_yr`, `epoch` (Julian year of the position, default [`USER_EPOCH`]) and `hip`.

use super::rows::{Rows, number, number_or};
use crate::catalog::{Star, StarId};
use crate::error::{Result, fail};

/// Epoch of a user catalog's positions when it has no `epoch` column (J2000.0).
pub const USER_EPOCH: f64 = 2000.0;

/// gpustar's own catalog CSV (what `catalog/hip2_hp9.csv` is).
pub(super) fn is_gpustar_csv(text: &str) -> bool {
    text.lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))
        .is_some_and(|l| l.starts_with("hip,ra_rad,"))
}

/// A header naming the columns a user catalog needs (or gpustar's own CSV header).
pub(super) fn looks_like(line: &str) -> bool {
    let h = Header::new(line);
    line.starts_with("hip,ra_rad,") || ["id", "ra_deg", "dec_deg", "mag"].iter().all(|c| h.has(c))
}

/// Fields of a CSV line: comma-separated, trimmed, a field in double quotes may hold commas
/// (`""` is a quote).
pub(super) fn split(line: &str) -> Vec<String> {
    let mut fields = Vec::new();
    let mut cur = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' if quoted && chars.peek() == Some(&'"') => {
                cur.push('"');
                chars.next();
            }
            '"' => quoted = !quoted,
            ',' if !quoted => fields.push(std::mem::take(&mut cur).trim().to_string()),
            _ => cur.push(c),
        }
    }
    fields.push(cur.trim().to_string());
    fields
}

/// Column names of a header row, found case-insensitively.
pub(super) struct Header(Vec<String>);

impl Header {
    pub(super) fn new(line: &str) -> Header {
        Header(split(line).into_iter().map(|s| s.to_lowercase()).collect())
    }

    pub(super) fn has(&self, name: &str) -> bool {
        self.find(name).is_some()
    }

    pub(super) fn find(&self, name: &str) -> Option<usize> {
        self.0.iter().position(|c| c == name)
    }

    pub(super) fn need(&self, name: &str, source: &str) -> Result<usize> {
        match self.find(name) {
            Some(i) => Ok(i),
            None => fail!(
                Catalog,
                "{source}: the header has no column {name:?} (it has {})",
                self.0.join(",")
            ),
        }
    }

    pub(super) fn len(&self) -> usize {
        self.0.len()
    }
}

/// Data rows after the header: (1-based line number, fields); the header itself first.
pub(super) fn rows(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(n, l)| (n + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

/// A row's fields, refused when there are fewer than the header's.
pub(super) fn fields(line: &str, header: &Header, source: &str, n: usize) -> Result<Vec<String>> {
    let f = split(line);
    if f.len() < header.len() {
        fail!(
            Catalog,
            "{source}: line {n}: {} fields, the header names {}",
            f.len(),
            header.len()
        );
    }
    Ok(f)
}

/// A user catalog: stars and their ids (kept verbatim).
pub(super) fn read(
    text: &str,
    source: &str,
    keep: impl Fn(f64) -> bool,
    rows_kept: &mut Rows,
) -> Result<()> {
    let mut it = rows(text);
    let Some((_, head)) = it.next() else {
        fail!(Catalog, "{source}: empty");
    };
    let h = Header::new(head);
    let (id, ra, dec, mag) = (
        h.need("id", source)?,
        h.need("ra_deg", source)?,
        h.need("dec_deg", source)?,
        h.need("mag", source)?,
    );
    let (pmra, pmdec, epoch, hip) = (
        h.find("pmra_mas_yr"),
        h.find("pmdec_mas_yr"),
        h.find("epoch"),
        h.find("hip"),
    );
    for (n, line) in it {
        let f = fields(line, &h, source, n)?;
        let m = number(&f[mag], "mag", source, n)?;
        if !keep(m) {
            continue;
        }
        let opt = |col: Option<usize>, default: f64, what: &str| -> Result<f64> {
            col.map_or(Ok(default), |c| number_or(&f[c], default, what, source, n))
        };
        let hip = match hip.map(|c| f[c].as_str()).filter(|s| !s.is_empty()) {
            None => None,
            Some(s) => match s.parse::<u32>() {
                Ok(h) if h > 0 => Some(h),
                _ => fail!(Catalog, "{source}: line {n}: bad hip {s:?}"),
            },
        };
        if f[id].is_empty() {
            fail!(Catalog, "{source}: line {n}: empty id");
        }
        let star = Star {
            // Set by push_named.
            id: StarId::Name(0),
            hip,
            ra_rad: number(&f[ra], "ra_deg", source, n)?.to_radians(),
            dec_rad: number(&f[dec], "dec_deg", source, n)?.to_radians(),
            pmra_mas_yr: opt(pmra, 0.0, "pmra_mas_yr")?,
            pmdec_mas_yr: opt(pmdec, 0.0, "pmdec_mas_yr")?,
            mag: m,
            epoch: opt(epoch, USER_EPOCH, "epoch")?,
        };
        rows_kept
            .push_named(star, &f[id], n)
            .map_err(|e| e.context(source))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalog::formats::{Format, read as import};

    const USER: &str = "# my stars\n\
                        mag,dec_deg,ra_deg,id,pmdec_mas_yr,pmra_mas_yr,epoch,hip\n\
                        3.5,-10.5,200.25,\"alpha, the first\",-20,100,2010.5,71683\n\
                        9.5,1,2,faint,,,,\n\
                        4.0,45,359.5,b-2,,,,\n";

    #[test]
    fn user_csv_reads_every_column_in_any_order_with_defaults() {
        assert_eq!(Format::detect(USER.as_bytes()), Some(Format::Csv));
        let c = import(USER.as_bytes(), None, Some(5.0), "u").unwrap();
        assert_eq!(c.stars.len(), 2);
        assert_eq!(c.names, ["alpha, the first", "b-2"]);
        let s = c.stars[0];
        assert_eq!((s.id, s.hip), (StarId::Name(0), Some(71683)));
        assert_eq!(s.ra_rad, 200.25f64.to_radians());
        assert_eq!(s.dec_rad, (-10.5f64).to_radians());
        assert_eq!((s.pmra_mas_yr, s.pmdec_mas_yr), (100.0, -20.0));
        assert_eq!((s.mag, s.epoch), (3.5, 2010.5));
        let t = c.stars[1];
        assert_eq!((t.id, t.hip), (StarId::Name(1), None));
        assert_eq!(
            (t.pmra_mas_yr, t.pmdec_mas_yr, t.epoch),
            (0.0, 0.0, USER_EPOCH)
        );
    }

    #[test]
    fn user_csv_errors_name_the_line() {
        let bad = "id,ra_deg,dec_deg,mag\nx,1,2,bright\n";
        let e = import(bad.as_bytes(), None, None, "u")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("line 2") && e.contains("mag"), "{e}");
        let short = "id,ra_deg,dec_deg,mag\nx,1,2\n";
        assert!(import(short.as_bytes(), None, None, "u").is_err());
        let missing = "id,ra_deg,mag\nx,1,2\n";
        let e = import(missing.as_bytes(), Some(Format::Csv), None, "u")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("dec_deg"), "{e}");
    }

    #[test]
    fn gpustar_csv_is_imported_as_it_is_loaded() {
        let t = "hip,ra_rad,dec_rad,pmra_mas_yr,pmdec_mas_yr,hp_mag\n7,1.0,0.5,1.5,-2,3.25\n";
        assert_eq!(Format::detect(t.as_bytes()), Some(Format::Csv));
        let c = import(t.as_bytes(), None, None, "g").unwrap();
        assert_eq!(c.stars[0].id, StarId::Hip(7));
        assert_eq!(c.stars[0].epoch, 1991.25);
    }

    #[test]
    fn a_star_moves_from_its_own_epoch_as_by_hand() {
        // 2010.5 → 2030.5 with (μα*, μδ) = (100, −20) mas/yr: the inverse gnomonic projection
        // of the tangent-plane offset (ξ, η) = μ·Δt, written out by hand.
        let c = import(USER.as_bytes(), None, None, "u").unwrap();
        let s = c.stars[0];
        let mas = std::f64::consts::PI / (180.0 * 3600.0 * 1000.0);
        let (xi, eta) = (100.0 * 20.0 * mas, -20.0 * 20.0 * mas);
        let (a0, d0) = (200.25f64.to_radians(), (-10.5f64).to_radians());
        let den = d0.cos() - eta * d0.sin();
        let ra = a0 + xi.atan2(den);
        let dec = (d0.sin() + eta * d0.cos()).atan2(xi.hypot(den));
        let (vr, vd) = crate::catalog::vector_to_radec(&s.vector_at(2030.5));
        assert!(
            (vr.to_radians() - ra).abs() < 1e-9,
            "{vr} {}",
            ra.to_degrees()
        );
        assert!(
            (vd.to_radians() - dec).abs() < 1e-9,
            "{vd} {}",
            dec.to_degrees()
        );
        // At its own epoch it is where the file puts it, whatever the file's epoch.
        let (r0, d) = crate::catalog::vector_to_radec(&s.vector_at(2010.5));
        assert!((r0 - 200.25).abs() < 1e-12 && (d + 10.5).abs() < 1e-12);
    }
}
