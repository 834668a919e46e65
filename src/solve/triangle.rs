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
use crate::catalog::table::PairTable;
use crate::cpu::vote::PairRange;
use nalgebra::Vector3;
use rustc_hash::FxHashSet;
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

/// Catalog pairs of one image pair: sorted partners to walk, and a hash set of the pairs to
/// probe (a side holds thousands of pairs and is probed millions of times: FxHash's one
/// multiply beats a binary search's dozen cache misses).
struct Side {
    /// (star, partner), both ways round, sorted.
    partners: Vec<(u32, u32)>,
    /// The pairs as `min << 32 | max` (ids are 32-bit).
    keys: FxHashSet<u64>,
}

impl Side {
    fn new(table: &PairTable, r: &PairRange) -> Side {
        let rows = table.range(r.lo, r.hi);
        let mut partners = Vec::with_capacity(2 * rows.len());
        let mut keys = FxHashSet::with_capacity_and_hasher(rows.len(), Default::default());
        for row in rows {
            let (a, b) = table.pair(row);
            partners.push((a, b));
            partners.push((b, a));
            keys.insert(pair_key(a, b));
        }
        partners.sort_unstable();
        Side { partners, keys }
    }

    /// The partners of catalog star `a` on this side.
    fn of(&self, a: u32) -> impl Iterator<Item = u32> + '_ {
        let start = self.partners.partition_point(|&(x, _)| x < a);
        self.partners[start..]
            .iter()
            .take_while(move |&&(x, _)| x == a)
            .map(|&(_, b)| b)
    }

    /// [`Side::of`] for `a` rising from call to call: `cursor` (starting at 0) walks
    /// `partners` once instead of searching it each time.
    fn of_rising(&self, a: u32, cursor: &mut usize) -> impl Iterator<Item = u32> + '_ {
        while self.partners.get(*cursor).is_some_and(|&(x, _)| x < a) {
            *cursor += 1;
        }
        self.partners[*cursor..]
            .iter()
            .take_while(move |&&(x, _)| x == a)
            .map(|&(_, b)| b)
    }

    fn has(&self, a: u32, b: u32) -> bool {
        self.keys.contains(&pair_key(a, b))
    }
}

/// The key of an unordered pair of catalog ids.
fn pair_key(a: u32, b: u32) -> u64 {
    u64::from(a.min(b)) << 32 | u64::from(a.max(b))
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
    let sides: HashMap<(usize, usize), Side> = ranges
        .iter()
        .filter(|r| (r.i as usize) < n && (r.j as usize) < n)
        .map(|r| {
            let (i, j) = (r.i.min(r.j) as usize, r.i.max(r.j) as usize);
            ((i, j), Side::new(table, r))
        })
        .collect();
    let side = |a: usize, b: usize| sides.get(&(a.min(b), a.max(b)));
    let v = |id: u32| refs.stars[id as usize].v;
    let mut out = Vec::new();
    let mut matched = 0u64;
    for [i, j, k] in triangle_order(n) {
        let (Some(ij), Some(ik), Some(jk)) = (side(i, j), side(i, k), side(j, k)) else {
            continue;
        };
        let handed = vectors[i].cross(&vectors[j]).dot(&vectors[k]) > 0.0;
        // Each pair both ways round, in sorted order: deterministic.
        let mut cursor = 0;
        for &(p, q) in &ij.partners {
            // Partners come sorted and once each.
            for r in ik
                .of_rising(p, &mut cursor)
                .filter(|&r| r != q && jk.has(q, r))
            {
                if (v(p).cross(&v(q)).dot(&v(r)) > 0.0) != handed {
                    continue;
                }
                matched += 1;
                let confirmed = (0..n).filter(|l| ![i, j, k].contains(l)).any(|l| {
                    let (Some(il), Some(jl), Some(kl)) = (side(i, l), side(j, l), side(k, l))
                    else {
                        return false;
                    };
                    il.of(p)
                        .any(|s| s != q && s != r && jl.has(q, s) && kl.has(r, s))
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
    (out, matched)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ids are 32-bit (deep catalogs): the pair key keeps both whole. The 16-bit packing it
    /// replaces made (1, 65541) and (2, 5) the same pair.
    #[test]
    fn pair_keys_of_large_ids_do_not_collide() {
        assert_ne!(pair_key(1, 65_541), pair_key(2, 5));
        assert_eq!(pair_key(70_000, 3), pair_key(3, 70_000));
        assert_ne!(pair_key(u32::MAX, 0), pair_key(0, u32::MAX - 1));
    }
}
