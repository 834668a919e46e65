//! The inputs of a run: the image files of a directory in a sorted, stable order, and the
//! shard of them a process takes.

use crate::error::{Context, Error, IntoKind, Result, fail};
use crate::io::frame::is_image_path;
use std::path::{Path, PathBuf};

/// An input file and its name in the records (its path relative to the directory, with '/').
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Input {
    pub path: PathBuf,
    pub name: String,
    /// Already recorded by an earlier run (`--resume`), taken again only for the state of its
    /// sequence: processed, its record not written.
    pub replay: bool,
}

/// The name of a path relative to the directory: components joined by '/'. A component that
/// is not UTF-8 is escaped reversibly: each byte that is not part of a UTF-8 character as
/// `\xNN` (two lower-case hex digits) and each backslash as `\\`. A UTF-8 component is kept
/// as it is but for a backslash followed by `x` or by another backslash, which is written
/// `\\`: so that no name spells out another's escape (`a\xff.png` beside a file whose name
/// holds the byte 0xff), and every name reads back to its bytes (`\\` is a backslash, `\xNN`
/// a byte, any other backslash itself).
fn relative_name(rel: &Path) -> String {
    rel.components()
        .map(|c| escape_component(c.as_os_str()))
        .collect::<Vec<_>>()
        .join("/")
}

#[cfg(not(unix))]
pub(crate) fn escape_component(c: &std::ffi::OsStr) -> String {
    c.to_string_lossy().into_owned()
}

#[cfg(unix)]
pub(crate) fn escape_component(c: &std::ffi::OsStr) -> String {
    if let Some(s) = c.to_str() {
        if !s.contains("\\\\") && !s.contains("\\x") {
            return s.to_string();
        }
        let mut out = String::with_capacity(s.len() + 2);
        let mut chars = s.chars().peekable();
        while let Some(ch) = chars.next() {
            out.push(ch);
            if ch == '\\' && matches!(chars.peek(), Some('\\' | 'x')) {
                out.push('\\');
            }
        }
        return out;
    }
    use std::os::unix::ffi::OsStrExt;
    let mut out = String::new();
    for chunk in c.as_bytes().utf8_chunks() {
        out.push_str(&chunk.valid().replace('\\', "\\\\"));
        for b in chunk.invalid() {
            out.push_str(&format!("\\x{b:02x}"));
        }
    }
    out
}

/// Every file under `dir` (in subdirectories too with `recursive`) whose extension is an image
/// type gpustar reads, sorted by path. Symbolic links to files are inputs (a broken or looping
/// one gets an error record when it is read); links to directories are not followed.
/// A directory that cannot be read is refused; a subdirectory that cannot be read is listed
/// as an input of its own (its error record says why), with a warning.
pub fn list(dir: &Path, recursive: bool) -> Result<Vec<Input>> {
    list_with(dir, recursive, is_image_path)
}

/// Star lists `--xyls` takes from a folder: `.xyls`, `.axy` and FITS tables.
pub fn is_star_list_path(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["xyls", "axy", "fits", "fit"].contains(&e.to_ascii_lowercase().as_str()))
}

