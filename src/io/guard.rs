//! The guard every file gpustar writes passes through (issue 45): before any work, every
//! output of a run is claimed, and an output on an input, two outputs on one path, an output
//! that the next run would read as a frame, a file that is not a regular file, and a file that
//! gpustar did not write are refused. Files are then written whole, through a new file
//! renamed over the old, so that a stop or a full disk leaves the old file.
//!
//! Records (`-o`) are opened by `io::output::open_output`, which also resumes them;
//! the whole files (TDM, IOD, WCS headers, annotations, catalogs, camera files) go through
//! [`check_replaceable`] before the run and [`write_atomically`] after it.

use crate::error::{Context, Result, fail};
use std::collections::HashMap;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// What a file gpustar writes holds: how it tells its own files, and how messages name them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Tdm,
    Iod,
    Wcs,
    Annotation,
    Camera,
    NewFits,
    Corr,
    Axy,
    Report,
    RunConfig,
}

/// The marks gpustar puts in the FITS files `--new-fits`, `--corr` and `--axy` write (a
/// COMMENT card), by which it knows them again.
pub const NEW_FITS_MARK: &str = "gpustar --new-fits";
pub const CORR_MARK: &str = "gpustar --corr";
pub const AXY_MARK: &str = "gpustar --axy";

/// The mark gpustar puts in the annotated PNGs it writes (a tEXt chunk), by which it knows
/// them again.
pub const PNG_SOFTWARE: (&str, &str) = ("Software", "gpustar");

/// The mark gpustar puts in the head of the report pages it writes (`gpustar report --html`),
/// followed by its version.
pub const HTML_GENERATOR: &str = "<meta name=\"generator\" content=\"gpustar";

/// The first line of the run configuration gpustar keeps beside a run's records
/// (`config::sidecar`).
pub const RUN_CONFIG_MARK: &str = "# gpustar run configuration";

/// How much of an existing file is read to tell whose it is: a FIFO, a device or a huge file
/// at an output path costs no more than this.
const HEAD_BYTES: u64 = 64 * 1024;

impl Kind {
    pub fn what(self) -> &'static str {
        match self {
            Kind::Tdm => "a TDM gpustar wrote",
            Kind::Iod => "IOD lines",
            Kind::Wcs => "a WCS header gpustar wrote",
            Kind::Annotation => "an image gpustar annotated",
            Kind::Camera => "a camera file gpustar calibrate wrote",
            Kind::NewFits => "a FITS frame gpustar wrote with its WCS",
            Kind::Corr => "a table of matched stars gpustar wrote",
            Kind::Axy => "a star list gpustar wrote",
            Kind::Report => "a page gpustar report wrote",
            Kind::RunConfig => "a run configuration gpustar wrote",
        }
    }

    /// Does a file that starts with `head` hold this kind as gpustar writes it (by the mark
    /// gpustar puts in it)?
    pub fn ours(self, head: &[u8]) -> bool {
        let text = String::from_utf8_lossy(head);
        match self {
            // Our TDMs name their originator in the header (formats::tdm_text).
            Kind::Tdm => {
                text.starts_with("CCSDS_TDM_VERS")
                    && text
                        .lines()
                        .take(12)
                        .any(|l| l.split_whitespace().eq(["ORIGINATOR", "=", "GPUSTAR"]))
            }
            // IOD lines carry no mark of their writer (sattools and stvid write the same
            // columns): gpustar knows its own by the stamp it keeps ([`remember_written`]).
            Kind::Iod => false,
            // Our WCS headers end with this comment card (io::wcs::wcs_header); one header
            // of 2880-byte blocks holds it.
            Kind::Wcs => {
                head.starts_with(b"SIMPLE  =")
                    && text.contains("WCS by gpustar.")
                    && !text.contains(NEW_FITS_MARK)
            }
            // The marks sit in headers, within the first blocks read.
            Kind::NewFits => head.starts_with(b"SIMPLE  =") && text.contains(NEW_FITS_MARK),
            Kind::Corr => head.starts_with(b"SIMPLE  =") && text.contains(CORR_MARK),
            Kind::Axy => head.starts_with(b"SIMPLE  =") && text.contains(AXY_MARK),
            Kind::Annotation => png_has_text(head, PNG_SOFTWARE),
            Kind::Camera => text.starts_with("# written by gpustar calibrate"),
            // Our pages name their generator in the head.
            Kind::Report => text.lines().take(4).any(|l| l.starts_with(HTML_GENERATOR)),
            Kind::RunConfig => text.starts_with(RUN_CONFIG_MARK),
        }
    }
}

