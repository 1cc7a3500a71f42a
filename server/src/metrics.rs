//! Prometheus metrics at `/metrics`. Counters (tiles and bytes received, lease latency)
//! are recorded as they happen; gauges (jobs, tasks and workers by state) are read from
//! the database at scrape time, so they are right after a restart too.
//!
//! Each server owns its recorder (used through `metrics::with_local_recorder`) instead of
//! installing a global one, so that several servers in one test process keep separate
//! numbers.

use metrics_exporter_prometheus::{PrometheusBuilder, PrometheusHandle, PrometheusRecorder};
use rusqlite::Connection;

use crate::db;
use crate::error::Result;

/// The server's recorder.
pub struct Metrics {
    recorder: PrometheusRecorder,
    handle: PrometheusHandle,
}

impl Default for Metrics {
    fn default() -> Self {
        let recorder = PrometheusBuilder::new().build_recorder();
        let handle = recorder.handle();
        let metrics = Metrics { recorder, handle };
        metrics.record(describe);
        metrics
    }
}

/// Every series' `# HELP` text and unit.
fn describe() {
    use metrics::{describe_counter, describe_gauge, describe_histogram, Unit};
    describe_counter!(
        "tessera_tiles_received_total",
        Unit::Count,
        "Tiles accepted (first upload of a task; duplicates are not counted)."
    );
    describe_counter!(
        "tessera_tile_bytes_received_total",
        Unit::Bytes,
        "Bytes of the accepted tiles' EXR files."
    );
    describe_counter!(
        "tessera_tiles_refused_total",
        Unit::Count,
        "Tile uploads refused: bad checksum, size, channels or values."
    );
    describe_counter!(
        "tessera_scene_bytes_received_total",
        Unit::Bytes,
        "Bytes of the scenes stored."
    );
    describe_counter!(
        "tessera_leases_total",
        Unit::Count,
        "Lease requests answered with a task."
    );
    describe_histogram!(
        "tessera_lease_latency_seconds",
        Unit::Seconds,
        "Time from a lease request to the task it got, waiting for work included."
    );
    describe_histogram!(
        "tessera_upload_seconds",
        Unit::Seconds,
        "Time to take a tile upload answered 200: reading, checking, storing and \
         committing it, and assembling the frame when it was the last tile."
    );
    describe_counter!(
        "tessera_frames_assembled_total",
        Unit::Count,
        "Frames assembled."
    );
    describe_counter!(
        "tessera_frame_assembly_tile_bytes_total",
        Unit::Bytes,
        "Bytes of the tile files read to assemble frames."
    );
    describe_histogram!(
        "tessera_frame_assembly_seconds",
        Unit::Seconds,
        "Time to assemble a frame: tiles read and merged, EXR and PNG written."
    );
    describe_counter!(
        "tessera_leases_expired_total",
        Unit::Count,
        "Leases that ran out without a heartbeat; their tasks were queued again."
    );
    describe_gauge!("tessera_jobs", Unit::Count, "Jobs by state.");
    describe_gauge!(
        "tessera_data_folder_bytes",
        Unit::Bytes,
        "Bytes of the files in the data folder (database, scenes, tiles, frames), measured \
         every 10 minutes."
    );
    describe_gauge!("tessera_tasks", Unit::Count, "Tasks by state.");
    describe_gauge!(
        "tessera_workers",
        Unit::Count,
        "Workers online (seen within two lease periods, not gone) and offline."
    );
    describe_gauge!(
        "tessera_event_listeners",
        Unit::Count,
        "Open server-sent event streams."
    );
    describe_gauge!(
        DEMAND,
        Unit::Count,
        "Tasks that want a worker now, for autoscalers: queued and leased tasks of jobs \
         that are not paused, plus the passes time-budget jobs could run now."
    );
}

/// The gauge autoscalers size the worker pool by (KEDA's query, `tessera scale`).
pub const DEMAND: &str = "tessera_demand_tasks";

/// Gauges read from the database.
#[derive(Debug, Default)]
pub struct Snapshot {
    jobs: Vec<(String, u64)>,
    tasks: Vec<(String, u64)>,
    workers_online: u64,
    workers_total: u64,
    /// Tasks that want a worker now (see [`snapshot`]).
    pub demand: u64,
    /// Open server-sent event streams.
    pub listeners: usize,
}

impl Metrics {
    fn record(&self, f: impl FnOnce()) {
        metrics::with_local_recorder(&self.recorder, f);
    }

