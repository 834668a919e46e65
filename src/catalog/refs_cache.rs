//! A run's selection of reference stars, kept in the cache directory beside the distance
//! tables and pattern indexes it keys: a deep catalog's selection (Tycho-2's 1.9 million stars:
//! propagated, double stars merged, sorted by brightness) took about a second of every run,
//! half of a narrow frame's whole process; mapped from its file it takes a few milliseconds.
//! The catalog's sorted magnitudes, which choose the selection's magnitude limit, are kept
//! beside it.

use super::ref_record::RefRecord;
use super::reference::selection_text;
use super::table::{CacheReader, write_cache};
use super::{Catalog, RefCatalog, Selection, fnv1a};
use crate::error::{Result, fail};
use std::path::Path;
use std::sync::Arc;

/// Catalogs smaller than this are selected afresh: their selection takes a few milliseconds,
/// less than a file of their own is worth. The built-in catalog (78,352 stars to Hp 9) is
/// above it: selected afresh, with its magnitudes sorted, it took 10–20 ms of a one-frame
/// run's 30–40 ms of CPU (docs/speed.md, "The built-in catalog's selection, cached").
pub const CACHED_FROM_STARS: usize = 50_000;

const MAGIC: &[u8; 8] = b"GPSREF01";
/// Header words: stars, stars removed as doubles, the largest proper motion (f64 bits).
const HEADS: usize = 3;

/// [`RefCatalog::select`], through the cache directory
/// ([`table::cache_dir`](super::table::cache_dir)) when `use_cache` and the catalog holds at
/// least [`CACHED_FROM_STARS`] stars.
pub fn load_or_select(
    catalog: &Catalog,
    selection: Selection,
    use_cache: bool,
) -> Result<RefCatalog> {
    let dir =
        super::table::cache_dir().filter(|_| use_cache && catalog.stars.len() >= CACHED_FROM_STARS);
    load_or_select_in(dir.as_deref(), catalog, selection)
}

/// [`load_or_select`] with the cache in `dir` (None: none), whatever the catalog's size.
pub(crate) fn load_or_select_in(
    dir: Option<&Path>,
    catalog: &Catalog,
    selection: Selection,
) -> Result<RefCatalog> {
    let Some(dir) = dir else {
        return RefCatalog::select(catalog, selection);
    };
    let text = format!(
        "gpustar-refs-v1|{}|{}",
        selection_text(&selection, catalog.content_hash),
        catalog.stars.len()
    );
    let key = fnv1a(text.as_bytes());
    let file = dir.join(format!("refs-{key:016x}.bin"));
    if file.exists() {
        match read_refs(dir, &file, key, catalog, selection) {
            Ok(refs) => return Ok(refs),
            Err(e) => tracing::warn!(
                "the cached star selection {} cannot be used ({e:#}): selecting again",
                file.display()
            ),
        }
    }
    let refs = RefCatalog::select(catalog, selection)?;
    let head = [
        refs.stars.len() as u64,
        refs.doubles_removed as u64,
        refs.max_motion.to_bits(),
    ];
    if let Err(e) = write_cache(
        &file,
        MAGIC,
        key,
        &head,
        bytemuck::cast_slice(&refs.stars[..]),
    ) {
        tracing::warn!(
            "could not write the star selection {}: {e:#}",
            file.display()
        );
    }
    Ok(refs)
}

/// The catalog's sorted magnitudes ([`Catalog::sorted_mags`], which the automatic magnitude
/// limit reads) from the cache directory when `use_cache` and the catalog holds at least
/// [`CACHED_FROM_STARS`] stars, or sorted now and stored there: sorting Tycho-2's 1.9 million
/// from the mapped records took a sixth of a narrow frame's run.
pub fn load_sorted_mags(catalog: &Catalog, use_cache: bool) {
    let dir = super::table::cache_dir();
    if let Some(dir) = dir.filter(|_| use_cache && catalog.stars.len() >= CACHED_FROM_STARS) {
        load_sorted_mags_in(&dir, catalog);
    }
}

/// [`load_sorted_mags`] with the cache in `dir`, whatever the catalog's size.
pub(crate) fn load_sorted_mags_in(dir: &Path, catalog: &Catalog) {
    if catalog.mags.get().is_some() {
        return;
    }
    let text = format!(
        "gpustar-mags-v1|{:016x}|{}",
        catalog.content_hash,
        catalog.stars.len()
    );
    let key = fnv1a(text.as_bytes());
    let file = dir.join(format!("mags-{key:016x}.bin"));
    if file.exists() {
        match read_mags(&file, key, catalog.stars.len()) {
            Ok(mags) => {
                let _ = catalog.mags.set(mags);
                return;
            }
            Err(e) => tracing::warn!(
                "the cached magnitudes {} cannot be used ({e:#}): sorting again",
                file.display()
            ),
        }
    }
    let mags = catalog.sorted_mags();
    if let Err(e) = write_cache(
        &file,
        MAGS_MAGIC,
        key,
        &[mags.len() as u64],
        bytemuck::cast_slice(mags),
    ) {
        tracing::warn!("could not write the magnitudes {}: {e:#}", file.display());
    }
}

const MAGS_MAGIC: &[u8; 8] = b"GPSMAG01";

