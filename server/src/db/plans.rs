//! What the time-budget planner ([`crate::budget`]) reads and changes: each worker's
//! recent speed on a job, the work open, the frames that could take a pass, and the passes
//! themselves.

use rusqlite::{params, Connection, OptionalExtension, Transaction};
use tracer::film::{SampleRange, TileRect};

use super::tasks::{self, NewTask};
use super::{frames, jobs, Cached};
use crate::error::Result;
use crate::limits::MAX_SAMPLE_PASSES;

/// The pixel samples of `worker`'s last `window` done tiles of `job`, and the
/// milliseconds from lease to upload they took; `None` before its first.
pub fn recent_speed(
    conn: &Connection,
    job: u64,
    worker: u64,
    window: u32,
) -> Result<Option<(i64, i64)>> {
    let (samples, ms): (Option<i64>, Option<i64>) = conn.row(
        "SELECT sum(w * h * (sample_end - sample_start)), sum(max(done_ms - leased_ms, 1))
         FROM (SELECT w, h, sample_start, sample_end, done_ms, leased_ms FROM tasks
               WHERE job_id = ?1 AND worker_id = ?2 AND state = 'done' AND kind = 'render'
               ORDER BY done_ms DESC LIMIT ?3)",
        params![job, worker, window],
        |r| Ok((r.get(0)?, r.get(1)?)),
    )?;
    Ok(samples.zip(ms))
}

/// Work queued and leased (checks included: they take a worker's time too).
#[derive(Clone, Copy, Debug, Default)]
pub struct Open {
    /// Pixel samples.
    pub samples: f64,
    /// The largest task's pixel samples.
    pub largest: f64,
    /// Tasks queued.
    pub queued: u64,
    /// First-pass tasks queued.
    pub first_pass_queued: u64,
}

/// The work of `job` queued and leased.
pub fn open_work(conn: &Connection, job: u64) -> Result<Open> {
    Ok(conn.row(
        "SELECT coalesce(sum(w * h * (sample_end - sample_start)), 0),
                coalesce(max(w * h * (sample_end - sample_start)), 0),
                coalesce(sum(state = 'queued'), 0),
                coalesce(sum(state = 'queued' AND pass = 0 AND check_of IS NULL), 0)
         FROM tasks WHERE job_id = ?1 AND state IN ('queued', 'leased')",
        [job],
        |r| {
            Ok(Open {
                samples: r.get::<_, i64>(0)? as f64,
                largest: r.get::<_, i64>(1)? as f64,
                queued: r.get(2)?,
                first_pass_queued: r.get(3)?,
            })
        },
    )?)
}

/// The frame that most needs a pass, with the samples it reached and its next pass's
/// index: assembled with everything it has (nothing of it in flight), under `spp`, highest
/// estimated error first (no estimate counts as the highest), then fewest samples.
pub fn noisiest_frame(conn: &Connection, job: u64, spp: u32) -> Result<Option<(i32, u32, u32)>> {
    Ok(conn
        .row(
            "SELECT frame, reached, passes FROM (
                 SELECT f.frame, f.noise,
                        (SELECT max(t.sample_end) FROM tasks t WHERE t.job_id = f.job_id
                           AND t.frame = f.frame AND t.check_of IS NULL) AS reached,
                        (SELECT max(t.pass) + 1 FROM tasks t WHERE t.job_id = f.job_id
                           AND t.frame = f.frame AND t.check_of IS NULL) AS passes
                 FROM frames f
                 WHERE f.job_id = ?1 AND f.tasks_done = f.tasks_total
                   AND f.assembled_tasks IS f.tasks_total)
             WHERE reached < ?2 AND passes < ?3
             ORDER BY noise IS NOT NULL, noise DESC, reached, frame LIMIT 1",
            params![job, spp, MAX_SAMPLE_PASSES],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
        )
        .optional()?)
}

/// Frames of `job` still under `spp` (at least 1).
pub fn hungry_frames(conn: &Connection, job: u64, spp: u32) -> Result<u32> {
    let n: u32 = conn.row(
        "SELECT count(*) FROM frames f WHERE f.job_id = ?1
           AND (SELECT max(t.sample_end) FROM tasks t
                WHERE t.job_id = f.job_id AND t.frame = f.frame) < ?2",
        params![job, spp],
        |r| r.get(0),
    )?;
    Ok(n.max(1))
}

