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
