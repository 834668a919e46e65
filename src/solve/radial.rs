//! Radial features + triangles (seed 002; notes/radial.md), `--method radial`: a second
//! identifier for narrow, deep fields.
//!
//! Every reference star carries a bit vector of [`BITS`] rings of equal width Δr out to R
//! around it: bit h is set when some other reference star lies at an angle in ring h, or within
//! the pair tolerance of it (redundant coding: a neighbour near a ring's edge sets both rings,
//! so centroid errors never clear a bit the image sets). R and Δr are fixed per band (R = half
//! the widest field's diagonal, Δr = R / [`BITS`]), not per frame as the paper has it: a
//! lost-in-space table cannot depend on the frame (notes/radial.md 1.5). Each image star's
//! vector has one bit per other detection among the voting stars. Stage `radial` scores every
//! (image star, catalog star) by AND + popcount, less what chance gives for their bit counts
//! (`cpu::radial`, `shaders/radial.wgsl`); stage `select` keeps the best K. Triangles among
//! those candidates only, side-side-side against the vote's pair ranges and the same
//! handedness, give attitudes in turn; refinement and the false-match test (counting every
//! triangle that matched) accept the first that holds.

use crate::catalog::RefCatalog;
use crate::catalog::table::{PairTable, angle_of_chord, chord_key};
use crate::cpu::vote::PairRange;
use crate::error::fail;
use crate::solve::triangle::{Triangle, triangle_order};
use nalgebra::Vector3;

pub use crate::cpu::radial::{BITS, WORDS};
/// Candidates kept per image star.
pub const CANDIDATES: usize = 32;
/// The brightest image stars whose candidates form triangles (560 triangles for 16): only
/// they are scored.
pub const TRIANGLE_STARS: usize = 16;
/// The brightest image stars that make the features' rings: the catalog holds the brightest
/// stars of the field, and fainter detections (uncatalogued stars, noise) would set rings no
/// catalog star has; too few, and false stars among the brightest crowd the true neighbours
/// out (on 4° frames 16, 20, 24 and 40 solved 199, 198, 195, 195 of 200 with 10 false stars
/// and 62, 69, 80, 87 of 100 with 40).
pub const FEATURE_STARS: usize = 20;

/// The catalog's features for a band, word-major: word w of star id is
/// `features[w · stars + id]` (a scan of one word over all stars reads memory in order, on the
/// CPU and in the GPU's coalesced loads).
#[derive(Clone, Debug)]
pub struct RadialTable {
    pub features: Vec<u32>,
    /// Rings set per catalog star (|B|).
    pub counts: Vec<u32>,
    /// Ring width Δr and feature radius R (radians).
    pub ring_rad: f64,
    pub radius_rad: f64,
    pub stars: usize,
}

impl RadialTable {
    /// Features of `refs` from their pair table (which reaches the widest field's diagonal,
    /// so R = half of it is inside), a neighbour within the vote's pair tolerance
    /// (`pair_tol_rad` + `scale_tol` · θ) of a ring's edge setting both rings.
    pub fn build(
        refs: &RefCatalog,
        table: &PairTable,
        pair_tol_rad: f64,
        scale_tol: f64,
    ) -> RadialTable {
        let radius_rad = table.max_sep_rad / 2.0;
        let ring_rad = radius_rad / BITS as f64;
        let n = refs.len();
        let mut features = vec![0u32; n * WORDS];
        let top =
            table.lower_bound(chord_key(crate::catalog::table::chord_of_angle(radius_rad)) + 1);
        for row in 0..top {
            let (a, b) = table.pair(row);
            let theta = angle_of_chord((refs.v(a as usize) - refs.v(b as usize)).norm());
            let tol_rad = pair_tol_rad + scale_tol * theta;
            let lo = ((theta - tol_rad) / ring_rad).floor().max(0.0) as usize;
            let hi = (((theta + tol_rad) / ring_rad).floor() as usize).min(BITS - 1);
            for h in lo..=hi {
                for s in [a, b] {
                    features[(h / 32) * n + s as usize] |= 1 << (h % 32);
                }
            }
        }
        RadialTable::from_features(features, n, table)
    }

    /// The table of word-major `features` of `stars` stars for `table`'s band: the rings'
    /// geometry and each star's count.
    fn from_features(features: Vec<u32>, stars: usize, table: &PairTable) -> RadialTable {
        let counts = (0..stars)
            .map(|id| {
                (0..WORDS)
                    .map(|w| features[w * stars + id].count_ones())
                    .sum()
            })
            .collect();
        let radius_rad = table.max_sep_rad / 2.0;
        RadialTable {
            features,
            counts,
            ring_rad: radius_rad / BITS as f64,
            radius_rad,
            stars,
        }
    }

