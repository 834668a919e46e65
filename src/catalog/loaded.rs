//! A catalog in memory: its stars, their names, the sky index over them and their
//! magnitudes' ranks.

use super::cells::{Cells, SkyIndex};
use super::star::Star;
use super::stars::Stars;
use nalgebra::Vector3;
use std::sync::{Arc, OnceLock};

/// The full catalog as loaded (in the file's order: by HIP for the CSV, by sky cell for a
/// binary catalog file).
#[derive(Clone, Debug)]
pub struct Catalog {
    /// Shared by the catalog's clones (a solver keeps one for deeper selections); a binary
    /// catalog file's are parsed when first read ([`Stars`]).
    pub stars: Arc<Stars>,
    /// The ids of a user catalog ([`StarId::Name`] indexes them); empty otherwise.
    pub names: Arc<Vec<String>>,
    /// Where it came from (a path, or [`BUILTIN_NAME`]).
    pub source: String,
    /// FNV-1a hash of the text it was parsed from (of a binary file's header, which holds the
    /// checksum of the rest): part of the distance-table cache key.
    pub content_hash: u64,
    /// The stars by sky cell: read from a binary file, built on the first cone query otherwise.
    pub(super) index: Arc<OnceLock<SkyIndex>>,
    /// The stars' magnitudes in ascending order, sorted on first use.
    pub(super) mags: Arc<OnceLock<Vec<f64>>>,
    /// The magnitude to which the catalog holds nearly every star of the sky: the automatic
    /// selection goes fainter only where a field would hold too few stars to identify
    /// (`solve::auto_mag_limit`). Infinite unless set ([`Catalog::complete_to`]): a
    /// user's catalog is as deep as its user made it.
    pub complete_mag: f64,
}

impl Catalog {
    /// A catalog of these stars; the sky index is built when first needed.
    pub fn new(stars: Vec<Star>, names: Vec<String>, source: &str, content_hash: u64) -> Catalog {
        Catalog::of_stars(stars.into(), names, source, content_hash)
    }

    pub(super) fn of_stars(
        stars: Stars,
        names: Vec<String>,
        source: &str,
        content_hash: u64,
    ) -> Catalog {
        Catalog {
            stars: Arc::new(stars),
            names: Arc::new(names),
            source: source.to_string(),
            content_hash,
            index: Arc::default(),
            mags: Arc::default(),
            complete_mag: f64::INFINITY,
        }
    }

    /// The same catalog, said to hold nearly every star of the sky to `mag`
    /// ([`Catalog::complete_mag`]).
    pub fn complete_to(self, mag: f64) -> Catalog {
        Catalog {
            complete_mag: mag,
            ..self
        }
    }

    /// The sky index (cells of about equal area), built now if the catalog has none yet.
    pub fn index(&self) -> &SkyIndex {
        self.index.get_or_init(|| {
            SkyIndex::build(
                Cells::for_stars(self.stars.len()),
                self.stars.iter().map(|s| (s.ra_rad, s.dec_rad)),
            )
        })
    }

    /// The magnitude of the `n`-th brightest star (`n` from 1, clamped to the catalog; NaN
    /// for an empty catalog). The faintest needs no sort: a narrow field's automatic limit
    /// takes every star, and sorting Tycho-2's 1.9 million magnitudes for it took 35 ms a run.
    pub fn mag_of_rank(&self, n: usize) -> f64 {
        let len = self.stars.len();
        if len == 0 {
            return f64::NAN;
        }
        let n = n.clamp(1, len);
        match self.mags.get() {
            None if n == len => ((0..len).map(|i| self.stars.mag(i)))
                .max_by(f64::total_cmp)
                .unwrap_or(f64::NAN),
            _ => self.sorted_mags()[n - 1],
        }
    }

    /// The stars' magnitudes, brightest first. Sorted once: the automatic magnitude limit
    /// reads it for every frame whose focal length was fitted (a field searched in scale).
    pub fn sorted_mags(&self) -> &[f64] {
        self.mags.get_or_init(|| {
            let mut mags: Vec<f64> = (0..self.stars.len()).map(|i| self.stars.mag(i)).collect();
            // Unstable: under a total order equal values are the same bits, so the result is
            // the stable sort's, in about half the time.
            mags.sort_unstable_by(f64::total_cmp);
            mags
        })
    }

    /// The stars at `indices` as a catalog of their own (a hinted region's), sharing the names.
    pub fn subset(&self, indices: &[u32], source: &str) -> Catalog {
        Catalog {
            stars: Arc::new(indices.iter().map(|&i| self.stars[i as usize]).collect()),
            names: self.names.clone(),
            source: source.to_string(),
            content_hash: 0,
            index: Arc::default(),
            mags: Arc::default(),
            complete_mag: self.complete_mag,
        }
    }

    /// Use `index` (read from a file) as the catalog's sky index.
    pub(crate) fn with_index(self, index: SkyIndex) -> Catalog {
        let cell = OnceLock::new();
        let _ = cell.set(index);
        Catalog {
            index: Arc::new(cell),
            ..self
        }
    }

    /// Indices into `stars` of every star within `radius_rad` of `centre` (a unit vector,
    /// ICRS), ascending. Exact: positions at the stars' own epochs, compared as unit vectors
    /// (angle ≤ radius); for another epoch widen the radius by the fastest proper motion
    /// times the years between.
    pub fn cone(&self, centre: &Vector3<f64>, radius_rad: f64) -> Vec<u32> {
        let index = self.index();
        let centre = centre.normalize();
        let cos_r = radius_rad.min(std::f64::consts::PI).cos();
        let mut out = Vec::new();
        for c in index.cells.cone_cells(&centre, radius_rad) {
            let (a, b) = (index.starts[c as usize], index.starts[c as usize + 1]);
            for &i in &index.order[a as usize..b as usize] {
                if self.stars[i as usize].position().dot(&centre) >= cos_r {
                    out.push(i);
                }
            }
        }
        out.sort_unstable();
        out
    }

    /// The id of star `i` as records print it (`catalog_id`).
    pub fn catalog_id(&self, i: usize) -> String {
        self.stars[i].id.display(&self.names)
    }

    /// Faintest magnitude in the catalog.
    pub fn faintest(&self) -> f64 {
        self.stars.iter().map(|s| s.mag).fold(f64::MIN, f64::max)
    }
}
