//! The web dashboard, served from the binary: one page, a script and a style sheet under
//! `server/assets/`, compiled in with `include_str!` (no CDN, no build step). The page
//! reads the JSON API and follows `/api/v1/events`, and acts through the API (pause,
//! resume, cancel, retry, priority, clone, delete, clear a quarantined worker); it needs no
//! token to load, and asks for the client token when the API answers 401, keeping it for
//! the browser session (`/#token=...` also works once).

use axum::http::header;
use axum::response::IntoResponse;
use axum::routing::get;
use axum::Router;

use crate::app::AppState;

const INDEX: &str = include_str!("../assets/index.html");
const SCRIPT: &str = include_str!("../assets/dashboard.js");
const STYLE: &str = include_str!("../assets/dashboard.css");

/// `/`, `/dashboard.js`, `/dashboard.css`.
pub fn routes() -> Router<AppState> {
    Router::new()
        .route(
            "/",
            get(|| async {
                ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], INDEX).into_response()
            }),
        )
        .route(
            "/dashboard.js",
            get(|| async {
                (
                    [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
                    SCRIPT,
                )
                    .into_response()
            }),
        )
        .route(
            "/dashboard.css",
            get(|| async {
                ([(header::CONTENT_TYPE, "text/css; charset=utf-8")], STYLE).into_response()
            }),
        )
}
