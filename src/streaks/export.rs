//! `--tdm` and `--iod`: the streaks of a run as orbit-determination users read them.
//!
//! Each tracklet ([`super::tracklet`]: the streaks of one object in consecutive frames) is
//! one object. A streak whose direction is known (linked into a tracklet, or matched one way
//! only to `--tle` elements) gives its ends inside the frame at the exposure's start and end;
//! one whose direction is unknown gives its midpoint at mid-exposure, which is order-free (as
//! stvid's IOD output does); a streak with neither (an end on the edge and no direction) is
//! left out (counted).
//!
//! An object matched to `--tle` elements (the NORAD id most of its streaks were matched to)
//! is written with that NORAD id and the elements' international designator. Others follow
//! stvid's scheme for unidentified objects (stvid/satellite.py numbers a frame's unidentified
//! tracks 99999, 99998, …; stvid/extract.py designates them `YY DDD+500 A`): the `n`-th
//! unidentified tracklet of the run is object 99999 − (n mod 10,000) and its designation's
//! piece counts the unidentified tracklets of its UTC day (A … Z, AA … ZZ without I and O),
//! so no two tracklets of a run share an object. The TDM names the same object in
//! PARTICIPANT_2, with the tracklet's name (its first input file and streak number).

use super::formats::{self, AngleObs, IodObs, Track};
use crate::error::{Context, Result};
use crate::io::guard::{Claims, Kind, check_replaceable, remember_written, write_atomically};
use crate::record::{Record, StreakEnd, StreakRecord};
use crate::sky::Utc;
use std::collections::BTreeMap;
use std::io::Read;
use std::path::PathBuf;

/// The observations of a run, collected record by record (in input order).
#[derive(Debug, Default)]
pub struct Exports {
    pub tdm: Option<PathBuf>,
    pub iod: Option<PathBuf>,
    /// The COSPAR station number written in IOD lines (9999, no site, when not given).
    pub iod_station: u16,
    /// One per tracklet with a timed observation, in the order they began.
    groups: Vec<Group>,
    /// Tracklet name → its place in `groups`.
    index: std::collections::HashMap<String, usize>,
    /// Streaks without a timed observation with RA/Dec (edge ends, no time, no plate, a
    /// partial `--tle` match).
    pub left_out: usize,
}

/// One tracklet's observations.
#[derive(Debug)]
struct Group {
    /// The tracklet's name (`FILE#N` of its first streak), escaped for the TDM.
    name: String,
    station: String,
    /// (observation, time uncertainty s, position uncertainty deg), in the order taken.
    obs: Vec<(AngleObs, f64, f64)>,
    /// NORAD id → (streaks matched to it, name, international designator).
    votes: BTreeMap<u64, (usize, String, Option<String>)>,
}