/// Is the PNG tEXt chunk `keyword`/`value` among the chunks before the image data?
fn png_has_text(bytes: &[u8], (keyword, value): (&str, &str)) -> bool {
    const SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";
    if !bytes.starts_with(SIGNATURE) {
        return false;
    }
    let mut at = SIGNATURE.len();
    while let Some(header) = bytes.get(at..at + 8) {
        let len = u32::from_be_bytes(header[..4].try_into().expect("4 bytes")) as usize;
        let kind = &header[4..8];
        if kind == b"IDAT" {
            return false;
        }
        if kind == b"tEXt"
            && let Some(data) = bytes.get(at + 8..at + 8 + len)
            && let Some(nul) = data.iter().position(|&b| b == 0)
            && &data[..nul] == keyword.as_bytes()
            && &data[nul + 1..] == value.as_bytes()
        {
            return true;
        }
        at = at.saturating_add(12).saturating_add(len);
    }
    false
}

/// The first bytes of a regular file at `path` (following links), None when nothing is there.
/// Anything else there (a directory, a FIFO, a device) is refused: gpustar writes whole files
/// through a new file renamed over the old, which only a regular file can take.
pub fn existing_head(path: &Path) -> Result<Option<Vec<u8>>> {
    let shown = path.display();
    let meta = match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            if std::fs::symlink_metadata(path).is_ok() {
                fail!(
                    Output,
                    "cannot write {shown}: it is a link to nothing (a dangling symbolic link)"
                );
            }
            return Ok(None);
        }
        Err(e) => return Err(e).with_context(|| format!("cannot read {shown}")),
        Ok(m) => m,
    };
    if !meta.is_file() {
        fail!(
            Output,
            "cannot write {shown}: it is {}, not a regular file (gpustar writes the file whole, \
             through a new file renamed over the old)",
            crate::files::file_kind(&meta.file_type())
        );
    }
    let mut head = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(HEAD_BYTES).read_to_end(&mut head))
        .with_context(|| format!("cannot read {shown}"))?;
    Ok(Some(head))
}

/// The directory a new file at `path` goes in.
fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// Refuse, before a run, a file of `kind` to be written at `path` at its end (or per frame)
/// unless it can be: its directory exists and takes new files, and nothing is there, or an
/// empty regular file, or `kind` as gpustar writes it, or (with `overwrite`) any regular file.
pub fn check_replaceable(path: &Path, kind: Kind, overwrite: bool) -> Result<()> {
    let shown = path.display();
    let dir = parent_dir(path);
    if !dir.is_dir() {
        fail!(
            Output,
            "cannot write {shown}: {} is not a directory",
            dir.display()
        );
    }
    check_takes_files(dir).with_context(|| format!("cannot write {shown}"))?;
    check_existing(path, kind, overwrite)
}

/// Refuse what is at `path` unless a file of `kind` may replace it: nothing, an empty regular
/// file, `kind` as gpustar writes it, or (with `overwrite`) any regular file.
pub fn check_existing(path: &Path, kind: Kind, overwrite: bool) -> Result<()> {
    match existing_head(path)? {
        None => Ok(()),
        Some(h) if h.is_empty() || overwrite || kind.ours(&h) || is_as_written(path) => Ok(()),
        Some(_) => fail!(
            Output,
            "{} exists and does not hold {}: not replaced; remove it, choose another path, or \
             add --overwrite",
            path.display(),
            kind.what()
        ),
    }
}

/// Can a new file be made in `dir`? (Made and removed: permissions alone do not say, on
/// read-only mounts or with ACLs.)
pub fn check_takes_files(dir: &Path) -> Result<()> {
    match tempfile::NamedTempFile::new_in(dir) {
        Ok(_) => Ok(()),
        Err(e) => Err(e).with_context(|| format!("cannot create a file in {}", dir.display())),
    }
}

/// Write a whole file through a new file in the same directory renamed over `path`: a crash
/// or a full disk leaves the old file or the new one, never a part. A symbolic link at `path`
/// stays a link: its target is replaced. The file keeps the old one's permissions, or gets a
/// new file's (0666 less the umask; the temporary file's own are 0600).
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let shown = path.display();
    let target = match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => std::fs::canonicalize(path)
            .with_context(|| format!("cannot write {shown}: its link leads nowhere"))?,
        _ => path.to_path_buf(),
    };
    let dir = parent_dir(&target);
    let mut tmp =
        tempfile::NamedTempFile::new_in(dir).with_context(|| format!("cannot write {shown}"))?;
    let permissions = match std::fs::metadata(&target) {
        Ok(m) => Some(m.permissions()),
        Err(_) => new_file_permissions(dir),
    };
    if let Some(p) = permissions {
        tmp.as_file()
            .set_permissions(p)
            .with_context(|| format!("cannot write {shown}"))?;
    }
    tmp.write_all(bytes)
        .and_then(|_| tmp.as_file().sync_all())
        .with_context(|| format!("cannot write {shown}"))?;
    tmp.persist(&target)
        .map_err(|e| e.error)
        .with_context(|| format!("cannot write {shown}"))?;
    Ok(())
}

