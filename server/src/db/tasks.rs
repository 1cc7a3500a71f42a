//! The `tasks` table (and `task_failures`): rows, the state column moved only through
//! [`crate::state::transition`], the queries the scheduler leases by, and the sets of tasks
//! assembly, checks and time budgets read.

use proto::TaskKind;
use rusqlite::{params, Connection, OptionalExtension, Transaction};
use tracer::film::{SampleRange, TileRect};

use super::{has_required_tags, Cached};
use crate::error::{Error, Result};
use crate::state::{transition, TaskEvent, TaskState};

/// One row of `tasks`.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskRow {
    /// Task id.
    pub id: u64,
    /// Render a tile, or denoise a frame.
    pub kind: TaskKind,
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

const COLUMNS: &str = "t.id, t.job_id, t.frame, t.tile, t.pass, t.x, t.y, t.w, t.h, \
     t.sample_start, t.sample_end, t.state, t.attempt, t.failures, t.worker_id, t.check_of, \
     t.kind";

fn from_row(r: &rusqlite::Row) -> rusqlite::Result<TaskRow> {
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
        kind: {
            let kind: String = r.get(16)?;
            TaskKind::parse(&kind).ok_or_else(|| {
                rusqlite::Error::FromSqlConversionFailure(
                    16,
                    rusqlite::types::Type::Text,
                    format!("unknown task kind `{kind}`").into(),
                )
            })?
        },
    })
}

/// The tasks (`t`) matching `filter` (SQL over `t`), with `params`.
fn select<P: rusqlite::Params>(conn: &Connection, filter: &str, params: P) -> Result<Vec<TaskRow>> {
    let mut stmt = conn.prepare_cached(&format!("SELECT {COLUMNS} FROM tasks t WHERE {filter}"))?;
    let rows = stmt.query_map(params, from_row)?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// The task `id`, if it exists.
pub fn load(conn: &Connection, id: u64) -> Result<Option<TaskRow>> {
    Ok(conn
        .row(
            &format!("SELECT {COLUMNS} FROM tasks t WHERE t.id = ?1"),
            [id],
            from_row,
        )
        .optional()?)
}

/// Moves `task` by `event` through the transition table and stores the new state; the
/// caller updates the other columns in the same transaction.
pub fn advance(tx: &Transaction, task: &TaskRow, event: TaskEvent) -> Result<TaskState> {
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

/// What a new task does.
#[derive(Clone, Copy, Debug)]
pub struct NewTask {
    /// Render a tile, or denoise a frame.
    pub kind: TaskKind,
    /// Its job.
    pub job: u64,
    /// Its frame.
    pub frame: i32,
    /// Its tile's index.
    pub tile: u32,
    /// Its sample pass.
    pub pass: u32,
    /// The tile.
    pub rect: TileRect,
    /// The samples.
    pub samples: SampleRange,
    /// The render task it checks, for a check task.
    pub check_of: Option<u64>,
    /// Leased before tasks of higher rounds (preview-first order).
    pub round: u32,
}

impl NewTask {
    /// A check of the render task `task`: the same tile and samples.
    pub fn check_of(task: &TaskRow) -> NewTask {
        NewTask {
            kind: TaskKind::Render,
            job: task.job_id,
            frame: task.frame,
            tile: task.tile,
            pass: task.pass,
            rect: task.rect,
            samples: task.samples,
            check_of: Some(task.id),
            // A check goes early: a worker found wrong should be found soon.
            round: 0,
        }
    }

    /// The encode task of a job whose frames are all finished: the first frame as its
    /// frame, the whole frame size, no samples.
    pub fn encode(job: u64, first_frame: i32, size: (u32, u32)) -> NewTask {
        NewTask {
            kind: TaskKind::Encode,
            ..NewTask::denoise(job, first_frame, size)
        }
    }

    /// The denoise task of an assembled frame of `size`: the whole frame, no samples,
    /// leased before the later frames' tiles (round 0), so that frames finish in order.
    pub fn denoise(job: u64, frame: i32, size: (u32, u32)) -> NewTask {
        NewTask {
            kind: TaskKind::Denoise,
            job,
            frame,
            tile: 0,
            pass: 0,
            rect: TileRect::new(0, 0, size.0, size.1),
            samples: SampleRange::new(0, 0),
            check_of: None,
            round: 0,
        }
    }
}

/// Queues one task.
pub fn insert(tx: &Transaction, t: &NewTask) -> Result<()> {
    tx.exec(
        "INSERT INTO tasks (job_id, frame, tile, pass, x, y, w, h, sample_start, sample_end,
                            state, check_of, round, kind)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, 'queued', ?11, ?12, ?13)",
        params![
            t.job,
            t.frame,
            t.tile,
            t.pass,
            t.rect.x,
            t.rect.y,
            t.rect.width,
            t.rect.height,
            t.samples.start,
            t.samples.end,
            t.check_of,
            t.round,
            t.kind.as_str()
        ],
    )?;
    Ok(())
}

