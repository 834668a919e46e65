//! The distance table (seed 000, "T(d, ID1, ID2)"): every pair of reference stars closer than
//! the camera's diagonal, sorted by a u32 chord key computed in f64, with a k-vector of bin
//! starts so that a range query starts in constant time.
//!
//! Keys: `key = floor(chord · 2³¹)` where `chord = |a − b| = 2 sin(θ/2)` of the unit vectors, so a
//! key step is 4.7e-10 rad (0.0001″). Keys depend on nothing but the two directions; the GPU
//! compares keys, never angles (see STYLE.md: f32 trig is off by arcseconds).

use crate::catalog::RefCatalog;
use crate::catalog::words::Words;
use crate::error::{Context, Error, IntoKind, Result, fail};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

/// Scale of the chord keys: key = floor(chord · KEY_SCALE).
pub const KEY_SCALE: f64 = 2147483648.0; // 2^31

/// The u32 key of a chord length (clamped to the u32 range).
pub fn chord_key(chord: f64) -> u32 {
    (chord * KEY_SCALE).floor().clamp(0.0, u32::MAX as f64) as u32
}

/// The chord of an angle (radians).
pub fn chord_of_angle(theta: f64) -> f64 {
    2.0 * (theta.clamp(0.0, std::f64::consts::PI) / 2.0).sin()
}

/// The angle of a chord (radians).
pub fn angle_of_chord(chord: f64) -> f64 {
    2.0 * (chord / 2.0).clamp(0.0, 1.0).asin()
}

/// Sorted pair table with its k-vector.
#[derive(Clone, Debug, PartialEq)]
pub struct PairTable {
    /// Chord keys, ascending.
    pub keys: Words<u32>,
    /// The two reference-star ids of each row, `[a, b]` with a < b: 32-bit ids, so a
    /// catalog selection of any size fits (the GPU reads them as `vec2<u32>`).
    pub pairs: Words<[u32; 2]>,
    /// `kvector[b]` = first row whose `key >> shift >= b`; one extra entry = number of rows.
    pub kvector: Words<u32>,
    /// Bin width of the k-vector as a shift of the key.
    pub shift: u32,
    /// Largest separation included (radians) and its key.
    pub max_sep_rad: f64,
    pub max_key: u32,
}

/// A half-open row range `[start, end)` of the table.
pub type RowRange = std::ops::Range<usize>;

impl PairTable {
    /// Build the table from reference stars: all pairs with angle < `max_sep_rad`.
    pub fn build(cat: &RefCatalog, max_sep_rad: f64) -> PairTable {
        let stars: Vec<_> = cat.stars().collect();
        let max_chord = chord_of_angle(max_sep_rad);
        let max_key = chord_key(max_chord);
        // Cubes of side max_chord over the unit vectors: a pair closer than max_chord lies in
        // the same or adjacent cubes (each coordinate differs by less than the side). A deep
        // catalog's 400,000 stars then compare with about 700 neighbours each, not the 10,000
        // of a sweep in z alone (31 s → under 2 s for Gaia G ≤ 10 at 2°).
        let side = max_chord.max(1e-9);
        let cell_of = |v: &nalgebra::Vector3<f64>| {
            let c = |x: f64| (x / side).floor() as i32;
            (c(v.x), c(v.y), c(v.z))
        };
        let mut order: Vec<u32> = (0..stars.len() as u32).collect();
        order.sort_by_key(|&a| (cell_of(&stars[a as usize].v), a));
        let mut cells: rustc_hash::FxHashMap<(i32, i32, i32), std::ops::Range<usize>> =
            Default::default();
        let mut start = 0;
        for k in 1..=order.len() {
            let here = cell_of(&stars[order[start] as usize].v);
            if k == order.len() || cell_of(&stars[order[k] as usize].v) != here {
                cells.insert(here, start..k);
                start = k;
            }
        }
        let mut rows: Vec<(u32, u32, u32)> = Vec::new();
        for (a, sa) in stars.iter().enumerate() {
            let (cx, cy, cz) = cell_of(&sa.v);
            for (dx, dy, dz) in NEIGHBOURS {
                let Some(range) = cells.get(&(cx + dx, cy + dy, cz + dz)) else {
                    continue;
                };
                for &b in &order[range.clone()] {
                    if b as usize <= a {
                        continue;
                    }
                    let chord = (sa.v - stars[b as usize].v).norm();
                    if chord < max_chord {
                        rows.push((chord_key(chord), b, a as u32));
                    }
                }
            }
        }
        // Sorting by (key, b, a) makes the table independent of the sweep order (and keeps the
        // row order of the 16-bit packing `a | b << 16`, which sorted the same way).
        rows.sort_unstable();
        let keys: Vec<u32> = rows.iter().map(|r| r.0).collect();
        let pairs: Vec<[u32; 2]> = rows.iter().map(|&(_, b, a)| [a, b]).collect();
        let shift = kvector_shift(max_key, keys.len());
        let kvector = build_kvector(&keys, shift, max_key);
        PairTable {
            keys: keys.into(),
            pairs: pairs.into(),
            kvector: kvector.into(),
            shift,
            max_sep_rad,
            max_key,
        }
    }