/// Where gpustar keeps the stamp of a file it wrote at `target` (its canonical path).
fn stamp_file(target: &Path) -> Option<PathBuf> {
    let key = crate::catalog::fnv1a(target.as_os_str().as_encoded_bytes());
    Some(crate::catalog::table::cache_dir()?.join(format!("written/{key:016x}")))
}

/// A file's identity, length and modification time: any other writer changes one of them.
fn stamp(meta: &std::fs::Metadata) -> String {
    let modified = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    let (dev, ino) = identity(meta);
    format!("{dev} {ino} {} {modified}\n", meta.len())
}

/// Remember that gpustar wrote the file at `path` as it now is (in the cache directory), for
/// files that carry no mark of their writer (IOD lines): a later run may replace it as long as
/// no other program has changed it since. Without a cache directory nothing is remembered,
/// and such a file is then replaced only with `--overwrite`.
pub fn remember_written(path: &Path) {
    let remembered = std::fs::canonicalize(path).ok().and_then(|target| {
        let meta = std::fs::metadata(&target).ok()?;
        let file = stamp_file(&target)?;
        std::fs::create_dir_all(file.parent()?).ok()?;
        write_atomically(&file, stamp(&meta).as_bytes()).ok()
    });
    if remembered.is_none() {
        tracing::debug!("could not remember writing {}", path.display());
    }
}

/// Is the file at `path` as gpustar last wrote it ([`remember_written`])?
fn is_as_written(path: &Path) -> bool {
    let Ok(target) = std::fs::canonicalize(path) else {
        return false;
    };
    match (std::fs::metadata(&target), stamp_file(&target)) {
        (Ok(meta), Some(file)) => std::fs::read_to_string(file).is_ok_and(|s| s == stamp(&meta)),
        _ => false,
    }
}

/// The permissions a new file gets in `dir` (0666 less the umask), found by making one: the
/// umask cannot be read without changing it, which would race other threads.
fn new_file_permissions(dir: &Path) -> Option<std::fs::Permissions> {
    let probe = dir.join(format!(".gpustar-mode-{}", std::process::id()));
    let made = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
        .and_then(|f| f.metadata());
    let _ = std::fs::remove_file(&probe);
    made.ok().map(|m| m.permissions())
}

/// A file's identity (device and inode): two paths, links or names of one file compare equal.
#[cfg(unix)]
fn identity(meta: &std::fs::Metadata) -> (u64, u64) {
    use std::os::unix::fs::MetadataExt;
    (meta.dev(), meta.ino())
}

#[cfg(not(unix))]
fn identity(_: &std::fs::Metadata) -> (u64, u64) {
    (0, 0)
}

/// A path as one key whatever way it is written: absolute, its directory's links and `..`
/// resolved (the file itself need not exist yet).
fn path_key(path: &Path) -> PathBuf {
    if let Ok(p) = std::fs::canonicalize(path) {
        return p;
    }
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    match (abs.parent().map(std::fs::canonicalize), abs.file_name()) {
        (Some(Ok(dir)), Some(name)) => dir.join(name),
        _ => abs,
    }
}

/// The files one run reads and writes, claimed before any work: an output may not be an
/// input, nor share its path with another output, nor be a frame the next run would read.
#[derive(Debug, Default)]
pub struct Claims {
    /// The files read (frames, catalog, camera, dark, TLEs), by identity: what they are.
    inputs: HashMap<(u64, u64), String>,
    /// The directories whose frames are read, and whether their subdirectories are.
    dirs: Vec<(PathBuf, bool)>,
    /// The outputs claimed, by path key and (existing files) by identity: what they are.
    outputs: HashMap<PathBuf, String>,
    output_ids: HashMap<(u64, u64), String>,
}

impl Claims {
    pub fn new() -> Claims {
        Claims::default()
    }

    /// A file the run reads (named `what` in messages). Files that cannot be read are
    /// claimed by nothing: they get their error where they are read.
    pub fn input(&mut self, path: &Path, what: &str) {
        if let Ok(m) = std::fs::metadata(path)
            && m.is_file()
        {
            self.inputs
                .entry(identity(&m))
                .or_insert_with(|| what.to_string());
        }
    }

