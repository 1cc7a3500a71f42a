//! Tessera's farm server: REST API, scheduler, persistence, tile assembly, live progress.
//! It uses the tracer only to validate scenes, check tiles and write frames and previews.
//!
//! | module | what it holds |
//! |---|---|
//! | [`config`] | settings: listen address, data folder, tokens, lease timing, limits |
//! | [`limits`] | every bound the server enforces, with its value |
//! | [`db`] | every SQL statement: one file per table, the versioned schema, SQLite (WAL) off the async runtime |
//! | [`store`] | files beside the database: scenes by SHA-256, tiles, job outputs |
//! | [`state`] | the task and job state machines: one transition table each |
//! | [`scheduler`] | leases, heartbeats, uploads accepted, failures, expiry: one transaction each |
//! | [`controls`] | job controls: submit, pause, resume, cancel, retry, rerender, priority, delete |
//! | [`retention`] | finished jobs past `--keep-jobs`, unused scenes, old events: removed |
//! | [`spec`] | job-spec checks (each error names its field) and the split into tasks |
//! | [`budget`] | time-budget jobs: the farm's measured speed decides which passes fit |
//! | [`scene`] | scene uploads checked with the tracer's loader and summarised |
//! | [`intake`], [`assembly`] | tile uploads checked and accepted; frames assembled |
//! | [`denoising`] | a frame's denoise task: queued once assembled, its upload written in as the `denoised` layer |
//! | [`encoding`] | a job's encode task: queued once every frame is finished, its MP4 kept beside the frames |
//! | [`status`] | a job's status: state, progress, speed, ETA |
//! | [`events`], [`metrics`] | the event hub; Prometheus metrics |
//! | [`verify`] | bit-for-bit checks of tiles on a second worker; quarantine |
//! | [`auth`] | client and join tokens, each worker's own credential |
//! | [`identity`] | workers joining: new, or an earlier one back by credential or name |
//! | [`tls`] | HTTPS from a certificate and key, handshakes off the accept loop |
//! | [`api`] | the HTTP routes, one file per resource, and the OpenAPI document |
//! | [`webhooks`] | signed notifications of jobs ending and workers quarantined |
//! | [`dashboard`] | the web page at `/` |
//!
//! A binary (or a test) calls [`serve`] with a bound listener and a shutdown future.

pub mod api;
pub mod app;
pub mod assembly;
pub mod auth;
pub mod budget;
pub mod config;
pub mod controls;
pub mod dashboard;
pub mod db;
pub mod denoising;
pub mod encoding;
pub mod error;
pub mod events;
#[cfg(test)]
mod farm_tests;
pub mod identity;
pub mod intake;
pub mod limits;
pub mod metrics;
pub mod retention;
pub mod scene;
pub mod scheduler;
pub mod spec;
pub mod state;
pub mod status;
pub mod store;
#[cfg(feature = "test-server")]
pub mod testing;
pub mod tls;
pub mod verify;
pub mod webhooks;

use std::future::Future;
use std::sync::Arc;

use axum::routing::get;
use axum::Router;
use tokio::net::TcpListener;
use tower_http::request_id::{
    MakeRequestUuid, PropagateRequestIdLayer, RequestId, SetRequestIdLayer,
};
use tower_http::trace::TraceLayer;

pub use config::Config;

use app::{now_ms, App, AppState};