    /// [`RadialTable::build`], or the features a previous run cached for the same table and
    /// tolerances (in `table::cache_dir()`, as `radial-<key>.bin`; `use_cache` false: built
    /// every time). Returns also whether they were read from the cache.
    pub fn load_or_build(
        refs: &RefCatalog,
        table: &PairTable,
        table_key: u64,
        pair_tol_rad: f64,
        scale_tol: f64,
        use_cache: bool,
    ) -> (RadialTable, bool) {
        let text = format!(
            "gpustar-radial-v1|{table_key:016x}|{BITS}|{pair_tol_rad}|{scale_tol}|{}",
            table.max_sep_rad
        );
        let key = crate::catalog::fnv1a(text.as_bytes());
        let file = crate::catalog::table::cache_dir()
            .filter(|_| use_cache)
            .map(|d| d.join(format!("radial-{key:016x}.bin")));
        if let Some(t) = file
            .as_ref()
            .and_then(|f| read_features(f, key, refs.len(), table))
        {
            return (t, true);
        }
        let t = RadialTable::build(refs, table, pair_tol_rad, scale_tol);
        if let Some(f) = &file
            && let Err(e) = write_features(f, key, &t)
        {
            tracing::warn!(
                "could not cache the radial features in {}: {e:#}",
                f.display()
            );
        }
        (t, false)
    }

    /// Bytes the features and their counts take.
    pub fn bytes(&self) -> usize {
        4 * (self.features.len() + self.counts.len())
    }
}

/// Version 2 adds the checksum.
const MAGIC: &[u8; 8] = b"GPSRAD02";

fn write_features(path: &std::path::Path, key: u64, t: &RadialTable) -> crate::error::Result<()> {
    crate::catalog::table::write_cache(path, MAGIC, key, &[t.stars as u64], &t.features)
}

/// The cached features, if the file is whole (its checksum), made for this key and catalog
/// size; else None, with a warning when a file was there.
fn read_features(
    path: &std::path::Path,
    key: u64,
    stars: usize,
    table: &PairTable,
) -> Option<RadialTable> {
    if !path.exists() {
        return None;
    }
    let read =
        crate::catalog::table::read_cache(path, MAGIC, key, 1).and_then(|(head, features)| {
            if head[0] != stars as u64 || features.len() != WORDS * stars {
                fail!(Catalog, "made for another catalog");
            }
            Ok(features)
        });
    match read {
        Ok(features) => Some(RadialTable::from_features(features, stars, table)),
        Err(e) => {
            tracing::warn!(
                "the cached radial features {} cannot be used ({e:#}): building them again",
                path.display()
            );
            None
        }
    }
}

/// The features of the first [`TRIANGLE_STARS`] of `vectors` (brightest first),
/// `out[star · WORDS ..]`: bit h for every other star among the first [`FEATURE_STARS`] at an
/// angle in ring h (within R).
pub fn image_features(vectors: &[Vector3<f64>], t: &RadialTable) -> Vec<u32> {
    let m = vectors.len().min(FEATURE_STARS);
    let n = vectors.len().min(TRIANGLE_STARS);
    let mut out = vec![0u32; n * WORDS];
    for i in 0..n {
        for j in 0..m {
            if i == j {
                continue;
            }
            let theta = angle_of_chord((vectors[i] - vectors[j]).norm());
            if theta < t.radius_rad {
                let h = ((theta / t.ring_rad) as usize).min(BITS - 1);
                out[i * WORDS + h / 32] |= 1 << (h % 32);
            }
        }
    }
    out
}

