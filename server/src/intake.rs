//! The tile upload pipeline, start to end on one blocking thread (a client that hangs up
//! cannot stop it half-way): is the lease current, is the tile good, store it, mark the
//! task done (one transaction), then assemble the frame or write a progressive preview.
//! A check task's tile is first compared with the tiles it repeats (see [`verify`]). A
//! frame's assembly ends in one transaction too: assembled (and, for a time-budget job,
//! planned again) or failed with its reason.

use std::collections::HashSet;
use std::time::Instant;

use proto::{ResultMetadata, TaskToken};
use rusqlite::Connection;
use tracer::film::{Layers, SamplingSummary};

use crate::app::{now_ms, App};
use crate::assembly::{self, FrameSource};
use crate::budget;
use crate::config::Timing;
use crate::db::events::log;
use crate::db::tasks::{self, TaskRow};
use crate::db::{frames, jobs};
use crate::error::{Error, Result};
use crate::scheduler::{self, Accepted};
use crate::state::JobControl;
use crate::store::write_atomic;
use crate::verify::{self, Verdict};

/// What became of an upload.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Received {
    /// First upload for the task (`false`: a duplicate, ignored).
    pub accepted: bool,
    /// The task's job.
    pub job: u64,
    /// The task's frame.
    pub frame: i32,
    /// The frame is now assembled.
    pub frame_done: bool,
}

/// Checks, stores and accepts one tile.
pub fn receive(
    app: &App,
    worker: u64,
    token: TaskToken,
    meta: &ResultMetadata,
    bytes: &[u8],
) -> Result<Received> {
    let (fresh, task) = app
        .db
        .with(|c| scheduler::precheck_upload(c, worker, token))?;
    if !fresh {
        return Ok(Received {
            accepted: false,
            job: task.job_id,
            frame: task.frame,
            frame_done: false,
        });
    }
    let spec = app.db.with(|c| jobs::spec(c, task.job_id))?;
    match task.kind {
        proto::TaskKind::Render => {}
        proto::TaskKind::Denoise => {
            return crate::denoising::receive(app, worker, token, meta, bytes, &task, &spec)
        }
        proto::TaskKind::Encode => {
            return crate::encoding::receive(app, worker, token, meta, bytes, &task)
        }
    }
    let layers = match assembly::check_tile(bytes, meta, &task, (spec.width, spec.height)) {
        Ok(layers) => layers,
        Err(e) => {
            app.metrics.tile_refused();
            return Err(e);
        }
    };
    let verdict = match task.check_of {
        Some(original) => Some(judge(app, &task, original, &layers, bytes)?),
        None => None,
    };
    match store_and_commit(
        app,
        worker,
        token,
        task.job_id,
        meta,
        verdict.as_ref(),
        bytes,
    )? {
        Accepted::Duplicate => Ok(Received {
            accepted: false,
            job: task.job_id,
            frame: task.frame,
            frame_done: false,
        }),
        Accepted::New {
            job,
            frame,
            frame_complete,
            pass_complete,
            queued,
            ..
        } => {
            counted(app, bytes.len(), queued);
            if frame_complete {
                finish_frame(app, job, frame)?;
            } else if pass_complete {
                preview_frame(app, job, frame)?;
            }
            Ok(Received {
                accepted: true,
                job,
                frame,
                frame_done: frame_complete,
            })
        }
    }
}

/// Counts an accepted upload of `bytes`; where its acceptance `queued` a task (a check, a
/// quarantined worker's tasks, the job's encode after its last denoised frame), wakes the
/// workers waiting for a lease now rather than when their waits run out (the demo sat idle
/// 30 s before its video).
fn counted(app: &App, bytes: usize, queued: bool) {
    app.metrics.tile_accepted(bytes);
    if queued {
        app.work.notify_waiters();
    }
}

/// Commits the upload of a step after rendering (denoise or encode), its result already
/// written, under the fencing token: the task is done, and a denoise task's frame with it.
pub fn accept_step(
    app: &App,
    worker: u64,
    token: TaskToken,
    meta: &ResultMetadata,
    task: &TaskRow,
    upload_bytes: usize,
) -> Result<Received> {
    let (now, timing) = (now_ms(), app.timing());
    let accepted = app
        .db
        .with(|c| scheduler::accept(c, worker, token, 0, meta.render_ms, None, now, timing))?;
    if let Accepted::New { queued, .. } = accepted {
        counted(app, upload_bytes, queued);
    }
    let accepted = matches!(accepted, Accepted::New { .. });
    Ok(Received {
        accepted,
        job: task.job_id,
        frame: task.frame,
        frame_done: accepted && task.kind == proto::TaskKind::Denoise,
    })
}

