//! The `workers` table: registration and return, liveness, quarantine and suspicion, and
//! the worker list clients read. Credentials are stored as their SHA-256 only; the caller
//! hashes.

use proto::{TaskToken, WorkerInfo, WorkerList};
use rusqlite::{params, Connection, OptionalExtension, Transaction};

use super::{has_required_tags, Cached};
use crate::error::{Error, Result};

/// What a worker says of itself when it joins.
#[derive(Clone, Copy, Debug)]
pub struct Profile<'a> {
    /// Its name.
    pub name: &'a str,
    /// Render threads.
    pub threads: u32,
    /// Its version.
    pub version: &'a str,
    /// Its machine and build.
    pub platform: Option<&'a str>,
    /// What it offers, for jobs that require tags.
    pub tags: &'a [String],
    /// The denoiser it loaded, if any: only then is it given denoise tasks.
    pub denoiser: Option<&'a str>,
    /// The video encoder it has, if any: only then is it given encode tasks.
    pub encoder: Option<&'a str>,
    /// What its denoiser and its encoder took per megapixel when it started.
    pub step_ms_per_mp: [Option<u64>; 2],
}

/// Stores a new worker with its credential's hash; returns its id.
pub fn insert(tx: &Transaction, p: &Profile, credential_hash: &str, now: i64) -> Result<u64> {
    tx.exec(
        "INSERT INTO workers (name, threads, version, registered_ms, last_seen_ms,
                              credential, platform, tags, denoiser, encoder,
                              denoise_ms_per_mp, encode_ms_per_mp)
         VALUES (?1, ?2, ?3, ?4, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11)",
        params![
            p.name,
            p.threads,
            p.version,
            now,
            credential_hash,
            p.platform,
            serde_json::to_string(p.tags)?,
            p.denoiser,
            p.encoder,
            p.step_ms_per_mp[0],
            p.step_ms_per_mp[1]
        ],
    )?;
    Ok(tx.last_insert_rowid() as u64)
}

/// An earlier worker comes back: its profile and credential are replaced and it is live.
pub fn set_returned(
    tx: &Transaction,
    id: u64,
    p: &Profile,
    credential_hash: &str,
    now: i64,
) -> Result<()> {
    tx.exec(
        "UPDATE workers SET name = ?2, threads = ?3, version = ?4, last_seen_ms = ?5,
                left_ms = NULL, credential = ?6, platform = ?7, tags = ?8, denoiser = ?9,
                encoder = ?10, denoise_ms_per_mp = ?11, encode_ms_per_mp = ?12
         WHERE id = ?1",
        params![
            id,
            p.name,
            p.threads,
            p.version,
            now,
            credential_hash,
            p.platform,
            serde_json::to_string(p.tags)?,
            p.denoiser,
            p.encoder,
            p.step_ms_per_mp[0],
            p.step_ms_per_mp[1]
        ],
    )?;
    Ok(())
}

/// The newest worker named `name`, with whether it is live (seen since `live_since` and
/// not left).
pub fn newest_named(conn: &Connection, name: &str, live_since: i64) -> Result<Option<(u64, bool)>> {
    Ok(conn
        .row(
            "SELECT id, last_seen_ms >= ?2 AND left_ms IS NULL FROM workers
             WHERE name = ?1 ORDER BY id DESC LIMIT 1",
            params![name, live_since],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .optional()?)
}

/// The hash of worker `id`'s credential: `None` when there is no such worker or it
/// registered before workers had credentials.
pub fn credential_hash(conn: &Connection, id: u64) -> Result<Option<String>> {
    Ok(conn
        .row("SELECT credential FROM workers WHERE id = ?1", [id], |r| {
            r.get::<_, Option<String>>(0)
        })
        .optional()?
        .flatten())
}

/// The worker whose credential has this hash, if any.
pub fn of_credential_hash(conn: &Connection, hash: &str) -> Result<Option<u64>> {
    Ok(conn
        .row(
            "SELECT id FROM workers WHERE credential = ?1",
            [hash],
            |r| r.get(0),
        )
        .optional()?)
}

/// Records that `worker` called now; fails if it never registered or has left.
pub fn touch(tx: &Transaction, worker: u64, now: i64) -> Result<()> {
    let n = tx.exec(
        "UPDATE workers SET last_seen_ms = ?2 WHERE id = ?1 AND left_ms IS NULL",
        params![worker, now],
    )?;
    if n == 0 {
        return Err(Error::NotFound(format!(
            "worker {worker} is not registered or has left (the server's data folder may \
             have been replaced); register again"
        )));
    }
    Ok(())
}

/// Counts a tile `worker` finished.
pub fn count_done(tx: &Transaction, worker: u64) -> Result<()> {
    tx.exec(
        "UPDATE workers SET tasks_done = tasks_done + 1 WHERE id = ?1",
        [worker],
    )?;
    Ok(())
}

/// `worker` has left.
pub fn set_left(tx: &Transaction, worker: u64, now: i64) -> Result<()> {
    tx.exec(
        "UPDATE workers SET left_ms = ?2 WHERE id = ?1",
        params![worker, now],
    )?;
    Ok(())
}

/// Whether a worker other than `except`, live (seen since `live_since`, not left), not
/// quarantined and with the tags `job` requires, exists.
pub fn another_live(conn: &Connection, job: u64, except: u64, live_since: i64) -> Result<bool> {
    Ok(conn.row(
        &format!(
            "SELECT EXISTS (SELECT 1 FROM workers w WHERE w.id != ?1 AND w.last_seen_ms >= ?2
                              AND w.left_ms IS NULL AND w.quarantined_ms IS NULL AND {})",
            has_required_tags("(SELECT spec FROM jobs WHERE id = ?3)", "w.tags")
        ),
        params![except, live_since, job],
        |r| r.get(0),
    )?)
}

