//! The HTTP surface: routes per resource, each group behind its token and body limit, and
//! the OpenAPI document generated from the same handlers (utoipa-axum registers a handler
//! and its documentation together, so the two cannot drift apart).
//!
//! | file | routes |
//! |---|---|
//! | `scenes.rs` | `POST /scenes`, `GET /scenes/{digest}`, `GET /scenes/{digest}/info` |
//! | `jobs.rs` | `POST/GET /jobs`, `GET/DELETE /jobs/{id}`, `POST /jobs/{id}/{cancel,pause,resume,retry,rerender,priority}` |
//! | `tasks.rs` | `GET /jobs/{id}/tasks`, `GET /jobs/{id}/failures`, `GET /jobs/{id}/tasks/{task}/log`, `GET /jobs/{id}/log` |
//! | `frames.rs` | `GET /jobs/{id}/frames`, `GET /jobs/{id}/frames/{frame}/{exr,png}`, `GET /jobs/{id}/video` |
//! | `workers.rs` | `POST/GET /workers`, `POST /workers/{id}/{lease,heartbeat,leave,clear}`, `POST /workers/{id}/tasks/{task}/{result,failure}`, `GET /workers/{id}/tasks/{task}/frame` |
//! | `events.rs` | `GET /events` (server-sent events) |
//! | `gc.rs` | `POST /gc` (retention) |
//! | `system.rs` | `/healthz`, `/metrics`, `/api/v1/openapi.json` |
//! | `error.rs` | errors as JSON; extractors that reject with them |

pub mod error;
pub mod events;
pub mod frames;
pub mod gc;
pub mod jobs;
pub mod scenes;
pub mod system;
pub mod tasks;
pub mod workers;

use axum::extract::DefaultBodyLimit;
use axum::middleware::from_fn_with_state;
use axum::Router;
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::{Modify, OpenApi};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::app::AppState;
use crate::auth::{self, Role};
use crate::limits::MAX_JSON_BYTES;

#[derive(OpenApi)]
#[openapi(
    info(title = "Tessera farm API", description = "Scenes, jobs, frames and workers of a Tessera render farm."),
    modifiers(&Security),
    tags(
        (name = "scenes", description = "GLB scenes, stored by SHA-256"),
        (name = "jobs", description = "render jobs"),
        (name = "frames", description = "assembled frames"),
        (name = "workers", description = "the worker protocol"),
        (name = "events", description = "server-sent events"),
        (name = "system", description = "retention"),
    )
)]
struct ApiDoc;

struct Security;

impl Modify for Security {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        for name in ["client_token", "worker_token", "worker_credential"] {
            components.add_security_scheme(
                name,
                SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
            );
        }
    }
}

/// The `/api/v1` routes and their OpenAPI document.
pub fn api(app: AppState) -> (Router<AppState>, utoipa::openapi::OpenApi) {
    let guard = |role| from_fn_with_state((app.clone(), role), auth::require);
    let json_limit = DefaultBodyLimit::max(MAX_JSON_BYTES);

    let client = OpenApiRouter::new()
        .routes(routes!(jobs::create, jobs::list))
        .routes(routes!(jobs::get, jobs::delete))
        .routes(routes!(jobs::cancel))
        .routes(routes!(jobs::pause))
        .routes(routes!(jobs::resume))
        .routes(routes!(jobs::retry))
        .routes(routes!(jobs::priority))
        .routes(routes!(jobs::rerender))
        .routes(routes!(tasks::list))
        .routes(routes!(tasks::failures))
        .routes(routes!(tasks::log))
        .routes(routes!(tasks::job_log))
        .routes(routes!(frames::list))
        .routes(routes!(frames::exr))
        .routes(routes!(frames::png))
        .routes(routes!(frames::video))
        .routes(routes!(workers::list))
        .routes(routes!(workers::clear))
        .routes(routes!(events::events))
        .routes(routes!(gc::collect))
        .layer(json_limit)
        .route_layer(guard(Role::Client));
    // Raw bodies: the handlers read them with their own limits (scene, tile).
    let scene_upload = OpenApiRouter::new()
        .routes(routes!(scenes::upload))
        .route_layer(guard(Role::Client));
    let shared = OpenApiRouter::new()
        .routes(routes!(scenes::download))
        .routes(routes!(scenes::info))
        .route_layer(guard(Role::Either));
    let join = OpenApiRouter::new()
        .routes(routes!(workers::register))
        .layer(json_limit)
        .route_layer(guard(Role::Worker));
    // A worker's own routes take its credential, and only its own.
    let itself = || from_fn_with_state(app.clone(), auth::require_worker);
    let worker = OpenApiRouter::new()
        .routes(routes!(workers::lease))
        .routes(routes!(workers::heartbeat))
        .routes(routes!(workers::failure))
        .routes(routes!(workers::leave))
        .routes(routes!(workers::frame))
        .layer(json_limit)
        .route_layer(itself());
    let tile_upload = OpenApiRouter::new()
        .routes(routes!(workers::result))
        .route_layer(itself());

    let v1 = OpenApiRouter::new()
        .merge(client)
        .merge(scene_upload)
        .merge(shared)
        .merge(join)
        .merge(worker)
        .merge(tile_upload);
    let (router, mut doc) = OpenApiRouter::with_openapi(ApiDoc::openapi())
        .nest(proto::API_PREFIX, v1)
        .split_for_parts();
    // After the routes are in: it reads each operation.
    error::ErrorAnswers.modify(&mut doc);
    (router, doc)
}
