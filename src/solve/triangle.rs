//! Side-side-side triangle matching (seed 002's final step, without its radial features): the
//! fallback when voting finds no consistent set.
//!
//! Voting ranks each image star's catalog candidates by how many pairs agree with them. In a
//! dense catalog (a narrow field with a deep magnitude limit) with many false detections among
//! the voters, chance candidates collect as many votes as the true ones, which then fall out of
//! the kept candidates. A triangle asks more of chance: three catalog stars whose three
//! distances all match three image stars, with the same handedness. Each match fixes an
//! attitude that refinement then tests against every star in view (the false-match probability
//! counts every triangle hypothesis tried, on top of the vote's).

use crate::catalog::RefCatalog;
use crate::catalog::table::{KEY_SCALE, PairTable, chord_of_angle};
use crate::cpu::vote::PairRange;
use nalgebra::Vector3;
use std::collections::HashMap;

/// The brightest image stars that form triangles (56 triangles for 8).
pub const TRIANGLE_STARS: usize = 8;

/// At most this many confirmed triangles per frame and scale are refined.
pub const MAX_HYPOTHESES: usize = 1000;

/// A hypothesis: image stars `stars` are catalog stars `refs`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Triangle {
    pub stars: [usize; 3],
    pub refs: [u32; 3],
}

/// Catalog pairs of one image pair: each catalog star's partners on this side, sorted, each
/// with its direction; and the side's key range, to test any two stars by their chord. A side
/// with wide tolerances holds thousands of pairs and is tested millions of times: with the
/// directions beside the ids, walking the stars in order reads each side front to back, where
/// fetching every partner's direction from the catalog missed the cache each time (3-4× the
/// time). The lists are built by a counting sort.
struct Side {
    /// Star `a`'s partners are `partners[start[a]..start[a + 1]]`.
    start: Vec<u32>,
    partners: Vec<u32>,
    /// The direction of each of `partners`.
    dirs: Vec<Vector3<f64>>,
    /// The side's chords, `lo..hi` (from its keys, `floor(chord · KEY_SCALE)` in
    /// `lo_key..=hi_key`, and below the table's largest chord), and their squares widened by a
    /// relative 1e-12 (a few thousand ulps: more than the rounding of a square or a root).
    lo: f64,
    hi: f64,
    lo2: f64,
    hi2: f64,
}

impl Side {
    fn new(table: &PairTable, r: &PairRange, dirs_of: &[Vector3<f64>]) -> Side {
        let rows = table.range(r.lo, r.hi);
        let mut start = vec![0u32; dirs_of.len() + 1];
        for row in rows.clone() {
            let (a, b) = table.pair(row);
            start[a as usize + 1] += 1;
            start[b as usize + 1] += 1;
        }
        for s in 1..start.len() {
            start[s] += start[s - 1];
        }
        let mut next = start.clone();
        let mut partners = vec![0u32; 2 * rows.len()];
        for row in rows {
            let (a, b) = table.pair(row);
            partners[next[a as usize] as usize] = b;
            next[a as usize] += 1;
            partners[next[b as usize] as usize] = a;
            next[b as usize] += 1;
        }
        for w in start.windows(2) {
            let list = &mut partners[w[0] as usize..w[1] as usize];
            if list.len() > 1 {
                list.sort_unstable();
            }
        }
        let dirs = partners.iter().map(|&b| dirs_of[b as usize]).collect();
        // key = floor(chord · KEY_SCALE), KEY_SCALE a power of two: key >= lo_key exactly when
        // chord >= lo_key / KEY_SCALE, and key <= hi_key when chord < (hi_key + 1) / KEY_SCALE.
        let lo = f64::from(r.lo) / KEY_SCALE;
        let hi = ((f64::from(r.hi) + 1.0) / KEY_SCALE).min(chord_of_angle(table.max_sep_rad));
        Side {
            start,
            partners,
            dirs,
            lo,
            hi,
            lo2: lo * lo * (1.0 - 1e-12),
            hi2: hi * hi * (1.0 + 1e-12),
        }
    }

    /// The partners of catalog star `a` on this side, in rising order, and their directions.
    #[inline]
    fn of(&self, a: u32) -> (&[u32], &[Vector3<f64>]) {
        let a = a as usize;
        let at = self.start[a] as usize..self.start[a + 1] as usize;
        (&self.partners[at.clone()], &self.dirs[at])
    }

