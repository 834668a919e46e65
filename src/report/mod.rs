//! `gpustar report`: a run's records summarised without a truth file, as text ([`text`]) and
//! as one self-contained HTML page of inline SVG plots ([`html`], drawn with [`svg`]).
//!
//! Reading never stops at a bad line: a run file is often the output of a run that was killed,
//! edited or concatenated, and what it does hold is still worth a summary. Lines that are not
//! records are kept as [`BadLine`]s and reported.

pub mod html;
pub mod svg;
pub mod text;

use crate::error::{Context, Result};
use crate::record::{Record, Status};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What the report uses of one record (JSON Lines or CSV give the same).
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub file: String,
    pub status: Status,
    pub reason: Option<String>,
    pub error: Option<String>,
    pub ra_deg: Option<f64>,
    pub dec_deg: Option<f64>,
    pub roll_deg: Option<f64>,
    pub fov_x_deg: Option<f64>,
    pub stars_detected: Option<f64>,
    pub stars_matched: Option<f64>,
    pub rmse_arcsec: Option<f64>,
    /// `timing_ms.total`; None when the record gives 0 (error records, old CSV).
    pub total_ms: Option<f64>,
    pub epoch: Option<f64>,
    pub sequence_mode: Option<String>,
    pub arcsec_per_px: Option<f64>,
}

impl From<Record> for Row {
    fn from(r: Record) -> Row {
        Row {
            file: r.file,
            status: r.status,
            reason: r.reason,
            error: r.error,
            ra_deg: r.ra_deg,
            dec_deg: r.dec_deg,
            roll_deg: r.roll_deg,
            fov_x_deg: r.fov_x_deg,
            stars_detected: r.stars_detected.map(|n| n as f64),
            stars_matched: r.stars_matched.map(|n| n as f64),
            rmse_arcsec: r.rmse_arcsec,
            total_ms: Some(r.timing_ms.total).filter(|t| *t > 0.0),
            epoch: r.epoch,
            sequence_mode: r.sequence_mode,
            arcsec_per_px: r.pixel_scale.map(|p| p.arcsec_per_px),
        }
    }
}

/// A line of a run file that is not a record.
#[derive(Clone, Debug, PartialEq)]
pub struct BadLine {
    pub path: PathBuf,
    /// 1-based, as editors count.
    pub line: usize,
    pub why: String,
}

impl std::fmt::Display for BadLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: line {}: not a record: {}",
            self.path.display(),
            self.line,
            self.why
        )
    }
}

/// The records of one run file, and its lines that are not records.
#[derive(Clone, Debug, Default)]
pub struct Run {
    pub path: PathBuf,
    pub rows: Vec<Row>,
    pub bad: Vec<BadLine>,
}

/// Read a run file (JSON Lines, or CSV as `--format csv` writes it). Only a file that cannot
/// be read is an error.
pub fn read_run(path: &Path) -> Result<Run> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let text = String::from_utf8_lossy(&bytes);
    let mut run = Run {
        path: path.to_path_buf(),
        ..Run::default()
    };
    let first = text.lines().next().unwrap_or("");
    if first.starts_with("file,status,") {
        read_csv(&text, &mut run);
    } else {
        read_jsonl(&text, &mut run);
    }
    Ok(run)
}

fn read_jsonl(text: &str, run: &mut Run) {
    let torn = !text.is_empty() && !text.ends_with('\n');
    let count = text.lines().count();
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        match serde_json::from_str::<Record>(line) {
            Ok(r) => run.rows.push(r.into()),
            Err(e) => run.bad.push(BadLine {
                path: run.path.clone(),
                line: n + 1,
                why: if torn && n + 1 == count {
                    "an incomplete last line (the run did not finish)".into()
                } else {
                    e.to_string()
                },
            }),
        }
    }
}

fn read_csv(text: &str, run: &mut Run) {
    let mut lines = csv_records(text).into_iter();
    let header: Vec<String> = lines
        .next()
        .map(|(_, h)| h.split(',').map(str::to_string).collect())
        .unwrap_or_default();
    for (line, record) in lines {
        if record.trim().is_empty() {
            continue;
        }
        let row = crate::io::output::csv_fields(record)
            .ok_or_else(|| "a quote left open".to_string())
            .and_then(|fields| csv_row(&header, &fields));
        match row {
            Ok(r) => run.rows.push(r),
            Err(why) => run.bad.push(BadLine {
                path: run.path.clone(),
                line,
                why,
            }),
        }
    }
}

