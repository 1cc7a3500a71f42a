//! The `frames` table: each frame's task count, its assembly (done, failed, what it
//! reached), and the frame list clients read.

use proto::{FrameList, FrameStatus};
use rusqlite::{params, Connection, OptionalExtension, Transaction};
use tracer::film::SamplingSummary;

use super::Cached;
use crate::error::{Error, Result};
use crate::state::{frame_state, FrameFacts};

/// A frame (row of `frames`) whose tasks are all done but that is not assembled from all
/// of them: a time-budget frame that got a pass is assembled again.
pub(super) const NEEDS_ASSEMBLY: &str =
    "tasks_done = tasks_total AND assembled_tasks IS NOT tasks_total AND failure IS NULL";

/// Stores a frame of a new job with its task count.
pub fn insert(tx: &Transaction, job: u64, frame: i32, tasks: u64) -> Result<()> {
    tx.exec(
        "INSERT INTO frames (job_id, frame, tasks_total) VALUES (?1, ?2, ?3)",
        params![job, frame, tasks],
    )?;
    Ok(())
}

/// Counts a finished task of a frame.
pub fn count_done(tx: &Transaction, job: u64, frame: i32) -> Result<()> {
    tx.exec(
        "UPDATE frames SET tasks_done = tasks_done + 1 WHERE job_id = ?1 AND frame = ?2",
        params![job, frame],
    )?;
    Ok(())
}

/// Whether every task of a frame is done.
pub fn is_complete(conn: &Connection, job: u64, frame: i32) -> Result<bool> {
    Ok(conn.row(
        "SELECT tasks_done = tasks_total FROM frames WHERE job_id = ?1 AND frame = ?2",
        params![job, frame],
        |r| r.get(0),
    )?)
}

/// A frame gained (or, negative, lost) `tasks` tasks.
pub fn add_tasks(tx: &Transaction, job: u64, frame: i32, tasks: i64) -> Result<()> {
    tx.exec(
        "UPDATE frames SET tasks_total = tasks_total + ?3 WHERE job_id = ?1 AND frame = ?2",
        params![job, frame, tasks],
    )?;
    Ok(())
}

/// A frame is assembled from every task it has so far, reaching `reached`.
pub fn set_assembled(
    tx: &Transaction,
    job: u64,
    frame: i32,
    now: i64,
    reached: &SamplingSummary,
) -> Result<()> {
    tx.exec(
        "UPDATE frames SET assembled_ms = ?3, assembled_tasks = tasks_total, spp_mean = ?4,
                           noise = ?5
         WHERE job_id = ?1 AND frame = ?2",
        params![job, frame, now, reached.mean_samples, reached.mean_noise],
    )?;
    Ok(())
}

/// A frame's assembly failed, for `reason`.
pub fn set_failure(tx: &Transaction, job: u64, frame: i32, reason: &str) -> Result<()> {
    tx.exec(
        "UPDATE frames SET failure = ?3 WHERE job_id = ?1 AND frame = ?2",
        params![job, frame, reason],
    )?;
    Ok(())
}

/// Whether `job` has frame `frame`.
pub fn exists(conn: &Connection, job: u64, frame: i32) -> Result<bool> {
    Ok(conn.row(
        "SELECT EXISTS (SELECT 1 FROM frames WHERE job_id = ?1 AND frame = ?2)",
        params![job, frame],
        |r| r.get(0),
    )?)
}

/// Whether a frame of `job` has every task done but is not assembled from them yet.
pub fn any_needs_assembly(conn: &Connection, job: u64) -> Result<bool> {
    Ok(conn.row(
        &format!("SELECT EXISTS (SELECT 1 FROM frames WHERE job_id = ?1 AND {NEEDS_ASSEMBLY})"),
        [job],
        |r| r.get(0),
    )?)
}

/// How many frames of `job` have no denoised layer.
pub fn undenoised_count(conn: &Connection, job: u64) -> Result<u64> {
    Ok(conn.row(
        "SELECT count(*) FROM frames WHERE job_id = ?1 AND denoised_ms IS NULL",
        [job],
        |r| r.get(0),
    )?)
}

