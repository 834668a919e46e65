//! Stage `select`: each image star keeps its `k` catalog stars with the most votes, best first;
//! ties go to the lowest id. A candidate is packed as `(votes << 32) | (0xFFFFFFFF − id)`, so
//! that the order is total and any scheduling of the GPU finds the same list (the GPU stores
//! it as two words, low first, which is this u64 in little-endian memory).

/// Pack votes and id into the tie-free key (votes saturate at 0xFFFF, the radix select's
/// two bytes; ids take 32 bits).
#[inline]
pub fn pack_candidate(votes: u32, id: u32) -> u64 {
    (u64::from(votes.min(0xFFFF)) << 32) | u64::from(u32::MAX - id)
}

/// (votes, id) of a packed candidate, or None for an empty slot.
#[inline]
pub fn unpack_candidate(packed: u64) -> Option<(u32, u32)> {
    let votes = (packed >> 32) as u32;
    (votes > 0).then_some((votes, u32::MAX - packed as u32))
}

/// The `k` best candidates of each image star, `out[star · k + rank]` (0 = empty slot).
///
/// The GPU finds T, the (saturated) votes of the m-th best candidate (m = min(k, candidates
/// with votes)), by counting votes, keeps every candidate above T and the lowest ids among
/// those at T, and sorts the m keys. Here one pass in id order keeps the best so far: once k
/// are kept, a later id needs more votes than the least of them to rank above it, so a run of
/// `RUN` (32) counters none of which exceeds that is passed over with one vectorised maximum.
/// The same m keys, in the same order.
pub fn select(votes: &[u32], n_stars: usize, n_ref: usize, k: usize) -> Vec<u64> {
    crate::simd::fast!(select_in(votes: &[u32], n_stars: usize, n_ref: usize, k: usize) -> Vec<u64>)
}

/// The counters [`select`] tests at a time.
const RUN: usize = 32;

/// [`select`], compiled where it is inlined (see [`crate::simd`]).
#[inline(always)]
fn select_in(votes: &[u32], n_stars: usize, n_ref: usize, k: usize) -> Vec<u64> {
    let mut out = vec![0u64; n_stars * k];
    if k == 0 {
        return out;
    }
    // The best keys so far, rising.
    let mut best: Vec<u64> = Vec::with_capacity(k + 1);
    for s in 0..n_stars {
        let row = &votes[s * n_ref..(s + 1) * n_ref];
        best.clear();
        // The votes a candidate must exceed: none until k are kept.
        let mut bar = 0u32;
        for (r, run) in row.chunks(RUN).enumerate() {
            if run.iter().fold(0, |m, &v| m.max(v)).min(0xFFFF) <= bar {
                continue;
            }
            for (i, &v) in run.iter().enumerate() {
                if v.min(0xFFFF) <= bar {
                    continue;
                }
                let key = pack_candidate(v, (r * RUN + i) as u32);
                best.insert(best.partition_point(|&b| b < key), key);
                if best.len() > k {
                    best.remove(0);
                }
                if best.len() == k {
                    bar = (best[0] >> 32) as u32;
                }
            }
        }
        for (o, &key) in out[s * k..(s + 1) * k].iter_mut().zip(best.iter().rev()) {
            *o = key;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The definition: every candidate with votes, ordered by votes (saturated) then lowest
    /// id, the first k; rows sparse and dense, with ties and saturated counts.
    #[test]
    fn select_keeps_the_best_k_of_the_definition() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for case in 0..300 {
            let (n_stars, n_ref, k) = (
                rng.random_range(1..5),
                rng.random_range(1..400),
                rng.random_range(1..12),
            );
            let density = [0.01, 0.1, 0.5, 1.0][case % 4];
            let top = [3u32, 40, 0x1_0005][case % 3];
            let votes: Vec<u32> = (0..n_stars * n_ref)
                .map(|_| {
                    if rng.random_bool(density) {
                        rng.random_range(1..=top)
                    } else {
                        0
                    }
                })
                .collect();
            let got = select(&votes, n_stars, n_ref, k);
            for s in 0..n_stars {
                let mut want: Vec<(u32, usize)> = (0..n_ref)
                    .map(|id| (votes[s * n_ref + id].min(0xFFFF), id))
                    .filter(|&(v, _)| v > 0)
                    .collect();
                want.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
                want.resize(k.min(want.len()), (0, 0));
                let row: Vec<(u32, usize)> = got[s * k..(s + 1) * k]
                    .iter()
                    .map_while(|&p| unpack_candidate(p))
                    .map(|(v, id)| (v, id as usize))
                    .collect();
                assert_eq!(row, want, "case {case} star {s}");
                assert!(got[s * k + row.len()..(s + 1) * k].iter().all(|&p| p == 0));
            }
        }
    }
}