/// Sorted magnitudes of a cache file, checked whole: the checksum, the count, the order.
fn read_mags(path: &Path, key: u64, stars: usize) -> Result<Vec<f64>> {
    let (head, mut body) = CacheReader::open(path, MAGS_MAGIC, key, 1)?;
    if head[0] != stars as u64 || body.words_left != 2 * stars {
        fail!(
            Catalog,
            "{} words where {stars} magnitudes need {}",
            body.words_left,
            2 * stars
        );
    }
    let mags = body.read::<f64>(stars)?.into_vec();
    body.finish()?;
    if !mags.windows(2).all(|w| w[0].total_cmp(&w[1]).is_le()) {
        fail!(Catalog, "magnitudes not sorted");
    }
    Ok(mags)
}

/// The selection of a cache file, checked whole: the checksum, then every record's id (a
/// file that passes gives back the stars it was written with); only its header and length
/// when it passed that check in an earlier run and has not changed since (`checked`'s stamp
/// in `dir`: the checksum of Tycho-2's 146 MB took a sixth of a narrow frame's run).
fn read_refs(
    dir: &Path,
    path: &Path,
    key: u64,
    catalog: &Catalog,
    selection: Selection,
) -> Result<RefCatalog> {
    let before = super::checked::passed(dir, path);
    let open = if before {
        CacheReader::open_unchecked
    } else {
        CacheReader::open
    };
    let (head, mut body) = open(path, MAGIC, key, HEADS)?;
    let n = usize::try_from(head[0]).unwrap_or(usize::MAX);
    let words = std::mem::size_of::<RefRecord>() / 4;
    if n.checked_mul(words) != Some(body.words_left) {
        fail!(
            Catalog,
            "{} words where {n} stars need {}",
            body.words_left,
            n.saturating_mul(words)
        );
    }
    let stars = body.read::<RefRecord>(n)?;
    body.finish()?;
    let names = catalog.names.len();
    let sound = |r: &RefRecord| match r.star_id() {
        Some(super::StarId::Name(i)) => (i as usize) < names,
        Some(_) => r.members >= 1 && r.zero == 0,
        None => false,
    };
    if n < 3 || !(before || stars.iter().all(sound)) {
        fail!(Catalog, "a star with no id the catalog can have");
    }
    let max_motion = f64::from_bits(head[2]);
    if !(max_motion.is_finite() && max_motion >= 0.0) {
        fail!(Catalog, "bad largest proper motion");
    }
    if !before {
        super::checked::mark(dir, path);
    }
    Ok(RefCatalog {
        stars: Arc::new(stars),
        stars_epoch: selection.epoch,
        max_motion,
        selection,
        doubles_removed: usize::try_from(head[1]).unwrap_or(usize::MAX),
        names: catalog.names.clone(),
        cones: Arc::default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalog::DoubleStars;
    use nalgebra::Vector3;

    /// The selection read back from its cache file is the one made afresh, star for star;
    /// a damaged file is selected again, not used.
    #[test]
    fn a_cached_selection_is_the_fresh_one() {
        let catalog = Catalog::builtin();
        let selection = Selection {
            epoch: 2026.5,
            mag_limit: 6.5,
            double_stars: DoubleStars::Merge,
            double_sep_rad: 3e-4,
        };
        let fresh = RefCatalog::select(&catalog, selection).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let written = load_or_select_in(Some(dir.path()), &catalog, selection).unwrap();
        let read = load_or_select_in(Some(dir.path()), &catalog, selection).unwrap();
        for refs in [&written, &read] {
            assert_eq!(refs.len(), fresh.len());
            assert_eq!(&refs.stars[..], &fresh.stars[..]);
            assert_eq!(refs.doubles_removed, fresh.doubles_removed);
            assert_eq!(refs.max_motion.to_bits(), fresh.max_motion.to_bits());
        }
        assert!(fresh.doubles_removed > 0, "the test merges some doubles");
        let file = std::fs::read_dir(dir.path())
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        let mut bytes = std::fs::read(&file).unwrap();
        let mid = bytes.len() / 2;
        bytes[mid] ^= 1;
        std::fs::write(&file, &bytes).unwrap();
        assert!(
            read_refs(dir.path(), &file, 0, &catalog, selection).is_err(),
            "another key"
        );
        let again = load_or_select_in(Some(dir.path()), &catalog, selection).unwrap();
        assert_eq!(&again.stars[..], &fresh.stars[..]);
        // The sorted magnitudes, written, read back, and sorted again when damaged: the same
        // bits each time.
        let sorted = Catalog::builtin().sorted_mags().to_vec();
        let mags_dir = tempfile::tempdir().unwrap();
        for round in 0..3 {
            if round == 2 {
                let file = std::fs::read_dir(mags_dir.path()).unwrap().next().unwrap();
                let file = file.unwrap().path();
                let mut bytes = std::fs::read(&file).unwrap();
                let at = bytes.len() / 3;
                bytes[at] ^= 0x40;
                std::fs::write(&file, &bytes).unwrap();
            }
            let c = Catalog::builtin();
            load_sorted_mags_in(mags_dir.path(), &c);
            let got = c.mags.get().expect("loaded or sorted");
            assert_eq!(got.len(), sorted.len(), "round {round}");
            assert!(
                got.iter()
                    .zip(&sorted)
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
        }
        // A position moved by its motion reads the same from either.
        let later = read.at_epoch(2030.0);
        let v: Vector3<f64> = later.v(7);
        assert_eq!(v, fresh.at_epoch(2030.0).v(7));
    }

    /// The built-in catalog's selections and magnitudes are cached: selected afresh they were
    /// half of a one-frame run.
    #[test]
    fn the_builtin_catalog_is_cached() {
        assert!(Catalog::builtin().stars.len() >= CACHED_FROM_STARS);
    }
}