    pub fn len(&self) -> usize {
        self.keys.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// Bytes held by keys, pairs and the k-vector.
    pub fn bytes(&self) -> usize {
        4 * (self.keys.len() + 2 * self.pairs.len() + self.kvector.len())
    }

    /// Rows with `lo <= key <= hi`: the k-vector gives the bin start, a short forward scan the
    /// first row (a bin holds a few rows on average).
    pub fn range(&self, lo: u32, hi: u32) -> RowRange {
        let start = self.lower_bound(lo);
        let end = match hi.checked_add(1) {
            Some(h) => self.lower_bound(h),
            None => self.keys.len(),
        };
        start..end.max(start)
    }

    /// First row with key >= `key`.
    pub fn lower_bound(&self, key: u32) -> usize {
        let bin = (key >> self.shift) as usize;
        if bin >= self.kvector.len() - 1 {
            return self.keys.len();
        }
        let mut i = self.kvector[bin] as usize;
        let end = self.kvector[bin + 1] as usize;
        while i < end && self.keys[i] < key {
            i += 1;
        }
        i
    }

    /// The two reference-star ids of row `r`.
    pub fn pair(&self, r: usize) -> (u32, u32) {
        let [a, b] = self.pairs[r];
        (a, b)
    }
}

/// The 27 offsets of a cube and its neighbours.
const NEIGHBOURS: [(i32, i32, i32); 27] = {
    let mut out = [(0, 0, 0); 27];
    let mut k = 0;
    while k < 27 {
        out[k] = (k as i32 % 3 - 1, k as i32 / 3 % 3 - 1, k as i32 / 9 - 1);
        k += 1;
    }
    out
};

/// Choose the bin width so that there are about as many bins as rows (≥ 1 bin).
fn kvector_shift(max_key: u32, rows: usize) -> u32 {
    let mut shift = 0;
    while shift < 31 && ((max_key >> shift) as usize) > rows.max(1) {
        shift += 1;
    }
    shift
}

/// Whether `kv` is what [`build_kvector`] makes of `keys` (sorted): its length, and each entry
/// the first row whose bin is at least the entry's (the row before it in a lower bin), without
/// building a second k-vector of megabytes to compare.
fn kvector_indexes(kv: &[u32], keys: &[u32], shift: u32, max_key: u32) -> bool {
    let bins = (max_key >> shift) as usize + 1;
    let bin = |r: usize| (keys[r] >> shift) as usize;
    kv.len() == bins + 1
        && kv.iter().enumerate().all(|(b, &r)| {
            let r = r as usize;
            r <= keys.len() && (r == keys.len() || bin(r) >= b) && (r == 0 || bin(r - 1) < b)
        })
}

fn build_kvector(keys: &[u32], shift: u32, max_key: u32) -> Vec<u32> {
    let bins = (max_key >> shift) as usize + 1;
    let mut kv = vec![0u32; bins + 1];
    let mut row = 0usize;
    for (b, slot) in kv.iter_mut().enumerate() {
        while row < keys.len() && ((keys[row] >> shift) as usize) < b {
            row += 1;
        }
        *slot = row as u32;
    }
    kv
}

/// What a table depends on, hashed into its cache file name.
pub fn cache_key(cat: &RefCatalog, catalog_hash: u64, max_sep_rad: f64) -> u64 {
    let text = format!(
        "gpustar-table-v{}|{}|{}|{}",
        FORMAT_VERSION,
        super::selection_key_text(cat, catalog_hash),
        max_sep_rad,
        cat.len()
    );
    crate::catalog::fnv1a(text.as_bytes())
}

const FORMAT_VERSION: u32 = 2;
/// Version 2 adds the checksum; version 3 has 32-bit star ids (two words a pair).
const MAGIC: &[u8; 8] = b"GPSTBL03";

/// Where cached tables live: `$GPUSTAR_CACHE_DIR`, else `$XDG_CACHE_HOME/gpustar`, else
/// `~/.cache/gpustar`.
pub fn cache_dir() -> Option<PathBuf> {
    // An empty variable is unset (as XDG says), not the working directory.
    let var = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    if let Some(d) = var("GPUSTAR_CACHE_DIR") {
        return Some(d);
    }
    if let Some(d) = var("XDG_CACHE_HOME") {
        return Some(d.join("gpustar"));
    }
    var("HOME").map(|h| h.join(".cache").join("gpustar"))
}

/// How the table of a run was obtained.
#[derive(Clone, Debug)]
pub struct TableOrigin {
    /// Built now (false: read from the cache).
    pub built: bool,
    /// Time to build or read, seconds.
    pub seconds: f64,
    /// The cache file, if a cache was used.
    pub cache_file: Option<PathBuf>,
    /// Why the cache could not be used, if so.
    pub cache_note: Option<String>,
}

/// Load the table from the cache ([`cache_dir`]), or build it (and try to store it).
pub fn load_or_build(
    cat: &RefCatalog,
    catalog_hash: u64,
    max_sep_rad: f64,
    use_cache: bool,
) -> (PairTable, TableOrigin) {
    let dir = cache_dir().filter(|_| use_cache);
    load_or_build_in(dir.as_deref(), cat, catalog_hash, max_sep_rad)
}

/// [`load_or_build`] with the cache in `dir` (None: no cache).
pub fn load_or_build_in(
    dir: Option<&Path>,
    cat: &RefCatalog,
    catalog_hash: u64,
    max_sep_rad: f64,
) -> (PairTable, TableOrigin) {
    let t0 = Instant::now();
    let key = cache_key(cat, catalog_hash, max_sep_rad);
    let file = dir.map(|d| d.join(format!("table-{key:016x}.bin")));
    let mut note = None;
    if let Some(f) = &file
        && f.exists()
    {
        match read_table(f, key, cat.len(), max_sep_rad) {
            Ok(t) => {
                return (
                    t,
                    TableOrigin {
                        built: false,
                        seconds: t0.elapsed().as_secs_f64(),
                        cache_file: file.clone(),
                        cache_note: None,
                    },
                );
            }
            Err(e) => {
                tracing::warn!(
                    "the cached distance table {} cannot be used ({e:#}): building it again",
                    f.display()
                );
                note = Some(format!("ignored cache {}: {e:#}", f.display()));
            }
        }
    }
    let table = PairTable::build(cat, max_sep_rad);
    let seconds = t0.elapsed().as_secs_f64();
    if let Some(f) = &file
        && let Err(e) = write_table(f, key, &table)
    {
        note = Some(format!("could not write cache {}: {e:#}", f.display()));
    }
    (
        table,
        TableOrigin {
            built: true,
            seconds,
            cache_file: file,
            cache_note: note,
        },
    )
}

fn write_table(path: &Path, key: u64, t: &PairTable) -> Result<()> {
    let head = [
        t.keys.len() as u64,
        t.kvector.len() as u64,
        t.shift as u64,
        t.max_key as u64,
    ];
    let mut body = Vec::with_capacity(t.bytes() / 4);
    body.extend_from_slice(&t.keys);
    body.extend_from_slice(bytemuck::cast_slice(&t.pairs));
    body.extend_from_slice(&t.kvector);
    write_cache(path, MAGIC, key, &head, &body)
}

/// Write a cache file: magic, key, header words, body words, and a CRC-32 of all that (a
/// file scribbled on or cut short is found out when it is read back, and rebuilt).
pub(crate) fn write_cache(
    path: &Path,
    magic: &[u8; 8],
    key: u64,
    head: &[u64],
    body: &[u32],
) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("create {}", dir.display()))?;
    }
    let mut buf = Vec::with_capacity(16 + 8 * head.len() + 4 * body.len() + 4);
    buf.extend_from_slice(magic);
    buf.extend_from_slice(&key.to_le_bytes());
    for v in head {
        buf.extend_from_slice(&v.to_le_bytes());
    }
    for v in body {
        buf.extend_from_slice(&v.to_le_bytes());
    }
    let crc = crc32fast::hash(&buf);
    buf.extend_from_slice(&crc.to_le_bytes());
    // Write to a temporary name and rename, so a concurrent reader never sees half a file.
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    std::fs::write(&tmp, &buf)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}

