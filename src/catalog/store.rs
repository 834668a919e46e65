//! gpustar's binary catalog file: what `gpustar catalog import` writes and `--catalog` reads
//! without parsing text. Little-endian throughout:
//!
//! ```text
//! header, 64 bytes:
//!    0  magic b"GPUSTARC"          8  version u32 (1)       12  id kinds u32 (bit 1 << kind)
//!   16  stars u64                 24  bands u32             28  cells u32
//!   32  names bytes u64           40  epoch f64 (the stars' common epoch; NaN when they differ)
//!   48  CRC-32 of all after the header, u32                 52  reserved u32 (0)
//!   56  file length u64
//! bands × u32        cells per declination band, south to north (see `cells`)
//! (cells + 1) × u32  index of each cell's first star; the last is the star count
//! stars × 64 bytes   in cell order: ra, dec (f64 rad), pmra, pmdec (f64 mas/yr, RA with
//!                    cos dec), mag f64, epoch f64 (Julian year), id u64, hip u32 (0: none),
//!                    id kind u8 (1 HIP, 2 Gaia DR3, 3 Tycho-2, 4 name), 3 bytes 0
//! names              per user id, in index order: u32 length + UTF-8 bytes
//! ```
//!
//! Numbers are stored as they were read (f64), so a file gives back exactly the stars written.

use super::cells::{Cells, SkyIndex};
use super::id::StarId;
use super::loaded::Catalog;
use super::star::fnv1a;
use super::stars::{RECORD, Stars, parse_records, record_star, u32_at, u64_at};
use crate::error::{Result, fail};
use std::sync::Arc;

/// The file's first bytes.
pub const MAGIC: &[u8; 8] = b"GPUSTARC";
/// The format version this build reads and writes.
pub const VERSION: u32 = 1;
const HEADER: usize = 64;
/// Whether `bytes` start like a binary catalog file.
pub fn is_store(bytes: &[u8]) -> bool {
    bytes.starts_with(MAGIC)
}

/// The file for `catalog`: its stars sorted by sky cell (stable within a cell).
pub fn write(catalog: &Catalog) -> Vec<u8> {
    let index = catalog.index();
    let cells = &index.cells;
    let stars = &catalog.stars;
    let mut names = Vec::new();
    for n in catalog.names.iter() {
        names.extend((n.len() as u32).to_le_bytes());
        names.extend(n.as_bytes());
    }
    let mut body = Vec::with_capacity(
        4 * (cells.bands() + cells.len() + 1) + RECORD * stars.len() + names.len(),
    );
    for &c in &cells.band_cells {
        body.extend(c.to_le_bytes());
    }
    for &s in &index.starts {
        body.extend(s.to_le_bytes());
    }
    let mut kinds = 0u32;
    for &i in &index.order {
        let s = &stars[i as usize];
        let (kind, id) = s.id.encode();
        kinds |= 1u32 << kind;
        for v in [
            s.ra_rad,
            s.dec_rad,
            s.pmra_mas_yr,
            s.pmdec_mas_yr,
            s.mag,
            s.epoch,
        ] {
            body.extend(v.to_le_bytes());
        }
        body.extend(id.to_le_bytes());
        body.extend(s.hip.unwrap_or(0).to_le_bytes());
        body.extend([kind, 0, 0, 0]);
    }
    body.extend(&names);
    let epoch = match stars.first() {
        Some(f) if stars.iter().all(|s| s.epoch == f.epoch) => f.epoch,
        _ => f64::NAN,
    };
    let mut out = Vec::with_capacity(HEADER + body.len());
    out.extend(MAGIC);
    out.extend(VERSION.to_le_bytes());
    out.extend(kinds.to_le_bytes());
    out.extend((stars.len() as u64).to_le_bytes());
    out.extend((cells.bands() as u32).to_le_bytes());
    out.extend((cells.len() as u32).to_le_bytes());
    out.extend((names.len() as u64).to_le_bytes());
    out.extend(epoch.to_le_bytes());
    out.extend(crc32fast::hash(&body).to_le_bytes());
    out.extend(0u32.to_le_bytes());
    out.extend(((HEADER + body.len()) as u64).to_le_bytes());
    out.extend(body);
    out
}

/// What [`check`] found of a file: its cells, its names, and where its records are.
struct Layout {
    cells: Cells,
    starts: Vec<u32>,
    names: Vec<String>,
    /// Byte offset of the first record in the file, and the number of records.
    records_at: usize,
    count: usize,
}

/// Check a binary catalog file whole (header, checksum, tables, every record's id); a
/// truncated, damaged or foreign file is an error that says so.
fn check(bytes: &[u8], source: &str) -> Result<Layout> {
    check_with(bytes, source, true)
}

