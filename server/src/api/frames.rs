//! Frames of a job: their states, the assembled EXR and the PNG preview; the job's video.

use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;
use proto::FrameList;

use super::error::{Id, PathParams};
use crate::app::AppState;
use crate::db;
use crate::error::{Error, Result};

/// The frames of a job, with their states.
#[utoipa::path(
    get,
    path = "/jobs/{id}/frames",
    tag = "frames",
    params(("id" = u64, Path, description = "job id")),
    responses((status = 200, body = FrameList), (status = 404, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn list(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
) -> Result<Json<FrameList>> {
    Ok(Json(app.db.run(move |c| db::frames::list(c, id)).await?))
}

async fn file(
    app: &AppState,
    job: u64,
    frame: i32,
    ext: &str,
    content_type: &'static str,
) -> Result<Response> {
    let f = app
        .db
        .run(move |c| db::frames::status(c, job, frame))
        .await?;
    let path = app
        .store
        .job_dir(job)
        .join(std::path::Path::new(&f.file).with_extension(ext));
    match tokio::fs::read(&path).await {
        Ok(bytes) => Ok(([(header::CONTENT_TYPE, content_type)], bytes).into_response()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(Error::NotFound(format!(
            "frame {frame} of job {job} has no {ext} yet (it is {})",
            f.state.as_str()
        ))),
        Err(e) => Err(e.into()),
    }
}

/// The assembled multi-layer EXR of a frame (once it is done).
#[utoipa::path(
    get,
    path = "/jobs/{id}/frames/{frame}/exr",
    tag = "frames",
    params(("id" = u64, Path, description = "job id"), ("frame" = i32, Path, description = "frame number")),
    responses((status = 200, content_type = "image/x-exr", body = Vec<u8>), (status = 404, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn exr(
    State(app): State<AppState>,
    PathParams((id, frame)): PathParams<(Id, i32)>,
) -> Result<Response> {
    file(&app, id.0, frame, "exr", "image/x-exr").await
}

/// The PNG preview of a frame: final once the frame is done, progressive (the sample
/// passes in so far) before.
#[utoipa::path(
    get,
    path = "/jobs/{id}/frames/{frame}/png",
    tag = "frames",
    params(("id" = u64, Path, description = "job id"), ("frame" = i32, Path, description = "frame number")),
    responses((status = 200, content_type = "image/png", body = Vec<u8>), (status = 404, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn png(
    State(app): State<AppState>,
    PathParams((id, frame)): PathParams<(Id, i32)>,
) -> Result<Response> {
    file(&app, id.0, frame, "png", "image/png").await
}

/// The job's H.264 MP4, once encoded (a job with `video`, after every frame finished).
#[utoipa::path(
    get,
    path = "/jobs/{id}/video",
    tag = "frames",
    params(("id" = u64, Path, description = "job id")),
    responses((status = 200, content_type = "video/mp4", body = Vec<u8>), (status = 404, body = proto::ErrorBody)),
    security(("client_token" = []))
)]
pub async fn video(
    State(app): State<AppState>,
    PathParams(Id(id)): PathParams<Id>,
) -> Result<Response> {
    let encode = app
        .db
        .run(move |c| {
            let spec = db::jobs::spec(c, id)?;
            Ok::<_, Error>((spec.video, db::tasks::encode_of_job(c, id)?))
        })
        .await?;
    let why = match encode {
        (false, _) => Some("it did not ask for one (`video` in its spec, `--video`)".to_string()),
        (true, None) => Some("its frames are not all finished yet".to_string()),
        (true, Some(t)) if t.state != crate::state::TaskState::Done => Some(format!(
            "it is being encoded (its task is {})",
            t.state.as_str()
        )),
        (true, Some(_)) => None,
    };
    if let Some(why) = why {
        return Err(Error::NotFound(format!("job {id} has no video: {why}")));
    }
    let bytes = tokio::fs::read(crate::encoding::video_path(&app, id)).await?;
    Ok(([(header::CONTENT_TYPE, "video/mp4")], bytes).into_response())
}
