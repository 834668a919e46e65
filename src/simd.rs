//! The CPU's wider vector instructions for the per-pixel loops, chosen at run time.
//!
//! Release builds target baseline x86-64 (SSE2), so that one binary runs on any x86-64 machine.
//! SSE2 lacks much that the pixel and matching loops want: an unsigned 16-bit minimum or
//! maximum, a byte shuffle (big-endian FITS pixels), 256-bit registers, a population count
//! (bit sets). `simd::fast!` (crate-internal) runs a loop compiled a second time for AVX2 and
//! POPCNT where the CPU has them; elsewhere (another architecture, an older CPU) as built.
//!
//! Both compilations compute the same results bit for bit: integer arithmetic is exact, and
//! floating point keeps its order (Rust neither reassociates nor fuses a multiply and an add;
//! AVX2 only widens the registers that independent lanes use). Tests hold the two equal by
//! running the same work inside [`baseline`].

use std::cell::Cell;

thread_local! {
    /// Set by [`baseline`]: this thread runs every loop as built.
    static BASELINE: Cell<bool> = const { Cell::new(false) };
}

/// Run `f` with every loop on this thread as built for baseline x86-64, not compiled for
/// AVX2: what a CPU without AVX2 computes, for tests that hold the two equal.
pub fn baseline<R>(f: impl FnOnce() -> R) -> R {
    struct Restore(bool);
    impl Drop for Restore {
        fn drop(&mut self) {
            BASELINE.set(self.0);
        }
    }
    let _restore = Restore(BASELINE.replace(true));
    f()
}

/// Whether the loops run compiled for AVX2 and POPCNT on this thread: the CPU has them and
/// the thread is not inside [`baseline`].
#[cfg(target_arch = "x86_64")]
pub fn wider() -> bool {
    !BASELINE.get()
        && std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("popcnt")
}

/// Other architectures run the loops as built.
#[cfg(not(target_arch = "x86_64"))]
pub fn wider() -> bool {
    false
}

/// The body of `fn name(a: &[u16], b: u32) -> R { simd::fast!(inner(a: &[u16], b: u32) -> R) }`:
/// it calls `inner(a, b)` compiled for AVX2 and POPCNT when the CPU has them (detected once
/// per process, then cached; see [`wider`]), else as built. `inner` and what it calls must be
/// `#[inline(always)]`: only code inlined into the AVX2 copy is compiled for AVX2.
macro_rules! fast {
    ($inner:ident($($arg:ident: $ty:ty),*) -> $ret:ty) => {{
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2,popcnt")]
            fn avx2($($arg: $ty),*) -> $ret {
                $inner($($arg),*)
            }
            if $crate::simd::wider() {
                // SAFETY: the CPU has AVX2 and POPCNT (`wider`), all that `avx2` requires.
                return unsafe { avx2($($arg),*) };
            }
        }
        $inner($($arg),*)
    }};
}
pub(crate) use fast;

#[cfg(test)]
mod tests {
    use super::{baseline, wider};

    /// `baseline` turns the wider loops off on its own thread, for its closure only.
    #[test]
    fn baseline_runs_the_loops_as_built_on_its_thread_only() {
        let outside = wider();
        assert!(!baseline(wider));
        assert_eq!(wider(), outside);
        baseline(|| {
            let other = std::thread::spawn(wider).join().unwrap();
            assert_eq!(other, outside);
        });
        let _ = std::panic::catch_unwind(|| baseline(|| panic!("restored after a panic too")));
        assert_eq!(wider(), outside);
    }
}
