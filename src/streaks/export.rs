//! `--tdm` and `--iod`: the streaks of a run as orbit-determination users read them.
//!
//! One frame cannot tell which end of a streak is its start, so these files carry each
//! streak's midpoint at mid-exposure, which is order-free (as stvid's IOD output does); a
//! streak that leaves the frame has no point at a known time and is left out (counted).

use super::formats::{self, AngleObs, IodObs, Track};
use crate::error::{Context, Result};
use crate::record::Record;
use std::path::PathBuf;

/// The observations of a run, collected record by record (in input order).
#[derive(Debug, Default)]
pub struct Exports {
    pub tdm: Option<PathBuf>,
    pub iod: Option<PathBuf>,
    /// The COSPAR station number written in IOD lines (9999 when not given).
    pub iod_station: u16,
    /// The station's name in the TDM (PARTICIPANT_1).
    pub station_name: String,
    /// One per streak with a timed midpoint.
    tracks: Vec<Track>,
    /// The IOD lines of the same midpoints.
    iod_lines: Vec<String>,
    /// Streaks without a timed midpoint with RA/Dec (edge ends, no time, no plate).
    pub left_out: usize,
}

impl Exports {
    /// Nothing collected yet; files written only where a path is given.
    pub fn new(
        tdm: Option<PathBuf>,
        iod: Option<PathBuf>,
        iod_station: u16,
        station_name: String,
    ) -> Exports {
        Exports {
            tdm,
            iod,
            iod_station,
            station_name,
            ..Exports::default()
        }
    }

    pub fn wanted(&self) -> bool {
        self.tdm.is_some() || self.iod.is_some()
    }

    /// Take the streaks of one record.
    pub fn add(&mut self, r: &Record) {
        for (k, s) in r.streaks.iter().flatten().enumerate() {
            let Some(m) = &s.mid else {
                self.left_out += 1;
                continue;
            };
            let (Some(t), Some(ra), Some(dec)) = (&m.time_utc, m.ra_deg, m.dec_deg) else {
                self.left_out += 1;
                continue;
            };
            let obs = AngleObs {
                time_utc: t.clone(),
                ra_deg: ra,
                dec_deg: dec,
                az_deg: m.az_deg,
                el_deg: m.el_deg,
            };
            let track = Track {
                object: format!("{}#{}", r.file, k + 1),
                station: self.station_name.clone(),
                observations: vec![obs],
            };
            // A streak the TDM cannot hold is left out on its own, never the whole file.
            if let Err(e) = formats::tdm_text(
                "2000-01-01T00:00:00",
                "GPUSTAR",
                std::slice::from_ref(&track),
            ) {
                tracing::warn!("{}: streak {} left out of the exports: {e}", r.file, k + 1);
                self.left_out += 1;
                continue;
            }
            self.tracks.push(track);
            let iod = IodObs {
                norad: 99_999,
                intl_des: String::new(),
                station: self.iod_station,
                status: ' ',
                time_utc: t.clone(),
                time_unc_s: f64::NAN,
                ra_deg: ra,
                dec_deg: dec,
                pos_unc_deg: f64::NAN,
                behaviour: ' ',
            };
            match formats::iod_line(&iod) {
                Ok(line) => self.iod_lines.push(line),
                Err(e) => tracing::warn!("{}: no IOD line for streak {}: {e}", r.file, k + 1),
            }
        }
    }

    /// Refuse, before a run, export paths that could not be written at its end: a directory
    /// that does not exist, or a file there that gpustar did not write (it is never replaced).
    pub fn check_paths(&self) -> Result<()> {
        if let Some(p) = &self.tdm {
            crate::io::output::check_replaceable(
                p,
                |text| text.starts_with("CCSDS_TDM_VERS"),
                "a TDM",
            )?;
        }
        if let Some(p) = &self.iod {
            crate::io::output::check_replaceable(p, formats::iod_like, "IOD lines")?;
        }
        Ok(())
    }

    /// Write the files asked for, each whole or not at all (through a new file renamed over
    /// the old); returns what was written, for the run's summary.
    pub fn finish(&self, created_utc: &str) -> Result<String> {
        let mut said = Vec::new();
        if let Some(p) = &self.tdm {
            let text = formats::tdm_text(created_utc, "GPUSTAR", &self.tracks)
                .with_context(|| format!("cannot write {}", p.display()))?;
            crate::io::output::write_atomically(p, text.as_bytes())?;
            said.push(format!(
                "{} (TDM, {} streaks)",
                p.display(),
                self.tracks.len()
            ));
        }
        if let Some(p) = &self.iod {
            let mut text = self.iod_lines.join("\n");
            if !text.is_empty() {
                text.push('\n');
            }
            crate::io::output::write_atomically(p, text.as_bytes())?;
            said.push(format!(
                "{} (IOD, {} lines)",
                p.display(),
                self.iod_lines.len()
            ));
        }
        if self.left_out > 0 {
            said.push(format!(
                "{} streaks without a timed midpoint left out (an end on the frame's edge, or \
                 no time or plate solution)",
                self.left_out
            ));
        }
        Ok(said.join("; "))
    }
}