/// A task `t` that the worker `?N` can do: a render task, a denoise task when it has a
/// denoiser, an encode task when it has an encoder.
fn can_take(worker: &str) -> String {
    format!(
        "(t.kind = 'render' OR EXISTS (SELECT 1 FROM workers d WHERE d.id = {worker}
           AND {}))",
        has_step("d")
    )
}

/// The worker `w` has what the task `t` needs beyond rendering.
fn has_step(w: &str) -> String {
    format!(
        "((t.kind = 'denoise' AND {w}.denoiser IS NOT NULL)
          OR (t.kind = 'encode' AND {w}.encoder IS NOT NULL))"
    )
}

/// Active jobs with a queued task that `worker` can do, has the tags for and is not
/// blocked from, with whether each is a time-budget job: by priority (highest first), then
/// age.
pub fn leasable_jobs(tx: &Transaction, worker: u64) -> Result<Vec<(u64, bool)>> {
    let mut stmt = tx.prepare_cached(&format!(
        "SELECT j.id, j.budget_plan IS NOT NULL FROM jobs j
         WHERE j.control = 'active'
           AND EXISTS (SELECT 1 FROM tasks t WHERE t.job_id = j.id AND t.state = 'queued'
                         AND {})
           AND NOT EXISTS (SELECT 1 FROM job_blocks b
                           WHERE b.job_id = j.id AND b.worker_id = ?1)
           AND {}
         ORDER BY j.priority DESC, j.created_ms, j.id",
        can_take("?1"),
        has_required_tags("j.spec", "(SELECT tags FROM workers WHERE id = ?1)")
    ))?;
    let rows = stmt.query_map([worker], |r| Ok((r.get(0)?, r.get(1)?)))?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// A check task (`t`) goes to a worker (`?2`) that has not rendered its tile yet.
const NOT_IN_CHECK_GROUP: &str = "(t.check_of IS NULL OR NOT EXISTS (
        SELECT 1 FROM tasks g WHERE (g.id = t.check_of OR g.check_of = t.check_of)
          AND g.state = 'done' AND g.worker_id = ?2))";

/// The lease order of a job's tasks: preview round, frame, pass, tile.
const FRAME_ORDER: &str = "t.round, t.frame, t.pass, t.tile";
/// A time-budget job's: as its plan issued them.
const BUDGET_ORDER: &str = "t.id";

