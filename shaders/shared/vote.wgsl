// Shared by the identification kernels (vote, select).

// Keep in sync with src/gpu/vote.rs (VoteUniform).
struct VoteUniform {
    images: u32,
    // Voting stars counted in this dispatch (the stride of the vote counters).
    stars: u32,
    // Reference stars (catalog ids are below this).
    refs: u32,
    pairs_per_image: u32,
    // Candidates kept per star.
    k: u32,
    // First voting star counted: stars star_lo .. star_lo + stars.
    star_lo: u32,
    // The table rows bound to this dispatch: row_lo .. row_hi.
    row_lo: u32,
    row_hi: u32,
}

// Keep in sync with src/gpu/vote.rs (RowSpan).
struct RowSpan {
    i: u32,
    j: u32,
    start: u32,
    end: u32,
}