/// Why the server could not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// The data folder could not be created or read.
    #[error("data folder {path}: {source}")]
    DataDir {
        /// The folder.
        path: String,
        /// What the OS said.
        #[source]
        source: std::io::Error,
    },
    /// The database could not be opened or migrated.
    #[error(transparent)]
    Database(#[from] db::OpenError),
    /// Recovering after a restart failed.
    #[error("recovering the previous run's state: {0}")]
    Recovery(#[from] error::Error),
    /// Serving failed.
    #[error("serving: {0}")]
    Serve(#[source] std::io::Error),
    /// The TLS certificate or key could not be used.
    #[error("{0}")]
    Tls(String),
    /// The address is reachable from the network and a role's routes would be open
    /// ([`Config::check_exposure`]).
    #[error("{0}")]
    Exposed(String),
}

/// Opens the data folder and the database, and recovers from the previous run: temp files
/// of writes it cut short are removed, leases that were live are re-queued (their
/// workers hear 409 and stop). Frames whose tiles
/// were all in but not yet assembled are left to the sweeper, which starts once the
/// server listens: a big frame takes minutes, and the API must be there meanwhile (to
/// cancel or delete its job, say).
pub fn open(config: Config) -> Result<AppState, StartError> {
    let store = store::Store::open(&config.data_dir).map_err(|source| StartError::DataDir {
        path: config.data_dir.display().to_string(),
        source,
    })?;
    let removed = store
        .remove_temp_files()
        .map_err(|source| StartError::DataDir {
            path: config.data_dir.display().to_string(),
            source,
        })?;
    if removed > 0 {
        tracing::info!("removed {removed} temp files of writes cut short by the last stop");
    }
    let db = db::Db::open(&store.database())?;
    let renamed = db.with(|c| {
        store.name_tiles_by_attempt(|task| Ok(db::tasks::load(c, task)?.map(|t| t.attempt)))
    })?;
    if renamed > 0 {
        tracing::info!("named {renamed} tiles by their accepted attempt");
    }
    let app = Arc::new(App {
        config,
        db,
        store,
        events: events::Hub::default(),
        metrics: metrics::Metrics::default(),
        work: tokio::sync::Notify::new(),
        assembly: std::sync::Mutex::new(()),
        webhooks: webhooks::Webhooks::default(),
    });
    let now = now_ms();
    let revoked = app.db.with(|c| scheduler::revoke_all_leases(c, now))?;
    if revoked > 0 {
        tracing::info!("re-queued {revoked} leases from before the restart");
    }
    Ok(app)
}

/// The whole HTTP service: API, OpenAPI document, health, metrics, dashboard.
pub fn router(app: AppState) -> Router {
    let (api, openapi) = api::api(app.clone());
    let openapi = Arc::new(openapi);
    Router::new()
        .merge(api)
        .route(
            &format!("{}/openapi.json", proto::API_PREFIX),
            get(move || {
                let doc = openapi.clone();
                async move { axum::Json(doc.as_ref().clone()) }
            }),
        )
        .route("/healthz", get(api::system::healthz))
        .route("/metrics", get(api::system::prometheus))
        .merge(dashboard::routes())
        // Outermost first: give the request an id (a caller's own `x-request-id` is kept),
        // log everything its handling logs inside a span that carries it, and return it.
        .layer(PropagateRequestIdLayer::x_request_id())
        .layer(TraceLayer::new_for_http().make_span_with(request_span))
        .layer(SetRequestIdLayer::x_request_id(MakeRequestUuid))
        .with_state(app)
}

/// The span of one request: its id, method and path. Not the query: a browser's
/// `access_token` travels there.
fn request_span(req: &axum::http::Request<axum::body::Body>) -> tracing::Span {
    let id = req
        .extensions()
        .get::<RequestId>()
        .and_then(|id| id.header_value().to_str().ok())
        .unwrap_or_default();
    tracing::info_span!(
        "request",
        request_id = id,
        method = %req.method(),
        path = req.uri().path()
    )
}

/// The OpenAPI document the server serves at `/api/v1/openapi.json`.
pub fn openapi() -> utoipa::openapi::OpenApi {
    let config = Config::new(std::env::temp_dir());
    // Building the router needs a state only for its type; the document does not use it.
    let app = Arc::new(App {
        db: db::Db::in_memory(),
        store: store::Store::unopened(&config.data_dir),
        config,
        events: events::Hub::default(),
        metrics: metrics::Metrics::default(),
        work: tokio::sync::Notify::new(),
        assembly: std::sync::Mutex::new(()),
        webhooks: webhooks::Webhooks::default(),
    });
    api::api(app).1
}

/// At once and then every `sweep_interval`: re-queues expired leases, plans time-budget
/// jobs again (the workers may have changed), and assembles frames whose tiles are all in
/// but which are not assembled: left by a restart, or whose assembly met a full disk when
/// their last tile came.
async fn sweep(app: AppState) {
    let mut tick = tokio::time::interval(app.config.sweep_interval);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last_gc: Option<std::time::Instant> = None;
    loop {
        tick.tick().await;
        webhooks::deliver_pending(&app).await;
        if last_gc.is_none_or(|t| t.elapsed() >= retention::GC_INTERVAL) {
            last_gc = Some(std::time::Instant::now());
            // Beside the sweep: walking a large data folder must not hold up expiry.
            tokio::spawn(housekeeping(app.clone()));
        }
        let (now, timing) = (now_ms(), app.timing());
        match app.db.run(move |c| scheduler::expire(c, now, timing)).await {
            Ok(jobs) if !jobs.is_empty() => {
                app.metrics.leases_expired(jobs.len() as u64);
                app.work.notify_waiters();
                for job in jobs {
                    app.publish_job(job).await;
                }
            }
            Ok(_) => {}
            Err(e) => tracing::error!("expiring leases: {e}"),
        }
        match app
            .db
            .run(move |c| budget::replan_running(c, now, timing))
            .await
        {
            Ok(jobs) if !jobs.is_empty() => {
                app.work.notify_waiters();
                for job in jobs {
                    app.publish_job(job).await;
                }
            }
            Ok(_) => {}
            Err(e) => tracing::error!("planning time budgets: {e}"),
        }
        let a = app.clone();
        let finished = tokio::task::spawn_blocking(move || -> error::Result<Vec<(u64, i32)>> {
            let pending = a.db.with(|c| db::frames::unassembled(c))?;
            // One frame that fails (the disk is still full) does not hold up the others,
            // and those assembled are announced.
            let mut done = Vec::new();
            for (job, frame) in pending {
                match intake::finish_frame(&a, job, frame) {
                    Ok(()) => done.push((job, frame)),
                    Err(e) => tracing::error!("assembling job {job} frame {frame}: {e}"),
                }
            }
            Ok(done)
        })
        .await;
        match finished {
            Ok(Ok(frames)) => {
                for (job, frame) in frames {
                    app.publish_frame(job, frame).await;
                    app.publish_job(job).await;
                }
            }
            Ok(Err(e)) => tracing::error!("assembling frames: {e}"),
            Err(e) => tracing::error!("assembling frames: {e}"),
        }
    }
}

/// Every [`retention::GC_INTERVAL`]: retention by the server's `--keep-jobs`, and the
/// data folder's disk use for the metric.
async fn housekeeping(app: AppState) {
    let done = tokio::task::spawn_blocking(move || {
        let collected = retention::collect(&app, app.config.keep_jobs, false, now_ms());
        app.metrics
            .set_data_bytes(store::disk_use(&app.config.data_dir));
        collected
    })
    .await;
    match done {
        Ok(Ok(_)) => {}
        Ok(Err(e)) => tracing::error!("retention: {e}"),
        Err(e) => tracing::error!("retention: {e}"),
    }
}

/// Serves the farm on `listener` until `shutdown` completes.
pub async fn serve(
    listener: TcpListener,
    config: Config,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), StartError> {
    let addr = listener.local_addr().map_err(StartError::Serve)?;
    config.check_exposure(addr).map_err(StartError::Exposed)?;
    // Read before anything else starts, so a bad file stops the server at once.
    let tls = match &config.tls {
        Some(files) => Some(files.load().map_err(StartError::Tls)?),
        None => None,
    };
    let app = tokio::task::spawn_blocking(move || open(config))
        .await
        .map_err(|e| StartError::Serve(std::io::Error::other(e.to_string())))??;
    match tls {
        Some(tls) => {
            let listener = tls::TlsListener::new(listener, tls).map_err(StartError::Serve)?;
            serve_app(listener, app, shutdown).await
        }
        None => serve_app(listener, app, shutdown).await,
    }
}

/// [`serve`] with an already opened state, on a TCP or a TLS listener.
pub async fn serve_app<L>(
    listener: L,
    app: AppState,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), StartError>
where
    L: axum::serve::Listener,
    L::Addr: std::fmt::Debug,
{
    let sweeper = tokio::spawn(sweep(app.clone()));
    let result = axum::serve(listener, router(app))
        .with_graceful_shutdown(shutdown)
        .await
        .map_err(StartError::Serve);
    sweeper.abort();
    result
}
