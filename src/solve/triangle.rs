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

use crate::catalog::table::{KEY_SCALE, PairTable, RowRange, chord_of_angle};
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

/// Catalog pairs of one image pair: the catalog stars on this side that a triangle can ask for
/// (a bit per star, with the count of set bits before each word, so that a star's place among
/// them is a popcount), each one's partners, rising, and their directions; and the side's key
/// range, to test any two stars by their chord. Most stars on a side have one partner there,
/// so a side is built by counting (no sort of its pairs) and two sides are joined word by
/// word: where sorted lists were walked star by star, most of a triangle's time went to stars
/// on only one side. With the directions beside the ids, the partners are read front to back.
struct Side {
    /// Bit `s % 64` of word `s / 64` is set when star `s` has partners on this side and is
    /// kept (see [`triangles`]: the others are never asked for).
    words: Vec<u64>,
    /// The stars kept in words before word w: `rank[w]`.
    rank: Vec<u32>,
    /// The star of rank t's partners are `partners[start[t]..start[t + 1]]`.
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

/// The place of bit `bit` of word `w` among the set bits of `words`, `rank[w]` counting those
/// before word `w`.
#[inline(always)]
fn place(words: &[u64], rank: &[u32], w: usize, bit: u32) -> usize {
    (rank[w] + (words[w] & ((1u64 << bit) - 1)).count_ones()) as usize
}

/// The catalog stars of a side's pairs (the table's `rows`) among stars `0..stars`: bit
/// `s % 64` of word `s / 64` for star `s`.
#[inline(always)]
fn stars_of(table: &PairTable, rows: RowRange, stars: usize) -> Vec<u64> {
    let mut words = vec![0u64; stars.div_ceil(64)];
    for row in rows {
        let (a, b) = table.pair(row);
        words[a as usize / 64] |= 1 << (a % 64);
        words[b as usize / 64] |= 1 << (b % 64);
    }
    words
}

impl Side {
    /// The side of image pair `r`, whose catalog pairs are the table's `rows`, keeping the
    /// partners of the stars of `words` (stars of those pairs, see [`stars_of`]) only.
    #[inline(always)]
    fn new(
        table: &PairTable,
        r: &PairRange,
        rows: RowRange,
        words: Vec<u64>,
        dir: impl Fn(u32) -> Vector3<f64>,
    ) -> Side {
        let mut rank = Vec::with_capacity(words.len());
        let mut owners = 0u32;
        for w in &words {
            rank.push(owners);
            owners += w.count_ones();
        }
        // Counting sort by rank: the places of each pair's two ends, then the partners there.
        let kept = |s: u32| words[s as usize / 64] >> (s % 64) & 1 == 1;
        let slot = |s: u32| place(&words, &rank, s as usize / 64, s % 64);
        let mut start = vec![0u32; owners as usize + 1];
        let mut ends: Vec<(u32, u32)> = Vec::with_capacity(2 * rows.len());
        for row in rows {
            let (a, b) = table.pair(row);
            for (s, partner) in [(a, b), (b, a)] {
                if kept(s) {
                    let t = slot(s);
                    start[t + 1] += 1;
                    ends.push((t as u32, partner));
                }
            }
        }
        for t in 1..start.len() {
            start[t] += start[t - 1];
        }
        let mut fill = start.clone();
        let mut partners = vec![0u32; ends.len()];
        for (t, b) in ends {
            partners[fill[t as usize] as usize] = b;
            fill[t as usize] += 1;
        }
        // Rows come in key order: each star's few partners are put in rising order here.
        for t in 0..owners as usize {
            let list = &mut partners[start[t] as usize..start[t + 1] as usize];
            if list.len() > 1 {
                list.sort_unstable();
            }
        }
        let dirs = partners.iter().map(|&b| dir(b)).collect();
        // key = floor(chord · KEY_SCALE), KEY_SCALE a power of two: key >= lo_key exactly when
        // chord >= lo_key / KEY_SCALE, and key <= hi_key when chord < (hi_key + 1) / KEY_SCALE.
        let lo = f64::from(r.lo) / KEY_SCALE;
        let hi = ((f64::from(r.hi) + 1.0) / KEY_SCALE).min(chord_of_angle(table.max_sep_rad));
        Side {
            words,
            rank,
            start,
            partners,
            dirs,
            lo,
            hi,
            lo2: lo * lo * (1.0 - 1e-12),
            hi2: hi * hi * (1.0 + 1e-12),
        }
    }

    /// The partners of the star of rank `t`, rising, and their directions.
    #[inline]
    fn at(&self, t: usize) -> (&[u32], &[Vector3<f64>]) {
        let at = self.start[t] as usize..self.start[t + 1] as usize;
        (&self.partners[at.clone()], &self.dirs[at])
    }

    /// The rank of the star at bit `bit` of word `w`, which is set.
    #[inline(always)]
    fn rank_at(&self, w: usize, bit: u32) -> usize {
        place(&self.words, &self.rank, w, bit)
    }

    /// The partners of catalog star `a` on this side, rising, and their directions (none when
    /// it has none).
    #[inline(always)]
    fn of(&self, a: u32) -> (&[u32], &[Vector3<f64>]) {
        let (w, bit) = (a as usize / 64, a % 64);
        match self.words.get(w) {
            Some(word) if word >> bit & 1 == 1 => self.at(self.rank_at(w, bit)),
            _ => (&[], &[]),
        }
    }

