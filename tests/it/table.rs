//! The distance table: range queries at bin edges, agreement with seed 000's Table 3, cache.

use gpustar::catalog::table::{PairTable, chord_key, chord_of_angle};
use gpustar::catalog::{Catalog, DoubleStars, RefCatalog, Selection};

fn refs(mag: f64) -> RefCatalog {
    RefCatalog::select(
        &Catalog::builtin(),
        Selection {
            epoch: 2000.0,
            mag_limit: mag,
            double_stars: DoubleStars::Keep,
            double_sep_rad: 0.0,
        },
    )
    .unwrap()
}

/// Rows with lo ≤ key ≤ hi by brute force.
fn brute(t: &PairTable, lo: u32, hi: u32) -> std::ops::Range<usize> {
    let start = t.keys.iter().position(|&k| k >= lo).unwrap_or(t.len());
    let end = t.keys.iter().position(|&k| k > hi).unwrap_or(t.len());
    start..end.max(start)
}

#[test]
fn range_queries_agree_with_brute_force_at_bin_edges_and_row_keys() {
    let t = PairTable::build(&refs(5.0), 12f64.to_radians());
    assert!(t.len() > 10_000);
    assert!(t.keys.windows(2).all(|w| w[0] <= w[1]), "sorted");
    let s = t.shift;
    let mut probes = vec![0u32, 1, t.max_key, t.max_key.saturating_add(1), u32::MAX];
    for b in [1u32, 2, 17, 1000, (t.max_key >> s) - 1, t.max_key >> s] {
        // Exactly on a bin edge, one below, one above.
        probes.extend([(b << s) - 1, b << s, (b << s) + 1]);
    }
    for r in [0, 1, t.len() / 3, t.len() / 2, t.len() - 2, t.len() - 1] {
        // Exactly a row's key (inclusive ends), one below and one above.
        let k = t.keys[r];
        probes.extend([k.saturating_sub(1), k, k.saturating_add(1)]);
    }
    for &lo in &probes {
        for &hi in &probes {
            assert_eq!(t.range(lo, hi), brute(&t, lo, hi), "range({lo}, {hi})");
        }
    }
    // Every row's pair really has its key.
    let cat = refs(5.0);
    for r in (0..t.len()).step_by(997) {
        let (a, b) = t.pair(r);
        assert!(a < b);
        let chord = (cat.v(a as usize) - cat.v(b as usize)).norm();
        assert_eq!(chord_key(chord), t.keys[r]);
        assert!(chord < chord_of_angle(12f64.to_radians()));
    }
}

#[test]
fn table_sizes_agree_with_seed_000_table_3() {
    // Seed 000, Table 3 (Tycho-2, V ≤ 6, 4,569 stars): rows for D = 5°, 10°, 15°, 20°.
    // Ours: Hipparcos-2, Hp ≤ 6 (4,559 stars); the counts should agree within a few percent.
    let cat = refs(6.0);
    assert!((cat.len() as i64 - 4569).abs() < 100, "{} stars", cat.len());
    for (deg, rows) in [
        (5.0, 23_481.0),
        (10.0, 91_096.0),
        (15.0, 201_692.0),
        (20.0, 352_429.0),
    ] {
        let t = PairTable::build(&cat, f64::to_radians(deg));
        let ratio = t.len() as f64 / rows;
        println!(
            "D = {deg}°: {} rows, seed 000: {rows}, ratio {ratio:.3}",
            t.len()
        );
        assert!(
            (ratio - 1.0).abs() < 0.05,
            "D = {deg}°: {} rows vs {rows}",
            t.len()
        );
    }
}

