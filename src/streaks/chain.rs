//! A chain of stars or a streak? Stars that happen to lie on a line make a "track" whose fit
//! passes every test a streak passes, and a tumbling object's streak rises and falls, breaks
//! and flashes along its track as a chain of stars does. What tells them apart is what a
//! chain is: point sources, each as wide along the track as the PSF, with nothing between
//! them. So the along-track profile is explained by point sources alone — PSF-shaped peaks
//! at its maxima, no closer than a star can be told from its neighbour — and the candidate is
//! a chain when they explain it to within the noise; whatever light they leave (a level
//! between flashes, a lit stretch between two gaps, light rising and falling more slowly
//! than the PSF) is light a chain of stars cannot have. Catalog stars at the peaks' places
//! (when the frame solved) are the other half of the test:
//! `catalog_chain.rs`.

/// What the point-source model makes of a track's along-track profile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Chain {
    /// Peaks the model places (maxima at least 4 noise sigmas high, 1.3 FWHM apart).
    pub peaks: usize,
    /// Share of the profile's light (its positive part) the point sources explain.
    pub explained: f64,
    /// RMS of what they leave, less the noise, over the median peak's height.
    pub excess: f64,
    /// Share of neighbouring peaks (of those at least half the median's height) with
    /// background between them: the profile between the two falls to 60 % of the lower one or
    /// less, by 3 noise sigmas or more, and to no more than the two sources' own wings (light
    /// that stays up between peaks is a lit track, not two stars).
    pub dips: f64,
    /// Point sources explain the profile: at least two peaks, background between 40 % of
    /// neighbouring peaks, ≥ 80 % of the light explained, and no more than 22 % of a peak's
    /// height left beyond the noise.
    pub is_chain: bool,
}

/// Peaks closer than this many FWHM are one star's (two stars this close are one blob).
const MIN_SEPARATION_FWHM: f64 = 1.3;
/// A peak stands this many noise sigmas of the profile above the background.
const PEAK_SIGMAS: f64 = 4.0;
// The thresholds sit between what independently simulated chains of stars and tumbling
// objects' streaks gave (scripts/sim_streaks.py --glints --hard-negatives, seeds 11 and 7,
// 400 frames; remeasured with the width taken across the track): of 396 chain candidates
// 393 pass as chains (82-98 % explained, at most 0.16 left, background between 62-100 % of
// neighbouring peaks; the other 3, under 72 px, are refused as short unsteady tracks); of
// 539 streak candidates none does: the 29 with background between 40 % or more of their
// peaks (flashes, deep periodic light curves) are at most 77 % explained, and the 135
// explained 80 % or more (a level tiled by peaks) have background between at most 33 % of
// them. ASTRiDE's broken streak: 82 %, 0.25 left (background between 51 %).
const MIN_EXPLAINED: f64 = 0.8;
const MAX_EXCESS: f64 = 0.22;
const MAX_DIP: f64 = 0.6;
const DIP_SIGMAS: f64 = 3.0;
const MIN_DIPS: f64 = 0.4;
const FWHM_PER_SIGMA: f64 = 2.354_820_045;
/// The PSF's width across the track is the median of this many of the highest maxima's.
const WIDTH_PEAKS: usize = 9;