/// Writes the tile to its attempt's own file, then commits it under the fencing token.
/// The file comes first, so a crash in between leaves a done task with its tile; the
/// attempt in its name means a stale upload racing the current one writes beside the
/// accepted bytes, never over them, and the commit decides which file counts. A file the
/// commit did not accept is removed.
pub fn store_and_commit(
    app: &App,
    worker: u64,
    token: TaskToken,
    job: u64,
    meta: &ResultMetadata,
    verdict: Option<&Verdict>,
    bytes: &[u8],
) -> Result<Accepted> {
    let path = app.store.tile(job, token.task_id, token.attempt);
    write_atomic(&path, bytes)?;
    let (now, timing) = (now_ms(), app.timing());
    let accepted = app.db.with(|c| -> Result<_> {
        let accepted = scheduler::accept(
            c,
            worker,
            token,
            meta.rays,
            meta.render_ms,
            verdict,
            now,
            timing,
        );
        // Whose tile counts: the task's done attempt (a duplicate of the same attempt
        // wrote the same path, and that file is the accepted one).
        let counts = match &accepted {
            Ok(Accepted::New { .. }) => true,
            Ok(Accepted::Duplicate) => {
                tasks::load(c, token.task_id)?.is_some_and(|t| t.attempt == token.attempt)
            }
            Err(_) => false,
        };
        Ok((accepted, counts))
    });
    let (accepted, counts) = accepted?;
    if !counts {
        let _ = std::fs::remove_file(&path);
    }
    accepted
}

/// The verdict on a check's tile, compared bit for bit with every finished render of its
/// group. When the task's own tile is found wrong, the check's tile takes its place now,
/// before the check is accepted, so the frame can never be assembled from the wrong one.
fn judge(
    app: &App,
    check: &TaskRow,
    original: u64,
    layers: &Layers,
    bytes: &[u8],
) -> Result<Verdict> {
    let group = app.db.with(|c| verify::group(c, original))?;
    let mut matching = Vec::new();
    for render in &group {
        let stored = assembly::read_tile(&app.store, check.job_id, render.task, render.attempt)?;
        if verify::identical(&stored, layers) {
            matching.push(render.task);
        }
    }
    let verdict = Verdict::new(&group, &matching);
    if verdict.replaces(original) {
        let wrong = group.iter().find(|r| r.task == original).ok_or_else(|| {
            Error::Internal(format!("task {original} is not among its own renders"))
        })?;
        write_atomic(
            &app.store.tile(check.job_id, original, wrong.attempt),
            bytes,
        )?;
    }
    if verdict != Verdict::Agrees(vec![original]) {
        tracing::warn!(
            "check {} of task {original} (job {}, frame {}): {verdict:?}",
            check.id,
            check.job_id,
            check.frame
        );
    }
    Ok(verdict)
}

/// Assembles a frame whose tasks are all done: EXR and PNG written atomically, the frame
/// marked assembled (a time-budget job plans its next passes then), then its tile files
/// removed. A time-budget frame also keeps every layer merged so far, for its next pass;
/// those go once the job finishes cleanly.
///
/// A frame that cannot be made from what is stored for it ([`Error::BadFrame`]: a tile
/// unreadable, a frame over this server's assembly memory) is marked failed with the
/// reason, and the job with it: assembling again would fail again, so it waits for the
/// job to be retried. A job cancelled or deleted meanwhile stops the assembly, which is
/// then no error. Other errors (a full disk, a folder in the way) are returned, for the
/// upload to report and the sweeper to try again.
pub fn finish_frame(app: &App, job: u64, frame: i32) -> Result<()> {
    let _guard = app.assembly.lock().unwrap_or_else(|p| p.into_inner());
    match assemble(app, job, frame) {
        Err(Error::BadFrame(reason)) => {
            tracing::error!("job {job} frame {frame} failed to assemble: {reason}");
            app.db
                .with(|c| fail_frame(c, job, frame, &reason, now_ms()))
        }
        Err(Error::Conflict(why) | Error::NotFound(why)) => {
            tracing::info!("job {job} frame {frame} not assembled: {why}");
            Ok(())
        }
        other => other,
    }
}

