//! astrometry.net index files (`index-41xx.fits` from Tycho-2, `index-52xx-yy.fits` from
//! Gaia, Debian's `astrometry-data-tycho2-*`): the stars of the index's star kd-tree, so that
//! anyone who has astrometry.net's indexes has a deep catalog.
//!
//! An index is a FITS file of binary-table chunks written by libkd and fitsbin (astrometry.net
//! `libkd/kdtree_internal_fits.c`, `util/starkd.c`):
//! - `kdtree_header_stars`: an empty table whose header says the tree's size and types
//!   (`KDT_NDAT` points, `KDT_NDIM` = 3, `KDT_DATA` u32, u16, float or double) and its byte
//!   order (`ENDIAN = '04:03:02:01'`: little-endian);
//! - `kdtree_data_stars`: the points, unit vectors (x, y, z) in the tree's order, in that byte
//!   order; integer points are `minval + value / scale`;
//! - `kdtree_range_stars`: `minval[3]`, `maxval[3]`, `scale`, doubles in that byte order;
//! - `kdtree_perm_stars` (rare): the tree's order of the original stars;
//! - the tag-along table (`AN_FILE = 'TAGALONG'`): per star, in the original order, the
//!   columns the index was built with (Tycho-2: `MAG_VT`; Gaia: `ra`, `dec`, magnitudes, …),
//!   big-endian as FITS tables are.
//!
//! The magnitude is the tag-along's first magnitude column (see [`MAG_COLUMNS`]); an index
//! without one (the 5200 "lite" files) is refused unless its stars are ranked by their
//! uniformisation `sweep` (`--max-mag` then counts sweeps). Positions are the index's, at
//! J2000.0 unless the tag-along gives `ref_epoch` (with `pmra`, `pmdec` where present).
//! Stars are named `AN <INDEXID>:<n>` (`n` the star's place in the file).

use crate::catalog::{Star, StarId};
use crate::error::{Result, fail};

/// Magnitude columns, in the order they are looked for (case-insensitive).
pub const MAG_COLUMNS: [&str; 8] = [
    "mag",
    "phot_g_mean_mag",
    "mag_vt",
    "mag_v",
    "vmag",
    "gmag",
    "mag_g",
    "mag_bt",
];

/// The epoch of the positions when the index does not say (Tycho-2's mean positions, and
/// astrometry.net's own convention).
pub const DEFAULT_EPOCH: f64 = 2000.0;

/// Whether `bytes` start like an astrometry.net index: a FITS file whose primary header
/// names an index (`INDEXID`, or `AN_FILE` of a star kd-tree or index).
pub fn looks_like(bytes: &[u8]) -> bool {
    if !bytes.starts_with(b"SIMPLE  =") {
        return false;
    }
    let Ok((cards, _)) = header(bytes, 0) else {
        return false;
    };
    cards.iter().any(|(k, _)| k == "INDEXID")
        || cards
            .iter()
            .any(|(k, v)| k == "AN_FILE" && matches!(v.as_str(), "INDEX" | "SKDT" | "QUAD"))
}

/// One header card: keyword and value (strings without their quotes, trimmed).
type Card = (String, String);

/// The cards of the header at `at` and the offset just after it (2880-byte blocks up to the
/// block holding END).
fn header(bytes: &[u8], at: usize) -> Result<(Vec<Card>, usize)> {
    let mut cards = Vec::new();
    let mut pos = at;
    loop {
        let Some(card) = bytes.get(pos..pos + 80) else {
            fail!(Catalog, "a header at byte {at} has no END card");
        };
        pos += 80;
        let key = String::from_utf8_lossy(&card[..8]).trim().to_string();
        if key == "END" {
            break;
        }
        if &card[8..10] == b"= " {
            let text = String::from_utf8_lossy(&card[10..]);
            let value = if let Some(rest) = text.trim_start().strip_prefix('\'') {
                rest.split('\'').next().unwrap_or("").trim().to_string()
            } else {
                text.split('/').next().unwrap_or("").trim().to_string()
            };
            cards.push((key, value));
        }
    }
    Ok((cards, pos.div_ceil(2880) * 2880))
}

/// A header-data unit: its cards and its data's bytes.
struct Hdu<'a> {
    cards: Vec<Card>,
    data: &'a [u8],
}