/// [`list`] of the files `accept` takes by their path.
pub fn list_with(dir: &Path, recursive: bool, accept: fn(&Path) -> bool) -> Result<Vec<Input>> {
    if !dir.is_dir() {
        fail!(Input, "{} is not a directory", dir.display());
    }
    let mut out = Vec::new();
    let walk = walkdir::WalkDir::new(dir)
        .min_depth(1)
        .max_depth(if recursive { usize::MAX } else { 1 })
        .follow_links(false)
        .sort_by_file_name();
    for entry in walk {
        let entry = match entry {
            Ok(e) => e,
            // The directory itself cannot be read: no run, rather than "0 files" and exit 0.
            Err(e) if e.depth() == 0 => {
                fail!(Input, "cannot read the directory {}: {e}", dir.display())
            }
            // A subdirectory that cannot be read is an input of its own, so that it gets an
            // error record (io::frame says why) and the run's exit status counts it.
            Err(e) => {
                tracing::warn!("{e}: the frames in it get no record");
                if let Some(p) = e.path()
                    && p.is_dir()
                    && let Ok(rel) = p.strip_prefix(dir)
                {
                    out.push(Input {
                        path: p.to_path_buf(),
                        name: relative_name(rel),
                        replay: false,
                    });
                }
                continue;
            }
        };
        // Anything but a directory with an image's name is an input: a FIFO, a socket or a
        // broken link gets an error record rather than no record.
        let ft = entry.file_type();
        let is_file = !(ft.is_dir() || ft.is_symlink() && entry.path().is_dir());
        if is_file && accept(entry.path()) {
            let rel = entry
                .path()
                .strip_prefix(dir)
                .into_kind(Error::Input)
                .context("walked outside the directory")?;
            out.push(Input {
                path: entry.path().to_path_buf(),
                name: relative_name(rel),
                replay: false,
            });
        }
    }
    // walkdir sorts each directory by file name; sort the whole list by record name so the
    // order is the same whatever the file system.
    out.sort_by(|a, b| a.name.cmp(&b.name));
    // Names are unique (the escape reads back to the bytes), but for a build without Unix
    // names (their lossy names can collide): refuse rather than give two inputs one record.
    if let Some(w) = out.windows(2).find(|w| w[0].name == w[1].name) {
        fail!(
            Input,
            "{} and {} would have the same record name {:?}: rename one",
            w[0].path.display(),
            w[1].path.display(),
            w[0].name
        );
    }
    Ok(out)
}

/// The inputs `batch` was given, and the directories among them (claimed as read: no output
/// may land on a frame a later run would list).
#[derive(Debug, Default)]
pub struct Gathered {
    pub inputs: Vec<Input>,
    pub dirs: Vec<PathBuf>,
}

/// What `batch` takes as its inputs, each argument one of:
/// - a directory: its files that `accept` takes, images or star lists (in its subdirectories
///   too with `recursive`);
/// - a file: that file, whatever its name says;
/// - `@LIST`: the files LIST names, one path a line (blank lines and lines starting with `#`
///   skipped; relative paths are taken from the current directory, as a shell would);
/// - `-`: the same, read from standard input (`stdin`, read whole).
///
/// Names in the records: one directory alone keeps its files' paths relative to it, as
/// always. Otherwise each name is the path as given (a directory's files: the directory's
/// path as given, then the file's below it), so that inputs from several places keep
/// apart. An argument that does not exist stops the run before any work; a listed file that
/// does not exist gets an error record like any unreadable frame. A file given twice is taken
/// once. Sorted by name, as [`list`] sorts.
pub fn gather(
    args: &[PathBuf],
    recursive: bool,
    accept: fn(&Path) -> bool,
    stdin: &mut dyn std::io::BufRead,
) -> Result<Gathered> {
    let list = |dir: &Path, recursive| list_with(dir, recursive, accept);
    if let [dir] = args
        && dir.is_dir()
    {
        return Ok(Gathered {
            inputs: list(dir, recursive)?,
            dirs: vec![dir.clone()],
        });
    }
    let mut out = Gathered::default();
    let file = |path: &Path| Input {
        path: path.to_path_buf(),
        name: given_name(path),
        replay: false,
    };
    for arg in args {
        let text = arg.to_string_lossy();
        let listed = if arg.as_os_str() == "-" {
            Some(read_list(stdin, "standard input")?)
        } else if let Some(list_path) = text.strip_prefix('@') {
            let f = std::fs::File::open(list_path)
                .with_context(|| format!("cannot open the list {list_path}"))?;
            Some(read_list(&mut std::io::BufReader::new(f), list_path)?)
        } else {
            None
        };
        match listed {
            Some(paths) => out.inputs.extend(paths.iter().map(|p| file(p))),
            None if arg.is_dir() => {
                let prefix = given_name(arg);
                for mut i in list(arg, recursive)? {
                    i.name = format!("{prefix}/{}", i.name);
                    out.inputs.push(i);
                }
                out.dirs.push(arg.clone());
            }
            // A dangling link is an input (its record says where it leads).
            None if std::fs::symlink_metadata(arg).is_ok() => out.inputs.push(file(arg)),
            None => fail!(Input, "{}: no such file or directory", arg.display()),
        }
    }
    out.inputs.sort_by(|a, b| a.name.cmp(&b.name));
    out.inputs.dedup_by(|a, b| a.name == b.name);
    Ok(out)
}