/// The CSV records of `text` with the line each starts on: a newline inside quotes (a file
/// name may hold one) does not end a record.
fn csv_records(text: &str) -> Vec<(usize, &str)> {
    let (mut out, mut start, mut line, mut start_line, mut quoted) = (Vec::new(), 0, 1, 1, false);
    for (i, c) in text.char_indices() {
        match c {
            '"' => quoted = !quoted,
            '\n' => {
                if !quoted {
                    out.push((start_line, text[start..i].trim_end_matches('\r')));
                    start = i + 1;
                    start_line = line + 1;
                }
                line += 1;
            }
            _ => {}
        }
    }
    if start < text.len() {
        out.push((start_line, &text[start..]));
    }
    out
}

/// One CSV record as a [`Row`], its columns found by the header's names (columns are only ever
/// added, so an older file's header is a prefix of today's).
fn csv_row(header: &[String], fields: &[String]) -> std::result::Result<Row, String> {
    if fields.len() != header.len() {
        return Err(format!(
            "{} fields where the header has {}",
            fields.len(),
            header.len()
        ));
    }
    let get = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .map(|i| fields[i].as_str())
            .filter(|v| !v.is_empty())
    };
    let num = |name: &str| -> std::result::Result<Option<f64>, String> {
        get(name)
            .map(|v| {
                v.parse::<f64>()
                    .map_err(|_| format!("{name} is not a number: {v:?}"))
            })
            .transpose()
    };
    let status = match get("status") {
        Some("solved") => Status::Solved,
        Some("unsolved") => Status::Unsolved,
        Some("error") => Status::Error,
        other => return Err(format!("status is not solved|unsolved|error: {other:?}")),
    };
    Ok(Row {
        file: get("file").ok_or("no file name")?.to_string(),
        status,
        reason: get("reason").map(str::to_string),
        error: get("error").map(str::to_string),
        ra_deg: num("ra_deg")?,
        dec_deg: num("dec_deg")?,
        roll_deg: num("roll_deg")?,
        fov_x_deg: num("fov_x_deg")?,
        stars_detected: num("stars_detected")?,
        stars_matched: num("stars_matched")?,
        rmse_arcsec: num("rmse_arcsec")?,
        total_ms: num("total_ms")?.filter(|t| *t > 0.0),
        epoch: num("epoch")?,
        sequence_mode: get("sequence_mode").map(str::to_string),
        arcsec_per_px: num("pixel_scale_arcsec")?,
    })
}

/// Median, 10th and 90th percentiles (interpolated between ranks, as numpy's default), range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dist {
    pub n: usize,
    pub min: f64,
    pub p10: f64,
    pub median: f64,
    pub p90: f64,
    pub max: f64,
}

/// The `q` quantile (0–1) of sorted values, interpolated between the two nearest ranks.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    let at = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let (i, frac) = (at.floor() as usize, at.fract());
    match sorted.get(i + 1) {
        Some(next) => sorted[i] + (next - sorted[i]) * frac,
        None => sorted[i],
    }
}

impl Dist {
    /// Of the finite values; None when there are none.
    pub fn of(values: impl IntoIterator<Item = f64>) -> Option<Dist> {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        Some(Dist {
            n: v.len(),
            min: v[0],
            p10: quantile(&v, 0.1),
            median: quantile(&v, 0.5),
            p90: quantile(&v, 0.9),
            max: v[v.len() - 1],
        })
    }
}

/// Frames of one folder (or of the whole run) by outcome.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Counts {
    pub name: String,
    pub frames: usize,
    pub solved: usize,
    /// Unsolved frames by reason, most frequent first ("unknown" when a record gives none).
    pub unsolved: Vec<(String, usize)>,
    pub errors: usize,
}

impl Counts {
    pub fn unsolved_total(&self) -> usize {
        self.unsolved.iter().map(|(_, n)| n).sum()
    }
    /// Solved frames over all frames (0 for none).
    pub fn availability(&self) -> f64 {
        self.solved as f64 / self.frames.max(1) as f64
    }
}

/// One solved frame of a [`Series`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttitudePoint {
    /// Its place among the series' frames (solved or not), from 0.
    pub index: usize,
    /// Seconds since the series' first frame, from the records' epochs; None when they do not
    /// tell frames apart.
    pub t_s: Option<f64>,
    pub ra_deg: f64,
    pub dec_deg: f64,
    pub roll_deg: f64,
    /// `sequence_mode` was `tracking`.
    pub tracking: bool,
}

