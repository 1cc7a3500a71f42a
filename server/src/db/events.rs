//! The `events` table: the farm's log of what happened to jobs, tasks and workers, written
//! in the transaction that made it happen.

use rusqlite::{params, Transaction};

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