    /// Whether two catalog stars in directions `a` and `b` are a pair of this side: the
    /// table's own test, with the chord computed as `PairTable::build` computed it, bit for
    /// bit. Most pairs tested are far from the side: their squared chord says so without the
    /// root.
    #[inline]
    fn holds(&self, a: &Vector3<f64>, b: &Vector3<f64>) -> bool {
        let d = a - b;
        let chord2 = d.norm_squared();
        if chord2 < self.lo2 || chord2 > self.hi2 {
            return false;
        }
        let chord = d.norm();
        chord >= self.lo && chord < self.hi
    }
}

/// Every triple of `n` stars (in brightness order), first triangles first: by the sum of the
/// stars' places, then lexicographically.
pub fn triangle_order(n: usize) -> Vec<[usize; 3]> {
    let mut order: Vec<[usize; 3]> = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            for k in j + 1..n {
                order.push([i, j, k]);
            }
        }
    }
    order.sort_by_key(|t| (t[0] + t[1] + t[2], *t));
    order
}

/// Triangle hypotheses among `vectors` (the brightest [`TRIANGLE_STARS`] voting stars, or the
/// spread retry's first stars), first triangles first (by the sum of the stars' places in
/// `vectors`, then lexicographically), each confirmed by a fourth star whose three distances
/// to the triangle's catalog stars match too (Mortari's pyramid): chance rarely passes that,
/// so few hypotheses reach refinement. At most `MAX_HYPOTHESES`. `ranges` are the vote's pair
/// ranges; `vectors` the stars' camera-frame directions; handedness must agree with the
/// catalog's (a proper rotation keeps it).
/// Returns also how many catalog triangles matched before confirmation: the hypotheses a
/// chance match could have come from.
pub fn triangles(
    table: &PairTable,
    ranges: &[PairRange],
    vectors: &[Vector3<f64>],
    refs: &RefCatalog,
) -> (Vec<Triangle>, u64) {
    let n = vectors.len();
    let dirs_of: Vec<Vector3<f64>> = refs.stars.iter().map(|s| s.v).collect();
    let sides: HashMap<(usize, usize), Side> = ranges
        .iter()
        .filter(|r| (r.i as usize) < n && (r.j as usize) < n)
        .map(|r| {
            let (i, j) = (r.i.min(r.j) as usize, r.i.max(r.j) as usize);
            ((i, j), Side::new(table, r, &dirs_of))
        })
        .collect();
    let side = |a: usize, b: usize| sides.get(&(a.min(b), a.max(b)));
    let mut out = Vec::new();
    let mut matched = 0u64;
    for [i, j, k] in triangle_order(n) {
        let (Some(ij), Some(ik), Some(jk)) = (side(i, j), side(i, k), side(j, k)) else {
            continue;
        };
        let handed = vectors[i].cross(&vectors[j]).dot(&vectors[k]) > 0.0;
        let fourth: Vec<[&Side; 3]> = (0..n)
            .filter(|l| ![i, j, k].contains(l))
            .filter_map(|l| Some([side(i, l)?, side(j, l)?, side(k, l)?]))
            .collect();
        // Each pair both ways round, in rising order of both stars: deterministic.
        for p in 0..refs.len() as u32 {
            let (rs, r_dirs) = ik.of(p);
            if rs.is_empty() {
                continue;
            }
            let (qs, q_dirs) = ij.of(p);
            for (&q, vq) in qs.iter().zip(q_dirs) {
                for (&r, vr) in rs.iter().zip(r_dirs) {
                    if r == q || !jk.holds(vq, vr) {
                        continue;
                    }
                    let vp = &dirs_of[p as usize];
                    if (vp.cross(vq).dot(vr) > 0.0) != handed {
                        continue;
                    }
                    matched += 1;
                    let confirmed = fourth.iter().any(|[il, jl, kl]| {
                        let (ss, s_dirs) = il.of(p);
                        ss.iter().zip(s_dirs).any(|(&s, vs)| {
                            s != q && s != r && jl.holds(vq, vs) && kl.holds(vr, vs)
                        })
                    });
                    if !confirmed {
                        continue;
                    }
                    out.push(Triangle {
                        stars: [i, j, k],
                        refs: [p, q, r],
                    });
                    if out.len() == MAX_HYPOTHESES {
                        return (out, matched);
                    }
                }
            }
        }
    }
    (out, matched)
}
