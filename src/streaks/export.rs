//! `--tdm` and `--iod`: the streaks of a run as orbit-determination users read them.
//!
//! One frame cannot tell which end of a streak is its start, so these files carry each
//! streak's midpoint at mid-exposure, which is order-free (as stvid's IOD output does); a
//! streak that leaves the frame has no point at a known time and is left out (counted).
//!
//! Each streak is its own object: nothing in one frame says which streaks are one object.
//! IOD lines carry stvid's scheme for unidentified objects (stvid/satellite.py numbers a
//! frame's unidentified tracks 99999, 99998, …; stvid/extract.py designates them `YY DDD+500
//! A`): here the `n`-th streak of the run is object 99999 − (n mod 10,000) and its
//! designation's piece counts the streaks of its UTC day (A … Z, AA … ZZ without I and O), so
//! no two streaks of a run share an object at one time. The TDM names the same object in
//! PARTICIPANT_2, with the input file and streak number.

use super::formats::{self, AngleObs, IodObs, Track};
use crate::error::{Context, Result};
use crate::record::{Record, StreakRecord};
use crate::sky::Utc;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// The observations of a run, collected record by record (in input order).
#[derive(Debug, Default)]
pub struct Exports {
    pub tdm: Option<PathBuf>,
    pub iod: Option<PathBuf>,
    /// The COSPAR station number written in IOD lines (9999, no site, when not given).
    pub iod_station: u16,
    /// One per streak with a timed midpoint.
    tracks: Vec<Track>,
    /// The IOD lines of the same midpoints.
    iod_lines: Vec<String>,
    /// Streaks numbered so far (the next object is 99999 minus this, modulo 10,000).
    objects: usize,
    /// Streaks numbered so far per UTC date (the next designation piece).
    per_day: BTreeMap<String, usize>,
    /// Streaks without a timed midpoint with RA/Dec (edge ends, no time, no plate).
    pub left_out: usize,
}

/// The station code gpustar writes when `--iod-station` is not given: no COSPAR site (sattools
/// drops the lines of a station it does not know).
pub const NO_SITE: u16 = 9999;

/// The objects stvid's scheme numbers down from 99999 before it would leave 90000-99999.
const OBJECTS: usize = 10_000;

/// The least uncertainties written: IOD's resolution in angle format 2 (0.01′ of Dec) and in
/// time (1 ms).
const MIN_POS_UNC_DEG: f64 = 0.01 / 60.0;
const MIN_TIME_UNC_S: f64 = 0.001;

/// Angle between two ICRS directions, degrees.
fn separation_deg(ra0: f64, dec0: f64, ra1: f64, dec1: f64) -> f64 {
    use crate::catalog::radec_to_vector as v;
    crate::camera::angle(&v(ra0, dec0), &v(ra1, dec1)).to_degrees()
}

/// IOD's two uncertainties of a streak's midpoint: (time in s, position in degrees).
///
/// Position: the fit's residual (RMS distance of the track's centroids from its line) times
/// the plate scale along the streak (the ends' angular over their pixel distance), with the
/// plate solution's star residual (`rmse_arcsec`, when gpustar solved the frame) added in
/// quadrature. Time: the midpoint's time is mid-exposure, taken from the header as exact;
/// an along-track error of the same residual is this much time at the streak's rate
/// (exposure × residual / length). Neither is below IOD's resolution (1 ms, 0.01′).
fn uncertainties(s: &StreakRecord, rmse_arcsec: Option<f64>) -> (f64, f64) {
    let [a, b] = &s.ends;
    let px = (b.x - a.x).hypot(b.y - a.y);
    let scale = match (a.ra_deg, a.dec_deg, b.ra_deg, b.dec_deg) {
        (Some(r0), Some(d0), Some(r1), Some(d1)) if px > 0.0 => separation_deg(r0, d0, r1, d1) / px,
        _ => 0.0,
    };
    let rms = s.fit_rms_px.max(0.0);
    let pos = (rms * scale).hypot(rmse_arcsec.unwrap_or(0.0) / 3600.0);
    let exposure = match (&a.time_utc, &b.time_utc) {
        (Some(t0), Some(t1)) => match (Utc::parse(t0), Utc::parse(t1)) {
            (Ok(t0), Ok(t1)) => t1.seconds_since(&t0).abs(),
            _ => 0.0,
        },
        _ => 0.0,
    };
    let time = if px > 0.0 { exposure * rms / px } else { 0.0 };
    let finite = |v: f64, min: f64| if v.is_finite() { v.max(min) } else { min };
    (finite(time, MIN_TIME_UNC_S), finite(pos, MIN_POS_UNC_DEG))
}

