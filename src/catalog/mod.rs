//! The star catalog: stars (Hipparcos-2, Gaia DR3, Tycho-2 or a user's list), propagated to the
//! observation epoch, cut to the camera's limiting magnitude, with the double stars the camera
//! cannot separate handled.
//!
//! The repository ships `catalog/hip2_hp9.csv` (made by `gpustar catalog import`, see
//! [`import_hip2`]); it is compiled into the binary so `gpustar` works with no files beside it.
//! Other catalogs are imported ([`formats`]) into gpustar's binary catalog file ([`store`]),
//! which `--catalog` reads as it reads the CSV.

pub mod cells;
mod checked;
pub mod formats;
mod id;
mod import;
mod load;
mod loaded;
pub mod patterns;
mod ref_record;
mod reference;
mod refs_cache;
mod star;
mod stars;
pub mod store;
pub mod table;
pub mod words;

pub use cells::{Cells, SkyIndex};
pub use id::StarId;
pub use import::import_hip2;
pub use load::{BUILTIN_COMPLETE_MAG, BUILTIN_CSV, BUILTIN_NAME};
pub use loaded::Catalog;
pub use ref_record::RefStar;
pub(crate) use reference::selection_key_text;
pub use reference::{DoubleStars, MAX_REF_STARS, RefCatalog, Selection};
pub use refs_cache::{load_or_select, load_sorted_mags};
pub use star::{HIPPARCOS_EPOCH, Star, fnv1a, radec_to_vector, vector_to_radec};
pub use stars::Stars;
pub use words::Words;

#[cfg(test)]
mod tests {
    use super::load::BUILTIN_HASH;
    use super::*;
    use nalgebra::Vector3;

    /// The built-in catalog, as `build.rs` parsed it, is its file's, star by star.
    #[test]
    fn the_builtin_stars_are_the_file_s() {
        let parsed = Catalog::parse(BUILTIN_CSV, BUILTIN_NAME).unwrap();
        let built = Catalog::builtin();
        assert_eq!(built.stars.len(), parsed.stars.len());
        assert!(built.stars.len() > 78_000);
        assert!(
            built.stars == parsed.stars,
            "build.rs parses the CSV as Catalog::parse"
        );
        assert_eq!(
            (built.source, built.content_hash),
            (parsed.source, parsed.content_hash)
        );
    }

    /// `within` keeps exactly the stars whose position at the catalog's epoch is within the
    /// reach, however far the epoch is from the stored positions' (centuries here, so that the
    /// fastest stars cross the cone's edge), as at the stored epoch.
    #[test]
    fn within_is_the_cone_at_the_epoch() {
        let selection = Selection {
            epoch: 2000.0,
            mag_limit: 6.5,
            double_stars: DoubleStars::Keep,
            double_sep_rad: 0.0,
        };
        let refs = RefCatalog::select(&Catalog::builtin(), selection).unwrap();
        // Axes on the fastest stars (their moves decide the edge), and elsewhere.
        let mut fastest: Vec<usize> = (0..refs.len()).collect();
        fastest.sort_by(|&a, &b| {
            Vector3::from(refs.stars[b].motion)
                .norm()
                .total_cmp(&Vector3::from(refs.stars[a].motion).norm())
        });
        // The scans first, then the cells (indexed after SCANS_BEFORE_INDEX searches; the
        // catalog at each epoch shares the index).
        let mut zoned = 0;
        for epoch in [2000.0, 1500.0, 2026.9, 2600.0] {
            let at = refs.at_epoch(epoch);
            for (k, &star) in fastest[..6].iter().enumerate() {
                let axis = if k % 2 == 0 {
                    refs.stars[star].v.into()
                } else {
                    Vector3::new(1.0, k as f64, -2.0).normalize()
                };
                for reach in [0.0, 1e-4, 0.01, 0.2, 1.5, 3.1, std::f64::consts::PI] {
                    let definition: Vec<u32> = (0..at.len())
                        .filter(|&id| at.v(id).dot(&axis) >= reach.cos())
                        .map(|id| id as u32)
                        .collect();
                    zoned += usize::from(at.cones.indexed());
                    assert_eq!(at.within(&axis, reach), definition, "{epoch} {k} {reach}");
                }
            }
        }
        // 4 epochs × 6 axes × 7 reaches: all but the scans and the search that made them.
        assert_eq!(zoned, 4 * 6 * 7 - cells::SCANS_BEFORE_INDEX as usize - 1);
    }

    /// A magnitude's rank is the sorted magnitudes' (the faintest found before they are
    /// sorted, the others after).
    #[test]
    fn ranks_are_the_sorted_magnitudes() {
        let sorted = Catalog::builtin().sorted_mags().to_vec();
        let c = Catalog::builtin();
        let len = sorted.len();
        for n in [len + 9, len, 0, 1, 2, 17, len / 2, len - 1, len] {
            let want = sorted[n.clamp(1, len) - 1];
            assert_eq!(c.mag_of_rank(n).to_bits(), want.to_bits(), "rank {n}");
        }
        assert!(
            Catalog::new(Vec::new(), Vec::new(), "e", 0)
                .mag_of_rank(1)
                .is_nan()
        );
    }

    /// The built-in catalog's hash is its file's (cache keys depend on it).
    #[test]
    fn the_builtin_hash_is_the_file_s() {
        let hash = fnv1a(BUILTIN_CSV.as_bytes());
        assert_eq!(
            BUILTIN_HASH, hash,
            "catalog/hip2_hp9.csv changed: set BUILTIN_HASH to {hash:#018x}"
        );
    }
}
