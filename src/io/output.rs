//! Writing records (JSON Lines or CSV) so that they are never torn, reading back what an
//! earlier run wrote (`--resume`), and merging shard outputs.

use crate::error::{Context, Result, fail};
use crate::record::{Record, Status};
use std::collections::{HashMap, HashSet};
use std::io::{Read, Seek, Write};
use std::path::Path;

crate::choice! {
    /// Output format of the records.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Format {
        Jsonl = "jsonl", "One JSON object per line (spec/INTERFACE.md)",
        Csv = "csv", "A header and one row per file, without the per-star matches",
    }
}

pub const CSV_HEADER: &str = "file,status,reason,error,ra_deg,dec_deg,roll_deg,qw,qx,qy,qz,fov_x_deg,fov_y_deg,stars_detected,stars_matched,rmse_arcsec,p90_arcsec,max_arcsec,false_match_prob,total_ms,backend,distortion_k1,streaks,sequence_mode,particles,epoch,warnings,hint,sigma_boresight_arcsec,sigma_roll_arcsec,mirrored,pixel_scale_arcsec,pixel_scale_source";

/// Held while records are handed to a file: a process that must end before its run does
/// (a stop request that frames in flight do not heed) takes it first, so that it never ends
/// in the middle of a line.
pub static WRITING: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Writes records as whole lines: lines are collected and handed to the file in one write
/// per flush, so a crash leaves at most one incomplete last line (which `--resume` drops).
pub struct RecordWriter {
    out: Box<dyn Write + Send>,
    format: Format,
    header_pending: bool,
    pending: Vec<u8>,
}

impl RecordWriter {
    /// `header` = write the CSV header first (not when appending to an existing CSV).
    pub fn new(out: Box<dyn Write + Send>, format: Format, header: bool) -> RecordWriter {
        RecordWriter {
            out,
            format,
            header_pending: header && format == Format::Csv,
            pending: Vec::new(),
        }
    }

    /// Queue a record (written at the next flush).
    pub fn write(&mut self, r: &Record) {
        if self.header_pending {
            self.pending.extend_from_slice(CSV_HEADER.as_bytes());
            self.pending.push(b'\n');
            self.header_pending = false;
        }
        match self.format {
            Format::Jsonl => self.pending.extend_from_slice(r.to_json_line().as_bytes()),
            Format::Csv => self.pending.extend_from_slice(csv_row(r).as_bytes()),
        }
        self.pending.push(b'\n');
    }

