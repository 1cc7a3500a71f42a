//! Versioned schema migrations. The database's `user_version` is the number of migrations
//! applied; each migration runs in its own transaction. Append, never edit: a database in
//! the field has already run the old ones.

use rusqlite::Connection;

/// Migration `i` takes the schema from version `i` to `i + 1`.
const MIGRATIONS: &[&str] = &[
    // 1: scenes, jobs, frames, tasks, workers, failures, blocks, event log.
    r#"
    CREATE TABLE scenes (
        digest      TEXT PRIMARY KEY,
        size        INTEGER NOT NULL,
        info        TEXT NOT NULL,             -- proto::SceneInfo as JSON
        created_ms  INTEGER NOT NULL
    );
    CREATE TABLE jobs (
        id              INTEGER PRIMARY KEY AUTOINCREMENT,
        name            TEXT NOT NULL,
        scene           TEXT NOT NULL REFERENCES scenes(digest),
        spec            TEXT NOT NULL,         -- resolved proto::JobSpec as JSON
        control         TEXT NOT NULL CHECK (control IN ('active', 'paused', 'cancelled')),
        priority        INTEGER NOT NULL,
        max_attempts    INTEGER NOT NULL,
        created_ms      INTEGER NOT NULL,
        first_lease_ms  INTEGER,
        finished_ms     INTEGER,               -- set while nothing is left to run
        pixel_samples   INTEGER NOT NULL       -- width * height * spp * frames
    );
    CREATE TABLE frames (
        job_id        INTEGER NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
        frame         INTEGER NOT NULL,
        tasks_total   INTEGER NOT NULL,
        tasks_done    INTEGER NOT NULL DEFAULT 0,
        assembled_ms  INTEGER,
        PRIMARY KEY (job_id, frame)
    );
    CREATE TABLE tasks (
        id            INTEGER PRIMARY KEY AUTOINCREMENT,
        job_id        INTEGER NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
        frame         INTEGER NOT NULL,
        tile          INTEGER NOT NULL,
        pass          INTEGER NOT NULL,
        x INTEGER NOT NULL, y INTEGER NOT NULL, w INTEGER NOT NULL, h INTEGER NOT NULL,
        sample_start  INTEGER NOT NULL,
        sample_end    INTEGER NOT NULL,
        state         TEXT NOT NULL
                      CHECK (state IN ('queued', 'leased', 'done', 'failed', 'cancelled')),
        attempt       INTEGER NOT NULL DEFAULT 0,   -- leases granted: the fencing token
        failures      INTEGER NOT NULL DEFAULT 0,   -- failed or expired attempts
        worker_id     INTEGER,
        leased_ms     INTEGER,
        deadline_ms   INTEGER,
        done_ms       INTEGER,
        rays          INTEGER,
        render_ms     INTEGER
    );
    CREATE INDEX tasks_queue ON tasks (state, job_id, frame, pass, tile);
    CREATE INDEX tasks_by_job ON tasks (job_id, frame, state);
    CREATE INDEX tasks_by_worker ON tasks (worker_id, state);
    CREATE TABLE workers (
        id             INTEGER PRIMARY KEY AUTOINCREMENT,
        name           TEXT NOT NULL,
        threads        INTEGER NOT NULL,
        version        TEXT NOT NULL,
        registered_ms  INTEGER NOT NULL,
        last_seen_ms   INTEGER NOT NULL,
        tasks_done     INTEGER NOT NULL DEFAULT 0
    );
    CREATE TABLE task_failures (
        task_id    INTEGER NOT NULL REFERENCES tasks(id) ON DELETE CASCADE,
        job_id     INTEGER NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
        worker_id  INTEGER NOT NULL,
        attempt    INTEGER NOT NULL,
        reason     TEXT NOT NULL CHECK (reason IN ('reported', 'expired')),
        message    TEXT NOT NULL,
        at_ms      INTEGER NOT NULL
    );
    CREATE INDEX task_failures_by_worker ON task_failures (job_id, worker_id);
    CREATE INDEX task_failures_by_task ON task_failures (task_id, worker_id);
    CREATE TABLE job_blocks (
        job_id     INTEGER NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
        worker_id  INTEGER NOT NULL,
        PRIMARY KEY (job_id, worker_id)
    );
    CREATE TABLE events (
        id      INTEGER PRIMARY KEY AUTOINCREMENT,
        at_ms   INTEGER NOT NULL,
        job_id  INTEGER,
        kind    TEXT NOT NULL,
        detail  TEXT NOT NULL
    );
    "#,
    // 2: a worker that shuts down says so; its leases go back to the queue at once.
    "ALTER TABLE workers ADD COLUMN left_ms INTEGER;",
    // 3: verification. A check task re-renders a done task on another worker; a worker
    // whose tile the checks prove wrong is quarantined until an operator clears it.
    r#"
    ALTER TABLE tasks ADD COLUMN check_of INTEGER;     -- the render task a check repeats
    CREATE INDEX tasks_by_check ON tasks (check_of);
    ALTER TABLE workers ADD COLUMN suspect_ms INTEGER;       -- a check disagreed with it
    ALTER TABLE workers ADD COLUMN quarantined_ms INTEGER;   -- proven wrong: no more work
    ALTER TABLE workers ADD COLUMN quarantine_reason TEXT;
    "#,
    // 4: what an assembled frame reached (adaptive sampling stops pixels early).
    r#"
    ALTER TABLE frames ADD COLUMN spp_mean REAL;
    ALTER TABLE frames ADD COLUMN noise REAL;   -- mean estimated error; NULL: no estimate
    "#,
    // 5: time budgets. A frame can be refined after it was assembled, so "assembled" is
    // "assembled from all of its tasks so far"; a budget job keeps its latest plan.
    r#"
    ALTER TABLE frames ADD COLUMN assembled_tasks INTEGER;  -- tasks_total at the last assembly
    UPDATE frames SET assembled_tasks = tasks_total WHERE assembled_ms IS NOT NULL;
    ALTER TABLE jobs ADD COLUMN budget_plan TEXT;           -- proto::BudgetPlan as JSON
    "#,
    // 6: a frame whose assembly failed (a tile unreadable, too large for this server) says
    // why, and is not assembled again until the job is retried.
    "ALTER TABLE frames ADD COLUMN failure TEXT;",
    // 7: worker identity. Each registration gets its own credential (its SHA-256 is kept);
    // a worker that comes back with it, or under the name of a worker that is gone, is
    // that worker again (quarantine, job blocks and history stay with it).
    r#"
    ALTER TABLE workers ADD COLUMN credential TEXT;
    CREATE UNIQUE INDEX workers_by_credential ON workers (credential);
    CREATE INDEX workers_by_name ON workers (name);
    "#,
    // 8: the machine and build a worker registered with, for the events of checks that
    // disagree.
    "ALTER TABLE workers ADD COLUMN platform TEXT;",
    // 9: worker tags (a job's required tags are in its spec).
    "ALTER TABLE workers ADD COLUMN tags TEXT NOT NULL DEFAULT '[]';  -- JSON array",
    // 10: the lines a worker logged per attempt at a task. `seq` numbers them from 0; a
    // row at seq = proto::log::MAX_TASK_LOG_LINES says later lines were dropped.
    r#"
    CREATE TABLE task_logs (
        task_id    INTEGER NOT NULL REFERENCES tasks(id) ON DELETE CASCADE,
        attempt    INTEGER NOT NULL,
        seq        INTEGER NOT NULL,
        worker_id  INTEGER NOT NULL,
        at_ms      INTEGER NOT NULL,
        level      TEXT NOT NULL,
        text       TEXT NOT NULL,
        PRIMARY KEY (task_id, attempt, seq)
    ) WITHOUT ROWID;
    CREATE INDEX events_by_job ON events (job_id, id);
    "#,
    // 11: preview-first order: tasks of round 0 are leased before those of round 1.
    "ALTER TABLE tasks ADD COLUMN round INTEGER NOT NULL DEFAULT 0;",
    // 12: notifications to deliver to webhooks, written in the transaction that made them
    // happen and removed once delivered (or given up on).
    r#"
    CREATE TABLE outbox (
        id         INTEGER PRIMARY KEY AUTOINCREMENT,
        kind       TEXT NOT NULL,     -- job_finished | worker_quarantined
        job_id     INTEGER,
        worker_id  INTEGER,
        at_ms      INTEGER NOT NULL
    );
    "#,
    // 13: a worker's recent failures, for the worker list.
    "CREATE INDEX task_failures_by_worker_time ON task_failures (worker_id, at_ms);",
    // 14: the lease order has the preview round first: the queue's index follows it, so a
    // lease walks the index instead of sorting the job's queue (measured: EXPLAIN QUERY
    // PLAN said "USE TEMP B-TREE FOR ORDER BY" without it).
    r#"
    DROP INDEX tasks_queue;
    CREATE INDEX tasks_queue ON tasks (state, job_id, round, frame, pass, tile);
    "#,
    // 15: denoising and video. A frame of a job that denoises gets a denoise task once
    // assembled, a job that wants a video an encode task once every frame is finished
    // (neither counted in a frame's tasks_total: those are its render tasks); only a
    // worker that registered a denoiser, or an encoder, leases one.
    r#"
    ALTER TABLE tasks ADD COLUMN kind TEXT NOT NULL DEFAULT 'render'
        CHECK (kind IN ('render', 'denoise', 'encode'));
    ALTER TABLE frames ADD COLUMN denoised_ms INTEGER;
    ALTER TABLE workers ADD COLUMN denoiser TEXT;
    ALTER TABLE workers ADD COLUMN encoder TEXT;
    "#,
    // 16: what a worker's denoise and encode steps took per megapixel when it started,
    // for the time-budget planner.
    r#"
    ALTER TABLE workers ADD COLUMN denoise_ms_per_mp INTEGER;
    ALTER TABLE workers ADD COLUMN encode_ms_per_mp INTEGER;
    "#,
];

