//! Scheduling and every task state change, each one database transaction: lease (priority,
//! then age), heartbeat, accept, fail, expire, revoke on restart, and the job controls
//! (pause, resume, cancel, retry, delete). Every state change goes through
//! [`state::transition`](crate::state::transition); times are passed in (`now`, Unix ms) so
//! tests need no clock.

use proto::{FailureAck, JobSpec, Lease, Rect, SampleSpan, TaskToken};
use rusqlite::{params, Connection, OptionalExtension, Transaction};
use tracer::film::{SampleRange, SamplingSummary, TileRect};

use crate::budget;
use crate::db::Cached;
use crate::error::{Error, Result};
use crate::spec::Plan;
use crate::state::{transition, TaskEvent, TaskState};
use crate::verify::{self, Verdict};

/// The scheduler's settings.
#[derive(Clone, Copy, Debug)]
pub struct Timing {
    /// Lease length, ms.
    pub lease_ms: i64,
    /// A worker that failed this many tasks of a job is blocked from it.
    pub block_after_failures: u32,
    /// The fraction of tasks rendered a second time to check the first (see [`verify`]).
    pub verify_fraction: f64,
    /// Tasks one job may hold, the passes a time budget adds included.
    pub max_tasks_per_job: u64,
}

/// One row of `tasks`.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskRow {
    /// Task id.
    pub id: u64,
    /// Job id.
    pub job_id: u64,
    /// Frame number.
    pub frame: i32,
    /// Tile index in the frame.
    pub tile: u32,
    /// Sample pass index.
    pub pass: u32,
    /// The tile.
    pub rect: TileRect,
    /// The samples.
    pub samples: SampleRange,
    /// State.
    pub state: TaskState,
    /// Leases granted so far (the current lease's attempt).
    pub attempt: u32,
    /// Failed or expired attempts.
    pub failures: u32,
    /// The worker holding the lease (or that rendered the tile, once done).
    pub worker_id: Option<u64>,
    /// For a check task, the render task it repeats.
    pub check_of: Option<u64>,
}

pub(crate) const TASK_COLUMNS: &str =
    "id, job_id, frame, tile, pass, x, y, w, h, sample_start, sample_end, state, attempt, \
     failures, worker_id, check_of";

pub(crate) fn task_from_row(r: &rusqlite::Row) -> rusqlite::Result<TaskRow> {
    let state: String = r.get(11)?;
    Ok(TaskRow {
        id: r.get(0)?,
        job_id: r.get(1)?,
        frame: r.get(2)?,
        tile: r.get(3)?,
        pass: r.get(4)?,
        rect: TileRect::new(r.get(5)?, r.get(6)?, r.get(7)?, r.get(8)?),
        samples: SampleRange::new(r.get(9)?, r.get(10)?),
        state: TaskState::parse(&state).ok_or_else(|| {
            rusqlite::Error::FromSqlConversionFailure(
                11,
                rusqlite::types::Type::Text,
                format!("unknown task state `{state}`").into(),
            )
        })?,
        attempt: r.get(12)?,
        failures: r.get(13)?,
        worker_id: r.get(14)?,
        check_of: r.get(15)?,
    })
}

/// The task `id`, if it exists.
pub fn load_task(conn: &Connection, id: u64) -> Result<Option<TaskRow>> {
    Ok(conn
        .row(
            &format!("SELECT {TASK_COLUMNS} FROM tasks WHERE id = ?1"),
            [id],
            task_from_row,
        )
        .optional()?)
}

/// Moves `task` by `event` through the transition table and stores the new state; the
/// caller updates the other columns in the same transaction.
fn set_state(tx: &Transaction, task: &TaskRow, event: TaskEvent) -> Result<TaskState> {
    let to = transition(task.state, event)?;
    let changed = tx.exec(
        "UPDATE tasks SET state = ?1 WHERE id = ?2 AND state = ?3",
        params![to.as_str(), task.id, task.state.as_str()],
    )?;
    if changed != 1 {
        return Err(Error::Conflict(format!(
            "task {} changed meanwhile",
            task.id
        )));
    }
    Ok(to)
}

/// Appends to the event log.
pub(crate) fn log(
    tx: &Transaction,
    now: i64,
    job: Option<u64>,
    kind: &str,
    detail: &str,
) -> Result<()> {
    tx.exec(
        "INSERT INTO events (at_ms, job_id, kind, detail) VALUES (?1, ?2, ?3, ?4)",
        params![now, job, kind, detail],
    )?;
    Ok(())
}

