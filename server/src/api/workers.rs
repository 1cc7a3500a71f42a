//! Workers: register, list, long-poll lease, heartbeat, upload a result, report a failure.

use std::time::{Duration, Instant};

use axum::body::Body;
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use proto::{
    FailureAck, FailureReport, Heartbeat, HeartbeatAck, Lease, LeaseRequest, ResultAck,
    ResultMetadata, TaskKind, TaskToken, WorkerLeft, WorkerList, WorkerRegistered,
    WorkerRegistration,
};

use super::error::{read_body, Id, JsonBody, PathParams, QueryParams};
use crate::app::{now_ms, AppState};
use crate::error::{Error, Result};
use crate::limits::{
    GONE_WORKER_LISTED_MS, MAX_FAILURE_MESSAGE_BYTES, MAX_STEP_MS_PER_MEGAPIXEL,
    MAX_WORKER_TEXT_BYTES,
};
use crate::{db, denoising, encoding, identity, intake, scheduler, verify};

/// Registers a worker with the join token (the server's worker token); the answer carries
/// its id, its own credential for every later call, and the timing it must keep. A worker
/// that presents the credential of an earlier registration, or the name of a worker that
/// is gone, is that worker again (200): its quarantine and job blocks stay. A name that a
/// live worker holds is refused (409).
#[utoipa::path(
    post,
    path = "/workers",
    tag = "workers",
    request_body = WorkerRegistration,
    responses(
        (status = 201, description = "a new worker", body = WorkerRegistered),
        (status = 200, description = "an earlier worker, back", body = WorkerRegistered),
        (status = 409, description = "a live worker has this name", body = proto::ErrorBody),
        (status = 422, body = proto::ErrorBody),
    ),
    security(("worker_token" = []))
)]
pub async fn register(
    State(app): State<AppState>,
    JsonBody(reg): JsonBody<WorkerRegistration>,
) -> Result<(StatusCode, Json<WorkerRegistered>)> {
    let platform = reg.platform.iter().map(|p| ("platform", p));
    let denoiser = reg.denoiser.iter().map(|d| ("denoiser", d));
    let encoder = reg.encoder.iter().map(|e| ("encoder", e));
    for (field, value) in [("name", &reg.name), ("version", &reg.version)]
        .into_iter()
        .chain(platform)
        .chain(denoiser)
        .chain(encoder)
    {
        if value.is_empty() || value.len() > MAX_WORKER_TEXT_BYTES {
            return Err(Error::Invalid {
                field: field.into(),
                message: format!(
                    "must be 1 to {MAX_WORKER_TEXT_BYTES} bytes, got {}",
                    value.len()
                ),
            });
        }
    }
    crate::spec::check_tags("tags", &reg.tags)?;
    if reg.threads == 0 || reg.threads > 4096 {
        return Err(Error::Invalid {
            field: "threads".into(),
            message: format!("must be 1 to 4096, got {}", reg.threads),
        });
    }
    let steps = [
        ("denoise_ms_per_megapixel", reg.denoise_ms_per_megapixel),
        ("encode_ms_per_megapixel", reg.encode_ms_per_megapixel),
    ];
    for (field, ms) in steps {
        if let Some(ms) = ms.filter(|&ms| ms > MAX_STEP_MS_PER_MEGAPIXEL) {
            return Err(Error::Invalid {
                field: field.into(),
                message: format!("must be at most {MAX_STEP_MS_PER_MEGAPIXEL}, got {ms}"),
            });
        }
    }
    let (now, timing) = (now_ms(), app.timing());
    let who = format!(
        "`{}` ({} threads, version {})",
        reg.name, reg.threads, reg.version
    );
    let joined = app
        .db
        .run(move |c| {
            let joining = identity::Joining {
                profile: db::workers::Profile {
                    name: &reg.name,
                    threads: reg.threads,
                    version: &reg.version,
                    platform: reg.platform.as_deref(),
                    tags: &reg.tags,
                    denoiser: reg.denoiser.as_deref(),
                    encoder: reg.encoder.as_deref(),
                    step_ms_per_mp: [reg.denoise_ms_per_megapixel, reg.encode_ms_per_megapixel],
                },
                credential: reg.credential.as_deref(),
            };
            identity::join(c, &joining, now, timing.live_since(now))
        })
        .await?;
    let id = joined.id;
    let status = if joined.returned {
        tracing::info!(worker = id, "worker {id} is back: {who}");
        // Its leases went back to the queue.
        app.work.notify_waiters();
        StatusCode::OK
    } else {
        tracing::info!(worker = id, "worker {id} registered: {who}");
        StatusCode::CREATED
    };
    app.publish_worker(id).await;
    Ok((
        status,
        Json(WorkerRegistered {
            worker_id: id,
            credential: joined.credential,
            lease_seconds: app.config.lease.as_secs(),
            heartbeat_seconds: app.config.heartbeat_interval().as_secs(),
            max_wait_seconds: app.config.max_lease_wait.as_secs(),
        }),
    ))
}

