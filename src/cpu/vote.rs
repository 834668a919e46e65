//! Stage `vote` (seed 000, geometric voting): every pair of image stars votes through every
//! table row whose chord key lies in the pair's range: both catalog stars of the row get a vote
//! from each of the two image stars.

use crate::catalog::table::PairTable;
use bytemuck::{Pod, Zeroable};

/// One image-star pair and its key range (inclusive), made on the CPU in f64. (The GPU gets
/// the table rows of the range, `gpu::vote::RowSpan`.)
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
    let mut votes = Vec::new();
    let scanned = vote_into(&mut votes, table, ranges, n_stars, n_ref);
    (votes, scanned)
}

/// [`vote`] into `votes` (cleared and resized): a deep catalog's counters take tens of MB a
/// frame, which a fresh allocation gets as new pages from the kernel, zeroed and faulted in
/// one by one (a fifth of the time of a 2° Gaia frame); a buffer kept by the caller is only
/// cleared.
pub fn vote_into(
    votes: &mut Vec<u32>,
    table: &PairTable,
    ranges: &[PairRange],
    n_stars: usize,
    n_ref: usize,
) -> u64 {
    votes.clear();
    votes.resize(n_stars * n_ref, 0);
    let rows: Vec<std::ops::Range<usize>> =
        ranges.iter().map(|r| table.range(r.lo, r.hi)).collect();
    let scanned = rows.iter().map(|r| r.len() as u64).sum();
    // Star by star, so that the counters being added to stay in the L1 cache: each row is read
    // twice (once for each of its two image stars), which costs less than scattering the four
    // increments of a row over all the stars' counters.
    for (s, counters) in votes.chunks_exact_mut(n_ref).enumerate() {
        for (r, rows) in ranges.iter().zip(&rows) {
            if r.i as usize != s && r.j as usize != s {
                continue;
            }
            for &[a, b] in &table.pairs[rows.clone()] {
                counters[a as usize] += 1;
                counters[b as usize] += 1;
            }
        }
    }
    scanned
}