/// The live workers (seen since `live_since`, not left, not quarantined) with the tags
/// `job` requires and not blocked from it.
pub fn live_for_job(conn: &Connection, job: u64, live_since: i64) -> Result<Vec<u64>> {
    let mut stmt = conn.prepare_cached(&format!(
        "SELECT w.id FROM workers w
         WHERE w.last_seen_ms >= ?2 AND w.left_ms IS NULL AND w.quarantined_ms IS NULL
           AND {}
           AND NOT EXISTS (SELECT 1 FROM job_blocks b
                           WHERE b.job_id = ?1 AND b.worker_id = w.id)",
        has_required_tags("(SELECT spec FROM jobs WHERE id = ?1)", "w.tags")
    ))?;
    let rows = stmt.query_map(params![job, live_since], |r| r.get(0))?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// What a worker may have beyond rendering, for the steps after it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// A denoiser, for denoise tasks.
    Denoise,
    /// A video encoder, for encode tasks.
    Encode,
}

impl Step {
    /// Its task kind.
    fn kind(self) -> &'static str {
        match self {
            Step::Denoise => "denoise",
            Step::Encode => "encode",
        }
    }

    /// The condition on a worker `w` (with `?1` the job, `?2` `live_since`) that it is
    /// live (seen since then, not left, not quarantined), has the tags the job requires,
    /// is not blocked from it, and can do this step.
    fn can_take(self) -> String {
        let column = match self {
            Step::Denoise => "denoiser",
            Step::Encode => "encoder",
        };
        format!(
            "w.last_seen_ms >= ?2 AND w.left_ms IS NULL AND w.quarantined_ms IS NULL
             AND w.{column} IS NOT NULL AND {}
             AND NOT EXISTS (SELECT 1 FROM job_blocks b WHERE b.job_id = ?1 AND b.worker_id = w.id)",
            has_required_tags("(SELECT spec FROM jobs WHERE id = ?1)", "w.tags")
        )
    }
}

/// Whether a live worker that may work on `job` can do `step` (see `Step::can_take`).
pub fn step_live_for_job(conn: &Connection, job: u64, step: Step, live_since: i64) -> Result<bool> {
    Ok(conn.row(
        &format!(
            "SELECT EXISTS (SELECT 1 FROM workers w WHERE {})",
            step.can_take()
        ),
        params![job, live_since],
        |r| r.get(0),
    )?)
}

/// Tasks of a step over which a worker's time for it is measured, newest first.
const STEP_WINDOW: u32 = 8;

/// What `step` takes per megapixel (milliseconds) on each live worker that could do it
/// for `job`: from lease to upload over the megapixels (an encode task's are all its
/// job's frames) of its last `STEP_WINDOW` such tasks of any job, and where it has done
/// none, the figure it timed when it started; workers with neither are left out.
pub fn step_ms_per_mp(
    conn: &Connection,
    job: u64,
    step: Step,
    live_since: i64,
) -> Result<Vec<f64>> {
    let registered = match step {
        Step::Denoise => "w.denoise_ms_per_mp",
        Step::Encode => "w.encode_ms_per_mp",
    };
    let mut stmt = conn.prepare(&format!(
        "SELECT coalesce(
                  (SELECT avg(max(done_ms - leased_ms, 1) * 1e6 / (w * h * n)) FROM
                     (SELECT t.done_ms, t.leased_ms, t.w, t.h,
                             CASE t.kind WHEN 'encode'
                               THEN (SELECT count(*) FROM frames f WHERE f.job_id = t.job_id)
                               ELSE 1 END AS n
                      FROM tasks t WHERE t.worker_id = w.id AND t.kind = ?3 AND t.state = 'done'
                      ORDER BY t.done_ms DESC LIMIT ?4)),
                  {registered})
         FROM workers w WHERE {}",
        step.can_take()
    ))?;
    let rows = stmt.query_map(params![job, live_since, step.kind(), STEP_WINDOW], |r| {
        r.get::<_, Option<f64>>(0)
    })?;
    Ok(rows
        .collect::<rusqlite::Result<Vec<_>>>()?
        .into_iter()
        .flatten()
        .collect())
}

