//! A job's video. A job that asks for one gets an encode task once every frame is
//! finished (assembled, and denoised where the job denoises); a worker with FFmpeg leases
//! it, reads every frame's PNG preview ([`frame_png_for`]) and uploads an H.264 MP4 at
//! the job's fps, which [`receive`] checks and keeps in the job's output folder.

use std::path::PathBuf;

use proto::{JobSpec, ResultMetadata, TaskToken};
use rusqlite::Transaction;

use crate::app::App;
use crate::assembly;
use crate::db::frames;
use crate::db::tasks::{self, NewTask, TaskRow};
use crate::error::{Error, Result};
use crate::intake::{self, Received};
use crate::scheduler;
use crate::store::write_atomic;

/// The video's file name in the job's output folder.
pub const VIDEO_FILE: &str = "video.mp4";

/// Queues the job's encode task, in the transaction that finished its last frame, when
/// it asks for a video, every frame is finished and it has none yet.
pub fn queue_if_complete(tx: &Transaction, job: u64, spec: &JobSpec) -> Result<bool> {
    if !spec.video || tasks::encode_of_job(tx, job)?.is_some() {
        return Ok(false);
    }
    let (total, finished) = frames::counts(tx, job)?;
    if finished < total || total == 0 {
        return Ok(false);
    }
    let first = spec.frames.map_or(0, |f| f.start);
    tasks::insert(tx, &NewTask::encode(job, first, (spec.width, spec.height)))?;
    Ok(true)
}

/// The largest MP4 an encode task may upload for `spec`: a sixth of its frames' 8-bit RGB
/// (H.264 at CRF 18 is a twentieth or less), and a megabyte for the container.
pub fn max_upload_bytes(spec: &JobSpec) -> usize {
    let frames = spec.frames.map_or(1, |f| f.count()) as usize;
    let rgb = spec.width as usize * spec.height as usize * 3;
    frames.saturating_mul(rgb) / 6 + (1 << 20)
}

/// The PNG of frame `frame` of the job `task` encodes: the task must be an encode task,
/// and the frame one of its job's.
pub fn frame_png_for(app: &App, task: &TaskRow, spec: &JobSpec, frame: i32) -> Result<PathBuf> {
    let range = spec
        .frames
        .ok_or_else(|| Error::Internal(format!("job {} has no frame range", task.job_id)))?;
    if !range.frames().any(|f| f == frame) {
        return Err(Error::Invalid {
            field: "frame".into(),
            message: format!("job {} has no frame {frame}", task.job_id),
        });
    }
    Ok(app.store.frame(task.job_id, frame, range.last(), "png"))
}

/// The job's video file.
pub fn video_path(app: &App, job: u64) -> PathBuf {
    app.store.job_dir(job).join(VIDEO_FILE)
}

/// Checks and keeps an encode task's upload: an MP4 (an ISO media file: its first box is
/// `ftyp`), written atomically as the job's video, then the task is done.
pub fn receive(
    app: &App,
    worker: u64,
    token: TaskToken,
    meta: &ResultMetadata,
    bytes: &[u8],
    task: &TaskRow,
) -> Result<Received> {
    assembly::check_step_upload(bytes, meta, task)?;
    if bytes.get(4..8) != Some(b"ftyp") {
        return Err(Error::BadTile(format!(
            "the video of task {} is not an MP4 (no `ftyp` box at its start)",
            task.id
        )));
    }
    // Checked before the file is written: a stale lease writes nothing.
    app.db.with(|c| scheduler::check_token(c, worker, token))?;
    write_atomic(&video_path(app, task.job_id), bytes)?;
    intake::accept_step(app, worker, token, meta, task, bytes.len())
}
