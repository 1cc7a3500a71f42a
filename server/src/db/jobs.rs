//! The `jobs` table (and `job_blocks`): a job's spec and control state, whether anything
//! of it is left to run, the workers blocked from it, and its time-budget plan.

use proto::{BudgetPlan, JobSpec};
use rusqlite::{params, Connection, OptionalExtension, Transaction};

use super::frames::NEEDS_ASSEMBLY;
use super::Cached;
use crate::error::{Error, Result};
use crate::state::JobControl;

/// Column `i` of `r` as a job control state.
pub(super) fn control_from_sql(r: &rusqlite::Row, i: usize) -> rusqlite::Result<JobControl> {
    let name: String = r.get(i)?;
    JobControl::parse(&name).ok_or_else(|| {
        rusqlite::Error::FromSqlConversionFailure(
            i,
            rusqlite::types::Type::Text,
            format!("unknown job control `{name}`").into(),
        )
    })
}

/// Stores a new active job (named after its id unless the spec names it); returns its id.
pub fn insert(tx: &Transaction, spec: &JobSpec, pixel_samples: u64, now: i64) -> Result<u64> {
    tx.exec(
        "INSERT INTO jobs (name, scene, spec, control, priority, max_attempts, created_ms,
                           pixel_samples)
         VALUES ('', ?1, ?2, ?3, ?4, ?5, ?6, ?7)",
        params![
            spec.scene,
            serde_json::to_string(spec)?,
            JobControl::Active.as_str(),
            spec.priority,
            spec.max_attempts,
            now,
            pixel_samples as i64
        ],
    )?;
    let id = tx.last_insert_rowid() as u64;
    let name = spec.name.clone().unwrap_or_else(|| format!("job {id}"));
    tx.exec("UPDATE jobs SET name = ?2 WHERE id = ?1", params![id, name])?;
    Ok(id)
}

/// A job's control state, or `None` when there is no such job.
pub fn find_control(conn: &Connection, job: u64) -> Result<Option<JobControl>> {
    Ok(conn
        .row("SELECT control FROM jobs WHERE id = ?1", [job], |r| {
            control_from_sql(r, 0)
        })
        .optional()?)
}

/// A job's control state; `NotFound` when there is no such job.
pub fn control(conn: &Connection, job: u64) -> Result<JobControl> {
    find_control(conn, job)?.ok_or_else(|| Error::NotFound(format!("job {job} does not exist")))
}

/// Sets a job's control state (the caller asked the transition table).
pub fn set_control(tx: &Transaction, job: u64, control: JobControl) -> Result<()> {
    tx.exec(
        "UPDATE jobs SET control = ?2 WHERE id = ?1",
        params![job, control.as_str()],
    )?;
    Ok(())
}

/// The resolved spec of a job.
pub fn spec(conn: &Connection, job: u64) -> Result<JobSpec> {
    let json: String = conn
        .row("SELECT spec FROM jobs WHERE id = ?1", [job], |r| r.get(0))
        .optional()?
        .ok_or_else(|| Error::NotFound(format!("job {job} does not exist")))?;
    Ok(serde_json::from_str(&json)?)
}

/// How many attempts each task of a job gets.
pub fn max_attempts(conn: &Connection, job: u64) -> Result<u32> {
    Ok(
        conn.row("SELECT max_attempts FROM jobs WHERE id = ?1", [job], |r| {
            r.get(0)
        })?,
    )
}

/// When a job's first task was leased (kept from the first time).
pub fn note_first_lease(tx: &Transaction, job: u64, now: i64) -> Result<()> {
    tx.exec(
        "UPDATE jobs SET first_lease_ms = coalesce(first_lease_ms, ?2) WHERE id = ?1",
        params![job, now],
    )?;
    Ok(())
}

/// Sets or clears `jobs.finished_ms`: set when nothing is left to run (every task done,
/// failed or cancelled and every complete frame assembled), cleared when work reappears.
/// Each time it is newly set, webhooks are to be told ([`super::outbox`]).
pub fn update_finished(tx: &Transaction, job: u64, now: i64) -> Result<()> {
    // EXISTS, not count(*): this runs on every accepted tile, and a count of a big job's
    // queue grows with the job (measured with `tessera bench farm`).
    let open: bool = tx.row(
        &format!(
            "SELECT EXISTS (SELECT 1 FROM tasks WHERE job_id = ?1
                              AND state IN ('queued', 'leased'))
                 OR EXISTS (SELECT 1 FROM frames WHERE job_id = ?1 AND {NEEDS_ASSEMBLY})"
        ),
        [job],
        |r| r.get(0),
    )?;
    if !open {
        let newly = tx.exec(
            "UPDATE jobs SET finished_ms = ?2 WHERE id = ?1 AND finished_ms IS NULL",
            params![job, now],
        )?;
        if newly == 1 {
            super::outbox::add(tx, super::outbox::Subject::JobFinished(job), now)?;
        }
    } else {
        tx.exec("UPDATE jobs SET finished_ms = NULL WHERE id = ?1", [job])?;
    }
    Ok(())
}

