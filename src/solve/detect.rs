//! Detection: threshold → components → centroid, then the star list (brightest first).

use crate::cpu;
use crate::cpu::centroid::Blob;
use crate::cpu::psf_fit::{PsfFit, Window};
use crate::cpu::threshold::{DetectParams, TileStats};
use crate::error::fail;
use crate::io::frame::Frame;

pub mod caption;
pub mod deblend;
mod detection;
pub mod faint;

pub use detection::{Detection, QUAD_STARS};

/// Settings of detection.
#[derive(Clone, Copy, Debug)]
pub struct DetectSettings {
    /// Tile side for background and noise (pixels, 4–64).
    pub tile: u32,
    /// Threshold above the local background, in noise sigmas.
    pub k_sigma: f32,
    /// Smallest component kept (pixels): 2 rejects single hot pixels.
    pub min_area: u32,
    /// How many of the brightest stars go on to identification.
    pub max_stars: usize,
    /// Threshold the frame smoothed by the matched filter (3×3 binomial) as well as the pixel:
    /// fainter stars (see `cpu::threshold::threshold_filtered`).
    pub matched_filter: bool,
    /// How each star's position is measured.
    pub centroid: Centroid,
    /// Split components that hold more than one source (`deblend`; on in `--sequence`, where
    /// particles cross the stars and each other).
    pub deblend: bool,
}

crate::choice! {
    /// How a star's position is measured (`--centroid`).
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Centroid {
        Cog = "cog", "Centre of gravity of the component's background-subtracted pixels (seed 000 \
            eq. 3)",
        Ml = "ml", "Maximum-likelihood fit of a pixel-integrated Gaussian on a 9×9 window \
            (`psf_fit`: the GPU kernel or its CPU twin); the centre of gravity where the fit does \
            not settle. The default: at the Cramér–Rao bound where CoG is 1.2–1.9× it (README, \
            \"Centroids\")",
    }
}

impl DetectSettings {
    /// The defaults (`Default`), as a constant: the run configuration's (`config`) come
    /// from here.
    pub const DEFAULT: DetectSettings = DetectSettings {
        tile: 32,
        k_sigma: 5.0,
        min_area: 2,
        max_stars: 100,
        matched_filter: false,
        centroid: Centroid::Ml,
        deblend: false,
    };
}

impl Default for DetectSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl DetectSettings {
    /// The same with the matched filter on: the detection retry's.
    pub fn filtered(self) -> DetectSettings {
        DetectSettings {
            matched_filter: true,
            ..self
        }
    }

    /// Detection of the sequence stage (`--sequence`): the brightest `max_stars`, deblended.
    pub fn for_sequence(self, max_stars: usize) -> DetectSettings {
        DetectSettings {
            max_stars,
            deblend: true,
            ..self
        }
    }
}

/// The stage parameters for a frame under these settings: with the matched filter, at the
/// frame's own noise gain ([`filter_gain_of`]).
pub fn params(frame: &Frame, s: &DetectSettings) -> DetectParams {
    params_at(frame, s, filter_gain_of(frame, s))
}

/// The matched filter's noise gain for a frame under these settings
/// ([`cpu::threshold::filter_gain`]; [`cpu::threshold::FILTER_NONE`] without the filter):
/// frames of a GPU batch are detected together where their gains agree.
pub fn filter_gain_of(frame: &Frame, s: &DetectSettings) -> u32 {
    if s.matched_filter {
        let gain = cpu::threshold::filter_gain(&frame.pixels, frame.width, frame.height);
        tracing::debug!("the matched filter's noise gain: {gain} (6 for white noise)");
        gain
    } else {
        cpu::threshold::FILTER_NONE
    }
}

/// [`params`] with the matched filter's gain given.
pub fn params_at(frame: &Frame, s: &DetectSettings, gain: u32) -> DetectParams {
    DetectParams::new(
        frame.width,
        frame.height,
        s.tile,
        s.k_sigma,
        frame.saturation as u32,
    )
    .with_filter_gain(gain)
}