/// The next queued task for `worker` in job `job`: tasks it has not failed first; a task
/// it failed only when no other live worker (seen since `live_since`) could take it.
/// Round by round (preview-first frames, then the rest), frame by frame, pass by pass; a
/// time-budget job's (`budget`) in the order its plan issued them (frame order would starve a late frame's pass behind the passes planned
/// for earlier frames after it).
pub fn next_for(
    tx: &Transaction,
    job: u64,
    budget: bool,
    worker: u64,
    live_since: i64,
) -> Result<Option<u64>> {
    let order = if budget { BUDGET_ORDER } else { FRAME_ORDER };
    let tagged = has_required_tags("(SELECT spec FROM jobs WHERE id = t.job_id)", "w.tags");
    let fresh: Option<u64> = tx
        .row(&next_fresh_sql(order), params![job, worker], |r| r.get(0))
        .optional()?;
    if fresh.is_some() {
        return Ok(fresh);
    }
    Ok(tx
        .row(
            &format!(
                "SELECT t.id FROM tasks t
             WHERE t.state = 'queued' AND t.job_id = ?1 AND {NOT_IN_CHECK_GROUP}
               AND {}
               AND NOT EXISTS (
                   SELECT 1 FROM workers w
                   WHERE w.id != ?2 AND w.last_seen_ms >= ?3 AND w.left_ms IS NULL
                     AND w.quarantined_ms IS NULL
                     AND (t.kind = 'render' OR {})
                     AND {tagged}
                     AND NOT EXISTS (SELECT 1 FROM task_failures f
                                     WHERE f.task_id = t.id AND f.worker_id = w.id)
                     AND NOT EXISTS (SELECT 1 FROM job_blocks b
                                     WHERE b.job_id = t.job_id AND b.worker_id = w.id))
             ORDER BY {order} LIMIT 1",
                can_take("?2"),
                has_step("w")
            ),
            params![job, worker, live_since],
            |r| r.get(0),
        )
        .optional()?)
}

/// The next queued task of job `?1` that worker `?2` has not failed, in `order`.
fn next_fresh_sql(order: &str) -> String {
    format!(
        "SELECT t.id FROM tasks t
         WHERE t.state = 'queued' AND t.job_id = ?1 AND {NOT_IN_CHECK_GROUP} AND {}
           AND NOT EXISTS (SELECT 1 FROM task_failures f
                           WHERE f.task_id = t.id AND f.worker_id = ?2)
         ORDER BY {order} LIMIT 1",
        can_take("?2")
    )
}

/// Records the lease of a task the caller moved to leased.
pub fn set_lease(
    tx: &Transaction,
    task: u64,
    attempt: u32,
    worker: u64,
    now: i64,
    deadline: i64,
) -> Result<()> {
    tx.exec(
        "UPDATE tasks SET attempt = ?2, worker_id = ?3, leased_ms = ?4, deadline_ms = ?5
         WHERE id = ?1",
        params![task, attempt, worker, now, deadline],
    )?;
    Ok(())
}

/// Moves a lease's deadline.
pub fn extend_lease(tx: &Transaction, task: u64, deadline: i64) -> Result<()> {
    tx.exec(
        "UPDATE tasks SET deadline_ms = ?2 WHERE id = ?1",
        params![task, deadline],
    )?;
    Ok(())
}

/// Records the result of a task the caller moved to done.
pub fn set_done(tx: &Transaction, task: u64, now: i64, rays: u64, render_ms: u64) -> Result<()> {
    tx.exec(
        "UPDATE tasks SET done_ms = ?2, rays = ?3, render_ms = ?4, deadline_ms = NULL
         WHERE id = ?1",
        params![task, now, rays as i64, render_ms as i64],
    )?;
    Ok(())
}

/// Clears the lease of a task the caller moved out of leased (queued, failed, cancelled).
pub fn clear_lease(tx: &Transaction, task: u64) -> Result<()> {
    tx.exec(
        "UPDATE tasks SET worker_id = NULL, deadline_ms = NULL WHERE id = ?1",
        [task],
    )?;
    Ok(())
}

/// Every task of `job` has all its attempts again.
pub fn reset_failures(tx: &Transaction, job: u64) -> Result<()> {
    tx.exec(
        "UPDATE tasks SET failures = 0 WHERE job_id = ?1 AND failures > 0",
        [job],
    )?;
    Ok(())
}

/// Sets how many attempts of a task failed.
pub fn set_failures(tx: &Transaction, task: u64, failures: u32) -> Result<()> {
    tx.exec(
        "UPDATE tasks SET failures = ?2 WHERE id = ?1",
        params![task, failures],
    )?;
    Ok(())
}

/// Queues again every task `worker` holds a lease on (no attempt is counted: it said it is
/// gone, or came back); returns them.
pub fn give_back(tx: &Transaction, worker: u64) -> Result<Vec<TaskRow>> {
    let held = leased_by(tx, worker)?;
    for task in &held {
        revoke(tx, task)?;
    }
    Ok(held)
}