/// Sets or clears `jobs.finished_ms`: set when nothing is left to run (every task done,
/// failed or cancelled and every complete frame assembled), cleared when work reappears.
pub fn update_finished(tx: &Transaction, job: u64, now: i64) -> Result<()> {
    // EXISTS, not count(*): this runs on every accepted tile, and a count of a big job's
    // queue grows with the job (measured with `tessera bench farm`).
    let open: bool = tx.row(
        &format!(
            "SELECT EXISTS (SELECT 1 FROM tasks WHERE job_id = ?1
                              AND state IN ('queued', 'leased'))
                 OR EXISTS (SELECT 1 FROM frames WHERE job_id = ?1 AND {FRAME_NEEDS_ASSEMBLY})"
        ),
        [job],
        |r| r.get(0),
    )?;
    if !open {
        tx.exec(
            "UPDATE jobs SET finished_ms = coalesce(finished_ms, ?2) WHERE id = ?1",
            params![job, now],
        )?;
    } else {
        tx.exec("UPDATE jobs SET finished_ms = NULL WHERE id = ?1", [job])?;
    }
    Ok(())
}

/// Records that `worker` called now; fails if it never registered or has left.
fn touch_worker(tx: &Transaction, worker: u64, now: i64) -> Result<()> {
    let n = tx.exec(
        "UPDATE workers SET last_seen_ms = ?2 WHERE id = ?1 AND left_ms IS NULL",
        params![worker, now],
    )?;
    if n == 0 {
        return Err(Error::NotFound(format!(
            "worker {worker} is not registered or has left (the server's data folder may \
             have been replaced); register again"
        )));
    }
    Ok(())
}

/// A worker counts as live if it called within two lease periods.
pub fn live_since(now: i64, timing: Timing) -> i64 {
    now - 2 * timing.lease_ms
}

/// Stores a new job and its tasks; returns its id.
pub fn create_job(conn: &mut Connection, plan: &Plan, now: i64) -> Result<u64> {
    let tx = conn.transaction()?;
    let spec = &plan.spec;
    tx.exec(
        "INSERT INTO jobs (name, scene, spec, control, priority, max_attempts, created_ms,
                           pixel_samples)
         VALUES ('', ?1, ?2, 'active', ?3, ?4, ?5, ?6)",
        params![
            spec.scene,
            serde_json::to_string(spec)?,
            spec.priority,
            spec.max_attempts,
            now,
            plan.pixel_samples() as i64
        ],
    )?;
    let id = tx.last_insert_rowid() as u64;
    let name = spec.name.clone().unwrap_or_else(|| format!("job {id}"));
    tx.exec("UPDATE jobs SET name = ?2 WHERE id = ?1", params![id, name])?;
    {
        let mut frame = tx.prepare_cached(
            "INSERT INTO frames (job_id, frame, tasks_total) VALUES (?1, ?2, ?3)",
        )?;
        for &f in &plan.frames {
            frame.execute(params![id, f, plan.tasks_per_frame()])?;
        }
        for t in plan.tasks() {
            insert_task(&tx, id, t.frame, t.tile, t.pass, t.rect, t.samples)?;
        }
    }
    // No worker has a speed on a new job: the plan says the first pass is queued.
    budget::replan(&tx, id, spec, now, now, u64::MAX)?;
    log(
        &tx,
        now,
        Some(id),
        "job_created",
        &format!("{} tasks", plan.task_count()),
    )?;
    tx.commit()?;
    Ok(id)
}

/// Queues one task.
pub(crate) fn insert_task(
    tx: &Transaction,
    job: u64,
    frame: i32,
    tile: u32,
    pass: u32,
    rect: TileRect,
    samples: SampleRange,
) -> Result<()> {
    tx.prepare_cached(
        "INSERT INTO tasks (job_id, frame, tile, pass, x, y, w, h, sample_start, sample_end,
                            state)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, 'queued')",
    )?
    .execute(params![
        job,
        frame,
        tile,
        pass,
        rect.x,
        rect.y,
        rect.width,
        rect.height,
        samples.start,
        samples.end
    ])?;
    Ok(())
}

