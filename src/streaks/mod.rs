//! Satellite streaks in optical-tracking frames (seed 004): found in the frame, measured to
//! sub-pixel ends, kept out of star detection, and reduced to RA/Dec and topocentric Az/El.
//!
//! The pipeline: `streak_filter` (the pixel stage, GPU kernels with their CPU twins in
//! `cpu::streak_filter`: the frame binned 2×2, less its background, smoothed by a 5×5 binomial
//! kernel, thresholded at k noise sigmas) → [`mod@segments`] (components of that mask, lines by a
//! coarse Hough vote per component, collinear pieces joined) → [`fit`] (least squares of a
//! PSF-blurred segment on the full-resolution pixels for the ends, width, flux) → the tests
//! below that keep stars, chains of stars, hot or bleeding columns, correlated noise and noise
//! out → [`reduce`] with [`sky`] (RA/Dec, times, station, Az/El) → [`export`] with [`formats`]
//! (CCSDS TDM, IOD).

pub mod catalog_chain;
pub mod chain;
pub mod export;
pub mod fit;
pub mod formats;
pub mod identify;
pub mod join_named;
mod options;
pub mod reduce;
pub mod segments;
pub mod simulate;
pub mod tracklet;

use crate::cpu::centroid::Blob;
use crate::cpu::streak_filter::{BIN, grid, mask_runs, streak_mask};
use crate::cpu::threshold::{DetectParams, TileStats, background_at};
use crate::io::frame::Frame;
use fit::StreakFit;
pub use fit::length;
pub use options::{StreakOptions, StreakSettings};
use segments::{SegmentSettings, segments};

/// On tracks shorter than [`StreakSettings::min_tumbling_px`]: the largest share of the
/// clear 4 px bins that may fall short of the fit, and the largest modulation of the
/// along-track profile (its excess scatter over its level; a steady streak's is about 0).
const MAX_GAP_FRACTION_SHORT: f64 = 0.25;
/// Largest share of any streak's track where the data fall short of a third of the fit.
const MAX_GAP_FRACTION: f64 = 0.7;
const MAX_MODULATION_SHORT: f64 = 0.3;

/// Lines closer to a frame axis than this (degrees) are suspects: bad columns and rows, and
/// charge bleeding from saturated stars, run exactly along the axes.
const AXIS_DEG: f64 = 0.5;

/// Find the streaks of a frame on the CPU: the pixel stage's twins, then [`measure`].
pub fn find_cpu(
    frame: &Frame,
    p: &DetectParams,
    s: &StreakSettings,
    k_detect: f32,
) -> Vec<StreakFit> {
    detect_cpu(frame, p, s, k_detect).1
}

/// Star detection and streaks of a frame on the CPU, from one set of tiles: the blobs of
/// star detection that are not on a streak, and the streaks.
pub fn detect_cpu(
    frame: &Frame,
    p: &DetectParams,
    s: &StreakSettings,
    k_detect: f32,
) -> (Vec<Blob>, Vec<StreakFit>) {
    use crate::cpu::{centroid, components, threshold};
    let tiles = crate::cpu::tile_clip::clipped_tile_stats(&frame.pixels, p);
    let runs = threshold::threshold(&frame.pixels, &tiles, p);
    let labels = components::components(&runs, p.width);
    let blobs = centroid::centroid(&frame.pixels, &runs, &labels, &tiles, p);
    let mask = streak_mask(&frame.pixels, &tiles, p, &s.params(p, k_detect));
    let streaks = measure(frame, &tiles, &mask, p, s);
    (off_streaks(&blobs, &streaks), streaks)
}

