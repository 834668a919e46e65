//! Writing records (JSON Lines or CSV) so that they are never torn, reading back what an
//! earlier run wrote (`--resume`), and merging shard outputs.

use crate::record::{Record, Status};
use anyhow::{Context, Result, bail};
use std::collections::{HashMap, HashSet};
use std::io::{Read, Seek, Write};
use std::path::Path;

/// Output format of the records.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// One JSON object per line (spec/INTERFACE.md).
    Jsonl,
    /// A header and one row per file, without the per-star matches.
    Csv,
}

pub const CSV_HEADER: &str = "file,status,reason,error,ra_deg,dec_deg,roll_deg,qw,qx,qy,qz,fov_x_deg,fov_y_deg,stars_detected,stars_matched,rmse_arcsec,p90_arcsec,max_arcsec,false_match_prob,total_ms,backend,distortion_k1,streaks,sequence_mode,particles";

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

    /// Hand the queued whole lines to the file.
    pub fn flush(&mut self) -> Result<()> {
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

fn csv_row(r: &Record) -> String {
    let num = |v: Option<f64>| v.map(|x| x.to_string()).unwrap_or_default();
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
    ]
    .join(",")
}

/// The first field of a CSV line (the file name), unquoted.
fn csv_first_field(line: &str) -> Option<String> {
    if let Some(rest) = line.strip_prefix('"') {
        let mut out = String::new();
        let mut chars = rest.chars().peekable();
        while let Some(c) = chars.next() {
            if c == '"' {
                if chars.peek() == Some(&'"') {
                    out.push('"');
                    chars.next();
                } else {
                    return Some(out);
                }
            } else {
                out.push(c);
            }
        }
        None
    } else {
        line.split(',').next().map(str::to_string)
    }
}

/// What an earlier run left in an output file.
#[derive(Clone, Debug, Default)]
pub struct Previous {
    /// Files with a complete record.
    pub done: HashSet<String>,
    /// Bytes of an incomplete last line that were cut off.
    pub truncated: u64,
    /// The file already has a CSV header.
    pub has_header: bool,
}

/// Read the complete records of an output file and cut off an incomplete last line (one not
/// ended by a newline, or that does not parse), so that appending continues on a clean line.
pub fn resume_from(path: &Path, format: Format) -> Result<Previous> {
    let mut file = match std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
    {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Previous::default()),
        Err(e) => {
            return Err(e).with_context(|| format!("cannot open {} to resume", path.display()));
        }
    };
    let mut bytes = Vec::new();
    file.read_to_end(&mut bytes)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let mut prev = Previous::default();
    let mut good_end = 0usize;
    let mut start = 0usize;
    while let Some(nl) = bytes[start..].iter().position(|&b| b == b'\n') {
        let line = &bytes[start..start + nl];
        let text = String::from_utf8_lossy(line);
        let name = match format {
            Format::Jsonl => serde_json::from_str::<Record>(&text).ok().map(|r| r.file),
            // The header, or that of an earlier version (columns are only ever added).
            Format::Csv
                if text == CSV_HEADER
                    || CSV_HEADER.starts_with(&*text) && text.starts_with("file,status,") =>
            {
                prev.has_header = true;
                start += nl + 1;
                good_end = start;
                continue;
            }
            Format::Csv => csv_first_field(&text),
        };
        match name {
            Some(n) => {
                prev.done.insert(n);
                start += nl + 1;
                good_end = start;
            }
            // A line that does not parse can only be a torn write followed by more output:
            // stop there, and cut it and everything after it.
            None => break,
        }
    }
    if good_end < bytes.len() {
        prev.truncated = (bytes.len() - good_end) as u64;
        file.set_len(good_end as u64)
            .with_context(|| format!("cannot truncate {}", path.display()))?;
        file.seek(std::io::SeekFrom::End(0))?;
    }
    Ok(prev)
}

/// Read every complete record of a JSON Lines file (an incomplete last line is ignored).
pub fn read_records(path: &Path) -> Result<Vec<Record>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read results {}", path.display()))?;
    let complete = match text.rfind('\n') {
        Some(i) => &text[..=i],
        None => "",
    };
    complete
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(n, l)| {
            serde_json::from_str(l)
                .with_context(|| format!("{}: line {}: not a result record", path.display(), n + 1))
        })
        .collect()
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
        bail!(
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
