//! Leases and every task state change a worker causes, each one database transaction:
//! lease (priority, then age), heartbeat, accept, fail, expire, revoke on restart, leave.
//! Every state change goes through [`state::transition`](crate::state::transition) (in
//! [`tasks::advance`]); times are passed in (`now`, Unix ms) so tests need no clock. The
//! job controls are in [`crate::controls`].

use proto::{
    FailureAck, FailureKind, Lease, LogLine, Rect, SampleSpan, TaskKind, TaskLogLines, TaskToken,
};
use rusqlite::{Connection, Transaction};

use crate::config::Timing;
use crate::db::events::log;
use crate::db::tasks::{self, TaskRow};
use crate::db::{failures, frames, jobs, logs, workers};
use crate::error::{Error, Result};
use crate::state::{JobControl, TaskEvent, TaskState};
use crate::verify::{self, Verdict};

/// Leases the next task to `worker`: active jobs by priority (highest first), then age;
/// within a job, round by round (preview-first), frame by frame and pass by pass so that
/// previews fill in evenly.
pub fn lease(
    conn: &mut Connection,
    worker: u64,
    now: i64,
    timing: Timing,
) -> Result<Option<Lease>> {
    lease_keeping(conn, worker, None, now, timing)
}

/// [`lease`], keeping first, in the same transaction, the lines the worker logged for its
/// previous lease after that lease's last heartbeat: only for an attempt that worker
/// held; others are dropped.
pub fn lease_keeping(
    conn: &mut Connection,
    worker: u64,
    late: Option<&TaskLogLines>,
    now: i64,
    timing: Timing,
) -> Result<Option<Lease>> {
    let tx = conn.transaction()?;
    workers::touch(&tx, worker, now)?;
    if let Some(late) = late {
        let held = tasks::load(&tx, late.token.task_id)?
            .is_some_and(|t| t.worker_id == Some(worker) && t.attempt == late.token.attempt);
        if held {
            logs::append(
                &tx,
                late.token.task_id,
                late.token.attempt,
                worker,
                &late.lines,
            )?;
        }
    }
    if workers::is_quarantined(&tx, worker)? {
        tx.commit()?;
        return Ok(None);
    }
    let live_since = timing.live_since(now);
    let mut chosen = None;
    for (job, budget) in tasks::leasable_jobs(&tx, worker)? {
        if let Some(id) = tasks::next_for(&tx, job, budget, worker, live_since)? {
            chosen = Some(id);
            break;
        }
    }
    let Some(id) = chosen else {
        tx.commit()?;
        return Ok(None);
    };
    let task = tasks::load(&tx, id)?.ok_or_else(|| Error::Internal("task vanished".into()))?;
    tasks::advance(&tx, &task, TaskEvent::Lease)?;
    let deadline = now + timing.lease_ms;
    let attempt = task.attempt + 1;
    tasks::set_lease(&tx, id, attempt, worker, now, deadline)?;
    jobs::note_first_lease(&tx, task.job_id, now)?;
    let spec = jobs::spec(&tx, task.job_id)?;
    tx.commit()?;
    Ok(Some(Lease {
        token: TaskToken {
            task_id: id,
            attempt,
        },
        kind: task.kind,
        job_id: task.job_id,
        scene: spec.scene,
        frame: task.frame,
        fps: spec.fps,
        width: spec.width,
        height: spec.height,
        camera: spec.camera,
        shutter: spec.shutter,
        motion_steps: spec.motion_steps,
        animation: spec.animation,
        max_depth: spec.max_depth,
        seed: spec.seed,
        fixed_pattern: spec.fixed_pattern,
        clamp_indirect: spec.clamp_indirect,
        noise_threshold: spec.noise_threshold,
        min_spp: spec.min_spp.unwrap_or(0),
        tile: Rect {
            x: task.rect.x,
            y: task.rect.y,
            width: task.rect.width,
            height: task.rect.height,
        },
        samples: SampleSpan {
            start: task.samples.start,
            end: task.samples.end,
        },
        sequence: (task.kind == TaskKind::Encode)
            .then_some(spec.frames)
            .flatten(),
        deadline_ms: deadline,
    }))
}

/// Checks that `token` is `worker`'s current lease; the error says why not, for the
/// worker's log.
pub fn check_token(conn: &Connection, worker: u64, token: TaskToken) -> Result<TaskRow> {
    let task = tasks::load(conn, token.task_id)?.ok_or_else(|| {
        Error::LeaseGone(format!(
            "task {} is unknown: it never existed, or its job was deleted",
            token.task_id
        ))
    })?;
    if task.state == TaskState::Leased
        && task.attempt == token.attempt
        && task.worker_id == Some(worker)
    {
        return Ok(task);
    }
    let why = match (task.state, jobs::control(conn, task.job_id)?) {
        (_, JobControl::Paused) => format!("job {} is paused", task.job_id),
        (TaskState::Cancelled, _) | (_, JobControl::Cancelled) => {
            format!("job {} is cancelled", task.job_id)
        }
        (TaskState::Done, _) => "the task is already done".to_string(),
        _ => format!(
            "the lease (attempt {}) expired or was taken back; the task is now {} at attempt {}",
            token.attempt,
            task.state.as_str(),
            task.attempt
        ),
    };
    Err(Error::LeaseGone(format!("task {}: {why}", token.task_id)))
}