/// From a streak mask (words of the binned grid, as `streak_filter` writes them, on the CPU or
/// the GPU) to the streaks: segments (found on the grid, fitted in pixels), fits, and the tests
/// that keep everything else out. Ordered by SNR,
/// brightest first (ties by position), so the order does not depend on the backend.
pub fn measure(
    frame: &Frame,
    tiles: &[TileStats],
    mask: &[u32],
    p: &DetectParams,
    s: &StreakSettings,
) -> Vec<StreakFit> {
    let (width, height) = grid(p);
    let runs = mask_runs(mask, width, height);
    let segs: Vec<segments::Joined> = segments(&runs, width, &SegmentSettings::default())
        .iter()
        .map(|j| j.in_pixels(BIN))
        .collect();
    // Saturated pixels tell nothing of the profile: the fit leaves them out (NaN).
    let d = |x: u32, y: u32| {
        let v = frame.pixels[(y * p.width + x) as usize];
        if v >= frame.saturation {
            f64::NAN
        } else {
            v as f64 - background_at(tiles, p, x, y) as f64
        }
    };
    let try_fit = |seg: &segments::Segment| -> Option<StreakFit> {
        let Some(f) = fit::fit(&d, p.width, p.height, seg) else {
            tracing::debug!("streak candidate {seg:?}: the fit failed");
            return None;
        };
        match accept(&f, frame, s) {
            Ok(()) => {
                tracing::debug!(
                    "streak {:?}: local snr {:.1}, {:?}",
                    f.ends,
                    f.local_snr,
                    f.chain
                );
                Some(f)
            }
            Err(why) => {
                tracing::debug!("streak candidate {:?}: {why}", f.ends);
                None
            }
        }
    };
    let mut out: Vec<StreakFit> = Vec::new();
    for j in &segs {
        // The joined line, else (a chance alignment along it) its longest piece that is one.
        let found = try_fit(&j.line).or_else(|| {
            (j.pieces.len() > 1)
                .then(|| j.pieces.iter().find_map(try_fit))
                .flatten()
        });
        let Some(f) = found else { continue };
        // One streak is one fit: pieces that were not joined (a defect crossing the track
        // splits it) can lie on the same line; such a pair is fitted again as one.
        match out.iter().position(|g| same_line(g, &f) || touches(g, &f)) {
            None => out.push(f),
            Some(k) => {
                let whole = try_fit(&span(&out[k], &f));
                let longer = if length(&f) > length(&out[k]) {
                    f
                } else {
                    out[k]
                };
                out[k] = whole.unwrap_or(longer);
            }
        }
    }
    // Pieces of a broken streak, farther apart or met in an order that left them apart:
    // joined where the fit of the whole holds, in passes until none is left (three pieces
    // can come in any order). A short piece's direction is the less sure, so the longer
    // piece's line decides; a piece inside the longer one's track that does not fit with it
    // is a part of it, else both are kept.
    let mut joined = true;
    while joined {
        joined = false;
        'pairs: for i in 0..out.len() {
            for j in i + 1..out.len() {
                let (long, short) = if length(&out[i]) >= length(&out[j]) {
                    (i, j)
                } else {
                    (j, i)
                };
                if !broken_pieces(&out[long], &out[short]) {
                    continue;
                }
                match try_fit(&span(&out[long], &out[short])) {
                    Some(whole) => out[long] = whole,
                    None if within(&out[long], &out[short]) => {}
                    None => continue,
                }
                out.remove(short);
                joined = true;
                break 'pairs;
            }
        }
    }
    out.retain(
        |f| match steady_if_short(f, s).and_then(|()| lit_along(f)) {
            Ok(()) => true,
            Err(why) => {
                tracing::debug!("streak candidate {:?}: {why}", f.ends);
                false
            }
        },
    );
    out.sort_by(|a, b| {
        b.snr
            .total_cmp(&a.snr)
            .then(a.ends[0].0.total_cmp(&b.ends[0].0))
            .then(a.ends[0].1.total_cmp(&b.ends[0].1))
    });
    out
}

/// Is this fit a streak, and not a star, a chain of stars, a defect or noise? If not, why.
fn accept(f: &StreakFit, frame: &Frame, s: &StreakSettings) -> Result<(), String> {
    let len = length(f);
    if len < s.min_length_px {
        return Err(format!("{len:.1} px long"));
    }
    if f.snr < s.min_snr {
        return Err(format!("SNR {:.1}", f.snr));
    }
    if f.sigma_px < s.min_sigma_px || f.sigma_px > s.max_sigma_px {
        return Err(format!("profile sigma {:.2} px", f.sigma_px));
    }
    if f.local_snr < s.min_local_snr {
        return Err(format!(
            "stands only {:.1} sigmas above the same filter beside it",
            f.local_snr
        ));
    }
    if f.fit_rms_px > s.max_fit_rms_px {
        return Err(format!(
            "not straight: centroids {:.2} px RMS off the line",
            f.fit_rms_px
        ));
    }
    // Gaps and modulation alone say nothing: a tumbling object's streak has both, and a chain
    // of stars is point sources with nothing between them (short tracks: `steady_if_short`).
    if f.chain.is_chain {
        return Err(format!(
            "a chain of {} point sources ({:.0} % of the light, {:.2} left, background between {:.0} % of them; modulation {:.2}, gaps {:.0} %)",
            f.chain.peaks,
            100.0 * f.chain.explained,
            f.chain.excess,
            100.0 * f.chain.dips,
            f.modulation,
            100.0 * f.gap_fraction
        ));
    }
    // Along a frame axis: a defective column or row is narrow; a bleed trail holds saturated
    // pixels.
    if f.axis_angle_deg < AXIS_DEG && (f.sigma_px < 0.7 || touches_saturation(f, frame)) {
        return Err("a defective or bleeding column or row".into());
    }
    Ok(())
}