/// The attitude over time of one sequence (`--sequence`: one directory), or of a folder whose
/// solved frames carry different epochs (FITS dates).
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub name: String,
    pub frames: usize,
    pub points: Vec<AttitudePoint>,
}

/// Everything the text and the page show.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    pub runs: Vec<(PathBuf, usize)>,
    pub bad: Vec<BadLine>,
    pub all: Counts,
    /// Per top-level folder; with several runs, per run (and folder where a run spans several).
    pub groups: Vec<Counts>,
    /// What a group is: "folder", "run" or "run: folder".
    pub group_by: &'static str,
    /// Error records by message, the file's own name taken out, most frequent first.
    pub errors: Vec<(String, usize)>,
    pub residual: Vec<f64>,
    pub matched: Vec<f64>,
    pub detected: Vec<f64>,
    pub time_ms: Vec<f64>,
    pub fov_x: Vec<f64>,
    pub scale: Vec<f64>,
    /// (matched stars, residual) of each solved frame that gives both.
    pub scatter: Vec<(f64, f64)>,
    pub series: Vec<Series>,
}

/// The folder a record counts under: its name's first component ("." for a file at the top;
/// for an absolute path, as `solve` writes, its directory).
pub fn folder_of(file: &str) -> String {
    if Path::new(file).is_absolute() {
        return Path::new(file)
            .parent()
            .map_or("/".into(), |p| p.display().to_string());
    }
    match file.split_once('/') {
        Some((first, _)) if !first.is_empty() => first.to_string(),
        _ => ".".into(),
    }
}

/// An error message as a kind: the frame's own path taken out (as the message gives it: as
/// named in the record, or with the batch directory before it), so that one cause on many
/// frames counts once.
fn error_kind(r: &Row) -> String {
    let msg = r.error.as_deref().unwrap_or("(no message)");
    let base = r.file.rsplit('/').next().unwrap_or(&r.file);
    if base.is_empty() {
        return msg.to_string();
    }
    let words: Vec<String> = msg
        .split(' ')
        .map(|w| match w.find(base) {
            // A path ending in the name: FILE, with what follows it (a colon).
            Some(i) if i == 0 || w[..i].ends_with('/') => {
                format!("FILE{}", &w[i + base.len()..])
            }
            _ => w.to_string(),
        })
        .collect();
    words.join(" ")
}

fn tally(counts: &mut BTreeMap<String, usize>, key: String) {
    *counts.entry(key).or_default() += 1;
}

/// Most frequent first, then by name.
fn ranked(m: BTreeMap<String, usize>) -> Vec<(String, usize)> {
    let mut v: Vec<_> = m.into_iter().collect();
    v.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    v
}

fn counts_of<'a>(name: String, rows: impl Iterator<Item = &'a Row>) -> Counts {
    let mut c = Counts {
        name,
        ..Counts::default()
    };
    let mut reasons = BTreeMap::new();
    for r in rows {
        c.frames += 1;
        match r.status {
            Status::Solved => c.solved += 1,
            Status::Error => c.errors += 1,
            Status::Unsolved => tally(
                &mut reasons,
                r.reason.clone().unwrap_or_else(|| "unknown".into()),
            ),
        }
    }
    c.unsolved = ranked(reasons);
    c
}

/// The attitude series of the rows, by the series key [`summarise`] gave each: each sequence
/// (rows with `sequence_mode`, by directory), and each group whose solved frames' epochs differ.
fn series_of(rows: &[Keyed]) -> Vec<Series> {
    let mut by_key: BTreeMap<&str, Vec<&Row>> = BTreeMap::new();
    for k in rows {
        by_key.entry(&k.series).or_default().push(k.row);
    }
    let mut out = Vec::new();
    for (name, rows) in by_key {
        let sequence = rows.iter().any(|r| r.sequence_mode.is_some());
        let epochs: Vec<f64> = rows.iter().filter_map(|r| r.epoch).collect();
        let t0 = epochs.iter().copied().fold(f64::INFINITY, f64::min);
        let timed = epochs.iter().any(|e| (e - t0).abs() > 1e-12);
        if !sequence && !timed {
            continue;
        }
        let mut points = Vec::new();
        for (index, r) in rows.iter().enumerate() {
            if let (Status::Solved, Some(ra), Some(dec), Some(roll)) =
                (r.status, r.ra_deg, r.dec_deg, r.roll_deg)
            {
                points.push(AttitudePoint {
                    index,
                    t_s: timed
                        .then_some(r.epoch)
                        .flatten()
                        .map(|e| (e - t0) * 365.25 * 86400.0),
                    ra_deg: ra,
                    dec_deg: dec,
                    roll_deg: roll,
                    tracking: r.sequence_mode.as_deref() == Some("tracking"),
                });
            }
        }
        // Epochs order the frames when they are known (an archive's names need not).
        if timed {
            points.sort_by(|a, b| a.t_s.unwrap_or(0.0).total_cmp(&b.t_s.unwrap_or(0.0)));
        }
        out.push(Series {
            name: name.to_string(),
            frames: rows.len(),
            points,
        });
    }
    out
}

