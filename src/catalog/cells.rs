//! The sky split into cells of about equal area, and an exact cone query over them.
//!
//! Declination bands of equal height; band `b` has `band_cells[b]` cells of equal RA width,
//! about ∝ cos(dec) so that cells are near square. The counts are stored (in the binary file)
//! rather than recomputed, so that a file never depends on a platform's `cos`.

use nalgebra::Vector3;
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// The cell layout: per-band cell counts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Cells {
    /// Cells in each band, south to north.
    pub band_cells: Vec<u32>,
    /// First cell of each band, and the total count at the end (len = bands + 1).
    first: Vec<u32>,
}

/// Widening of the searched cells (radians): what floating point can move a star across a
/// boundary by is ~1e-15; the exact test on each star decides.
const SEARCH_MARGIN: f64 = 1e-9;

impl Cells {
    /// The layout for `bands` bands (cells ≈ 180°/bands on a side).
    pub fn new(bands: u32) -> Cells {
        let bands = bands.max(1);
        let h = PI / bands as f64;
        let band_cells = (0..bands)
            .map(|b| {
                let mid = -FRAC_PI_2 + (b as f64 + 0.5) * h;
                ((TAU * mid.cos() / h).round() as u32).max(1)
            })
            .collect();
        Cells::from_counts(band_cells).expect("counts made here are valid")
    }

    /// The layout a catalog of `stars` stars gets: about 8 stars per cell, cells no smaller
    /// than 1° (a cone query of a few degrees touches tens of cells) nor larger than 30°.
    pub fn for_stars(stars: usize) -> Cells {
        Cells::new(((stars as f64 / 10.0).sqrt().round() as u32).clamp(6, 180))
    }

    /// A layout from stored counts; None when they cannot be one (no bands, an empty band,
    /// more cells than a u32 holds).
    pub fn from_counts(band_cells: Vec<u32>) -> Option<Cells> {
        if band_cells.is_empty() || band_cells.contains(&0) {
            return None;
        }
        let mut first = Vec::with_capacity(band_cells.len() + 1);
        let mut total: u32 = 0;
        for &c in &band_cells {
            first.push(total);
            total = total.checked_add(c)?;
        }
        first.push(total);
        Some(Cells { band_cells, first })
    }