/// A short track has too little profile to tell a tumbling object from a chain of stars
/// (pairs of stars, comatic stars in a frame's corner, fixed-pattern noise in real frames
/// pass the point-source test there): a streak shorter than
/// [`StreakSettings::min_tumbling_px`] must be steady and unbroken. Asked of whole streaks,
/// after the pieces of broken ones are joined.
fn steady_if_short(f: &StreakFit, s: &StreakSettings) -> Result<(), String> {
    let len = length(f);
    if len >= s.min_tumbling_px {
        return Ok(());
    }
    if f.gap_fraction > MAX_GAP_FRACTION_SHORT {
        return Err(format!(
            "gaps in {:.0} % of a {len:.0} px track",
            100.0 * f.gap_fraction
        ));
    }
    if f.modulation > MAX_MODULATION_SHORT {
        return Err(format!(
            "modulation {:.2} along a {len:.0} px track",
            f.modulation
        ));
    }
    Ok(())
}

/// A streak is lit along most of its track: where the data fall short of a third of the fitted
/// brightness along more than [`MAX_GAP_FRACTION`] of it, the fit's brightness comes from one
/// source (a saturated star's halo drew a 164 px "streak" from a bleeding star), not from an
/// object's motion. Tumbling objects' gaps and dark phases leave far more of the track lit.
fn lit_along(f: &StreakFit) -> Result<(), String> {
    if f.gap_fraction > MAX_GAP_FRACTION {
        return Err(format!(
            "dark along {:.0} % of the track: the light of one source",
            100.0 * f.gap_fraction
        ));
    }
    Ok(())
}

fn same_line(a: &StreakFit, b: &StreakFit) -> bool {
    let cos = (a.dir.0 * b.dir.0 + a.dir.1 * b.dir.1).abs();
    let mid = |f: &StreakFit| {
        (
            0.5 * (f.ends[0].0 + f.ends[1].0),
            0.5 * (f.ends[0].1 + f.ends[1].1),
        )
    };
    let (m, n) = (mid(b), mid(a));
    let across = (-(m.0 - n.0) * a.dir.1 + (m.1 - n.1) * a.dir.0).abs();
    cos > 2f64.to_radians().cos() && across < 3.0 && distance_to(a, m.0, m.1) < 3.0
}

/// Do both ends of `b` lie within 3 px of `a`'s segment?
fn within(a: &StreakFit, b: &StreakFit) -> bool {
    b.ends.iter().all(|&(x, y)| distance_to(a, x, y) < 3.0)
}

/// Is (x, y) within `tol` of the line of `f`?
fn near_line(f: &StreakFit, (x, y): (f64, f64), tol: f64) -> bool {
    let (x0, y0) = f.ends[0];
    (-(x - x0) * f.dir.1 + (y - y0) * f.dir.0).abs() < tol
}

/// Do two fits lie on one line with their tracks overlapping or less than 10 px apart?
fn touches(a: &StreakFit, b: &StreakFit) -> bool {
    let cos = (a.dir.0 * b.dir.0 + a.dir.1 * b.dir.1).abs();
    cos > 2f64.to_radians().cos()
        && b.ends.iter().all(|&e| near_line(a, e, 3.0))
        && b.ends.iter().any(|&(x, y)| distance_to(a, x, y) < 10.0)
}