/// [`check`], or with `whole` false only the header and the tables (not the checksum and the
/// records' ids): for a file that passed the whole check before and has not changed since
/// (`checked`).
fn check_with(bytes: &[u8], source: &str, whole: bool) -> Result<Layout> {
    let again = "make it again with `gpustar catalog import`";
    if !is_store(bytes) {
        fail!(Catalog, "{source}: not a gpustar catalog file");
    }
    if bytes.len() < HEADER {
        fail!(
            Catalog,
            "{source}: truncated gpustar catalog file ({} bytes, less than its header); {again}",
            bytes.len()
        );
    }
    let version = u32_at(bytes, 8);
    if version != VERSION {
        fail!(
            Catalog,
            "{source}: gpustar catalog file version {version}; this gpustar reads version \
             {VERSION}: {again}"
        );
    }
    let length = u64_at(bytes, 56);
    if length != bytes.len() as u64 {
        fail!(
            Catalog,
            "{source}: truncated or damaged gpustar catalog file: {} bytes, its header says \
             {length}; {again}",
            bytes.len()
        );
    }
    let body = &bytes[HEADER..];
    if whole && crc32fast::hash(body) != u32_at(bytes, 48) {
        fail!(
            Catalog,
            "{source}: damaged gpustar catalog file (checksum mismatch); {again}"
        );
    }
    let count = u64_at(bytes, 16);
    let (bands, ncells) = (u32_at(bytes, 24) as u64, u32_at(bytes, 28) as u64);
    let names_len = u64_at(bytes, 32);
    // Sizes in u128 so that no header value can overflow the sum.
    let need = 4 * (bands as u128 + ncells as u128 + 1)
        + RECORD as u128 * count as u128
        + names_len as u128;
    if need != body.len() as u128 || count > u32::MAX as u64 {
        fail!(
            Catalog,
            "{source}: inconsistent gpustar catalog file header ({count} stars, {bands} bands, \
             {ncells} cells in {} bytes); {again}",
            body.len()
        );
    }
    let (bands, ncells, count) = (bands as usize, ncells as usize, count as usize);
    let band_cells: Vec<u32> = (0..bands).map(|b| u32_at(body, 4 * b)).collect();
    let Some(cells) = Cells::from_counts(band_cells).filter(|c| c.len() == ncells) else {
        fail!(Catalog, "{source}: bad cell table; {again}");
    };
    let at = 4 * bands;
    let starts: Vec<u32> = (0..=ncells).map(|c| u32_at(body, at + 4 * c)).collect();
    if starts[0] != 0 || starts[ncells] as usize != count || starts.windows(2).any(|w| w[0] > w[1])
    {
        fail!(Catalog, "{source}: bad cell offsets; {again}");
    }
    let at = at + 4 * (ncells + 1);
    let names_at = at + RECORD * count;
    let mut names = Vec::new();
    let mut o = names_at;
    while o < body.len() {
        let n = u32_at(body, o) as usize;
        let Some(s) = body.get(o + 4..o + 4 + n) else {
            fail!(Catalog, "{source}: bad name table; {again}");
        };
        names.push(String::from_utf8_lossy(s).into_owned());
        o += 4 + n;
    }
    let records = if whole { &body[at..names_at] } else { &[] };
    for (k, r) in records.chunks_exact(RECORD).enumerate() {
        let named = |id: &StarId| !matches!(id, StarId::Name(i) if *i as usize >= names.len());
        if !record_star(r).is_some_and(|s| named(&s.id)) {
            fail!(Catalog, "{source}: star {k}: bad id; {again}");
        }
    }
    Ok(Layout {
        cells,
        starts,
        names,
        records_at: HEADER + at,
        count,
    })
}

impl Layout {
    fn catalog(self, stars: Stars, bytes: &[u8], source: &str) -> Catalog {
        let index = SkyIndex {
            cells: self.cells,
            starts: self.starts,
            order: (0..self.count as u32).collect(),
        };
        Catalog::of_stars(stars, self.names, source, fnv1a(&bytes[..HEADER])).with_index(index)
    }
}

/// Read a binary catalog file, its stars parsed now.
pub fn read(bytes: &[u8], source: &str) -> Result<Catalog> {
    let layout = check(bytes, source)?;
    let records = &bytes[layout.records_at..layout.records_at + RECORD * layout.count];
    Ok(layout.catalog(parse_records(records).into(), bytes, source))
}