/// Indices of `frames` grouped by their matched filter's gain under `s` (one group, in order,
/// without the filter), each group with its gain.
pub fn gain_groups(frames: &[&Frame], s: &DetectSettings) -> Vec<(u32, Vec<usize>)> {
    let mut groups: std::collections::BTreeMap<u32, Vec<usize>> = Default::default();
    for (i, f) in frames.iter().enumerate() {
        groups.entry(filter_gain_of(f, s)).or_default().push(i);
    }
    groups.into_iter().collect()
}

/// Run the CPU twins of the detection kernels: the blobs in label order.
pub fn blobs_cpu(frame: &Frame, p: &DetectParams) -> Vec<Blob> {
    blobs_cpu_with(
        frame,
        p,
        &cpu::tile_clip::clipped_tile_stats(&frame.pixels, p),
    )
}

/// [`blobs_cpu`] with the frame's tile statistics already computed (under parameters of the
/// same tile side and threshold).
fn blobs_cpu_with(frame: &Frame, p: &DetectParams, tiles: &[TileStats]) -> Vec<Blob> {
    let runs = cpu::threshold::threshold(&frame.pixels, tiles, p);
    let labels = cpu::components::components(&runs, p.width);
    cpu::centroid::centroid(&frame.pixels, &runs, &labels, tiles, p)
}

/// Smallest component kept with the matched filter: a star of peak SNR 4 sets about five
/// pixels, a hot pixel one (two with one noisy neighbour). Noise smoothed by the filter sets
/// three: the filter's level takes the noise as white, and a JPEG's is not (its blocks carry
/// it from pixel to pixel), so that on 8-bit JPEG frames most of the filter's new detections
/// were of 3 pixels (228 of 293 on f8, docs/speed.md "8-bit noise"), none of them a star;
/// on the FITS frames the stars it found were of 4 pixels or more, and of the detection
/// retry's 3-pixel components none was a star.
pub const MIN_AREA_FILTERED: u32 = 4;

/// Turn blobs into the star list: drop those smaller than `min_area` (hot pixels), order by
/// flux (ties by label, so the order is total), keep the brightest `max_stars`.
pub fn star_list(blobs: &[Blob], s: &DetectSettings) -> Vec<Detection> {
    // With the matched filter a hot pixel's neighbours need only reach 0.375 k sigmas to join
    // it (a few per cent of them do by chance); two of them rarely.
    let min_area = if s.matched_filter {
        s.min_area.max(MIN_AREA_FILTERED)
    } else {
        s.min_area
    };
    let mut kept: Vec<&Blob> = blobs.iter().filter(|b| b.area >= min_area).collect();
    kept.sort_by(|a, b| b.m0.cmp(&a.m0).then(a.label.cmp(&b.label)));
    kept.truncate(s.max_stars);
    kept.iter()
        .map(|b| {
            let (x, y) = b.centre();
            Detection {
                x,
                y,
                flux: b.m0 as f64,
                area: b.area,
                peak: b.peak,
                saturated: b.saturated > 0,
                sigma_px: None,
            }
        })
        .collect()
}

/// The star list of a frame's blobs, with each position measured as the settings say (the
/// PSF fits by the CPU twin).
pub fn stars(frame: &Frame, blobs: &[Blob], s: &DetectSettings) -> Vec<Detection> {
    let mut out = stars_with(&[frame], &[blobs], s, fit_cpu).expect("the CPU fits");
    out.pop().unwrap_or_default()
}

/// The star lists of a batch of frames (with their blobs), without burned-in captions
/// (`caption`), deblended when the settings say
/// (`deblend`, on the CPU for both backends), each position measured as the settings say
/// ([`fit_positions`]).
pub fn stars_with(
    frames: &[&Frame],
    blobs: &[&[Blob]],
    s: &DetectSettings,
    fit: impl FnOnce(&[Window]) -> crate::error::Result<Vec<Option<PsfFit>>>,
) -> crate::error::Result<Vec<Vec<Detection>>> {
    let mut lists = unfitted_stars(frames, blobs, s);
    fit_positions(frames, &mut lists, s, fit)?;
    Ok(lists)
}

