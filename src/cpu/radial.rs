//! Stage `radial` (seed 002; CPU twin of `shaders/radial.wgsl`): each image star's radial
//! feature A against every catalog star's B, `scores[star · n_ref + id]` =
//! max(0, BITS·|A ∧ B| − |A|·|B|): the rings both have, less what chance gives two random
//! vectors with these bit counts (times BITS: integers, so the GPU's are the same). A crowded
//! catalog star, with many rings set, matches anything by chance and scores accordingly less.
//! An image feature sets a few of the `WORDS` words (one per neighbour at most): only those
//! are read, each over all catalog stars in order (the catalog is word-major). Integer
//! arithmetic only: GPU = CPU bit for bit; `select` then keeps the best.

/// Rings per feature: chance sets few of them in common (a feature of 16 neighbours against a
/// catalog star's 30 shares 0.5 rings by chance). Keep in sync with `shaders/radial.wgsl`.
pub const BITS: usize = 4096;
/// u32 words per feature.
pub const WORDS: usize = BITS / 32;

/// Scores of `image`'s features (`WORDS` words each) against the catalog's (word-major,
/// `catalog[w · n_ref + id]`), whose bit counts are `counts` (one per catalog star).
pub fn radial(catalog: &[u32], counts: &[u32], image: &[u32], n_stars: usize) -> Vec<u32> {
    let n_ref = counts.len();
    let mut scores = vec![0u32; n_stars * n_ref];
    for (s, row) in scores
        .chunks_exact_mut(n_ref.max(1))
        .take(n_stars)
        .enumerate()
    {
        let a = &image[s * WORDS..(s + 1) * WORDS];
        let na: u32 = a.iter().map(|w| w.count_ones()).sum();
        // Rings in common, accumulated word by word.
        for (w, &aw) in a.iter().enumerate().filter(|(_, w)| **w != 0) {
            let words = &catalog[w * n_ref..(w + 1) * n_ref];
            for (both, &b) in row.iter_mut().zip(words) {
                *both += (aw & b).count_ones();
            }
        }
        for (score, &nb) in row.iter_mut().zip(counts) {
            *score = (BITS as u32 * *score).saturating_sub(na * nb);
        }
    }
    scores
}
