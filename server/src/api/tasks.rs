//! A job's tasks, why their attempts failed and what happened: `GET /jobs/{id}/tasks`,
//! `GET /jobs/{id}/failures`, `GET /jobs/{id}/tasks/{task}/log`, `GET /jobs/{id}/log`.

use axum::extract::State;
use axum::Json;
use proto::log::MAX_EVENTS_PER_PAGE;
use proto::{FailureList, JobEventList, TaskList, TaskLog, TaskState};

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

/// The lines the workers logged while they held a task, per attempt (sent with their
/// heartbeats and failure reports; at most 200 lines per attempt are kept).
#[utoipa::path(
    get,
    path = "/jobs/{id}/tasks/{task}/log",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id"), ("task" = u64, Path, description = "task id")),
    responses(
        (status = 200, body = TaskLog),
        (status = 404, description = "no such job, or the job has no such task", body = proto::ErrorBody),
    ),
    security(("client_token" = []))
)]
pub async fn log(
    State(app): State<AppState>,
    PathParams((id, task)): PathParams<(Id, Id)>,
) -> Result<Json<TaskLog>> {
    let (id, task) = (id.0, task.0);
    Ok(Json(
        app.db.run(move |c| status::task_log(c, id, task)).await?,
    ))
}

/// The query of `GET /jobs/{id}/log`.
#[derive(Clone, Copy, Debug, serde::Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct EventQuery {
    /// Only events with ids past this (the previous page's `next_after`).
    #[serde(default, deserialize_with = "proto::deserialize_id")]
    #[param(minimum = 0)]
    after: u64,
    /// Events per page, 1 to 1000 (the default).
    #[param(minimum = 1, maximum = 1000)]
    limit: Option<u32>,
}

/// A job's event log, oldest first, a page at a time: created, paused, resumed, tasks
/// failed or retried, frames assembled, checks, workers blocked.
#[utoipa::path(
    get,
    path = "/jobs/{id}/log",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id"), EventQuery),
    responses((status = 200, body = JobEventList), (status = 404, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn job_log(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
    QueryParams(q): QueryParams<EventQuery>,
) -> Result<Json<JobEventList>> {
    let limit = q.limit.unwrap_or(MAX_EVENTS_PER_PAGE);
    Ok(Json(
        app.db
            .run(move |c| status::job_log(c, id, q.after, limit))
            .await?,
    ))
}
