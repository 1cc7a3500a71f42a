//! The shutdown signal: set once when the caller's shutdown future completes; every wait
//! in the daemon (long poll, backoff sleep, render) also listens to it.

use tokio::sync::watch;

/// A cheap, cloneable view of the shutdown signal.
#[derive(Clone, Debug)]
pub(crate) struct Stop(watch::Receiver<bool>);

impl Stop {
    /// A signal and the sender that sets it.
    pub(crate) fn new() -> (watch::Sender<bool>, Stop) {
        let (tx, rx) = watch::channel(false);
        (tx, Stop(rx))
    }

    /// Whether shutdown has begun.
    pub(crate) fn is_set(&self) -> bool {
        *self.0.borrow()
    }

    /// Completes when shutdown begins (or the sender is gone, which only happens as
    /// [`crate::run`] returns).
    pub(crate) async fn wait(&self) {
        let mut rx = self.0.clone();
        let _ = rx.wait_for(|set| *set).await;
    }
}
