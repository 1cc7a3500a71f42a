//! Read models: job status (tasks by state, frames done, samples per second, ETA), frame
//! lists, workers. Nothing here writes.

use proto::{
    BudgetPlan, FrameList, FrameState, FrameStatus, JobSpec, JobState, JobStatus, TaskCounts,
    TaskToken, WorkerInfo, WorkerList,
};
use rusqlite::{params, Connection, OptionalExtension};

use crate::db::Cached;
use crate::error::{Error, Result};

/// One job's status at `now`.
pub fn job_status(conn: &Connection, job: u64, now: i64) -> Result<JobStatus> {
    let row = conn
        .row(
            "SELECT name, spec, control, created_ms, first_lease_ms, finished_ms, pixel_samples,
                    budget_plan
             FROM jobs WHERE id = ?1",
            [job],
            |r| {
                Ok((
                    r.get::<_, String>(0)?,
                    r.get::<_, String>(1)?,
                    r.get::<_, String>(2)?,
                    r.get::<_, i64>(3)?,
                    r.get::<_, Option<i64>>(4)?,
                    r.get::<_, Option<i64>>(5)?,
                    r.get::<_, i64>(6)?,
                    r.get::<_, Option<String>>(7)?,
                ))
            },
        )
        .optional()?
        .ok_or_else(|| Error::NotFound(format!("job {job} does not exist")))?;
    let (name, spec, control, created_ms, first_lease_ms, finished_ms, pixel_samples, plan) = row;
    let spec: JobSpec = serde_json::from_str(&spec)?;
    let budget: Option<BudgetPlan> = plan.map(|p| serde_json::from_str(&p)).transpose()?;

    let mut tasks = TaskCounts::default();
    let mut done_samples = 0i64;
    let mut last_done_ms = None::<i64>;
    {
        let mut stmt = conn.prepare_cached(
            // Check tasks count as tasks but not as samples: they repeat samples.
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
            match state.as_str() {
                "queued" => tasks.queued = n,
                "leased" => tasks.leased = n,
                "done" => {
                    tasks.done = n;
                    done_samples = samples;
                    last_done_ms = done_ms;
                }
                "failed" => tasks.failed = n,
                _ => tasks.cancelled = n,
            }
        }
    }
    let (frames_total, frames_done): (u64, u64) = conn.row(
        "SELECT count(*), coalesce(sum(assembled_ms IS NOT NULL), 0) FROM frames WHERE job_id = ?1",
        [job],
        |r| Ok((r.get(0)?, r.get(1)?)),
    )?;
    let frames_failed: u64 = conn.row(
        "SELECT count(*) FROM frames f WHERE job_id = ?1
           AND (failure IS NOT NULL
                OR EXISTS (SELECT 1 FROM tasks t WHERE t.job_id = f.job_id
                             AND t.frame = f.frame AND t.state = 'failed'))",
        [job],
        |r| r.get(0),
    )?;

    let state = if control == "cancelled" {
        JobState::Cancelled
    } else if frames_failed > 0 {
        JobState::Failed
    } else if frames_done == frames_total && finished_ms.is_some() {
        // (A time-budget job's frames all exist after its first pass; it is done when
        // nothing more is planned.)
        JobState::Done
    } else if control == "paused" {
        JobState::Paused
    } else if tasks.leased > 0 || tasks.done > 0 {
        JobState::Running
    } else {
        JobState::Queued
    };

    // Throughput over the time the job has been worked on: from its first lease to its
    // last accepted tile once finished, to now while running.
    let end = match finished_ms {
        Some(_) => last_done_ms.unwrap_or(now),
        None => now,
    };
    let samples_per_second = match first_lease_ms {
        Some(start) if end > start && done_samples > 0 => {
            done_samples as f64 / ((end - start) as f64 / 1000.0)
        }
        _ => 0.0,
    };
    let remaining = (pixel_samples - done_samples).max(0) as f64;
    let running = matches!(
        state,
        JobState::Running | JobState::Queued | JobState::Failed
    ) && finished_ms.is_none();
    // A time-budget job's samples grow as it goes: its progress is the budget's time, and
    // it ends when its plan says.
    let (progress, eta_seconds) = match &budget {
        Some(plan) => (
            match finished_ms {
                Some(_) => 1.0,
                None => {
                    ((now - created_ms) as f64 / (plan.budget_seconds * 1000.0)).clamp(0.0, 1.0)
                }
            },
            plan.predicted_end_ms
                .filter(|_| running)
                .map(|end| (end - now).max(0) as f64 / 1000.0),
        ),
        None => (
            if pixel_samples > 0 {
                done_samples as f64 / pixel_samples as f64
            } else {
                0.0
            },
            (running && samples_per_second > 0.0).then(|| remaining / samples_per_second),
        ),
    };
    Ok(JobStatus {
        id: job,
        name,
        state,
        spec,
        created_ms,
        finished_ms,
        tasks,
        frames_total,
        frames_done,
        frames_failed,
        progress,
        samples_per_second,
        eta_seconds,
        budget,
    })
}

/// Every job, newest first.
pub fn list_jobs(conn: &Connection, now: i64) -> Result<Vec<JobStatus>> {
    let ids: Vec<u64> = {
        let mut stmt = conn.prepare_cached("SELECT id FROM jobs ORDER BY id DESC")?;
        let rows = stmt.query_map([], |r| r.get(0))?;
        rows.collect::<rusqlite::Result<_>>()?
    };
    ids.into_iter()
        .map(|id| job_status(conn, id, now))
        .collect()
}

