//! A job as clients read it, made from what [`crate::db`] stores: its status (state, tasks
//! by state, frames done, samples per second, progress, ETA, and why it is stuck if it
//! is), its tasks, why their attempts failed, what workers logged and the job's event
//! log. Nothing here writes.

use proto::log::MAX_EVENTS_PER_PAGE;
use proto::{
    FailureList, JobEventList, JobState, JobStatus, Rect, SampleSpan, TaskInfo, TaskKind, TaskList,
    TaskLog,
};
use rusqlite::Connection;

use crate::db::workers::{Availability, Step};
use crate::db::{events, failures, frames, jobs, logs, tasks, workers};
use crate::error::{Error, Result};
use crate::limits::{MAX_FAILURE_GROUPS, MAX_TASKS_PER_PAGE};
use crate::state::{job_state, JobControl, JobFacts, TaskState};

/// One job's status at `now`; workers seen since `live_since` count as live.
pub fn job_status(conn: &Connection, job: u64, now: i64, live_since: i64) -> Result<JobStatus> {
    let jobs::JobRow {
        name,
        spec,
        control,
        created_ms,
        first_lease_ms,
        finished_ms,
        pixel_samples,
        budget,
    } = jobs::load(conn, job)?;
    let tasks::Progress {
        counts: tasks,
        done_samples,
        last_done_ms,
    } = tasks::progress(conn, job)?;
    let (frames_total, frames_done) = frames::counts(conn, job)?;
    let frames_failed = frames::failed_count(conn, job)?;
    let state = job_state(JobFacts {
        control,
        frames_failed,
        // (A time-budget job's frames all exist after its first pass; it is done when
        // nothing more is planned.)
        complete: frames_done == frames_total && finished_ms.is_some(),
        started: tasks.leased > 0 || tasks.done > 0,
    });

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
    let attempts_failed = failures::count(conn, job)?;
    // Stuck: work is queued, none runs, and no live worker may take it. (No live worker
    // at all is a farm waiting for workers, not a stuck job.)
    let stuck = if control == JobControl::Active
        && finished_ms.is_none()
        && tasks.queued > 0
        && tasks.leased == 0
    {
        let farm = workers::availability(conn, job, live_since)?;
        if farm.live > 0 && farm.usable() == 0 {
            Some(stuck_reason(
                conn,
                job,
                &spec.require_tags,
                farm,
                attempts_failed,
            )?)
        } else {
            None
        }
    } else {
        None
    };
    let waiting = match control {
        JobControl::Active => waiting_reason(conn, job, live_since)?,
        JobControl::Paused | JobControl::Cancelled => None,
    };
    let video = tasks::encode_of_job(conn, job)?.is_some_and(|t| t.state == TaskState::Done);
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
        attempts_failed,
        stuck,
        waiting,
        video,
    })
}

/// What `job` waits for that no live worker offers: a denoiser for its queued frames, an
/// encoder for its video.
fn waiting_reason(conn: &Connection, job: u64, live_since: i64) -> Result<Option<String>> {
    let frames = tasks::queued_count(conn, job, TaskKind::Denoise)?;
    if frames > 0 && !workers::step_live_for_job(conn, job, Step::Denoise, live_since)? {
        return Ok(Some(format!(
            "{frames} frame(s) wait to be denoised, and no live worker that may take this job \
             has Open Image Denoise: run `tessera install oidn` on a worker's machine and \
             restart its worker (it takes denoise tasks once it finds the library)"
        )));
    }
    let video = tasks::queued_count(conn, job, TaskKind::Encode)?;
    if video > 0 && !workers::step_live_for_job(conn, job, Step::Encode, live_since)? {
        return Ok(Some(
            "its video waits to be encoded, and no live worker that may take this job has \
             FFmpeg: run `tessera install ffmpeg` on a worker's machine and restart its worker"
                .to_string(),
        ));
    }
    Ok(None)
}

