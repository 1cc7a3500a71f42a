//! The event hub: every job, frame and worker change is broadcast to the listeners of
//! `GET /api/v1/events` (the dashboard, `tessera status --watch`; the route is in
//! [`crate::api::events`]).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use tokio::sync::broadcast;
use tokio_stream::wrappers::errors::BroadcastStreamRecvError;
use tokio_stream::wrappers::BroadcastStream;
use tokio_stream::{Stream, StreamExt};

/// Events a slow listener may fall behind by before it misses some (it is told, and
/// should re-read the lists).
const BACKLOG: usize = 1024;

/// The broadcast channel.
pub struct Hub {
    tx: broadcast::Sender<proto::Event>,
    listeners: Arc<AtomicUsize>,
}

impl Default for Hub {
    fn default() -> Self {
        Hub {
            tx: broadcast::channel(BACKLOG).0,
            listeners: Arc::new(AtomicUsize::new(0)),
        }
    }
}

/// Counts a listener for as long as its stream lives.
struct Listening(Arc<AtomicUsize>);

impl Drop for Listening {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

impl Hub {
    /// Sends `event` to every listener (none listening is fine).
    pub fn send(&self, event: proto::Event) {
        let _ = self.tx.send(event);
    }

    /// Whether anyone listens: an event nobody receives need not be built.
    pub fn has_listeners(&self) -> bool {
        self.tx.receiver_count() > 0
    }

    /// A new listener.
    pub fn subscribe(&self) -> broadcast::Receiver<proto::Event> {
        self.tx.subscribe()
    }

    /// A new listener as a stream, counted in [`Hub::listeners`] for as long as it lives:
    /// each event, or how many it missed after falling behind.
    pub fn stream(&self) -> impl Stream<Item = Result<proto::Event, u64>> {
        self.listeners.fetch_add(1, Ordering::Relaxed);
        let listening = Listening(self.listeners.clone());
        BroadcastStream::new(self.subscribe()).map(move |item| {
            let _ = &listening; // dropped with the stream when the listener goes away
            item.map_err(|BroadcastStreamRecvError::Lagged(n)| n)
        })
    }

    /// Open `/events` streams (a gauge in `/metrics`).
    pub fn listeners(&self) -> usize {
        self.listeners.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hub_knows_whether_anyone_listens() {
        let hub = Hub::default();
        assert!(!hub.has_listeners());
        let rx = hub.subscribe();
        assert!(hub.has_listeners());
        drop(rx);
        assert!(!hub.has_listeners());
    }
}
