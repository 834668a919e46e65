//! Identification by geometric voting (seed 000; Kolomenkin et al. 2008): pair ranges → vote →
//! select → verification with the clustering cut.

use crate::camera::Camera;
use crate::catalog::RefCatalog;
use crate::cpu;
use crate::cpu::vote::PairRange;
use crate::table::{PairTable, chord_key, chord_of_angle};
use nalgebra::Vector3;

/// Settings of identification.
#[derive(Clone, Copy, Debug)]
pub struct IdentifySettings {
    /// How many of the brightest detected stars vote.
    pub vote_stars: usize,
    /// Pair distance tolerance from centroid errors, pixels (times the pixel scale).
    pub pair_tol_px: f64,
    /// Pair distance tolerance from focal-length and distortion errors, relative to the distance.
    pub scale_tol: f64,
    /// Candidates per star that go from the vote to verification.
    pub candidates: usize,
}

impl Default for IdentifySettings {
    fn default() -> Self {
        IdentifySettings {
            vote_stars: 30,
            pair_tol_px: 0.5,
            scale_tol: 0.0002,
            candidates: 16,
        }
    }
}

impl IdentifySettings {
    /// Tolerance e on the angular distance d of a pair (radians).
    pub fn tolerance(&self, camera: &Camera, d: f64) -> f64 {
        self.pair_tol_px * camera.ifov_rad() + self.scale_tol * d
    }
}

/// The key range of every pair of image stars: [d − e, d + e] as chord keys (made in f64).
pub fn pair_ranges(
    vectors: &[Vector3<f64>],
    camera: &Camera,
    s: &IdentifySettings,
) -> Vec<PairRange> {
    let mut out = Vec::with_capacity(vectors.len() * vectors.len().saturating_sub(1) / 2);
    for i in 0..vectors.len() {
        for j in i + 1..vectors.len() {
            let d = crate::camera::angle(&vectors[i], &vectors[j]);
            let e = s.tolerance(camera, d);
            out.push(PairRange {
                i: i as u32,
                j: j as u32,
                lo: chord_key(chord_of_angle((d - e).max(0.0))),
                hi: chord_key(chord_of_angle(d + e)),
            });
        }
    }
    out
}

/// What voting produced for one frame.
#[derive(Clone, Debug, Default)]
pub struct VoteResult {
    /// The best `candidates` packed candidates per voting star (see `cpu::select`).
    pub candidates: Vec<u32>,
    /// Candidates kept per star.
    pub k: usize,
    /// (pair, row) hypotheses scanned: the multiple-testing factor of the false-match probability.
    pub hypotheses: u64,
}

/// Vote and select on the CPU twins.
pub fn vote_cpu(
    table: &PairTable,
    ranges: &[PairRange],
    n_stars: usize,
    n_ref: usize,
    k: usize,
) -> VoteResult {
    let (votes, hypotheses) = cpu::vote::vote(table, ranges, n_stars, n_ref);
    VoteResult {
        candidates: cpu::select::select(&votes, n_stars, n_ref, k),
        k,
        hypotheses,
    }
}

/// An image star and the reference star it was identified with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Identification {
    pub star: usize,
    pub ref_id: u32,
}

/// Squared-chord bounds [lo², hi²] of each image pair's distance range, `i · n + j`.
fn chord2_bounds(
    vectors: &[Vector3<f64>],
    camera: &Camera,
    s: &IdentifySettings,
) -> Vec<(f64, f64)> {
    let n = vectors.len();
    let mut b = vec![(0.0, 0.0); n * n];
    for i in 0..n {
        for j in 0..n {
            if i != j {
                let d = crate::camera::angle(&vectors[i], &vectors[j]);
                let e = s.tolerance(camera, d);
                let lo = chord_of_angle((d - e).max(0.0));
                let hi = chord_of_angle(d + e);
                b[i * n + j] = (lo * lo, hi * hi);
            }
        }
    }
    b
}

/// Verification. Votes alone are noisy: a catalog star in a dense field collects many chance
/// votes, and the true star is often second or tenth. So each star's candidates are first
/// scored by geometry: candidate a of star i counts the other stars j that have a candidate b
/// whose catalog distance to a lies within the pair's tolerance; each star takes its
/// best-scored candidate (ties: more votes). Then seed 000's verification runs on those picks:
/// each consistent pair gives both stars a vote, and stars with fewer than half the best count
/// (and fewer than two) are dropped, as are stars that share a catalog star with a
/// better-supported one.
pub fn verify(
    voted: &VoteResult,
    vectors: &[Vector3<f64>],
    refs: &RefCatalog,
    camera: &Camera,
    s: &IdentifySettings,
) -> Vec<Identification> {
    let n = vectors.len();
    let k = voted.k;
    let bounds = chord2_bounds(vectors, camera, s);
    let ids: Vec<Vec<u32>> = (0..n)
        .map(|i| {
            voted.candidates[i * k..(i + 1) * k]
                .iter()
                .filter_map(|&c| cpu::select::unpack_candidate(c).map(|(_, id)| id))
                .collect()
        })
        .collect();
    let consistent = |i: usize, a: u32, j: usize, b: u32| {
        if a == b {
            return false;
        }
        let c2 = (refs.stars[a as usize].v - refs.stars[b as usize].v).norm_squared();
        let (lo, hi) = bounds[i * n + j];
        c2 >= lo && c2 <= hi
    };
    // Geometric score of each candidate; pick the best per star.
    let picks: Vec<Option<u32>> = (0..n)
        .map(|i| {
            let mut best: Option<(usize, u32)> = None;
            for &a in &ids[i] {
                let score = (0..n)
                    .filter(|&j| j != i && ids[j].iter().any(|&b| consistent(i, a, j, b)))
                    .count();
                if best.is_none_or(|(bs, _)| score > bs) {
                    best = Some((score, a));
                }
            }
            best.filter(|&(score, _)| score > 0).map(|(_, a)| a)
        })
        .collect();
    let mut support = vec![0u32; n];
    for i in 0..n {
        for j in i + 1..n {
            if let (Some(a), Some(b)) = (picks[i], picks[j]) {
                if consistent(i, a, j, b) {
                    support[i] += 1;
                    support[j] += 1;
                }
            }
        }
    }
    let best = support.iter().copied().max().unwrap_or(0);
    let cut = best.div_ceil(2).max(2);
    let mut kept: Vec<Identification> = (0..n)
        .filter(|&i| support[i] >= cut)
        .map(|i| Identification {
            star: i,
            ref_id: picks[i].unwrap(),
        })
        .collect();
    // One image star per catalog star: keep the best-supported claim (ties: brighter star).
    kept.sort_by(|a, b| {
        support[b.star]
            .cmp(&support[a.star])
            .then(a.star.cmp(&b.star))
    });
    let mut taken = std::collections::HashSet::new();
    kept.retain(|m| taken.insert(m.ref_id));
    kept.sort_by_key(|m| m.star);
    kept
}
