//! `gpustar catalog import`: hip2.dat to the catalog CSV.

use anyhow::{Context, Result};
use std::io::Write;
use std::path::Path;
use std::process::ExitCode;

/// Convert Hipparcos-2's hip2.dat into the catalog CSV gpustar reads.
pub(crate) fn import_cmd(hip2: &Path, max_mag: f64, output: Option<&Path>) -> Result<ExitCode> {
    let text =
        std::fs::read_to_string(hip2).with_context(|| format!("cannot read {}", hip2.display()))?;
    let csv = gpustar::catalog::import_hip2(&text, max_mag)?;
    match output {
        Some(p) => {
            std::fs::write(p, csv).with_context(|| format!("cannot write {}", p.display()))?
        }
        None => std::io::stdout().write_all(csv.as_bytes())?,
    }
    Ok(ExitCode::SUCCESS)
}