/// Takes a lease back through no fault of its worker: the task is queued again with no
/// attempt counted.
pub fn revoke(tx: &Transaction, task: &TaskRow) -> Result<()> {
    advance(tx, task, TaskEvent::Revoke)?;
    clear_lease(tx, task.id)
}

/// Up to `limit` tasks of `job` with ids past `after`, in `state` when given, by id.
pub fn page(
    conn: &Connection,
    job: u64,
    state: Option<TaskState>,
    after: u64,
    limit: u32,
) -> Result<Vec<TaskRow>> {
    match state {
        Some(s) => select(
            conn,
            "t.job_id = ?1 AND t.id > ?2 AND t.state = ?3 ORDER BY t.id LIMIT ?4",
            params![job, after, s.as_str(), limit],
        ),
        None => select(
            conn,
            "t.job_id = ?1 AND t.id > ?2 ORDER BY t.id LIMIT ?3",
            params![job, after, limit],
        ),
    }
}

/// Every leased task.
pub fn leased(conn: &Connection) -> Result<Vec<TaskRow>> {
    select(conn, "t.state = 'leased'", [])
}

/// The leased tasks whose deadline passed before `now`.
pub fn expired(conn: &Connection, now: i64) -> Result<Vec<TaskRow>> {
    select(conn, "t.state = 'leased' AND t.deadline_ms < ?1", [now])
}

/// The tasks `worker` holds a lease on.
pub fn leased_by(conn: &Connection, worker: u64) -> Result<Vec<TaskRow>> {
    select(conn, "t.state = 'leased' AND t.worker_id = ?1", [worker])
}

/// The tasks of `job` in one of `states`.
pub fn of_job(conn: &Connection, job: u64, states: &[TaskState]) -> Result<Vec<TaskRow>> {
    let list: Vec<String> = states.iter().map(|s| format!("'{}'", s.as_str())).collect();
    select(
        conn,
        &format!("t.job_id = ?1 AND t.state IN ({})", list.join(", ")),
        [job],
    )
}

/// Every task of one frame, render and check tasks alike.
pub fn of_frame(conn: &Connection, job: u64, frame: i32) -> Result<Vec<TaskRow>> {
    select(conn, "t.job_id = ?1 AND t.frame = ?2", params![job, frame])
}

/// Deletes a task (its failures and log lines go with it).
pub fn delete(tx: &Transaction, task: u64) -> Result<()> {
    tx.exec("DELETE FROM tasks WHERE id = ?1", [task])?;
    Ok(())
}

/// A task queued again from scratch: no lease, no failures (its attempts count on).
pub fn clear_for_rerender(tx: &Transaction, task: u64) -> Result<()> {
    tx.exec(
        "UPDATE tasks SET worker_id = NULL, leased_ms = NULL, deadline_ms = NULL, failures = 0
         WHERE id = ?1",
        [task],
    )?;
    Ok(())
}

/// The done render tasks of one frame (for assembly), by tile then pass.
pub fn done_of_frame(conn: &Connection, job: u64, frame: i32) -> Result<Vec<TaskRow>> {
    select(
        conn,
        "t.job_id = ?1 AND t.frame = ?2 AND t.state = 'done' AND t.check_of IS NULL
           AND t.kind = 'render'
         ORDER BY t.tile, t.pass",
        params![job, frame],
    )
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

/// Seconds the workers spent rendering one frame's tiles (its done tasks, checks left
/// out), as they reported.
pub fn render_seconds_of_frame(conn: &Connection, job: u64, frame: i32) -> Result<f64> {
    let ms: Option<i64> = conn.row(
        "SELECT SUM(render_ms) FROM tasks WHERE job_id = ?1 AND frame = ?2 AND state = 'done'
           AND check_of IS NULL AND kind = 'render'",
        params![job, frame],
        |r| r.get(0),
    )?;
    Ok(ms.unwrap_or(0) as f64 / 1000.0)
}

/// Whether every render task of one pass of a frame is done.
pub fn pass_done(tx: &Transaction, job: u64, frame: i32, pass: u32) -> Result<bool> {
    let left: i64 = tx.row(
        "SELECT count(*) FROM tasks WHERE job_id = ?1 AND frame = ?2 AND pass = ?3
           AND state != 'done' AND check_of IS NULL AND kind = 'render'",
        params![job, frame, pass],
        |r| r.get(0),
    )?;
    Ok(left == 0)
}

/// One finished render of a task or of a check of it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Render {
    /// The task (the original or a check).
    pub task: u64,
    /// The attempt whose tile was accepted (its file's name).
    pub attempt: u32,
    /// Its worker.
    pub worker: u64,
    /// That worker is quarantined.
    pub quarantined: bool,
}

