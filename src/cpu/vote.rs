//! Stage `vote` (seed 000, geometric voting): every pair of image stars votes through every
//! table row whose chord key lies in the pair's range: both catalog stars of the row get a vote
//! from each of the two image stars.

use crate::table::PairTable;
use bytemuck::{Pod, Zeroable};

/// One image-star pair and its key range (inclusive), made on the CPU in f64.
/// Keep in sync with `shaders/shared/vote.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct PairRange {
    pub i: u32,
    pub j: u32,
    pub lo: u32,
    pub hi: u32,
}

/// Vote counters, `votes[star · n_ref + ref_id]`. Returns also the number of (pair, row)
/// hypotheses scanned, which the false-match probability needs.
pub fn vote(
    table: &PairTable,
    ranges: &[PairRange],
    n_stars: usize,
    n_ref: usize,
) -> (Vec<u32>, u64) {
    let mut votes = vec![0u32; n_stars * n_ref];
    let mut scanned = 0u64;
    for r in ranges {
        let rows = table.range(r.lo, r.hi);
        scanned += rows.len() as u64;
        let (i, j) = (r.i as usize * n_ref, r.j as usize * n_ref);
        for row in rows {
            let (a, b) = table.pair(row);
            let (a, b) = (a as usize, b as usize);
            votes[i + a] += 1;
            votes[i + b] += 1;
            votes[j + a] += 1;
            votes[j + b] += 1;
        }
    }
    (votes, scanned)
}
