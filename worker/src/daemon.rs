//! The worker's loop: register, long-poll for a lease, fetch the scene (memory, then disk
//! cache, then the server), prepare the frame, render the tile on the rayon pool while a
//! heartbeat task keeps the lease, upload, repeat.
//!
//! The upload runs on a task of its own: a rendered tile is encoded and sent while the
//! next lease is taken and rendered, so the render threads do not wait for the encoding,
//! the network or the server's frame assembly. One upload is in flight at most: the next
//! tile's starts once the previous one's has ended.
//!
//! What ends a task early, and what follows:
//!
//! | event | render | then |
//! |---|---|---|
//! | heartbeat answered 409 (lease gone) | cancelled, tile dropped | lease again |
//! | scene or frame cannot be prepared | — | failure reported, lease again |
//! | upload answered 409 | — | tile dropped, lease again |
//! | upload answered 422/413 | — | failure reported, lease again |
//! | a 404 saying the worker is unknown | cancelled | register again |
//! | 401 | cancelled | [`run`] returns the error |
//! | shutdown | cancelled | `POST /workers/{id}/leave`, [`run`] returns `Ok` |
//!
//! Shutdown drops a long poll, a scene download or a backoff wait at once; only an upload
//! (or failure report) already under way gets a few seconds to finish, since its tile is
//! rendered. `leave` then re-queues whatever the worker still holds, including a lease
//! granted to a long poll that was dropped.
//!
//! Network errors and 5xx answers are retried with backoff (see [`crate::backoff`]) until
//! the server answers or shutdown begins; a heartbeat that fails is simply tried again at
//! the next beat while the render goes on.

use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use proto::{Lease, TaskKind, TaskLogLines, TaskToken, WorkerRegistered, WorkerRegistration};
use tokio::task::JoinHandle;
use tracer::film::TileBuffer;
use tracer::output::ExrCompression;
use tracer::render::PreparedFrame;
use tracer::scene::Scene;
use tracing::Instrument;

use crate::api::{Api, ApiError, HeartbeatAnswer, InFlight, LeaseAnswer};
use crate::backoff::{jitter, seconds, Backoff, IDLE_PAUSE};
use crate::cache::SceneCache;
use crate::config::{Fault, WorkerConfig};
use crate::finishing::{Denoiser, Encoder};
use crate::identity;
use crate::render::render_lease;
use crate::stop::Stop;
use crate::task_log::{self, TaskLog};

mod courier;
mod pilot;
mod scenes;
mod steps;

use self::courier::Courier;
pub use self::pilot::Ending;
use self::pilot::Pilot;
use self::steps::{find_encoder, load_denoiser, time_steps, ENCODER_NAME};

/// How long the goodbye (`leave`) may take in all before the worker exits anyway; its
/// leases then expire on the server after one lease period.
const LEAVE_TIMEOUT: Duration = Duration::from_secs(10);

/// What a worker did before it stopped.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RunSummary {
    /// Tiles uploaded and stored (including repeats the server ignored).
    pub tasks_done: u64,
    /// Tasks reported as failed (scene or frame unusable, tile refused).
    pub tasks_failed: u64,
    /// Tasks given up because the server took them back: lease gone (409: paused,
    /// cancelled, expired) or the worker forgotten (404).
    pub tasks_abandoned: u64,
    /// Tasks given back because shutdown began while they were rendered or uploaded.
    pub tasks_interrupted: u64,
    /// Scenes downloaded from the server (not found valid in the disk cache).
    pub scenes_downloaded: u64,
    /// Times the worker registered (more than 1 when the server forgot it).
    pub registrations: u64,
    /// Why it stopped.
    pub ended: Ending,
}

