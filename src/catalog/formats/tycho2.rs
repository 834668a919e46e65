//! Tycho-2 `tyc2.dat` (CDS I/259): '|'-separated fixed columns. Mean positions are ICRS at
//! J2000 with proper motion; a star without one (pflag 'X') has only its observed Tycho-2
//! position, at its own epoch (1990 + epRA), and no proper motion.
//! Magnitude: Johnson V ≈ VT − 0.090 (BT − VT) (I/259 ReadMe, note 7), else VT or BT.

use super::rows::{Rows, number, number_or};
use crate::catalog::{Star, StarId};
use crate::error::{Result, fail};

/// Fields of a tyc2.dat line (0-based, split at '|'; ReadMe byte ranges in the comments).
const TYC: usize = 0; // 1-12: TYC1 TYC2 TYC3
const PFLAG: usize = 1; // 14
const MRA: usize = 2; // 16-27 mRAdeg
const MDE: usize = 3; // 29-40 mDEdeg
const PMRA: usize = 4; // 42-48
const PMDE: usize = 5; // 50-56
const BT: usize = 17; // 111-116
const VT: usize = 19; // 124-129
const HIP: usize = 23; // 143-151: HIP (6) and CCDM (3)
const RA: usize = 24; // 153-164 RAdeg (observed)
const DE: usize = 25; // 166-177
const EPRA: usize = 26; // 179-182 epRA-1990
const FIELDS: usize = 32;

/// A tyc2.dat line: 32 '|'-separated fields, the first three numbers.
pub(super) fn looks_like(line: &str) -> bool {
    let f: Vec<&str> = line.split('|').collect();
    f.len() >= FIELDS && tyc(f[TYC]).is_some()
}

fn tyc(field: &str) -> Option<StarId> {
    let mut it = field.split_whitespace();
    let id = StarId::Tycho2 {
        tyc1: it.next()?.parse().ok()?,
        tyc2: it.next()?.parse().ok()?,
        tyc3: it.next()?.parse().ok()?,
    };
    it.next().is_none().then_some(id)
}

