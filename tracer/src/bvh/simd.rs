//! Which node test the eight-wide traversal runs: AVX's eight lanes in one register where
//! the CPU has AVX, SSE2's two halves of four elsewhere. A query picks once, at its start,
//! and runs a copy of its whole loop compiled for that choice (the node test must be
//! inlined to pay). Both tests are the same IEEE operations per lane (subtract, multiply,
//! min, max, compare; no fused multiply-add), so a tile has the same bits on either:
//! `allow_avx(false)` turns the AVX path off so that tests can compare the two.

use std::sync::atomic::{AtomicBool, Ordering};

/// Set by [`allow_avx`]`(false)`.
static AVX_OFF: AtomicBool = AtomicBool::new(false);

/// Whether queries run the AVX node test: the CPU has AVX and [`allow_avx`] has not turned
/// it off.
pub fn avx() -> bool {
    // (std caches the CPU's features after the first call.)
    #[cfg(target_arch = "x86_64")]
    return !AVX_OFF.load(Ordering::Relaxed) && std::arch::is_x86_feature_detected!("avx");
    #[cfg(not(target_arch = "x86_64"))]
    return false;
}

/// Turns the AVX node test off (`false`), or on again where the CPU has it, for every
/// query of this process from now on. The image is the same either way; this is for tests
/// and measurements that compare the two.
pub fn allow_avx(allowed: bool) {
    AVX_OFF.store(!allowed, Ordering::Relaxed);
}

/// Runs `f` compiled for AVX: what it inlines (a query's loop) may use AVX instructions.
///
/// # Safety
/// The CPU must have AVX ([`avx`] says so).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
pub(super) unsafe fn with_avx<R>(f: impl FnOnce() -> R) -> R {
    f()
}
