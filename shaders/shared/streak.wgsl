// Shared by the streak kernels (streak_rows, streak_filter), after shared/detect.wgsl.

// Keep in sync with src/cpu/streak_filter.rs (StreakParams).
struct StreakParams {
    level_num: u32,
    level_den: u32,
    // The binned grid (blocks of 2×2 pixels) and its mask words per frame.
    width: u32,
    height: u32,
    words: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Keep in sync with src/gpu/detect.rs (StreakUniform).
struct StreakUniform {
    p: DetectParams,
    b: BatchParams,
    s: StreakParams,
}
