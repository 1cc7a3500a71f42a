//! The one place where errors become HTTP answers: a status and a JSON
//! [`proto::ErrorBody`]; plus extractors whose rejections answer the same way.

use axum::extract::rejection::JsonRejection;
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::{request::Parts, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use proto::ErrorBody;
use serde::de::DeserializeOwned;

use crate::error::{Error, StorageProblem};

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
            Error::Forbidden(_) => (StatusCode::FORBIDDEN, "forbidden"),
            Error::Conflict(_) => (StatusCode::CONFLICT, "conflict"),
            Error::LeaseGone(_) => (StatusCode::CONFLICT, "lease_gone"),
            Error::Storage {
                problem: StorageProblem::Full,
                ..
            } => (StatusCode::INSUFFICIENT_STORAGE, "storage_full"),
            Error::Storage {
                problem: StorageProblem::ReadOnly,
                ..
            } => (StatusCode::SERVICE_UNAVAILABLE, "storage_read_only"),
            Error::Internal(_) => (StatusCode::INTERNAL_SERVER_ERROR, "internal"),
            Error::BadFrame(_) => (StatusCode::INTERNAL_SERVER_ERROR, "frame_failed"),
        }
    }

    /// The JSON body.
    pub fn body(&self) -> ErrorBody {
        let (_, kind) = self.status();
        let (message, field) = match self {
            Error::Invalid { field, message } => {
                (format!("{field}: {message}"), Some(field.clone()))
            }
            Error::Internal(_) | Error::BadFrame(_) => (
                "the server could not complete the request; its log says why".to_string(),
                None,
            ),
            // The OS error names server paths: the log has it, the client needs only this.
            Error::Storage { problem, .. } => {
                let fix = match problem {
                    StorageProblem::Full => "once space is freed",
                    StorageProblem::ReadOnly => "once it is writable again",
                };
                (
                    format!("{problem}: nothing was stored; try again {fix}"),
                    None,
                )
            }
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
        match &self {
            Error::Internal(detail) | Error::BadFrame(detail) => {
                tracing::error!("internal error: {detail}")
            }
            Error::Storage { .. } => tracing::error!("{self}"),
            _ => {}
        }
        (status, Json(self.body())).into_response()
    }
}

/// Adds to every operation of the OpenAPI document the error answers the server gives it
/// beyond those its handler lists, each with the [`ErrorBody`] schema: 400 and 404 for an
/// operation with path parameters, 400 for one with query parameters, 400, 413 and 422 for one with a request body, 401 for
/// one behind a token, 403 for a worker's own routes, 503 and 507 for one that writes.
/// A handler's own description of a status is kept.
pub struct ErrorAnswers;