impl Hdu<'_> {
    fn get(&self, key: &str) -> Option<&str> {
        self.cards
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    fn int(&self, key: &str) -> Option<u64> {
        self.get(key)?.parse().ok()
    }
}

/// Every HDU of the file, refusing one whose data would run past its end.
fn hdus<'a>(bytes: &'a [u8], source: &str) -> Result<Vec<Hdu<'a>>> {
    let mut out = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        let (cards, data_at) = header(bytes, at).map_err(|e| {
            crate::error::error!(Catalog, "{source}: HDU {} is damaged: {e}", out.len())
        })?;
        let find = |k: &str| {
            cards
                .iter()
                .find(|(c, _)| c == k)
                .and_then(|(_, v)| v.parse::<i64>().ok())
        };
        let naxis = find("NAXIS").unwrap_or(0);
        let mut size: u64 = if naxis > 0 { 1 } else { 0 };
        for i in 1..=naxis.clamp(0, 999) {
            let n = find(&format!("NAXIS{i}")).unwrap_or(0);
            size = size.saturating_mul(u64::try_from(n).unwrap_or(u64::MAX));
        }
        let bytes_per = find("BITPIX").unwrap_or(8).unsigned_abs() / 8;
        size = size
            .saturating_mul(bytes_per)
            .saturating_add(u64::try_from(find("PCOUNT").unwrap_or(0)).unwrap_or(u64::MAX));
        let end = (data_at as u64).saturating_add(size);
        if end > bytes.len() as u64 {
            fail!(
                Catalog,
                "{source}: HDU {} needs {size} bytes of data; the file ends first (cut short?)",
                out.len()
            );
        }
        out.push(Hdu {
            cards,
            data: &bytes[data_at..end as usize],
        });
        at = (end as usize).div_ceil(2880) * 2880;
    }
    Ok(out)
}

/// The data of the table chunk whose first column is `name`.
fn chunk<'a>(hdus: &'a [Hdu<'a>], name: &str) -> Option<&'a Hdu<'a>> {
    hdus.iter().find(|h| h.get("TTYPE1") == Some(name))
}

/// A tag-along column: its bytes per row, offset in the row and FITS type letter.
struct Column {
    offset: usize,
    kind: u8,
}

/// The numeric columns of a binary table (a repeat count of 1 only), by lowercase name.
fn columns(h: &Hdu) -> Vec<(String, Column)> {
    let n = h.int("TFIELDS").unwrap_or(0).min(999);
    let mut out = Vec::new();
    let mut offset = 0usize;
    for i in 1..=n {
        let form = h.get(&format!("TFORM{i}")).unwrap_or("").trim();
        let digits: String = form.chars().take_while(|c| c.is_ascii_digit()).collect();
        let repeat: usize = if digits.is_empty() {
            1
        } else {
            digits.parse().unwrap_or(0)
        };
        let kind = form[digits.len()..].bytes().next().unwrap_or(b'?');
        let width = match kind {
            b'L' | b'B' | b'A' | b'X' => 1,
            b'I' => 2,
            b'J' | b'E' => 4,
            b'K' | b'D' | b'C' => 8,
            b'M' => 16,
            _ => 0,
        };
        let name = h.get(&format!("TTYPE{i}")).unwrap_or("").to_lowercase();
        if repeat == 1 && matches!(kind, b'B' | b'I' | b'J' | b'K' | b'E' | b'D') {
            out.push((name, Column { offset, kind }));
        }
        offset += repeat * width;
    }
    out
}

/// Value of a column in a row (big-endian, as FITS stores tables).
fn value(row: &[u8], c: &Column) -> Option<f64> {
    let b = |n: usize| row.get(c.offset..c.offset + n);
    Some(match c.kind {
        b'B' => b(1)?[0] as f64,
        b'I' => i16::from_be_bytes(b(2)?.try_into().ok()?) as f64,
        b'J' => i32::from_be_bytes(b(4)?.try_into().ok()?) as f64,
        b'K' => i64::from_be_bytes(b(8)?.try_into().ok()?) as f64,
        b'E' => f32::from_be_bytes(b(4)?.try_into().ok()?) as f64,
        b'D' => f64::from_be_bytes(b(8)?.try_into().ok()?),
        _ => return None,
    })
}

