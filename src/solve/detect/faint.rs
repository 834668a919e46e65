//! Faint sources for `--sequence`, where particles may be as faint as the stars: the frame is
//! thresholded twice, as pixels and smoothed by the matched filter, and the filter's detections
//! complete the plain ones. The filter alone merges neighbours (a particle beside a star becomes
//! one blob, and the star a particle); taken this way, it adds sources without merging any.

use super::{DetectSettings, Detection, Detector, detect, fit_cpu, fit_positions, unfitted_stars};
use crate::cpu::psf_fit::{PsfFit, Window};
use crate::error::Result;
use crate::io::frame::Frame;

/// Extra distance (pixels) beyond a filtered component's own radius within which a plain
/// detection is of the same source.
pub const APART_PX: f64 = 2.0;

/// A filtered detection this much brighter than the one plain detection of its source replaces
/// it: the plain component held only the source's peak, and its flux, which the tracker
/// compares from frame to frame, swung with the noise.
pub const FLUX_GAIN: f64 = 1.5;

/// A frame's detections under `s` (`DetectSettings::for_sequence`), completed by the matched
/// filter's ([`complete`]); the filter's alone when `s` asks for it. On the CPU; the GPU
/// runner makes the two lists with its kernels and completes them the same way.
pub fn detect_with_faint(frame: &Frame, s: &DetectSettings) -> Vec<Detection> {
    if s.matched_filter {
        return detect(frame, s);
    }
    let d = Detector::new(frame, s);
    let filtered = s.filtered();
    let candidates = unfitted_stars(&[frame], &[&d.blobs_with(&filtered)], &filtered);
    let mut out =
        complete(&[frame], vec![d.detect()], candidates, s, fit_cpu).expect("the CPU fits");
    out.pop().unwrap_or_default()
}

/// A batch's `plain` star lists (positions measured) completed by the matched filter's
/// `filtered` ones (at their centres of gravity, as [`unfitted_stars`] leaves them) as
/// [`with_faint`] says, the positions of the filtered stars taken measured by `fit` in one call:
/// most of the filter's stars are the plain ones again, and are not fitted twice.
pub fn complete(
    frames: &[&Frame],
    plain: Vec<Vec<Detection>>,
    filtered: Vec<Vec<Detection>>,
    s: &DetectSettings,
    fit: impl FnOnce(&[Window]) -> Result<Vec<Option<PsfFit>>>,
) -> Result<Vec<Vec<Detection>>> {
    let (kept, mut taken): (Vec<_>, Vec<_>) = plain
        .into_iter()
        .zip(&filtered)
        .map(|(p, f)| choose(p, f))
        .unzip();
    fit_positions(frames, &mut taken, &s.filtered(), fit)?;
    Ok(kept
        .into_iter()
        .zip(taken)
        .map(|(k, t)| merged(k, t))
        .collect())
}

/// `plain` completed by `filtered`, brightest first (ties in the order given, plain first). Each
/// filtered detection, by the plain ones within its radius (from its area) plus [`APART_PX`]:
/// - none: a source only the filter found; added;
/// - one, [`FLUX_GAIN`] times fainter or more: the same source, measured whole; replaces it;
/// - one brighter, or two and more: the plain ones stay (a star's wings, or neighbours merged).
///
/// No plain detection is pushed out: each list holds at most `max_stars` (the sequence's 250),
/// and the two together up to twice that. In a frame full of particles the faintest plain
/// detections are stars, and particles measured whole would have displaced them (on a set of
/// 200 particles a frame, 172 fewer star IDs, docs/sequences.md).
pub fn with_faint(plain: Vec<Detection>, filtered: &[Detection]) -> Vec<Detection> {
    let (kept, taken) = choose(plain, filtered);
    merged(kept, taken)
}

/// The plain detections [`with_faint`] keeps, and the filtered ones it takes.
fn choose(plain: Vec<Detection>, filtered: &[Detection]) -> (Vec<Detection>, Vec<Detection>) {
    let within = |f: &Detection| -> Vec<usize> {
        let r = (f64::from(f.area) / std::f64::consts::PI).sqrt() + APART_PX;
        (0..plain.len())
            .filter(|&i| (plain[i].x - f.x).powi(2) + (plain[i].y - f.y).powi(2) <= r * r)
            .collect()
    };
    let mut replaced = vec![false; plain.len()];
    let mut taken = Vec::new();
    for f in filtered {
        match within(f)[..] {
            [] => taken.push(*f),
            [i] if !replaced[i] && f.flux >= FLUX_GAIN * plain[i].flux => {
                replaced[i] = true;
                taken.push(*f);
            }
            _ => {}
        }
    }
    let kept = plain
        .into_iter()
        .zip(replaced)
        .filter_map(|(d, r)| (!r).then_some(d))
        .collect();
    (kept, taken)
}

/// `kept` and `taken` in one list, brightest first (ties: `kept` first).
fn merged(mut kept: Vec<Detection>, taken: Vec<Detection>) -> Vec<Detection> {
    kept.extend(taken);
    kept.sort_by(|a, b| b.flux.total_cmp(&a.flux));
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(x: f64, y: f64, flux: f64, area: u32) -> Detection {
        Detection {
            x,
            y,
            flux,
            area,
            peak: 0,
            saturated: false,
            sigma_px: None,
        }
    }

    #[test]
    fn the_filter_adds_and_completes_sources_without_merging_any() {
        let star = det(100.0, 100.0, 5000.0, 30);
        let faint_peak = det(300.0, 300.0, 40.0, 2);
        let neighbour = det(106.0, 100.0, 900.0, 12);
        let plain = vec![star, neighbour, faint_peak];
        let filtered = [
            // The star and its neighbour merged into one blob between them.
            det(101.0, 100.0, 6100.0, 60),
            // The faint source's peak measured whole.
            det(300.3, 299.8, 95.0, 9),
            // A source only the filter found.
            det(500.0, 40.0, 60.0, 6),
            // A star's blob a little wider than the plain one: the plain stays.
            det(100.1, 100.0, 5200.0, 40),
        ];
        assert_eq!(
            with_faint(plain.clone(), &filtered),
            vec![star, neighbour, filtered[1], filtered[2]],
            "brightest first"
        );
        // A bright source the filter alone found takes its place by flux among the plain ones.
        let bright_new = det(700.0, 700.0, 2000.0, 20);
        assert_eq!(
            with_faint(plain, &[bright_new]),
            vec![star, bright_new, neighbour, faint_peak]
        );
    }
}