/// A binary catalog file mapped, checked as [`read`] checks it (only its header and tables
/// when `checked_before`: see [`check_with`]), its stars parsed when first read ([`Stars`]).
pub fn read_mapped(map: Arc<memmap2::Mmap>, source: &str, checked_before: bool) -> Result<Catalog> {
    let layout = check_with(&map, source, !checked_before)?;
    let stars = Stars::mapped(Arc::clone(&map), layout.records_at, layout.count);
    Ok(layout.catalog(stars, &map, source))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Catalog {
        let csv = "id,ra_deg,dec_deg,mag,pmra_mas_yr,pmdec_mas_yr,epoch,hip\n\
                   north,10,89.9,3,100,-50,2010.25,1\n\
                   equator b,359.99,0,4,,,,\n\
                   south,180,-89.5,5,1,2,1991.25,\n\
                   \"a, b\",0.01,0.5,6,,,,77\n";
        let imp = crate::catalog::formats::read(csv.as_bytes(), None, None, "s").unwrap();
        Catalog::new(imp.stars, imp.names, "s", 0)
    }

    #[test]
    fn write_then_read_gives_the_same_stars_and_ids() {
        let cat = sample();
        let bytes = write(&cat);
        let back = read(&bytes, "f").unwrap();
        assert_eq!(back.stars.len(), cat.stars.len());
        // Stars come back in cell order; as sets they are identical, field by field.
        for s in cat.stars.iter() {
            let b = back.stars.iter().find(|b| b.id == s.id).unwrap();
            assert_eq!(b, s);
        }
        // Mapped, the same stars: magnitudes read from the records before they are parsed.
        let mut f = tempfile::NamedTempFile::new().unwrap();
        std::io::Write::write_all(&mut f, &bytes).unwrap();
        // SAFETY: a temporary file of this test only.
        let map = Arc::new(unsafe { memmap2::Mmap::map(f.as_file()) }.unwrap());
        let mapped = read_mapped(map, "f", false).unwrap();
        assert_eq!(mapped.stars.len(), back.stars.len());
        let mags: Vec<f64> = (0..mapped.stars.len())
            .map(|i| mapped.stars.mag(i))
            .collect();
        assert_eq!(mapped.sorted_mags(), back.sorted_mags());
        assert_eq!(mapped.stars, back.stars);
        assert_eq!(mags, back.stars.iter().map(|s| s.mag).collect::<Vec<_>>());
        assert_eq!(mapped.content_hash, back.content_hash);
        for i in 0..cat.stars.len() {
            let j = back
                .stars
                .iter()
                .position(|b| b.id == cat.stars[i].id)
                .unwrap();
            assert_eq!(back.catalog_id(j), cat.catalog_id(i));
        }
        assert_eq!(back.index().order, (0..4).collect::<Vec<u32>>());
        // Writing what was read gives the same bytes; the hash follows the content.
        assert_eq!(write(&back), bytes);
        assert_ne!(back.content_hash, 0);
        // A Gaia and a Tycho-2 id survive too.
        let mut stars = cat.stars.to_vec();
        stars[0].id = StarId::GaiaDr3(1576683529448755328);
        stars[1].id = StarId::Tycho2 {
            tyc1: 9537,
            tyc2: 12121,
            tyc3: 3,
        };
        let other = Catalog::new(stars, cat.names.to_vec(), "o", 0);
        let b2 = read(&write(&other), "g").unwrap();
        assert!(b2.stars.iter().any(|s| s.id == other.stars[0].id));
        assert!(b2.stars.iter().any(|s| s.id == other.stars[1].id));
        assert_ne!(b2.content_hash, back.content_hash);
    }

    #[test]
    fn truncated_or_damaged_files_are_refused_with_a_message() {
        let bytes = write(&sample());
        for cut in [0, 8, 40, HEADER, bytes.len() / 2, bytes.len() - 1] {
            let msg = read(&bytes[..cut], "f").unwrap_err().to_string();
            assert!(msg.starts_with("f: "), "{msg}");
        }
        let e = read(&bytes[..bytes.len() - 1], "f")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("truncated"), "{e}");
        let mut flipped = bytes.clone();
        let mid = HEADER + (bytes.len() - HEADER) / 2;
        flipped[mid] ^= 0x10;
        let e = read(&flipped, "f").err().unwrap().to_string();
        assert!(e.contains("checksum"), "{e}");
        let mut future = bytes.clone();
        future[8] = 9;
        let e = read(&future, "f").err().unwrap().to_string();
        assert!(e.contains("version 9"), "{e}");
        // Header fields that do not add up (with the CRC still right) are refused, no panic.
        let mut lying = bytes.clone();
        lying[16..24].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(read(&lying, "f").is_err());
    }
}
