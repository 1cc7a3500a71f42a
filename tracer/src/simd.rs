//! Which compiled copy of the hot loops runs: one built for AVX where the CPU has it, the
//! baseline (SSE2) one elsewhere.
//!
//! - A BVH query picks once, at its start, and runs a copy of its whole loop compiled for
//!   that choice: the eight-wide node test in AVX's eight lanes in one register, or in
//!   SSE2's two halves of four (the node test must be inlined to pay).
//! - A pixel's run of camera samples ([`crate::integrator::trace_samples`]) likewise: AVX's
//!   three-operand instructions spare the register copies of SSE2's two-operand ones.
//!   Its AVX copy calls the AVX queries (`PreparedFrame::query_avx`) straight away, with
//!   no second choice per ray.
//!
//! Both copies are the same IEEE operations (Rust never fuses a multiply and an add on its
//! own, and nothing here asks for it), so a tile has the same bits on either:
//! `allow_avx(false)` turns the AVX copies off so that tests can compare the two.

use std::sync::atomic::{AtomicBool, Ordering};

/// Set by [`allow_avx`]`(false)`.
static AVX_OFF: AtomicBool = AtomicBool::new(false);

/// Whether the AVX copies run: the CPU has AVX and [`allow_avx`] has not turned them off.
pub fn avx() -> bool {
    // (std caches the CPU's features after the first call.)
    #[cfg(target_arch = "x86_64")]
    return !AVX_OFF.load(Ordering::Relaxed) && std::arch::is_x86_feature_detected!("avx");
    #[cfg(not(target_arch = "x86_64"))]
    return false;
}

/// Turns the AVX copies off (`false`), or on again where the CPU has AVX, for every query
/// and camera sample of this process from now on. The image is the same either way; this
/// is for tests and measurements that compare the two.
pub fn allow_avx(allowed: bool) {
    AVX_OFF.store(!allowed, Ordering::Relaxed);
}

/// Runs `f` compiled for AVX: what it inlines (a query's loop) may use AVX instructions.
/// (The path loop has its own AVX function, `integrator::trace_samples_avx`: run through
/// this, its closure was left out of line, compiled for the baseline.)
///
/// # Safety
/// The CPU must have AVX ([`avx`] says so).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
pub(crate) unsafe fn with_avx<R>(f: impl FnOnce() -> R) -> R {
    f()
}