    /// Hand the queued whole lines to the file (holding [`WRITING`]).
    pub fn flush(&mut self) -> Result<()> {
        let _writing = WRITING.lock().unwrap_or_else(|e| e.into_inner());
        if !self.pending.is_empty() {
            self.out
                .write_all(&self.pending)
                .context("cannot write the results")?;
            self.pending.clear();
        }
        self.out.flush().context("cannot write the results")
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

pub(crate) fn csv_row(r: &Record) -> String {
    // As the JSON record writes numbers: the shortest text that reads back to the value, with
    // an exponent where it is shorter (a false-match probability of 1e-70, not 70 zeros).
    let num = |v: Option<f64>| {
        v.filter(|x| x.is_finite())
            .map(|x| serde_json::to_string(&x).expect("finite numbers serialise"))
            .unwrap_or_default()
    };
    let json = |v: Option<String>| csv_field(&v.unwrap_or_default());
    let int = |v: Option<usize>| v.map(|x| x.to_string()).unwrap_or_default();
    let q = r.quaternion.map(|q| q.map(Some)).unwrap_or([None; 4]);
    let status = match r.status {
        Status::Solved => "solved",
        Status::Unsolved => "unsolved",
        Status::Error => "error",
    };
    [
        csv_field(&r.file),
        status.to_string(),
        csv_field(r.reason.as_deref().unwrap_or("")),
        csv_field(r.error.as_deref().unwrap_or("")),
        num(r.ra_deg),
        num(r.dec_deg),
        num(r.roll_deg),
        num(q[0]),
        num(q[1]),
        num(q[2]),
        num(q[3]),
        num(r.fov_x_deg),
        num(r.fov_y_deg),
        int(r.stars_detected),
        int(r.stars_matched),
        num(r.rmse_arcsec),
        num(r.p90_arcsec),
        num(r.max_arcsec),
        num(r.false_match_prob),
        r.timing_ms.total.to_string(),
        csv_field(&r.backend),
        num(r.distortion_k1),
        // The streaks as their JSON array (empty without --streaks).
        csv_field(
            &r.streaks
                .as_ref()
                .map(|s| serde_json::to_string(s).expect("streaks serialise"))
                .unwrap_or_default(),
        ),
        // With --sequence: the mode, and the particles as their JSON array.
        csv_field(r.sequence_mode.as_deref().unwrap_or_default()),
        csv_field(
            &r.particles
                .as_ref()
                .map(|p| serde_json::to_string(p).expect("particles serialise"))
                .unwrap_or_default(),
        ),
        num(r.epoch),
        // The warnings and the hint as their JSON (empty when none).
        json(
            (!r.warnings.is_empty())
                .then(|| serde_json::to_string(&r.warnings).expect("warnings serialise")),
        ),
        json(
            r.hint
                .as_ref()
                .map(|h| serde_json::to_string(h).expect("hint serialises")),
        ),
        num(r.attitude_sigma_arcsec.as_ref().map(|a| a.boresight)),
        num(r.attitude_sigma_arcsec.as_ref().map(|a| a.roll)),
        r.mirrored.map(|m| m.to_string()).unwrap_or_default(),
        num(r.pixel_scale.as_ref().map(|p| p.arcsec_per_px)),
        csv_field(r.pixel_scale.as_ref().map_or("", |p| p.source.as_str())),
    ]
    .join(",")
}

/// The fields of one CSV record (quotes removed, `""` unescaped), or None when a quote is
/// left open or stray text follows a closing quote.
pub(crate) fn csv_fields(record: &str) -> Option<Vec<String>> {
    let mut fields = vec![String::new()];
    let mut chars = record.chars().peekable();
    let mut quoted = false;
    let mut after_quote = false;
    while let Some(c) = chars.next() {
        let field = fields.last_mut().expect("one field at least");
        match (quoted, c) {
            (true, '"') if chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            (true, '"') => {
                quoted = false;
                after_quote = true;
            }
            (true, c) => field.push(c),
            (false, ',') => {
                fields.push(String::new());
                after_quote = false;
            }
            (false, '"') if field.is_empty() && !after_quote => quoted = true,
            (false, _) if after_quote => return None,
            (false, c) => field.push(c),
        }
    }
    (!quoted).then_some(fields)
}

/// Ends of the CSV records in `bytes`: a newline outside quotes ends one (names may hold
/// newlines inside quotes).
fn csv_record_ends(bytes: &[u8]) -> Vec<usize> {
    let mut ends = Vec::new();
    let mut quoted = false;
    for (i, &b) in bytes.iter().enumerate() {
        match b {
            b'"' => quoted = !quoted,
            b'\n' if !quoted => ends.push(i),
            _ => {}
        }
    }
    ends
}

/// Is this line the CSV header, or that of an earlier version (columns are only ever added)?
fn is_csv_header(line: &str) -> bool {
    line == CSV_HEADER || line.starts_with("file,status,") && CSV_HEADER.starts_with(line)
}

/// What an earlier run left in an output file.
#[derive(Clone, Debug, Default)]
pub struct Previous {
    /// Files with a complete record.
    pub done: HashSet<String>,
    /// Error records kept in the file (not retried): they count in the run's exit status.
    pub errors: usize,
    /// Error records taken out of the file to be tried again (`--retry-errors`).
    pub retried: usize,
    /// Bytes of an incomplete last line that were cut off.
    pub truncated: u64,
    /// The file already has a CSV header.
    pub has_header: bool,
    /// The records kept in the file that have streaks, as their file and streaks only: a
    /// resumed run's `--tdm`/`--iod` are written whole at its end and cover them too.
    pub streaks: Vec<Record>,
}

/// One complete line (JSON Lines) or record (CSV) of an earlier output.
struct Line {
    /// Byte range in the file, newline included.
    range: std::ops::Range<usize>,
    /// The input it is the record of; None for the CSV header.
    file: Option<String>,
    error: bool,
    /// Its streaks (`--streaks` runs), for the exports of a resumed run.
    streaks: Option<Vec<crate::record::StreakRecord>>,
    /// Its plate solution's star residual (the exports' position uncertainty uses it).
    rmse_arcsec: Option<f64>,
}

/// An output file opened for a run: locked against a second writer for as long as it is
/// held, positioned at its end.
pub struct Output {
    pub file: std::fs::File,
    pub previous: Previous,
}

/// The marks of gpustar's output at the start of a line: a record's first key, or the CSV
/// header's first columns.
const JSONL_START: &str = "{\"file\":";
const CSV_START: &str = "file,status,";

/// Does a file starting with `bytes` hold gpustar output of either format? Its first line is
/// a whole record or the CSV header; a file of one unterminated line (a first write torn by a
/// crash) must at least start with a record's first key or the header's first columns. A
/// pretty-printed JSON file (first line `{`) or a text that starts with `f` is not ours.
fn looks_like_output(bytes: &[u8]) -> bool {
    match bytes.iter().position(|&b| b == b'\n') {
        Some(end) => std::str::from_utf8(&bytes[..end])
            .is_ok_and(|t| is_csv_header(t) || serde_json::from_str::<Record>(t).is_ok()),
        None => [JSONL_START, CSV_START]
            .iter()
            .any(|m| bytes.starts_with(m.as_bytes())),
    }
}

/// Open `-o PATH` for a run and lock it, so that a second process on the same file refuses
/// to start instead of writing every record twice.
///
/// Without `resume` the file is emptied, but only when it is empty or holds gpustar output
/// (its first line a record or the CSV header): anything else (a notes file, an input image
/// named by mistake) is refused untouched.
///
/// With `resume` every complete line must be a record of `format` (after the header, for
/// CSV); only an unterminated last line of that format, a write torn by a crash, is cut off.
/// A file of the other format, or one that is not gpustar output, is refused untouched.
/// `retry_errors` takes the error records out (through a new file renamed over the old one),
/// so that their inputs are tried again.
pub fn open_output(
    path: &Path,
    format: Format,
    resume: bool,
    retry_errors: bool,
) -> Result<Output> {
    use std::fs::OpenOptions;
    let shown = path.display();
    // Not a regular file (a terminal, /dev/null, a pipe): written as it is, nothing to read
    // or lock. Opening a FIFO to read would wait forever for a writer.
    if let Ok(m) = std::fs::metadata(path)
        && !m.is_file()
    {
        if resume {
            fail!(
                Output,
                "cannot resume into {shown}: it is not a regular file"
            );
        }
        let file = OpenOptions::new()
            .append(true)
            .open(path)
            .with_context(|| format!("cannot open {shown} to write the results"))?;
        return Ok(Output {
            file,
            previous: Previous::default(),
        });
    }
    let mut file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .with_context(|| format!("cannot open {shown} to write the results"))?;
    lock(&file, path)?;
    let mut bytes = Vec::new();
    file.read_to_end(&mut bytes)
        .with_context(|| format!("cannot read {shown}"))?;
    if !resume {
        if !bytes.is_empty() && !looks_like_output(&bytes) {
            fail!(
                Output,
                "{shown} exists and does not hold gpustar results (its first line is neither a \
                 record nor the CSV header): not overwritten; remove it or choose another \
                 --output"
            );
        }
        file.set_len(0)
            .with_context(|| format!("cannot empty {shown}"))?;
        file.seek(std::io::SeekFrom::Start(0))?;
        return Ok(Output {
            file,
            previous: Previous::default(),
        });
    }
    let (mut lines, complete) = parse_lines(&bytes, format, path)?;
    let tail = &bytes[complete..];
    if !tail.is_empty() && lines.is_empty() && !looks_like_output(tail) {
        fail!(
            Output,
            "{shown} does not hold gpustar results (no complete line, and it does not start \
             like a record): not resumed, not touched"
        );
    }
    let mut previous = Previous {
        truncated: tail.len() as u64,
        has_header: lines.iter().any(|l| l.file.is_none()),
        ..Previous::default()
    };
    for l in &mut lines {
        match &l.file {
            Some(_) if l.error && retry_errors => previous.retried += 1,
            Some(name) => {
                previous.errors += usize::from(l.error);
                previous.done.insert(name.clone());
                if let Some(streaks) = l.streaks.take().filter(|s| !s.is_empty()) {
                    let mut r = Record::empty(name, "");
                    r.streaks = Some(streaks);
                    r.rmse_arcsec = l.rmse_arcsec;
                    previous.streaks.push(r);
                }
            }
            None => {}
        }
    }
    if previous.retried > 0 {
        // Keep every line but the retried error records, in a new file locked before it
        // takes the name: a crash leaves the old file or the new one, never half of either.
        let mut kept = Vec::with_capacity(complete);
        for l in lines.iter().filter(|l| !(l.error && retry_errors)) {
            kept.extend_from_slice(&bytes[l.range.clone()]);
        }
        let tmp = path.with_file_name(format!(
            ".{}.gpustar-retry-{}",
            path.file_name()
                .map_or_else(Default::default, |n| n.to_string_lossy()),
            std::process::id()
        ));
        let mut new = OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&tmp)
            .with_context(|| format!("cannot create {}", tmp.display()))?;
        lock(&new, &tmp)?;
        let written = new
            .write_all(&kept)
            .and_then(|_| new.sync_all())
            .and_then(|_| std::fs::rename(&tmp, path));
        if let Err(e) = written {
            let _ = std::fs::remove_file(&tmp);
            return Err(e).with_context(|| format!("cannot rewrite {shown} without its errors"));
        }
        file = new;
    } else if !tail.is_empty() {
        file.set_len(complete as u64)
            .with_context(|| format!("cannot cut the torn last line off {shown}"))?;
    }
    file.seek(std::io::SeekFrom::End(0))?;
    Ok(Output { file, previous })
}

/// Hold `file`'s exclusive lock (advisory, released when the file is closed), or say who
/// has it.
fn lock(file: &std::fs::File, path: &Path) -> Result<()> {
    match file.try_lock() {
        Ok(()) => Ok(()),
        Err(std::fs::TryLockError::WouldBlock) => fail!(
            Output,
            "{} is being written by another gpustar process (it holds the file's lock): \
             not touched; wait for that run to end, or write elsewhere",
            path.display()
        ),
        // File systems without locks (some network mounts): go on as before.
        Err(std::fs::TryLockError::Error(e)) => {
            tracing::warn!("cannot lock {}: {e}; going on unlocked", path.display());
            Ok(())
        }
    }
}

/// The complete lines of an earlier output of `format`, and where they end; an error, naming
/// the line, when one is not a record of that format.
fn parse_lines(bytes: &[u8], format: Format, path: &Path) -> Result<(Vec<Line>, usize)> {
    let shown = path.display();
    let other = |text: &str| -> &'static str {
        match format {
            Format::Jsonl if is_csv_header(text) => " (it holds CSV results: add --format csv)",
            Format::Csv if serde_json::from_str::<Record>(text).is_ok() => {
                " (it holds JSON Lines results: leave out --format csv)"
            }
            _ => "",
        }
    };
    let ends = match format {
        Format::Jsonl => bytes
            .iter()
            .enumerate()
            .filter(|(_, b)| **b == b'\n')
            .map(|(i, _)| i)
            .collect(),
        Format::Csv => csv_record_ends(bytes),
    };
    let mut lines = Vec::with_capacity(ends.len());
    let mut start = 0;
    // CSV: the header's column count, and where its streaks column is (if it has one).
    let (mut columns, mut streaks_at, mut rmse_at) = (0, None, None);
    for (n, end) in ends.into_iter().enumerate() {
        let text = std::str::from_utf8(&bytes[start..end]).ok();
        let parsed = text.and_then(|text| match format {
            Format::Jsonl => serde_json::from_str::<Record>(text).ok().map(|r| {
                (
                    Some(r.file),
                    r.status == Status::Error,
                    r.streaks,
                    r.rmse_arcsec,
                )
            }),
            Format::Csv if n == 0 => {
                columns = text.split(',').count();
                streaks_at = text.split(',').position(|c| c == "streaks");
                rmse_at = text.split(',').position(|c| c == "rmse_arcsec");
                is_csv_header(text).then_some((None, false, None, None))
            }
            Format::Csv => csv_fields(text).filter(|f| f.len() == columns).map(|f| {
                let streaks = streaks_at
                    .and_then(|c| f.get(c))
                    .filter(|s| !s.is_empty())
                    .and_then(|s| serde_json::from_str(s).ok());
                let rmse = rmse_at.and_then(|c| f.get(c)).and_then(|v| v.parse().ok());
                (Some(f[0].clone()), f[1] == "error", streaks, rmse)
            }),
        });
        let Some((file, error, streaks, rmse_arcsec)) = parsed else {
            let text = String::from_utf8_lossy(&bytes[start..end]);
            let what = if n == 0 && format == Format::Csv {
                "the CSV header"
            } else {
                "a gpustar record"
            };
            fail!(
                Output,
                "{shown}: line {} is not {what}{}: not resumed, not touched",
                n + 1,
                other(&text)
            );
        };
        lines.push(Line {
            range: start..end + 1,
            file,
            error,
            streaks,
            rmse_arcsec,
        });
        start = end + 1;
    }
    Ok((lines, start))
}

