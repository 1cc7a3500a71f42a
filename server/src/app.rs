//! The state every handler shares, and the helpers that publish changes.

use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

use tokio::sync::Notify;

use crate::config::{Config, Timing};
use crate::db::{self, Db};
use crate::events::Hub;
use crate::metrics::Metrics;
use crate::status;
use crate::store::Store;

/// Shared server state.
pub struct App {
    /// Settings.
    pub config: Config,
    /// The database.
    pub db: Db,
    /// Files beside it.
    pub store: Store,
    /// Server-sent events.
    pub events: Hub,
    /// Prometheus metrics.
    pub metrics: Metrics,
    /// Woken whenever tasks may have become leasable, so long-polling workers look again.
    pub work: Notify,
    /// Held while a frame or a preview is written, so that a late progressive preview
    /// never replaces a finished frame's PNG.
    pub assembly: std::sync::Mutex<()>,
    /// Webhook deliveries under way.
    pub webhooks: crate::webhooks::Webhooks,
}

/// What handlers get.
pub type AppState = Arc<App>;

/// Unix time in milliseconds.
pub fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

impl App {
    /// The scheduler's settings.
    pub fn timing(&self) -> Timing {
        self.config.timing()
    }

    /// Sends the job's current status to event listeners.
    pub async fn publish_job(&self, job: u64) {
        // Reading a job's status scans its tasks: with nobody listening, every lease and
        // upload paid that for nothing (80% of the server's time at 20,000 tasks).
        if !self.events.has_listeners() {
            return;
        }
        let now = now_ms();
        let live_since = self.timing().live_since(now);
        if let Ok(status) = self
            .db
            .run(move |c| status::job_status(c, job, now, live_since))
            .await
        {
            self.events.send(proto::Event::Job {
                job: Box::new(status),
            });
        }
    }

    /// Sends a frame's current status to event listeners.
    pub async fn publish_frame(&self, job: u64, frame: i32) {
        if !self.events.has_listeners() {
            return;
        }
        if let Ok(f) = self
            .db
            .run(move |c| db::frames::status(c, job, frame))
            .await
        {
            self.events.send(proto::Event::Frame {
                job_id: job,
                frame: f,
            });
        }
    }

    /// Sends a worker's current state to event listeners.
    pub async fn publish_worker(&self, worker: u64) {
        if !self.events.has_listeners() {
            return;
        }
        let now = now_ms();
        let live_since = self.timing().live_since(now);
        if let Ok(w) = self
            .db
            .run(move |c| db::workers::info(c, worker, now, live_since))
            .await
        {
            self.events.send(proto::Event::Worker { worker: w });
        }
    }
}
