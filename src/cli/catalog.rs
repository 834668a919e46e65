//! `gpustar catalog import`: a star catalog to gpustar's binary catalog file (or hip2.dat to
//! the catalog CSV the repository ships).

use anyhow::{Context, Result, bail};
use gpustar::catalog::formats::{self, Format};
use gpustar::catalog::{Catalog, StarId, store};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The magnitude cut of the CSV output when none is given (what catalog/hip2_hp9.csv holds).
const CSV_MAX_MAG: f64 = 9.0;

/// Import `inputs` and write them to `output`: the binary catalog file (several inputs make
/// one catalog, a star in more than one kept once), or for a `.csv` name (or stdout)
/// gpustar's catalog CSV, which only hip2.dat makes. The output is written beside and renamed
/// into place, and only over a file gpustar wrote (never over an input).
pub(crate) fn import_cmd(
    inputs: &[PathBuf],
    format: Option<Format>,
    max_mag: Option<f64>,
    output: Option<&Path>,
) -> Result<ExitCode> {
    let csv_out = output.is_none_or(|p| p.extension().is_some_and(|e| e == "csv"));
    if let Some(out) = output {
        check_output(out, inputs, csv_out)?;
    }
    let read = |input: &PathBuf| -> Result<Vec<u8>> {
        Ok(gpustar::files::read_regular_file(input, "catalog")?)
    };
    let out = if csv_out {
        let [input] = inputs else {
            bail!("the catalog CSV is made from one hip2.dat; give -o FILE (not .csv) to merge");
        };
        let bytes = read(input)?;
        let source = input.display().to_string();
        let bytes = formats::without_bom(&bytes);
        let format = format.or_else(|| Format::detect(bytes));
        if format != Some(Format::Hip2) {
            bail!(
                "{source}: the catalog CSV is made from hip2.dat only; give -o FILE (not .csv) \
                 for a gpustar catalog file"
            );
        }
        let text = std::str::from_utf8(bytes).with_context(|| format!("{source}: not text"))?;
        gpustar::catalog::import_hip2(text, max_mag.unwrap_or(CSV_MAX_MAG))?.into_bytes()
    } else {
        let mut stars = Vec::new();
        let mut names: Vec<String> = Vec::new();
        let mut seen = rustc_hash::FxHashSet::default();
        let mut repeated = 0usize;
        for input in inputs {
            let bytes = read(input)?;
            let source = input.display().to_string();
            let imported = formats::read(&bytes, format, max_mag, &source)?;
            let n = imported.stars.len();
            let offset = names.len() as u32;
            names.extend(imported.names);
            let before = stars.len();
            for mut s in imported.stars {
                // A star of several inputs: the same place to 1 mas (astrometry.net's index
                // files of one series share their stars' quantised positions exactly).
                if inputs.len() > 1 {
                    let key = (
                        (s.ra_rad * 2.0e8).round() as i64,
                        (s.dec_rad * 2.0e8).round() as i64,
                    );
                    if !seen.insert(key) {
                        repeated += 1;
                        continue;
                    }
                }
                if let StarId::Name(i) = s.id {
                    s.id = StarId::Name(i + offset);
                }
                stars.push(s);
            }
            eprintln!(
                "{source}: {}, {n} stars{}{}{}",
                imported.format.name(),
                max_mag.map_or(String::new(), |m| format!(" at or brighter than {m}")),
                if inputs.len() > 1 {
                    format!(", {} new", stars.len() - before)
                } else {
                    String::new()
                },
                left_out(imported.out_of_range, imported.repeated)
            );
        }
        let n = stars.len();
        let source = if inputs.len() == 1 {
            inputs[0].display().to_string()
        } else {
            format!("{} files", inputs.len())
        };
        let catalog = Catalog::new(stars, names, &source, 0);
        let file = store::write(&catalog);
        eprintln!(
            "{n} stars{} -> {} ({} bytes)",
            match repeated {
                0 => String::new(),
                r => format!(" ({r} found in an earlier file left out)"),
            },
            output.expect("not stdout").display(),
            file.len()
        );
        file
    };
    match output {
        Some(p) => gpustar::io::guard::write_atomically(p, &out)?,
        None => std::io::stdout().write_all(&out)?,
    }
    Ok(ExitCode::SUCCESS)
}

/// What a file's import left out (the warnings name the first row of each), or nothing.
fn left_out(out_of_range: usize, repeated: usize) -> String {
    match (out_of_range, repeated) {
        (0, 0) => String::new(),
        (o, 0) => format!(" ({o} out of range left out)"),
        (0, r) => format!(" ({r} repeated ids left out)"),
        (o, r) => format!(" ({o} out of range and {r} repeated ids left out)"),
    }
}

/// Refuse an output that is one of the inputs, or an existing file gpustar did not write (a
/// catalog file, or with `csv` the catalog CSV): an image or a catalog of someone else's is
/// never replaced.
fn check_output(out: &Path, inputs: &[PathBuf], csv: bool) -> Result<()> {
    let same = |a: &Path, b: &Path| match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if let Some(i) = inputs.iter().find(|i| same(i, out)) {
        bail!(
            "-o {} is an input ({}): give another output file",
            out.display(),
            i.display()
        );
    }
    // At most its first bytes, and only of a regular file (a FIFO or a device is refused).
    let Some(head) = gpustar::io::guard::existing_head(out)? else {
        return Ok(());
    };
    let ours = head.is_empty()
        || store::is_store(&head)
        || (csv
            && String::from_utf8_lossy(&head)
                .trim_start()
                .starts_with("hip,ra_rad,"));
    if !ours {
        bail!(
            "{} exists and is not a catalog gpustar wrote: not replaced; remove it or choose \
             another output file",
            out.display()
        );
    }
    Ok(())
}