/// The finished renders of the task `original` and its checks.
pub fn renders_of(conn: &Connection, original: u64) -> Result<Vec<Render>> {
    let mut stmt = conn.prepare_cached(
        "SELECT t.id, t.attempt, t.worker_id, w.quarantined_ms IS NOT NULL
         FROM tasks t JOIN workers w ON w.id = t.worker_id
         WHERE (t.id = ?1 OR t.check_of = ?1) AND t.state = 'done'
         ORDER BY t.id",
    )?;
    let rows = stmt.query_map([original], |r| {
        Ok(Render {
            task: r.get(0)?,
            attempt: r.get(1)?,
            worker: r.get(2)?,
            quarantined: r.get(3)?,
        })
    })?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// A done task `t` whose tile is not yet in its frame `f` (which keeps it until then):
/// the frame was never assembled, or the task came after its last assembly (a time-budget
/// frame's next pass).
const UNMERGED: &str = "(f.assembled_ms IS NULL OR t.done_ms > f.assembled_ms)";

/// The done render tasks of `worker` that no check covers and whose tiles are not yet in
/// their frames.
pub fn unchecked_unmerged_of(conn: &Connection, worker: u64) -> Result<Vec<TaskRow>> {
    select(
        conn,
        &format!(
            "t.worker_id = ?1 AND t.state = 'done' AND t.check_of IS NULL AND t.kind = 'render'
             AND NOT EXISTS (SELECT 1 FROM tasks c WHERE c.check_of = t.id)
             AND EXISTS (SELECT 1 FROM frames f WHERE f.job_id = t.job_id AND f.frame = t.frame
                           AND {UNMERGED})"
        ),
        [worker],
    )
}

/// How many tiles of `worker` are already in assembled frames.
pub fn merged_count_of(conn: &Connection, worker: u64) -> Result<i64> {
    Ok(conn.row(
        &format!(
            "SELECT count(*) FROM tasks t JOIN frames f ON f.job_id = t.job_id AND f.frame = t.frame
             WHERE t.worker_id = ?1 AND t.state = 'done' AND t.kind = 'render'
               AND NOT {UNMERGED}"
        ),
        [worker],
        |r| r.get(0),
    )?)
}

/// Tasks by state (each state's name with its count), over the whole farm.
pub fn count_by_state(conn: &Connection) -> Result<Vec<(TaskState, u64)>> {
    let mut counts: Vec<(TaskState, u64)> = TaskState::ALL.iter().map(|&s| (s, 0)).collect();
    let mut stmt = conn.prepare_cached("SELECT state, count(*) FROM tasks GROUP BY state")?;
    let rows = stmt.query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, u64>(1)?)))?;
    for row in rows {
        let (state, n) = row?;
        if let Some(slot) = counts.iter_mut().find(|(s, _)| s.as_str() == state) {
            slot.1 = n;
        }
    }
    Ok(counts)
}

/// The denoise task of a frame, if it has one.
pub fn denoise_of_frame(conn: &Connection, job: u64, frame: i32) -> Result<Option<u64>> {
    Ok(conn
        .row(
            "SELECT id FROM tasks WHERE job_id = ?1 AND frame = ?2 AND kind = 'denoise'",
            params![job, frame],
            |r| r.get(0),
        )
        .optional()?)
}

/// The upload limit of a denoise or encode task (its frame, or its video); `None` for a
/// render task or an unknown one.
pub fn upload_limit(conn: &Connection, task: u64) -> Result<Option<usize>> {
    let Some(row) = load(conn, task)? else {
        return Ok(None);
    };
    let spec = super::jobs::spec(conn, row.job_id)?;
    Ok(match row.kind {
        TaskKind::Render => None,
        TaskKind::Denoise => Some(crate::denoising::max_upload_bytes(&spec)),
        TaskKind::Encode => Some(crate::encoding::max_upload_bytes(&spec)),
    })
}

