//! Stage `pattern` (the scale-free first pass's lookup): for every query key of a batch, the
//! rows `[start, end)` of the sorted pattern keys equal to it, the lower bounds of the key and
//! of the key + 1. Integers only: GPU = CPU exactly. The kernel searches all the keys; here
//! a table of where each key prefix starts ([`Buckets`]) leaves a search of a few keys, since
//! the two binary searches over a million keys (cache misses) were a quarter of a noisy
//! 18-degree frame's time with the field searched. The rows are the same.

use bytemuck::{Pod, Zeroable};

/// The rows of one query key: `start .. end` of the pattern keys. Keep in sync with
/// `shaders/pattern.wgsl` (Rows).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Rows {
    pub start: u32,
    pub end: u32,
}

/// Where each key prefix starts in a sorted key list: bucket `b` holds the keys whose top
/// bits (the key shifted right by `shift`) are `b`, from `starts[b]` to `starts[b + 1]`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Buckets {
    shift: u32,
    starts: Vec<u32>,
}

impl Buckets {
    /// About two keys a bucket (at most 2^22 buckets) for `keys`, ascending.
    pub fn new(keys: &[u32]) -> Buckets {
        let bits_of = |v: u64| 64 - v.leading_zeros();
        let top = bits_of(keys.last().map_or(0, |&k| u64::from(k)));
        let bits = bits_of(keys.len() as u64 / 2).min(22).min(top);
        let shift = top - bits;
        let n = 1usize << bits;
        let mut starts = Vec::with_capacity(n + 1);
        let mut i = 0usize;
        for b in 0..n as u64 {
            while i < keys.len() && u64::from(keys[i]) >> shift < b {
                i += 1;
            }
            starts.push(i as u32);
        }
        starts.push(keys.len() as u32);
        Buckets { shift, starts }
    }

    /// [`lower_bound`] of `key` in the `keys` these buckets were made from.
    pub fn lower_bound(&self, keys: &[u32], key: u32) -> u32 {
        let b = (key >> self.shift) as usize;
        if b + 1 >= self.starts.len() {
            return keys.len() as u32;
        }
        let (lo, hi) = (self.starts[b], self.starts[b + 1]);
        lo + lower_bound(&keys[lo as usize..hi as usize], key)
    }
}

/// First index of `keys` (ascending) whose key is at least `key` (`keys.len()` if none): the
/// kernel's loop, step for step.
pub fn lower_bound(keys: &[u32], key: u32) -> u32 {
    let mut lo = 0u32;
    let mut hi = keys.len() as u32;
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if keys[mid as usize] < key {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// The rows of each query (one GPU thread each), `buckets` made from `keys` (None: each
/// query searches all the keys, as the kernel does).
pub fn pattern(keys: &[u32], buckets: Option<&Buckets>, queries: &[u32]) -> Vec<Rows> {
    let lower = |key: u32| match buckets {
        Some(b) => b.lower_bound(keys, key),
        None => lower_bound(keys, key),
    };
    queries
        .iter()
        .map(|&q| {
            let start = lower(q);
            // Keys are 30 bits: q + 1 does not overflow, but the kernel's guard is kept alike.
            let end = if q == u32::MAX {
                keys.len() as u32
            } else {
                lower(q + 1)
            };
            Rows { start, end }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_the_equal_keys() {
        let keys = [1, 3, 3, 3, 7, 9, 9];
        let buckets = Buckets::new(&keys);
        // With the table of key prefixes and without it (the kernel's search).
        for b in [Some(&buckets), None] {
            let rows = pattern(&keys, b, &[0, 1, 3, 4, 9, 10, u32::MAX]);
            let got: Vec<(u32, u32)> = rows.iter().map(|r| (r.start, r.end)).collect();
            assert_eq!(
                got,
                [(0, 0), (0, 1), (1, 4), (4, 4), (5, 7), (7, 7), (7, 7)]
            );
        }
        for b in [Some(&Buckets::new(&[])), None] {
            assert_eq!(pattern(&[], b, &[5]), [Rows { start: 0, end: 0 }]);
        }
    }

    #[test]
    fn buckets_find_what_the_search_of_all_keys_finds() {
        // Keys of 30 bits and of a few, with runs of equal keys; queries on and between them.
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as u32
        };
        for (n, mask) in [
            (1usize, 0x3fff_ffffu32),
            (1000, 0x3fff_ffff),
            (5000, 0xff),
            (3, 7),
        ] {
            let mut keys: Vec<u32> = (0..n).map(|_| next() & mask).collect();
            keys.extend_from_within(..n / 3);
            keys.sort_unstable();
            let b = Buckets::new(&keys);
            let mut queries: Vec<u32> = keys
                .iter()
                .flat_map(|&k| [k, k + 1, k.saturating_sub(1)])
                .collect();
            queries.extend([0, mask, mask + 1, u32::MAX, u32::MAX - 1]);
            queries.extend((0..1000).map(|_| next() & mask));
            for q in queries {
                assert_eq!(
                    b.lower_bound(&keys, q),
                    lower_bound(&keys, q),
                    "n {n}, key {q}"
                );
            }
        }
    }
}
