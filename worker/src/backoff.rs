//! How long to wait before trying again: exponential backoff with jitter, so that a farm
//! of workers that lost the server together does not hammer it in lockstep when it
//! returns (Flamenco's worker waits the same way, "so that Workers don't sync up").

use std::collections::hash_map::RandomState;
use std::hash::{BuildHasher, Hasher};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The first retry waits about this long.
pub const RETRY_FIRST: Duration = Duration::from_millis(500);
/// Retries never wait longer than about this.
pub const RETRY_MAX: Duration = Duration::from_secs(30);
/// After a lease request answered "no work" faster than this (a server whose long poll
/// is short or off), wait about this long before asking again, so an idle worker does
/// not spin.
pub const IDLE_PAUSE: Duration = Duration::from_secs(1);

/// Delays that double from [`RETRY_FIRST`] up to [`RETRY_MAX`], each jittered.
#[derive(Clone, Debug)]
pub struct Backoff {
    next: Duration,
    failures: u32,
}

impl Default for Backoff {
    fn default() -> Self {
        Self::new()
    }
}

impl Backoff {
    /// A backoff at its first delay.
    pub fn new() -> Self {
        Backoff {
            next: RETRY_FIRST,
            failures: 0,
        }
    }

    /// The delay before the next try (jittered), and doubles the one after.
    pub fn next_delay(&mut self) -> Duration {
        let base = self.next;
        self.next = (self.next * 2).min(RETRY_MAX);
        self.failures += 1;
        jitter(base)
    }

    /// Tries that failed since the last [`Backoff::reset`].
    pub fn failures(&self) -> u32 {
        self.failures
    }

    /// Back to the first delay, after a success.
    pub fn reset(&mut self) {
        *self = Backoff::new();
    }
}

/// `base` scaled by a random factor in [0.75, 1.25).
pub fn jitter(base: Duration) -> Duration {
    base.mul_f64(0.75 + 0.5 * random_unit())
}

/// A random number in [0, 1). Not for cryptography: std's `RandomState` has random keys
/// per process (and new ones per call), mixed with a counter and the clock; that is
/// enough to keep workers apart without a dependency for randomness.
fn random_unit() -> f64 {
    static CALLS: AtomicU64 = AtomicU64::new(0);
    let mut h = RandomState::new().build_hasher();
    h.write_u64(CALLS.fetch_add(1, Ordering::Relaxed));
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    h.write_u128(nanos);
    (h.finish() >> 11) as f64 / (1u64 << 53) as f64
}

/// A duration for a log line: `0.5 s`, `4 s`, `30 s`.
pub fn seconds(d: Duration) -> String {
    let s = d.as_secs_f64();
    if s < 9.95 && (s * 10.0).round() % 10.0 != 0.0 {
        format!("{s:.1} s")
    } else {
        format!("{s:.0} s")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delays_double_up_to_the_cap_within_the_jitter() {
        let mut b = Backoff::new();
        let mut base = RETRY_FIRST;
        for _ in 0..12 {
            let d = b.next_delay();
            assert!(
                d >= base.mul_f64(0.75) && d < base.mul_f64(1.25),
                "{d:?} vs {base:?}"
            );
            base = (base * 2).min(RETRY_MAX);
        }
        assert_eq!(b.failures(), 12);
        b.reset();
        assert!(b.next_delay() < RETRY_FIRST.mul_f64(1.25));
    }

    #[test]
    fn jitter_spreads_the_delays() {
        let delays: Vec<Duration> = (0..32).map(|_| jitter(Duration::from_secs(4))).collect();
        let distinct = delays
            .iter()
            .collect::<std::collections::BTreeSet<_>>()
            .len();
        assert!(distinct > 16, "{delays:?}");
    }

    #[test]
    fn seconds_read_well() {
        assert_eq!(seconds(Duration::from_millis(500)), "0.5 s");
        assert_eq!(seconds(Duration::from_millis(4000)), "4 s");
        assert_eq!(seconds(Duration::from_millis(1500)), "1.5 s");
        assert_eq!(seconds(Duration::from_secs(30)), "30 s");
        assert_eq!(seconds(Duration::from_millis(12_400)), "12 s");
    }
}