/// Put the records of `path` back in input order (`order`: the names of the run's inputs), the
/// CSV header first: `--retry-errors` takes error records out and writes their new records at
/// the end. Written through a new file renamed over the old; records of names not in `order`
/// keep their places after the others.
pub fn restore_input_order(path: &Path, format: Format, order: &[String]) -> Result<()> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let (mut lines, complete) = parse_lines(&bytes, format, path)?;
    let rank: HashMap<&str, usize> = order
        .iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i))
        .collect();
    // The header (no file) first; a stable sort keeps the rest as they were among equals.
    lines.sort_by_key(|l| match &l.file {
        None => (0, 0),
        Some(f) => (1, rank.get(f.as_str()).copied().unwrap_or(usize::MAX)),
    });
    let mut out = Vec::with_capacity(bytes.len());
    for l in &lines {
        out.extend_from_slice(&bytes[l.range.clone()]);
    }
    out.extend_from_slice(&bytes[complete..]);
    crate::io::guard::write_atomically(path, &out)
}

/// Read the records of a JSON Lines file (a torn last line is an error: see
/// [`crate::record::read_jsonl`]).
pub fn read_records(path: &Path) -> Result<Vec<Record>> {
    crate::record::read_jsonl(path, "record")
}

/// Combine shard outputs: every expected input exactly once, in input order. Returns the
/// records, or an error naming what is missing, duplicated or unexpected.
pub fn merge(parts: &[Vec<Record>], expected: Option<&[String]>) -> Result<Vec<Record>> {
    let mut by_name: HashMap<String, Record> = HashMap::new();
    let mut duplicated = Vec::new();
    for r in parts.iter().flatten() {
        if by_name.insert(r.file.clone(), r.clone()).is_some() {
            duplicated.push(r.file.clone());
        }
    }
    let order: Vec<String> = match expected {
        Some(names) => names.to_vec(),
        None => {
            let mut v: Vec<String> = by_name.keys().cloned().collect();
            v.sort();
            v
        }
    };
    let missing: Vec<&String> = order.iter().filter(|n| !by_name.contains_key(*n)).collect();
    let known: HashSet<&String> = order.iter().collect();
    let unexpected: Vec<&String> = by_name.keys().filter(|n| !known.contains(n)).collect();
    if !duplicated.is_empty() || !missing.is_empty() || !unexpected.is_empty() {
        let show = |v: &[&String]| {
            let mut s: Vec<String> = v.iter().take(5).map(|x| x.to_string()).collect();
            if v.len() > 5 {
                s.push(format!("… ({} in all)", v.len()));
            }
            s.join(", ")
        };
        let dup: Vec<&String> = duplicated.iter().collect();
        fail!(
            Output,
            "the shard outputs do not hold every input exactly once: {} missing [{}], {} \
             duplicated [{}], {} not inputs of the directory [{}]",
            missing.len(),
            show(&missing),
            dup.len(),
            show(&dup),
            unexpected.len(),
            show(&unexpected)
        );
    }
    Ok(order
        .into_iter()
        .map(|n| by_name.remove(&n).expect("checked above"))
        .collect())
}