/// Runs a worker until `shutdown` completes: then a render in progress is cancelled, the
/// server is told (`leave`, so the lease is queued again at once) and the summary is
/// returned. Fails only when the server refuses the token (401), refuses the registration,
/// or the config is unusable.
pub async fn run(
    config: WorkerConfig,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<RunSummary> {
    run_draining(config, shutdown, std::future::pending()).await
}

/// [`run`], and when `drain` completes, the worker finishes the task in hand (render and
/// upload), takes no other and leaves: what a cluster's scheduler asks before it stops a
/// worker's job (Slurm's SIGUSR1 before a time limit).
pub async fn run_draining(
    config: WorkerConfig,
    shutdown: impl Future<Output = ()> + Send + 'static,
    drain: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<RunSummary> {
    anyhow::ensure!(config.threads >= 1, "threads must be at least 1");
    anyhow::ensure!(
        config.server.starts_with("http://") || config.server.starts_with("https://"),
        "server `{}` must be an http:// or https:// URL",
        config.server
    );
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(config.threads)
        .thread_name(|i| format!("tessera-render-{i}"))
        .build()
        .context("starting the render threads")?;
    let api = Api::new(
        &config.server,
        &config.api_base(),
        config.token.as_deref(),
        config.ca.as_deref(),
    )?;
    let (set_stop, stop) = Stop::new();
    let watcher = tokio::spawn(async move {
        shutdown.await;
        let _ = set_stop.send(true);
    });
    let (set_drain, draining) = Stop::new();
    let drain_watcher = tokio::spawn(async move {
        drain.await;
        tracing::info!("asked to drain: finishing the task in hand, then leaving");
        let _ = set_drain.send(true);
    });
    let compression = config.upload_compression.for_server(&config.server);
    tracing::info!(
        "tiles are uploaded {} ({:?})",
        match compression {
            ExrCompression::Zip => "ZIP-compressed",
            ExrCompression::Uncompressed => "uncompressed",
        },
        config.upload_compression
    );
    let denoiser = config.denoise.then(|| load_denoiser(&config)).flatten();
    let encoder = config.encode.then(|| find_encoder(&config)).flatten();
    let step_ms_per_mp = time_steps(denoiser.clone(), encoder.clone()).await;
    let mut daemon = Daemon {
        api,
        fault: config.fault,
        registration: WorkerRegistration {
            name: config.name.clone(),
            threads: config.threads.min(u32::MAX as usize) as u32,
            version: env!("CARGO_PKG_VERSION").to_string(),
            credential: identity::load(&config.cache_dir, &config.server, &config.name)
                .map(|i| i.credential),
            platform: Some(crate::config::platform()),
            tags: config.tags.clone(),
            denoiser: denoiser.as_ref().map(|_| post::DENOISER_NAME.to_string()),
            encoder: encoder.as_ref().map(|_| ENCODER_NAME.to_string()),
            denoise_ms_per_megapixel: step_ms_per_mp[0],
            encode_ms_per_megapixel: step_ms_per_mp[1],
        },
        denoiser,
        encoder,
        identity_dir: config.cache_dir.clone(),
        registered: None,
        stop,
        pool: Arc::new(pool),
        cache: SceneCache::new(&config.cache_dir, config.cache_limit_bytes),
        scene: None,
        frame: None,
        warned: Vec::new(),
        compression,
        delivery: None,
        late_log: None,
        summary: RunSummary::default(),
        pilot: Pilot::new(config.pilot),
        draining,
    };
    let result = daemon.main_loop().await;
    watcher.abort();
    drain_watcher.abort();
    result.map(|()| daemon.summary)
}

struct Daemon {
    api: Api,
    /// Open Image Denoise, when this worker takes denoise tasks.
    denoiser: Option<Denoiser>,
    /// FFmpeg, when this worker takes encode tasks.
    encoder: Option<Encoder>,
    /// Where the identity file is kept ([`identity`]).
    identity_dir: std::path::PathBuf,
    fault: Option<Fault>,
    registration: WorkerRegistration,
    registered: Option<WorkerRegistered>,
    stop: Stop,
    pool: Arc<rayon::ThreadPool>,
    cache: SceneCache,
    /// The last scene loaded, by digest.
    scene: Option<(String, Arc<Scene>)>,
    /// The last frame prepared, by [`frame_key`].
    frame: Option<(Lease, Arc<PreparedFrame>)>,
    /// The frame warnings already logged for the current scene.
    warned: Vec<String>,
    /// How tiles are compressed for upload.
    compression: ExrCompression,
    /// The last tile's upload, running while the next tile renders.
    delivery: Option<JoinHandle<Delivered>>,
    /// The lines logged for the last lease after its last heartbeat: sent with the next
    /// lease request.
    late_log: Option<TaskLogLines>,
    summary: RunSummary,
    /// Its progress towards leaving by itself.
    pilot: Pilot,
    /// Set once a drain is asked for.
    draining: Stop,
}

/// What became of a rendered tile handed to [`Courier::deliver`]: the summary's count it
/// adds to, and an error the main loop acts on.
struct Delivered {
    fate: Fate,
    result: Result<(), ApiError>,
}

/// Which [`RunSummary`] count a task adds to.
#[derive(Clone, Copy, Debug)]
enum Fate {
    Done,
    Failed,
    Abandoned,
    Interrupted,
}

/// What a lease produced, to upload.
enum Product {
    /// A rendered tile.
    Tile(Box<TileBuffer>),
    /// A frame's denoised RGB.
    Denoised(Vec<glam::Vec3>),
    /// The job's MP4.
    Video(Vec<u8>),
}

/// Why a task could not be rendered.
enum TaskError {
    /// The scene or the frame is unusable: report it to the server.
    Failed(String),
    /// A call to the server failed in a way retrying does not fix.
    Api(ApiError),
    /// Shutdown began.
    Stopped,
}

/// Aborts a task when dropped.
struct AbortOnDrop(tokio::task::AbortHandle);

impl Drop for AbortOnDrop {
    fn drop(&mut self) {
        self.0.abort();
    }
}

/// Why the heartbeat task ended (it runs until aborted otherwise).
enum HeartbeatEnd {
    LeaseGone(String),
    Error(ApiError),
}

impl Daemon {
    async fn main_loop(&mut self) -> anyhow::Result<()> {
        let mut trouble = Backoff::new();
        while !self.stop.is_set() {
            let Some(reg) = self.registered.clone() else {
                match self.register().await? {
                    Some(reg) => self.registered = Some(reg),
                    None => break,
                }
                continue;
            };
            if let Some(ending) = self.pilot.ending(self.draining.is_set()) {
                tracing::info!("leaving the farm: {}", ending.describe(self.pilot.limits()));
                self.summary.ended = ending;
                break;
            }
            // A finished upload is counted first: its error may be one to act on.
            let result = if self.delivery.as_ref().is_some_and(JoinHandle::is_finished) {
                self.settle().await
            } else {
                match self.lease_and_work(&reg).await {
                    Some(result) => result,
                    None => break,
                }
            };
            match result {
                Ok(()) => trouble.reset(),
                Err(ApiError::UnknownWorker { message }) => {
                    tracing::warn!("server {}: {message}", self.api.server());
                    self.registered = None;
                    // An upload under the forgotten registration fails the same way.
                    self.settle_and_log().await;
                }
                Err(ApiError::Unauthorized { .. }) => {
                    // The credential is nobody's now: another process took this worker's
                    // name over while it was silent. Register again (a wrong join token
                    // then stops the worker).
                    tracing::warn!(
                        "server {} no longer knows this worker's credential; registering \
                         again",
                        self.api.server()
                    );
                    self.registered = None;
                    self.registration.credential = None;
                    self.settle_and_log().await;
                }
                Err(e) => {
                    // An answer the protocol does not expect: a bug on one side. Keep
                    // going, slowly, rather than exit a daemon over it.
                    let delay = trouble.next_delay();
                    tracing::error!("{e}; trying again in {}", seconds(delay));
                    self.pause(delay).await;
                }
            }
        }
        self.settle_and_log().await;
        self.leave().await;
        Ok(())
    }

    /// Long-polls for a lease and works on it; `None` when shutdown began meanwhile.
    async fn lease_and_work(&mut self, reg: &WorkerRegistered) -> Option<Result<(), ApiError>> {
        let wait = self
            .pilot
            .poll_wait(Duration::from_secs(reg.max_wait_seconds));
        let asked = Instant::now();
        let late_log = self.late_log.take();
        // A drain ends the long poll (a lease granted to it meanwhile is given back by
        // `leave`).
        let answer = tokio::select! {
            answer = self.api.retry("lease", &self.stop, InFlight::Drop, || {
                self.api.lease(reg.worker_id, wait, late_log.clone())
            }) => answer,
            () = self.draining.wait() => return Some(Ok(())),
        };
        Some(match answer {
            Ok(None) => return None,
            Ok(Some(LeaseAnswer::NoWork)) => {
                if asked.elapsed() < IDLE_PAUSE {
                    self.pause(jitter(IDLE_PAUSE)).await;
                }
                Ok(())
            }
            Ok(Some(LeaseAnswer::Assigned(lease))) => {
                // Every line logged about this lease names it.
                let span = tracing::info_span!(
                    "task",
                    id = lease.token.task_id,
                    job = lease.job_id,
                    attempt = lease.token.attempt
                );
                let worked = self.work(reg, *lease).instrument(span).await;
                self.pilot.worked();
                worked
            }
            Err(e) => Err(e),
        })
    }

    /// Waits for the upload in flight, if any, and counts it; returns its error.
    async fn settle(&mut self) -> Result<(), ApiError> {
        let Some(delivery) = self.delivery.take() else {
            return Ok(());
        };
        match delivery.await {
            Ok(Delivered { fate, result }) => {
                self.count(fate);
                result
            }
            Err(e) => {
                tracing::error!("an upload task died: {e}");
                self.count(Fate::Abandoned);
                Ok(())
            }
        }
    }

    /// [`Daemon::settle`] where its error needs no action, only a line in the log: at
    /// shutdown, or once the registration it was made under is gone.
    async fn settle_and_log(&mut self) {
        if let Err(e) = self.settle().await {
            tracing::warn!("upload: {e}");
        }
    }

    /// Adds a task's end to the summary: the one place its task counts change.
    fn count(&mut self, fate: Fate) {
        let s = &mut self.summary;
        match fate {
            Fate::Done => s.tasks_done += 1,
            Fate::Failed => s.tasks_failed += 1,
            Fate::Abandoned => s.tasks_abandoned += 1,
            Fate::Interrupted => s.tasks_interrupted += 1,
        }
    }

    /// The courier for `reg`'s uploads and failure reports.
    fn courier(&self, reg: &WorkerRegistered) -> Courier {
        Courier {
            api: self.api.clone(),
            stop: self.stop.clone(),
            worker: reg.worker_id,
        }
    }

    /// Sleeps `d`, or less if shutdown begins.
    async fn pause(&self, d: Duration) {
        tokio::select! {
            _ = tokio::time::sleep(d) => {}
            _ = self.stop.wait() => {}
        }
    }

    /// Registers (retrying while the server is unreachable); `None` on shutdown.
    async fn register(&mut self) -> anyhow::Result<Option<WorkerRegistered>> {
        let reg = &self.registration;
        let answer = self
            .api
            .retry("register", &self.stop, InFlight::Drop, || {
                self.api.register(reg)
            })
            .await
            .map_err(anyhow::Error::from)
            .with_context(|| format!("registering with {}", self.api.server()))?;
        if let Some(r) = &answer {
            self.summary.registrations += 1;
            let kept = identity::Identity {
                server: self.api.server().to_string(),
                name: reg.name.clone(),
                worker_id: r.worker_id,
                credential: r.credential.clone(),
            };
            if let Err(e) = identity::save(&self.identity_dir, &kept) {
                tracing::warn!(
                    "could not keep this worker's identity in {} ({e}): after a restart it \
                     is known by its name only",
                    self.identity_dir.display()
                );
            }
            tracing::info!(
                "registered with {} as worker {} ({}, {} threads); heartbeat every {} s",
                self.api.server(),
                r.worker_id,
                reg.name,
                reg.threads,
                r.heartbeat_seconds
            );
            // The next registration (the server forgot this worker) comes back as it.
            self.registration.credential = Some(r.credential.clone());
        }
        Ok(answer)
    }

    /// Tells the server this worker is gone, so its leases (the one being rendered, or one
    /// granted to a long poll that was dropped) are queued again at once.
    async fn leave(&mut self) {
        let Some(reg) = self.registered.take() else {
            tracing::info!("shutting down (not registered: nothing to give back)");
            return;
        };
        let id = reg.worker_id;
        let attempt = async {
            let mut backoff = Backoff::new();
            loop {
                match self.api.leave(id).await {
                    Err(e) if e.is_transient() => {
                        tracing::warn!("leave: {e}");
                        tokio::time::sleep(backoff.next_delay()).await;
                    }
                    other => return other,
                }
            }
        };
        match tokio::time::timeout(LEAVE_TIMEOUT, attempt).await {
            Ok(Ok(left)) => tracing::info!(
                "worker {id} left {}; leases given back for jobs {:?}",
                self.api.server(),
                left.jobs
            ),
            Ok(Err(e)) => tracing::warn!("worker {id} could not leave: {e}"),
            Err(_) => tracing::warn!(
                "worker {id} could not tell {} it is leaving within {}; its leases expire \
                 on their own",
                self.api.server(),
                seconds(LEAVE_TIMEOUT)
            ),
        }
    }

    /// One lease: render it and hand it to an upload task, or report why not. Errors are
    /// the ones the main loop acts on (unknown worker, 401, unexpected answers).
    async fn work(&mut self, reg: &WorkerRegistered, lease: Lease) -> Result<(), ApiError> {
        let task = lease.token.task_id;
        // What is logged about the lease from here on goes to the server with its
        // heartbeats, its failure report or the next lease request (the upload's own lines
        // stay in this log only).
        let _log = TaskLog::open(task);
        tracing::info!(
            "lease taken: job {} frame {} tile {}x{} at ({}, {}) samples {}..{} (task {}, \
             attempt {})",
            lease.job_id,
            lease.frame,
            lease.tile.width,
            lease.tile.height,
            lease.tile.x,
            lease.tile.y,
            lease.samples.start,
            lease.samples.end,
            task,
            lease.token.attempt
        );
        let cancel = Arc::new(AtomicBool::new(false));
        let courier = self.courier(reg);
        let mut heartbeat = tokio::spawn(
            heartbeat_until_gone(
                self.api.clone(),
                reg.worker_id,
                lease.token,
                Duration::from_secs(reg.heartbeat_seconds.max(1)),
            )
            .in_current_span(),
        );
        // The lease is kept until this task is handed to its upload, which may first wait
        // for the previous tile's.
        let _beating = AbortOnDrop(heartbeat.abort_handle());
        let stop = self.stop.clone();
        // The render runs on the rayon pool; when this select drops it, the pool's threads
        // stop at their next pixel because `cancel` is set below.
        let produced = tokio::select! {
            r = self.produce(reg.worker_id, &lease, &cancel) => Some(r),
            end = &mut heartbeat => {
                cancel.store(true, Ordering::Relaxed);
                self.count(Fate::Abandoned);
                return match end {
                    Ok(HeartbeatEnd::LeaseGone(why)) => {
                        tracing::warn!(
                            "lease on task {task} gone ({why}): render aborted, tile dropped"
                        );
                        Ok(())
                    }
                    Ok(HeartbeatEnd::Error(e)) => Err(e),
                    Err(e) => {
                        tracing::error!("heartbeat task of task {task} died: {e}");
                        Ok(())
                    }
                };
            }
            _ = stop.wait() => None,
        };
        let (product, render_ms) = match produced {
            None | Some(Err(TaskError::Stopped)) => {
                cancel.store(true, Ordering::Relaxed);
                self.count(Fate::Interrupted);
                tracing::info!(
                    "shutdown: task {task} (job {} frame {}) aborted, tile dropped",
                    lease.job_id,
                    lease.frame
                );
                return Ok(());
            }
            Some(Ok(r)) => r,
            Some(Err(TaskError::Api(e))) => {
                self.count(Fate::Abandoned);
                return Err(e);
            }
            Some(Err(TaskError::Failed(message))) => {
                self.count(Fate::Failed);
                return courier.report_failure(&lease, &message).await;
            }
        };
        // One upload in flight at most: the previous tile's has had this render's time.
        if let Err(e) = self.settle().await {
            self.count(Fate::Abandoned);
            return Err(e);
        }
        // What was logged since the last heartbeat goes with the next lease request.
        self.late_log = Some(TaskLogLines {
            token: lease.token,
            lines: task_log::take(task),
        });
        let delivery = courier.deliver(lease, product, render_ms, self.compression);
        self.delivery = Some(tokio::spawn(delivery.in_current_span()));
        Ok(())
    }

    /// Scene, frame, render: `Ok` with the tile and its render time in milliseconds; or,
    /// for a denoise lease, the frame and its denoising.
    async fn produce(
        &mut self,
        worker: u64,
        lease: &Lease,
        cancel: &Arc<AtomicBool>,
    ) -> Result<(Product, u64), TaskError> {
        match lease.kind {
            TaskKind::Render => {
                let (tile, ms) = self.render(lease, cancel).await?;
                Ok((Product::Tile(Box::new(tile)), ms))
            }
            TaskKind::Denoise => {
                let (denoised, ms) = self.denoise(worker, lease).await?;
                Ok((Product::Denoised(denoised), ms))
            }
            TaskKind::Encode => {
                let (mp4, ms) = self.encode(worker, lease).await?;
                Ok((Product::Video(mp4), ms))
            }
        }
    }

    /// Scene, frame, render: `Ok` with the tile and its render time in milliseconds.
    async fn render(
        &mut self,
        lease: &Lease,
        cancel: &Arc<AtomicBool>,
    ) -> Result<(TileBuffer, u64), TaskError> {
        if self.fault == Some(Fault::FailJob(lease.job_id)) {
            return Err(TaskError::Failed(format!(
                "injected fault: every task of job {} fails",
                lease.job_id
            )));
        }
        let frame = self.frame(lease).await?;
        let (pool, job, cancel) = (self.pool.clone(), lease.clone(), cancel.clone());
        let perturb = self.fault == Some(Fault::Perturb);
        let rendered = tokio::task::spawn_blocking(move || {
            let (mut tile, ms) = pool.install(|| render_lease(&frame, &job, &cancel))?;
            if perturb {
                // One pixel's red a thousandth too bright, after averaging.
                tile.beauty[0].x += 1e-3 * tile.samples[0].max(1) as f32;
            }
            Some((tile, ms))
        })
        .await;
        match rendered {
            Ok(Some(tile)) => Ok(tile),
            // Cancelled: only shutdown or a lost lease set the flag, and both end the
            // select in `work` first; this is the same outcome.
            Ok(None) => Err(TaskError::Stopped),
            Err(e) => Err(TaskError::Failed(format!("the render panicked: {e}"))),
        }
    }
}

/// Heartbeats the lease every `every`, with the lines logged for it since the last beat,
/// until the server says it is gone (409) or refuses the worker; a heartbeat that fails
/// on the network is tried again at the next beat (its lines are lost).
async fn heartbeat_until_gone(
    api: Api,
    worker: u64,
    token: TaskToken,
    every: Duration,
) -> HeartbeatEnd {
    let mut ticker = tokio::time::interval_at(tokio::time::Instant::now() + every, every);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        ticker.tick().await;
        match api
            .heartbeat(worker, token, task_log::take(token.task_id))
            .await
        {
            Ok(HeartbeatAnswer::Extended(_)) => {}
            Ok(HeartbeatAnswer::LeaseGone(why)) => return HeartbeatEnd::LeaseGone(why),
            Err(e) if e.is_transient() => tracing::warn!(
                "heartbeat of task {}: {e}; rendering on, next beat in {}",
                token.task_id,
                seconds(every)
            ),
            Err(e) => return HeartbeatEnd::Error(e),
        }
    }
}