/// A row with the group it counts in and the attitude series it belongs to.
struct Keyed<'a> {
    row: &'a Row,
    group: String,
    series: String,
}

/// Groups are top-level folders; with several runs, each run (named by its file's stem, or
/// its path where two stems are alike), split by folder where it spans several. A series is a
/// sequence's directory, else the group: frames of different runs never join one series.
fn keys(runs: &[Run]) -> Vec<Keyed<'_>> {
    let stem = |r: &Run| {
        r.path.file_stem().map_or_else(
            || r.path.display().to_string(),
            |n| n.to_string_lossy().into(),
        )
    };
    let stems: Vec<String> = runs.iter().map(stem).collect();
    let mut out = Vec::new();
    for (run, name) in runs.iter().zip(&stems) {
        let name = if stems.iter().filter(|s| *s == name).count() > 1 {
            run.path.display().to_string()
        } else {
            name.clone()
        };
        let folders: std::collections::HashSet<String> =
            run.rows.iter().map(|r| folder_of(&r.file)).collect();
        for row in &run.rows {
            let folder = folder_of(&row.file);
            let group = match (runs.len() > 1, folders.len() > 1) {
                (false, _) => folder,
                (true, false) => name.clone(),
                (true, true) => format!("{name}: {folder}"),
            };
            let series = match row.sequence_mode {
                Some(_) => {
                    let dir = crate::sequence::sequence_of(&row.file);
                    let dir = if dir.is_empty() { "." } else { dir };
                    if runs.len() > 1 {
                        format!("{name}: {dir}")
                    } else {
                        dir.to_string()
                    }
                }
                None => group.clone(),
            };
            out.push(Keyed { row, group, series });
        }
    }
    out
}

/// Summarise the runs (their records together).
pub fn summarise(runs: &[Run]) -> Summary {
    let keyed = keys(runs);
    let rows: Vec<&Row> = keyed.iter().map(|k| k.row).collect();
    let group_by = match runs.len() {
        0 | 1 => "folder",
        _ if keyed.iter().any(|k| k.group.contains(": ")) => "run: folder",
        _ => "run",
    };
    let mut s = Summary {
        runs: runs
            .iter()
            .map(|r| (r.path.clone(), r.rows.len()))
            .collect(),
        bad: runs.iter().flat_map(|r| r.bad.iter().cloned()).collect(),
        all: counts_of("all".into(), rows.iter().copied()),
        group_by,
        ..Summary::default()
    };
    // Groups in first-seen order: a batch's records are in path order already.
    let mut order: Vec<&str> = Vec::new();
    let mut members: BTreeMap<&str, Vec<&Row>> = BTreeMap::new();
    for k in &keyed {
        if !members.contains_key(k.group.as_str()) {
            order.push(&k.group);
        }
        members.entry(&k.group).or_default().push(k.row);
    }
    s.groups = order
        .into_iter()
        .map(|k| counts_of(k.to_string(), members[k].iter().copied()))
        .collect();
    let mut errors = BTreeMap::new();
    for r in &rows {
        match r.status {
            Status::Error => tally(&mut errors, error_kind(r)),
            Status::Solved => {
                s.residual.extend(r.rmse_arcsec);
                s.matched.extend(r.stars_matched);
                s.fov_x.extend(r.fov_x_deg);
                s.scale.extend(r.arcsec_per_px);
                if let (Some(m), Some(e)) = (r.stars_matched, r.rmse_arcsec) {
                    s.scatter.push((m, e));
                }
            }
            Status::Unsolved => {}
        }
        if r.status != Status::Error {
            s.detected.extend(r.stars_detected);
            s.time_ms.extend(r.total_ms);
        }
    }
    s.errors = ranked(errors);
    s.series = series_of(&keyed);
    s
}

#[cfg(test)]
mod tests;
