//! Jobs: create, list, get, cancel, pause, resume, retry failed tasks, delete.

use axum::extract::State;
use axum::http::StatusCode;
use axum::Json;
use proto::{JobList, JobSpec, JobStatus, PriorityChange, Rerender};

use super::error::{Id, JsonBody, PathParams};
use crate::app::{now_ms, AppState};
use crate::error::{Error, Result};
use crate::{assembly, controls, db, spec, status, webhooks};

/// Creates a job: the spec is checked field by field and split into tasks.
#[utoipa::path(
    post,
    path = "/jobs",
    tag = "jobs",
    request_body = JobSpec,
    responses(
        (status = 201, body = JobStatus),
        (status = 422, description = "a field is out of bounds; `field` names it", body = proto::ErrorBody),
    ),
    security(("client_token" = []))
)]
pub async fn create(
    State(app): State<AppState>,
    JsonBody(mut spec): JsonBody<JobSpec>,
) -> Result<(StatusCode, Json<JobStatus>)> {
    let (max_tasks, assembly_memory) = (app.config.max_tasks_per_job, app.config.assembly_memory);
    if let Some(url) = &spec.webhook {
        webhooks::check_url("webhook", url)?;
        if app.config.webhook_secret.is_none() {
            return Err(Error::Invalid {
                field: "webhook".into(),
                message: "this server has no webhook secret to sign deliveries with; start it \
                          with --webhook-secret"
                    .into(),
            });
        }
    }
    let now = now_ms();
    let live_since = app.timing().live_since(now);
    let id = app
        .db
        .run(move |c| -> Result<u64> {
            // The digest may be shortened, as the CLI prints it.
            spec.scene = match super::scenes::resolve(c, "scene", &spec.scene) {
                Err(Error::NotFound(message)) => {
                    return Err(Error::Invalid {
                        field: "scene".into(),
                        message,
                    })
                }
                other => other?,
            };
            let scene = db::scenes::info(c, &spec.scene)?
                .ok_or_else(|| Error::Internal(format!("scene {} vanished", spec.scene)))?;
            let plan = spec::plan(spec, &scene, max_tasks)?;
            assembly::check_assembly_memory(&plan.spec, assembly_memory)?;
            controls::submit(c, &plan, now)
        })
        .await?;
    app.work.notify_waiters();
    let status = app
        .db
        .run(move |c| status::job_status(c, id, now, live_since))
        .await?;
    app.events.send(proto::Event::Job {
        job: Box::new(status.clone()),
    });
    Ok((StatusCode::CREATED, Json(status)))
}

/// Every job, newest first.
#[utoipa::path(get, path = "/jobs", tag = "jobs", responses((status = 200, body = JobList)), security(("client_token" = [])))]
pub async fn list(State(app): State<AppState>) -> Result<Json<JobList>> {
    let now = now_ms();
    let live_since = app.timing().live_since(now);
    let jobs = app
        .db
        .run(move |c| status::list_jobs(c, now, live_since))
        .await?;
    Ok(Json(JobList { jobs }))
}

