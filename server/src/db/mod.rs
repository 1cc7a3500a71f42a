//! The persistence layer: every SQL statement of the server is in this module, one file per
//! table (or concern), and nowhere else. One SQLite connection in WAL mode behind a mutex;
//! every call runs on tokio's blocking pool ([`Db::run`]) so SQLite never blocks the async
//! runtime; code that is already on a blocking thread (tile assembly) uses [`Db::with`].
//!
//! | module | what it holds |
//! |---|---|
//! | [`migrations`] | the versioned schema |
//! | [`jobs`] | specs, control states, finished or not, worker blocks, budget plans |
//! | [`frames`] | task counts per frame, assembly done or failed, the frame list |
//! | [`tasks`] | task rows and states, the lease queries, check groups |
//! | [`failures`] | every failed attempt and its reason, per task and grouped |
//! | [`logs`] | the lines workers logged per attempt at a task |
//! | [`workers`] | registration, liveness, credentials (hashed), quarantine |
//! | [`scenes`] | uploaded scenes' summaries |
//! | [`plans`] | what the time-budget planner measures and the passes it adds |
//! | [`events`] | the event log, and a job's part of it |
//! | [`outbox`] | notifications for webhooks, until delivered |
//!
//! Functions take a `&Connection` to read and a `&Transaction` to write: a change is
//! made inside the transaction of the operation that needs it, never on its own.

pub mod events;
pub mod failures;
pub mod frames;
pub mod jobs;
pub mod logs;
pub mod migrations;
pub mod outbox;
pub mod plans;
pub mod scenes;
pub mod tasks;
pub mod workers;

use std::path::Path;
use std::sync::{Arc, Mutex};

use rusqlite::{Connection, Params, Row};

use migrations::MigrationError;

/// Why the database could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// SQLite could not open or configure the file.
    #[error("opening the database {path}: {source}")]
    Sql {
        /// The file.
        path: String,
        /// What SQLite said.
        #[source]
        source: rusqlite::Error,
    },
    /// The schema could not be migrated.
    #[error(transparent)]
    Migration(#[from] MigrationError),
}

/// Statements kept prepared. The server runs the same few dozen again and again; parsing
/// them on every lease and upload took 12% of its time under `tessera bench farm`.
const STATEMENT_CACHE: usize = 128;

/// `execute` and `query_row` through the connection's statement cache.
pub trait Cached {
    /// `Connection::execute`, with the statement prepared once.
    fn exec<P: Params>(&self, sql: &str, params: P) -> rusqlite::Result<usize>;
    /// `Connection::query_row`, with the statement prepared once.
    fn row<T, P: Params, F: FnOnce(&Row<'_>) -> rusqlite::Result<T>>(
        &self,
        sql: &str,
        params: P,
        f: F,
    ) -> rusqlite::Result<T>;
}

impl Cached for Connection {
    fn exec<P: Params>(&self, sql: &str, params: P) -> rusqlite::Result<usize> {
        self.prepare_cached(sql)?.execute(params)
    }

    fn row<T, P: Params, F: FnOnce(&Row<'_>) -> rusqlite::Result<T>>(
        &self,
        sql: &str,
        params: P,
        f: F,
    ) -> rusqlite::Result<T> {
        self.prepare_cached(sql)?.query_row(params, f)
    }
}

/// SQL: the worker whose tags are the JSON array `worker_tags` has every tag the job whose
/// spec is `job_spec` requires (`require_tags`; none required: any worker).
pub(crate) fn has_required_tags(job_spec: &str, worker_tags: &str) -> String {
    format!(
        "NOT EXISTS (SELECT 1 FROM json_each({job_spec}, '$.require_tags') r
                     WHERE r.value NOT IN (SELECT value FROM json_each({worker_tags})))"
    )
}

/// Whether the database answers (for the health check).
pub fn ping(conn: &Connection) -> rusqlite::Result<()> {
    conn.row("SELECT 1", [], |r| r.get::<_, i64>(0)).map(|_| ())
}

/// A handle on the database; clones share the connection.
#[derive(Clone)]
pub struct Db {
    conn: Arc<Mutex<Connection>>,
}

impl Db {
    /// Opens (creating) the database at `path`, in WAL mode with foreign keys on, and
    /// migrates it to the current schema.
    pub fn open(path: &Path) -> Result<Db, OpenError> {
        let sql = |source| OpenError::Sql {
            path: path.display().to_string(),
            source,
        };
        let mut conn = Connection::open(path).map_err(sql)?;
        // WAL: readers do not block the writer; synchronous=FULL: a committed transaction
        // survives a power cut, which the restart guarantees rely on.
        conn.pragma_update(None, "journal_mode", "WAL")
            .map_err(sql)?;
        conn.pragma_update(None, "synchronous", "FULL")
            .map_err(sql)?;
        conn.pragma_update(None, "foreign_keys", "ON")
            .map_err(sql)?;
        conn.busy_timeout(std::time::Duration::from_secs(5))
            .map_err(sql)?;
        conn.set_prepared_statement_cache_capacity(STATEMENT_CACHE);
        migrations::migrate(&mut conn)?;
        Ok(Db {
            conn: Arc::new(Mutex::new(conn)),
        })
    }

    /// An empty in-memory database at the current schema (for building the router
    /// without a data folder, as [`crate::openapi`] does).
    pub fn in_memory() -> Db {
        let mut conn = Connection::open_in_memory().expect("SQLite opens an in-memory database");
        migrations::migrate(&mut conn).expect("the schema applies to an empty database");
        Db {
            conn: Arc::new(Mutex::new(conn)),
        }
    }

    /// Runs `f` with the connection on the current thread (which must be allowed to
    /// block).
    pub fn with<R>(&self, f: impl FnOnce(&mut Connection) -> R) -> R {
        // A panic inside `f` poisons the mutex; the connection itself is still usable
        // (SQLite rolls back an unfinished transaction when it is dropped).
        let mut conn = self.conn.lock().unwrap_or_else(|p| p.into_inner());
        f(&mut conn)
    }

    /// Runs `f` with the connection on the blocking pool.
    pub async fn run<R: Send + 'static>(
        &self,
        f: impl FnOnce(&mut Connection) -> R + Send + 'static,
    ) -> R {
        let db = self.clone();
        // What `f` logs belongs to the caller's request or task.
        let span = tracing::Span::current();
        match tokio::task::spawn_blocking(move || span.in_scope(|| db.with(f))).await {
            Ok(r) => r,
            Err(e) => std::panic::resume_unwind(e.into_panic()),
        }
    }
}
