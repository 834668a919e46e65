//! `gpustar evaluate`: score records against a simulation's truth.

use super::console::print_all;
use anyhow::Result;
use gpustar::io::output::{self};
use std::path::Path;
use std::process::ExitCode;

/// Score a record file against a simulation's truth.
pub(crate) fn evaluate_cmd(
    results: &Path,
    truth: &Path,
    tolerance_deg: f64,
    id_tolerance_px: f64,
    per_frame: bool,
) -> Result<ExitCode> {
    let truth = gpustar::simulate::read_truth(truth)?;
    let records = output::read_records(results)?;
    let (s, frames) =
        gpustar::simulate::evaluate::evaluate(&truth, &records, tolerance_deg, id_tolerance_px);
    let mut text = String::new();
    if per_frame {
        for f in &frames {
            text += &serde_json::to_string(f)?;
            text.push('\n');
        }
    }
    text += &serde_json::to_string_pretty(&s)?;
    text.push('\n');
    print_all(&text)
}