/// The tiles of a frame (those of its first pass: every pass covers the same ones).
pub fn tiles(conn: &Connection, job: u64, frame: i32) -> Result<Vec<(u32, TileRect)>> {
    let mut stmt = conn.prepare_cached(
        "SELECT tile, x, y, w, h FROM tasks
         WHERE job_id = ?1 AND frame = ?2 AND pass = 0 AND check_of IS NULL ORDER BY tile",
    )?;
    let rows = stmt.query_map(params![job, frame], |r| {
        Ok((
            r.get(0)?,
            TileRect::new(r.get(1)?, r.get(2)?, r.get(3)?, r.get(4)?),
        ))
    })?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// How many tasks `job` holds.
pub fn task_count(conn: &Connection, job: u64) -> Result<u64> {
    Ok(
        conn.row("SELECT count(*) FROM tasks WHERE job_id = ?1", [job], |r| {
            r.get(0)
        })?,
    )
}

/// How many passes were added to `job`'s frames beyond the first.
pub fn passes_added(conn: &Connection, job: u64) -> Result<u32> {
    Ok(conn.row(
        "SELECT count(*) FROM tasks WHERE job_id = ?1 AND pass > 0 AND tile = 0
           AND check_of IS NULL",
        [job],
        |r| r.get(0),
    )?)
}

/// Queues a pass of `samples` over `tiles` of a frame of `frame_pixels` pixels.
pub fn add_pass(
    tx: &Transaction,
    job: u64,
    frame: i32,
    pass: u32,
    tiles: &[(u32, TileRect)],
    samples: SampleRange,
    frame_pixels: f64,
) -> Result<()> {
    for &(tile, rect) in tiles {
        tasks::insert(
            tx,
            &NewTask {
                kind: proto::TaskKind::Render,
                job,
                frame,
                tile,
                pass,
                rect,
                samples,
                check_of: None,
                round: 0,
            },
        )?;
    }
    frames::add_tasks(tx, job, frame, tiles.len() as i64)?;
    jobs::add_pixel_samples(tx, job, (frame_pixels * f64::from(samples.len())) as i64)
}

/// Removes the newest pass (after the first) of which no task was ever leased; returns
/// whether there was one.
pub fn withdraw_unstarted_pass(tx: &Transaction, job: u64, frame_pixels: f64) -> Result<bool> {
    let newest: Option<(i32, u32, i64, i64)> = tx
        .row(
            "SELECT frame, pass, count(*), max(sample_end - sample_start) FROM tasks
             WHERE job_id = ?1 AND pass > 0 AND check_of IS NULL
             GROUP BY frame, pass
             HAVING sum(state != 'queued' OR attempt > 0) = 0
             ORDER BY max(id) DESC LIMIT 1",
            [job],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)),
        )
        .optional()?;
    let Some((frame, pass, tasks, samples)) = newest else {
        return Ok(false);
    };
    tx.exec(
        "DELETE FROM tasks WHERE job_id = ?1 AND frame = ?2 AND pass = ?3",
        params![job, frame, pass],
    )?;
    frames::add_tasks(tx, job, frame, -tasks)?;
    jobs::add_pixel_samples(tx, job, -((frame_pixels * samples as f64) as i64))?;
    Ok(true)
}

/// The tasks time-budget jobs could run now beyond those queued and leased: a budget job
/// keeps only a few tasks per live worker queued, however much work it has left, so its
/// queue says nothing about how many workers it could use. Each of its frames still under
/// the job's spp with no pass open could run a pass of one task per tile now, had it the
/// workers. Counts active jobs before their deadline.
pub fn waiting_passes(conn: &Connection, now: i64) -> Result<u64> {
    Ok(conn.row(
        "SELECT coalesce(sum((SELECT count(*) FROM tasks t WHERE t.job_id = f.job_id
                                AND t.frame = f.frame AND t.pass = 0
                                AND t.check_of IS NULL)), 0)
         FROM frames f JOIN jobs j ON j.id = f.job_id
         WHERE j.control = 'active'
           AND json_extract(j.spec, '$.time_budget') IS NOT NULL
           AND j.created_ms + json_extract(j.spec, '$.time_budget') * 1000 > ?1
           AND (SELECT max(t.sample_end) FROM tasks t WHERE t.job_id = f.job_id
                  AND t.frame = f.frame AND t.check_of IS NULL)
               < json_extract(j.spec, '$.spp')
           AND NOT EXISTS (SELECT 1 FROM tasks t WHERE t.job_id = f.job_id
                             AND t.frame = f.frame AND t.state IN ('queued', 'leased'))",
        [now],
        |r| r.get(0),
    )?)
}