/// The schema version this build writes.
pub const SCHEMA_VERSION: u32 = MIGRATIONS.len() as u32;

/// Why the database cannot be brought to [`SCHEMA_VERSION`].
#[derive(Debug, thiserror::Error)]
pub enum MigrationError {
    /// The database was written by a newer Tessera.
    #[error(
        "the database has schema version {found}, newer than this server's {SCHEMA_VERSION}; \
         run a newer tessera or point --data at another folder"
    )]
    TooNew {
        /// The version found.
        found: u32,
    },
    /// SQLite refused a migration.
    #[error("migrating the database to version {to}: {source}")]
    Sql {
        /// The version being reached.
        to: u32,
        /// What SQLite said.
        #[source]
        source: rusqlite::Error,
    },
}

/// Applies every migration the database has not run yet.
pub fn migrate(conn: &mut Connection) -> Result<u32, MigrationError> {
    let sql_err = |to| move |source| MigrationError::Sql { to, source };
    let found: u32 = conn
        .pragma_query_value(None, "user_version", |r| r.get(0))
        .map_err(sql_err(0))?;
    if found > SCHEMA_VERSION {
        return Err(MigrationError::TooNew { found });
    }
    for (i, sql) in MIGRATIONS.iter().enumerate().skip(found as usize) {
        let to = i as u32 + 1;
        let tx = conn.transaction().map_err(sql_err(to))?;
        tx.execute_batch(sql).map_err(sql_err(to))?;
        tx.pragma_update(None, "user_version", to)
            .map_err(sql_err(to))?;
        tx.commit().map_err(sql_err(to))?;
    }
    Ok(SCHEMA_VERSION)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresh_database_reaches_current_version_and_stays_there() {
        let mut conn = Connection::open_in_memory().unwrap();
        assert_eq!(migrate(&mut conn).unwrap(), SCHEMA_VERSION);
        // Running again applies nothing (the tables exist; a rerun would fail).
        assert_eq!(migrate(&mut conn).unwrap(), SCHEMA_VERSION);
        let tables: i64 = conn
            .query_row(
                "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name IN \
                 ('scenes','jobs','frames','tasks','workers','task_failures','job_blocks','events')",
                [],
                |r| r.get(0),
            )
            .unwrap();
        assert_eq!(tables, 8);
    }

    #[test]
    fn newer_database_is_refused() {
        let mut conn = Connection::open_in_memory().unwrap();
        conn.pragma_update(None, "user_version", SCHEMA_VERSION + 1)
            .unwrap();
        let err = migrate(&mut conn).unwrap_err();
        assert!(matches!(err, MigrationError::TooNew { found } if found == SCHEMA_VERSION + 1));
        assert!(err.to_string().contains("newer"));
    }
}