/// The stars of an index file, with magnitudes at or brighter than `keep`. `source` names
/// it in messages.
pub(crate) fn read(
    bytes: &[u8],
    source: &str,
    keep: impl Fn(f64) -> bool,
    rows: &mut super::rows::Rows,
) -> Result<()> {
    let hdus = hdus(bytes, source)?;
    let index_id = hdus
        .first()
        .and_then(|h| h.int("INDEXID"))
        .and_then(|n| u32::try_from(n).ok())
        .unwrap_or(0);
    let Some(head) = chunk(&hdus, "kdtree_header_stars") else {
        fail!(
            Catalog,
            "{source}: an astrometry.net file without a star kd-tree (kdtree_header_stars)"
        );
    };
    let little = match head.get("ENDIAN") {
        Some("04:03:02:01") => true,
        Some("01:02:03:04") => false,
        other => fail!(
            Catalog,
            "{source}: the star kd-tree's byte order {other:?} is not one gpustar reads"
        ),
    };
    let n = head.int("KDT_NDAT").unwrap_or(0) as usize;
    let dim = head.int("KDT_NDIM").unwrap_or(0);
    if dim != 3 {
        fail!(
            Catalog,
            "{source}: a star kd-tree of {dim} dimensions (3 expected)"
        );
    }
    let width = match head.get("KDT_DATA") {
        Some("double") => 8,
        Some("float") => 4,
        Some("u32") => 4,
        Some("u16") => 2,
        other => fail!(Catalog, "{source}: star kd-tree data of type {other:?}"),
    };
    let data_type = head.get("KDT_DATA").unwrap_or("").to_string();
    let Some(data) = chunk(&hdus, "kdtree_data_stars") else {
        fail!(Catalog, "{source}: no kdtree_data_stars table");
    };
    if data.data.len() < n.saturating_mul(3 * width) {
        fail!(
            Catalog,
            "{source}: kdtree_data_stars holds {} bytes where {n} stars need {}",
            data.data.len(),
            n.saturating_mul(3 * width)
        );
    }
    let f64_at = |b: &[u8]| -> f64 {
        let a: [u8; 8] = b.try_into().expect("8 bytes");
        if little {
            f64::from_le_bytes(a)
        } else {
            f64::from_be_bytes(a)
        }
    };
    // Integer points: minval + value / scale.
    let (minval, scale) = if matches!(data_type.as_str(), "u32" | "u16") {
        let Some(range) = chunk(&hdus, "kdtree_range_stars").filter(|r| r.data.len() >= 56) else {
            fail!(
                Catalog,
                "{source}: integer kd-tree points without kdtree_range_stars"
            );
        };
        let r: Vec<f64> = range.data[..56].chunks_exact(8).map(f64_at).collect();
        if !(r[6].is_finite() && r[6] > 0.0) {
            fail!(Catalog, "{source}: kd-tree scale {}", r[6]);
        }
        ([r[0], r[1], r[2]], r[6])
    } else {
        ([0.0; 3], 1.0)
    };
    let point = |i: usize, d: usize| -> f64 {
        let at = (3 * i + d) * width;
        let b = &data.data[at..at + width];
        match data_type.as_str() {
            "double" => f64_at(b),
            "float" => {
                let a: [u8; 4] = b.try_into().expect("4 bytes");
                (if little {
                    f32::from_le_bytes(a)
                } else {
                    f32::from_be_bytes(a)
                }) as f64
            }
            "u32" => {
                let a: [u8; 4] = b.try_into().expect("4 bytes");
                let v = if little {
                    u32::from_le_bytes(a)
                } else {
                    u32::from_be_bytes(a)
                };
                minval[d] + v as f64 / scale
            }
            _ => {
                let a: [u8; 2] = b.try_into().expect("2 bytes");
                let v = if little {
                    u16::from_le_bytes(a)
                } else {
                    u16::from_be_bytes(a)
                };
                minval[d] + v as f64 / scale
            }
        }
    };
    // The tree's order of the original stars, where the file keeps one.
    let perm: Option<Vec<usize>> = match chunk(&hdus, "kdtree_perm_stars") {
        None => None,
        Some(p) if p.data.len() >= 4 * n => Some(
            p.data[..4 * n]
                .chunks_exact(4)
                .map(|b| {
                    let a: [u8; 4] = b.try_into().expect("4 bytes");
                    (if little {
                        u32::from_le_bytes(a)
                    } else {
                        u32::from_be_bytes(a)
                    }) as usize
                })
                .collect(),
        ),
        Some(_) => fail!(
            Catalog,
            "{source}: kdtree_perm_stars is shorter than the tree"
        ),
    };
    let tag = hdus.iter().find(|h| h.get("AN_FILE") == Some("TAGALONG"));
    let cols = tag.map(columns).unwrap_or_default();
    let row_len = tag.and_then(|t| t.int("NAXIS1")).unwrap_or(0) as usize;
    let tag_rows = tag.and_then(|t| t.int("NAXIS2")).unwrap_or(0) as usize;
    let col = |name: &str| cols.iter().find(|(c, _)| c == name).map(|(_, c)| c);
    let mag_col = MAG_COLUMNS.iter().find_map(|m| col(m));
    let sweep = chunk(&hdus, "sweep").filter(|s| s.data.len() >= n);
    if mag_col.is_none() && sweep.is_none() {
        fail!(
            Catalog,
            "{source}: an index without a magnitude column (looked for {}) or sweep numbers: \
             gpustar cannot rank its stars by brightness",
            MAG_COLUMNS.join(", ")
        );
    }
    let (epoch_col, pmra_col, pmdec_col) = (col("ref_epoch"), col("pmra"), col("pmdec"));
    if tag.is_some() && tag_rows < n {
        fail!(
            Catalog,
            "{source}: the tag-along table has {tag_rows} rows for {n} stars"
        );
    }
    for i in 0..n {
        let original = perm.as_ref().map_or(i, |p| p[i]);
        let row = tag
            .and_then(|t| t.data.get(original * row_len..(original + 1) * row_len))
            .unwrap_or(&[]);
        let mag = match mag_col {
            Some(c) => value(row, c),
            // Ranked by sweep (the sweep chunk is in the tree's order).
            None => sweep.map(|s| s.data[i] as f64),
        };
        let Some(mag) = mag.filter(|m| m.is_finite()) else {
            continue;
        };
        if !keep(mag) {
            continue;
        }
        let v = nalgebra::Vector3::new(point(i, 0), point(i, 1), point(i, 2));
        let norm = v.norm();
        if !(norm > 0.5 && norm < 1.5) {
            fail!(Catalog, "{source}: star {i} is not a unit vector ({v:?})");
        }
        let v = v / norm;
        let extra = |c: Option<&Column>| c.and_then(|c| value(row, c)).filter(|x| x.is_finite());
        let star = Star {
            id: StarId::AnIndex {
                index: index_id,
                star: i as u32,
            },
            hip: None,
            ra_rad: v.y.atan2(v.x).rem_euclid(std::f64::consts::TAU),
            dec_rad: v.z.clamp(-1.0, 1.0).asin(),
            pmra_mas_yr: extra(pmra_col).unwrap_or(0.0),
            pmdec_mas_yr: extra(pmdec_col).unwrap_or(0.0),
            mag,
            epoch: extra(epoch_col).unwrap_or(DEFAULT_EPOCH),
        };
        rows.push(star, i);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A header block of `cards` (keyword, value as written).
    fn block(cards: &[(&str, &str)]) -> Vec<u8> {
        let mut b = Vec::new();
        for (k, v) in cards {
            b.extend(format!("{k:<8}= {v:>20}").bytes());
            b.resize(b.len().div_ceil(80) * 80, b' ');
        }
        b.extend(format!("{:<80}", "END").bytes());
        b.resize(b.len().div_ceil(2880) * 2880, b' ');
        b
    }

    fn data(mut d: Vec<u8>) -> Vec<u8> {
        d.resize(d.len().div_ceil(2880) * 2880, 0);
        d
    }

    fn table(name: &str, row: usize, rows: usize, extra: &[(&str, &str)]) -> Vec<(String, String)> {
        let mut c = vec![
            ("XTENSION".to_string(), "'BINTABLE'".to_string()),
            ("BITPIX".into(), "8".into()),
            ("NAXIS".into(), "2".into()),
            ("NAXIS1".into(), row.to_string()),
            ("NAXIS2".into(), rows.to_string()),
            ("PCOUNT".into(), "0".into()),
            ("GCOUNT".into(), "1".into()),
            ("TFIELDS".into(), "1".into()),
            ("TFORM1".into(), format!("'{row}A'")),
            ("TTYPE1".into(), format!("'{name}'")),
        ];
        c.extend(extra.iter().map(|(k, v)| (k.to_string(), v.to_string())));
        c
    }

    fn cards(c: &[(String, String)]) -> Vec<u8> {
        let r: Vec<(&str, &str)> = c.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
        block(&r)
    }

    /// A small index in the layout of Debian's `index-tycho2-*` files: two stars as u32
    /// points, the range chunk, a MAG_VT tag-along.
    fn tiny_index() -> Vec<u8> {
        let stars = [
            nalgebra::Vector3::new(1.0, 0.0, 0.0),
            nalgebra::Vector3::new(0.0, 0.6, 0.8),
        ];
        let scale = 2147483647.5;
        let mut f = block(&[
            ("SIMPLE", "T"),
            ("BITPIX", "8"),
            ("NAXIS", "0"),
            ("INDEXID", "4107"),
        ]);
        f.extend(cards(&table(
            "kdtree_header_stars",
            0,
            0,
            &[
                ("ENDIAN", "'04:03:02:01'"),
                ("KDT_NDAT", "2"),
                ("KDT_NDIM", "3"),
                ("KDT_DATA", "'u32'"),
            ],
        )));
        f.extend(cards(&table("kdtree_range_stars", 8, 7, &[])));
        let mut r = Vec::new();
        for x in [-1.0f64, -1.0, -1.0, 1.0, 1.0, 1.0, scale] {
            r.extend(x.to_le_bytes());
        }
        f.extend(data(r));
        f.extend(cards(&table("kdtree_data_stars", 12, 2, &[])));
        let mut d = Vec::new();
        for s in &stars {
            for x in [s.x, s.y, s.z] {
                d.extend((((x + 1.0) * scale).round() as u32).to_le_bytes());
            }
        }
        f.extend(data(d));
        let mut tag = table("MAG_VT", 4, 2, &[("AN_FILE", "'TAGALONG'")]);
        tag[8].1 = "'1E'".into();
        f.extend(cards(&tag));
        let mut m = Vec::new();
        for x in [9.5f32, 11.25] {
            m.extend(x.to_be_bytes());
        }
        f.extend(data(m));
        f
    }

    /// The stars `read` keeps.
    fn read(bytes: &[u8], source: &str, keep: impl Fn(f64) -> bool) -> Result<Vec<Star>> {
        let mut rows =
            crate::catalog::formats::Rows::new(crate::catalog::formats::Format::AnIndex.row_unit());
        super::read(bytes, source, keep, &mut rows)?;
        Ok(rows.finish(source).0)
    }

    #[test]
    fn stars_come_from_the_tree_with_the_tag_along_magnitudes() {
        let f = tiny_index();
        assert!(looks_like(&f));
        let stars = read(&f, "tiny", |_| true).unwrap();
        assert_eq!(stars.len(), 2);
        assert!(stars[0].ra_rad.abs() < 1e-8 && stars[0].dec_rad.abs() < 1e-8);
        assert!((stars[1].ra_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-8);
        assert!((stars[1].dec_rad - 0.8f64.asin()).abs() < 1e-8);
        assert_eq!((stars[0].mag, stars[1].mag), (9.5, 11.25));
        assert_eq!(stars[1].epoch, DEFAULT_EPOCH);
        assert_eq!(
            stars[1].id,
            StarId::AnIndex {
                index: 4107,
                star: 1
            }
        );
        let bright = read(&f, "tiny", |m| m <= 10.0).unwrap();
        assert_eq!(bright.len(), 1);
    }

    #[test]
    fn cut_or_damaged_files_are_refused() {
        let f = tiny_index();
        for cut in [100, 2880, 2880 * 3 + 10, f.len() - 2880] {
            assert!(read(&f[..cut], "tiny", |_| true).is_err(), "cut at {cut}");
        }
        let mut bad_endian = f.clone();
        let at = bad_endian
            .windows(11)
            .position(|w| w == b"04:03:02:01")
            .unwrap();
        bad_endian[at..at + 11].copy_from_slice(b"03:04:01:02");
        assert!(read(&bad_endian, "tiny", |_| true).is_err());
    }
}
