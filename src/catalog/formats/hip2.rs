//! Hipparcos-2 `hip2.dat` (CDS I/311): whitespace-separated, positions ICRS at J1991.25.

use super::rows::{Rows, number};
use crate::catalog::{HIPPARCOS_EPOCH, Star, StarId};
use crate::error::{Result, fail};

/// A data line of hip2.dat: at least 20 columns, an integer HIP, RA in radians.
pub(super) fn looks_like(line: &str) -> bool {
    let f: Vec<&str> = line.split_whitespace().collect();
    f.len() >= 20
        && f[0].parse::<u32>().is_ok()
        && f[4]
            .parse::<f64>()
            .is_ok_and(|ra| (0.0..=std::f64::consts::TAU).contains(&ra))
}

/// Columns used (1-based, I/311 ReadMe): 1 HIP, 5 RArad, 6 DErad, 8 pmRA, 9 pmDE, 20 Hpmag.
pub(super) fn read(
    text: &str,
    source: &str,
    keep: impl Fn(f64) -> bool,
    rows: &mut Rows,
) -> Result<()> {
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 20 {
            fail!(
                Catalog,
                "{source}: line {}: {} columns, expected at least 20 (is this CDS I/311 \
                 hip2.dat?)",
                n + 1,
                f.len()
            );
        }
        let mag = number(f[19], "Hpmag", source, n + 1)?;
        if !keep(mag) {
            continue;
        }
        let Ok(hip) = f[0].parse::<u32>() else {
            fail!(Catalog, "{source}: line {}: bad HIP {:?}", n + 1, f[0]);
        };
        let star = Star {
            id: StarId::Hip(hip),
            hip: Some(hip),
            ra_rad: number(f[4], "RArad", source, n + 1)?,
            dec_rad: number(f[5], "DErad", source, n + 1)?,
            pmra_mas_yr: number(f[7], "pmRA", source, n + 1)?,
            pmdec_mas_yr: number(f[8], "pmDE", source, n + 1)?,
            mag,
            epoch: HIPPARCOS_EPOCH,
        };
        rows.push(star, n + 1);
    }
    Ok(())
}

/// Two lines of the real hip2.dat (HIP 1, Hp 9.2; HIP 3, Hp 6.6), for tests.
#[cfg(test)]
pub(crate) const TWO_LINES: &str = "     1   5 0 1  0.0000159148  0.0190068680    4.55    -4.55    -1.19   1.29   0.66   1.33   1.25   0.75  90  0.91  0    0.0    0  9.2043 0.0020 0.017 0  0.482 0.025  0.550   1.19  -0.71   1.00  -0.02   0.02   1.00   0.45  -0.05   0.03   1.09  -0.41   0.09   0.08  -0.60   1.00
     3   5 0 1  0.0000874051  0.6782224871    2.26     4.27    -3.43   0.31   0.21   0.36   0.34   0.27 129  1.56  0    0.0    0  6.6081 0.0006 0.008 0 -0.019 0.004  0.000   1.13  -0.32   1.03  -0.42   0.13   1.00  -1.68   0.20   0.16   1.03   0.41  -1.12  -0.14  -0.94   1.00
";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hip2_is_recognised_and_read_column_by_column() {
        use crate::catalog::formats::{Format, read};
        assert_eq!(Format::detect(TWO_LINES.as_bytes()), Some(Format::Hip2));
        let cat = read(TWO_LINES.as_bytes(), None, Some(8.0), "t").unwrap();
        assert_eq!(cat.stars.len(), 1);
        let s = cat.stars[0];
        assert_eq!((s.id, s.hip), (StarId::Hip(3), Some(3)));
        assert_eq!((s.ra_rad, s.dec_rad), (0.0000874051, 0.6782224871));
        assert_eq!((s.pmra_mas_yr, s.pmdec_mas_yr), (4.27, -3.43));
        assert_eq!((s.mag, s.epoch), (6.6081, 1991.25));
        assert_eq!(
            read(TWO_LINES.as_bytes(), None, None, "t")
                .unwrap()
                .stars
                .len(),
            2
        );
    }
}
