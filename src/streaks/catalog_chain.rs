//! The other half of the chain test (`chain.rs` reads the profile): on a solved frame, a
//! track whose peaks are catalog stars is a chain of those stars, however its profile looks.

use super::distance_to;
use super::fit::StreakFit;
use crate::solve::refine::stars_in_view;
use crate::solve::{Outcome, Solution};

/// The streaks of a frame less those that are chains of catalog stars: when the frame solved,
/// a track on which catalog stars lie (within 2 px, or 1.5σ of a wide one) as many as 60 % of
/// its profile's peaks, at least two, is those stars. A streak crossing a star or two has
/// many more peaks (its level's, a PSF width apart) than stars on it.
pub fn off_catalog_chains(found: &[StreakFit], sol: &Solution) -> Vec<StreakFit> {
    let Outcome::Solved(r, refs) = &sol.outcome else {
        return found.to_vec();
    };
    let stars: Vec<(f64, f64)> = stars_in_view(&r.r, refs, &r.camera)
        .into_iter()
        .map(|(_, x, y)| (x, y))
        .collect();
    found
        .iter()
        .filter(|f| {
            let chain = catalog_chain(f, &stars);
            if chain {
                tracing::debug!("streak {:?}: a chain of catalog stars", f.ends);
            }
            !chain
        })
        .copied()
        .collect()
}

/// Do catalog stars at `stars` (pixels) make the track's peaks?
fn catalog_chain(f: &StreakFit, stars: &[(f64, f64)]) -> bool {
    let reach = (1.5 * f.sigma_px).max(2.0);
    let on = stars
        .iter()
        .filter(|&&(x, y)| distance_to(f, x, y) <= reach)
        .count();
    f.chain.peaks >= 2 && on >= 2 && on as f64 >= 0.6 * f.chain.peaks as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::streaks::chain::Chain;

    #[test]
    fn a_track_whose_peaks_are_catalog_stars_is_a_chain_of_them() {
        let chain = |peaks| Chain {
            peaks,
            explained: 0.5,
            excess: 0.5,
            dips: 0.0,
            is_chain: false,
        };
        let fit = |peaks| StreakFit {
            ends: [(10.0, 10.0), (110.0, 10.0)],
            edge: [false, false],
            sigma_px: 1.2,
            amplitude: 50.0,
            noise: 5.0,
            flux: 1e4,
            snr: 100.0,
            fit_rms_px: 0.2,
            gap_fraction: 0.0,
            modulation: 0.5,
            local_snr: 50.0,
            chain: chain(peaks),
            dir: (1.0, 0.0),
            axis_angle_deg: 0.0,
        };
        // Five catalog stars on the track (one 1.5 px off it), one far from it.
        let stars = [
            (12.0, 10.5),
            (35.0, 9.0),
            (60.0, 10.0),
            (85.0, 11.5),
            (108.0, 10.0),
            (60.0, 40.0),
        ];
        assert!(catalog_chain(&fit(6), &stars));
        // A streak of 30 peaks that crosses those five stars is still a streak.
        assert!(!catalog_chain(&fit(30), &stars));
        // One star on a track is no chain.
        assert!(!catalog_chain(&fit(2), &stars[..1]));
    }
}
