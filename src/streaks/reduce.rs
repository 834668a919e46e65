//! From fitted streaks to records: RA/Dec of the ends through the plate solution (gpustar's
//! own attitude and camera, or the FITS header's TAN/TAN-SIP WCS), their times from the
//! header's time keywords, and topocentric Az/El for the station.

use super::fit::{StreakFit, length};
use super::join_named::join_named_pieces;
pub use super::options::Astrometry;
use super::options::StreakOptions;
use crate::catalog::vector_to_radec;
use crate::record::{StreakEnd, StreakRecord};
use crate::sky::{self, Exposure, Utc};
use crate::solve::{Outcome, Solution};
use std::collections::BTreeMap;

/// FWHM of a Gaussian in units of its σ.
const FWHM_PER_SIGMA: f64 = 2.354_820_045_030_949;

/// The records of a frame's streaks, and the warnings a person should see (no plate
/// solution, no time, no station), each said once per frame. `size` is the frame's (width,
/// height), which a header WCS is checked against.
pub fn records(
    found: &[StreakFit],
    sol: &Solution,
    keywords: &BTreeMap<String, String>,
    size: (u32, u32),
    opts: &StreakOptions,
) -> (Vec<StreakRecord>, Vec<String>) {
    let mut warnings = Vec::new();
    if found.is_empty() {
        return (Vec::new(), warnings);
    }
    let get = |k: &str| keywords.get(k).cloned();
    let plate = plate(sol, keywords, size, opts.astrometry, &mut warnings);
    let (exposure, w) = sky::exposure_from_header(&get);
    warnings.extend(w);
    let station = match opts.station {
        Some(s) => Some(s),
        None => {
            let (s, w) = sky::station_from_header(&get);
            warnings.extend(w);
            s
        }
    };
    let station_name = station_name(&get, station.as_ref());
    if exposure.is_none() {
        warnings.push("no exposure time in the header: streak ends have no time, Az or El".into());
    }
    let mut eop_warned = false;
    let mut end = |x: f64, y: f64, edge: Option<bool>, t: Option<Utc>| {
        let radec = plate.as_ref().and_then(|p| p.radec(x, y));
        let t = t.filter(|_| edge != Some(true));
        let azel = match (radec, t, station) {
            (Some((ra, dec)), Some(t), Some(st)) => {
                let (table_dut1, xp, yp, w) = sky::earth_orientation(&t);
                if let (Some(w), None, false) = (w, opts.dut1_s, eop_warned) {
                    warnings.push(w);
                    eop_warned = true;
                }
                let dut1 = opts.dut1_s.unwrap_or(table_dut1);
                match sky::az_el(ra, dec, &t, &st, dut1, xp, yp) {
                    Ok(v) => Some(v),
                    Err(e) => {
                        warnings.push(format!("no Az/El at ({x:.1}, {y:.1}): {e}"));
                        None
                    }
                }
            }
            _ => None,
        };
        StreakEnd {
            x,
            y,
            ra_deg: radec.map(|r| r.0),
            dec_deg: radec.map(|r| r.1),
            edge,
            time_utc: t.map(|t| t.iso()),
            az_deg: azel.map(|a| a.0),
            el_deg: azel.map(|a| a.1),
        }
    };
    let times = |e: &Exposure| [e.start, e.end];
    let mut build = |f: &StreakFit| {
        let t = exposure.as_ref().map(times);
        let ends = [0, 1].map(|k| {
            let (x, y) = f.ends[k];
            end(x, y, Some(f.edge[k]), t.map(|t| t[k]))
        });
        // The other way along: each place at the other end's time (its Az/El with it).
        let reversed = [0, 1].map(|k| {
            let (x, y) = f.ends[1 - k];
            end(x, y, Some(f.edge[1 - k]), t.map(|t| t[k]))
        });
        let mid = (!f.edge[0] && !f.edge[1]).then(|| {
            let (x, y) = (
                0.5 * (f.ends[0].0 + f.ends[1].0),
                0.5 * (f.ends[0].1 + f.ends[1].1),
            );
            end(x, y, None, exposure.as_ref().map(Exposure::mid))
        });
        StreakRecord {
            ends,
            direction_known: false,
            mid,
            length_px: length(f),
            width_px: f.sigma_px * FWHM_PER_SIGMA,
            flux: f.flux,
            snr: f.snr,
            fit_rms_px: f.fit_rms_px,
            station: station_name.clone(),
            tracklet: None,
            tracklet_index: None,
            satellite: None,
            uncorrelated: None,
            reversed: Some(Box::new(reversed)),
            exposure_utc: exposure.as_ref().map(|e| [e.start.iso(), e.end.iso()]),
        }
    };
    let mut out: Vec<StreakRecord> = found.iter().map(&mut build).collect();
    if let Some(catalog) = &opts.tle {
        match (station, exposure) {
            (Some(station), Some(exposure)) => {
                let (table_dut1, xp, yp, _) = sky::earth_orientation(&exposure.mid());
                let frame = super::identify::FrameSky {
                    catalog,
                    station,
                    exposure,
                    dut1_s: opts.dut1_s.unwrap_or(table_dut1),
                    xp,
                    yp,
                };
                frame.identify(&mut out, &opts.identify);
                // Pieces of one object's broken streak, joined by their match, matched again;
                // kept apart when the whole does not match the object.
                if let Some(joined) = join_named_pieces(found, &out) {
                    let mut again: Vec<StreakRecord> = joined.iter().map(&mut build).collect();
                    frame.identify(&mut again, &opts.identify);
                    if again.len() < out.len() && whole_matches(&out, &again) {
                        out = again;
                    }
                }
            }
            _ => warnings.push(
                "--tle: no station or no exposure time, so the streaks are not matched to the \
                 elements"
                    .into(),
            ),
        }
    }
    // Each said once, though the joined streaks' ends were reduced again.
    let mut said = std::collections::HashSet::new();
    warnings.retain(|w| said.insert(w.clone()));
    (out, warnings)
}

