//! `gpustar report`: a run's records summarised on stdout, and with `--html` as a page of
//! plots (`gpustar::report`).

use super::console::print_all;
use anyhow::{Result, bail};
use clap::Args;
use gpustar::io::guard::{Claims, Kind, check_replaceable, write_atomically};
use gpustar::report;
use std::path::PathBuf;
use std::process::ExitCode;

/// Lines that are not records listed on stderr; the rest are counted.
const BAD_LINES_SHOWN: usize = 10;

const REPORT_HELP: &str = "\
Examples:
  gpustar report run.jsonl                      # the summary
  gpustar report run.jsonl --html run.html      # and a page of plots
  gpustar report shard1.jsonl shard2.jsonl      # several runs together, per run and folder

Reads JSON Lines (or CSV) as batch writes them; a line that is not a record is counted and
named on stderr, not fatal. Exit status: 0 when the summary was made; 2 when a file cannot be
read, none holds a record, or --html is refused.";

#[derive(Args, Debug)]
#[command(after_help = REPORT_HELP)]
pub struct ReportArgs {
    /// Result records of `batch` or `solve` (JSON Lines, or CSV with its header).
    #[arg(required = true, value_name = "RUN")]
    pub runs: Vec<PathBuf>,
    /// Also write a self-contained HTML page (inline SVG plots, no scripts): availability per
    /// folder, residual and match-count histograms, residual against matches, and the attitude
    /// over time of sequences and of folders of dated frames.
    #[arg(long, value_name = "FILE")]
    pub html: Option<PathBuf>,
    /// Replace a file at the --html path that gpustar did not write (never a RUN).
    #[arg(long, requires = "html")]
    pub overwrite: bool,
}

pub(crate) fn report_cmd(a: ReportArgs) -> Result<ExitCode> {
    // The page is checked before anything is read: a refusal costs nothing.
    if let Some(out) = &a.html {
        let mut claims = Claims::new();
        for r in &a.runs {
            claims.input(r, "a RUN file");
        }
        claims.output(out, "--html")?;
        check_replaceable(out, Kind::Report, a.overwrite)?;
    }
    let runs = a
        .runs
        .iter()
        .map(|p| report::read_run(p))
        .collect::<gpustar::Result<Vec<_>>>()?;
    let bad: Vec<&report::BadLine> = runs.iter().flat_map(|r| &r.bad).collect();
    for b in bad.iter().take(BAD_LINES_SHOWN) {
        eprintln!("gpustar: warning: {b}");
    }
    if bad.len() > BAD_LINES_SHOWN {
        eprintln!(
            "gpustar: warning: … and {} more lines that are not records",
            bad.len() - BAD_LINES_SHOWN
        );
    }
    if runs.iter().all(|r| r.rows.is_empty()) {
        let names: Vec<String> = a.runs.iter().map(|p| p.display().to_string()).collect();
        bail!(
            "{} {} no result records{}",
            names.join(", "),
            if names.len() == 1 { "holds" } else { "hold" },
            if bad.is_empty() {
                ""
            } else {
                " (see the lines above)"
            }
        );
    }
    let summary = report::summarise(&runs);
    if let Some(out) = &a.html {
        write_atomically(out, report::html::render(&summary).as_bytes())?;
    }
    print_all(&report::text::render(&summary))
}
