//! Identification by geometric voting (seed 000; Kolomenkin et al. 2008): pair ranges → vote →
//! select → verification with the clustering cut.

use crate::camera::Camera;
use crate::catalog::RefCatalog;
use crate::catalog::table::{PairTable, chord_key, chord_of_angle};
use crate::cpu;
use crate::cpu::vote::PairRange;
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
    /// About how many (star, candidate) pairs go from the vote to verification: few stars
    /// get more candidates each, since their true star is less often near the top.
    pub candidate_nodes: usize,
}

impl IdentifySettings {
    /// The defaults (`Default`), as a constant: the run configuration's (`config`) come
    /// from here.
    pub const DEFAULT: IdentifySettings = IdentifySettings {
        vote_stars: 40,
        pair_tol_px: 0.4,
        scale_tol: 0.0002,
        candidate_nodes: 512,
    };
}

impl Default for IdentifySettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl IdentifySettings {
    /// Candidates kept per star when `n` stars vote: `candidate_nodes / n`, within 16..=64.
    pub fn candidates_per_star(&self, n: usize) -> usize {
        (self.candidate_nodes / n.max(1)).clamp(16, 64)
    }

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
    pub candidates: Vec<u64>,
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
    thread_local! {
        // The vote counters of this thread's last frame, kept for the next (see `vote_into`).
        static COUNTERS: std::cell::RefCell<Vec<u32>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    COUNTERS.with_borrow_mut(|votes| {
        let hypotheses = cpu::vote::vote_into(votes, table, ranges, n_stars, n_ref);
        VoteResult {
            candidates: cpu::select::select(votes, n_stars, n_ref, k),
            k,
            hypotheses,
        }
    })
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
/// votes, so the true star is often not the argmax but second or tenth. And a chance candidate
/// is rarely alone: the table row that voted catalog star a to image star i also voted its
/// partner b to image star j, so (i, a) and (j, b) agree on their distance by construction.
/// What chance does not give is a triangle: three candidates of three stars whose three
/// distances all agree. So:
///
/// 1. nodes are the candidates (star, catalog star); an edge joins two nodes of different stars
///    and different catalog stars whose catalog distance lies within the pair's tolerance;
/// 2. each node is scored by the triangles it is in;
/// 3. from each of the best-scored nodes, a set is grown greedily in score order, adding a node
///    when its star and catalog star are new and it has an edge to every node in the set;
///    the largest set wins (ties: the one grown first).
///
/// This is seed 000's verification (pairs of identified stars vote when their distances agree,
/// and stars far below the best count are dropped) made strict: every pair in the result agrees.
pub fn verify(
    voted: &VoteResult,
    vectors: &[Vector3<f64>],
    refs: &RefCatalog,
    camera: &Camera,
    s: &IdentifySettings,
) -> Vec<Identification> {
    crate::simd::fast!(verify_in(
        voted: &VoteResult,
        vectors: &[Vector3<f64>],
        refs: &RefCatalog,
        camera: &Camera,
        s: &IdentifySettings
    ) -> Vec<Identification>)
}

/// [`verify`], compiled where it is inlined (see [`crate::simd`]): the triangle counts are
/// population counts.
#[inline(always)]
fn verify_in(
    voted: &VoteResult,
    vectors: &[Vector3<f64>],
    refs: &RefCatalog,
    camera: &Camera,
    s: &IdentifySettings,
) -> Vec<Identification> {
    let n = vectors.len();
    let k = voted.k;
    let bounds = chord2_bounds(vectors, camera, s);
    // Nodes in (star, rank) order: rank order is vote order.
    let mut nodes: Vec<Identification> = Vec::new();
    for i in 0..n {
        for &c in &voted.candidates[i * k..(i + 1) * k] {
            if let Some((_, id)) = cpu::select::unpack_candidate(c) {
                nodes.push(Identification {
                    star: i,
                    ref_id: id,
                });
            }
        }
    }
    let m = nodes.len();
    let words = m.div_ceil(64);
    let mut adj = vec![0u64; m * words];
    // Nodes come grouped by star; each star's candidates' vectors side by side.
    let mut first = vec![0usize; n + 1];
    for (u, node) in nodes.iter().enumerate() {
        first[node.star + 1] = u + 1;
    }
    for i in 0..n {
        first[i + 1] = first[i + 1].max(first[i]);
    }
    // Coordinates side by side (x..., y..., z...) so the distance loop below vectorises.
    let (xs, ys, zs): (Vec<f64>, Vec<f64>, Vec<f64>) = nodes
        .iter()
        .map(|node| {
            let v = refs.v(node.ref_id as usize);
            (v.x, v.y, v.z)
        })
        .collect();
    for i in 0..n {
        for j in i + 1..n {
            let (lo, hi) = bounds[i * n + j];
            let (b0, b1) = (first[j], first[j + 1]);
            for u in first[i]..first[i + 1] {
                let (ax, ay, az) = (xs[u], ys[u], zs[u]);
                // Which of star j's candidates lie at the right distance, as bits (≤ 64).
                let mut hits = 0u64;
                for (bit, ((bx, by), bz)) in xs[b0..b1]
                    .iter()
                    .zip(&ys[b0..b1])
                    .zip(&zs[b0..b1])
                    .enumerate()
                {
                    let c2 = (ax - bx).powi(2) + (ay - by).powi(2) + (az - bz).powi(2);
                    hits |= ((c2 >= lo && c2 <= hi) as u64) << bit;
                }
                while hits != 0 {
                    let v = b0 + hits.trailing_zeros() as usize;
                    hits &= hits - 1;
                    if nodes[u].ref_id != nodes[v].ref_id {
                        adj[u * words + v / 64] |= 1 << (v % 64);
                        adj[v * words + u / 64] |= 1 << (u % 64);
                    }
                }
            }
        }
    }
    let row = |u: usize| &adj[u * words..(u + 1) * words];
    let linked = |u: usize, v: usize| adj[u * words + v / 64] >> (v % 64) & 1 == 1;
    // Triangles through each node: for each edge, the common neighbours of its ends.
    let mut triangles = vec![0u32; m];
    for u in 0..m {
        // The edges (u, v) with v > u, from u's adjacency bits.
        for (w, &word) in row(u).iter().enumerate().skip(u / 64) {
            let mut bits = if w == u / 64 {
                // Bits above u's own (two shifts: one by 64 would overflow).
                word & (u64::MAX << (u % 64) << 1)
            } else {
                word
            };
            while bits != 0 {
                let v = w * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let common: u32 = row(u)
                    .iter()
                    .zip(row(v))
                    .map(|(x, y)| (x & y).count_ones())
                    .sum();
                triangles[u] += common;
                triangles[v] += common;
            }
        }
    }
    let mut order: Vec<usize> = (0..m).filter(|&u| triangles[u] > 0).collect();
    order.sort_by(|&u, &v| triangles[v].cmp(&triangles[u]).then(u.cmp(&v)));
    let mut best: Vec<usize> = Vec::new();
    for &seed in order.iter().take(SEEDS) {
        let mut set = vec![seed];
        for &u in &order {
            let fresh = set
                .iter()
                .all(|&w| nodes[w].star != nodes[u].star && nodes[w].ref_id != nodes[u].ref_id);
            if fresh && set.iter().all(|&w| linked(u, w)) {
                set.push(u);
            }
        }
        if set.len() > best.len() {
            best = set;
        }
    }
    if best.len() < 3 {
        return Vec::new();
    }
    let mut ids: Vec<Identification> = best.iter().map(|&u| nodes[u]).collect();
    ids.sort_by_key(|m| m.star);
    ids
}

/// How many of the best-scored nodes a consistent set is grown from.
const SEEDS: usize = 8;