/// [`stars_with`] before the positions are measured: each star at its centre of gravity.
pub fn unfitted_stars(
    frames: &[&Frame],
    blobs: &[&[Blob]],
    s: &DetectSettings,
) -> Vec<Vec<Detection>> {
    let mut lists: Vec<Vec<Detection>> = blobs.iter().map(|b| star_list(b, s)).collect();
    for (list, frame) in lists.iter_mut().zip(frames) {
        caption::drop_caption_rows(list, frame.height);
    }
    if s.deblend {
        for (list, frame) in lists.iter_mut().zip(frames) {
            *list = deblend::deblend(frame, list, s.k_sigma as f64, s.max_stars);
        }
    }
    lists
}

/// Each star's position measured as the settings say: with `--centroid ml` every unsaturated
/// star's window goes to `fit` in one call (the CPU twin, or the GPU kernel in one submission
/// for the batch); a star whose window leaves the frame, or whose fit does not settle, keeps
/// its centre of gravity.
pub fn fit_positions(
    frames: &[&Frame],
    lists: &mut [Vec<Detection>],
    s: &DetectSettings,
    fit: impl FnOnce(&[Window]) -> crate::error::Result<Vec<Option<PsfFit>>>,
) -> crate::error::Result<()> {
    if s.centroid != Centroid::Ml {
        return Ok(());
    }
    // (frame, star) of each window, in order.
    let mut at = Vec::new();
    let mut windows = Vec::new();
    for (f, (frame, list)) in frames.iter().zip(lists.iter()).enumerate() {
        for (k, d) in list.iter().enumerate().filter(|(_, d)| !d.saturated) {
            let w = cpu::psf_fit::window(&frame.pixels, frame.width, frame.height, d.x, d.y);
            if let Some(w) = w {
                at.push((f, k));
                windows.push(w);
            }
        }
    }
    let fits = fit(&windows)?;
    if fits.len() != windows.len() {
        fail!(Gpu, "one PSF fit per window");
    }
    for ((f, k), fit) in at.into_iter().zip(fits) {
        if let Some(p) = fit {
            let d = &mut lists[f][k];
            (d.x, d.y) = (p.x, p.y);
            d.sigma_px = Some(((p.sx * p.sx + p.sy * p.sy) / 2.0).sqrt());
        }
    }
    Ok(())
}

/// The CPU twin of the PSF fit over windows, as [`stars_with`] takes it.
pub fn fit_cpu(w: &[Window]) -> crate::error::Result<Vec<Option<PsfFit>>> {
    Ok(w.iter().map(cpu::psf_fit::psf_fit).collect())
}

/// Detect stars in a frame on the CPU.
pub fn detect(frame: &Frame, s: &DetectSettings) -> Vec<Detection> {
    stars(frame, &blobs_cpu(frame, &params(frame, s)), s)
}

/// A frame's detection on the CPU that keeps its tile statistics for the detection retry: the
/// matched filter thresholds against the same tiles (only the comparison differs), which a
/// sparse frame had computed twice.
pub struct Detector<'f> {
    frame: &'f Frame<'f>,
    settings: DetectSettings,
    tiles: Vec<TileStats>,
}

impl<'f> Detector<'f> {
    /// The frame's tile statistics under `settings`.
    pub fn new(frame: &'f Frame<'f>, settings: &DetectSettings) -> Self {
        // The tiles do not depend on the matched filter: its gain is measured when it runs.
        let p = params_at(frame, settings, cpu::threshold::FILTER_NONE);
        let tiles = cpu::tile_clip::clipped_tile_stats(&frame.pixels, &p);
        Detector {
            frame,
            settings: *settings,
            tiles,
        }
    }

