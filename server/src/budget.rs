//! Time budgets: "render frames 1-600 within 256 seconds on the workers I have". A budget
//! job starts as one pass of `min_spp` samples for every frame, so that every frame exists
//! early. Whenever one of its frames is assembled, [`replan`] measures the farm and adds a
//! sample pass to the frame with the highest estimated error, for as long as the work
//! queued and leased is predicted to end before the deadline. A worker that joins or leaves
//! changes the measured speed, so it changes the plan, never the deadline.
//!
//! A pass goes to a whole frame (every tile), so a frame's noise is even across it. It at
//! most doubles the frame's samples, so each pass buys about the same relative error, and
//! it takes at most the frame's share of the time left, so late passes stay small enough to
//! go round the frames.

use proto::{BudgetPlan, JobSpec};
use rusqlite::{params, OptionalExtension, Transaction};
use tracer::film::{SampleRange, TileRect};

use crate::db::Cached;
use crate::error::Result;
use crate::limits::MAX_SAMPLE_PASSES;
use crate::scheduler::insert_task;

/// A worker's speed is measured over its last this many tiles of the job.
const SPEED_WINDOW: u32 = 8;
/// Queued tasks kept per live worker, so that none waits for the next pass.
const QUEUE_PER_WORKER: u64 = 2;
/// The measured speeds are discounted by this much: a later frame may be slower, and the
/// last frame's assembly comes after its last tile.
const SPEED_MARGIN: f64 = 0.9;

/// The share of the budget kept for assembling the last frames (at least 0.25 s, at most
/// 30 s).
const RESERVE_FRACTION: f64 = 0.02;

/// The farm's speed on one job, in pixel samples per second.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Speed {
    /// Summed over the measured workers.
    total: f64,
    /// The slowest measured worker's: the last task of a pass may fall to it.
    slowest: f64,
    /// Workers measured.
    measured: u32,
    /// Live workers that may work on the job (measured or not yet).
    live: u32,
}

/// Each live worker's speed (a worker is live if seen since `live_since`): the pixel
/// samples of its last [`SPEED_WINDOW`] tiles of the job over the time from lease to
/// upload (so preparing frames and uploads count).
fn measure(tx: &Transaction, job: u64, live_since: i64) -> Result<Speed> {
    let workers: Vec<u64> = {
        let mut stmt = tx.prepare_cached(
            "SELECT w.id FROM workers w
             WHERE w.last_seen_ms >= ?2 AND w.left_ms IS NULL AND w.quarantined_ms IS NULL
               AND NOT EXISTS (SELECT 1 FROM job_blocks b
                               WHERE b.job_id = ?1 AND b.worker_id = w.id)",
        )?;
        let rows = stmt.query_map(params![job, live_since], |r| r.get(0))?;
        rows.collect::<rusqlite::Result<_>>()?
    };
    let mut speed = Speed {
        slowest: f64::INFINITY,
        live: workers.len() as u32,
        ..Speed::default()
    };
    let mut stmt = tx.prepare_cached(
        "SELECT sum(w * h * (sample_end - sample_start)), sum(max(done_ms - leased_ms, 1))
         FROM (SELECT w, h, sample_start, sample_end, done_ms, leased_ms FROM tasks
               WHERE job_id = ?1 AND worker_id = ?2 AND state = 'done'
               ORDER BY done_ms DESC LIMIT ?3)",
    )?;
    for worker in workers {
        let (samples, ms): (Option<i64>, Option<i64>) = stmt
            .query_row(params![job, worker, SPEED_WINDOW], |r| {
                Ok((r.get(0)?, r.get(1)?))
            })?;
        if let (Some(samples), Some(ms)) = (samples, ms) {
            let rate = samples as f64 / (ms as f64 / 1000.0) * SPEED_MARGIN;
            speed.total += rate;
            speed.slowest = speed.slowest.min(rate);
            speed.measured += 1;
        }
    }
    if speed.measured == 0 {
        speed.slowest = 0.0;
    }
    Ok(speed)
}

/// Work queued and leased (checks included: they take a worker's time too).
#[derive(Clone, Copy, Debug, Default)]
struct Open {
    /// Pixel samples.
    samples: f64,
    /// The largest task's pixel samples.
    largest: f64,
    /// Tasks queued.
    queued: u64,
    /// First-pass tasks queued.
    first_pass_queued: u64,
}

