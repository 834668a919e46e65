//! Stage `select`: each image star keeps its `k` catalog stars with the most votes, best first;
//! ties go to the lowest id. A candidate is packed as `(votes << 16) | (0xFFFF − id)`, so that
//! the order is total and the GPU finds the same list with `atomicMax` in any scheduling
//! (round r takes the largest key below round r − 1's).

/// Pack votes and id into the tie-free argmax key (votes saturate at 0xFFFF).
#[inline]
pub fn pack_candidate(votes: u32, id: u32) -> u32 {
    (votes.min(0xFFFF) << 16) | (0xFFFF - id)
}

/// (votes, id) of a packed candidate, or None for an empty slot.
#[inline]
pub fn unpack_candidate(packed: u32) -> Option<(u32, u32)> {
    let votes = packed >> 16;
    (votes > 0).then_some((votes, 0xFFFF - (packed & 0xFFFF)))
}

/// The `k` best candidates of each image star, `out[star · k + rank]` (0 = empty slot).
pub fn select(votes: &[u32], n_stars: usize, n_ref: usize, k: usize) -> Vec<u32> {
    let mut out = vec![0u32; n_stars * k];
    for s in 0..n_stars {
        let mut keys: Vec<u32> = votes[s * n_ref..(s + 1) * n_ref]
            .iter()
            .enumerate()
            .filter(|&(_, &v)| v > 0)
            .map(|(id, &v)| pack_candidate(v, id as u32))
            .collect();
        let top = k.min(keys.len());
        if top == 0 {
            continue;
        }
        if top < keys.len() {
            keys.select_nth_unstable_by(top - 1, |a, b| b.cmp(a));
        }
        keys[..top].sort_unstable_by(|a, b| b.cmp(a));
        out[s * k..s * k + top].copy_from_slice(&keys[..top]);
    }
    out
}