/// A check task (`t`) goes to a worker (`?2`) that has not rendered its tile yet.
const NOT_IN_CHECK_GROUP: &str = "(t.check_of IS NULL OR NOT EXISTS (
        SELECT 1 FROM tasks g WHERE (g.id = t.check_of OR g.check_of = t.check_of)
          AND g.state = 'done' AND g.worker_id = ?2))";

/// The next queued task for `worker` in job `job`: tasks it has not failed first; a task
/// it failed only when no other live worker could take it. Frame by frame, pass by pass;
/// a time-budget job's in the order its plan issued them (frame order would starve a
/// late frame's pass behind the passes planned for earlier frames after it).
fn next_task_in_job(
    tx: &Transaction,
    job: u64,
    budget: bool,
    worker: u64,
    live_since: i64,
) -> Result<Option<u64>> {
    let order = if budget {
        "t.id"
    } else {
        "t.frame, t.pass, t.tile"
    };
    let fresh: Option<u64> = tx
        .row(
            &format!(
                "SELECT t.id FROM tasks t
             WHERE t.state = 'queued' AND t.job_id = ?1 AND {NOT_IN_CHECK_GROUP}
               AND NOT EXISTS (SELECT 1 FROM task_failures f
                               WHERE f.task_id = t.id AND f.worker_id = ?2)
             ORDER BY {order} LIMIT 1"
            ),
            params![job, worker],
            |r| r.get(0),
        )
        .optional()?;
    if fresh.is_some() {
        return Ok(fresh);
    }
    Ok(tx
        .row(
            &format!(
                "SELECT t.id FROM tasks t
             WHERE t.state = 'queued' AND t.job_id = ?1 AND {NOT_IN_CHECK_GROUP}
               AND NOT EXISTS (
                   SELECT 1 FROM workers w
                   WHERE w.id != ?2 AND w.last_seen_ms >= ?3 AND w.left_ms IS NULL
                     AND w.quarantined_ms IS NULL
                     AND NOT EXISTS (SELECT 1 FROM task_failures f
                                     WHERE f.task_id = t.id AND f.worker_id = w.id)
                     AND NOT EXISTS (SELECT 1 FROM job_blocks b
                                     WHERE b.job_id = t.job_id AND b.worker_id = w.id))
             ORDER BY {order} LIMIT 1"
            ),
            params![job, worker, live_since],
            |r| r.get(0),
        )
        .optional()?)
}

/// Leases the next task to `worker`: active jobs by priority (highest first), then age;
/// within a job, frame by frame and pass by pass so that previews fill in evenly.
pub fn lease(
    conn: &mut Connection,
    worker: u64,
    now: i64,
    timing: Timing,
) -> Result<Option<Lease>> {
    let tx = conn.transaction()?;
    touch_worker(&tx, worker, now)?;
    if verify::is_quarantined(&tx, worker)? {
        tx.commit()?;
        return Ok(None);
    }
    let live_since = live_since(now, timing);
    let jobs: Vec<(u64, bool)> = {
        let mut stmt = tx.prepare_cached(
            "SELECT j.id, j.budget_plan IS NOT NULL FROM jobs j
             WHERE j.control = 'active'
               AND EXISTS (SELECT 1 FROM tasks t WHERE t.job_id = j.id AND t.state = 'queued')
               AND NOT EXISTS (SELECT 1 FROM job_blocks b
                               WHERE b.job_id = j.id AND b.worker_id = ?1)
             ORDER BY j.priority DESC, j.created_ms, j.id",
        )?;
        let rows = stmt.query_map([worker], |r| Ok((r.get(0)?, r.get(1)?)))?;
        rows.collect::<rusqlite::Result<_>>()?
    };
    let mut chosen = None;
    for (job, budget) in jobs {
        if let Some(id) = next_task_in_job(&tx, job, budget, worker, live_since)? {
            chosen = Some(id);
            break;
        }
    }
    let Some(id) = chosen else {
        tx.commit()?;
        return Ok(None);
    };
    let task = load_task(&tx, id)?.ok_or_else(|| Error::Internal("task vanished".into()))?;
    set_state(&tx, &task, TaskEvent::Lease)?;
    let deadline = now + timing.lease_ms;
    let attempt = task.attempt + 1;
    tx.exec(
        "UPDATE tasks SET attempt = ?2, worker_id = ?3, leased_ms = ?4, deadline_ms = ?5
         WHERE id = ?1",
        params![id, attempt, worker, now, deadline],
    )?;
    tx.exec(
        "UPDATE jobs SET first_lease_ms = coalesce(first_lease_ms, ?2) WHERE id = ?1",
        params![task.job_id, now],
    )?;
    let spec = job_spec(&tx, task.job_id)?;
    tx.commit()?;
    Ok(Some(Lease {
        token: TaskToken {
            task_id: id,
            attempt,
        },
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
        deadline_ms: deadline,
    }))
}