    /// A tile of `bytes` was accepted.
    pub fn tile_accepted(&self, bytes: usize) {
        self.record(|| {
            metrics::counter!("tessera_tiles_received_total").increment(1);
            metrics::counter!("tessera_tile_bytes_received_total").increment(bytes as u64);
        });
    }

    /// A tile upload was answered after `seconds`.
    pub fn upload_taken(&self, seconds: f64) {
        self.record(|| metrics::histogram!("tessera_upload_seconds").record(seconds));
    }

    /// A tile was refused (bad checksum, size, channels, values).
    pub fn tile_refused(&self) {
        self.record(|| metrics::counter!("tessera_tiles_refused_total").increment(1));
    }

    /// A scene of `bytes` was stored.
    pub fn scene_stored(&self, bytes: usize) {
        self.record(|| {
            metrics::counter!("tessera_scene_bytes_received_total").increment(bytes as u64)
        });
    }

    /// A lease request was answered with a task after `seconds`.
    pub fn lease_granted(&self, seconds: f64) {
        self.record(|| {
            metrics::counter!("tessera_leases_total").increment(1);
            metrics::histogram!("tessera_lease_latency_seconds").record(seconds);
        });
    }

    /// A frame was assembled in `seconds` from tiles of `tile_bytes` in all (read, merged,
    /// written as EXR and PNG, marked in the database).
    pub fn frame_assembled(&self, seconds: f64, tile_bytes: u64) {
        self.record(|| {
            metrics::counter!("tessera_frames_assembled_total").increment(1);
            metrics::counter!("tessera_frame_assembly_tile_bytes_total").increment(tile_bytes);
            metrics::histogram!("tessera_frame_assembly_seconds").record(seconds);
        });
    }

    /// The data folder holds `bytes`.
    pub fn set_data_bytes(&self, bytes: u64) {
        self.record(|| metrics::gauge!("tessera_data_folder_bytes").set(bytes as f64));
    }

    /// Leases that expired.
    pub fn leases_expired(&self, n: u64) {
        self.record(|| metrics::counter!("tessera_leases_expired_total").increment(n));
    }

    /// The Prometheus text, with the gauges of `snapshot`.
    pub fn render(&self, snapshot: &Snapshot) -> String {
        self.record(|| {
            for (state, n) in &snapshot.jobs {
                metrics::gauge!("tessera_jobs", "state" => state.clone()).set(*n as f64);
            }
            for (state, n) in &snapshot.tasks {
                metrics::gauge!("tessera_tasks", "state" => state.clone()).set(*n as f64);
            }
            metrics::gauge!("tessera_workers", "state" => "online")
                .set(snapshot.workers_online as f64);
            metrics::gauge!("tessera_workers", "state" => "offline")
                .set((snapshot.workers_total - snapshot.workers_online) as f64);
            metrics::gauge!("tessera_event_listeners").set(snapshot.listeners as f64);
            metrics::gauge!(DEMAND).set(snapshot.demand as f64);
        });
        self.handle.render()
    }
}

/// Reads the gauges: jobs by state, tasks by state, workers online (seen since
/// `live_since`) and offline, and the demand an autoscaler sizes the pool by: the queued and
/// leased tasks of jobs that are not paused, plus the passes time-budget jobs could run
/// now ([`db::plans::waiting_passes`]).
pub fn snapshot(conn: &Connection, now: i64, live_since: i64) -> Result<Snapshot> {
    let mut jobs: Vec<(String, u64)> =
        ["queued", "running", "paused", "cancelled", "failed", "done"]
            .iter()
            .map(|s| (s.to_string(), 0))
            .collect();
    for job in crate::status::list_jobs(conn, now, live_since)? {
        let name = serde_json::to_value(job.state)?
            .as_str()
            .unwrap_or("")
            .to_string();
        if let Some(slot) = jobs.iter_mut().find(|(s, _)| *s == name) {
            slot.1 += 1;
        }
    }
    let tasks = db::tasks::count_by_state(conn)?
        .into_iter()
        .map(|(s, n)| (s.as_str().to_string(), n))
        .collect();
    let (workers_total, workers_online) = db::workers::counts(conn, live_since)?;
    let open = db::tasks::open_of_active_jobs(conn)?;
    Ok(Snapshot {
        jobs,
        tasks,
        workers_online,
        workers_total,
        demand: open + db::plans::waiting_passes(conn, now)?,
        listeners: 0,
    })
}
