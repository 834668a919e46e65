//! `gpustar catalog import`: a star catalog to gpustar's binary catalog file (or hip2.dat to
//! the catalog CSV the repository ships).

use anyhow::{Context, Result, bail};
use gpustar::catalog::formats::{self, Format};
use gpustar::catalog::{Catalog, store};
use std::io::Write;
use std::path::Path;
use std::process::ExitCode;

/// The magnitude cut of the CSV output when none is given (what catalog/hip2_hp8.csv holds).
const CSV_MAX_MAG: f64 = 8.0;

/// Import `input` and write it to `output`: the binary catalog file, or for a `.csv` name (or
/// stdout) gpustar's catalog CSV, which only hip2.dat makes.
pub(crate) fn import_cmd(
    input: &Path,
    format: Option<Format>,
    max_mag: Option<f64>,
    output: Option<&Path>,
) -> Result<ExitCode> {
    let bytes = std::fs::read(input).with_context(|| format!("cannot read {}", input.display()))?;
    let source = input.display().to_string();
    let csv_out = output.is_none_or(|p| p.extension().is_some_and(|e| e == "csv"));
    let out = if csv_out {
        let format = format.or_else(|| Format::detect(&bytes));
        if format != Some(Format::Hip2) {
            bail!(
                "{source}: the catalog CSV is made from hip2.dat only; give -o FILE (not .csv) \
                 for a gpustar catalog file"
            );
        }
        let text = std::str::from_utf8(&bytes).with_context(|| format!("{source}: not text"))?;
        gpustar::catalog::import_hip2(text, max_mag.unwrap_or(CSV_MAX_MAG))?.into_bytes()
    } else {
        let imported = formats::read(&bytes, format, max_mag, &source)?;
        let n = imported.stars.len();
        let catalog = Catalog::new(imported.stars, imported.names, &source, 0);
        let file = store::write(&catalog);
        eprintln!(
            "{source}: {}, {n} stars{} -> {} ({} bytes)",
            imported.format.name(),
            max_mag.map_or(String::new(), |m| format!(" at or brighter than {m}")),
            output.expect("not stdout").display(),
            file.len()
        );
        file
    };
    match output {
        Some(p) => {
            std::fs::write(p, out).with_context(|| format!("cannot write {}", p.display()))?
        }
        None => std::io::stdout().write_all(&out)?,
    }
    Ok(ExitCode::SUCCESS)
}
