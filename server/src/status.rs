//! A job's status as clients read it: its state, tasks by state, frames done, samples per
//! second, progress and ETA, made from what [`crate::db`] stores. Nothing here writes.

use proto::{JobState, JobStatus};
use rusqlite::Connection;

use crate::db::{frames, jobs, tasks};
use crate::error::Result;
use crate::state::{job_state, JobFacts};

/// One job's status at `now`.
pub fn job_status(conn: &Connection, job: u64, now: i64) -> Result<JobStatus> {
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
    jobs::ids(conn)?
        .into_iter()
        .map(|id| job_status(conn, id, now))
        .collect()
}