/// The resolved spec of a job.
pub fn job_spec(conn: &Connection, job: u64) -> Result<JobSpec> {
    let json: String = conn
        .row("SELECT spec FROM jobs WHERE id = ?1", [job], |r| r.get(0))
        .optional()?
        .ok_or_else(|| Error::NotFound(format!("job {job} does not exist")))?;
    Ok(serde_json::from_str(&json)?)
}

/// Checks that `token` is `worker`'s current lease; the error says why not, for the
/// worker's log.
pub fn check_token(conn: &Connection, worker: u64, token: TaskToken) -> Result<TaskRow> {
    let task = load_task(conn, token.task_id)?.ok_or_else(|| {
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
    let control: String = conn.row(
        "SELECT control FROM jobs WHERE id = ?1",
        [task.job_id],
        |r| r.get(0),
    )?;
    let why = match (task.state, control.as_str()) {
        (_, "paused") => format!("job {} is paused", task.job_id),
        (TaskState::Cancelled, _) | (_, "cancelled") => format!("job {} is cancelled", task.job_id),
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

/// A heartbeat: extends `token`'s lease and returns the new deadline, or says the lease
/// is gone (paused, cancelled, expired). Without a token it only marks the worker alive.
pub fn heartbeat(
    conn: &mut Connection,
    worker: u64,
    token: Option<TaskToken>,
    now: i64,
    timing: Timing,
) -> Result<Option<i64>> {
    let tx = conn.transaction()?;
    touch_worker(&tx, worker, now)?;
    let Some(token) = token else {
        tx.commit()?;
        return Ok(None);
    };
    let result = check_token(&tx, worker, token).and_then(|task| {
        let deadline = now + timing.lease_ms;
        tx.exec(
            "UPDATE tasks SET deadline_ms = ?2 WHERE id = ?1",
            params![task.id, deadline],
        )?;
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
    },
}

/// Whether an upload for `token` should be read at all: `Ok(true)` for the current lease,
/// `Ok(false)` for a task already done (a duplicate to ignore), else the lease is gone.
pub fn precheck_upload(
    conn: &Connection,
    worker: u64,
    token: TaskToken,
) -> Result<(bool, TaskRow)> {
    if let Some(task) = load_task(conn, token.task_id)? {
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
    touch_worker(&tx, worker, now)?;
    let (fresh, task) = precheck_upload(&tx, worker, token)?;
    if !fresh {
        tx.commit()?;
        return Ok(Accepted::Duplicate);
    }
    set_state(&tx, &task, TaskEvent::Complete)?;
    tx.exec(
        "UPDATE tasks SET done_ms = ?2, rays = ?3, render_ms = ?4, deadline_ms = NULL
         WHERE id = ?1",
        params![task.id, now, rays as i64, render_ms as i64],
    )?;
    tx.exec(
        "UPDATE workers SET tasks_done = tasks_done + 1 WHERE id = ?1",
        [worker],
    )?;
    tx.exec(
        "UPDATE frames SET tasks_done = tasks_done + 1 WHERE job_id = ?1 AND frame = ?2",
        params![task.job_id, task.frame],
    )?;
    match (task.check_of, verdict) {
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
            live_since(now, timing),
            now,
        )?,
    }
    let frame_complete: bool = tx.row(
        "SELECT tasks_done = tasks_total FROM frames WHERE job_id = ?1 AND frame = ?2",
        params![task.job_id, task.frame],
        |r| r.get(0),
    )?;
    let pass_left: i64 = tx.row(
        "SELECT count(*) FROM tasks WHERE job_id = ?1 AND frame = ?2 AND pass = ?3
           AND state != 'done' AND check_of IS NULL",
        params![task.job_id, task.frame, task.pass],
        |r| r.get(0),
    )?;
    update_finished(&tx, task.job_id, now)?;
    tx.commit()?;
    Ok(Accepted::New {
        job: task.job_id,
        frame: task.frame,
        pass: task.pass,
        frame_complete,
        pass_complete: pass_left == 0,
    })
}

/// Records a failed attempt of `task` by `worker` (reported or expired): re-queues it, or
/// fails it past its job's max attempts, and blocks the worker from the job once it has
/// failed `block_after_failures` of its tasks.
fn fail_attempt(
    tx: &Transaction,
    task: &TaskRow,
    worker: u64,
    reason: &str,
    message: &str,
    now: i64,
    timing: Timing,
) -> Result<FailureAck> {
    let max_attempts: u32 = tx.row(
        "SELECT max_attempts FROM jobs WHERE id = ?1",
        [task.job_id],
        |r| r.get(0),
    )?;
    let failures = task.failures + 1;
    let exhausted = failures >= max_attempts;
    let event = match reason {
        "expired" => TaskEvent::Expire { exhausted },
        _ => TaskEvent::Fail { exhausted },
    };
    let to = set_state(tx, task, event)?;
    tx.exec(
        "UPDATE tasks SET failures = ?2, worker_id = NULL, deadline_ms = NULL WHERE id = ?1",
        params![task.id, failures],
    )?;
    tx.exec(
        "INSERT INTO task_failures (task_id, job_id, worker_id, attempt, reason, message, at_ms)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
        params![
            task.id,
            task.job_id,
            worker,
            task.attempt,
            reason,
            message,
            now
        ],
    )?;
    let by_worker: u32 = tx.row(
        "SELECT count(*) FROM task_failures WHERE job_id = ?1 AND worker_id = ?2",
        params![task.job_id, worker],
        |r| r.get(0),
    )?;
    let blocked = by_worker >= timing.block_after_failures;
    if blocked {
        let added = tx.exec(
            "INSERT OR IGNORE INTO job_blocks (job_id, worker_id) VALUES (?1, ?2)",
            params![task.job_id, worker],
        )?;
        if added > 0 {
            log(
                tx,
                now,
                Some(task.job_id),
                "worker_blocked",
                &format!("worker {worker} failed {by_worker} tasks of the job"),
            )?;
        }
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
            "task {} attempt {} on worker {worker} ({reason}): {message}",
            task.id, task.attempt
        ),
    )?;
    update_finished(tx, task.job_id, now)?;
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
    now: i64,
    timing: Timing,
) -> Result<(u64, FailureAck)> {
    let tx = conn.transaction()?;
    touch_worker(&tx, worker, now)?;
    let task = check_token(&tx, worker, token)?;
    let ack = fail_attempt(&tx, &task, worker, "reported", message, now, timing)?;
    tx.commit()?;
    Ok((task.job_id, ack))
}

/// Re-queues (or fails) every lease whose deadline passed; returns the jobs touched.
pub fn expire(conn: &mut Connection, now: i64, timing: Timing) -> Result<Vec<u64>> {
    let tx = conn.transaction()?;
    let expired: Vec<TaskRow> = {
        let mut stmt = tx.prepare_cached(&format!(
            "SELECT {TASK_COLUMNS} FROM tasks WHERE state = 'leased' AND deadline_ms < ?1"
        ))?;
        let rows = stmt.query_map([now], task_from_row)?;
        rows.collect::<rusqlite::Result<_>>()?
    };
    let mut jobs = Vec::new();
    for task in &expired {
        let worker = task.worker_id.unwrap_or(0);
        fail_attempt(
            &tx,
            task,
            worker,
            "expired",
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
    let leased: Vec<TaskRow> = {
        let mut stmt = tx.prepare_cached(&format!(
            "SELECT {TASK_COLUMNS} FROM tasks WHERE state = 'leased'"
        ))?;
        let rows = stmt.query_map([], task_from_row)?;
        rows.collect::<rusqlite::Result<_>>()?
    };
    for task in &leased {
        revoke(&tx, task)?;
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
    touch_worker(&tx, worker, now)?;
    let held = give_back(&tx, worker)?;
    let mut jobs = Vec::new();
    for task in &held {
        if !jobs.contains(&task.job_id) {
            jobs.push(task.job_id);
        }
    }
    tx.exec(
        "UPDATE workers SET left_ms = ?2 WHERE id = ?1",
        params![worker, now],
    )?;
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

/// Queues again every task `worker` holds a lease on (no attempt is counted: it said it is
/// gone, or came back); returns them.
pub(crate) fn give_back(tx: &Transaction, worker: u64) -> Result<Vec<TaskRow>> {
    let held: Vec<TaskRow> = {
        let mut stmt = tx.prepare_cached(&format!(
            "SELECT {TASK_COLUMNS} FROM tasks WHERE state = 'leased' AND worker_id = ?1"
        ))?;
        let rows = stmt.query_map([worker], task_from_row)?;
        rows.collect::<rusqlite::Result<_>>()?
    };
    for task in &held {
        revoke(tx, task)?;
    }
    Ok(held)
}

pub(crate) fn revoke(tx: &Transaction, task: &TaskRow) -> Result<()> {
    set_state(tx, task, TaskEvent::Revoke)?;
    tx.exec(
        "UPDATE tasks SET worker_id = NULL, deadline_ms = NULL WHERE id = ?1",
        [task.id],
    )?;
    Ok(())
}

fn job_tasks(tx: &Transaction, job: u64, states: &[TaskState]) -> Result<Vec<TaskRow>> {
    let list: Vec<String> = states.iter().map(|s| format!("'{}'", s.as_str())).collect();
    let mut stmt = tx.prepare_cached(&format!(
        "SELECT {TASK_COLUMNS} FROM tasks WHERE job_id = ?1 AND state IN ({})",
        list.join(", ")
    ))?;
    let rows = stmt.query_map([job], task_from_row)?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

fn job_control(tx: &Transaction, job: u64) -> Result<String> {
    tx.row("SELECT control FROM jobs WHERE id = ?1", [job], |r| {
        r.get(0)
    })
    .optional()?
    .ok_or_else(|| Error::NotFound(format!("job {job} does not exist")))
}

fn job_finished(tx: &Transaction, job: u64) -> Result<bool> {
    Ok(tx.row(
        "SELECT finished_ms IS NOT NULL FROM jobs WHERE id = ?1",
        [job],
        |r| r.get(0),
    )?)
}

/// Pauses a job: nothing more is leased, and its live leases are taken back (their
/// workers hear 409 on their next heartbeat).
pub fn pause(conn: &mut Connection, job: u64, now: i64) -> Result<()> {
    let tx = conn.transaction()?;
    match job_control(&tx, job)?.as_str() {
        "cancelled" => return Err(Error::Conflict(format!("job {job} is cancelled"))),
        "paused" => return Ok(()),
        _ => {}
    }
    if job_finished(&tx, job)? {
        return Err(Error::Conflict(format!(
            "job {job} has nothing left to run"
        )));
    }
    tx.exec("UPDATE jobs SET control = 'paused' WHERE id = ?1", [job])?;
    for task in job_tasks(&tx, job, &[TaskState::Leased])? {
        revoke(&tx, &task)?;
    }
    log(&tx, now, Some(job), "job_paused", "")?;
    tx.commit()?;
    Ok(())
}

/// Resumes a paused job.
pub fn resume(conn: &mut Connection, job: u64, now: i64) -> Result<()> {
    let tx = conn.transaction()?;
    match job_control(&tx, job)?.as_str() {
        "cancelled" => return Err(Error::Conflict(format!("job {job} is cancelled"))),
        "active" => return Ok(()),
        _ => {}
    }
    tx.exec("UPDATE jobs SET control = 'active' WHERE id = ?1", [job])?;
    log(&tx, now, Some(job), "job_resumed", "")?;
    tx.commit()?;
    Ok(())
}

/// Cancels a job: its queued and leased tasks are cancelled (workers hear 409).
pub fn cancel(conn: &mut Connection, job: u64, now: i64) -> Result<()> {
    let tx = conn.transaction()?;
    if job_control(&tx, job)? == "cancelled" {
        return Ok(());
    }
    let open = job_tasks(&tx, job, &[TaskState::Queued, TaskState::Leased])?;
    if open.is_empty() && job_finished(&tx, job)? {
        return Err(Error::Conflict(format!("job {job} has already finished")));
    }
    tx.exec("UPDATE jobs SET control = 'cancelled' WHERE id = ?1", [job])?;
    for task in &open {
        set_state(&tx, task, TaskEvent::Cancel)?;
        tx.exec(
            "UPDATE tasks SET worker_id = NULL, deadline_ms = NULL WHERE id = ?1",
            [task.id],
        )?;
    }
    log(
        &tx,
        now,
        Some(job),
        "job_cancelled",
        &format!("{} tasks cancelled", open.len()),
    )?;
    update_finished(&tx, job, now)?;
    tx.commit()?;
    Ok(())
}

/// Re-queues a job's failed tasks with fresh attempts, lifts its worker blocks, and lets
/// frames whose assembly failed be assembled again. Returns how many tasks and frames.
pub fn retry(conn: &mut Connection, job: u64, now: i64) -> Result<usize> {
    let tx = conn.transaction()?;
    if job_control(&tx, job)? == "cancelled" {
        return Err(Error::Conflict(format!("job {job} is cancelled")));
    }
    let failed = job_tasks(&tx, job, &[TaskState::Failed])?;
    let frames = tx.exec(
        "UPDATE frames SET failure = NULL WHERE job_id = ?1 AND failure IS NOT NULL",
        [job],
    )?;
    if failed.is_empty() && frames == 0 {
        return Err(Error::Conflict(format!(
            "job {job} has no failed tasks or frames"
        )));
    }
    for task in &failed {
        set_state(&tx, task, TaskEvent::Retry)?;
        tx.exec("UPDATE tasks SET failures = 0 WHERE id = ?1", [task.id])?;
        tx.exec("DELETE FROM task_failures WHERE task_id = ?1", [task.id])?;
    }
    tx.exec("DELETE FROM job_blocks WHERE job_id = ?1", [job])?;
    log(
        &tx,
        now,
        Some(job),
        "job_retried",
        &format!("{} tasks, {frames} frames", failed.len()),
    )?;
    update_finished(&tx, job, now)?;
    tx.commit()?;
    Ok(failed.len() + frames)
}

/// Deletes a job's rows (its files are removed by the caller after this commits).
pub fn delete_job(conn: &mut Connection, job: u64, now: i64) -> Result<()> {
    let tx = conn.transaction()?;
    job_control(&tx, job)?;
    tx.exec("DELETE FROM jobs WHERE id = ?1", [job])?;
    log(&tx, now, Some(job), "job_deleted", "")?;
    tx.commit()?;
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
    tx.exec(
        "UPDATE frames SET assembled_ms = ?3, assembled_tasks = tasks_total, spp_mean = ?4,
                           noise = ?5
         WHERE job_id = ?1 AND frame = ?2",
        params![job, frame, now, reached.mean_samples, reached.mean_noise],
    )?;
    log(&tx, now, Some(job), "frame_assembled", &frame.to_string())?;
    replan(&tx, job, now, timing)?;
    update_finished(&tx, job, now)?;
    tx.commit()?;
    Ok(())
}

/// [`budget::replan`] with the scheduler's settings.
fn replan(tx: &Transaction, job: u64, now: i64, timing: Timing) -> Result<()> {
    budget::replan(
        tx,
        job,
        &job_spec(tx, job)?,
        now,
        live_since(now, timing),
        timing.max_tasks_per_job,
    )
}

/// Plans every unfinished active time-budget job again (the sweeper does, every tick, so
/// that a worker joining or leaving between two frames changes the plan at once);
/// returns those jobs.
pub fn replan_budgets(conn: &mut Connection, now: i64, timing: Timing) -> Result<Vec<u64>> {
    let tx = conn.transaction()?;
    let jobs: Vec<u64> = {
        let mut stmt = tx.prepare_cached(
            "SELECT id FROM jobs
             WHERE budget_plan IS NOT NULL AND finished_ms IS NULL AND control = 'active'",
        )?;
        let rows = stmt.query_map([], |r| r.get(0))?;
        rows.collect::<rusqlite::Result<_>>()?
    };
    for &job in &jobs {
        replan(&tx, job, now, timing)?;
        update_finished(&tx, job, now)?;
    }
    tx.commit()?;
    Ok(jobs)
}

/// Whether a job has finished with no failed task (nothing of it can run again).
pub fn finished_cleanly(conn: &Connection, job: u64) -> Result<bool> {
    Ok(conn.row(
        "SELECT finished_ms IS NOT NULL
                AND NOT EXISTS (SELECT 1 FROM tasks WHERE job_id = ?1 AND state = 'failed')
         FROM jobs WHERE id = ?1",
        [job],
        |r| r.get(0),
    )?)
}

/// Frames whose tasks are all done but which are not assembled from all of them (a crash
/// in between, or a full disk), of jobs not cancelled.
pub fn unassembled_frames(conn: &Connection) -> Result<Vec<(u64, i32)>> {
    let mut stmt = conn.prepare_cached(&format!(
        "SELECT job_id, frame FROM frames JOIN jobs ON jobs.id = frames.job_id
         WHERE control != 'cancelled' AND {FRAME_NEEDS_ASSEMBLY}"
    ))?;
    let rows = stmt.query_map([], |r| Ok((r.get(0)?, r.get(1)?)))?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// Whether a frame of `job` should still be assembled: `NotFound` once the job is
/// deleted, `Conflict` once it is cancelled (an assembly under way stops).
pub fn assembly_wanted(conn: &Connection, job: u64) -> Result<()> {
    let control: Option<String> = conn
        .row("SELECT control FROM jobs WHERE id = ?1", [job], |r| {
            r.get(0)
        })
        .optional()?;
    match control.as_deref() {
        None => Err(Error::NotFound(format!("job {job} was deleted"))),
        Some("cancelled") => Err(Error::Conflict(format!("job {job} was cancelled"))),
        Some(_) => Ok(()),
    }
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
    tx.exec(
        "UPDATE frames SET failure = ?3 WHERE job_id = ?1 AND frame = ?2",
        params![job, frame, reason],
    )?;
    log(
        &tx,
        now,
        Some(job),
        "frame_failed",
        &format!("{frame}: {reason}"),
    )?;
    update_finished(&tx, job, now)?;
    tx.commit()?;
    Ok(())
}

/// Whether a frame is assembled from all of its tasks so far.
pub fn is_assembled(conn: &Connection, job: u64, frame: i32) -> Result<bool> {
    Ok(conn.row(
        "SELECT assembled_tasks IS tasks_total FROM frames WHERE job_id = ?1 AND frame = ?2",
        params![job, frame],
        |r| r.get(0),
    )?)
}

/// A frame (row of `frames`) whose tasks are all done but that is not assembled from all
/// of them: a time-budget frame that got a pass is assembled again.
const FRAME_NEEDS_ASSEMBLY: &str =
    "tasks_done = tasks_total AND assembled_tasks IS NOT tasks_total AND failure IS NULL";

/// The done render tasks of one frame (for assembly), by tile then pass.
pub fn done_tasks_of_frame(conn: &Connection, job: u64, frame: i32) -> Result<Vec<TaskRow>> {
    let mut stmt = conn.prepare_cached(&format!(
        "SELECT {TASK_COLUMNS} FROM tasks WHERE job_id = ?1 AND frame = ?2 AND state = 'done'
           AND check_of IS NULL
         ORDER BY tile, pass"
    ))?;
    let rows = stmt.query_map(params![job, frame], task_from_row)?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// Seconds the workers spent rendering one frame's tiles (its done tasks, checks left
/// out), as they reported.
pub fn frame_render_seconds(conn: &Connection, job: u64, frame: i32) -> Result<f64> {
    let ms: Option<i64> = conn.row(
        "SELECT SUM(render_ms) FROM tasks WHERE job_id = ?1 AND frame = ?2 AND state = 'done'
           AND check_of IS NULL",
        params![job, frame],
        |r| r.get(0),
    )?;
    Ok(ms.unwrap_or(0) as f64 / 1000.0)
}

/// What the scene of `job` needs from the tracer (its summary's `features`).
pub fn job_scene_features(conn: &Connection, job: u64) -> Result<Vec<String>> {
    let json: String = conn.row(
        "SELECT scenes.info FROM jobs JOIN scenes ON scenes.digest = jobs.scene
         WHERE jobs.id = ?1",
        [job],
        |r| r.get(0),
    )?;
    Ok(serde_json::from_str::<proto::SceneInfo>(&json)?.features)
}

/// The ids of one frame's done check tasks (whose tiles go once the frame is assembled).
pub fn done_checks_of_frame(conn: &Connection, job: u64, frame: i32) -> Result<Vec<u64>> {
    let mut stmt = conn.prepare_cached(
        "SELECT id FROM tasks WHERE job_id = ?1 AND frame = ?2 AND state = 'done'
           AND check_of IS NOT NULL",
    )?;
    let rows = stmt.query_map(params![job, frame], |r| r.get(0))?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

#[cfg(test)]
#[path = "scheduler_tests.rs"]
mod tests;