/// Read a cache file written by [`write_cache`] with `heads` header words: the header and the
/// body, or why the file cannot be used (another magic or key, a length that disagrees, a
/// checksum that does not match).
pub(crate) fn read_cache(
    path: &Path,
    magic: &[u8; 8],
    key: u64,
    heads: usize,
) -> Result<(Vec<u64>, Vec<u32>)> {
    let (head, mut body) = CacheReader::open(path, magic, key, heads)?;
    let words = body.read(body.words_left)?;
    body.finish()?;
    Ok((head, words.into_vec()))
}

/// A cache file written by [`write_cache`], its header read and checked, its body mapped
/// read-only and handed out as the caller's columns (see [`Words`]: fresh memory's page faults
/// were most of a load), its checksum taken on the way and checked by [`CacheReader::finish`]
/// before anything read is used (unless opened with [`CacheReader::open_unchecked`]).
pub(crate) struct CacheReader {
    map: Arc<memmap2::Mmap>,
    /// Byte offset of the next value.
    at: usize,
    /// None: the body's checksum is not taken.
    crc: Option<crc32fast::Hasher>,
    /// Body words not read yet.
    pub(crate) words_left: usize,
}

impl CacheReader {
    pub(crate) fn open(
        path: &Path,
        magic: &[u8; 8],
        key: u64,
        heads: usize,
    ) -> Result<(Vec<u64>, Self)> {
        let file = std::fs::File::open(path)?;
        let len = file.metadata()?.len();
        let fixed = 16 + 8 * heads as u64;
        if len < fixed + 4 || !(len - fixed - 4).is_multiple_of(4) {
            fail!(Catalog, "truncated ({len} bytes)");
        }
        // SAFETY: the cache directory is gpustar's own, and its files are replaced by rename,
        // never rewritten in place (write_cache), so the mapped file does not change under us.
        let map = Arc::new(unsafe { memmap2::Mmap::map(&file) }?);
        if map.len() as u64 != len {
            fail!(Catalog, "changed while it was opened");
        }
        let fixed = fixed as usize;
        let head = &map[..fixed];
        if &head[..8] != magic.as_slice() {
            fail!(Catalog, "not a gpustar cache file of this version");
        }
        let u64_at = |o: usize| u64::from_le_bytes(head[o..o + 8].try_into().expect("8 bytes"));
        if u64_at(8) != key {
            fail!(Catalog, "key mismatch");
        }
        let mut crc = crc32fast::Hasher::new();
        crc.update(head);
        let words_left = (map.len() - fixed - 4) / 4;
        let values = (0..heads).map(|i| u64_at(16 + 8 * i)).collect();
        Ok((
            values,
            CacheReader {
                map,
                at: fixed,
                crc: Some(crc),
                words_left,
            },
        ))
    }

