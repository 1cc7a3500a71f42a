//! `POST /scenes` (upload a GLB), `GET /scenes/{digest}` (the GLB),
//! `GET /scenes/{digest}/info` (what it holds).

use axum::body::Body;
use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use proto::SceneInfo;

use super::error::{read_body, PathParams};
use crate::app::{now_ms, AppState};
use crate::db;
use crate::error::{Error, Result};
use crate::store::{self, is_digest};

/// Uploads a scene as one self-contained GLB. The tracer's loader checks it here, so a
/// malformed scene never reaches a worker. Stored by SHA-256: uploading the same bytes
/// twice stores them once.
#[utoipa::path(
    post,
    path = "/scenes",
    tag = "scenes",
    request_body(content = Vec<u8>, content_type = "model/gltf-binary", description = "a GLB file"),
    responses(
        (status = 201, description = "stored", body = SceneInfo),
        (status = 200, description = "already stored", body = SceneInfo),
        (status = 413, description = "over the size limit", body = proto::ErrorBody),
        (status = 422, description = "not a scene the tracer can load; the message names the glTF element", body = proto::ErrorBody),
    ),
    security(("client_token" = []))
)]
pub async fn upload(State(app): State<AppState>, body: Body) -> Result<Response> {
    let bytes = read_body(body, app.config.max_scene_bytes, "scene").await?;
    if bytes.is_empty() {
        return Err(Error::BadScene(
            "the body is empty; send the scene's GLB bytes".into(),
        ));
    }
    let a = app.clone();
    let (info, created) = tokio::task::spawn_blocking(move || -> Result<(SceneInfo, bool)> {
        // A scene already stored was checked when it first came: answer from the database.
        let digest = store::sha256_hex(&bytes);
        if let Some(info) = a.db.with(|c| db::scenes::info(c, &digest))? {
            // Uploaded again: retention counts its grace from now.
            let now = now_ms();
            a.db.with(|c| db::scenes::insert(c, &digest, bytes.len() as u64, &info, now))?;
            return Ok((info, false));
        }
        let (info, _scene) = crate::scene::inspect(&bytes)
            .map_err(|e| Error::BadScene(format!("the scene cannot be loaded: {e}")))?;
        store::write_atomic(&a.store.scene(&digest), &bytes)?;
        let now = now_ms();
        a.db.with(|c| db::scenes::insert(c, &digest, bytes.len() as u64, &info, now))?;
        a.metrics.scene_stored(bytes.len());
        Ok((info, true))
    })
    .await
    .map_err(|e| Error::Internal(format!("scene check panicked: {e}")))??;
    let status = if created {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    Ok((status, Json(info)).into_response())
}

fn check_digest(digest: &str) -> Result<()> {
    if is_digest(digest) {
        Ok(())
    } else {
        // Malformed like any other path parameter (400), not a field out of bounds.
        Err(Error::BadRequest(format!(
            "in the URL path: `{digest}` is not a SHA-256 digest (64 lower-case hex digits)"
        )))
    }
}

/// The full digest of the scene whose digest starts with `prefix` (the whole digest, or
/// its first 8 or more hex digits, as the CLI prints them).
pub fn resolve(c: &rusqlite::Connection, field: &str, prefix: &str) -> Result<String> {
    if !store::is_digest_prefix(prefix) {
        return Err(Error::Invalid {
            field: field.into(),
            message: format!(
                "`{prefix}` is not a SHA-256 digest or its start ({} to 64 lower-case hex \
                 digits)",
                store::MIN_DIGEST_PREFIX
            ),
        });
    }
    match db::scenes::resolve(c, prefix)? {
        Ok(Some(digest)) => Ok(digest),
        Ok(None) => Err(Error::NotFound(format!(
            "no scene with digest `{prefix}`; upload it first (POST /api/v1/scenes)"
        ))),
        Err(many) => Err(Error::Invalid {
            field: field.into(),
            message: format!(
                "`{prefix}` starts the digests of several scenes ({}); give more of it",
                many.join(", ")
            ),
        }),
    }
}

/// What an uploaded scene holds; the digest may be shortened to its first 8 or more hex
/// digits.
#[utoipa::path(
    get,
    path = "/scenes/{digest}/info",
    tag = "scenes",
    params(("digest" = String, Path, description = "SHA-256 of the GLB, or its first 8 or more hex digits")),
    responses(
        (status = 200, body = SceneInfo),
        (status = 404, body = proto::ErrorBody),
        (status = 422, description = "not a digest, or the start of several", body = proto::ErrorBody),
    ),
    security(("client_token" = []), ("worker_token" = []), ("worker_credential" = []))
)]
pub async fn info(
    State(app): State<AppState>,
    PathParams(digest): PathParams<String>,
) -> Result<Json<SceneInfo>> {
    let info = app
        .db
        .run(move |c| {
            let digest = resolve(c, "digest", &digest)?;
            db::scenes::info(c, &digest)?
                .ok_or_else(|| Error::NotFound(format!("no scene with digest {digest}")))
        })
        .await?;
    Ok(Json(info))
}

/// The GLB bytes of a scene (workers fetch it once per digest and cache it).
#[utoipa::path(
    get,
    path = "/scenes/{digest}",
    tag = "scenes",
    params(("digest" = String, Path, description = "SHA-256 of the GLB")),
    responses(
        (status = 200, description = "the GLB", content_type = "model/gltf-binary", body = Vec<u8>),
        (status = 404, body = proto::ErrorBody)
    ),
    security(("client_token" = []), ("worker_token" = []), ("worker_credential" = []))
)]
pub async fn download(
    State(app): State<AppState>,
    PathParams(digest): PathParams<String>,
) -> Result<Response> {
    check_digest(&digest)?;
    let path = app.store.scene(&digest);
    match tokio::fs::read(&path).await {
        Ok(bytes) => Ok(([(header::CONTENT_TYPE, "model/gltf-binary")], bytes).into_response()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(Error::NotFound(format!(
            "no scene with digest {digest}; upload it first"
        ))),
        Err(e) => Err(e.into()),
    }
}