/// Why no live worker may take `job`'s tasks (it requires `tags`), with its most frequent
/// failure (of `attempts_failed`) and what to do.
fn stuck_reason(
    conn: &Connection,
    job: u64,
    tags: &[String],
    farm: Availability,
    attempts_failed: u64,
) -> Result<String> {
    let mut why = format!(
        "no live worker may take its tasks: of {} live worker(s), {} blocked from this job \
         after failing its tasks and {} quarantined",
        farm.live, farm.blocked, farm.quarantined
    );
    if farm.untagged > 0 {
        why.push_str(&format!(
            ", {} without the tags it requires ({}); start a worker with `--tags {}`",
            farm.untagged,
            tags.join(", "),
            tags.join(",")
        ));
    }
    if let Some(g) = failures::groups(conn, job, 1)?.first() {
        why.push_str(&format!(
            "; most frequent failure ({} of {attempts_failed} attempt(s)): {}",
            g.attempts, g.reason
        ));
    }
    if farm.blocked > 0 {
        why.push_str(&format!(
            "; fix the cause, then `tessera retry {job}` lifts the blocks"
        ));
    }
    Ok(why)
}

/// Up to `limit` (at most [`MAX_TASKS_PER_PAGE`]) tasks of `job` with ids past `after`, in
/// `state` when given, each with its failed attempts.
pub fn tasks(
    conn: &Connection,
    job: u64,
    state: Option<TaskState>,
    after: u64,
    limit: u32,
) -> Result<TaskList> {
    jobs::control(conn, job)?;
    let limit = limit.clamp(1, MAX_TASKS_PER_PAGE);
    let rows = tasks::page(conn, job, state, after, limit)?;
    let ids: Vec<u64> = rows.iter().map(|t| t.id).collect();
    let mut failed = failures::of_tasks(conn, job, &ids)?;
    let next_after = (rows.len() == limit as usize).then(|| ids[ids.len() - 1]);
    let tasks = rows
        .into_iter()
        .map(|t| TaskInfo {
            id: t.id,
            kind: t.kind,
            frame: t.frame,
            tile: t.tile,
            pass: t.pass,
            rect: Rect {
                x: t.rect.x,
                y: t.rect.y,
                width: t.rect.width,
                height: t.rect.height,
            },
            samples: SampleSpan {
                start: t.samples.start,
                end: t.samples.end,
            },
            state: t.state,
            attempt: t.attempt,
            worker_id: t.worker_id,
            check_of: t.check_of,
            failures: failed.remove(&t.id).unwrap_or_default(),
        })
        .collect();
    Ok(TaskList { tasks, next_after })
}

/// Why `job`'s attempts failed, grouped by reason (the [`MAX_FAILURE_GROUPS`] most
/// frequent).
pub fn failures(conn: &Connection, job: u64) -> Result<FailureList> {
    jobs::control(conn, job)?;
    Ok(FailureList {
        groups: failures::groups(conn, job, MAX_FAILURE_GROUPS)?,
    })
}

/// What the workers logged while they held `task` of `job`, per attempt.
pub fn task_log(conn: &Connection, job: u64, task: u64) -> Result<TaskLog> {
    jobs::control(conn, job)?;
    let row = tasks::load(conn, task)?
        .filter(|t| t.job_id == job)
        .ok_or_else(|| Error::NotFound(format!("job {job} has no task {task}")))?;
    Ok(TaskLog {
        task_id: task,
        frame: row.frame,
        attempts: logs::of_task(conn, task)?,
    })
}

/// A page of `job`'s event log: events past `after`, oldest first.
pub fn job_log(conn: &Connection, job: u64, after: u64, limit: u32) -> Result<JobEventList> {
    jobs::control(conn, job)?;
    events::of_job(conn, job, after, limit.clamp(1, MAX_EVENTS_PER_PAGE))
}

/// Every job, newest first.
pub fn list_jobs(conn: &Connection, now: i64, live_since: i64) -> Result<Vec<JobStatus>> {
    jobs::ids(conn)?
        .into_iter()
        .map(|id| job_status(conn, id, now, live_since))
        .collect()
}