    /// [`CacheReader::open`] for a file whose reader checks what it uses as it uses it, its
    /// checksum not taken: reading all of a 1.7 GB pattern index to check it took longer than
    /// a frame's identification.
    pub(crate) fn open_unchecked(
        path: &Path,
        magic: &[u8; 8],
        key: u64,
        heads: usize,
    ) -> Result<(Vec<u64>, Self)> {
        let (head, reader) = Self::open(path, magic, key, heads)?;
        Ok((
            head,
            CacheReader {
                crc: None,
                ..reader
            },
        ))
    }

    /// The next `n` values of the body (each a whole number of little-endian words).
    pub(crate) fn read<T: bytemuck::Pod>(&mut self, n: usize) -> Result<Words<T>> {
        let words = n.saturating_mul(std::mem::size_of::<T>() / 4);
        if words > self.words_left {
            fail!(
                Catalog,
                "truncated (the body is shorter than its header says)"
            );
        }
        let bytes = &self.map[self.at..self.at + 4 * words];
        if let Some(crc) = &mut self.crc {
            crc.update(bytes);
        }
        let mapped = if cfg!(target_endian = "little") {
            Words::mapped(&self.map, self.at, n)
        } else {
            None
        };
        let values = mapped.unwrap_or_else(|| {
            // Big-endian (or, never with these files, misaligned): a converted copy.
            let mut v = vec![T::zeroed(); n];
            bytemuck::cast_slice_mut::<T, u8>(&mut v).copy_from_slice(bytes);
            for w in bytemuck::cast_slice_mut::<T, u32>(&mut v) {
                *w = u32::from_le(*w);
            }
            v.into()
        });
        self.at += 4 * words;
        self.words_left -= words;
        Ok(values)
    }

