//! The `task_failures` table: every failed attempt with its worker and reason (the
//! worker's error chain, word for word, or the lease's expiry), kept until the task is
//! retried; read back per task and grouped by reason.

use std::collections::HashMap;

use proto::{FailureGroup, FailureKind, TaskFailure};
use rusqlite::{params, Connection, Transaction};

use super::tasks::TaskRow;
use super::Cached;
use crate::error::Result;

fn kind_from_sql(r: &rusqlite::Row, i: usize) -> rusqlite::Result<FailureKind> {
    let name: String = r.get(i)?;
    match name.as_str() {
        "reported" => Ok(FailureKind::Reported),
        "expired" => Ok(FailureKind::Expired),
        _ => Err(rusqlite::Error::FromSqlConversionFailure(
            i,
            rusqlite::types::Type::Text,
            format!("unknown failure kind `{name}`").into(),
        )),
    }
}

/// Records why an attempt of `task` by `worker` failed; returns how many attempts of the
/// job's tasks that worker has failed.
pub fn record(
    tx: &Transaction,
    task: &TaskRow,
    worker: u64,
    kind: FailureKind,
    reason: &str,
    now: i64,
) -> Result<u32> {
    tx.exec(
        "INSERT INTO task_failures (task_id, job_id, worker_id, attempt, reason, message, at_ms)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
        params![
            task.id,
            task.job_id,
            worker,
            task.attempt,
            kind.as_str(),
            reason,
            now
        ],
    )?;
    Ok(tx.row(
        "SELECT count(*) FROM task_failures WHERE job_id = ?1 AND worker_id = ?2",
        params![task.job_id, worker],
        |r| r.get(0),
    )?)
}

/// Forgets the failed attempts of `job`'s tasks (retried with fresh attempts).
pub fn forget(tx: &Transaction, job: u64) -> Result<()> {
    tx.exec("DELETE FROM task_failures WHERE job_id = ?1", [job])?;
    Ok(())
}

/// How many attempts of `job`'s tasks failed (since their last retry).
pub fn count(conn: &Connection, job: u64) -> Result<u64> {
    Ok(conn.row(
        "SELECT count(*) FROM task_failures WHERE job_id = ?1",
        [job],
        |r| r.get(0),
    )?)
}

/// The failed attempts of the tasks `tasks` (of `job`), each task's oldest first.
pub fn of_tasks(
    conn: &Connection,
    job: u64,
    tasks: &[u64],
) -> Result<HashMap<u64, Vec<TaskFailure>>> {
    let mut by_task: HashMap<u64, Vec<TaskFailure>> = HashMap::new();
    let (Some(&first), Some(&last)) = (tasks.iter().min(), tasks.iter().max()) else {
        return Ok(by_task);
    };
    let mut stmt = conn.prepare_cached(
        "SELECT f.task_id, f.attempt, f.worker_id, coalesce(w.name, ''), f.reason, f.message,
                f.at_ms
         FROM task_failures f LEFT JOIN workers w ON w.id = f.worker_id
         WHERE f.job_id = ?1 AND f.task_id BETWEEN ?2 AND ?3
         ORDER BY f.task_id, f.at_ms, f.attempt",
    )?;
    let rows = stmt.query_map(params![job, first, last], |r| {
        Ok((
            r.get::<_, u64>(0)?,
            TaskFailure {
                attempt: r.get(1)?,
                worker_id: r.get(2)?,
                worker: r.get(3)?,
                kind: kind_from_sql(r, 4)?,
                reason: r.get(5)?,
                at_ms: r.get(6)?,
            },
        ))
    })?;
    for row in rows {
        let (task, failure) = row?;
        if tasks.contains(&task) {
            by_task.entry(task).or_default().push(failure);
        }
    }
    Ok(by_task)
}

/// The failed attempts of `job` grouped by kind and reason, most attempts first; at most
/// `limit` groups.
pub fn groups(conn: &Connection, job: u64, limit: usize) -> Result<Vec<FailureGroup>> {
    let mut stmt = conn.prepare_cached(
        "SELECT reason, message, count(*), count(DISTINCT task_id), min(task_id), max(at_ms)
         FROM task_failures WHERE job_id = ?1
         GROUP BY reason, message
         ORDER BY count(*) DESC, max(at_ms) DESC LIMIT ?2",
    )?;
    let rows = stmt.query_map(params![job, limit as i64], |r| {
        Ok(FailureGroup {
            kind: kind_from_sql(r, 0)?,
            reason: r.get(1)?,
            attempts: r.get(2)?,
            tasks: r.get(3)?,
            example_task: r.get(4)?,
            last_ms: r.get(5)?,
            workers: Vec::new(),
        })
    })?;
    let mut groups: Vec<FailureGroup> = rows.collect::<rusqlite::Result<_>>()?;
    let mut names = conn.prepare_cached(
        "SELECT DISTINCT coalesce(w.name, 'worker ' || f.worker_id)
         FROM task_failures f LEFT JOIN workers w ON w.id = f.worker_id
         WHERE f.job_id = ?1 AND f.reason = ?2 AND f.message = ?3 ORDER BY 1",
    )?;
    for g in &mut groups {
        let rows = names.query_map(params![job, g.kind.as_str(), g.reason], |r| r.get(0))?;
        g.workers = rows.collect::<rusqlite::Result<_>>()?;
    }
    Ok(groups)
}