/// The query of `GET /workers`.
#[derive(Clone, Copy, Debug, Default, serde::Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct WorkerQuery {
    /// Also the workers gone for more than a day (their rows stay for the jobs' records).
    #[serde(default)]
    all: bool,
}

/// The workers seen within a day (every one with `?all=true`): name, threads, version,
/// current task, last seen.
#[utoipa::path(
    get,
    path = "/workers",
    tag = "workers",
    params(WorkerQuery),
    responses((status = 200, body = WorkerList)),
    security(("client_token" = []))
)]
pub async fn list(
    State(app): State<AppState>,
    QueryParams(q): QueryParams<WorkerQuery>,
) -> Result<Json<WorkerList>> {
    let now = now_ms();
    let live_since = app.timing().live_since(now);
    let listed_since = if q.all {
        0
    } else {
        now - GONE_WORKER_LISTED_MS
    };
    Ok(Json(
        app.db
            .run(move |c| db::workers::list(c, now, live_since, listed_since))
            .await?,
    ))
}

/// Asks for a task, waiting up to `wait_seconds` (capped by the server) for one:
/// 200 with a lease, or 204 when there is no work.
#[utoipa::path(
    post,
    path = "/workers/{id}/lease",
    tag = "workers",
    params(("id" = u64, Path, description = "worker id")),
    request_body = LeaseRequest,
    responses((status = 200, body = Lease), (status = 204, description = "no work now; ask again"), (status = 404, body = proto::ErrorBody)),
    security(("worker_credential" = []))
)]
pub async fn lease(
    State(app): State<AppState>,
    PathParams(Id(worker)): PathParams<Id>,
    JsonBody(req): JsonBody<LeaseRequest>,
) -> Result<Response> {
    let started = Instant::now();
    // Kept with the first look for work, in its transaction.
    let mut late = req.last_task_log;
    let wait = Duration::from_secs(req.wait_seconds).min(app.config.max_lease_wait);
    let deadline = tokio::time::Instant::now() + wait;
    loop {
        // Listen before looking, so work that appears in between is not missed.
        let notified = app.work.notified();
        tokio::pin!(notified);
        notified.as_mut().enable();
        let (now, timing) = (now_ms(), app.timing());
        // If the worker hangs up while this runs, the lease is granted but never seen; it
        // expires after one lease period and the task is leased again.
        let late = late.take();
        let lease = app
            .db
            .run(move |c| scheduler::lease_keeping(c, worker, late.as_ref(), now, timing))
            .await?;
        if let Some(lease) = lease {
            app.metrics.lease_granted(started.elapsed().as_secs_f64());
            app.publish_worker(worker).await;
            app.publish_job(lease.job_id).await;
            return Ok(Json(lease).into_response());
        }
        if tokio::time::timeout_at(deadline, notified).await.is_err() {
            return Ok(StatusCode::NO_CONTENT.into_response());
        }
    }
}

/// Extends a lease and keeps the lines the worker logged for it since the last beat (or,
/// without a token, says the worker is alive). 409 means the lease
/// is gone — the job was paused or cancelled, or the lease expired: stop rendering.
#[utoipa::path(
    post,
    path = "/workers/{id}/heartbeat",
    tag = "workers",
    params(("id" = u64, Path, description = "worker id")),
    request_body = Heartbeat,
    responses((status = 200, body = HeartbeatAck), (status = 409, description = "lease gone: stop", body = proto::ErrorBody)),
    security(("worker_credential" = []))
)]
#[tracing::instrument(
    name = "task",
    skip_all,
    fields(id = hb.token.map(|t| t.task_id), worker = worker)
)]
pub async fn heartbeat(
    State(app): State<AppState>,
    PathParams(Id(worker)): PathParams<Id>,
    JsonBody(hb): JsonBody<Heartbeat>,
) -> Result<Json<HeartbeatAck>> {
    let (now, timing) = (now_ms(), app.timing());
    let deadline = app
        .db
        .run(move |c| scheduler::heartbeat(c, worker, hb.token, &hb.log, now, timing))
        .await?;
    Ok(Json(HeartbeatAck {
        deadline_ms: deadline,
    }))
}