/// What a finished run writes: the TDM's tracks and the IOD lines.
struct Written {
    tracks: Vec<Track>,
    iod_lines: Vec<String>,
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
            let (time_unc_s, pos_unc_deg) = uncertainties(s, r.rmse_arcsec);
            let timed = |e: &StreakEnd| {
                let (Some(t), Some(ra), Some(dec)) = (&e.time_utc, e.ra_deg, e.dec_deg) else {
                    return None;
                };
                (e.edge != Some(true)).then(|| AngleObs {
                    time_utc: t.clone(),
                    ra_deg: ra,
                    dec_deg: dec,
                    az_deg: e.az_deg,
                    el_deg: e.el_deg,
                })
            };
            // Matched to only part of its predicted path: its ends are not timed.
            let partial = s
                .satellite
                .as_ref()
                .is_some_and(|m| m.seen_fraction.is_some());
            let obs: Vec<AngleObs> = if partial {
                Vec::new()
            } else if s.direction_known {
                s.ends.iter().filter_map(timed).collect()
            } else {
                s.mid.iter().filter_map(timed).collect()
            };
            if obs.is_empty() {
                self.left_out += 1;
                continue;
            }
            let name = s
                .tracklet
                .clone()
                .unwrap_or_else(|| format!("{}#{}", r.file, k + 1));
            let g = *self.index.entry(name.clone()).or_insert_with(|| {
                self.groups.push(Group {
                    name: formats::kvn_escape(&name),
                    station: s.station.as_deref().map_or_else(
                        || "UNKNOWN STATION (no --station, no station in the header)".to_string(),
                        formats::kvn_escape,
                    ),
                    obs: Vec::new(),
                    votes: BTreeMap::new(),
                });
                self.groups.len() - 1
            });
            let group = &mut self.groups[g];
            group
                .obs
                .extend(obs.into_iter().map(|o| (o, time_unc_s, pos_unc_deg)));
            if let Some(sat) = &s.satellite {
                let v = group.votes.entry(sat.norad).or_insert((
                    0,
                    sat.name.clone(),
                    sat.intl_des.clone(),
                ));
                v.0 += 1;
            }
        }
    }

    /// The tracks and IOD lines of every tracklet, numbering the unidentified ones; a tracklet
    /// either file cannot hold is left out of both (warned about and counted).
    fn written(&self) -> (Written, usize) {
        let mut out = Written {
            tracks: Vec::new(),
            iod_lines: Vec::new(),
        };
        let mut unidentified = 0usize;
        let mut per_day: BTreeMap<String, usize> = BTreeMap::new();
        let mut left_out = 0;
        for g in &self.groups {
            let mut obs = g.obs.clone();
            obs.sort_by(|a, b| a.0.time_utc.cmp(&b.0.time_utc));
            // TDM epochs must differ: one frame's end at the next one's start keeps the first.
            obs.dedup_by(|b, a| same_ms(&a.0.time_utc, &b.0.time_utc));
            let first = obs[0].0.time_utc.clone();
            let day = first.get(..10).unwrap_or(&first).to_string();
            // The NORAD id most streaks were matched to (ties: the lower id).
            let voted = g
                .votes
                .iter()
                .max_by(|a, b| a.1.0.cmp(&b.1.0).then(b.0.cmp(a.0)))
                .and_then(|(&norad, (_, name, des))| {
                    let des = des.as_deref().and_then(iod_designation)?;
                    (norad <= 99_999).then(|| (norad as u32, des, name.clone()))
                });
            let identified = voted.is_some();
            let (norad, designation, object) = match voted {
                Some((norad, des, name)) => {
                    let object = format!(
                        "{norad:05} {} ({des}; tracklet {})",
                        formats::kvn_escape(&name),
                        g.name
                    );
                    (norad, des, object)
                }
                None => {
                    let norad = 99_999 - (unidentified % OBJECTS) as u32;
                    let piece = *per_day.get(&day).unwrap_or(&0);
                    let des = match formats::unidentified_designation(&first, piece) {
                        Ok(d) => d,
                        Err(e) => {
                            tracing::warn!("tracklet {} left out of the exports: {e}", g.name);
                            left_out += 1;
                            continue;
                        }
                    };
                    let object = format!("{norad:05} {des} ({})", g.name);
                    (norad, des, object)
                }
            };
            let track = Track {
                object,
                station: g.station.clone(),
                observations: obs.iter().map(|o| o.0.clone()).collect(),
            };
            let lines: crate::Result<Vec<String>> = obs
                .iter()
                .map(|(o, time_unc_s, pos_unc_deg)| {
                    formats::iod_line(&IodObs {
                        norad,
                        intl_des: designation.clone(),
                        station: self.iod_station,
                        // Sky conditions good enough to measure the frame (stvid writes G too).
                        status: 'G',
                        time_utc: o.time_utc.clone(),
                        time_unc_s: *time_unc_s,
                        ra_deg: o.ra_deg,
                        dec_deg: o.dec_deg,
                        pos_unc_deg: *pos_unc_deg,
                        behaviour: ' ',
                    })
                })
                .collect();
            let checked = lines.and_then(|l| {
                formats::tdm_text(
                    "2000-01-01T00:00:00",
                    "GPUSTAR",
                    std::slice::from_ref(&track),
                )?;
                Ok(l)
            });
            match checked {
                Ok(l) => {
                    out.iod_lines.extend(l);
                    out.tracks.push(track);
                    if !identified {
                        unidentified += 1;
                        *per_day.entry(day).or_insert(0) += 1;
                    }
                }
                Err(e) => {
                    tracing::warn!("tracklet {} left out of the exports: {e}", g.name);
                    left_out += 1;
                }
            }
        }
        (out, left_out)
    }

    /// Claim the export paths and refuse, before a run, those that could not be written at
    /// its end: a directory that does not exist, a path that is not a regular file, an input
    /// or another output of the run, or a file gpustar did not write (replaced only with
    /// `overwrite`). IOD lines carry no mark of their writer: gpustar knows an IOD file as its
    /// own by the stamp it kept when it wrote it (unchanged since), or with `resume` (the run
    /// that wrote it goes on, and its exports are written whole again).
    pub fn check_paths(&self, claims: &mut Claims, overwrite: bool, resume: bool) -> Result<()> {
        if let Some(p) = &self.tdm {
            claims.output(p, "--tdm")?;
            check_replaceable(p, Kind::Tdm, overwrite)?;
        }
        if let Some(p) = &self.iod {
            claims.output(p, "--iod")?;
            check_replaceable(p, Kind::Iod, overwrite || resume)?;
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
        let (written, unwritable) = self.written();
        if let Some(p) = &self.tdm {
            match write_tdm(&written.tracks, p, created_utc) {
                Ok(s) => said.push(s),
                Err(e) => failed = Some(e),
            }
        }
        if let Some(p) = &self.iod {
            let mut text = written.iod_lines.join("\n");
            if !text.is_empty() {
                // sattools takes the last byte of every line for its newline.
                text.push('\n');
            }
            match write_atomically(p, text.as_bytes()) {
                Ok(()) => {
                    remember_written(p);
                    said.push(format!(
                        "{} (IOD, {} lines)",
                        p.display(),
                        written.iod_lines.len()
                    ))
                }
                Err(e) => {
                    failed.get_or_insert(e);
                }
            }
        }
        if self.left_out > 0 {
            said.push(format!(
                "{} streaks without a timed observation left out (an end on the frame's edge \
                 and no direction, no time or plate solution, or dark over part of the \
                 exposure: --tle's seen_fraction)",
                self.left_out
            ));
        }
        if unwritable > 0 {
            said.push(format!(
                "{unwritable} tracklets the formats cannot hold left out"
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
}

fn write_tdm(tracks: &[Track], p: &std::path::Path, created_utc: &str) -> Result<String> {
    if tracks.is_empty() {
        // An older TDM of gpustar's would be taken for this run's: it goes. Anything else
        // (another program's TDM, kept with --overwrite; a link) is left as it is.
        let older_is_ours = std::fs::symlink_metadata(p).is_ok_and(|m| m.is_file())
            && std::fs::File::open(p).is_ok_and(|f| {
                let mut head = Vec::new();
                std::io::Read::take(f, 4096).read_to_end(&mut head).is_ok() && Kind::Tdm.ours(&head)
            });
        let removed = if !older_is_ours {
            if std::fs::symlink_metadata(p).is_ok() {
                "; the file there, not a TDM gpustar wrote, left as it was"
            } else {
                ""
            }
        } else {
            match std::fs::remove_file(p) {
                Ok(()) => "; the older file there removed",
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => "",
                Err(e) => {
                    return Err(e).with_context(|| {
                        format!(
                            "no streak with a timed observation, so no TDM; cannot remove the \
                             older {}",
                            p.display()
                        )
                    });
                }
            }
        };
        return Ok(format!(
            "no TDM at {} (no streak with a timed observation; TDM 2.0 requires a \
             segment){removed}",
            p.display()
        ));
    }
    let text = formats::tdm_text(created_utc, "GPUSTAR", tracks)
        .with_context(|| format!("cannot write {}", p.display()))?;
    write_atomically(p, text.as_bytes())?;
    let obs: usize = tracks.iter().map(|t| t.observations.len()).sum();
    Ok(format!(
        "{} (TDM, {} objects, {obs} observations)",
        p.display(),
        tracks.len()
    ))
}

/// Do two UTC strings name the same millisecond (as the formats write them)?
fn same_ms(a: &str, b: &str) -> bool {
    match (Utc::parse(a), Utc::parse(b)) {
        (Ok(x), Ok(y)) => x.seconds_since(&y).abs() < 0.0005,
        _ => a == b,
    }
}

/// An international designator as IOD's columns 7–15 hold it, `YY NNNPPP`: from TLE's
/// `98067A` or OMM's `1998-067A`; `None` for anything else.
pub fn iod_designation(des: &str) -> Option<String> {
    let d = des.trim();
    let (yy, rest) = match d.find('-') {
        Some(4) => (d.get(2..4)?, &d[5..]),
        None => (d.get(..2)?, d.get(2..)?),
        _ => return None,
    };
    let (num, piece) = (rest.get(..3)?, rest.get(3..)?.trim());
    let ok = yy.bytes().all(|c| c.is_ascii_digit())
        && num.bytes().all(|c| c.is_ascii_digit())
        && (1..=3).contains(&piece.len())
        && piece.bytes().all(|c| c.is_ascii_uppercase());
    ok.then(|| format!("{yy} {num}{piece}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::SatelliteRecord;

    /// A named streak is exported with its timed ends; named as a partial match (dark over
    /// part of its exposure, so its ends are not timed), it is left out and counted.
    #[test]
    fn a_partial_match_gives_no_timed_observation() {
        let end = |ra: f64, t: &str| StreakEnd {
            x: 0.0,
            y: 0.0,
            ra_deg: Some(ra),
            dec_deg: Some(20.0),
            edge: Some(false),
            time_utc: Some(t.into()),
            az_deg: None,
            el_deg: None,
        };
        let (t0, t1) = ("2025-03-10T20:00:00.000", "2025-03-10T20:00:04.000");
        let named = |seen_fraction| {
            let mut s = StreakRecord::for_tests(
                [end(10.0, t0), end(10.5, t1)],
                [end(10.5, t0), end(10.0, t1)],
                100.0,
                None,
            );
            s.direction_known = true;
            s.satellite = Some(SatelliteRecord {
                norad: 25544,
                name: "ISS".into(),
                intl_des: Some("98067A".into()),
                cross_track_arcsec: 0.0,
                along_track_s: 0.0,
                seen_fraction,
            });
            let mut r = Record::empty("f.fits", "cpu");
            r.streaks = Some(vec![s]);
            r
        };
        let mut e = Exports::new(None, None, 9999);
        e.add(&named(None));
        assert_eq!(
            (e.groups.len(), e.groups[0].obs.len(), e.left_out),
            (1, 2, 0)
        );
        let mut e = Exports::new(None, None, 9999);
        e.add(&named(Some(0.4)));
        assert_eq!((e.groups.len(), e.left_out), (0, 1));
    }
}