/// Assess `profile` (the track's along-track profile in 1 px steps, NaN where unknown; the
/// same cross-track weighting as a star would get), with `noise` its noise (one sample's σ),
/// `sigma` the track's fitted Gaussian σ across it (pixels) and `across_at(i)` the σ of the
/// light across the track where the profile's sample `i` lies (None where it cannot be
/// measured).
///
/// A point source is as wide along the track as across it, so the point sources' width is
/// measured across the track at the profile's highest maxima (their median), not taken from
/// the track's fit: a line fitted through a chain of stars is a compromise between stars a
/// little off it, and its σ came out 0.6 to 1.4 times the stars' own on independent chains
/// (scripts/sim_streaks.py seeds 3 and 9), far enough for their light to look unexplained.
/// On a streak the two agree.
pub fn assess(
    profile: &[f64],
    noise: f64,
    sigma: f64,
    across_at: &dyn Fn(usize) -> Option<f64>,
) -> Chain {
    let none = Chain {
        peaks: 0,
        explained: 0.0,
        excess: f64::INFINITY,
        dips: 0.0,
        is_chain: false,
    };
    let n = profile.len();
    if n < 3 || noise.is_nan() || sigma.is_nan() || noise <= 0.0 || sigma <= 0.0 {
        return none;
    }
    let p = |i: usize| {
        let v = profile[i];
        if v.is_finite() { v } else { 0.0 }
    };
    // Local maxima above the threshold, highest first (ties by position), each farther than
    // the separation from every higher one.
    let mut cand: Vec<usize> = (0..n)
        .filter(|&i| {
            let v = p(i);
            v >= PEAK_SIGMAS * noise && (i == 0 || v >= p(i - 1)) && (i + 1 == n || v >= p(i + 1))
        })
        .collect();
    cand.sort_by(|&a, &b| p(b).total_cmp(&p(a)).then(a.cmp(&b)));
    let sigma = psf_sigma(&cand, across_at).unwrap_or(sigma);
    let sep = MIN_SEPARATION_FWHM * FWHM_PER_SIGMA * sigma;
    let mut peaks: Vec<usize> = Vec::new();
    for i in cand {
        if peaks.iter().all(|&k| (k as f64 - i as f64).abs() >= sep) {
            peaks.push(i);
        }
    }
    if peaks.len() < 2 {
        return Chain {
            peaks: peaks.len(),
            ..none
        };
    }
    peaks.sort_unstable();
    // The PSF along the track need not be the fitted width across it (an elongated PSF), nor
    // Gaussian (stars have wings): the best of a few widths and Moffat exponents, from steep
    // (a Gaussian) to the wings of a Moffat β = 2.
    let mut best: Option<(Chain, Vec<f64>)> = None;
    for f in [0.6, 0.7, 0.85, 1.0, 1.2] {
        for beta in [0.0, 4.0, 3.0, 2.5, 2.0] {
            let c = explain(profile, &peaks, noise, f * FWHM_PER_SIGMA * sigma, beta);
            if best.as_ref().is_none_or(|b| c.0.excess < b.0.excess) {
                best = Some(c);
            }
        }
    }
    let Some((b, model)) = best else {
        return none;
    };
    // Background between neighbours, among the peaks at least half the median's height (a
    // chain's faint extra maxima, noise in a star's wings or between stars, are not stars).
    let mut heights: Vec<f64> = peaks.iter().map(|&k| p(k)).collect();
    heights.sort_by(f64::total_cmp);
    let tall: Vec<usize> = peaks
        .iter()
        .copied()
        .filter(|&k| p(k) >= 0.5 * heights[heights.len() / 2])
        .collect();
    let dipping = tall
        .windows(2)
        .filter(|w| {
            let (at, low) = (w[0] + 1..w[1])
                .map(|i| (i, p(i)))
                .fold((w[0], f64::MAX), |m, v| if v.1 < m.1 { v } else { m });
            let lower = p(w[0]).min(p(w[1]));
            // Deep, deeper than the noise can dig between two maxima of a faint level, and no
            // higher than the two stars' wings make it: a level between flashes is not
            // background.
            low <= MAX_DIP * lower
                && lower - low >= DIP_SIGMAS * noise
                && low - model[at] <= DIP_SIGMAS * noise + 0.15 * lower
        })
        .count();
    let dips = dipping as f64 / (tall.len().max(2) - 1) as f64;
    Chain {
        dips,
        is_chain: b.is_chain && dips >= MIN_DIPS,
        ..b
    }
}

/// The median σ across the track at up to [`WIDTH_PEAKS`] of the highest maxima `cand`
/// (highest first), each at least 2 px from a higher one; None where none is measured.
fn psf_sigma(cand: &[usize], across_at: &dyn Fn(usize) -> Option<f64>) -> Option<f64> {
    let mut at: Vec<usize> = Vec::new();
    for &i in cand {
        if at.len() == WIDTH_PEAKS {
            break;
        }
        if at.iter().all(|&k| k.abs_diff(i) >= 2) {
            at.push(i);
        }
    }
    let mut widths: Vec<f64> = at.into_iter().filter_map(across_at).collect();
    if widths.is_empty() {
        return None;
    }
    widths.sort_by(f64::total_cmp);
    Some(widths[widths.len() / 2])
}