    /// [`detect`] under the settings.
    pub fn detect(&self) -> Vec<Detection> {
        self.detect_with(&self.settings)
    }

    /// [`detect`] under the settings with the matched filter on (the detection retry).
    pub fn detect_filtered(&self) -> Vec<Detection> {
        self.detect_with(&self.settings.filtered())
    }

    /// [`detect`] under `s` (this detector's tile statistics: `s` may differ from its settings
    /// only in the matched filter).
    pub fn detect_with(&self, s: &DetectSettings) -> Vec<Detection> {
        stars(self.frame, &self.blobs_with(s), s)
    }

    /// The blobs under `s` (as [`Detector::detect_with`]).
    pub fn blobs_with(&self, s: &DetectSettings) -> Vec<Blob> {
        blobs_cpu_with(self.frame, &params(self.frame, s), &self.tiles)
    }
}

/// The detections less those the PSF model does not fit: unsaturated, their PSF window within
/// the frame, and yet their fit did not settle (`--centroid ml`). On a 200-pixel raw DSLR crop
/// (`tiny.fits`, 10″/px) three of the five brightest detections were such blobs; in its
/// solution with `--mag-limit 11.5` (which matches them too) their centres lie 16–19″
/// (1.6–1.8 px) from their catalog stars, where the 19 others lie within 5″: blends of Tycho-2
/// pairs 4 px apart, whose centres fall between the stars, so that no quad holding them is a
/// catalog quad. Not every blend is caught: two stars of σ 1.3 px 3.2 px apart are fitted as
/// one. None when no detection among the brightest [`QUAD_STARS`] is one (the list would be
/// the same), or with centres of gravity (no fits).
pub fn point_sources(
    dets: &[Detection],
    width: u32,
    height: u32,
    s: &DetectSettings,
) -> Option<Vec<Detection>> {
    use cpu::psf_fit::HALF;
    if s.centroid != Centroid::Ml {
        return None;
    }
    let (w, h) = (i64::from(width), i64::from(height));
    let unsettled = |d: &Detection| {
        let (cx, cy) = (d.x.round() as i64, d.y.round() as i64);
        let inside = cx - HALF >= 0 && cy - HALF >= 0 && cx + HALF < w && cy + HALF < h;
        d.sigma_px.is_none() && !d.saturated && inside
    };
    let n = dets.len().min(QUAD_STARS);
    if !dets[..n].iter().any(unsettled) {
        return None;
    }
    Some(dets.iter().filter(|d| !unsettled(d)).copied().collect())
}

/// The matched filter's detection of a star the first detection found moves it by less than
/// this (pixels), the false-match test's smallest radius (`refine::CONFIDENCE_RADIUS_FLOOR_PX`,
/// which refine's tests hold equal to it; refine reads detections, so not read from there). Of 1,400
/// independent frames at 8–18°, 154 reached the detection retry and 80 of those showed the
/// same stars again: moved by at most 0.26 px (PSF fits by about 1e-9 px, centres of gravity
/// of the larger components more), in another brightness order in a third of them. The retry
/// solved 30 frames, none of the 80.
pub const SAME_STAR_PX: f64 = 0.5;

