//! `gpustar catalog import`: make the shipped catalog from Hipparcos-2 (`hip2.dat`, CDS I/311).

use crate::error::{Context, Error, IntoKind, Result, fail};
use std::fmt::Write as _;

/// Convert the whitespace-separated `hip2.dat` of I/311 into gpustar's catalog CSV, keeping
/// stars with Hp ≤ `max_mag`. Columns used (1-based, I/311 ReadMe): 1 HIP, 5 RArad, 6 DErad,
/// 8 pmRA, 9 pmDE, 20 Hpmag. Numbers are copied as written, so the output is reproducible
/// byte for byte.
pub fn import_hip2(text: &str, max_mag: f64) -> Result<String> {
    let mut rows = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 20 {
            fail!(
                Catalog,
                "hip2.dat line {}: {} columns, expected at least 20 (is this CDS I/311 hip2.dat?)",
                n + 1,
                f.len()
            );
        }
        let mag: f64 = f[19]
            .parse()
            .into_kind(Error::Catalog)
            .with_context(|| format!("hip2.dat line {}: bad Hpmag {:?}", n + 1, f[19]))?;
        if mag > max_mag {
            continue;
        }
        for i in [0, 4, 5, 7, 8] {
            f[i].parse::<f64>()
                .into_kind(Error::Catalog)
                .with_context(|| format!("hip2.dat line {}: bad number {:?}", n + 1, f[i]))?;
        }
        rows.push([f[0], f[4], f[5], f[7], f[8], f[19]].join(","));
    }
    if rows.is_empty() {
        fail!(
            Catalog,
            "no star with Hp <= {max_mag} found: is this hip2.dat?"
        );
    }
    let mut out = String::new();
    writeln!(
        out,
        "# gpustar catalog: Hipparcos, the new reduction (van Leeuwen 2007, CDS I/311; public domain)"
    )
    .expect("writing to a String");
    writeln!(
        out,
        "# {} stars with Hp <= {max_mag}; positions ICRS at epoch J1991.25. Made by: gpustar catalog import hip2.dat --max-mag {max_mag}",
        rows.len()
    )
    .expect("writing to a String");
    writeln!(out, "hip,ra_rad,dec_rad,pmra_mas_yr,pmdec_mas_yr,hp_mag")
        .expect("writing to a String");
    for r in rows {
        writeln!(out, "{r}").expect("writing to a String");
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::catalog::formats::hip2::TWO_LINES;

    #[test]
    fn import_keeps_bright_stars_and_copies_columns() {
        let csv = import_hip2(TWO_LINES, 8.0).unwrap();
        let cat = crate::catalog::Catalog::parse(&csv, "test").unwrap();
        assert_eq!(cat.stars.len(), 1);
        let s = cat.stars[0];
        assert_eq!(s.hip, Some(3));
        assert_eq!(s.ra_rad, 0.0000874051);
        assert_eq!(s.dec_rad, 0.6782224871);
        assert_eq!(s.pmra_mas_yr, 4.27);
        assert_eq!(s.pmdec_mas_yr, -3.43);
        assert_eq!(s.mag, 6.6081);
    }

    #[test]
    fn import_rejects_other_files() {
        assert!(import_hip2("hello world\n", 8.0).is_err());
    }
}
