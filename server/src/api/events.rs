//! `GET /events`: the event hub ([`crate::events`]) as server-sent events.

use std::convert::Infallible;
use std::time::Duration;

use axum::extract::State;
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use tokio_stream::{Stream, StreamExt};

use crate::app::AppState;

/// How often an idle stream gets a comment, so proxies keep it open.
const KEEP_ALIVE: Duration = Duration::from_secs(15);

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
    let stream = app.events.stream().map(|item| {
        Ok(match item {
            Ok(event) => SseEvent::default()
                .event(event.name())
                .data(serde_json::to_string(&event).unwrap_or_default()),
            Err(missed) => SseEvent::default().event("lagged").data(missed.to_string()),
        })
    });
    Sse::new(stream).keep_alive(KeepAlive::new().interval(KEEP_ALIVE))
}
