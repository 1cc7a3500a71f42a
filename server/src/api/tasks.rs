//! A job's tasks and why their attempts failed: `GET /jobs/{id}/tasks`,
//! `GET /jobs/{id}/failures`.

use axum::extract::State;
use axum::Json;
use proto::{FailureList, TaskList, TaskState};

use super::error::{Id, PathParams, QueryParams};
use crate::app::AppState;
use crate::error::Result;
use crate::limits::MAX_TASKS_PER_PAGE;
use crate::status;

/// The query of `GET /jobs/{id}/tasks`.
#[derive(Clone, Copy, Debug, serde::Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct TaskQuery {
    /// Only tasks in this state.
    state: Option<TaskState>,
    /// Only tasks with ids past this (the previous page's `next_after`).
    #[serde(default, deserialize_with = "proto::deserialize_id")]
    #[param(minimum = 0)]
    after: u64,
    /// Tasks per page, 1 to 1000 (the default).
    #[param(minimum = 1, maximum = 1000)]
    limit: Option<u32>,
}

/// A job's tasks by id, a page at a time, each with its failed attempts and their
/// reasons; `?state=failed` for those out of attempts.
#[utoipa::path(
    get,
    path = "/jobs/{id}/tasks",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id"), TaskQuery),
    responses((status = 200, body = TaskList), (status = 404, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn list(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
    QueryParams(q): QueryParams<TaskQuery>,
) -> Result<Json<TaskList>> {
    let limit = q.limit.unwrap_or(MAX_TASKS_PER_PAGE);
    Ok(Json(
        app.db
            .run(move |c| status::tasks(c, id, q.state, q.after, limit))
            .await?,
    ))
}

/// Why a job's attempts failed, grouped by reason word for word (the worker's error, or
/// an expired lease), the most frequent first, with the workers it happened on.
#[utoipa::path(
    get,
    path = "/jobs/{id}/failures",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id")),
    responses((status = 200, body = FailureList), (status = 404, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn failures(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
) -> Result<Json<FailureList>> {
    Ok(Json(app.db.run(move |c| status::failures(c, id)).await?))
}