/// Do the joined records keep every object the pieces were matched to?
fn whole_matches(pieces: &[StreakRecord], joined: &[StreakRecord]) -> bool {
    let named = |r: &[StreakRecord]| {
        let mut n: Vec<u64> = r
            .iter()
            .filter_map(|s| s.satellite.as_ref().map(|m| m.norad))
            .collect();
        n.sort_unstable();
        n.dedup();
        n
    };
    named(pieces) == named(joined)
}

/// Header keywords that name the station, in order of preference.
const STATION_NAME_KEYS: [&str; 3] = ["OBSERVAT", "SITE", "TELESCOP"];

/// The station as the TDM names it (PARTICIPANT_1): the header's name for it, and its
/// coordinates when known; `None` when neither is.
fn station_name(
    get: &dyn Fn(&str) -> Option<String>,
    station: Option<&sky::Station>,
) -> Option<String> {
    let name = STATION_NAME_KEYS
        .iter()
        .find_map(|k| crate::sky::value(get, k));
    let at = station.map(|s| {
        format!(
            "lat {:.5} lon {:.5} h {:.1} m",
            s.lat_deg, s.lon_deg, s.height_m
        )
    });
    match (name, at) {
        (Some(n), Some(at)) => Some(format!("{n} ({at})")),
        (Some(n), None) => Some(n),
        (None, Some(at)) => Some(format!("station at {at}")),
        (None, None) => None,
    }
}

/// A map from pixels to ICRS.
enum Plate<'a> {
    /// gpustar's solution: the fitted camera, then the attitude.
    Solved(&'a crate::solve::refine::Refined),
    Header(crate::io::wcs::HeaderWcs),
}

impl Plate<'_> {
    fn radec(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        match self {
            Plate::Solved(r) => {
                let v = r.r.transpose() * r.camera.pixel_to_vector(x, y);
                Some(vector_to_radec(&v))
            }
            Plate::Header(w) => w.pixel_to_radec(x, y),
        }
    }
}

fn plate<'a>(
    sol: &'a Solution,
    keywords: &BTreeMap<String, String>,
    size: (u32, u32),
    mode: Astrometry,
    warnings: &mut Vec<String>,
) -> Option<Plate<'a>> {
    if mode != Astrometry::Header
        && let Outcome::Solved(r, _) = &sol.outcome
    {
        return Some(Plate::Solved(r));
    }
    if mode == Astrometry::Solve {
        warnings.push("the frame is not solved: streak ends have no RA/Dec, Az or El".into());
        return None;
    }
    match crate::io::wcs::HeaderWcs::from_keywords(keywords, size) {
        Ok(Some(w)) => Some(Plate::Header(w)),
        Ok(None) => {
            warnings.push(
                "the frame is not solved and its header has no celestial WCS: streak ends \
                 have no RA/Dec, Az or El"
                    .into(),
            );
            None
        }
        Err(e) => {
            warnings.push(format!(
                "the header's WCS cannot be used ({e}): streak ends have no RA/Dec, Az or El"
            ));
            None
        }
    }
}
