//! The `task_logs` table: the lines a worker logged while it held a task, per attempt,
//! at most [`MAX_TASK_LOG_LINES`] each (then one row that says more were dropped).

use proto::log::MAX_TASK_LOG_LINES;
use proto::{AttemptLog, LogLevel, LogLine};
use rusqlite::{params, Connection, Transaction};

use super::Cached;
use crate::error::Result;

/// The `seq` of the row that marks an attempt's log as cut short.
const TRUNCATED_SEQ: usize = MAX_TASK_LOG_LINES;

/// Appends `lines` to the log of `attempt` at `task` by `worker`, each cut to
/// [`proto::log::MAX_LOG_LINE_BYTES`], until the attempt holds [`MAX_TASK_LOG_LINES`].
pub fn append(
    tx: &Transaction,
    task: u64,
    attempt: u32,
    worker: u64,
    lines: &[LogLine],
) -> Result<()> {
    if lines.is_empty() {
        return Ok(());
    }
    let held: usize = tx.row(
        "SELECT count(*) FROM task_logs WHERE task_id = ?1 AND attempt = ?2",
        params![task, attempt],
        |r| r.get(0),
    )?;
    let insert = "INSERT OR IGNORE INTO task_logs
                  (task_id, attempt, seq, worker_id, at_ms, level, text)
                  VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)";
    for (seq, line) in (held..).zip(lines) {
        if seq >= TRUNCATED_SEQ {
            let at = line.at_ms;
            tx.exec(
                insert,
                params![task, attempt, TRUNCATED_SEQ, worker, at, "WARN", ""],
            )?;
            break;
        }
        let line = LogLine::bounded(line.at_ms, line.level, line.text.clone());
        tx.exec(
            insert,
            params![
                task,
                attempt,
                seq,
                worker,
                line.at_ms,
                line.level.as_str(),
                line.text
            ],
        )?;
    }
    Ok(())
}

/// Every attempt of `task` that logged something, oldest first, with its lines.
pub fn of_task(conn: &Connection, task: u64) -> Result<Vec<AttemptLog>> {
    let mut stmt = conn.prepare_cached(
        "SELECT l.attempt, l.seq, l.worker_id, coalesce(w.name, 'worker ' || l.worker_id),
                l.at_ms, l.level, l.text
         FROM task_logs l LEFT JOIN workers w ON w.id = l.worker_id
         WHERE l.task_id = ?1 ORDER BY l.attempt, l.seq",
    )?;
    let mut rows = stmt.query([task])?;
    let mut attempts: Vec<AttemptLog> = Vec::new();
    while let Some(r) = rows.next()? {
        let attempt: u32 = r.get(0)?;
        if attempts.last().map(|a| a.attempt) != Some(attempt) {
            attempts.push(AttemptLog {
                attempt,
                worker_id: r.get(2)?,
                worker: r.get(3)?,
                lines: Vec::new(),
                truncated: false,
            });
        }
        let log = attempts.last_mut().expect("pushed above");
        if r.get::<_, usize>(1)? == TRUNCATED_SEQ {
            log.truncated = true;
            continue;
        }
        let level: String = r.get(5)?;
        log.lines.push(LogLine {
            at_ms: r.get(4)?,
            level: LogLevel::parse(&level).ok_or_else(|| {
                rusqlite::Error::FromSqlConversionFailure(
                    5,
                    rusqlite::types::Type::Text,
                    format!("unknown log level `{level}`").into(),
                )
            })?,
            text: r.get(6)?,
        });
    }
    Ok(attempts)
}