    pub fn bands(&self) -> usize {
        self.band_cells.len()
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        *self.first.last().expect("first has bands + 1 entries") as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn band(&self, dec_rad: f64) -> usize {
        let b = ((dec_rad + FRAC_PI_2) / PI * self.bands() as f64).floor();
        (b.max(0.0) as usize).min(self.bands() - 1)
    }

    fn column(&self, band: usize, ra_rad: f64) -> u32 {
        let n = self.band_cells[band];
        let c = (ra_rad.rem_euclid(TAU) / TAU * n as f64).floor();
        (c.max(0.0) as u32).min(n - 1)
    }

    /// The cell of a position.
    pub fn cell(&self, ra_rad: f64, dec_rad: f64) -> u32 {
        let b = self.band(dec_rad);
        self.first[b] + self.column(b, ra_rad)
    }

    /// Every cell that may hold a point within `radius_rad` of `centre` (a unit vector),
    /// ascending. A superset: the caller tests each star.
    pub fn cone_cells(&self, centre: &Vector3<f64>, radius_rad: f64) -> Vec<u32> {
        let r = radius_rad + SEARCH_MARGIN;
        let dec = centre.z.clamp(-1.0, 1.0).asin();
        let ra = centre.y.atan2(centre.x);
        let (lo, hi) = (dec - r, dec + r);
        // Over a cap that holds no pole, RA strays at most asin(sin r / cos dec) from its
        // centre's (the tangent meridians); with a pole inside, every RA is reached.
        let half = if lo <= -FRAC_PI_2 || hi >= FRAC_PI_2 || r >= FRAC_PI_2 {
            PI
        } else {
            (r.sin() / dec.cos()).min(1.0).asin() + SEARCH_MARGIN
        };
        let mut out = Vec::new();
        for b in self.band(lo)..=self.band(hi) {
            let n = self.band_cells[b];
            if half >= PI {
                out.extend(self.first[b]..self.first[b] + n);
                continue;
            }
            let (c0, c1) = (self.column(b, ra - half), self.column(b, ra + half));
            if (ra - half).rem_euclid(TAU) <= (ra + half).rem_euclid(TAU) {
                out.extend(self.first[b] + c0..=self.first[b] + c1);
            } else {
                // Across RA = 0: the two ends of the band.
                out.extend(self.first[b]..=self.first[b] + c1);
                out.extend(self.first[b] + c0..self.first[b] + n);
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }
}

/// Stars grouped by cell: `order[starts[c]..starts[c + 1]]` are the stars of cell `c`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SkyIndex {
    pub cells: Cells,
    /// Index of the first star of each cell in `order` (len = cells + 1).
    pub starts: Vec<u32>,
    /// Star indices sorted by cell (the identity for a binary catalog file, whose stars are
    /// stored in cell order).
    pub order: Vec<u32>,
}

impl SkyIndex {
    /// Index stars given by (RA, Dec) in radians, keeping their order within a cell.
    pub fn build(cells: Cells, radec: impl Iterator<Item = (f64, f64)>) -> SkyIndex {
        let cell_of: Vec<u32> = radec.map(|(ra, dec)| cells.cell(ra, dec)).collect();
        let mut order: Vec<u32> = (0..cell_of.len() as u32).collect();
        order.sort_by_key(|&i| cell_of[i as usize]);
        let mut starts = vec![0u32; cells.len() + 1];
        for &c in &cell_of {
            starts[c as usize + 1] += 1;
        }
        for c in 0..cells.len() {
            starts[c + 1] += starts[c];
        }
        SkyIndex {
            cells,
            starts,
            order,
        }
    }
}

/// Cone searches over a fixed set of unit vectors, asked many times: the first
/// [`SCANS_BEFORE_INDEX`] scan them all, then a [`SkyIndex`] is made (once, whichever thread
/// asks) and a search tests the vectors of the few cells about the cone, packed in cell order.
/// A run of a frame or two never pays for the index (made at once it was a tenth of a
/// one-frame run); a run of many pays once, where a scan of every reference star took a
/// refinement a tenth of a sparse frame's time (and more with deeper catalogs).
#[derive(Debug, Default)]
pub struct ConeIndex {
    scans: AtomicU32,
    index: OnceLock<(SkyIndex, Vec<Vector3<f64>>)>,
}

/// Searches by scanning before the index is made: a scan of a 10° camera's reference stars
/// costs about a thirtieth of making it.
pub const SCANS_BEFORE_INDEX: u32 = 32;

impl ConeIndex {
    /// The places k, rising, of the `n` unit vectors `v(k)` within `reach` radians of the unit
    /// vector `axis` (`v(k) · axis >= reach.cos()`). `n` and `v` must be the same at every
    /// call: the index made from them is kept.
    pub fn cone(
        &self,
        n: usize,
        v: impl Fn(usize) -> Vector3<f64>,
        axis: &Vector3<f64>,
        reach: f64,
    ) -> Vec<u32> {
        let cos = if reach >= PI { -2.0 } else { reach.cos() };
        let index = match self.index.get() {
            Some(index) => index,
            None if self.scans.fetch_add(1, Relaxed) >= SCANS_BEFORE_INDEX => {
                self.index.get_or_init(|| {
                    let radec = (0..n).map(|k| {
                        let p = v(k);
                        (p.y.atan2(p.x), p.z.clamp(-1.0, 1.0).asin())
                    });
                    let index = SkyIndex::build(Cells::for_stars(n), radec);
                    let packed = index.order.iter().map(|&k| v(k as usize)).collect();
                    (index, packed)
                })
            }
            None => {
                return (0..n as u32)
                    .filter(|&k| v(k as usize).dot(axis) >= cos)
                    .collect();
            }
        };
        let (index, packed) = index;
        let mut out = Vec::new();
        for c in index.cells.cone_cells(&axis.normalize(), reach) {
            let cell = index.starts[c as usize] as usize..index.starts[c as usize + 1] as usize;
            out.extend(
                cell.filter(|&i| packed[i].dot(axis) >= cos)
                    .map(|i| index.order[i]),
            );
        }
        out.sort_unstable();
        out
    }

    /// Whether the index has been made.
    pub fn indexed(&self) -> bool {
        self.index.get().is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_are_near_square_and_cover_the_sphere_once() {
        let c = Cells::new(180);
        assert_eq!(c.bands(), 180);
        // Equator: 360 cells of 1°; the polar bands keep a few.
        assert_eq!(c.band_cells[90], 360);
        assert!(c.band_cells[0] >= 1 && c.band_cells[0] <= 4);
        // About 4π / (1°)² = 41,253 cells.
        assert!((c.len() as f64 - 41_253.0).abs() < 300.0, "{}", c.len());
        assert_eq!(c.cell(0.0, -FRAC_PI_2), 0);
        assert_eq!(c.cell(TAU - 1e-12, FRAC_PI_2) as usize, c.len() - 1);
        assert_eq!(Cells::from_counts(vec![1, 0]), None);
    }

    #[test]
    fn cone_finds_exactly_the_stars_brute_force_finds() {
        use crate::catalog::{Catalog, Star, StarId, radec_to_vector};
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        // Uniform on the sphere, plus stars packed near both poles and along RA = 0.
        let mut radec: Vec<(f64, f64)> = (0..20_000)
            .map(|_| {
                let z: f64 = rng.random_range(-1.0..1.0);
                (rng.random_range(0.0..360.0), z.asin().to_degrees())
            })
            .collect();
        for _ in 0..3000 {
            radec.push((rng.random_range(0.0..360.0), rng.random_range(88.0..90.0)));
            radec.push((rng.random_range(0.0..360.0), rng.random_range(-90.0..-88.0)));
            let ra: f64 = rng.random_range(-1.0..1.0);
            radec.push((ra.rem_euclid(360.0), rng.random_range(-60.0..60.0)));
        }
        radec.push((0.0, 90.0));
        radec.push((359.999_999_9, 0.0));
        let stars = radec
            .iter()
            .enumerate()
            .map(|(i, &(ra, dec))| Star {
                id: StarId::Hip(i as u32 + 1),
                hip: None,
                ra_rad: ra.to_radians(),
                dec_rad: dec.to_radians(),
                pmra_mas_yr: 0.0,
                pmdec_mas_yr: 0.0,
                mag: 5.0,
                epoch: 2000.0,
            })
            .collect();
        let cat = Catalog::new(stars, Vec::new(), "test", 0);
        let mut centres = vec![
            (0.0, 90.0, 1.0),
            (123.0, 89.5, 2.0),
            (10.0, -89.9, 0.5),
            (0.0, 0.0, 3.0),
            (359.9, 45.0, 5.0),
            (0.05, -70.0, 10.0),
            (180.0, 0.0, 90.0),
            (0.0, 0.0, 179.0),
            (200.0, 10.0, 0.0),
        ];
        for _ in 0..200 {
            let z: f64 = rng.random_range(-1.0..1.0);
            centres.push((
                rng.random_range(0.0..360.0),
                z.asin().to_degrees(),
                rng.random_range(0.01..20.0),
            ));
        }
        for (ra, dec, r) in centres {
            let c = radec_to_vector(ra, dec);
            let rad = f64::to_radians(r);
            let brute: Vec<u32> = (0..cat.stars.len() as u32)
                .filter(|&i| cat.stars[i as usize].position().dot(&c) >= rad.cos())
                .collect();
            assert_eq!(
                cat.cone(&c, rad),
                brute,
                "cone at ({ra}, {dec}) radius {r}°"
            );
        }
        // A star exactly at the centre is found with radius 0.
        assert_eq!(cat.cone(&radec_to_vector(0.0, 90.0), 0.0).len(), 1);
    }
}