pub(super) fn read(
    text: &str,
    source: &str,
    keep: impl Fn(f64) -> bool,
    rows: &mut Rows,
) -> Result<()> {
    for (n, line) in text.lines().enumerate() {
        let n = n + 1;
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split('|').collect();
        if f.len() < FIELDS {
            fail!(
                Catalog,
                "{source}: line {n}: {} '|'-separated fields, expected {FIELDS} (is this CDS \
                 I/259 tyc2.dat, gunzipped?)",
                f.len()
            );
        }
        let Some(id) = tyc(f[TYC]) else {
            fail!(Catalog, "{source}: line {n}: bad TYC {:?}", f[TYC]);
        };
        let bt = (!f[BT].trim().is_empty())
            .then(|| number(f[BT], "BTmag", source, n))
            .transpose()?;
        let vt = (!f[VT].trim().is_empty())
            .then(|| number(f[VT], "VTmag", source, n))
            .transpose()?;
        let mag = match (bt, vt) {
            (Some(b), Some(v)) => v - 0.090 * (b - v),
            (None, Some(v)) => v,
            (Some(b), None) => b,
            (None, None) => continue,
        };
        if !keep(mag) {
            continue;
        }
        let hip_field = f[HIP].get(..6).unwrap_or(f[HIP]).trim();
        let hip = if hip_field.is_empty() {
            None
        } else {
            match hip_field.parse::<u32>() {
                Ok(h) if h > 0 => Some(h),
                _ => fail!(Catalog, "{source}: line {n}: bad HIP {hip_field:?}"),
            }
        };
        let star = if f[PFLAG].trim() == "X" {
            Star {
                id,
                hip,
                ra_rad: number(f[RA], "RAdeg", source, n)?.to_radians(),
                dec_rad: number(f[DE], "DEdeg", source, n)?.to_radians(),
                pmra_mas_yr: 0.0,
                pmdec_mas_yr: 0.0,
                mag,
                epoch: 1990.0 + number(f[EPRA], "epRA", source, n)?,
            }
        } else {
            Star {
                id,
                hip,
                ra_rad: number(f[MRA], "mRAdeg", source, n)?.to_radians(),
                dec_rad: number(f[MDE], "mDEdeg", source, n)?.to_radians(),
                pmra_mas_yr: number_or(f[PMRA], 0.0, "pmRA", source, n)?,
                pmdec_mas_yr: number_or(f[PMDE], 0.0, "pmDE", source, n)?,
                mag,
                epoch: 2000.0,
            }
        };
        rows.push(star, n);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::catalog::formats::{Format, read as import};

    // Made from the I/259 ReadMe's byte layout: a star with a mean position, a HIP star, a
    // star with only an observed position (pflag X), and one with VT only.
    const SAMPLE: &str = "\
0001 00008 1| |  2.31750494|  2.23184345|  -16.3|   -9.0| 68| 73| 1.7| 1.8|1958.89|1951.94| 4|1.0|1.0|0.9|1.0|12.146|0.158|12.146|0.223|999| |         |  2.31754222|  2.23186444|1.67|1.54| 88.0|100.8| |-0.2
4424 01234 1| |217.42872683| 69.20412612|  -42.1|   15.6| 10| 11| 1.1| 1.2|1990.12|1990.45|12|0.9|0.8|1.0|1.1| 7.512|0.012| 6.987|0.009|  7|T| 71683   |217.42873883| 69.20412041|1.49|1.61|  5.1|  6.0| |-0.1
0002 00035 2|X|            |            |       |       |   |   |    |    |       |       |  |   |   |   |   |10.521|0.050| 9.870|0.040|999| |         | 45.12345678|-12.34567890|1.23|1.40| 60.0| 70.0|D| 0.3
0003 00099 1| |100.00000000|-30.00000000|    5.0|   -4.0| 50| 50| 2.0| 2.0|1980.00|1980.00| 3|1.0|1.0|1.0|1.0|      |     |11.200|0.150|999| |         |100.00001000|-30.00001000|1.50|1.50| 90.0| 90.0| | 0.0
";

    #[test]
    fn tycho2_reads_mean_and_observed_positions_ids_and_v() {
        assert_eq!(Format::detect(SAMPLE.as_bytes()), Some(Format::Tycho2));
        let c = import(SAMPLE.as_bytes(), None, None, "t").unwrap();
        assert_eq!(c.stars.len(), 4);
        let s = c.stars[0];
        assert_eq!(s.id.display(&[]), "TYC 1-8-1");
        assert_eq!(s.hip, None);
        assert_eq!(
            (s.ra_rad, s.dec_rad),
            (2.31750494f64.to_radians(), 2.23184345f64.to_radians())
        );
        assert_eq!(
            (s.pmra_mas_yr, s.pmdec_mas_yr, s.epoch),
            (-16.3, -9.0, 2000.0)
        );
        assert!((s.mag - 12.146).abs() < 1e-12, "BT = VT: V = VT");
        let h = c.stars[1];
        assert_eq!(h.id.display(&[]), "TYC 4424-1234-1");
        assert_eq!(h.hip, Some(71683));
        assert!((h.mag - (6.987 - 0.090 * (7.512 - 6.987))).abs() < 1e-12);
        let x = c.stars[2];
        assert_eq!(
            (x.ra_rad, x.dec_rad),
            (45.12345678f64.to_radians(), (-12.3456789f64).to_radians())
        );
        assert_eq!((x.pmra_mas_yr, x.pmdec_mas_yr), (0.0, 0.0));
        assert!((x.epoch - 1991.23).abs() < 1e-12);
        assert_eq!(c.stars[3].mag, 11.2, "VT alone");
        // The magnitude cut applies to V.
        assert_eq!(
            import(SAMPLE.as_bytes(), None, Some(7.0), "t")
                .unwrap()
                .stars
                .len(),
            1
        );
    }

    #[test]
    fn tycho2_damaged_line_is_refused_with_its_number() {
        let bad = SAMPLE.replace("|  2.23184345|", "|  2.2318x345|");
        let e = import(bad.as_bytes(), Some(Format::Tycho2), None, "t")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("line 1") && e.contains("mDEdeg"), "{e}");
    }
}