    /// The stars kept on this side, rising.
    #[cfg(test)]
    fn owners(&self) -> Vec<u32> {
        (0..self.words.len() * 64)
            .filter(|&s| self.words[s / 64] >> (s % 64) & 1 == 1)
            .map(|s| s as u32)
            .collect()
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
/// ranges; `vectors` the stars' camera-frame directions; `dirs` the catalog stars' directions
/// by id, those the table was made from (a band's `directions`); handedness must agree with
/// the catalog's (a proper rotation keeps it).
/// Returns also how many catalog triangles matched before confirmation: the hypotheses a
/// chance match could have come from.
pub fn triangles(
    table: &PairTable,
    ranges: &[PairRange],
    vectors: &[Vector3<f64>],
    dirs: &[Vector3<f64>],
) -> (Vec<Triangle>, u64) {
    crate::simd::fast!(triangles_in(
        table: &PairTable,
        ranges: &[PairRange],
        vectors: &[Vector3<f64>],
        dirs: &[Vector3<f64>]
    ) -> (Vec<Triangle>, u64))
}

/// [`triangles`], compiled where it is inlined (see [`crate::simd`]): its sides' bit sets
/// count with POPCNT.
#[inline(always)]
fn triangles_in(
    table: &PairTable,
    ranges: &[PairRange],
    vectors: &[Vector3<f64>],
    dirs: &[Vector3<f64>],
) -> (Vec<Triangle>, u64) {
    let n = vectors.len();
    // The image pairs among these stars, with their table rows.
    let pairs: Vec<(&PairRange, RowRange)> = ranges
        .iter()
        .filter(|r| (r.i as usize) < n && (r.j as usize) < n)
        .map(|r| (r, table.range(r.lo, r.hi)))
        .collect();
    let dir = |id: u32| dirs[id as usize];
    let stars = dirs.len();
    // Each side's catalog stars, and those that can stand for image star i in a triangle
    // [i, j, k] (i < j < k: the loop below joins sides ij and ik at i): on both of some two
    // sides (i, j), (i, k). A side (a, b) is only asked for such stars of a or b (as ij or ik
    // at a, or as the fourth star's side il at i = a or i = b), so it keeps their partners
    // only: on sparse frames' deep selections fewer than half of its stars. Loops, not an
    // iterator's collect: `stars_of` and `Side::new` stay inlined here, in the AVX2 copy.
    let key = |r: &PairRange| (r.i.min(r.j) as usize, r.i.max(r.j) as usize);
    let mut on_side: HashMap<(usize, usize), Vec<u64>> = HashMap::with_capacity(pairs.len());
    for (r, rows) in &pairs {
        on_side.insert(key(r), stars_of(table, rows.clone(), stars));
    }
    let mut joinable = vec![vec![0u64; stars.div_ceil(64)]; n];
    for (i, joins) in joinable.iter_mut().enumerate() {
        for j in i + 1..n {
            for k in j + 1..n {
                if let (Some(a), Some(b)) = (on_side.get(&(i, j)), on_side.get(&(i, k))) {
                    for (w, (a, b)) in joins.iter_mut().zip(a.iter().zip(b)) {
                        *w |= a & b;
                    }
                }
            }
        }
    }
    let mut sides: HashMap<(usize, usize), Side> = HashMap::with_capacity(pairs.len());
    for (r, rows) in pairs {
        let (i, j) = key(r);
        let mut words = on_side[&(i, j)].clone();
        for (w, (a, b)) in words.iter_mut().zip(joinable[i].iter().zip(&joinable[j])) {
            *w &= a | b;
        }
        sides.insert((i, j), Side::new(table, r, rows, words, dir));
    }
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
        // Each pair both ways round, in rising order of both stars: deterministic. The
        // catalog stars on both sides ij and ik, word by word.
        for (w, (&on_ik, &on_ij)) in ik.words.iter().zip(&ij.words).enumerate() {
            let mut both = on_ik & on_ij;
            while both != 0 {
                let bit = both.trailing_zeros();
                both &= both - 1;
                let p = w as u32 * 64 + bit;
                let (rs, r_dirs) = ik.at(ik.rank_at(w, bit));
                let (qs, q_dirs) = ij.at(ij.rank_at(w, bit));
                let vp = &dir(p);
                for (&q, vq) in qs.iter().zip(q_dirs) {
                    for (&r, vr) in rs.iter().zip(r_dirs) {
                        if r == q || !jk.holds(vq, vr) {
                            continue;
                        }
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
    }
    (out, matched)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ids are 32-bit (deep catalogs): a side keeps both ids of a pair whole, both ways round.
    /// (A 16-bit packing once made (1, 65541) and (2, 5) the same pair.)
    #[test]
    fn sides_keep_large_ids_apart() {
        let keys = vec![10u32, 20];
        let max_key = 31;
        let kvector = (0..=max_key + 1)
            .map(|b| keys.iter().filter(|&&k| k < b).count() as u32)
            .collect();
        let table = PairTable {
            keys: keys.into(),
            pairs: vec![[1, 65_541], [2, 5]].into(),
            kvector,
            shift: 0,
            max_sep_rad: 1.0,
            max_key,
        };
        let all = PairRange {
            i: 0,
            j: 1,
            lo: 0,
            hi: max_key,
        };
        let rows = table.range(all.lo, all.hi);
        let side = Side::new(
            &table,
            &all,
            rows.clone(),
            stars_of(&table, rows, 65_542),
            |_| Vector3::zeros(),
        );
        assert_eq!(side.owners(), vec![1, 2, 5, 65_541]);
        assert_eq!(side.of(1).0, &[65_541]);
        assert_eq!(side.of(65_541).0, &[1]);
        assert_eq!(side.of(2).0, &[5]);
        assert_eq!(side.of(5).0, &[2]);
        assert!(side.of(3).0.is_empty());
    }
}