/// A worker shuts down: the leases it holds are queued again at once (no attempt is
/// counted), and its id takes no more calls.
#[utoipa::path(
    post,
    path = "/workers/{id}/leave",
    tag = "workers",
    params(("id" = u64, Path, description = "worker id")),
    responses((status = 200, body = WorkerLeft), (status = 404, body = proto::ErrorBody)),
    security(("worker_credential" = []))
)]
pub async fn leave(
    State(app): State<AppState>,
    PathParams(Id(worker)): PathParams<Id>,
) -> Result<Json<WorkerLeft>> {
    let now = now_ms();
    let jobs = app
        .db
        .run(move |c| scheduler::leave(c, worker, now))
        .await?;
    // Operators see scale-downs and restarts in the log, not only in the event table.
    tracing::info!(
        worker,
        "worker {worker} left; leases given back for jobs {jobs:?}"
    );
    app.work.notify_waiters();
    for &job in &jobs {
        app.publish_job(job).await;
    }
    app.publish_worker(worker).await;
    Ok(Json(WorkerLeft { jobs }))
}

/// Uploads a rendered tile: the body is the EXR, the `x-tessera-*` headers carry the
/// attempt, SHA-256, samples, rays and render time. A second upload for a finished task
/// is answered 200 with `accepted: false` and ignored.
#[utoipa::path(
    post,
    path = "/workers/{id}/tasks/{task}/result",
    tag = "workers",
    params(
        ("id" = u64, Path, description = "worker id"),
        ("task" = u64, Path, description = "task id"),
        ("x-tessera-attempt" = u32, Header, description = "the lease's attempt"),
        ("x-tessera-sha256" = String, Header, description = "hex SHA-256 of the body"),
        ("x-tessera-samples" = u32, Header, description = "samples per pixel rendered"),
        ("x-tessera-rays" = u64, Header, description = "rays traced"),
        ("x-tessera-render-ms" = u64, Header, description = "render time on the worker"),
    ),
    request_body(content = Vec<u8>, content_type = "image/x-exr", description = "the tile"),
    responses(
        (status = 200, body = ResultAck),
        (status = 409, description = "lease gone: drop the tile", body = proto::ErrorBody),
        (status = 413, body = proto::ErrorBody),
        (status = 422, description = "the tile is refused; the message says why", body = proto::ErrorBody),
        (status = 503, description = "the data folder is read-only: nothing stored, send it again later", body = proto::ErrorBody),
        (status = 507, description = "the server's disk is full: nothing stored, send it again later", body = proto::ErrorBody),
    ),
    security(("worker_credential" = []))
)]
#[tracing::instrument(name = "task", skip_all, fields(id = task.0, worker = worker.0))]
pub async fn result(
    State(app): State<AppState>,
    PathParams((worker, task)): PathParams<(Id, Id)>,
    headers: HeaderMap,
    body: Body,
) -> Result<Json<ResultAck>> {
    let (worker, task) = (worker.0, task.0);
    let started = Instant::now();
    let meta = ResultMetadata::from_headers(|name| headers.get(name).and_then(|v| v.to_str().ok()))
        .map_err(|(field, message)| Error::Invalid {
            field: field.into(),
            message,
        })?;
    // A denoise task uploads its whole frame: its limit is the frame's size.
    let limit = app
        .db
        .run(move |c| db::tasks::upload_limit(c, task))
        .await?
        .map_or(app.config.max_tile_bytes, |frame| {
            frame.max(app.config.max_tile_bytes)
        });
    let bytes = read_body(body, limit, "tile").await?;
    let token = TaskToken {
        task_id: task,
        attempt: meta.attempt,
    };
    let (a, span) = (app.clone(), tracing::Span::current());
    let received = tokio::task::spawn_blocking(move || {
        span.in_scope(|| intake::receive(&a, worker, token, &meta, &bytes))
    })
    .await
    .map_err(|e| Error::Internal(format!("tile intake panicked: {e}")))??;
    app.metrics.upload_taken(started.elapsed().as_secs_f64());
    if received.accepted {
        app.publish_frame(received.job, received.frame).await;
        app.publish_job(received.job).await;
        app.publish_worker(worker).await;
    }
    Ok(Json(ResultAck {
        accepted: received.accepted,
        frame_done: received.frame_done,
    }))
}

/// The query of `GET /workers/{id}/tasks/{task}/frame`.
#[derive(Clone, Copy, Debug, serde::Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct FrameQuery {
    /// The lease's attempt.
    attempt: u32,
    /// For an encode lease, the frame whose PNG to read (one of its `sequence`).
    #[serde(default)]
    frame: Option<i32>,
}