const FRAME_QUERY: &str = "SELECT f.frame, f.tasks_total, f.tasks_done, f.assembled_ms,
        f.spp_mean, f.noise,
        (SELECT count(*) FROM tasks t WHERE t.job_id = f.job_id AND t.frame = f.frame
           AND t.state = 'failed'),
        (SELECT count(*) FROM tasks t WHERE t.job_id = f.job_id AND t.frame = f.frame
           AND t.state = 'leased'),
        j.control, f.failure,
        (SELECT max(frame) FROM frames WHERE job_id = f.job_id)
     FROM frames f JOIN jobs j ON j.id = f.job_id";

fn frame_from_row(r: &rusqlite::Row) -> rusqlite::Result<FrameStatus> {
    let frame: i32 = r.get(0)?;
    let (total, done): (u64, u64) = (r.get(1)?, r.get(2)?);
    let assembled: Option<i64> = r.get(3)?;
    let (spp_mean, noise): (Option<f64>, Option<f64>) = (r.get(4)?, r.get(5)?);
    let (failed, leased): (u64, u64) = (r.get(6)?, r.get(7)?);
    let control: String = r.get(8)?;
    let failure: Option<String> = r.get(9)?;
    let state = if failure.is_some() {
        FrameState::Failed
    } else if assembled.is_some() {
        FrameState::Done
    } else if failed > 0 {
        FrameState::Failed
    } else if control == "cancelled" {
        FrameState::Cancelled
    } else if done > 0 || leased > 0 {
        FrameState::Rendering
    } else {
        FrameState::Queued
    };
    Ok(FrameStatus {
        frame,
        state,
        tasks_total: total,
        tasks_done: done,
        spp_mean,
        noise,
        file: proto::job::frame_file_name(frame, r.get(10)?, "exr"),
        failure,
    })
}

/// The frames of a job, in order.
pub fn frames(conn: &Connection, job: u64) -> Result<FrameList> {
    let exists: bool = conn.row("SELECT count(*) > 0 FROM jobs WHERE id = ?1", [job], |r| {
        r.get(0)
    })?;
    if !exists {
        return Err(Error::NotFound(format!("job {job} does not exist")));
    }
    let mut stmt = conn.prepare_cached(&format!(
        "{FRAME_QUERY} WHERE f.job_id = ?1 ORDER BY f.frame"
    ))?;
    let rows = stmt.query_map([job], frame_from_row)?;
    Ok(FrameList {
        frames: rows.collect::<rusqlite::Result<_>>()?,
    })
}

/// One frame of a job.
pub fn frame_status(conn: &Connection, job: u64, frame: i32) -> Result<FrameStatus> {
    conn.row(
        &format!("{FRAME_QUERY} WHERE f.job_id = ?1 AND f.frame = ?2"),
        params![job, frame],
        frame_from_row,
    )
    .optional()?
    .ok_or_else(|| Error::NotFound(format!("job {job} has no frame {frame}")))
}

const WORKER_QUERY: &str =
    "SELECT w.id, w.name, w.threads, w.version, w.last_seen_ms, w.tasks_done,
        t.id, t.attempt, t.job_id, t.frame, w.left_ms, w.suspect_ms, w.quarantine_reason,
        w.platform
     FROM workers w
     LEFT JOIN tasks t ON t.id = (SELECT id FROM tasks WHERE worker_id = w.id AND state = 'leased'
                                  ORDER BY leased_ms DESC LIMIT 1)";

fn worker_from_row(r: &rusqlite::Row, now: i64, lease_ms: i64) -> rusqlite::Result<WorkerInfo> {
    let last_seen_ms: i64 = r.get(4)?;
    let task: Option<u64> = r.get(6)?;
    Ok(WorkerInfo {
        id: r.get(0)?,
        name: r.get(1)?,
        threads: r.get(2)?,
        version: r.get(3)?,
        last_seen_ms,
        online: last_seen_ms >= now - 2 * lease_ms && r.get::<_, Option<i64>>(10)?.is_none(),
        tasks_done: r.get(5)?,
        current_task: match task {
            Some(task_id) => Some(TaskToken {
                task_id,
                attempt: r.get(7)?,
            }),
            None => None,
        },
        current_job: r.get(8)?,
        current_frame: r.get(9)?,
        suspect: r.get::<_, Option<i64>>(11)?.is_some(),
        quarantined: r.get(12)?,
        platform: r.get(13)?,
    })
}

/// One worker.
pub fn worker(conn: &Connection, id: u64, now: i64, lease_ms: i64) -> Result<WorkerInfo> {
    conn.row(&format!("{WORKER_QUERY} WHERE w.id = ?1"), [id], |r| {
        worker_from_row(r, now, lease_ms)
    })
    .optional()?
    .ok_or_else(|| Error::NotFound(format!("worker {id} is not registered")))
}

/// Every worker, by id.
pub fn workers(conn: &Connection, now: i64, lease_ms: i64) -> Result<WorkerList> {
    let mut stmt = conn.prepare_cached(&format!("{WORKER_QUERY} ORDER BY w.id"))?;
    let rows = stmt.query_map([], |r| worker_from_row(r, now, lease_ms))?;
    Ok(WorkerList {
        workers: rows.collect::<rusqlite::Result<_>>()?,
    })
}