    /// A directory whose image files are the run's frames (with its subdirectories when
    /// `recursive`): an output there with an image's name would be a frame of the next run.
    pub fn input_dir(&mut self, dir: &Path, recursive: bool) {
        self.dirs.push((path_key(dir), recursive));
    }

    /// Claim `path` for the output `what` (e.g. "--tdm"): refused when an input, an output
    /// already claimed, or a frame of a directory read has that path.
    pub fn output(&mut self, path: &Path, what: &str) -> Result<()> {
        let shown = path.display();
        let key = path_key(path);
        if let Some(other) = self.outputs.get(&key) {
            fail!(
                Output,
                "{what} {shown} is also {other}: give each output its own file"
            );
        }
        let id = std::fs::metadata(path).ok().map(|m| identity(&m));
        if let Some(id) = id {
            if let Some(input) = self.inputs.get(&id) {
                fail!(
                    Output,
                    "{what} {shown} is {input}, an input of this run: not written; give \
                     another path"
                );
            }
            if let Some(other) = self.output_ids.get(&id) {
                fail!(
                    Output,
                    "{what} {shown} is the same file as {other}: give each output its own file"
                );
            }
        }
        if crate::io::frame::is_image_path(&key)
            && let Some((dir, _)) = self.dirs.iter().find(|(dir, recursive)| {
                key.parent() == Some(dir.as_path()) || *recursive && key.starts_with(dir)
            })
        {
            fail!(
                Output,
                "{what} {shown} is an image file in {}, where the frames are read: the next \
                 run would take it for a frame; write it elsewhere",
                dir.display()
            );
        }
        if let Some(id) = id {
            self.output_ids.insert(id, format!("{what} {shown}"));
        }
        self.outputs.insert(key, format!("{what} {shown}"));
        Ok(())
    }

    /// Claim standard output for the records (when no `-o` is given), so that an export to
    /// `/dev/stdout` or to the file standard output is redirected to is refused.
    pub fn stdout(&mut self) {
        if let Ok(m) = std::fs::metadata("/dev/stdout") {
            self.output_ids
                .insert(identity(&m), "the records' output (standard output)".into());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn own_files_are_told_by_their_marks() {
        let tdm =
            "CCSDS_TDM_VERS = 2.0\nCOMMENT x\nCREATION_DATE = 2026-01-01\nORIGINATOR = GPUSTAR\n";
        assert!(Kind::Tdm.ours(tdm.as_bytes()));
        let theirs = tdm.replace("GPUSTAR", "SATTOOLS");
        assert!(!Kind::Tdm.ours(theirs.as_bytes()));
        assert!(!Kind::Tdm.ours(b"CCSDS_TDM_VERS = 2.0\n"));
        assert!(
            !Kind::Iod.ours(b"25544 98 067A   4353 G 20260101000000000 17 25 0000000+000000 37\n")
        );
        assert!(!Kind::Camera.ours(b"width = 10\n"));
        assert!(Kind::Camera.ours(b"# written by gpustar calibrate from 3 solved frames\n"));
        assert!(!Kind::Wcs.ours(b"SIMPLE  =                    T / astrometry.net"));
        let page = "<!DOCTYPE html>\n<html><head>\n<meta name=\"generator\" content=\"gpustar 1\">";
        assert!(Kind::Report.ours(page.as_bytes()));
        assert!(!Kind::Report.ours(b"<!DOCTYPE html>\n<html><head><title>mine</title>"));
    }

    #[test]
    fn png_marks_are_found_before_the_image_data_only() {
        let mut png = Vec::new();
        {
            let mut e = png::Encoder::new(&mut png, 1, 1);
            e.set_color(png::ColorType::Grayscale);
            e.add_text_chunk(PNG_SOFTWARE.0.into(), PNG_SOFTWARE.1.into())
                .unwrap();
            e.write_header().unwrap().write_image_data(&[0]).unwrap();
        }
        assert!(Kind::Annotation.ours(&png));
        let mut plain = Vec::new();
        {
            let mut e = png::Encoder::new(&mut plain, 1, 1);
            e.set_color(png::ColorType::Grayscale);
            e.write_header().unwrap().write_image_data(&[0]).unwrap();
        }
        assert!(!Kind::Annotation.ours(&plain));
        // A chunk length running past the end, or garbage, is not a mark.
        assert!(!Kind::Annotation.ours(&png[..20]));
        assert!(!Kind::Annotation.ours(b"\x89PNG\r\n\x1a\n\xff\xff\xff\xfftEXt"));
    }
}