/// Triangles among the candidates: for each triple of the first `n` image stars (by the sum of
/// their places, then lexicographically) and each triple of their candidates (best first), the
/// three catalog distances inside the image pairs' ranges and the same handedness. `candidates`
/// are `select`'s packed lists (`k` per star); `ranges` the vote's pair ranges of these stars.
/// Returns the hypotheses in order.
pub fn triangles(
    candidates: &[u64],
    k: usize,
    ranges: &[PairRange],
    vectors: &[Vector3<f64>],
    refs: &RefCatalog,
    n: usize,
) -> Vec<Triangle> {
    let n = n.min(vectors.len()).min(candidates.len() / k.max(1));
    let mut range = vec![None; n * n];
    for r in ranges {
        let (i, j) = (r.i as usize, r.j as usize);
        if i < n && j < n {
            range[i * n + j] = Some((r.lo, r.hi));
            range[j * n + i] = Some((r.lo, r.hi));
        }
    }
    let ids = |s: usize| -> Vec<u32> {
        candidates[s * k..(s + 1) * k]
            .iter()
            .filter_map(|&c| crate::cpu::select::unpack_candidate(c).map(|(_, id)| id))
            .collect()
    };
    let lists: Vec<Vec<u32>> = (0..n).map(ids).collect();
    let v = |id: u32| refs.v(id as usize);
    let fits = |i: usize, j: usize, a: u32, b: u32| -> bool {
        let Some((lo, hi)) = range[i * n + j] else {
            return false;
        };
        let key = chord_key((v(a) - v(b)).norm());
        a != b && lo <= key && key <= hi
    };
    let mut out = Vec::new();
    for [i, j, l] in triangle_order(n) {
        let handed = vectors[i].cross(&vectors[j]).dot(&vectors[l]) > 0.0;
        for &a in &lists[i] {
            for &b in lists[j].iter().filter(|&&b| fits(i, j, a, b)) {
                for &c in lists[l]
                    .iter()
                    .filter(|&&c| fits(i, l, a, c) && fits(j, l, b, c))
                {
                    if (v(a).cross(&v(b)).dot(&v(c)) > 0.0) == handed {
                        out.push(Triangle {
                            stars: [i, j, l],
                            refs: [a, b, c],
                        });
                    }
                }
            }
        }
    }
    out
}

crate::choice! {
    /// How stars are identified (`--method`).
    #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
    pub enum Method {
        #[default]
        Vote = "vote", "Geometric voting against the distance table (seed 000), triangles as the \
            fallback",
        Radial = "radial", "Radial features as the candidate filter, triangles among the \
            candidates (seed 002)",
        Triangle = "triangle", "Triangles alone, no candidate filter: side-side-side matches of \
            the 8 brightest stars' triangles through the distance table, each confirmed by a \
            fourth star (the vote's fallback on its own; seed 002's baseline)",
    }
}

impl Method {
    /// The identifiers a frame is tried with, in turn, each through all its passes until one
    /// solves. `--method radial` falls back to the vote: where the radial features cannot
    /// rank three true candidates of a triangle among their best (few catalog stars among
    /// many false ones), the vote, which counts pairs, can (issue 28, docs/radial.md). Each
    /// identifier judges its hypotheses against an even share of the false-match budget
    /// (`Solver::hypothesis_factor`).
    pub fn identifiers(self) -> &'static [Method] {
        match self {
            Method::Vote => &[Method::Vote],
            Method::Radial => &[Method::Radial, Method::Vote],
            Method::Triangle => &[Method::Triangle],
        }
    }
}

/// The CPU twins of the radial stages: score (`cpu::radial`) and select.
pub fn candidates_cpu(
    t: &RadialTable,
    image: &[u32],
    k: usize,
) -> crate::solve::identify::VoteResult {
    let n = image.len() / WORDS;
    let scores = crate::cpu::radial::radial(&t.features, &t.counts, image, n);
    crate::solve::identify::VoteResult {
        candidates: crate::cpu::select::select(&scores, n, t.stars, k),
        k,
        hypotheses: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Features written to the cache read back the same, and a file for another key or a
    /// truncated one is refused.
    #[test]
    fn cached_features_read_back_and_bad_files_are_refused() {
        let refs = RefCatalog::select(
            &crate::catalog::Catalog::builtin(),
            crate::catalog::Selection {
                epoch: 2000.0,
                mag_limit: 4.0,
                double_stars: crate::catalog::DoubleStars::Merge,
                double_sep_rad: 0.0,
            },
        )
        .unwrap();
        let table = PairTable::build(&refs, 0.2);
        let t = RadialTable::build(&refs, &table, 1e-5, 2e-4);
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("radial.bin");
        write_features(&f, 7, &t).unwrap();
        let back = read_features(&f, 7, refs.len(), &table).unwrap();
        assert_eq!(back.features, t.features);
        assert_eq!(back.counts, t.counts);
        assert_eq!(back.ring_rad, t.ring_rad);
        assert!(t.counts.iter().any(|&c| c > 0));
        assert!(read_features(&f, 8, refs.len(), &table).is_none());
        let bytes = std::fs::read(&f).unwrap();
        std::fs::write(&f, &bytes[..bytes.len() - 4]).unwrap();
        assert!(read_features(&f, 7, refs.len(), &table).is_none());
    }
}
