//! `POST /gc`: retention now, or what it would remove.

use axum::extract::State;
use axum::Json;
use proto::{GcReport, GcRequest};

use super::error::JsonBody;
use crate::app::{now_ms, AppState};
use crate::error::{Error, Result};
use crate::retention::{self, KeepJobs};

/// Removes finished jobs past the server's `--keep-jobs` (or the rule given) with their
/// files, scenes no job uses a day after their last upload, and events of jobs that are
/// gone or past the log's bound; with `dry_run`, only says what would go. Jobs with work
/// left are never touched.
#[utoipa::path(
    post,
    path = "/gc",
    tag = "system",
    request_body = GcRequest,
    responses(
        (status = 200, body = GcReport),
        (status = 422, description = "keep_jobs is not a count or an age", body = proto::ErrorBody),
    ),
    security(("client_token" = []))
)]
pub async fn collect(
    State(app): State<AppState>,
    JsonBody(request): JsonBody<GcRequest>,
) -> Result<Json<GcReport>> {
    let keep = match &request.keep_jobs {
        None => app.config.keep_jobs,
        Some(rule) => rule.parse::<KeepJobs>().map_err(|message| Error::Invalid {
            field: "keep_jobs".into(),
            message,
        })?,
    };
    let a = app.clone();
    let report = tokio::task::spawn_blocking(move || {
        retention::collect(&a, keep, request.dry_run, now_ms())
    })
    .await
    .map_err(|e| Error::Internal(format!("retention panicked: {e}")))??;
    Ok(Json(report))
}