/// Whether a job has nothing left to run (see [`update_finished`]).
pub fn is_finished(conn: &Connection, job: u64) -> Result<bool> {
    Ok(conn.row(
        "SELECT finished_ms IS NOT NULL FROM jobs WHERE id = ?1",
        [job],
        |r| r.get(0),
    )?)
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

/// Deletes a job's rows (its tasks, frames, failures and blocks go with it).
pub fn delete(tx: &Transaction, job: u64) -> Result<()> {
    tx.exec("DELETE FROM jobs WHERE id = ?1", [job])?;
    Ok(())
}

/// Finished jobs (nothing left to run, cancelled ones included), the last finished first.
pub fn finished(conn: &Connection) -> Result<Vec<proto::GcJob>> {
    let mut stmt = conn.prepare_cached(
        "SELECT id, name, finished_ms FROM jobs WHERE finished_ms IS NOT NULL
         ORDER BY finished_ms DESC, id DESC",
    )?;
    let rows = stmt.query_map([], |r| {
        Ok(proto::GcJob {
            id: r.get(0)?,
            name: r.get(1)?,
            finished_ms: r.get(2)?,
        })
    })?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// Every job with its scene's digest.
pub fn scenes(conn: &Connection) -> Result<Vec<(u64, String)>> {
    let mut stmt = conn.prepare_cached("SELECT id, scene FROM jobs")?;
    let rows = stmt.query_map([], |r| Ok((r.get(0)?, r.get(1)?)))?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// What the scene of `job` needs from the tracer (its summary's `features`).
pub fn scene_features(conn: &Connection, job: u64) -> Result<Vec<String>> {
    let json: String = conn.row(
        "SELECT scenes.info FROM jobs JOIN scenes ON scenes.digest = jobs.scene
         WHERE jobs.id = ?1",
        [job],
        |r| r.get(0),
    )?;
    Ok(serde_json::from_str::<proto::SceneInfo>(&json)?.features)
}

/// Blocks `worker` from `job`; `false` when it already was.
pub fn block(tx: &Transaction, job: u64, worker: u64) -> Result<bool> {
    Ok(tx.exec(
        "INSERT OR IGNORE INTO job_blocks (job_id, worker_id) VALUES (?1, ?2)",
        params![job, worker],
    )? > 0)
}

/// Lifts every worker's block from `job`; returns how many there were.
pub fn unblock_all(tx: &Transaction, job: u64) -> Result<usize> {
    Ok(tx.exec("DELETE FROM job_blocks WHERE job_id = ?1", [job])?)
}

/// The unfinished active time-budget jobs.
pub fn running_budget_jobs(conn: &Connection) -> Result<Vec<u64>> {
    let mut stmt = conn.prepare_cached(
        "SELECT id FROM jobs
         WHERE budget_plan IS NOT NULL AND finished_ms IS NULL AND control = 'active'",
    )?;
    let rows = stmt.query_map([], |r| r.get(0))?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// A job's pixel samples grew (or, negative, shrank) by `samples`.
pub fn add_pixel_samples(tx: &Transaction, job: u64, samples: i64) -> Result<()> {
    tx.exec(
        "UPDATE jobs SET pixel_samples = pixel_samples + ?2 WHERE id = ?1",
        params![job, samples],
    )?;
    Ok(())
}

/// Sets a job's priority, in its row and its spec.
pub fn set_priority(tx: &Transaction, job: u64, priority: i32) -> Result<()> {
    tx.exec(
        "UPDATE jobs SET priority = ?2, spec = json_set(spec, '$.priority', ?2) WHERE id = ?1",
        params![job, priority],
    )?;
    Ok(())
}

/// Stores a time-budget job's latest plan.
pub fn set_budget_plan(tx: &Transaction, job: u64, plan: &BudgetPlan) -> Result<()> {
    tx.exec(
        "UPDATE jobs SET budget_plan = ?2 WHERE id = ?1",
        params![job, serde_json::to_string(plan)?],
    )?;
    Ok(())
}

/// One row of `jobs`, as the job's status is made from it.
#[derive(Clone, Debug)]
pub struct JobRow {
    /// Its name.
    pub name: String,
    /// Its resolved spec.
    pub spec: JobSpec,
    /// Its control state.
    pub control: JobControl,
    /// When it was submitted.
    pub created_ms: i64,
    /// When its first task was leased.
    pub first_lease_ms: Option<i64>,
    /// Since when nothing of it is left to run.
    pub finished_ms: Option<i64>,
    /// Pixel samples it renders in all.
    pub pixel_samples: i64,
    /// A time-budget job's latest plan.
    pub budget: Option<BudgetPlan>,
}

/// The row of `job`; `NotFound` when there is no such job.
pub fn load(conn: &Connection, job: u64) -> Result<JobRow> {
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
                    control_from_sql(r, 2)?,
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
    Ok(JobRow {
        name,
        spec: serde_json::from_str(&spec)?,
        control,
        created_ms,
        first_lease_ms,
        finished_ms,
        pixel_samples,
        budget: plan.map(|p| serde_json::from_str(&p)).transpose()?,
    })
}

/// Every job's id, newest first.
pub fn ids(conn: &Connection) -> Result<Vec<u64>> {
    let mut stmt = conn.prepare_cached("SELECT id FROM jobs ORDER BY id DESC")?;
    let rows = stmt.query_map([], |r| r.get(0))?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// When a job was submitted.
pub fn created_ms(conn: &Connection, job: u64) -> Result<i64> {
    Ok(
        conn.row("SELECT created_ms FROM jobs WHERE id = ?1", [job], |r| {
            r.get(0)
        })?,
    )
}
