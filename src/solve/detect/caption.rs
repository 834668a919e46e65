//! Burned-in captions: smart-telescope apps (Seestar, ASIAIR) and phone apps write the
//! target, the telescope and the exposure into the frame in white letters along its top or
//! bottom edge. Each letter is a saturated component brighter than most stars: on a Seestar S30
//! frame of NGC 3372 ("c92_seestar-ai.jpg") 26 of the 30 brightest detections were letters, and
//! no quad of the brightest stars was the catalog's. astrometry.net spreads its quads over the
//! frame (its "uniformize"); here a caption is recognised by what sets it apart from stars:
//! many of the brightest detections on one horizontal line near the edge, which stars of
//! uniform density do by chance less than once in ten thousand frames.

use super::detection::{Detection, QUAD_STARS};

/// A caption row has at least this many of the brightest [`QUAD_STARS`]. Stars spread uniformly
/// put 0.6 of them in a strip of [`ROW_HALF`] either side of a line; 8 or more in one such
/// strip happen with a probability of about 3e-6 a strip, 1e-4 a frame. The caption above held
/// 17 in one row and 8 in the other.
pub const CAPTION_MIN: usize = 8;

/// A row's half height, as a share of the frame's height: a line of letters, its centroids
/// within ±0.2 % (the caption above) under ascenders and descenders.
pub const ROW_HALF: f64 = 0.01;

/// Captions lie within this share of the height from the top or bottom edge.
pub const CAPTION_BAND: f64 = 0.15;

/// Rows removed at most: a caption of two or three lines, each found once the one above it is
/// gone.
pub const MAX_ROWS: usize = 4;

/// Remove the detections of caption rows from `list` (brightest first), for a frame of
/// `height` rows: while some detection near the top or bottom edge has [`CAPTION_MIN`] − 1
/// others among the brightest [`QUAD_STARS`] within [`ROW_HALF`] of its row, every detection
/// of that strip goes. Returns how many were removed; a frame without a caption keeps its list
/// as it was.
pub fn drop_caption_rows(list: &mut Vec<Detection>, height: u32) -> usize {
    let h = height.max(1) as f64;
    let half = ROW_HALF * h;
    let in_band = |d: &Detection| d.y < CAPTION_BAND * h || d.y > (1.0 - CAPTION_BAND) * h;
    let before = list.len();
    for _ in 0..MAX_ROWS {
        let top = &list[..list.len().min(QUAD_STARS)];
        let row = top.iter().filter(|d| in_band(d)).find_map(|d| {
            let members = top.iter().filter(|o| (o.y - d.y).abs() <= half).count();
            (members >= CAPTION_MIN).then_some(d.y)
        });
        let Some(y) = row else { break };
        list.retain(|d| (d.y - y).abs() > half);
    }
    let removed = before - list.len();
    if removed > 0 {
        tracing::debug!("{removed} detections in caption rows dropped");
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f64, y: f64) -> Detection {
        Detection {
            x,
            y,
            flux: 1.0,
            area: 9,
            peak: 255,
            saturated: true,
            sigma_px: None,
        }
    }

    /// Stars spread over a 2000 × 3000 frame by a fixed low-discrepancy sequence.
    fn stars(n: usize) -> Vec<Detection> {
        (0..n)
            .map(|i| {
                let u = (i as f64 * 0.618_033_988_75).fract();
                let v = (i as f64 * 0.754_877_666_2 + 0.3).fract();
                at(2000.0 * u, 3000.0 * v)
            })
            .collect()
    }

    #[test]
    fn a_caption_s_rows_go_and_the_stars_stay() {
        // Two lines of letters at the bottom, brighter than the stars: 12 and 9 letters.
        let mut list: Vec<Detection> = (0..12)
            .map(|k| at(100.0 + 60.0 * k as f64, 2840.0 + (k % 3) as f64))
            .chain((0..9).map(|k| at(150.0 + 70.0 * k as f64, 2950.0 - (k % 2) as f64)))
            .collect();
        let stars = stars(40);
        list.extend(stars.iter().copied());
        let removed = drop_caption_rows(&mut list, 3000);
        assert!(removed >= 21, "{removed}");
        assert!(list.iter().all(|d| d.y < 2810.0 || d.y > 2870.0));
        assert!(list.iter().all(|d| d.y < 2920.0));
        // Only the stars within 30 px (1 % of the height) of the two rows went with the letters.
        let in_strips =
            |d: &Detection| (d.y - 2840.0).abs() <= 30.0 || (d.y - 2950.0).abs() <= 30.0;
        assert_eq!(removed - 21, stars.iter().filter(|d| in_strips(d)).count());
    }

    #[test]
    fn star_fields_and_rows_away_from_the_edges_are_left_alone() {
        let mut list = stars(100);
        let kept = list.clone();
        assert_eq!(drop_caption_rows(&mut list, 3000), 0);
        assert_eq!(list, kept);
        // A line of bright detections across the middle (a satellite's trail broken up) is
        // no caption.
        let mut trail: Vec<Detection> = (0..15).map(|k| at(100.0 * k as f64, 1500.0)).collect();
        trail.extend(stars(30));
        let kept = trail.clone();
        assert_eq!(drop_caption_rows(&mut trail, 3000), 0);
        assert_eq!(trail, kept);
        // Seven in a row near the edge: short of a caption.
        let mut short: Vec<Detection> = (0..7).map(|k| at(100.0 * k as f64, 2900.0)).collect();
        short.extend(stars(30));
        assert_eq!(drop_caption_rows(&mut short, 3000), 0);
    }
}