fn open_work(tx: &Transaction, job: u64) -> Result<Open> {
    Ok(tx.row(
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

/// Seconds until `open` is done at `speed`: the work shared among the workers, then the
/// largest task on the slowest of them.
fn seconds_to_finish(open: &Open, speed: &Speed) -> f64 {
    open.samples / speed.total + open.largest / speed.slowest
}

/// The frame that most needs a pass: assembled with everything it has (nothing of it in
/// flight), under the job's spp, highest estimated error first (no estimate counts as the
/// highest), then fewest samples.
fn noisiest_frame(tx: &Transaction, job: u64, spp: u32) -> Result<Option<(i32, u32, u32)>> {
    Ok(tx
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

/// Frames still under the job's spp (at least 1).
fn hungry_frames(tx: &Transaction, job: u64, spp: u32) -> Result<u32> {
    let n: u32 = tx.row(
        "SELECT count(*) FROM frames f WHERE f.job_id = ?1
           AND (SELECT max(t.sample_end) FROM tasks t
                WHERE t.job_id = f.job_id AND t.frame = f.frame) < ?2",
        params![job, spp],
        |r| r.get(0),
    )?;
    Ok(n.max(1))
}

/// The tiles of a frame (those of its first pass: every pass covers the same ones).
fn tiles(tx: &Transaction, job: u64, frame: i32) -> Result<Vec<(u32, TileRect)>> {
    let mut stmt = tx.prepare_cached(
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

/// Removes the newest pass (after the first) of which no task was ever leased; returns
/// whether there was one.
fn withdraw_unstarted_pass(tx: &Transaction, job: u64, frame_pixels: f64) -> Result<bool> {
    let newest: Option<(i32, u32, u32, i64)> = tx
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
    tx.exec(
        "UPDATE frames SET tasks_total = tasks_total - ?3 WHERE job_id = ?1 AND frame = ?2",
        params![job, frame, tasks],
    )?;
    tx.exec(
        "UPDATE jobs SET pixel_samples = pixel_samples - ?2 WHERE id = ?1",
        params![job, (frame_pixels * samples as f64) as i64],
    )?;
    Ok(true)
}

/// The tasks time-budget jobs could run now beyond those queued and leased: a budget job
/// keeps only about `QUEUE_PER_WORKER` (2) tasks per live worker queued, however much work
/// it has left, so its queue says nothing about how many workers it could use. Each of its
/// frames still under the job's spp with no pass open could run a pass of one task per
/// tile now, had it the workers. Counts active jobs before their deadline.
pub fn waiting_passes(conn: &rusqlite::Connection, now: i64) -> Result<u64> {
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

/// Plans a time-budget job again at `now` (see the module documentation): adds the passes
/// that fit and stores the plan for the job's status. Workers seen since `live_since` count
/// as live; the job holds at most `max_tasks` tasks. Does nothing for other jobs.
pub fn replan(
    tx: &Transaction,
    job: u64,
    spec: &JobSpec,
    now: i64,
    live_since: i64,
    max_tasks: u64,
) -> Result<()> {
    let Some(budget) = spec.time_budget else {
        return Ok(());
    };
    let (control, created_ms): (String, i64) = tx.row(
        "SELECT control, created_ms FROM jobs WHERE id = ?1",
        [job],
        |r| Ok((r.get(0)?, r.get(1)?)),
    )?;
    let deadline_ms = created_ms + (budget * 1000.0).round() as i64;
    // The last frames are assembled after their last tiles come in: plan to end a little
    // before the deadline.
    let plan_end_ms =
        deadline_ms - (budget * RESERVE_FRACTION * 1000.0).clamp(250.0, 30_000.0) as i64;
    let speed = measure(tx, job, live_since)?;
    let mut open = open_work(tx, job)?;
    let first_spp = spec.min_spp.unwrap_or(1).max(1);
    let frame_pixels = spec.width as f64 * spec.height as f64;

    let stage = if control != "active" {
        format!("{control}: no passes added")
    } else if open.first_pass_queued > 0 {
        format!("first pass: every frame at {first_spp} spp")
    } else if speed.measured == 0 {
        "waiting for a worker's speed".to_string()
    } else {
        let mut stage = String::from("refining: the noisiest frames get more samples");
        let mut tasks: u64 =
            tx.row("SELECT count(*) FROM tasks WHERE job_id = ?1", [job], |r| {
                r.get(0)
            })?;
        while open.queued < QUEUE_PER_WORKER * u64::from(speed.live.max(1)) {
            let Some((frame, reached, pass)) = noisiest_frame(tx, job, spec.spp)? else {
                stage = if open.samples > 0.0 {
                    "refining: every frame that can take more has a pass running".into()
                } else {
                    format!("done: every frame reached {} spp", spec.spp)
                };
                break;
            };
            let tiles = tiles(tx, job, frame)?;
            if tasks + tiles.len() as u64 > max_tasks {
                stage = format!("stopped: the job holds {tasks} tasks, this server's limit");
                break;
            }
            let largest_tile = tiles.iter().map(|(_, r)| r.area()).max().unwrap_or(0) as f64;
            // The pass fits when the open work, the pass shared out, and the larger of the
            // last tasks on the slowest worker all end by the deadline.
            let left = (plan_end_ms - now) as f64 / 1000.0 - open.samples / speed.total;
            let fit_shared = (left - open.largest / speed.slowest) / (frame_pixels / speed.total);
            let fit_tail = left / (frame_pixels / speed.total + largest_tile / speed.slowest);
            let fit = fit_shared.min(fit_tail).floor().max(0.0) as u32;
            // A frame's fair share of the samples left, so that one frame's big pass late
            // in the budget does not leave the others behind.
            let share =
                (left * speed.total / frame_pixels / f64::from(hungry_frames(tx, job, spec.spp)?))
                    .floor()
                    .max(f64::from(first_spp)) as u32;
            let k = reached.min(spec.spp - reached).min(fit).min(share);
            if k < first_spp.min(spec.spp - reached) {
                stage = format!(
                    "stopped: another pass on frame {frame} (at {reached} spp) would end \
                     after the deadline"
                );
                break;
            }
            let samples = SampleRange::new(reached, reached + k);
            for (tile, rect) in &tiles {
                insert_task(tx, job, frame, *tile, pass, *rect, samples)?;
            }
            tx.exec(
                "UPDATE frames SET tasks_total = tasks_total + ?3 WHERE job_id = ?1 AND frame = ?2",
                params![job, frame, tiles.len()],
            )?;
            tx.exec(
                "UPDATE jobs SET pixel_samples = pixel_samples + ?2 WHERE id = ?1",
                params![job, (frame_pixels * f64::from(k)) as i64],
            )?;
            open.samples += frame_pixels * f64::from(k);
            open.largest = open.largest.max(largest_tile * f64::from(k));
            open.queued += tiles.len() as u64;
            tasks += tiles.len() as u64;
        }
        // The farm slowed (a worker left): passes nobody started that would end after
        // the deadline go, newest first.
        let mut withdrawn = 0;
        while now as f64 + seconds_to_finish(&open, &speed) * 1000.0 > deadline_ms as f64 {
            if !withdraw_unstarted_pass(tx, job, frame_pixels)? {
                break;
            }
            withdrawn += 1;
            open = open_work(tx, job)?;
        }
        if withdrawn > 0 {
            stage = format!("slowed down: {withdrawn} pass(es) nobody started were withdrawn");
        }
        stage
    };
    let passes_added: u32 = tx.row(
        "SELECT count(*) FROM tasks WHERE job_id = ?1 AND pass > 0 AND tile = 0
           AND check_of IS NULL",
        [job],
        |r| r.get(0),
    )?;
    let predicted_end_ms = (speed.measured > 0)
        .then(|| now + (seconds_to_finish(&open, &speed) * 1000.0).round() as i64);
    let plan = BudgetPlan {
        budget_seconds: budget,
        deadline_ms,
        planned_ms: now,
        samples_per_second: speed.total,
        workers: speed.measured,
        predicted_end_ms,
        passes_added,
        stage,
    };
    tx.exec(
        "UPDATE jobs SET budget_plan = ?2 WHERE id = ?1",
        params![job, serde_json::to_string(&plan)?],
    )?;
    Ok(())
}
