//! The `events` table: the farm's log of what happened to jobs, tasks and workers, written
//! in the transaction that made it happen.

use proto::{JobEvent, JobEventList};
use rusqlite::{params, Connection, Transaction};

use super::Cached;
use crate::error::Result;

/// Appends to the event log.
pub fn log(tx: &Transaction, now: i64, job: Option<u64>, kind: &str, detail: &str) -> Result<()> {
    tx.exec(
        "INSERT INTO events (at_ms, job_id, kind, detail) VALUES (?1, ?2, ?3, ?4)",
        params![now, job, kind, detail],
    )?;
    Ok(())
}

/// The events of `job` with ids past `after`, oldest first, at most `limit`.
pub fn of_job(conn: &Connection, job: u64, after: u64, limit: u32) -> Result<JobEventList> {
    let mut stmt = conn.prepare_cached(
        "SELECT id, at_ms, kind, detail FROM events
         WHERE job_id = ?1 AND id > ?2 ORDER BY id LIMIT ?3",
    )?;
    let rows = stmt.query_map(params![job, after, limit], |r| {
        Ok(JobEvent {
            id: r.get(0)?,
            at_ms: r.get(1)?,
            kind: r.get(2)?,
            detail: r.get(3)?,
        })
    })?;
    let events: Vec<JobEvent> = rows.collect::<rusqlite::Result<_>>()?;
    let next_after = (events.len() == limit as usize).then(|| events[events.len() - 1].id);
    Ok(JobEventList { events, next_after })
}

/// Events of jobs that are gone (but for the record of their deletion).
const OF_GONE_JOBS: &str = "job_id IS NOT NULL AND kind != 'job_deleted'
                            AND NOT EXISTS (SELECT 1 FROM jobs WHERE jobs.id = events.job_id)";

/// How many events [`trim`] would remove after `going` jobs were deleted too.
pub fn to_trim(conn: &Connection, going: &[u64], max: u64) -> Result<u64> {
    let mut of_gone: u64 = conn.row(
        &format!("SELECT count(*) FROM events WHERE {OF_GONE_JOBS}"),
        [],
        |r| r.get(0),
    )?;
    for &job in going {
        of_gone += conn.row(
            "SELECT count(*) FROM events WHERE job_id = ?1 AND kind != 'job_deleted'",
            [job],
            |r| r.get::<_, u64>(0),
        )?;
    }
    let total: u64 = conn.row("SELECT count(*) FROM events", [], |r| r.get(0))?;
    // Each deletion adds its own record.
    let left = total + going.len() as u64 - of_gone;
    Ok(of_gone + left.saturating_sub(max))
}

/// Removes the events of jobs that are gone, then the oldest past `max`; returns how many.
pub fn trim(tx: &Transaction, max: u64) -> Result<u64> {
    let gone = tx.exec(&format!("DELETE FROM events WHERE {OF_GONE_JOBS}"), [])?;
    let oldest = tx.exec(
        "DELETE FROM events WHERE id <= (SELECT id FROM events ORDER BY id DESC
                                         LIMIT 1 OFFSET ?1)",
        [max],
    )?;
    Ok((gone + oldest) as u64)
}