/// Whether the matched filter's detections `filtered` hold a star that the first ones,
/// `first`, do not: unless they are as many and each has its own counterpart among `first`
/// within [`SAME_STAR_PX`]. When they do not, the detection retry would try the same stars
/// again, so it is skipped (docs/speed.md, "Fail fast: no detection retry without a new star").
pub fn adds_stars(first: &[Detection], filtered: &[Detection]) -> bool {
    if first.len() != filtered.len() {
        return true;
    }
    let mut taken = vec![false; first.len()];
    let near = |a: &Detection, b: &Detection| (a.x - b.x).hypot(a.y - b.y);
    !filtered.iter().all(|f| {
        let nearest = (0..first.len())
            .filter(|&k| !taken[k])
            .min_by(|&a, &b| near(f, &first[a]).total_cmp(&near(f, &first[b])));
        match nearest {
            Some(k) if near(f, &first[k]) <= SAME_STAR_PX => {
                taken[k] = true;
                true
            }
            _ => false,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f64, y: f64) -> Detection {
        Detection {
            x,
            y,
            flux: 1.0,
            area: 4,
            peak: 10,
            saturated: false,
            sigma_px: None,
        }
    }

    #[test]
    fn point_sources_leave_out_unsettled_fits_only() {
        let fitted = |x: f64, y: f64| Detection {
            sigma_px: Some(0.05),
            ..at(x, y)
        };
        let ml = DetectSettings::default();
        // Fits everywhere, or none where the window leaves the frame or the star is
        // saturated: the same list, so None.
        let mut sat = at(50.0, 50.0);
        sat.saturated = true;
        let clean = [fitted(10.0, 10.0), at(2.0, 50.0), sat, at(97.0, 40.0)];
        assert_eq!(point_sources(&clean, 100, 100, &ml), None);
        // A fit that did not settle inside the frame (a blend) goes; the others stay, in order.
        let blend = at(40.0, 60.0);
        let list = [
            fitted(10.0, 10.0),
            blend,
            at(2.0, 50.0),
            sat,
            fitted(70.0, 30.0),
        ];
        let kept = point_sources(&list, 100, 100, &ml).unwrap();
        assert_eq!(kept, vec![list[0], list[2], list[3], list[4]]);
        // Only the brightest QUAD_STARS are looked at for one.
        let mut long: Vec<Detection> = (0..QUAD_STARS)
            .map(|k| fitted(10.0 + k as f64, 20.0))
            .collect();
        long.push(blend);
        assert_eq!(point_sources(&long, 100, 100, &ml), None);
        // Centres of gravity have no fits at all: nothing to tell.
        let cog = DetectSettings {
            centroid: Centroid::Cog,
            ..ml
        };
        assert_eq!(point_sources(&list, 100, 100, &cog), None);
    }

    /// The matched filter's list keeps components of 4 pixels or more (the noise it smooths
    /// sets 3); the pixel threshold's keeps 2 or more (a hot pixel sets 1).
    #[test]
    fn the_matched_filter_keeps_components_of_four_pixels() {
        let blobs: Vec<Blob> = (1..=5)
            .map(|area| Blob {
                label: area,
                area,
                m0: 100 * area as u64,
                mx: 1000 * area as u64,
                my: 1000 * area as u64,
                ..Blob::default()
            })
            .collect();
        let areas = |s: &DetectSettings| -> Vec<u32> {
            star_list(&blobs, s).iter().map(|d| d.area).collect()
        };
        assert_eq!(areas(&DetectSettings::default()), vec![5, 4, 3, 2]);
        assert_eq!(areas(&DetectSettings::default().filtered()), vec![5, 4]);
    }

    #[test]
    fn the_same_stars_in_another_order_add_none() {
        let first = [at(10.0, 10.0), at(50.0, 60.0), at(300.0, 20.0)];
        let moved = [at(50.1, 59.9), at(300.0, 20.2), at(10.0, 10.0)];
        assert!(!adds_stars(&first, &moved));
        assert!(!adds_stars(&first, &first));
        // A new star, one more star, a star moved by more than the tolerance.
        let new = [at(10.0, 10.0), at(50.0, 60.0), at(700.0, 20.0)];
        assert!(adds_stars(&first, &new));
        assert!(adds_stars(
            &first,
            &[first.as_slice(), &[at(1.0, 1.0)]].concat()
        ));
        assert!(adds_stars(
            &first,
            &[at(10.0, 10.0), at(50.0, 60.6), at(300.0, 20.0)]
        ));
        // Two filtered stars near one first star: one of them is new.
        let pair = [at(10.0, 10.0), at(10.3, 10.0), at(300.0, 20.0)];
        assert!(adds_stars(&first, &pair));
    }
}