/// A heartbeat: extends `token`'s lease, keeps the lines the worker logged for it, and
/// returns the new deadline, or says the lease is gone (paused, cancelled, expired).
/// Without a token it only marks the worker alive.
pub fn heartbeat(
    conn: &mut Connection,
    worker: u64,
    token: Option<TaskToken>,
    log: &[LogLine],
    now: i64,
    timing: Timing,
) -> Result<Option<i64>> {
    let tx = conn.transaction()?;
    workers::touch(&tx, worker, now)?;
    let Some(token) = token else {
        tx.commit()?;
        return Ok(None);
    };
    let result = check_token(&tx, worker, token).and_then(|task| {
        let deadline = now + timing.lease_ms;
        tasks::extend_lease(&tx, task.id, deadline)?;
        logs::append(&tx, task.id, token.attempt, worker, log)?;
        Ok(deadline)
    });
    // The worker's last-seen time is kept even when the lease is gone.
    tx.commit()?;
    result.map(Some)
}

/// What [`accept`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Accepted {
    /// The task was already done; this upload is ignored.
    Duplicate,
    /// The tile is the task's result.
    New {
        /// The task's job.
        job: u64,
        /// Its frame.
        frame: i32,
        /// Its pass.
        pass: u32,
        /// Every task of the frame is now done: assemble it.
        frame_complete: bool,
        /// Every task of this pass of the frame is done: a preview can be made.
        pass_complete: bool,
        /// The acceptance queued a task (a check of this tile, or the job's encode once
        /// its last frame is denoised): workers waiting for work should look again.
        queued: bool,
    },
}

/// Whether an upload for `token` should be read at all: `Ok(true)` for the current lease,
/// `Ok(false)` for a task already done (a duplicate to ignore), else the lease is gone.
pub fn precheck_upload(
    conn: &Connection,
    worker: u64,
    token: TaskToken,
) -> Result<(bool, TaskRow)> {
    if let Some(task) = tasks::load(conn, token.task_id)? {
        if task.state == TaskState::Done {
            return Ok((false, task));
        }
    }
    check_token(conn, worker, token).map(|t| (true, t))
}

/// Marks `token`'s task done with its (validated, stored) tile. A second upload for a
/// finished task is a [`Accepted::Duplicate`]. A render task may be sampled for a check;
/// a check task comes with the verdict of comparing its tile (see [`verify`]).
#[allow(clippy::too_many_arguments)]
pub fn accept(
    conn: &mut Connection,
    worker: u64,
    token: TaskToken,
    rays: u64,
    render_ms: u64,
    verdict: Option<&Verdict>,
    now: i64,
    timing: Timing,
) -> Result<Accepted> {
    let tx = conn.transaction()?;
    workers::touch(&tx, worker, now)?;
    let (fresh, task) = precheck_upload(&tx, worker, token)?;
    if !fresh {
        tx.commit()?;
        return Ok(Accepted::Duplicate);
    }
    tasks::advance(&tx, &task, TaskEvent::Complete)?;
    tasks::set_done(&tx, task.id, now, rays, render_ms)?;
    workers::count_done(&tx, worker)?;
    if task.kind != TaskKind::Render {
        let mut queued = false;
        if task.kind == TaskKind::Denoise {
            // Its frame's denoised layer is written: the frame is finished, and with it
            // perhaps the job's last.
            crate::denoising::mark_denoised(&tx, &task, now)?;
            let spec = jobs::spec(&tx, task.job_id)?;
            queued = crate::encoding::queue_if_complete(&tx, task.job_id, &spec)?;
        }
        jobs::update_finished(&tx, task.job_id, now)?;
        tx.commit()?;
        return Ok(Accepted::New {
            job: task.job_id,
            frame: task.frame,
            pass: task.pass,
            frame_complete: false,
            pass_complete: false,
            queued,
        });
    }
    frames::count_done(&tx, task.job_id, task.frame)?;
    let queued = match (task.check_of, verdict) {
        (Some(_), Some(verdict)) => verify::record(&tx, &task, worker, verdict, now)?,
        (Some(_), None) => {
            return Err(Error::Internal(format!(
                "check task {} accepted without a verdict",
                task.id
            )))
        }
        (None, _) => verify::sample(
            &tx,
            &task,
            worker,
            timing.verify_fraction,
            timing.live_since(now),
            now,
        )?,
    };
    // Asked after the verdict: a check it queued belongs to the frame.
    let frame_complete = frames::is_complete(&tx, task.job_id, task.frame)?;
    let pass_complete = tasks::pass_done(&tx, task.job_id, task.frame, task.pass)?;
    jobs::update_finished(&tx, task.job_id, now)?;
    tx.commit()?;
    Ok(Accepted::New {
        job: task.job_id,
        frame: task.frame,
        pass: task.pass,
        frame_complete,
        pass_complete,
        queued,
    })
}

