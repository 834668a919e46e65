//! Whether a catalog file already passed its whole check: a stamp of the file (size, inode,
//! modification and change times) kept in the cache directory after a check that passed. A
//! run whose file still has that stamp maps it with its header and layout checked, without
//! the checksum and the per-record ids: on Tycho-2's 120 MB those took 60 ms of a narrow
//! frame's 150 ms run. Any write to the file changes its change time, which no program can
//! set back, so a file changed since is checked whole again. As git does with its index
//! ("racy git"), a file changed within [`SETTLED_S`] of the check gets no stamp: timestamps
//! are coarse (a few ms), and a write within the same tick would leave the stamp as it was.
//! (`io::guard` keeps stamps of the IOD files gpustar wrote, for another question: whether
//! another program has written them since.)

use super::fnv1a;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

/// A file changed less than this long before its check gets no stamp.
pub const SETTLED_S: u64 = 2;

/// The stamp file of `path` in `dir`.
fn stamp_path(dir: &Path, path: &Path) -> Option<PathBuf> {
    let full = std::fs::canonicalize(path).ok()?;
    // The version in the key: another gpustar's checks may differ from the ones that passed.
    let version = env!("CARGO_PKG_VERSION");
    let key = fnv1a(format!("gpustar-checked-v1|{version}|{}", full.display()).as_bytes());
    Some(dir.join(format!("checked-{key:016x}.txt")))
}

/// The file's stamp now: size, device, inode, modification and change times (ns). None where
/// the platform has no change time (the file is then checked whole on every run).
fn stamp(path: &Path) -> Option<(String, SystemTime)> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let m = std::fs::metadata(path).ok()?;
        let text = format!(
            "{} {} {} {}.{:09} {}.{:09}",
            m.len(),
            m.dev(),
            m.ino(),
            m.mtime(),
            m.mtime_nsec(),
            m.ctime(),
            m.ctime_nsec()
        );
        let ns = |s: i64, n: i64| {
            SystemTime::UNIX_EPOCH + Duration::new(s.max(0) as u64, n.clamp(0, 999_999_999) as u32)
        };
        let changed = ns(m.mtime(), m.mtime_nsec()).max(ns(m.ctime(), m.ctime_nsec()));
        Some((text, changed))
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        None
    }
}

/// Whether `path` carries the stamp a passed check left in `dir`.
pub fn passed(dir: &Path, path: &Path) -> bool {
    let (Some(file), Some((now, _))) = (stamp_path(dir, path), stamp(path)) else {
        return false;
    };
    std::fs::read_to_string(file).is_ok_and(|kept| kept == now)
}

/// Record that `path` passed its whole check, unless it changed within [`SETTLED_S`]. A stamp
/// that cannot be written costs only the next run's check.
pub fn mark(dir: &Path, path: &Path) {
    let (Some(file), Some((now, changed))) = (stamp_path(dir, path), stamp(path)) else {
        return;
    };
    let settled = SystemTime::now()
        .duration_since(changed)
        .is_ok_and(|age| age >= Duration::from_secs(SETTLED_S));
    if !settled {
        return;
    }
    // Written under another name and renamed, as `table::write_cache` writes: a reader sees
    // the old stamp or the new, never a part.
    let tmp = file.with_extension(format!("tmp{}", std::process::id()));
    let done = std::fs::create_dir_all(dir)
        .and_then(|_| std::fs::write(&tmp, &now))
        .and_then(|_| std::fs::rename(&tmp, &file));
    if let Err(e) = done {
        let _ = std::fs::remove_file(&tmp);
        tracing::debug!("could not stamp {} as checked: {e}", path.display());
    }
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    /// A settled file is stamped and passes; any write afterwards (even of the same size)
    /// takes the stamp away; a file changed just now is not stamped.
    #[test]
    fn a_stamp_holds_until_the_file_changes() {
        let dir = std::env::temp_dir().join(format!("gpustar-checked-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("cat.bin");
        std::fs::write(&f, b"0123456789").unwrap();
        // Just written: no stamp.
        mark(&dir, &f);
        assert!(!passed(&dir, &f));
        // Settled: once both its times are SETTLED_S old.
        std::thread::sleep(Duration::from_millis(SETTLED_S * 1000 + 100));
        mark(&dir, &f);
        assert!(passed(&dir, &f));
        // Rewritten in place with the same size: the change time moves, the stamp no longer
        // holds.
        std::fs::write(&f, b"0123456780").unwrap();
        assert!(!passed(&dir, &f));
        // Another file is not stamped by this one's stamp.
        let g = dir.join("other.bin");
        std::fs::write(&g, b"0123456789").unwrap();
        assert!(!passed(&dir, &g));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
