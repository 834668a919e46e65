//! `gpustar merge`: one record file from the parts of a sharded run.

use super::exit::Exit;
use anyhow::Result;
use gpustar::io::inputs;
use gpustar::io::output::{self, Format, RecordWriter};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Join the record files of a sharded run; with the inputs' directory, check that every input
/// has exactly one record.
pub(crate) fn merge_cmd(
    parts: &[PathBuf],
    dir: Option<&Path>,
    recursive: bool,
    output: Option<&Path>,
) -> Result<ExitCode> {
    let records: Vec<_> = parts
        .iter()
        .map(|p| output::read_records(p))
        .collect::<gpustar::Result<_>>()?;
    let expected: Option<Vec<String>> = match &dir {
        Some(d) => Some(
            inputs::list(d, recursive)?
                .into_iter()
                .map(|i| i.name)
                .collect(),
        ),
        None => None,
    };
    let merged = match output::merge(&records, expected.as_deref()) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("gpustar: error: {e:#}");
            return Ok(Exit::NotStarted.into());
        }
    };
    let out: Box<dyn Write + Send> = match &output {
        Some(p) => {
            // Not over a part: it would be emptied while its records are being written.
            let mut claims = gpustar::io::guard::Claims::new();
            for part in parts {
                claims.input(part, "a part to merge");
            }
            claims.output(p, "-o")?;
            Box::new(output::open_output(p, Format::Jsonl, false, false)?.file)
        }
        None => Box::new(std::io::stdout()),
    };
    let mut w = RecordWriter::new(out, Format::Jsonl, false);
    for r in &merged {
        w.write(r);
    }
    w.flush()?;
    eprintln!(
        "gpustar: merged {} records from {} files{}",
        merged.len(),
        parts.len(),
        if dir.is_some() {
            "; every input exactly once"
        } else {
            ""
        }
    );
    Ok(ExitCode::SUCCESS)
}