impl Exports {
    /// Nothing collected yet; files written only where a path is given. Warns (once, on
    /// stderr) when IOD lines will carry [`NO_SITE`].
    pub fn new(tdm: Option<PathBuf>, iod: Option<PathBuf>, iod_station: u16) -> Exports {
        if iod.is_some() && iod_station == NO_SITE {
            tracing::warn!(
                "--iod without --iod-station: the IOD lines carry station {NO_SITE}, which is \
                 no COSPAR site (sattools drops such lines); give your station's 4-digit \
                 COSPAR number"
            );
        }
        Exports {
            tdm,
            iod,
            iod_station,
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
            let norad = 99_999 - (self.objects % OBJECTS) as u32;
            let day = t.get(..10).unwrap_or(t).to_string();
            let piece = *self.per_day.get(&day).unwrap_or(&0);
            let designation = match formats::unidentified_designation(t, piece) {
                Ok(d) => d,
                Err(e) => {
                    tracing::warn!("{}: streak {} left out of the exports: {e}", r.file, k + 1);
                    self.left_out += 1;
                    continue;
                }
            };
            let (time_unc_s, pos_unc_deg) = uncertainties(s, r.rmse_arcsec);
            let iod = IodObs {
                norad,
                intl_des: designation.clone(),
                station: self.iod_station,
                // Sky conditions good enough to measure the frame (stvid writes G too).
                status: 'G',
                time_utc: t.clone(),
                time_unc_s,
                ra_deg: ra,
                dec_deg: dec,
                pos_unc_deg,
                behaviour: ' ',
            };
            let obs = AngleObs {
                time_utc: t.clone(),
                ra_deg: ra,
                dec_deg: dec,
                az_deg: m.az_deg,
                el_deg: m.el_deg,
            };
            let track = Track {
                object: format!(
                    "{norad:05} {designation} ({}#{})",
                    formats::kvn_escape(&r.file),
                    k + 1
                ),
                station: s.station.as_deref().map_or_else(
                    || "UNKNOWN STATION (no --station, no station in the header)".to_string(),
                    formats::kvn_escape,
                ),
                observations: vec![obs],
            };
            // A streak either file cannot hold is left out of both, never a whole file.
            let line = formats::iod_line(&iod).and_then(|line| {
                formats::tdm_text(
                    "2000-01-01T00:00:00",
                    "GPUSTAR",
                    std::slice::from_ref(&track),
                )?;
                Ok(line)
            });
            match line {
                Ok(line) => {
                    self.iod_lines.push(line);
                    self.tracks.push(track);
                    self.objects += 1;
                    self.per_day.insert(day, piece + 1);
                }
                Err(e) => {
                    tracing::warn!("{}: streak {} left out of the exports: {e}", r.file, k + 1);
                    self.left_out += 1;
                }
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
    /// the old), the IOD file also when the TDM cannot be written; returns what was written,
    /// for the run's summary, or the first error after trying both.
    ///
    /// A run without a timed streak writes no TDM (TDM 2.0 requires a segment): an older TDM
    /// at the path (which [`Exports::check_paths`] found to be gpustar's) is removed, so
    /// that it is not taken for this run's, and the summary says so. Its IOD file is empty.
    pub fn finish(&self, created_utc: &str) -> Result<String> {
        let mut said = Vec::new();
        let mut failed = None;
        if let Some(p) = &self.tdm {
            match self.write_tdm(p, created_utc) {
                Ok(s) => said.push(s),
                Err(e) => failed = Some(e),
            }
        }
        if let Some(p) = &self.iod {
            let mut text = self.iod_lines.join("\n");
            if !text.is_empty() {
                // sattools takes the last byte of every line for its newline.
                text.push('\n');
            }
            match crate::io::output::write_atomically(p, text.as_bytes()) {
                Ok(()) => said.push(format!(
                    "{} (IOD, {} lines)",
                    p.display(),
                    self.iod_lines.len()
                )),
                Err(e) => {
                    failed.get_or_insert(e);
                }
            }
        }
        if self.left_out > 0 {
            said.push(format!(
                "{} streaks without a timed midpoint left out (an end on the frame's edge, or \
                 no time or plate solution)",
                self.left_out
            ));
        }
        match failed {
            Some(e) => {
                if !said.is_empty() {
                    tracing::warn!("wrote {}", said.join("; "));
                }
                Err(e)
            }
            None => Ok(said.join("; ")),
        }
    }

    fn write_tdm(&self, p: &std::path::Path, created_utc: &str) -> Result<String> {
        if self.tracks.is_empty() {
            let removed = match std::fs::remove_file(p) {
                Ok(()) => "; the older file there removed",
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => "",
                Err(e) => {
                    return Err(e).with_context(|| {
                        format!(
                            "no streak with a timed midpoint, so no TDM; cannot remove the \
                             older {}",
                            p.display()
                        )
                    });
                }
            };
            return Ok(format!(
                "no TDM at {} (no streak with a timed midpoint; TDM 2.0 requires a \
                 segment){removed}",
                p.display()
            ));
        }
        let text = formats::tdm_text(created_utc, "GPUSTAR", &self.tracks)
            .with_context(|| format!("cannot write {}", p.display()))?;
        crate::io::output::write_atomically(p, text.as_bytes())?;
        Ok(format!(
            "{} (TDM, {} streaks)",
            p.display(),
            self.tracks.len()
        ))
    }
}
