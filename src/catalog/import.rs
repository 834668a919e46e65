//! `gpustar catalog import`: make the shipped catalog from Hipparcos-2 (`hip2.dat`, CDS I/311).

use super::formats::{OUT_OF_RANGE, REPEATED, Tally, out_of_range as out_of_range_of};
use super::{HIPPARCOS_EPOCH, Star, StarId};
use crate::error::{Context, Error, IntoKind, Result, fail};
use std::fmt::Write as _;

/// Convert the whitespace-separated `hip2.dat` of I/311 into gpustar's catalog CSV, keeping
/// stars with Hp ≤ `max_mag`. Columns used (1-based, I/311 ReadMe): 1 HIP, 5 RArad, 6 DErad,
/// 8 pmRA, 9 pmDE, 20 Hpmag. Numbers are copied as written, so the output is reproducible
/// byte for byte.
pub fn import_hip2(text: &str, max_mag: f64) -> Result<String> {
    let mut rows = Vec::new();
    let (mut out_of_range, mut repeated) = (Tally::default(), Tally::default());
    let mut seen = std::collections::HashSet::new();
    for (n, line) in text.trim_start_matches('\u{feff}').lines().enumerate() {
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
        let mut v = [0.0; 5];
        for (k, i) in [0, 4, 5, 7, 8].into_iter().enumerate() {
            v[k] = f[i]
                .parse::<f64>()
                .into_kind(Error::Catalog)
                .with_context(|| format!("hip2.dat line {}: bad number {:?}", n + 1, f[i]))?;
        }
        let mut star = Star {
            id: StarId::Hip(0),
            hip: None,
            ra_rad: v[1],
            dec_rad: v[2],
            pmra_mas_yr: v[3],
            pmdec_mas_yr: v[4],
            mag,
            epoch: HIPPARCOS_EPOCH,
        };
        if let Some(why) = out_of_range_of(&mut star) {
            out_of_range.add(n + 1, || why);
            continue;
        }
        if !seen.insert(f[0]) {
            repeated.add(n + 1, || format!("HIP {}", f[0]));
            continue;
        }
        // Copied as written unless the RA was wrapped into [0, 2π).
        let ra = if star.ra_rad == v[1] {
            f[4].to_string()
        } else {
            star.ra_rad.to_string()
        };
        rows.push([f[0], &ra, f[5], f[7], f[8], f[19]].join(","));
    }
    out_of_range.warn("hip2.dat", "line", OUT_OF_RANGE);
    repeated.warn("hip2.dat", "line", REPEATED);
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

    /// Rows out of range and repeated HIP numbers are left out of the CSV too; an RA within a
    /// turn of [0, 2π) is written wrapped.
    #[test]
    fn import_leaves_out_impossible_rows_and_repeats() {
        let line = TWO_LINES.lines().nth(1).unwrap();
        let bad_dec = line.replacen("0.6782224871", "1.6782224871", 1);
        let bad_pm = line.replacen("    4.27 ", " 1e300 ", 1);
        let negative_ra = line.replacen("0.0000874051", "-0.0000874051", 1);
        let text = format!(
            "{TWO_LINES}{line}
{bad_dec}
{bad_pm}
"
        );
        let csv = import_hip2(&text, 10.0).unwrap();
        let cat = crate::catalog::Catalog::parse(&csv, "t").unwrap();
        assert_eq!(cat.stars.len(), 2, "{csv}");
        assert!(csv.contains("# 2 stars"));
        let csv = import_hip2(
            &format!(
                "{negative_ra}
"
            ),
            10.0,
        )
        .unwrap();
        let cat = crate::catalog::Catalog::parse(&csv, "t").unwrap();
        let ra = cat.stars[0].ra_rad;
        assert!(
            (ra - (std::f64::consts::TAU - 0.0000874051)).abs() < 1e-12,
            "{ra}"
        );
    }

    #[test]
    fn import_rejects_other_files() {
        assert!(import_hip2("hello world\n", 8.0).is_err());
    }
}