/// How many denoise and encode tasks `job` has.
pub fn steps_count(conn: &Connection, job: u64) -> Result<u64> {
    Ok(conn.row(
        "SELECT count(*) FROM tasks WHERE job_id = ?1 AND kind != 'render'",
        [job],
        |r| r.get(0),
    )?)
}

/// The encode task of a job, if it has one.
pub fn encode_of_job(conn: &Connection, job: u64) -> Result<Option<TaskRow>> {
    Ok(select(conn, "t.job_id = ?1 AND t.kind = 'encode'", [job])?
        .into_iter()
        .next())
}

/// How many tasks of `kind` of `job` are queued.
pub fn queued_count(conn: &Connection, job: u64, kind: TaskKind) -> Result<u64> {
    Ok(conn.row(
        "SELECT count(*) FROM tasks WHERE job_id = ?1 AND state = 'queued' AND kind = ?2",
        params![job, kind.as_str()],
        |r| r.get(0),
    )?)
}

/// The queued and leased tasks of jobs that are not paused or cancelled.
pub fn open_of_active_jobs(conn: &Connection) -> Result<u64> {
    Ok(conn.row(
        "SELECT count(*) FROM tasks t JOIN jobs j ON j.id = t.job_id
         WHERE j.control = 'active' AND t.state IN ('queued', 'leased')",
        [],
        |r| r.get(0),
    )?)
}

/// A job's tasks by state, with the pixel samples of its done render tasks and when the
/// last task was done.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Progress {
    /// Tasks by state.
    pub counts: proto::TaskCounts,
    /// Pixel samples of the done render tasks (checks repeat samples: left out).
    pub done_samples: i64,
    /// When the last task was done.
    pub last_done_ms: Option<i64>,
}

/// The progress of `job`'s tasks.
pub fn progress(conn: &Connection, job: u64) -> Result<Progress> {
    let mut p = Progress::default();
    let mut stmt = conn.prepare_cached(
        "SELECT state, count(*),
                coalesce(sum(CASE WHEN check_of IS NULL
                                  THEN w * h * (sample_end - sample_start) END), 0),
                max(done_ms)
         FROM tasks WHERE job_id = ?1 GROUP BY state",
    )?;
    let rows = stmt.query_map([job], |r| {
        Ok((
            r.get::<_, String>(0)?,
            r.get::<_, u64>(1)?,
            r.get::<_, i64>(2)?,
            r.get::<_, Option<i64>>(3)?,
        ))
    })?;
    for row in rows {
        let (state, n, samples, done_ms) = row?;
        let state = TaskState::parse(&state)
            .ok_or_else(|| Error::Internal(format!("unknown task state `{state}`")))?;
        let slot = match state {
            TaskState::Queued => &mut p.counts.queued,
            TaskState::Leased => &mut p.counts.leased,
            TaskState::Done => {
                p.done_samples = samples;
                p.last_done_ms = done_ms;
                &mut p.counts.done
            }
            TaskState::Failed => &mut p.counts.failed,
            TaskState::Cancelled => &mut p.counts.cancelled,
        };
        *slot = n;
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lease walks the queue's index in lease order: a sort would read the job's whole
    /// queue on every lease (a million tasks for the largest job). A time-budget job's
    /// queue holds only the passes its plan issued, and is sorted.
    #[test]
    fn the_next_task_is_read_off_the_queue_index_without_a_sort() {
        let mut conn = Connection::open_in_memory().unwrap();
        super::super::migrations::migrate(&mut conn).unwrap();
        let plan: Vec<String> = conn
            .prepare(&format!(
                "EXPLAIN QUERY PLAN {}",
                next_fresh_sql(FRAME_ORDER)
            ))
            .unwrap()
            .query_map(params![1, 2], |r| r.get::<_, String>(3))
            .unwrap()
            .collect::<rusqlite::Result<_>>()
            .unwrap();
        assert!(
            plan.iter().all(|step| !step.contains("TEMP B-TREE")),
            "{plan:?}"
        );
    }
}