/// Are two fits pieces of one broken streak: as wide, `b` on `a`'s line (within 2° and 3 px),
/// and apart by less than 1.5 times their lengths together (or overlapping)? A tumbling object goes dark for part of an
/// exposure (in a shadowed face's turn, or an eclipse): its streak breaks into pieces whose
/// gaps can be as long as the pieces.
fn broken_pieces(a: &StreakFit, b: &StreakFit) -> bool {
    let cos = (a.dir.0 * b.dir.0 + a.dir.1 * b.dir.1).abs();
    if cos <= 2f64.to_radians().cos() || !b.ends.iter().all(|&e| near_line(a, e, 3.0)) {
        return false;
    }
    let gap = b
        .ends
        .iter()
        .map(|&(x, y)| distance_to(a, x, y))
        .fold(f64::MAX, f64::min);
    let (wa, wb) = (a.sigma_px, b.sigma_px);
    wa.max(wb) < 1.5 * wa.min(wb) && gap < 1.5 * (length(a) + length(b))
}

/// The segment from the farther apart of two collinear fits' ends to the other.
fn span(a: &StreakFit, b: &StreakFit) -> segments::Segment {
    let (ux, uy) = a.dir;
    let (x0, y0) = a.ends[0];
    let ts: Vec<f64> = a
        .ends
        .iter()
        .chain(&b.ends)
        .map(|&(x, y)| (x - x0) * ux + (y - y0) * uy)
        .collect();
    let (lo, hi) = ts
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, h), &t| (l.min(t), h.max(t)));
    segments::Segment {
        cx: x0,
        cy: y0,
        ux,
        uy,
        t_min: lo,
        t_max: hi,
        pixels: 0,
    }
}

/// Does any pixel within 2σ of the track reach saturation?
fn touches_saturation(f: &StreakFit, frame: &Frame) -> bool {
    let len = length(f).max(1.0);
    let r = (2.0 * f.sigma_px).max(1.5);
    let [(x0, y0), (x1, y1)] = f.ends;
    let steps = len.ceil() as usize;
    (0..=steps).any(|k| {
        let t = k as f64 / steps as f64;
        let (x, y) = (x0 + t * (x1 - x0), y0 + t * (y1 - y0));
        let (xa, xb) = ((x - r).floor().max(0.0) as u32, (x + r).ceil() as u32);
        let (ya, yb) = ((y - r).floor().max(0.0) as u32, (y + r).ceil() as u32);
        (ya..=yb.min(frame.height - 1)).any(|yy| {
            (xa..=xb.min(frame.width - 1))
                .any(|xx| frame.pixels[(yy * frame.width + xx) as usize] >= frame.saturation)
        })
    })
}

/// Distance of (x, y) from the streak's segment between its ends (pixels).
pub fn distance_to(f: &StreakFit, x: f64, y: f64) -> f64 {
    let [(x0, y0), (x1, y1)] = f.ends;
    let (dx, dy) = (x1 - x0, y1 - y0);
    let l2 = (dx * dx + dy * dy).max(1e-12);
    let t = (((x - x0) * dx + (y - y0) * dy) / l2).clamp(0.0, 1.0);
    ((x - x0 - t * dx).powi(2) + (y - y0 - t * dy).powi(2)).sqrt()
}

/// The blobs of star detection that do not lie on a streak (to star detection a streak is
/// one bright "star", or a row of them): those farther than 3σ + 2 px from every segment.
pub fn off_streaks(blobs: &[Blob], streaks: &[StreakFit]) -> Vec<Blob> {
    blobs
        .iter()
        .filter(|b| {
            let (x, y) = b.centre();
            !streaks
                .iter()
                .any(|f| distance_to(f, x, y) <= 3.0 * f.sigma_px + 2.0)
        })
        .copied()
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A long track dark along most of its length is one source's light, whatever else it
    /// passed; a tumbling object's gaps (up to 60 % here) leave it a streak.
    #[test]
    fn a_track_dark_along_most_of_it_is_no_streak() {
        let fit = |gap_fraction| StreakFit {
            ends: [(10.0, 10.0), (180.0, 110.0)],
            edge: [false, false],
            sigma_px: 2.5,
            amplitude: 500.0,
            noise: 5.0,
            flux: 1e6,
            snr: 500.0,
            fit_rms_px: 0.3,
            gap_fraction,
            modulation: 2.0,
            local_snr: 50.0,
            chain: chain::Chain {
                peaks: 1,
                explained: 0.5,
                excess: 0.5,
                dips: 0.0,
                is_chain: false,
            },
            dir: (0.86, 0.5),
            axis_angle_deg: 30.0,
        };
        assert!(lit_along(&fit(0.6)).is_ok());
        let why = lit_along(&fit(0.9)).unwrap_err();
        assert!(why.contains("dark along 90 %"), "{why}");
    }
}
