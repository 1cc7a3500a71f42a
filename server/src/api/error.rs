//! The one place where errors become HTTP answers: a status and a JSON
//! [`proto::ErrorBody`]; plus extractors whose rejections answer the same way.

use axum::extract::rejection::JsonRejection;
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::{request::Parts, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use proto::ErrorBody;
use serde::de::DeserializeOwned;

use crate::error::Error;

impl Error {
    /// The HTTP status and the stable kind name.
    pub fn status(&self) -> (StatusCode, &'static str) {
        match self {
            Error::NotFound(_) => (StatusCode::NOT_FOUND, "not_found"),
            Error::Invalid { .. } => (StatusCode::UNPROCESSABLE_ENTITY, "invalid_field"),
            Error::BadRequest(_) => (StatusCode::BAD_REQUEST, "bad_request"),
            Error::BadScene(_) => (StatusCode::UNPROCESSABLE_ENTITY, "bad_scene"),
            Error::BadTile(_) => (StatusCode::UNPROCESSABLE_ENTITY, "bad_tile"),
            Error::TooLarge(_) => (StatusCode::PAYLOAD_TOO_LARGE, "too_large"),
            Error::Conflict(_) => (StatusCode::CONFLICT, "conflict"),
            Error::LeaseGone(_) => (StatusCode::CONFLICT, "lease_gone"),
            Error::Internal(_) => (StatusCode::INTERNAL_SERVER_ERROR, "internal"),
        }
    }

    /// The JSON body.
    pub fn body(&self) -> ErrorBody {
        let (_, kind) = self.status();
        let (message, field) = match self {
            Error::Invalid { field, message } => {
                (format!("{field}: {message}"), Some(field.clone()))
            }
            Error::Internal(_) => (
                "the server could not complete the request; its log says why".to_string(),
                None,
            ),
            other => (other.to_string(), None),
        };
        ErrorBody {
            error: kind.to_string(),
            message,
            field,
        }
    }
}

impl IntoResponse for Error {
    fn into_response(self) -> Response {
        let (status, _) = self.status();
        if let Error::Internal(detail) = &self {
            tracing::error!("internal error: {detail}");
        }
        (status, Json(self.body())).into_response()
    }
}

/// `axum::Json` whose rejections are JSON errors naming the problem (serde's message
/// names the field and position).
pub struct JsonBody<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned> FromRequest<S> for JsonBody<T> {
    type Rejection = Error;

    async fn from_request(req: Request, state: &S) -> Result<Self, Error> {
        match Json::<T>::from_request(req, state).await {
            Ok(Json(v)) => Ok(JsonBody(v)),
            Err(rejection) => Err(json_rejection(rejection)),
        }
    }
}

fn json_rejection(r: JsonRejection) -> Error {
    match r {
        JsonRejection::JsonDataError(e) => {
            // "Failed to deserialize the JSON body into the target type: spp: invalid
            // type ..." — serde's own text after the first colon names the field.
            let text = e.body_text();
            let detail = text
                .split_once(": ")
                .map(|(_, d)| d)
                .unwrap_or(&text)
                .to_string();
            let field = detail
                .split_once(": ")
                .map(|(f, _)| f.to_string())
                .filter(|f| !f.contains(' '));
            match field {
                Some(field) => Error::Invalid {
                    field,
                    message: detail
                        .split_once(": ")
                        .map(|(_, m)| m.to_string())
                        .unwrap_or(detail),
                },
                None => Error::BadRequest(format!("the JSON body does not fit: {detail}")),
            }
        }
        JsonRejection::JsonSyntaxError(e) => {
            Error::BadRequest(format!("the body is not valid JSON: {}", e.body_text()))
        }
        JsonRejection::MissingJsonContentType(_) => {
            Error::BadRequest("send the body with `Content-Type: application/json`".into())
        }
        other if other.status() == StatusCode::PAYLOAD_TOO_LARGE => Error::TooLarge(format!(
            "the JSON body is over this route's limit of {} bytes",
            crate::limits::MAX_JSON_BYTES
        )),
        other => Error::BadRequest(other.body_text()),
    }
}

/// `axum::extract::Path` whose rejections are JSON errors.
pub struct PathParams<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned + Send> FromRequestParts<S> for PathParams<T> {
    type Rejection = Error;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Error> {
        match axum::extract::Path::<T>::from_request_parts(parts, state).await {
            Ok(axum::extract::Path(v)) => Ok(PathParams(v)),
            Err(e) => Err(Error::BadRequest(format!(
                "in the URL path: {}",
                e.body_text()
            ))),
        }
    }
}

/// Reads a whole raw body of at most `limit` bytes; `what` names it in the error.
pub async fn read_body(
    body: axum::body::Body,
    limit: usize,
    what: &str,
) -> Result<axum::body::Bytes, Error> {
    axum::body::to_bytes(body, limit).await.map_err(|e| {
        let too_large = std::error::Error::source(&e)
            .map(|s| s.to_string().contains("length limit"))
            .unwrap_or(false)
            || e.to_string().contains("length limit");
        if too_large {
            Error::TooLarge(format!(
                "the {what} is over this server's limit of {limit} bytes"
            ))
        } else {
            Error::BadRequest(format!("reading the {what}: {e}"))
        }
    })
}
