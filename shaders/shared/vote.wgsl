// Shared by the identification kernels (vote, select).

// Keep in sync with src/gpu/vote.rs (VoteUniform).
struct VoteUniform {
    images: u32,
    // Voting stars per image (the stride of the vote counters).
    stars: u32,
    // Reference stars (catalog ids are below this).
    refs: u32,
    pairs_per_image: u32,
    // Candidates kept per star.
    k: u32,
    // k-vector bin width as a shift of the key.
    shift: u32,
    rows: u32,
    kvector_len: u32,
}

// Keep in sync with src/cpu/vote.rs (PairRange).
struct PairRange {
    i: u32,
    j: u32,
    lo: u32,
    hi: u32,
}
