//! Whether a solution explains the frame's brightest detections. The false-match probability
//! asks whether a wrong attitude could match as many stars by chance; it cannot see a solution
//! that matches real images of the sky which are not the frame's own: a double exposure's
//! fainter copies, or ghosts (internal reflections, a point reflection of the field about a
//! centre). Such a solution leaves a brighter detection unmatched beside each star it matches,
//! all at one offset (the copies') or all reflected through one point (the ghosts'), where a
//! right solution's unmatched detections (planets, satellites, hot pixels, trees, fainter
//! copies) stand in no such relation to its matches. A solution is refused when more than
//! [`MAX_COPIED`] of its matches (and at least [`MIN_COPIES`]) have a brighter unmatched
//! detection at one offset, or at one reflection.

use super::detect::Detection;
use rustc_hash::{FxHashMap, FxHashSet};

/// Matches with a brighter copy below which a solution is never refused.
pub const MIN_COPIES: usize = 4;

/// The share of the matches with a brighter copy in one relation above which a solution is
/// refused.
pub const MAX_COPIED: f64 = 0.5;

/// The cell (pixels) in which offsets or reflection centres count as one: centroid errors of
/// bloated or saturated images, a slight rotation between the exposures.
pub const RELATION_CELL_PX: f64 = 4.0;

/// The most matches that have a brighter unmatched detection in one relation: at one offset
/// (unmatched − matched), or one reflection (unmatched + matched), within
/// [`RELATION_CELL_PX`]. `matched`: the indices in `dets` of the matched detections.
pub fn copied_matches(dets: &[Detection], matched: &[usize]) -> usize {
    let is_matched: FxHashSet<usize> = matched.iter().copied().collect();
    let unmatched: Vec<&Detection> = dets
        .iter()
        .enumerate()
        .filter(|(i, _)| !is_matched.contains(i))
        .map(|(_, d)| d)
        .collect();
    let mut best = 0;
    for sign in [-1.0, 1.0] {
        // Cell of each relation → the matches that have a brighter copy in it.
        let mut cells: FxHashMap<(i64, i64), Vec<usize>> = FxHashMap::default();
        for (k, &m) in matched.iter().enumerate() {
            let a = &dets[m];
            for u in unmatched.iter().filter(|u| u.flux > a.flux) {
                let key = (
                    ((u.x + sign * a.x) / RELATION_CELL_PX).round() as i64,
                    ((u.y + sign * a.y) / RELATION_CELL_PX).round() as i64,
                );
                cells.entry(key).or_default().push(k);
            }
        }
        // A relation on a cell's border falls in two: count each cell with its neighbours.
        for &(cx, cy) in cells.keys() {
            let mut ks: FxHashSet<usize> = FxHashSet::default();
            for dx in -1..=1 {
                for dy in -1..=1 {
                    if let Some(v) = cells.get(&(cx + dx, cy + dy)) {
                        ks.extend(v);
                    }
                }
            }
            best = best.max(ks.len());
        }
    }
    best
}

/// Whether the matched detections (indices in `dets`) explain the brightest of `dets` (see the
/// module documentation).
pub fn explains_brightest(dets: &[Detection], matched: &[usize]) -> bool {
    explained(copied_matches(dets, matched), matched.len())
}

/// Whether `copied` of `matches` matches with a brighter copy in one relation leave the
/// solution standing.
pub fn explained(copied: usize, matches: usize) -> bool {
    copied < MIN_COPIES || (copied as f64) <= MAX_COPIED * matches as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(x: f64, y: f64, flux: f64) -> Detection {
        Detection {
            x,
            y,
            flux,
            area: 9,
            peak: 100,
            saturated: false,
            sigma_px: None,
        }
    }

    fn matched(dets: &[usize]) -> Vec<usize> {
        dets.to_vec()
    }

    /// 12 stars on a pseudo-random scatter, brightest first.
    fn stars() -> Vec<(f64, f64, f64)> {
        (0..12)
            .map(|i| {
                let t = i as f64;
                (
                    (t * 379.0) % 1000.0,
                    (t * 613.0 + 50.0) % 1000.0,
                    1000.0 * 0.8f64.powi(i),
                )
            })
            .collect()
    }

    #[test]
    fn the_stars_matched_beside_bright_extras_pass() {
        // Bright unmatched extras (a planet, hot pixels, a tree) in no relation to the stars.
        let mut dets: Vec<Detection> = stars().iter().map(|&(x, y, f)| det(x, y, f)).collect();
        for i in 0..10 {
            dets.push(det(
                20.0 + 7.0 * i as f64,
                900.0 + (i * i) as f64,
                5000.0 + i as f64,
            ));
        }
        let m = matched(&(0..12).collect::<Vec<_>>());
        assert!(copied_matches(&dets, &m) < MIN_COPIES);
        assert!(explains_brightest(&dets, &m));
    }

    #[test]
    fn fainter_copies_matched_are_refused_and_their_primaries_accepted() {
        for (dx, dy, reflect) in [(140.0, -35.0, false), (-3.0, 90.0, false), (0.0, 0.0, true)] {
            let mut dets = Vec::new();
            for &(x, y, f) in &stars() {
                dets.push(det(x, y, f));
                // The copy 1 mag fainter: moved, or reflected through (512, 400), 1.5 px off.
                let (cx, cy) = if reflect {
                    (1024.0 - x + 1.5, 800.0 - y - 1.0)
                } else {
                    (x + dx + 1.5, y + dy - 1.0)
                };
                dets.push(det(cx, cy, f / 2.512));
            }
            let copies: Vec<usize> = (0..dets.len()).filter(|k| k % 2 == 1).collect();
            let primaries: Vec<usize> = (0..dets.len()).filter(|k| k % 2 == 0).collect();
            assert_eq!(
                copied_matches(&dets, &matched(&copies)),
                12,
                "{dx} {dy} {reflect}"
            );
            assert!(!explains_brightest(&dets, &matched(&copies)));
            assert!(explains_brightest(&dets, &matched(&primaries)));
        }
    }

    #[test]
    fn a_few_copies_are_not_judged() {
        let mut dets: Vec<Detection> = stars().iter().map(|&(x, y, f)| det(x, y, f)).collect();
        // Three of the twelve have a brighter detection 50 px to the right.
        for k in 0..3 {
            let d = dets[k + 6];
            dets.push(det(d.x + 50.0, d.y, 2.0 * d.flux));
        }
        let m = matched(&(0..12).collect::<Vec<_>>());
        assert_eq!(copied_matches(&dets, &m), 3);
        assert!(explains_brightest(&dets, &m));
    }
}