/// The paths of a list, one a line (bytes on Unix: a name need not be UTF-8).
fn read_list(r: &mut dyn std::io::BufRead, shown: &str) -> Result<Vec<PathBuf>> {
    let mut paths = Vec::new();
    let mut line = Vec::new();
    loop {
        line.clear();
        let n = r
            .read_until(b'\n', &mut line)
            .with_context(|| format!("cannot read the list {shown}"))?;
        if n == 0 {
            break;
        }
        let end = line.iter().rposition(|&b| b != b'\n' && b != b'\r');
        let line = &line[..end.map_or(0, |e| e + 1)];
        if line.trim_ascii().is_empty() || line.starts_with(b"#") {
            continue;
        }
        paths.push(path_of_bytes(line));
    }
    Ok(paths)
}

#[cfg(unix)]
fn path_of_bytes(b: &[u8]) -> PathBuf {
    use std::os::unix::ffi::OsStrExt;
    PathBuf::from(std::ffi::OsStr::from_bytes(b))
}

#[cfg(not(unix))]
fn path_of_bytes(b: &[u8]) -> PathBuf {
    PathBuf::from(String::from_utf8_lossy(b).into_owned())
}

/// A path as given, in a record's name: its components joined by '/' (escaped as
/// [`relative_name`] does), `./` left out, a leading '/' kept.
fn given_name(path: &Path) -> String {
    use std::path::Component;
    let parts: Vec<String> = path
        .components()
        .filter_map(|c| match c {
            Component::CurDir => None,
            Component::RootDir => Some(String::new()),
            Component::ParentDir => Some("..".to_string()),
            Component::Normal(p) => Some(escape_component(p)),
            Component::Prefix(p) => Some(p.as_os_str().to_string_lossy().into_owned()),
        })
        .collect();
    match parts.as_slice() {
        [] => ".".to_string(),
        [root] if root.is_empty() => "/".to_string(),
        _ => parts.join("/"),
    }
}

/// Shard K of N (0-based): the inputs whose stable hash of the name is K modulo N.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub k: u64,
    pub n: u64,
}

impl std::str::FromStr for Shard {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Shard, String> {
        let (k, n) = s
            .split_once('/')
            .ok_or_else(|| format!("expected K/N (e.g. 0/4), got {s:?}"))?;
        let k: u64 = k
            .trim()
            .parse()
            .map_err(|_| format!("bad shard index {k:?}"))?;
        let n: u64 = n
            .trim()
            .parse()
            .map_err(|_| format!("bad shard count {n:?}"))?;
        if n == 0 || k >= n {
            return Err(format!("shard {k}/{n}: need 0 <= K < N"));
        }
        Ok(Shard { k, n })
    }
}

impl Shard {
    /// Does this shard take the input of this name? FNV-1a of the name's UTF-8 bytes: the same
    /// on every machine and every run.
    pub fn takes(&self, name: &str) -> bool {
        crate::catalog::fnv1a(name.as_bytes()) % self.n == self.k
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_of_given_paths() {
        assert_eq!(given_name(Path::new("./a/b.png")), "a/b.png");
        assert_eq!(given_name(Path::new("/data/x.fits")), "/data/x.fits");
        assert_eq!(given_name(Path::new("../n/")), "../n");
        assert_eq!(given_name(Path::new(".")), ".");
        assert_eq!(given_name(Path::new("/")), "/");
    }

    #[test]
    fn lists_skip_blanks_and_comments() {
        let text = "a.png\n\n# a comment\nsub dir/b.fits\r\n";
        let got = read_list(&mut text.as_bytes(), "t").unwrap();
        assert_eq!(
            got,
            [PathBuf::from("a.png"), PathBuf::from("sub dir/b.fits")]
        );
    }
}
