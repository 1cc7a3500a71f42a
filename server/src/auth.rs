//! Bearer tokens: one for workers, one for clients. A worker token cannot create jobs and
//! a client token cannot lease. Tokens are compared in constant time (over their SHA-256
//! digests, so the length does not leak either); a refusal is a bare 401.

use axum::extract::{Request, State};
use axum::http::{header, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use sha2::{Digest, Sha256};

use crate::app::AppState;

/// Who a route is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// CLI and dashboard: scenes, jobs, frames, events.
    Client,
    /// Worker daemons: register, lease, heartbeat, upload.
    Worker,
    /// Either (workers download scenes by digest; clients may too).
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
    let ok = allowed(
        role,
        token.as_deref(),
        app.config.client_token.as_deref(),
        app.config.worker_token.as_deref(),
    );
    if ok {
        next.run(req).await
    } else {
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
