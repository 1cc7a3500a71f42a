//! The `outbox` table: what webhooks are to be told, written in the transaction that made
//! it happen (so a notification is never lost to a crash, nor sent for something undone),
//! read and removed by [`crate::webhooks`].

use rusqlite::{params, Connection, Transaction};

use super::Cached;
use crate::error::Result;

/// What happened, as stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Subject {
    /// A job has nothing left to run (done, failed or cancelled: told apart on delivery).
    JobFinished(u64),
    /// A worker was quarantined.
    WorkerQuarantined(u64),
}

/// One notification to deliver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pending {
    /// Its id.
    pub id: u64,
    /// What it is about.
    pub subject: Subject,
    /// When it happened.
    pub at_ms: i64,
}

/// Records a notification.
pub fn add(tx: &Transaction, subject: Subject, now: i64) -> Result<()> {
    let (kind, job, worker) = match subject {
        Subject::JobFinished(job) => ("job_finished", Some(job), None),
        Subject::WorkerQuarantined(worker) => ("worker_quarantined", None, Some(worker)),
    };
    tx.exec(
        "INSERT INTO outbox (kind, job_id, worker_id, at_ms) VALUES (?1, ?2, ?3, ?4)",
        params![kind, job, worker, now],
    )?;
    Ok(())
}

/// The oldest `limit` notifications.
pub fn pending(conn: &Connection, limit: u32) -> Result<Vec<Pending>> {
    let mut stmt = conn.prepare_cached(
        "SELECT id, kind, job_id, worker_id, at_ms FROM outbox ORDER BY id LIMIT ?1",
    )?;
    let rows = stmt.query_map([limit], |r| {
        let kind: String = r.get(1)?;
        let subject = match (kind.as_str(), r.get(2)?, r.get(3)?) {
            ("job_finished", Some(job), _) => Subject::JobFinished(job),
            ("worker_quarantined", _, Some(worker)) => Subject::WorkerQuarantined(worker),
            _ => {
                return Err(rusqlite::Error::FromSqlConversionFailure(
                    1,
                    rusqlite::types::Type::Text,
                    format!("outbox row of unknown kind `{kind}`").into(),
                ))
            }
        };
        Ok(Pending {
            id: r.get(0)?,
            subject,
            at_ms: r.get(4)?,
        })
    })?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// Removes a notification (delivered, or given up on).
pub fn remove(conn: &Connection, id: u64) -> Result<()> {
    conn.exec("DELETE FROM outbox WHERE id = ?1", [id])?;
    Ok(())
}
