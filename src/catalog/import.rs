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

    const TWO_LINES: &str = "     1   5 0 1  0.0000159148  0.0190068680    4.55    -4.55    -1.19   1.29   0.66   1.33   1.25   0.75  90  0.91  0    0.0    0  9.2043 0.0020 0.017 0  0.482 0.025  0.550   1.19  -0.71   1.00  -0.02   0.02   1.00   0.45  -0.05   0.03   1.09  -0.41   0.09   0.08  -0.60   1.00
     3   5 0 1  0.0000874051  0.6782224871    2.26     4.27    -3.43   0.31   0.21   0.36   0.34   0.27 129  1.56  0    0.0    0  6.6081 0.0006 0.008 0 -0.019 0.004  0.000   1.13  -0.32   1.03  -0.42   0.13   1.00  -1.68   0.20   0.16   1.03   0.41  -1.12  -0.14  -0.94   1.00
";

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
