//! Server settings: where to listen, where data lives, tokens, timing and limits.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use crate::limits;

/// Everything `serve` needs. [`Config::new`] gives the defaults `tessera server` uses.
#[derive(Clone, Debug)]
pub struct Config {
    /// Address to listen on (loopback by default: the farm is opened up on purpose).
    pub listen: SocketAddr,
    /// Folder holding the database, scenes, tiles and job outputs.
    pub data_dir: PathBuf,
    /// Bearer token workers must present; `None` leaves worker routes open.
    pub worker_token: Option<String>,
    /// Bearer token clients (CLI, dashboard) must present; `None` leaves them open.
    pub client_token: Option<String>,
    /// Serve HTTPS with this certificate and key; plain HTTP when `None`.
    pub tls: Option<crate::tls::TlsFiles>,
    /// Serve beyond loopback with a role's routes open (a token missing): refused unless
    /// set, see [`Config::check_exposure`].
    pub insecure_no_auth: bool,
    /// How long a lease lasts without a heartbeat.
    pub lease: Duration,
    /// How often the server looks for expired leases.
    pub sweep_interval: Duration,
    /// The longest a lease request may wait for work.
    pub max_lease_wait: Duration,
    /// A worker that fails this many tasks of one job gets no more of that job.
    pub block_after_failures: u32,
    /// The fraction of tiles rendered a second time, on another worker, and compared bit
    /// for bit (0 = none, 1 = every tile); see [`crate::verify`].
    pub verify_fraction: f64,
    /// Most tasks (frames × tiles × passes) one job may have.
    pub max_tasks_per_job: u64,
    /// Largest scene upload, bytes.
    pub max_scene_bytes: usize,
    /// Largest tile upload, bytes.
    pub max_tile_bytes: usize,
    /// Memory one frame's assembly may take, bytes: a job whose frames need more is
    /// refused when it is submitted (see [`crate::assembly::assembly_bytes`]).
    pub assembly_memory: u64,
    /// Which finished jobs are kept; the others are removed with their files
    /// ([`crate::retention`]).
    pub keep_jobs: crate::retention::KeepJobs,
    /// URLs told when any job ends or a worker is quarantined ([`crate::webhooks`]).
    pub webhooks: Vec<String>,
    /// The key webhook deliveries are signed with; webhooks need one.
    pub webhook_secret: Option<String>,
}

impl Config {
    /// The scheduler's settings.
    pub fn timing(&self) -> Timing {
        Timing {
            lease_ms: self.lease_ms(),
            block_after_failures: self.block_after_failures,
            verify_fraction: self.verify_fraction,
            max_tasks_per_job: self.max_tasks_per_job,
        }
    }

    /// Defaults: 127.0.0.1:8700, no tokens, 60 s leases.
    pub fn new(data_dir: impl Into<PathBuf>) -> Self {
        Config {
            listen: SocketAddr::from(([127, 0, 0, 1], 8700)),
            data_dir: data_dir.into(),
            worker_token: None,
            client_token: None,
            tls: None,
            insecure_no_auth: false,
            lease: Duration::from_secs(60),
            sweep_interval: Duration::from_secs(2),
            max_lease_wait: Duration::from_secs(30),
            block_after_failures: 3,
            verify_fraction: 0.0,
            max_tasks_per_job: limits::DEFAULT_MAX_TASKS_PER_JOB,
            max_scene_bytes: limits::DEFAULT_MAX_SCENE_BYTES,
            max_tile_bytes: limits::MAX_TILE_BYTES,
            assembly_memory: limits::DEFAULT_ASSEMBLY_MEMORY,
            keep_jobs: crate::retention::KeepJobs::All,
            webhooks: Vec::new(),
            webhook_secret: None,
        }
    }

    /// Whether serving on `addr` is safe by default: on loopback, or with both tokens. A
    /// server reachable from the network with a role's routes open lets anyone there submit
    /// and delete jobs, read scenes and frames, or act as a worker; that takes
    /// [`Config::insecure_no_auth`].
    pub fn check_exposure(&self, addr: SocketAddr) -> Result<(), String> {
        let open: Vec<&str> = [
            ("--worker-token", &self.worker_token),
            ("--client-token", &self.client_token),
        ]
        .iter()
        .filter(|(_, token)| token.is_none())
        .map(|(flag, _)| *flag)
        .collect();
        if addr.ip().is_loopback() || open.is_empty() || self.insecure_no_auth {
            return Ok(());
        }
        Err(format!(
            "refusing to listen on {addr} without {}: anyone who can reach it could submit \
             and delete jobs, read scenes and frames, or act as a worker. Set both tokens \
             (TESSERA_WORKER_TOKEN, TESSERA_CLIENT_TOKEN), listen on loopback, or pass \
             --insecure-no-auth on a network where everyone may do that",
            open.join(" and ")
        ))
    }

    /// Lease length in milliseconds.
    pub(crate) fn lease_ms(&self) -> i64 {
        self.lease.as_millis() as i64
    }

    /// How often a worker should heartbeat: a quarter of the lease, so that three
    /// heartbeats may be lost before the lease expires.
    pub fn heartbeat_interval(&self) -> Duration {
        (self.lease / 4).max(Duration::from_secs(1))
    }
}

/// The scheduler's settings, from the [`Config`].
#[derive(Clone, Copy, Debug)]
pub struct Timing {
    /// Lease length, ms.
    pub lease_ms: i64,
    /// A worker that failed this many tasks of a job is blocked from it.
    pub block_after_failures: u32,
    /// The fraction of tasks rendered a second time to check the first (see
    /// [`crate::verify`]).
    pub verify_fraction: f64,
    /// Tasks one job may hold, the passes a time budget adds included.
    pub max_tasks_per_job: u64,
}

impl Timing {
    /// A worker counts as live at `now` if it called since this: within two lease periods.
    pub fn live_since(&self, now: i64) -> i64 {
        now - 2 * self.lease_ms
    }
}