/// [`finish_frame`]'s work, with the assembly lock held.
fn assemble(app: &App, job: u64, frame: i32) -> Result<()> {
    let (spec, tasks, assembled, render_seconds, features) = app.db.with(|c| -> Result<_> {
        Ok((
            jobs::spec(c, job)?,
            tasks::done_of_frame(c, job, frame)?,
            frames::is_assembled(c, job, frame)?,
            tasks::render_seconds_of_frame(c, job, frame)?,
            jobs::scene_features(c, job)?,
        ))
    })?;
    // Another caller (the upload that completed it, or the sweeper) got here first.
    if assembled {
        return Ok(());
    }
    let budget = app.config.assembly_memory;
    // The job may be cancelled or deleted while a big frame is written: each band asks.
    let wanted = || app.db.with(|c| assembly_wanted(c, job));
    let started = Instant::now();
    let tile_bytes: u64 = tasks
        .iter()
        .filter_map(|t| std::fs::metadata(app.store.tile(job, t.id, t.attempt)).ok())
        .map(|m| m.len())
        .sum();
    let mut source =
        FrameSource::new(&app.store, &spec, job, frame, &tasks, budget)?.with_proceed(wanted);
    if spec.time_budget.is_some() {
        source.write_merged()?;
        // From here on the merged frame holds every pass, and is read alone.
        source =
            FrameSource::new(&app.store, &spec, job, frame, &tasks, budget)?.with_proceed(wanted);
    }
    let facts = assembly::FrameFacts {
        reached: source.sampling()?,
        render_seconds,
        features,
    };
    source.write_frame(&facts)?;
    let (now, timing) = (now_ms(), app.timing());
    app.db
        .with(|c| mark_assembled(c, job, frame, now, &facts.reached, timing))?;
    if spec.denoise || spec.video {
        // Its denoise task, or the job's encode task, is waiting to be leased.
        app.work.notify_waiters();
    }
    app.metrics
        .frame_assembled(started.elapsed().as_secs_f64(), tile_bytes);
    let checks = app
        .db
        .with(|c| tasks::done_checks_of_frame(c, job, frame))?;
    let done: HashSet<u64> = tasks.iter().map(|t| t.id).chain(checks).collect();
    app.store.remove_tiles(job, &done);
    if spec.time_budget.is_some() {
        // Passes planned just now are waiting to be leased.
        app.work.notify_waiters();
        if app.db.with(|c| jobs::finished_cleanly(c, job))? {
            remove_merged_frames(app, job);
        }
    }
    Ok(())
}

/// Marks a frame assembled from all of its tasks so far, with what it reached; a time-budget
/// job then plans its next passes (before it can count as finished).
pub fn mark_assembled(
    conn: &mut Connection,
    job: u64,
    frame: i32,
    now: i64,
    reached: &SamplingSummary,
    timing: Timing,
) -> Result<()> {
    let tx = conn.transaction()?;
    frames::set_assembled(&tx, job, frame, now, reached)?;
    log(&tx, now, Some(job), "frame_assembled", &frame.to_string())?;
    let spec = jobs::spec(&tx, job)?;
    if spec.time_budget.is_none() {
        crate::denoising::queue(&tx, job, frame, &spec)?;
        crate::encoding::queue_if_complete(&tx, job, &spec)?;
    }
    // A time-budget job's frames get more passes: its planner starts the steps after
    // rendering once they are over.
    budget::replan_with(&tx, job, now, timing)?;
    jobs::update_finished(&tx, job, now)?;
    tx.commit()?;
    Ok(())
}

/// Marks a frame whose assembly failed, with the reason: it is not assembled again until
/// the job is retried, and the job counts as failed.
pub fn fail_frame(
    conn: &mut Connection,
    job: u64,
    frame: i32,
    reason: &str,
    now: i64,
) -> Result<()> {
    let tx = conn.transaction()?;
    frames::set_failure(&tx, job, frame, reason)?;
    log(
        &tx,
        now,
        Some(job),
        "frame_failed",
        &format!("{frame}: {reason}"),
    )?;
    jobs::update_finished(&tx, job, now)?;
    tx.commit()?;
    Ok(())
}

/// Whether a frame of `job` should still be assembled: `NotFound` once the job is
/// deleted, `Conflict` once it is cancelled (an assembly under way stops).
fn assembly_wanted(conn: &Connection, job: u64) -> Result<()> {
    match jobs::find_control(conn, job)? {
        None => Err(Error::NotFound(format!("job {job} was deleted"))),
        Some(JobControl::Cancelled) => Err(Error::Conflict(format!("job {job} was cancelled"))),
        Some(JobControl::Active | JobControl::Paused) => Ok(()),
    }
}

