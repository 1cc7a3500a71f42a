//! Server-sent events: every job, frame and worker change is broadcast to the listeners of
//! `GET /api/v1/events` (the dashboard, `tessera status --watch`).

use std::convert::Infallible;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use axum::extract::State;
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use tokio::sync::broadcast;
use tokio_stream::wrappers::errors::BroadcastStreamRecvError;
use tokio_stream::wrappers::BroadcastStream;
use tokio_stream::{Stream, StreamExt};

use crate::app::AppState;

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

    /// Open `/events` streams (a gauge in `/metrics`).
    pub fn listeners(&self) -> usize {
        self.listeners.load(Ordering::Relaxed)
    }
}

/// The SSE stream: event name = the event's `type`, data = its JSON. A listener that fell
/// behind gets a `lagged` event with the number missed.
#[utoipa::path(
    get,
    path = "/events",
    tag = "events",
    responses((status = 200, description = "text/event-stream of `Event` JSON", body = proto::Event, content_type = "text/event-stream")),
    security(("client_token" = []))
)]
pub async fn events(
    State(app): State<AppState>,
) -> Sse<impl Stream<Item = Result<SseEvent, Infallible>>> {
    app.events.listeners.fetch_add(1, Ordering::Relaxed);
    let listening = Listening(app.events.listeners.clone());
    let stream = BroadcastStream::new(app.events.subscribe()).map(move |item| {
        let _ = &listening; // dropped with the stream when the client goes away
        Ok(match item {
            Ok(event) => SseEvent::default()
                .event(event.name())
                .data(serde_json::to_string(&event).unwrap_or_default()),
            Err(BroadcastStreamRecvError::Lagged(n)) => {
                SseEvent::default().event("lagged").data(n.to_string())
            }
        })
    });
    Sse::new(stream).keep_alive(KeepAlive::new().interval(Duration::from_secs(15)))
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