#[test]
fn cached_table_is_read_back_identically() {
    let dir = tempfile::tempdir().unwrap();
    let cat = refs(4.5);
    let load_or_build = |cat: &RefCatalog, hash: u64, sep: f64, _: bool| {
        gpustar::catalog::table::load_or_build_in(Some(dir.path()), cat, hash, sep)
    };
    let (built, o1) = load_or_build(&cat, 42, 0.2, true);
    assert!(o1.built && o1.cache_note.is_none(), "{:?}", o1.cache_note);
    let (read, o2) = load_or_build(&cat, 42, 0.2, true);
    assert!(!o2.built);
    assert_eq!(built, read);
    // Another catalog hash is another cache entry.
    let (_, o3) = load_or_build(&cat, 43, 0.2, true);
    assert!(o3.built);
    // A corrupt file is ignored with a note, and rebuilt.
    std::fs::write(o2.cache_file.as_ref().unwrap(), b"garbage").unwrap();
    let (again, o4) = load_or_build(&cat, 42, 0.2, true);
    assert!(o4.built);
    assert!(
        o4.cache_note
            .as_deref()
            .is_some_and(|n| n.contains("ignored")),
        "{:?}",
        o4.cache_note
    );
    assert_eq!(again, built);
}

/// Tables read from the cache are its file mapped (docs/speed.md, "Cached tables mapped"): a
/// table in use stays as it was read when the file is replaced the way gpustar replaces one (a
/// new file renamed over it, as another process rebuilding the cache does) and when it is
/// removed.
#[test]
fn a_mapped_table_outlives_its_cache_file() {
    let dir = tempfile::tempdir().unwrap();
    let load = |dir: &std::path::Path, cat: &RefCatalog| {
        gpustar::catalog::table::load_or_build_in(Some(dir), cat, 9, 0.2)
    };
    let (built, o) = load(dir.path(), &refs(4.5));
    assert!(o.built);
    let (mapped, o) = load(dir.path(), &refs(4.5));
    assert!(!o.built, "read from the cache");
    let file = o.cache_file.unwrap();
    let elsewhere = dir.path().join("elsewhere");
    let (other, o) = load(&elsewhere, &refs(4.0));
    assert_ne!(other, built);
    std::fs::rename(o.cache_file.unwrap(), &file).unwrap();
    assert_eq!(mapped, built, "after a rename over the file");
    std::fs::remove_file(&file).unwrap();
    assert_eq!(mapped, built, "after the file was removed");
}

/// A change to a cache file's bytes, for the tests of damaged files.
type Scribble = Box<dyn Fn(&mut Vec<u8>)>;

/// `good` scribbled on, its checksum recomputed when asked (so that only the bounds checks
/// can find the damage).
fn scribbled(good: &[u8], scribble: &Scribble, recompute_crc: bool) -> Vec<u8> {
    let mut bad = good.to_vec();
    scribble(&mut bad);
    if recompute_crc {
        let n = bad.len() - 4;
        let crc = crc32fast::hash(&bad[..n]);
        bad[n..].copy_from_slice(&crc.to_le_bytes());
    }
    bad
}

/// Issue 22, item 2: a cache file scribbled on (pair ids, the k-vector, the row count; with
/// its checksum recomputed too, so that the bounds checks alone must find it) is never used:
/// it is rebuilt, and the table is the one built from the catalog.
#[test]
fn damaged_cache_files_are_rebuilt() {
    let dir = tempfile::tempdir().unwrap();
    let cat = refs(4.5);
    let table_at =
        |dir: &std::path::Path| gpustar::catalog::table::load_or_build_in(Some(dir), &cat, 7, 0.2);
    let (built, o) = table_at(dir.path());
    let file = o.cache_file.unwrap();
    let good = std::fs::read(&file).unwrap();
    let rows = built.len();
    // Header 48 bytes; a key per row, then a pair of ids per row, then the k-vector.
    let (keys, pairs, kvector) = (48, 48 + 4 * rows, 48 + 12 * rows);
    let put = |b: &mut Vec<u8>, at: usize, v: u32| b[at..at + 4].copy_from_slice(&v.to_le_bytes());
    let cases: Vec<(&str, Scribble)> = vec![
        (
            "pair id",
            Box::new(move |b| put(b, pairs + 40, 0xFFFF_FFFF)),
        ),
        (
            "pair ids in the wrong order",
            Box::new(move |b| {
                put(b, pairs + 40, 2);
                put(b, pairs + 44, 1);
            }),
        ),
        ("k-vector", Box::new(move |b| put(b, kvector + 8, u32::MAX))),
        (
            "k-vector order",
            Box::new(move |b| b.swap(kvector + 4, kvector + 12)),
        ),
        (
            "key",
            Box::new(move |b| put(b, keys + 4 * (rows - 1), u32::MAX)),
        ),
        ("row count", Box::new(|b| b[16] ^= 1)),
    ];
    for (what, scribble) in cases {
        for recompute_crc in [false, true] {
            std::fs::write(&file, scribbled(&good, &scribble, recompute_crc)).unwrap();
            let (table, origin) = table_at(dir.path());
            assert!(
                origin.built,
                "{what} (crc recomputed: {recompute_crc}): cache used"
            );
            assert!(origin.cache_note.is_some(), "{what}: no note");
            assert_eq!(table, built, "{what}: the table differs");
            assert_eq!(std::fs::read(&file).unwrap(), good, "{what}: not rewritten");
        }
    }
}