/// Records a failed attempt of `task` by `worker` (reported or expired): re-queues it, or
/// fails it past its job's max attempts, and blocks the worker from the job once it has
/// failed `block_after_failures` of its tasks.
fn fail_attempt(
    tx: &Transaction,
    task: &TaskRow,
    worker: u64,
    kind: FailureKind,
    message: &str,
    now: i64,
    timing: Timing,
) -> Result<FailureAck> {
    let max_attempts = jobs::max_attempts(tx, task.job_id)?;
    let failures = task.failures + 1;
    let exhausted = failures >= max_attempts;
    let event = match kind {
        FailureKind::Expired => TaskEvent::Expire { exhausted },
        FailureKind::Reported => TaskEvent::Fail { exhausted },
    };
    let to = tasks::advance(tx, task, event)?;
    tasks::clear_lease(tx, task.id)?;
    tasks::set_failures(tx, task.id, failures)?;
    let by_worker = failures::record(tx, task, worker, kind, message, now)?;
    let blocked = by_worker >= timing.block_after_failures;
    // Logged once, when the block is new.
    if blocked && jobs::block(tx, task.job_id, worker)? {
        log(
            tx,
            now,
            Some(task.job_id),
            "worker_blocked",
            &format!("worker {worker} failed {by_worker} tasks of the job"),
        )?;
    }
    log(
        tx,
        now,
        Some(task.job_id),
        if exhausted {
            "task_failed"
        } else {
            "task_retry"
        },
        &format!(
            "task {} attempt {} on worker {worker} ({}): {message}",
            task.id,
            task.attempt,
            kind.as_str()
        ),
    )?;
    jobs::update_finished(tx, task.job_id, now)?;
    Ok(FailureAck {
        requeued: to == TaskState::Queued,
        task_failed: to == TaskState::Failed,
        blocked_from_job: blocked,
    })
}

/// A worker reports that it could not render its lease.
pub fn fail(
    conn: &mut Connection,
    worker: u64,
    token: TaskToken,
    message: &str,
    log: &[LogLine],
    now: i64,
    timing: Timing,
) -> Result<(u64, FailureAck)> {
    let tx = conn.transaction()?;
    workers::touch(&tx, worker, now)?;
    let task = check_token(&tx, worker, token)?;
    logs::append(&tx, task.id, token.attempt, worker, log)?;
    let ack = fail_attempt(
        &tx,
        &task,
        worker,
        FailureKind::Reported,
        message,
        now,
        timing,
    )?;
    tx.commit()?;
    Ok((task.job_id, ack))
}

/// Re-queues (or fails) every lease whose deadline passed; returns the jobs touched.
pub fn expire(conn: &mut Connection, now: i64, timing: Timing) -> Result<Vec<u64>> {
    let tx = conn.transaction()?;
    let expired = tasks::expired(&tx, now)?;
    let mut jobs = Vec::new();
    for task in &expired {
        let worker = task.worker_id.unwrap_or(0);
        fail_attempt(
            &tx,
            task,
            worker,
            FailureKind::Expired,
            "lease expired without a heartbeat",
            now,
            timing,
        )?;
        if !jobs.contains(&task.job_id) {
            jobs.push(task.job_id);
        }
    }
    tx.commit()?;
    Ok(jobs)
}

/// At startup: every lease from before the restart is taken back (no attempt counted: the
/// server, not the worker, lost it). Returns how many.
pub fn revoke_all_leases(conn: &mut Connection, now: i64) -> Result<usize> {
    let tx = conn.transaction()?;
    let leased = tasks::leased(&tx)?;
    for task in &leased {
        tasks::revoke(&tx, task)?;
    }
    if !leased.is_empty() {
        log(
            &tx,
            now,
            None,
            "leases_revoked",
            &format!("{} leases after a restart", leased.len()),
        )?;
    }
    tx.commit()?;
    Ok(leased.len())
}

/// A worker shuts down: every lease it holds goes back to the queue (no attempt counted:
/// it gave the task back rather than failing it) and it gets no more work. Returns the
/// jobs touched.
pub fn leave(conn: &mut Connection, worker: u64, now: i64) -> Result<Vec<u64>> {
    let tx = conn.transaction()?;
    workers::touch(&tx, worker, now)?;
    let held = tasks::give_back(&tx, worker)?;
    let mut jobs = Vec::new();
    for task in &held {
        if !jobs.contains(&task.job_id) {
            jobs.push(task.job_id);
        }
    }
    workers::set_left(&tx, worker, now)?;
    log(
        &tx,
        now,
        None,
        "worker_left",
        &format!("{worker}, {} leases given back", held.len()),
    )?;
    tx.commit()?;
    Ok(jobs)
}
