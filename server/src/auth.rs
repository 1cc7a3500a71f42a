//! Bearer tokens: the client token, the worker (join) token, and each worker's own
//! credential. The join token only registers a worker, which answers with the worker's
//! credential; every call on a worker's own routes (`/workers/{id}/...`) must carry that
//! worker's credential, so a worker can act only for itself. A worker token cannot create
//! jobs and a client token cannot lease. The client and join tokens are compared in
//! constant time (over their SHA-256 digests, so the length does not leak either); a
//! credential is looked up by its SHA-256, all the database keeps of it. A refusal
//! without a token that proves who the caller is, is a bare 401.

use std::collections::HashMap;

use axum::extract::{FromRequestParts, Request, State};
use axum::http::{header, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use sha2::{Digest, Sha256};

use crate::app::AppState;
use crate::error::Error;
use crate::identity;

/// Who a route is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// CLI and dashboard: scenes, jobs, frames, events.
    Client,
    /// Worker daemons joining the farm: register (the join token).
    Worker,
    /// Either (workers download scenes by digest, with their credential or the join
    /// token; clients may too).
    Either,
}

/// Whether `given` equals `expected`, in time independent of where they differ.
pub fn constant_time_eq(given: &[u8], expected: &[u8]) -> bool {
    let (a, b) = (Sha256::digest(given), Sha256::digest(expected));
    a.iter()
        .zip(b.iter())
        .fold(0u8, |acc, (x, y)| acc | (x ^ y))
        == 0
}

/// Whether a request presenting `token` may use a route for `role`. A role without a
/// configured token is open.
pub fn allowed(
    role: Role,
    token: Option<&str>,
    client: Option<&str>,
    worker: Option<&str>,
) -> bool {
    let matches = |expected: Option<&str>| match expected {
        None => true,
        Some(e) => token.is_some_and(|t| constant_time_eq(t.as_bytes(), e.as_bytes())),
    };
    match role {
        Role::Client => matches(client),
        Role::Worker => matches(worker),
        Role::Either => matches(client) || matches(worker),
    }
}

/// The token of a request: `Authorization: Bearer T`, or for GET requests an
/// `access_token=T` query parameter (browsers cannot set headers on EventSource or <img>).
fn token_of(req: &Request) -> Option<String> {
    if let Some(v) = req.headers().get(header::AUTHORIZATION) {
        return v
            .to_str()
            .ok()
            .and_then(|v| v.strip_prefix("Bearer "))
            .map(|t| t.trim().to_string());
    }
    if req.method() == Method::GET {
        return query_token(req.uri());
    }
    None
}

/// The `access_token` query value, percent-decoded (the dashboard encodes it with
/// `encodeURIComponent`, so a token with `+`, `&` or `%` in it arrives encoded).
fn query_token(uri: &axum::http::Uri) -> Option<String> {
    #[derive(serde::Deserialize)]
    struct Query {
        access_token: Option<String>,
    }
    let Query { access_token } = axum::extract::Query::try_from_uri(uri).ok()?.0;
    access_token
}

/// Middleware: lets the request through if its token fits `role`, else answers 401.
pub async fn require(
    State((app, role)): State<(AppState, Role)>,
    req: Request,
    next: Next,
) -> Response {
    let token = token_of(&req);
    let mut ok = allowed(
        role,
        token.as_deref(),
        app.config.client_token.as_deref(),
        app.config.worker_token.as_deref(),
    );
    if !ok && role == Role::Either {
        if let Some(t) = token.clone() {
            match app
                .db
                .run(move |c| identity::worker_of_credential(c, &t))
                .await
            {
                Ok(worker) => ok = worker.is_some(),
                Err(e) => return e.into_response(),
            }
        }
    }
    if ok {
        next.run(req).await
    } else {
        unauthorized()
    }
}

/// A bare 401.
fn unauthorized() -> Response {
    (
        StatusCode::UNAUTHORIZED,
        [(header::WWW_AUTHENTICATE, "Bearer")],
        axum::Json(proto::ErrorBody {
            error: "unauthorized".into(),
            message: "unauthorized".into(),
            field: None,
        }),
    )
        .into_response()
}

/// Middleware of a worker's own routes (`/workers/{id}/...`): the bearer token must be the
/// credential worker `id` was given when it joined. 404 when there is no such worker (or
/// it joined before workers had credentials: it registers again), 401 without a token or
/// with one that is no worker's, 403 with another worker's. An `id` that is not an id is
/// left to the handler's 400.
pub async fn require_worker(State(app): State<AppState>, req: Request, next: Next) -> Response {
    let (mut parts, body) = req.into_parts();
    let id = axum::extract::Path::<HashMap<String, String>>::from_request_parts(&mut parts, &app)
        .await
        .ok()
        .and_then(|p| p.0.get("id")?.parse::<u64>().ok())
        .filter(|&id| id <= proto::MAX_ID);
    let req = Request::from_parts(parts, body);
    let Some(id) = id else {
        return next.run(req).await;
    };
    let presented = token_of(&req);
    let found = app
        .db
        .run(move |c| -> crate::error::Result<_> {
            let stored = crate::db::workers::credential_hash(c, id)?;
            let owner = match &presented {
                Some(t) => identity::worker_of_credential(c, t)?,
                None => None,
            };
            Ok((stored, owner))
        })
        .await;
    let refusal = match found {
        Err(e) => e,
        Ok((None, _)) => Error::NotFound(format!(
            "no worker {id} here: register (POST {}/workers) and use the id and credential \
             it answers",
            proto::API_PREFIX
        )),
        Ok((Some(_), Some(owner))) if owner == id => return next.run(req).await,
        Ok((Some(_), Some(owner))) => Error::Forbidden(format!(
            "this is worker {owner}'s credential, not worker {id}'s: a worker acts only for \
             itself"
        )),
        Ok((Some(_), None)) => return unauthorized(),
    };
    refusal.into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_take_only_their_token() {
        let (c, w) = (Some("client-secret"), Some("worker-secret"));
        assert!(allowed(Role::Client, Some("client-secret"), c, w));
        assert!(!allowed(Role::Client, Some("worker-secret"), c, w));
        assert!(allowed(Role::Worker, Some("worker-secret"), c, w));
        assert!(!allowed(Role::Worker, Some("client-secret"), c, w));
        assert!(allowed(Role::Either, Some("worker-secret"), c, w));
        assert!(!allowed(Role::Either, Some("nobody"), c, w));
        assert!(!allowed(Role::Client, None, c, w));
        // A role with no token configured is open.
        assert!(allowed(Role::Client, None, None, w));
    }

    #[test]
    fn the_query_token_is_percent_decoded() {
        let token = |uri: &str| query_token(&uri.parse().unwrap());
        assert_eq!(
            token("/events?x=1&access_token=a%2Bb%26c%25d%20e").as_deref(),
            Some("a+b&c%d e")
        );
        assert_eq!(
            token("/events?access_token=plain").as_deref(),
            Some("plain")
        );
        assert_eq!(token("/events?other=1"), None);
        assert_eq!(token("/events"), None);
    }

    #[test]
    fn comparison_needs_the_whole_token() {
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abcd"));
        assert!(!constant_time_eq(b"", b"a"));
    }
}
