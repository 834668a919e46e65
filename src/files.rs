//! Reading the whole of a file a run depends on (catalog, camera file, TLEs) without waiting
//! on a FIFO or reading a device without end. Below every other module (`catalog`, `camera`,
//! `sky` and `io` use it).

use crate::error::{Context, Result, fail};
use std::path::Path;

/// The whole of a regular file, for the files a run reads whole (catalogs, `--tle`,
/// `--camera`): refused before opening when `path` is not a regular file (a FIFO would block
/// the read forever, `/dev/zero` never ends), and read no further than the size its metadata
/// gave, so that a file growing meanwhile cannot make the read unbounded either. `what` names
/// the file in messages ("catalog", "--tle").
pub fn read_regular_file(path: &Path, what: &str) -> Result<Vec<u8>> {
    use std::io::Read;
    let shown = path.display();
    let (file, meta) = open_regular(path, what)?;
    let mut bytes = Vec::new();
    if bytes
        .try_reserve_exact(usize::try_from(meta.len()).unwrap_or(usize::MAX))
        .is_err()
    {
        fail!(
            Input,
            "cannot read {what} {shown}: {} bytes do not fit in memory",
            meta.len()
        );
    }
    file.take(meta.len())
        .read_to_end(&mut bytes)
        .with_context(|| format!("cannot read {what} {shown}"))?;
    Ok(bytes)
}

/// A regular file mapped read-only, for a binary catalog file read on every run: the stars
/// come from the page cache as they are read, where reading Tycho-2's 120 MB into fresh memory
/// first took a sixth of a narrow frame's whole process. Refused, as [`read_regular_file`]
/// refuses, when `path` is not a regular file.
pub fn map_regular_file(path: &Path, what: &str) -> Result<memmap2::Mmap> {
    let shown = path.display();
    let (file, _) = open_regular(path, what)?;
    // SAFETY: mapped read-only and read while the catalog is loaded. `gpustar catalog import`
    // replaces a catalog by rename, never in place, so the mapped file keeps its bytes; a file
    // truncated in place by another program meanwhile is outside what gpustar can guard.
    unsafe { memmap2::Mmap::map(&file) }.with_context(|| format!("cannot map {what} {shown}"))
}

/// `path` opened, refused before opening when it is not a regular file.
fn open_regular(path: &Path, what: &str) -> Result<(std::fs::File, std::fs::Metadata)> {
    let shown = path.display();
    let meta = std::fs::metadata(path).with_context(|| format!("cannot read {what} {shown}"))?;
    if !meta.is_file() {
        fail!(
            Input,
            "cannot read {what} {shown}: not a regular file but {}",
            file_kind(&meta.file_type())
        );
    }
    let file = std::fs::File::open(path).with_context(|| format!("cannot read {what} {shown}"))?;
    Ok((file, meta))
}

/// [`read_regular_file`] of a text file: refused when it is not UTF-8.
pub fn read_regular_text(path: &Path, what: &str) -> Result<String> {
    String::from_utf8(read_regular_file(path, what)?).map_err(|e| {
        crate::error::error!(
            Input,
            "cannot read {what} {}: not UTF-8 text ({})",
            path.display(),
            e.utf8_error()
        )
    })
}

/// What a path that is not a regular file is, for messages.
pub fn file_kind(t: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_socket() {
            return "a socket";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
    }
    if t.is_dir() {
        "a directory"
    } else {
        "something else"
    }
}