/// The pattern index's cache file (mapped, its body not read when it is opened: a deep
/// catalog's is gigabytes): read back it is the index built; with its header scribbled on (the
/// row count) or cut short it is never used: the index is built again and the file rewritten.
/// A scribbled row (a key out of order, a star beyond the catalog) is mapped as it is, whatever
/// its checksum: a frame checks the rows it reads (`check_quad` skips a quad naming a star the
/// selection lacks; the lookup stays within the keys).
#[test]
fn damaged_pattern_files_are_rebuilt() {
    use gpustar::catalog::patterns::{levels_for, load_or_build_in};
    let dir = tempfile::tempdir().unwrap();
    let cat = refs(4.5);
    let levels = levels_for(0.15, 0.3);
    let index_at = |dir: &std::path::Path| load_or_build_in(Some(dir), &cat, 7, &levels);
    let (built, was_built, _) = index_at(dir.path());
    assert!(was_built);
    let (again, was_built, _) = index_at(dir.path());
    assert!(!was_built, "the cache file was not used");
    assert_eq!(again, built);
    let file = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.to_string_lossy().contains("patterns-"))
        .unwrap();
    let good = std::fs::read(&file).unwrap();
    let rows = built.keys.len();
    assert!(rows > 10, "{rows} patterns");
    // Header 24 bytes; a key per row, then four star ids per row.
    let (keys, quads) = (24, 24 + 4 * rows);
    let put = |b: &mut Vec<u8>, at: usize, v: u32| b[at..at + 4].copy_from_slice(&v.to_le_bytes());
    let rows_of: Vec<(&str, Scribble)> = vec![
        ("key order", Box::new(move |b| put(b, keys, u32::MAX >> 2))),
        ("star id", Box::new(move |b| put(b, quads + 12, u32::MAX))),
    ];
    for (what, scribble) in rows_of {
        for recompute_crc in [false, true] {
            let bytes = scribbled(&good, &scribble, recompute_crc);
            std::fs::write(&file, &bytes).unwrap();
            let (index, was_built, _) = index_at(dir.path());
            assert!(
                !was_built,
                "{what} (crc recomputed: {recompute_crc}): rebuilt"
            );
            assert_ne!(index, built, "{what}: the scribble is not what was mapped");
            assert_eq!(std::fs::read(&file).unwrap(), bytes, "{what}: rewritten");
        }
    }
    let cases: Vec<(&str, Scribble)> = vec![
        ("row count", Box::new(|b| b[16] ^= 1)),
        ("cut short", Box::new(|b| b.truncate(b.len() - 8))),
    ];
    for (what, scribble) in cases {
        for recompute_crc in [false, true] {
            std::fs::write(&file, scribbled(&good, &scribble, recompute_crc)).unwrap();
            let (index, was_built, _) = index_at(dir.path());
            assert!(
                was_built,
                "{what} (crc recomputed: {recompute_crc}): cache used"
            );
            assert_eq!(index, built, "{what}: the index differs");
            assert_eq!(std::fs::read(&file).unwrap(), good, "{what}: not rewritten");
        }
    }
}
