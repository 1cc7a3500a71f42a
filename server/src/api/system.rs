//! Health, metrics and the OpenAPI document: unauthenticated (the server listens on
//! loopback unless told otherwise; put a proxy in front to expose them).

use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;
use proto::Health;

use crate::app::{now_ms, AppState};
use crate::db;
use crate::error::Result;
use crate::metrics;

/// `GET /healthz`: 200 while the server answers and its database responds.
pub async fn healthz(State(app): State<AppState>) -> Result<Json<Health>> {
    app.db.run(|c| db::ping(c)).await?;
    Ok(Json(Health {
        status: "ok".into(),
        version: env!("CARGO_PKG_VERSION").into(),
    }))
}

/// `GET /metrics`: Prometheus text format.
pub async fn prometheus(State(app): State<AppState>) -> Result<Response> {
    let now = now_ms();
    let live_since = app.timing().live_since(now);
    let mut snapshot = app
        .db
        .run(move |c| metrics::snapshot(c, now, live_since))
        .await?;
    snapshot.listeners = app.events.listeners();
    let text = app.metrics.render(&snapshot);
    Ok(([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], text).into_response())
}