/// One job: tasks by state, frames done, samples per second, ETA.
#[utoipa::path(
    get,
    path = "/jobs/{id}",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id")),
    responses((status = 200, body = JobStatus), (status = 404, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn get(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
) -> Result<Json<JobStatus>> {
    let now = now_ms();
    let live_since = app.timing().live_since(now);
    Ok(Json(
        app.db
            .run(move |c| status::job_status(c, id, now, live_since))
            .await?,
    ))
}

/// Runs a job control, then answers and broadcasts the job's new status.
async fn control(
    app: AppState,
    id: u64,
    f: impl FnOnce(&mut rusqlite::Connection, u64, i64) -> Result<()> + Send + 'static,
) -> Result<Json<JobStatus>> {
    let now = now_ms();
    let live_since = app.timing().live_since(now);
    let status = app
        .db
        .run(move |c| {
            f(c, id, now)?;
            status::job_status(c, id, now, live_since)
        })
        .await?;
    app.work.notify_waiters();
    app.events.send(proto::Event::Job {
        job: Box::new(status.clone()),
    });
    Ok(Json(status))
}

/// Cancels a job: unfinished tasks will not run; workers rendering them hear 409.
#[utoipa::path(
    post,
    path = "/jobs/{id}/cancel",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id")),
    responses((status = 200, body = JobStatus), (status = 404, body = proto::ErrorBody), (status = 409, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn cancel(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
) -> Result<Json<JobStatus>> {
    control(app, id, controls::cancel).await
}

/// Pauses a job: nothing more is leased; workers rendering it hear 409 and the tasks go
/// back to the queue.
#[utoipa::path(
    post,
    path = "/jobs/{id}/pause",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id")),
    responses((status = 200, body = JobStatus), (status = 404, body = proto::ErrorBody), (status = 409, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn pause(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
) -> Result<Json<JobStatus>> {
    control(app, id, controls::pause).await
}

/// Resumes a paused job.
#[utoipa::path(
    post,
    path = "/jobs/{id}/resume",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id")),
    responses((status = 200, body = JobStatus), (status = 404, body = proto::ErrorBody), (status = 409, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn resume(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
) -> Result<Json<JobStatus>> {
    control(app, id, controls::resume).await
}

/// Re-queues a job's failed tasks with fresh attempts, lifts the blocks of workers that
/// failed its tasks, and assembles again the frames whose assembly failed.
#[utoipa::path(
    post,
    path = "/jobs/{id}/retry",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id")),
    responses((status = 200, body = JobStatus), (status = 404, body = proto::ErrorBody), (status = 409, description = "no failed tasks or frames and no blocked workers, or cancelled", body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn retry(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
) -> Result<Json<JobStatus>> {
    control(app, id, |c, id, now| {
        controls::retry(c, id, now).map(|_| ())
    })
    .await
}

/// Renders some of a job's frames again from scratch (after a fix to the workers, or a
/// frame file lost): their tasks are queued again and their files removed; an unchanged
/// tracer gives the same bits. Frames still rendering, and time-budget jobs, are refused.
#[utoipa::path(
    post,
    path = "/jobs/{id}/rerender",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id")),
    request_body = Rerender,
    responses(
        (status = 200, body = JobStatus),
        (status = 404, body = proto::ErrorBody),
        (status = 409, description = "a frame is still rendering, the job is cancelled, or it has a time budget", body = proto::ErrorBody),
        (status = 422, description = "no frames, a frame twice, or a frame the job does not have", body = proto::ErrorBody),
    ),
    security(("client_token" = []))
)]
pub async fn rerender(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
    JsonBody(request): JsonBody<Rerender>,
) -> Result<Json<JobStatus>> {
    let frames = request.frames;
    let store = app.store.clone();
    control(app, id, move |c, id, now| {
        let tasks = controls::rerender(c, id, &frames, now)?;
        // The rows say the frames are not rendered; their old files go while this holds
        // the database, so no worker can have finished them again yet.
        let last = db::jobs::load(c, id)?.spec.frames.map_or(0, |f| f.last());
        for &frame in &frames {
            store.remove_frame(id, frame, last)?;
        }
        store.remove_tiles(id, &tasks.into_iter().collect());
        Ok(())
    })
    .await
}

/// Changes a job's priority (higher runs first): its next tasks are leased by it.
#[utoipa::path(
    post,
    path = "/jobs/{id}/priority",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id")),
    request_body = PriorityChange,
    responses((status = 200, body = JobStatus), (status = 404, body = proto::ErrorBody), (status = 422, description = "the priority is out of bounds", body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn priority(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
    JsonBody(change): JsonBody<PriorityChange>,
) -> Result<Json<JobStatus>> {
    control(app, id, move |c, id, now| {
        controls::set_priority(c, id, change.priority, now)
    })
    .await
}

/// Deletes a job with its outputs.
#[utoipa::path(
    delete,
    path = "/jobs/{id}",
    tag = "jobs",
    params(("id" = u64, Path, description = "job id")),
    responses((status = 204, description = "deleted"), (status = 404, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn delete(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
) -> Result<StatusCode> {
    let now = now_ms();
    app.db
        .run(move |c| controls::delete(c, id, now, "by a client"))
        .await?;
    let store = app.store.clone();
    tokio::task::spawn_blocking(move || store.remove_job(id))
        .await
        .map_err(|e| Error::Internal(format!("removing the files of job {id}: {e}")))??;
    app.events.send(proto::Event::JobDeleted { job_id: id });
    Ok(StatusCode::NO_CONTENT)
}