/// Who could work on `job` now: the live workers (seen since `live_since`, not left), and
/// of them those quarantined, those (not quarantined) without the tags it requires, and
/// those (neither) blocked from it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Availability {
    /// Live workers.
    pub live: u64,
    /// Of them, quarantined.
    pub quarantined: u64,
    /// Of them, not quarantined but without a tag the job requires.
    pub untagged: u64,
    /// Of them, neither but blocked from the job.
    pub blocked: u64,
}

impl Availability {
    /// Live workers that may take the job's tasks.
    pub fn usable(&self) -> u64 {
        self.live - self.quarantined - self.untagged - self.blocked
    }
}

/// [`Availability`] of the farm for `job`.
pub fn availability(conn: &Connection, job: u64, live_since: i64) -> Result<Availability> {
    let tagged = has_required_tags("(SELECT spec FROM jobs WHERE id = ?1)", "w.tags");
    Ok(conn.row(
        &format!(
            "SELECT count(*), coalesce(sum(w.quarantined_ms IS NOT NULL), 0),
                    coalesce(sum(w.quarantined_ms IS NULL AND NOT {tagged}), 0),
                    coalesce(sum(w.quarantined_ms IS NULL AND {tagged} AND EXISTS (
                        SELECT 1 FROM job_blocks b WHERE b.job_id = ?1 AND b.worker_id = w.id)),
                        0)
             FROM workers w WHERE w.last_seen_ms >= ?2 AND w.left_ms IS NULL"
        ),
        params![job, live_since],
        |r| {
            Ok(Availability {
                live: r.get(0)?,
                quarantined: r.get(1)?,
                untagged: r.get(2)?,
                blocked: r.get(3)?,
            })
        },
    )?)
}

/// A worker's name and the platform it reported.
pub fn name_and_platform(conn: &Connection, worker: u64) -> Result<(String, Option<String>)> {
    Ok(conn.row(
        "SELECT name, platform FROM workers WHERE id = ?1",
        [worker],
        |r| Ok((r.get(0)?, r.get(1)?)),
    )?)
}

/// The denoiser `worker` registered, if any.
pub fn denoiser(conn: &Connection, worker: u64) -> Result<Option<String>> {
    Ok(conn.row(
        "SELECT denoiser FROM workers WHERE id = ?1",
        [worker],
        |r| r.get(0),
    )?)
}

/// Whether `worker` is quarantined.
pub fn is_quarantined(conn: &Connection, worker: u64) -> Result<bool> {
    Ok(conn.row(
        "SELECT quarantined_ms IS NOT NULL FROM workers WHERE id = ?1",
        [worker],
        |r| r.get(0),
    )?)
}

/// Quarantines `worker` with `reason`; `false` when it already was.
pub fn quarantine(tx: &Transaction, worker: u64, reason: &str, now: i64) -> Result<bool> {
    Ok(tx.exec(
        "UPDATE workers SET quarantined_ms = ?2, quarantine_reason = ?3, suspect_ms = NULL
         WHERE id = ?1 AND quarantined_ms IS NULL",
        params![worker, now, reason],
    )? > 0)
}

/// Lifts `worker`'s quarantine and suspicion; `false` when there is no such worker.
pub fn clear(tx: &Transaction, worker: u64) -> Result<bool> {
    Ok(tx.exec(
        "UPDATE workers SET quarantined_ms = NULL, quarantine_reason = NULL, suspect_ms = NULL
         WHERE id = ?1",
        [worker],
    )? > 0)
}

/// `worker` is a suspect (since the first time it became one).
pub fn suspect(tx: &Transaction, worker: u64, now: i64) -> Result<()> {
    tx.exec(
        "UPDATE workers SET suspect_ms = coalesce(suspect_ms, ?2) WHERE id = ?1",
        params![worker, now],
    )?;
    Ok(())
}

/// `worker` is no longer a suspect.
pub fn unsuspect(tx: &Transaction, worker: u64) -> Result<()> {
    tx.exec(
        "UPDATE workers SET suspect_ms = NULL WHERE id = ?1",
        [worker],
    )?;
    Ok(())
}

/// Workers registered, and those live (seen since `live_since`, not left).
pub fn counts(conn: &Connection, live_since: i64) -> Result<(u64, u64)> {
    Ok(conn.row(
        "SELECT count(*), coalesce(sum(last_seen_ms >= ?1 AND left_ms IS NULL), 0) FROM workers",
        [live_since],
        |r| Ok((r.get(0)?, r.get(1)?)),
    )?)
}

