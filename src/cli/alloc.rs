//! How the command line's allocator keeps frame-sized buffers (glibc only).
//!
//! Each frame allocates and frees buffers of megabytes: the file's bytes, its pixels,
//! detection's planes, the catalog moved to the frame's own date. glibc maps anything above
//! its threshold (128 KiB at start, raised only as large blocks are freed) afresh and returns
//! it to the system on free, so frame after frame paid the page faults of new memory again.
//! Keeping blocks up to 32 MiB on the heap, and the heap's free top up to 256 MiB, lets the next
//! frame reuse them: 15 % of an 18° run of easy frames, 6 % of a sparse 8° run (docs/speed.md).
//! A process-wide setting, so the command line's alone: the library leaves its host's
//! allocator as it is.

/// Keep freed frame-sized buffers for reuse (see the module documentation).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub fn keep_frame_buffers() {
    // SAFETY: mallopt only changes glibc's thresholds; called before any thread starts.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
    }
}

/// Other allocators keep their own policy.
#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn keep_frame_buffers() {}
