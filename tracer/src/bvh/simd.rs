//! Which node test the eight-wide traversal runs: AVX's eight lanes in one register where
//! the CPU has AVX, SSE2's two halves of four elsewhere. A query picks once, at its start,
//! and runs a copy of its whole loop compiled for that choice (the node test must be
//! inlined to pay). Both tests are the same IEEE operations per lane (subtract, multiply,
//! min, max, compare; no fused multiply-add), so a tile has the same bits on either:
//! `allow_avx(false)` turns the AVX path off so that tests can compare the two.

use std::sync::atomic::{AtomicU8, Ordering};

const UNDECIDED: u8 = 0;
const SSE2: u8 = 1;
const AVX: u8 = 2;

static CHOICE: AtomicU8 = AtomicU8::new(UNDECIDED);

/// Whether the CPU has AVX.
fn detected() -> bool {
    #[cfg(target_arch = "x86_64")]
    return std::arch::is_x86_feature_detected!("avx");
    #[cfg(not(target_arch = "x86_64"))]
    return false;
}

/// Whether queries run the AVX node test: the CPU has AVX and [`allow_avx`] has not turned
/// it off.
pub fn avx() -> bool {
    match CHOICE.load(Ordering::Relaxed) {
        UNDECIDED => {
            let avx = detected();
            CHOICE.store(if avx { AVX } else { SSE2 }, Ordering::Relaxed);
            avx
        }
        choice => choice == AVX,
    }
}

/// Turns the AVX node test off (`false`), or on again where the CPU has it, for every
/// query of this process from now on. The image is the same either way; this is for tests
/// and measurements that compare the two.
pub fn allow_avx(allowed: bool) {
    let choice = if allowed && detected() { AVX } else { SSE2 };
    CHOICE.store(choice, Ordering::Relaxed);
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