const INFO_QUERY: &str = "SELECT w.id, w.name, w.threads, w.version, w.last_seen_ms, w.tasks_done,
        t.id, t.attempt, t.job_id, t.frame, w.left_ms, w.suspect_ms, w.quarantine_reason,
        w.platform, w.tags, w.denoiser, w.encoder
     FROM workers w
     LEFT JOIN tasks t ON t.id = (SELECT id FROM tasks WHERE worker_id = w.id AND state = 'leased'
                                  ORDER BY leased_ms DESC LIMIT 1)";

fn info_from_row(r: &rusqlite::Row, live_since: i64) -> rusqlite::Result<WorkerInfo> {
    let last_seen_ms: i64 = r.get(4)?;
    let task: Option<u64> = r.get(6)?;
    Ok(WorkerInfo {
        id: r.get(0)?,
        name: r.get(1)?,
        threads: r.get(2)?,
        version: r.get(3)?,
        last_seen_ms,
        online: last_seen_ms >= live_since && r.get::<_, Option<i64>>(10)?.is_none(),
        tasks_done: r.get(5)?,
        current_task: match task {
            Some(task_id) => Some(TaskToken {
                task_id,
                attempt: r.get(7)?,
            }),
            None => None,
        },
        current_job: r.get(8)?,
        current_frame: r.get(9)?,
        suspect: r.get::<_, Option<i64>>(11)?.is_some(),
        quarantined: r.get(12)?,
        platform: r.get(13)?,
        tags: serde_json::from_str(&r.get::<_, String>(14)?).map_err(|e| {
            rusqlite::Error::FromSqlConversionFailure(14, rusqlite::types::Type::Text, e.into())
        })?,
        denoiser: r.get(15)?,
        encoder: r.get(16)?,
        samples_per_second: None,
        recent_failures: 0,
        last_failure: None,
    })
}

/// Tasks a worker's speed is measured over: its last done ones.
const SPEED_TASKS: u32 = 20;
/// Failures within this much of the last seen time are recent: an hour, in ms.
const RECENT_FAILURES_MS: i64 = 3_600_000;

/// Fills in what a worker did lately: its speed over its last [`SPEED_TASKS`] tasks, and
/// its failed attempts within [`RECENT_FAILURES_MS`] of `now`.
fn with_recent(conn: &Connection, mut w: WorkerInfo, now: i64) -> rusqlite::Result<WorkerInfo> {
    let (samples, ms): (Option<f64>, Option<f64>) = conn.row(
        "SELECT sum(w * h * (sample_end - sample_start) * 1.0), sum(render_ms * 1.0) FROM (
             SELECT w, h, sample_start, sample_end, render_ms FROM tasks
             WHERE worker_id = ?1 AND state = 'done' AND render_ms > 0 AND kind = 'render'
             ORDER BY id DESC LIMIT ?2)",
        params![w.id, SPEED_TASKS],
        |r| Ok((r.get(0)?, r.get(1)?)),
    )?;
    w.samples_per_second = match (samples, ms) {
        (Some(s), Some(ms)) if ms > 0.0 => Some(s / ms * 1000.0),
        _ => None,
    };
    (w.recent_failures, w.last_failure) = conn.row(
        "SELECT count(*), (SELECT message FROM task_failures WHERE worker_id = ?1
                           ORDER BY at_ms DESC LIMIT 1)
         FROM task_failures WHERE worker_id = ?1 AND at_ms >= ?2",
        params![w.id, now - RECENT_FAILURES_MS],
        |r| Ok((r.get(0)?, r.get(1)?)),
    )?;
    Ok(w)
}

/// One worker as clients see it at `now`; online when seen since `live_since`.
pub fn info(conn: &Connection, id: u64, now: i64, live_since: i64) -> Result<WorkerInfo> {
    let info = conn
        .row(&format!("{INFO_QUERY} WHERE w.id = ?1"), [id], |r| {
            info_from_row(r, live_since)
        })
        .optional()?
        .ok_or_else(|| Error::NotFound(format!("worker {id} is not registered")))?;
    Ok(with_recent(conn, info, now)?)
}

/// The workers seen since `listed_since` (0: every worker), by id; those seen since
/// `live_since` are online.
pub fn list(conn: &Connection, now: i64, live_since: i64, listed_since: i64) -> Result<WorkerList> {
    let mut stmt = conn.prepare_cached(&format!(
        "{INFO_QUERY} WHERE w.last_seen_ms >= ?1 ORDER BY w.id"
    ))?;
    let rows = stmt.query_map([listed_since], |r| info_from_row(r, live_since))?;
    let workers = rows
        .map(|w| with_recent(conn, w?, now))
        .collect::<rusqlite::Result<_>>()?;
    Ok(WorkerList { workers })
}