/// What a step after rendering reads: for a denoise lease the assembled EXR of its frame,
/// for an encode lease the PNG of `frame`. The lease must be current.
#[utoipa::path(
    get,
    path = "/workers/{id}/tasks/{task}/frame",
    tag = "workers",
    params(
        ("id" = u64, Path, description = "worker id"),
        ("task" = u64, Path, description = "task id"),
        FrameQuery,
    ),
    responses(
        (status = 200, content_type = "image/x-exr", body = Vec<u8>),
        (status = 409, description = "lease gone", body = proto::ErrorBody),
        (status = 422, description = "the task renders a tile, or the frame is not the task's", body = proto::ErrorBody),
    ),
    security(("worker_credential" = []))
)]
#[tracing::instrument(name = "task", skip_all, fields(id = task.0, worker = worker.0))]
pub async fn frame(
    State(app): State<AppState>,
    PathParams((worker, task)): PathParams<(Id, Id)>,
    QueryParams(q): QueryParams<FrameQuery>,
) -> Result<Response> {
    let token = TaskToken {
        task_id: task.0,
        attempt: q.attempt,
    };
    let a = app.clone();
    let (path, content_type) = tokio::task::spawn_blocking(move || {
        let (task, spec) = a.db.with(|c| -> Result<_> {
            let task = scheduler::check_token(c, worker.0, token)?;
            let spec = db::jobs::spec(c, task.job_id)?;
            Ok((task, spec))
        })?;
        let wrong = |message: String| Error::Invalid {
            field: "frame".into(),
            message,
        };
        match (task.kind, q.frame) {
            (TaskKind::Denoise, None) => {
                Ok((denoising::frame_exr(&a, &task, &spec), "image/x-exr"))
            }
            (TaskKind::Denoise, Some(f)) if f == task.frame => {
                Ok((denoising::frame_exr(&a, &task, &spec), "image/x-exr"))
            }
            (TaskKind::Denoise, Some(f)) => Err(wrong(format!(
                "task {} denoises frame {}, not frame {f}",
                task.id, task.frame
            ))),
            (TaskKind::Encode, Some(f)) => {
                Ok((encoding::frame_png_for(&a, &task, &spec, f)?, "image/png"))
            }
            (TaskKind::Encode, None) => Err(wrong(format!(
                "task {} encodes the job's frames: name one with ?frame=",
                task.id
            ))),
            (TaskKind::Render, _) => Err(wrong(format!(
                "task {} renders a tile: it has no frame to read",
                task.id
            ))),
        }
    })
    .await
    .map_err(|e| Error::Internal(format!("finding the frame panicked: {e}")))??;
    let bytes = tokio::fs::read(&path).await?;
    Ok(([(axum::http::header::CONTENT_TYPE, content_type)], bytes).into_response())
}

/// Reports that a lease could not be rendered: the task goes back to the queue (or fails
/// past its job's max attempts).
#[utoipa::path(
    post,
    path = "/workers/{id}/tasks/{task}/failure",
    tag = "workers",
    params(("id" = u64, Path, description = "worker id"), ("task" = u64, Path, description = "task id")),
    request_body = FailureReport,
    responses((status = 200, body = FailureAck), (status = 409, description = "lease gone", body = proto::ErrorBody)),
    security(("worker_credential" = []))
)]
#[tracing::instrument(
    name = "task",
    skip_all,
    fields(id = task.0, worker = worker.0, attempt = report.attempt)
)]
pub async fn failure(
    State(app): State<AppState>,
    PathParams((worker, task)): PathParams<(Id, Id)>,
    JsonBody(report): JsonBody<FailureReport>,
) -> Result<Json<FailureAck>> {
    let (worker, task) = (worker.0, task.0);
    let mut message = report.message;
    proto::log::truncate_at_char(&mut message, MAX_FAILURE_MESSAGE_BYTES);
    tracing::warn!("worker {worker} failed task {task}: {message}");
    let token = TaskToken {
        task_id: task,
        attempt: report.attempt,
    };
    let (now, timing) = (now_ms(), app.timing());
    let (job, ack) = app
        .db
        .run(move |c| scheduler::fail(c, worker, token, &message, &report.log, now, timing))
        .await?;
    app.work.notify_waiters();
    app.publish_job(job).await;
    app.publish_worker(worker).await;
    Ok(Json(ack))
}

/// An operator clears a worker that checks found computing wrong pixels (once its machine
/// is repaired): it is no longer quarantined and gets work again.
#[utoipa::path(
    post,
    path = "/workers/{id}/clear",
    tag = "workers",
    params(("id" = u64, Path, description = "worker id")),
    responses((status = 200, body = proto::WorkerInfo), (status = 404, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn clear(
    State(app): State<AppState>,
    PathParams(Id(worker)): PathParams<Id>,
) -> Result<Json<proto::WorkerInfo>> {
    let now = now_ms();
    let live_since = app.timing().live_since(now);
    let info = app
        .db
        .run(move |c| {
            verify::clear(c, worker, now)?;
            db::workers::info(c, worker, now, live_since)
        })
        .await?;
    app.work.notify_waiters();
    app.publish_worker(worker).await;
    Ok(Json(info))
}