/// The frames of `job` assembled from every task they have, in order.
pub fn assembled(conn: &Connection, job: u64) -> Result<Vec<i32>> {
    let mut stmt = conn.prepare(
        "SELECT frame FROM frames WHERE job_id = ?1 AND assembled_ms IS NOT NULL
           AND assembled_tasks = tasks_total ORDER BY frame",
    )?;
    let rows = stmt.query_map([job], |r| r.get(0))?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// Whether every task of a frame is done but the frame is not assembled from them yet.
pub fn needs_assembly(conn: &Connection, job: u64, frame: i32) -> Result<bool> {
    Ok(conn.row(
        &format!("SELECT {NEEDS_ASSEMBLY} FROM frames WHERE job_id = ?1 AND frame = ?2"),
        params![job, frame],
        |r| r.get(0),
    )?)
}

/// A frame starts again with `tasks` tasks, none done, not assembled, not failed.
pub fn reset(tx: &Transaction, job: u64, frame: i32, tasks: u64) -> Result<()> {
    tx.exec(
        "UPDATE frames SET tasks_total = ?3, tasks_done = 0, assembled_ms = NULL,
                           assembled_tasks = NULL, spp_mean = NULL, noise = NULL, failure = NULL,
                           denoised_ms = NULL
         WHERE job_id = ?1 AND frame = ?2",
        params![job, frame, tasks],
    )?;
    Ok(())
}

/// A frame's denoised layer is written.
pub fn set_denoised(tx: &Transaction, job: u64, frame: i32, now: i64) -> Result<()> {
    tx.exec(
        "UPDATE frames SET denoised_ms = ?3 WHERE job_id = ?1 AND frame = ?2",
        params![job, frame, now],
    )?;
    Ok(())
}

/// Forgets the failed assemblies of `job`; returns how many frames had one.
pub fn clear_failures(tx: &Transaction, job: u64) -> Result<usize> {
    Ok(tx.exec(
        "UPDATE frames SET failure = NULL WHERE job_id = ?1 AND failure IS NOT NULL",
        [job],
    )?)
}

/// Whether a frame is assembled from all of its tasks so far.
pub fn is_assembled(conn: &Connection, job: u64, frame: i32) -> Result<bool> {
    Ok(conn.row(
        "SELECT assembled_tasks IS tasks_total FROM frames WHERE job_id = ?1 AND frame = ?2",
        params![job, frame],
        |r| r.get(0),
    )?)
}

/// Frames whose tasks are all done but which are not assembled from all of them (a crash
/// in between, or a full disk), of jobs not cancelled.
pub fn unassembled(conn: &Connection) -> Result<Vec<(u64, i32)>> {
    let mut stmt = conn.prepare_cached(&format!(
        "SELECT job_id, frame FROM frames JOIN jobs ON jobs.id = frames.job_id
         WHERE control != 'cancelled' AND {NEEDS_ASSEMBLY}"
    ))?;
    let rows = stmt.query_map([], |r| Ok((r.get(0)?, r.get(1)?)))?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// A frame `f` whose denoise task is not done (queued, leased, failed or cancelled).
const DENOISE_UNFINISHED: &str = "EXISTS (SELECT 1 FROM tasks t WHERE t.job_id = f.job_id
        AND t.frame = f.frame AND t.kind = 'denoise' AND t.state != 'done')";

/// A job's frames, and those finished: assembled, and denoised where the job denoises.
pub fn counts(conn: &Connection, job: u64) -> Result<(u64, u64)> {
    Ok(conn.row(
        &format!(
            "SELECT count(*),
                    coalesce(sum(f.assembled_ms IS NOT NULL AND NOT {DENOISE_UNFINISHED}), 0)
             FROM frames f WHERE f.job_id = ?1"
        ),
        [job],
        |r| Ok((r.get(0)?, r.get(1)?)),
    )?)
}

/// A job's failed frames: a task out of attempts, or the assembly.
pub fn failed_count(conn: &Connection, job: u64) -> Result<u64> {
    Ok(conn.row(
        "SELECT count(*) FROM frames f WHERE job_id = ?1
           AND (failure IS NOT NULL
                OR EXISTS (SELECT 1 FROM tasks t WHERE t.job_id = f.job_id
                             AND t.frame = f.frame AND t.state = 'failed'))",
        [job],
        |r| r.get(0),
    )?)
}

const STATUS_QUERY: &str = "SELECT f.frame, f.tasks_total, f.tasks_done, f.assembled_ms,
        f.spp_mean, f.noise,
        (SELECT count(*) FROM tasks t WHERE t.job_id = f.job_id AND t.frame = f.frame
           AND t.state = 'failed'),
        (SELECT count(*) FROM tasks t WHERE t.job_id = f.job_id AND t.frame = f.frame
           AND t.state = 'leased'),
        j.control, f.failure,
        (SELECT max(frame) FROM frames WHERE job_id = f.job_id),
        (SELECT count(*) FROM tasks t WHERE t.job_id = f.job_id AND t.frame = f.frame
           AND t.kind = 'denoise' AND t.state != 'done')
     FROM frames f JOIN jobs j ON j.id = f.job_id";

fn status_from_row(r: &rusqlite::Row) -> rusqlite::Result<FrameStatus> {
    let frame: i32 = r.get(0)?;
    let (total, done): (u64, u64) = (r.get(1)?, r.get(2)?);
    let (failed, leased): (u64, u64) = (r.get(6)?, r.get(7)?);
    let failure: Option<String> = r.get(9)?;
    let state = frame_state(FrameFacts {
        assembly_failed: failure.is_some(),
        assembled: r.get::<_, Option<i64>>(3)?.is_some(),
        tasks_failed: failed,
        control: super::jobs::control_from_sql(r, 8)?,
        started: done > 0 || leased > 0,
        denoise_unfinished: r.get::<_, u64>(11)? > 0,
    });
    Ok(FrameStatus {
        frame,
        state,
        tasks_total: total,
        tasks_done: done,
        spp_mean: r.get(4)?,
        noise: r.get(5)?,
        file: proto::job::frame_file_name(frame, r.get(10)?, "exr"),
        failure,
    })
}

/// The frames of a job, in order.
pub fn list(conn: &Connection, job: u64) -> Result<FrameList> {
    super::jobs::control(conn, job)?;
    let mut stmt = conn.prepare_cached(&format!(
        "{STATUS_QUERY} WHERE f.job_id = ?1 ORDER BY f.frame"
    ))?;
    let rows = stmt.query_map([job], status_from_row)?;
    Ok(FrameList {
        frames: rows.collect::<rusqlite::Result<_>>()?,
    })
}

/// One frame of a job.
pub fn status(conn: &Connection, job: u64, frame: i32) -> Result<FrameStatus> {
    conn.row(
        &format!("{STATUS_QUERY} WHERE f.job_id = ?1 AND f.frame = ?2"),
        params![job, frame],
        status_from_row,
    )
    .optional()?
    .ok_or_else(|| Error::NotFound(format!("job {job} has no frame {frame}")))
}