/// A point source's profile of FWHM `fwhm` at distance `d`: a Gaussian for β = 0, else a
/// Moffat of exponent β.
fn point(d: f64, fwhm: f64, beta: f64) -> f64 {
    if beta == 0.0 {
        let s = fwhm / FWHM_PER_SIGMA;
        (-0.5 * (d / s).powi(2)).exp()
    } else {
        let alpha = 0.5 * fwhm / (2f64.powf(1.0 / beta) - 1.0).sqrt();
        (1.0 + (d / alpha).powi(2)).powf(-beta)
    }
}

/// Point sources of the given FWHM and β at `peaks`, amplitudes by non-negative least squares
/// (coordinate descent: the peaks are 1.3 FWHM apart, so they overlap little), and how well
/// they explain the profile.
fn explain(
    profile: &[f64],
    peaks: &[usize],
    noise: f64,
    fwhm: f64,
    beta: f64,
) -> (Chain, Vec<f64>) {
    let n = profile.len();
    // Out to where the profile falls below 1 % of its peak.
    let reach = (fwhm
        * if beta == 0.0 {
            1.3
        } else {
            0.5 * (100f64.powf(1.0 / beta) - 1.0).sqrt() / (2f64.powf(1.0 / beta) - 1.0).sqrt()
        })
    .ceil() as usize;
    let g = |d: f64| point(d, fwhm, beta);
    let range = |k: usize| k.saturating_sub(reach)..(k + reach + 1).min(n);
    let mut model = vec![0.0; n];
    let mut amp = vec![0.0; peaks.len()];
    for _ in 0..20 {
        for (j, &k) in peaks.iter().enumerate() {
            // The best amplitude of this peak with the others held.
            let (mut num, mut den) = (0.0, 0.0);
            for i in range(k) {
                let v = profile[i];
                if !v.is_finite() {
                    continue;
                }
                let gi = g(i as f64 - k as f64);
                num += gi * (v - (model[i] - amp[j] * gi));
                den += gi * gi;
            }
            let a = if den > 0.0 { (num / den).max(0.0) } else { 0.0 };
            for i in range(k) {
                model[i] += (a - amp[j]) * g(i as f64 - k as f64);
            }
            amp[j] = a;
        }
    }
    let (mut light, mut modelled, mut r2, mut m) = (0.0, 0.0, 0.0, 0usize);
    for (i, &v) in profile.iter().enumerate() {
        if !v.is_finite() {
            continue;
        }
        light += v.max(0.0);
        modelled += model[i].min(v.max(0.0));
        r2 += (v - model[i]).powi(2);
        m += 1;
    }
    let mut heights: Vec<f64> = peaks.iter().map(|&k| profile[k]).collect();
    heights.sort_by(f64::total_cmp);
    let height = heights[heights.len() / 2].max(noise);
    let rms = (r2 / m.max(1) as f64).sqrt();
    let excess = (rms * rms - noise * noise).max(0.0).sqrt() / height;
    let explained = if light > 0.0 { modelled / light } else { 0.0 };
    let c = Chain {
        peaks: peaks.len(),
        explained,
        excess,
        dips: 0.0,
        is_chain: explained >= MIN_EXPLAINED && excess <= MAX_EXCESS,
    };
    (c, model)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A profile in 1 px steps: `f(t)` plus deterministic noise of σ `noise`.
    fn profile(n: usize, noise: f64, f: impl Fn(f64) -> f64) -> Vec<f64> {
        let mut state = 12345u64;
        (0..n)
            .map(|i| {
                // A sum of uniforms: near-Gaussian, σ = noise.
                let mut u = 0.0;
                for _ in 0..12 {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    u += (state >> 11) as f64 / (1u64 << 53) as f64;
                }
                f(i as f64) + noise * (u - 6.0)
            })
            .collect()
    }

    /// A named along-track profile.
    type Case = (&'static str, Box<dyn Fn(f64) -> f64>);

    fn star(t: f64, at: f64, h: f64, s: f64) -> f64 {
        h * (-0.5 * ((t - at) / s).powi(2)).exp()
    }

    #[test]
    fn stars_in_a_row_are_a_chain() {
        // Eight stars 12 px apart (σ 1.2 px, so 4.2 FWHM), heights 15 to 40 noise sigmas.
        let hs = [20.0, 35.0, 15.0, 40.0, 22.0, 30.0, 18.0, 25.0];
        let p = profile(100, 1.0, |t| {
            hs.iter()
                .enumerate()
                .map(|(k, &h)| star(t, 8.0 + 12.0 * k as f64, h, 1.2))
                .sum()
        });
        let c = assess(&p, 1.0, 1.2, &|_| None);
        assert!(c.is_chain, "{c:?}");
        assert_eq!(c.peaks, 8);
        // Dense: 5 px apart (1.8 FWHM), the PSF along the track 15 % wider than across.
        let p = profile(60, 1.0, |t| {
            (0..10)
                .map(|k| star(t, 6.0 + 5.0 * k as f64, 25.0, 1.35))
                .sum()
        });
        let c = assess(&p, 1.0, 1.2, &|_| None);
        assert!(c.is_chain, "{c:?}");
    }

    #[test]
    fn a_chain_is_judged_by_its_stars_width_not_the_tracks() {
        // Eleven stars 8.3 px apart, σ 1.13 px (seed 3's frame 22 of sim_streaks.py); the
        // line fitted through them came out σ 0.63: point sources that narrow leave a third
        // of the light unexplained.
        let p = profile(100, 1.0, |t| {
            (0..11)
                .map(|k| star(t, 8.0 + 8.3 * k as f64, 12.0, 1.13))
                .sum()
        });
        assert!(!assess(&p, 1.0, 0.63, &|_| None).is_chain);
        let c = assess(&p, 1.0, 0.63, &|_| Some(1.13));
        assert!(c.is_chain, "{c:?}");
        assert_eq!(c.peaks, 11);
        // Fourteen stars 5.9 px apart, σ 1.19, the line's σ 1.67 (seed 9's frame 187): peaks
        // 1.3 FWHM of the line's σ apart merge neighbours.
        let p = profile(100, 1.0, |t| {
            (0..14)
                .map(|k| star(t, 6.0 + 5.9 * k as f64, 9.0, 1.19))
                .sum()
        });
        let c = assess(&p, 1.0, 1.67, &|_| Some(1.19));
        assert!(c.is_chain, "{c:?}");
        assert_eq!(c.peaks, 14);
    }

    #[test]
    fn streaks_that_rise_fall_break_and_flash_are_not() {
        let s = 1.2;
        let level = |t: f64| if (5.0..195.0).contains(&t) { 10.0 } else { 0.0 };
        let cases: [Case; 4] = [
            ("steady", Box::new(level)),
            (
                "periodic, 30 px, to zero",
                Box::new(move |t| level(t) * (1.0 + (t / 30.0 * std::f64::consts::TAU).sin())),
            ),
            (
                "a gap",
                Box::new(move |t| {
                    if (80.0..120.0).contains(&t) {
                        0.0
                    } else {
                        level(t)
                    }
                }),
            ),
            (
                "flashes on a level",
                Box::new(move |t| {
                    level(t)
                        + [30.0, 70.0, 130.0, 170.0]
                            .iter()
                            .map(|&c| star(t, c, 60.0, s))
                            .sum::<f64>()
                }),
            ),
        ];
        for (what, f) in cases {
            // Across a streak the light is as wide as the PSF wherever it is measured.
            let c = assess(&profile(200, 1.0, f), 1.0, s, &|_| Some(s));
            assert!(!c.is_chain, "{what}: {c:?}");
        }
        // Nothing but noise, or a single star: no chain to speak of.
        assert!(!assess(&profile(100, 1.0, |_| 0.0), 1.0, s, &|_| None).is_chain);
        assert!(
            !assess(
                &profile(100, 1.0, |t| star(t, 50.0, 30.0, s)),
                1.0,
                s,
                &|_| None
            )
            .is_chain
        );
        assert!(!assess(&[], 1.0, s, &|_| None).is_chain);
        assert!(!assess(&[f64::NAN; 20], 1.0, s, &|_| None).is_chain);
    }
}