impl utoipa::Modify for ErrorAnswers {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::path::{HttpMethod, ParameterIn};
        use utoipa::openapi::{ContentBuilder, Ref, ResponseBuilder};
        for item in openapi.paths.paths.values_mut() {
            let operations = [
                (HttpMethod::Get, &mut item.get),
                (HttpMethod::Post, &mut item.post),
                (HttpMethod::Put, &mut item.put),
                (HttpMethod::Delete, &mut item.delete),
            ];
            for (method, operation) in operations {
                let Some(op) = operation.as_mut() else {
                    continue;
                };
                let in_path = op
                    .parameters
                    .iter()
                    .flatten()
                    .any(|p| matches!(p.parameter_in, ParameterIn::Path));
                let in_query = op
                    .parameters
                    .iter()
                    .flatten()
                    .any(|p| matches!(p.parameter_in, ParameterIn::Query));
                let body = op.request_body.is_some();
                let schemes: Vec<String> = op
                    .security
                    .iter()
                    .flatten()
                    .filter_map(|s| serde_json::to_value(s).ok())
                    .filter_map(|v| v.as_object().map(|o| o.keys().cloned().collect::<Vec<_>>()))
                    .flatten()
                    .collect();
                let writes = matches!(method, HttpMethod::Post | HttpMethod::Delete);
                let mut add = |status: &str, description: &str, applies: bool| {
                    if applies && !op.responses.responses.contains_key(status) {
                        let content = ContentBuilder::new()
                            .schema(Some(Ref::from_schema_name("ErrorBody")))
                            .build();
                        let response = ResponseBuilder::new()
                            .description(description)
                            .content("application/json", content)
                            .build();
                        op.responses
                            .responses
                            .insert(status.to_string(), response.into());
                    }
                };
                add(
                    "400",
                    "the request is malformed: a path or query parameter that is not one (an \
                     id past the largest, an unknown state), a body that is not JSON or not \
                     sent as application/json",
                    in_path || in_query || body,
                );
                add(
                    "401",
                    "no token, or not one of this route's",
                    !schemes.is_empty(),
                );
                add(
                    "403",
                    "another worker's credential: a worker acts only for itself",
                    schemes.iter().any(|s| s == "worker_credential"),
                );
                add("404", "nothing has this id", in_path);
                add("413", "the body is over this route's limit", body);
                add(
                    "422",
                    "a field is out of bounds or of the wrong type; `field` names it",
                    body,
                );
                add(
                    "503",
                    "the data folder is read-only: nothing stored, try again later",
                    writes,
                );
                add(
                    "507",
                    "the server's disk is full: nothing stored, try again later",
                    writes,
                );
            }
        }
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

/// `axum::extract::Query` whose rejections are JSON errors naming the parameter.
pub struct QueryParams<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned + Send> FromRequestParts<S> for QueryParams<T> {
    type Rejection = Error;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Error> {
        match axum::extract::Query::<T>::from_request_parts(parts, state).await {
            Ok(axum::extract::Query(v)) => Ok(QueryParams(v)),
            Err(e) => Err(Error::BadRequest(format!(
                "in the URL query: {}",
                e.body_text()
            ))),
        }
    }
}

/// A job, task or worker id in the URL path; one past [`proto::MAX_ID`] is refused (400)
/// before it reaches the database, which could not bind it.
#[derive(Clone, Copy, Debug, serde::Deserialize)]
pub struct Id(#[serde(deserialize_with = "proto::deserialize_id")] pub u64);

/// Reads a whole raw body of at most `limit` bytes; `what` names it in the error: over
/// the limit (413), cut short by a client that hung up mid-body, or otherwise unreadable.
pub async fn read_body(
    body: axum::body::Body,
    limit: usize,
    what: &str,
) -> Result<axum::body::Bytes, Error> {
    axum::body::to_bytes(body, limit).await.map_err(|e| {
        let text = error_chain(&e);
        if text.contains("length limit") {
            Error::TooLarge(format!(
                "the {what} is over this server's limit of {limit} bytes"
            ))
        } else if ends_early(&e) {
            Error::BadRequest(format!(
                "the {what} was cut short: the connection ended before the body's \
                 Content-Length was reached ({text}); send it again"
            ))
        } else {
            Error::BadRequest(format!("reading the {what}: {text}"))
        }
    })
}

/// `e` and its sources, each once (axum's error repeats hyper's): "error reading a body
/// from connection: end of file before message length reached".
fn error_chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut next = Some(e);
    while let Some(err) = next {
        let text = err.to_string();
        if parts.last() != Some(&text) {
            parts.push(text);
        }
        next = err.source();
    }
    parts.join(": ")
}

/// Whether the body ended before its announced length: hyper reports that as an
/// `UnexpectedEof` I/O error somewhere down the chain.
fn ends_early(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut next = Some(e);
    while let Some(err) = next {
        if err
            .downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::UnexpectedEof)
        {
            return true;
        }
        next = err.source();
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::body::{Body, Bytes};

    fn message(e: Error) -> (StatusCode, String) {
        (e.status().0, e.body().message)
    }

    #[tokio::test]
    async fn a_body_cut_short_or_over_the_limit_says_so() {
        // What hyper yields when the client hangs up before its Content-Length.
        let cut = Body::from_stream(tokio_stream::iter([
            Ok(Bytes::from_static(b"half a tile")),
            Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                "end of file before message length reached",
            )),
        ]));
        let (status, text) = message(read_body(cut, 1000, "tile").await.unwrap_err());
        assert_eq!(status, StatusCode::BAD_REQUEST);
        assert!(
            text.starts_with("the tile was cut short") && text.contains("end of file"),
            "{text}"
        );
        let big = Body::from(vec![0u8; 11]);
        let (status, text) = message(read_body(big, 10, "scene").await.unwrap_err());
        assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE);
        assert_eq!(text, "the scene is over this server's limit of 10 bytes");
        let fine = Body::from(vec![1u8; 10]);
        assert_eq!(read_body(fine, 10, "tile").await.unwrap().len(), 10);
    }
}