/// Removes a finished time-budget job's merged frames (kept while a failed task could
/// still be retried).
fn remove_merged_frames(app: &App, job: u64) {
    let Ok(entries) = std::fs::read_dir(app.store.tile_dir(job)) else {
        return;
    };
    for entry in entries.flatten() {
        if entry.file_name().to_string_lossy().ends_with(".merged.exr") {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// Writes a progressive PNG of a frame from the passes accepted so far (not once the frame
/// is assembled: the final preview must not be replaced by an older one).
pub fn preview_frame(app: &App, job: u64, frame: i32) -> Result<()> {
    let _guard = app.assembly.lock().unwrap_or_else(|p| p.into_inner());
    let (spec, tasks, assembled) = app.db.with(|c| -> Result<_> {
        Ok((
            jobs::spec(c, job)?,
            tasks::done_of_frame(c, job, frame)?,
            frames::is_assembled(c, job, frame)?,
        ))
    })?;
    if assembled {
        return Ok(());
    }
    let budget = app.config.assembly_memory;
    let source = FrameSource::new(&app.store, &spec, job, frame, &tasks, budget)?;
    source.write_preview()
}

#[cfg(test)]
mod tests {
    use proto::{JobSpec, SceneInfo};

    use super::*;
    use crate::Config;

    fn meta() -> ResultMetadata {
        ResultMetadata {
            attempt: 0,
            sha256: String::new(),
            samples: 1,
            rays: 1,
            render_ms: 1,
        }
    }

    /// The race the attempt in a tile's name closes: worker a's upload passed its
    /// precheck while its lease was current, then stalled; the lease expired, b took the
    /// task and its tile was accepted; a's write and commit come last. a's tile is
    /// ignored as a duplicate, its file goes, and b's accepted bytes are untouched.
    #[test]
    fn a_stale_upload_racing_the_current_one_cannot_replace_the_accepted_tile() {
        let dir = tempfile::tempdir().unwrap();
        let app = crate::open(Config::new(dir.path().join("data"))).unwrap();
        let scene = SceneInfo {
            digest: "a".repeat(64),
            ..Default::default()
        };
        let mut spec = JobSpec::new(scene.digest.clone());
        (spec.width, spec.height, spec.tile_size) = (8, 8, Some(8));
        let timing = app.timing();
        let (job, a, b, first, second) = app.db.with(|c| {
            crate::db::scenes::insert(c, &scene.digest, 1, &scene, 0).unwrap();
            let plan = crate::spec::plan(spec, &scene, 10).unwrap();
            let job = crate::controls::submit(c, &plan, 0).unwrap();
            let joining = |name| crate::identity::Joining {
                profile: crate::db::workers::Profile {
                    name,
                    threads: 1,
                    version: "t",
                    platform: None,
                    tags: &[],
                    denoiser: None,
                    encoder: None,
                    step_ms_per_mp: [None; 2],
                },
                credential: None,
            };
            let a = crate::identity::join(c, &joining("a"), 0, 0).unwrap().id;
            let b = crate::identity::join(c, &joining("b"), 0, 0).unwrap().id;
            let first = scheduler::lease(c, a, 0, timing).unwrap().unwrap();
            let late = timing.lease_ms + 1;
            scheduler::expire(c, late, timing).unwrap();
            let second = scheduler::lease(c, b, late, timing).unwrap().unwrap();
            (job, a, b, first.token, second.token)
        });
        assert_eq!((first.attempt, second.attempt), (1, 2));

        let current = store_and_commit(&app, b, second, job, &meta(), None, b"b's tile").unwrap();
        assert!(matches!(current, Accepted::New { .. }));
        let stale = store_and_commit(&app, a, first, job, &meta(), None, b"a's tile");
        assert!(matches!(stale, Ok(Accepted::Duplicate)), "{stale:?}");

        let accepted = app.store.tile(job, second.task_id, second.attempt);
        assert_eq!(std::fs::read(accepted).unwrap(), b"b's tile");
        assert!(!app.store.tile(job, first.task_id, first.attempt).exists());
        // A second upload of the accepted attempt is a duplicate and keeps the file.
        let again = store_and_commit(&app, b, second, job, &meta(), None, b"b's tile").unwrap();
        assert!(matches!(again, Accepted::Duplicate));
        assert!(app.store.tile(job, second.task_id, second.attempt).exists());
    }
}
