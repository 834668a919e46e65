//! Stage `pattern` (the scale-free first pass's lookup): for every query key of a batch, the
//! rows `[start, end)` of the sorted pattern keys equal to it, by two binary searches (lower
//! bounds of the key and of the key + 1). Integers only: GPU = CPU exactly.

use bytemuck::{Pod, Zeroable};

/// The rows of one query key: `start .. end` of the pattern keys. Keep in sync with
/// `shaders/pattern.wgsl` (Rows).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Rows {
    pub start: u32,
    pub end: u32,
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

/// The rows of each query (one GPU thread each).
pub fn pattern(keys: &[u32], queries: &[u32]) -> Vec<Rows> {
    queries
        .iter()
        .map(|&q| {
            let start = lower_bound(keys, q);
            // Keys are 30 bits: q + 1 does not overflow, but the kernel's guard is kept alike.
            let end = if q == u32::MAX {
                keys.len() as u32
            } else {
                lower_bound(keys, q + 1)
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
        let rows = pattern(&keys, &[0, 1, 3, 4, 9, 10, u32::MAX]);
        let got: Vec<(u32, u32)> = rows.iter().map(|r| (r.start, r.end)).collect();
        assert_eq!(
            got,
            [(0, 0), (0, 1), (1, 4), (4, 4), (5, 7), (7, 7), (7, 7)]
        );
        assert_eq!(pattern(&[], &[5]), [Rows { start: 0, end: 0 }]);
    }
}