    /// The whole body read, and the checksum the file ends with is that of what was read.
    pub(crate) fn finish(self) -> Result<()> {
        if self.words_left != 0 {
            fail!(Catalog, "{} words left over", self.words_left);
        }
        let Some(taken) = self.crc else {
            return Ok(());
        };
        let crc = &self.map[self.at..self.at + 4];
        if taken.finalize() != u32::from_le_bytes(crc.try_into().expect("4 bytes")) {
            fail!(
                Catalog,
                "checksum mismatch (the file was changed or damaged)"
            );
        }
        Ok(())
    }
}

/// The table of a cache file, checked whole: the checksum, then every bound the range
/// queries and the GPU rely on (a file that passes cannot make a frame fail).
fn read_table(path: &Path, key: u64, stars: usize, max_sep_rad: f64) -> Result<PairTable> {
    let (head, mut body) = CacheReader::open(path, MAGIC, key, 4)?;
    let (rows, kvlen) = (head[0] as usize, head[1] as usize);
    if body.words_left != rows.saturating_mul(3).saturating_add(kvlen) {
        fail!(
            Catalog,
            "{} words where {rows} rows and a k-vector of {kvlen} need {}",
            body.words_left,
            rows.saturating_mul(3).saturating_add(kvlen)
        );
    }
    let t = PairTable {
        keys: body.read(rows)?,
        pairs: body.read(rows)?,
        kvector: body.read(kvlen)?,
        shift: u32::try_from(head[2]).into_kind(Error::Catalog)?,
        max_sep_rad,
        max_key: u32::try_from(head[3]).into_kind(Error::Catalog)?,
    };
    body.finish()?;
    if t.max_key != chord_key(chord_of_angle(max_sep_rad))
        || t.shift != kvector_shift(t.max_key, rows)
    {
        fail!(Catalog, "made for another separation");
    }
    if !t.keys.windows(2).all(|w| w[0] <= w[1]) || t.keys.last().is_some_and(|&k| k > t.max_key) {
        fail!(Catalog, "keys not sorted or beyond the largest separation");
    }
    if !t.pairs.iter().all(|&[a, b]| a < b && (b as usize) < stars) {
        fail!(Catalog, "a pair names a star the catalog does not have");
    }
    if !kvector_indexes(&t.kvector, &t.keys, t.shift, t.max_key) {
        fail!(Catalog, "the k-vector does not index the keys");
    }
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The check of a cached k-vector accepts the one `build_kvector` makes and refuses it with
    /// any entry moved by one row, or with an entry more or fewer.
    #[test]
    fn the_kvector_check_is_the_rebuild() {
        // Sorted keys with gaps, repeats, empty bins and keys at bin edges.
        let keys: Vec<u32> = vec![0, 0, 3, 4, 4, 4, 15, 16, 17, 40, 63, 63, 64];
        let (shift, max_key) = (2, 70);
        let kv = build_kvector(&keys, shift, max_key);
        assert!(kvector_indexes(&kv, &keys, shift, max_key));
        for b in 0..kv.len() {
            for moved in [kv[b].wrapping_sub(1), kv[b] + 1] {
                let mut bad = kv.clone();
                bad[b] = moved;
                assert!(!kvector_indexes(&bad, &keys, shift, max_key), "entry {b}");
            }
        }
        assert!(!kvector_indexes(&kv[..kv.len() - 1], &keys, shift, max_key));
        let mut longer = kv.clone();
        longer.push(keys.len() as u32);
        assert!(!kvector_indexes(&longer, &keys, shift, max_key));
        // No keys at all: every entry is row 0.
        let none = build_kvector(&[], shift, max_key);
        assert!(kvector_indexes(&none, &[], shift, max_key));
    }
}
