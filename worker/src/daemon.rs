//! The worker's loop: register, long-poll for a lease, fetch the scene (memory, then disk
//! cache, then the server), prepare the frame, render the tile on the rayon pool while a
//! heartbeat task keeps the lease, upload, repeat.
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
use proto::{Lease, TaskToken, WorkerRegistered, WorkerRegistration};
use tracer::render::{prepare_frame, PreparedFrame};
use tracer::scene::Scene;
use tracing::Instrument;

use crate::api::{
    Api, ApiError, FailureAnswer, HeartbeatAnswer, InFlight, LeaseAnswer, UploadAnswer,
};
use crate::backoff::{jitter, seconds, Backoff, IDLE_PAUSE};
use crate::cache::{is_digest, sha256_hex, Cached, SceneCache};
use crate::config::{Fault, WorkerConfig};
use crate::render::{encode_tile, frame_key, frame_options, render_lease, RenderedTile};
use crate::stop::Stop;

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
}

/// Runs a worker until `shutdown` completes: then a render in progress is cancelled, the
/// server is told (`leave`, so the lease is queued again at once) and the summary is
/// returned. Fails only when the server refuses the token (401), refuses the registration,
/// or the config is unusable.
pub async fn run(
    config: WorkerConfig,
    shutdown: impl Future<Output = ()> + Send + 'static,
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
    let api = Api::new(&config.server, &config.api_base(), config.token.as_deref())
        .context("setting up the HTTP client")?;
    let (set_stop, stop) = Stop::new();
    let watcher = tokio::spawn(async move {
        shutdown.await;
        let _ = set_stop.send(true);
    });
    let mut daemon = Daemon {
        api,
        fault: config.fault,
        registration: WorkerRegistration {
            name: config.name.clone(),
            threads: config.threads.min(u32::MAX as usize) as u32,
            version: env!("CARGO_PKG_VERSION").to_string(),
        },
        registered: None,
        stop,
        pool: Arc::new(pool),
        cache: SceneCache::new(&config.cache_dir, config.cache_limit_bytes),
        scene: None,
        frame: None,
        warned: Vec::new(),
        summary: RunSummary::default(),
    };
    let result = daemon.main_loop().await;
    watcher.abort();
    result.map(|()| daemon.summary)
}

struct Daemon {
    api: Api,
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
    summary: RunSummary,
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
            let wait = Duration::from_secs(reg.max_wait_seconds);
            let asked = Instant::now();
            let answer = self
                .api
                .retry("lease", &self.stop, InFlight::Drop, || {
                    self.api.lease(reg.worker_id, wait)
                })
                .await;
            let result = match answer {
                Ok(None) => break,
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
                    self.work(&reg, *lease).instrument(span).await
                }
                Err(e) => Err(e),
            };
            match result {
                Ok(()) => trouble.reset(),
                Err(ApiError::UnknownWorker { message }) => {
                    tracing::warn!("server {}: {message}", self.api.server());
                    self.registered = None;
                }
                Err(e @ ApiError::Unauthorized { .. }) => return Err(e.into()),
                Err(e) => {
                    // An answer the protocol does not expect: a bug on one side. Keep
                    // going, slowly, rather than exit a daemon over it.
                    let delay = trouble.next_delay();
                    tracing::error!("{e}; trying again in {}", seconds(delay));
                    self.pause(delay).await;
                }
            }
        }
        self.leave().await;
        Ok(())
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
            tracing::info!(
                "registered with {} as worker {} ({}, {} threads); heartbeat every {} s",
                self.api.server(),
                r.worker_id,
                reg.name,
                reg.threads,
                r.heartbeat_seconds
            );
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

    /// One lease: render and upload it, or report why not. Errors are the ones the main
    /// loop acts on (unknown worker, 401, unexpected answers).
    async fn work(&mut self, reg: &WorkerRegistered, lease: Lease) -> Result<(), ApiError> {
        let task = lease.token.task_id;
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
        let mut heartbeat = tokio::spawn(
            heartbeat_until_gone(
                self.api.clone(),
                reg.worker_id,
                lease.token,
                Duration::from_secs(reg.heartbeat_seconds.max(1)),
            )
            .in_current_span(),
        );
        let stop = self.stop.clone();
        // The render runs on the rayon pool; when this select drops it, the pool's threads
        // stop at their next pixel because `cancel` is set below.
        let produced = tokio::select! {
            r = self.produce(&lease, &cancel) => Some(r),
            end = &mut heartbeat => {
                cancel.store(true, Ordering::Relaxed);
                self.summary.tasks_abandoned += 1;
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
        heartbeat.abort();
        let rendered = match produced {
            None | Some(Err(TaskError::Stopped)) => {
                cancel.store(true, Ordering::Relaxed);
                self.summary.tasks_interrupted += 1;
                tracing::info!(
                    "shutdown: task {task} (job {} frame {}) aborted, tile dropped",
                    lease.job_id,
                    lease.frame
                );
                return Ok(());
            }
            Some(Ok(r)) => r,
            Some(Err(TaskError::Api(e))) => {
                self.summary.tasks_abandoned += 1;
                return Err(e);
            }
            Some(Err(TaskError::Failed(message))) => {
                return self.report_failure(reg, &lease, &message).await;
            }
        };
        self.upload(reg, &lease, rendered).await
    }

    /// Scene, frame, render, EXR: `Ok` with the tile to upload.
    async fn produce(
        &mut self,
        lease: &Lease,
        cancel: &Arc<AtomicBool>,
    ) -> Result<RenderedTile, TaskError> {
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
            Some(encode_tile(&job, &tile, ms))
        })
        .await;
        match rendered {
            Ok(Some(Ok(tile))) => Ok(tile),
            // Cancelled: only shutdown or a lost lease set the flag, and both end the
            // select in `work` first; this is the same outcome.
            Ok(None) => Err(TaskError::Stopped),
            Ok(Some(Err(e))) => Err(TaskError::Failed(format!("encoding the tile: {e}"))),
            Err(e) => Err(TaskError::Failed(format!("the render panicked: {e}"))),
        }
    }

    /// The prepared frame of `lease`: kept from the previous task when its key matches.
    async fn frame(&mut self, lease: &Lease) -> Result<Arc<PreparedFrame>, TaskError> {
        let key = frame_key(lease);
        if let Some((k, frame)) = &self.frame {
            if *k == key {
                return Ok(frame.clone());
            }
        }
        // Drop the old frame before building the next: they can be large.
        self.frame = None;
        let scene = self.scene(&lease.scene).await?;
        let (pool, options) = (self.pool.clone(), frame_options(lease));
        let started = Instant::now();
        let prepared =
            tokio::task::spawn_blocking(move || pool.install(|| prepare_frame(scene, &options)))
                .await
                .map_err(|e| TaskError::Failed(format!("preparing the frame panicked: {e}")))?
                .map_err(|e| TaskError::Failed(format!("preparing frame {}: {e}", lease.frame)))?;
        // Warnings are about the scene more than the frame: say each once per scene.
        for w in &prepared.warnings {
            if !self.warned.contains(w) {
                tracing::warn!("scene {}: {w}", &lease.scene[..12]);
                self.warned.push(w.clone());
            }
        }
        tracing::debug!(
            "frame {} of job {} prepared in {} ms",
            lease.frame,
            lease.job_id,
            started.elapsed().as_millis()
        );
        let frame = Arc::new(prepared);
        self.frame = Some((key, frame.clone()));
        Ok(frame)
    }

    /// The scene `digest`: from memory, else the disk cache, else downloaded (verified
    /// and cached).
    async fn scene(&mut self, digest: &str) -> Result<Arc<Scene>, TaskError> {
        if let Some((d, scene)) = &self.scene {
            if d == digest {
                return Ok(scene.clone());
            }
        }
        self.scene = None;
        self.warned.clear();
        if !is_digest(digest) {
            return Err(TaskError::Failed(format!(
                "scene digest `{digest}` is not 64 lower-case hex digits"
            )));
        }
        let short = &digest[..12];
        let cache = self.cache.clone();
        let d = digest.to_string();
        let cached = tokio::task::spawn_blocking(move || cache.read(&d))
            .await
            .map_err(|e| TaskError::Failed(format!("reading the scene cache panicked: {e}")))?;
        let bytes = match cached {
            Ok(Cached::Hit(bytes)) => {
                tracing::info!(
                    "scene {short} from the cache ({})",
                    self.cache.path(digest).display()
                );
                bytes
            }
            other => {
                match other {
                    Ok(Cached::Corrupt { found }) => tracing::warn!(
                        "cached scene {short} has SHA-256 {found}: removed, downloading again"
                    ),
                    Err(e) => tracing::warn!(
                        "reading cached scene {}: {e}; downloading it",
                        self.cache.path(digest).display()
                    ),
                    _ => {}
                }
                self.download(digest).await?
            }
        };
        let scene = tokio::task::spawn_blocking(move || tracer::loader::load_glb(&bytes))
            .await
            .map_err(|e| TaskError::Failed(format!("loading the scene panicked: {e}")))?
            .map_err(|e| TaskError::Failed(format!("scene {digest}: {e}")))?;
        let scene = Arc::new(scene);
        self.scene = Some((digest.to_string(), scene.clone()));
        Ok(scene)
    }

    async fn download(&mut self, digest: &str) -> Result<Vec<u8>, TaskError> {
        let started = Instant::now();
        let bytes = match self
            .api
            .retry("scene download", &self.stop, InFlight::Drop, || {
                self.api.scene(digest)
            })
            .await
        {
            Ok(Some(b)) => b,
            Ok(None) => return Err(TaskError::Stopped),
            Err(e @ ApiError::Unexpected { .. }) => return Err(TaskError::Failed(e.to_string())),
            Err(e) => return Err(TaskError::Api(e)),
        };
        self.summary.scenes_downloaded += 1;
        let (cache, d) = (self.cache.clone(), digest.to_string());
        let stored = tokio::task::spawn_blocking(move || {
            let found = sha256_hex(&bytes);
            if found != d {
                return Err(format!(
                    "scene {d} as downloaded has SHA-256 {found}: the transfer or the \
                     server's copy is corrupt"
                ));
            }
            // A cache that cannot be written costs a download next time, nothing more.
            let written = cache.write(&d, &bytes).map_err(|e| (cache.path(&d), e));
            // Make room under the limit, keeping the scene about to be used.
            let trimmed = written.is_ok().then(|| cache.trim(&d));
            Ok((bytes, written, trimmed))
        })
        .await
        .map_err(|e| TaskError::Failed(format!("storing the scene panicked: {e}")))?
        .map_err(TaskError::Failed)?;
        let (bytes, written, trimmed) = stored;
        match written {
            Ok(path) => tracing::info!(
                "scene {} downloaded ({} bytes in {} ms) into {}",
                &digest[..12],
                bytes.len(),
                started.elapsed().as_millis(),
                path.display()
            ),
            Err((path, e)) => tracing::warn!("caching the scene as {}: {e}", path.display()),
        }
        match trimmed {
            Some(Ok(t)) if t.scenes > 0 => tracing::info!(
                "scene cache over its limit: removed {} least recently used scenes ({} bytes)",
                t.scenes,
                t.bytes
            ),
            Some(Err(e)) => tracing::warn!(
                "trimming the scene cache {}: {e}",
                self.cache.dir().display()
            ),
            _ => {}
        }
        Ok(bytes)
    }

    async fn upload(
        &mut self,
        reg: &WorkerRegistered,
        lease: &Lease,
        tile: RenderedTile,
    ) -> Result<(), ApiError> {
        let task = lease.token.task_id;
        let meta = tile.meta.clone();
        // Uploads are idempotent: a repeat after a lost answer is stored once.
        let answer = self
            .api
            .retry("upload", &self.stop, InFlight::Finish, || {
                self.api
                    .upload(reg.worker_id, task, &meta, tile.exr.clone())
            })
            .await;
        match answer {
            Ok(Some(UploadAnswer::Stored(ack))) => {
                self.summary.tasks_done += 1;
                tracing::info!(
                    "tile uploaded: job {} frame {} tile ({}, {}) samples {}..{} rendered in \
                     {} ms, {} rays{}{}",
                    lease.job_id,
                    lease.frame,
                    lease.tile.x,
                    lease.tile.y,
                    lease.samples.start,
                    lease.samples.end,
                    meta.render_ms,
                    meta.rays,
                    if ack.accepted {
                        ""
                    } else {
                        " (a repeat: ignored)"
                    },
                    if ack.frame_done {
                        "; frame complete"
                    } else {
                        ""
                    }
                );
                Ok(())
            }
            Ok(Some(UploadAnswer::LeaseGone(why))) => {
                self.summary.tasks_abandoned += 1;
                tracing::warn!("tile of task {task} dropped: lease gone ({why})");
                Ok(())
            }
            Ok(Some(UploadAnswer::Refused(why))) => {
                let message = format!("the server refused the tile: {why}");
                self.report_failure(reg, lease, &message).await
            }
            Ok(None) => {
                self.summary.tasks_interrupted += 1;
                tracing::info!("shutdown: upload of task {task} abandoned");
                Ok(())
            }
            Err(e) => {
                self.summary.tasks_abandoned += 1;
                Err(e)
            }
        }
    }

    async fn report_failure(
        &mut self,
        reg: &WorkerRegistered,
        lease: &Lease,
        message: &str,
    ) -> Result<(), ApiError> {
        let task = lease.token.task_id;
        tracing::warn!(
            "task {task} (job {} frame {}) failed: {message}",
            lease.job_id,
            lease.frame
        );
        self.summary.tasks_failed += 1;
        let answer = self
            .api
            .retry("failure report", &self.stop, InFlight::Finish, || {
                self.api.failure(reg.worker_id, lease.token, message)
            })
            .await?;
        match answer {
            Some(FailureAnswer::Recorded(ack)) => {
                if ack.task_failed {
                    tracing::warn!(
                        "task {task} is out of attempts: job {} failed",
                        lease.job_id
                    );
                } else if ack.blocked_from_job {
                    tracing::warn!(
                        "this worker failed too many tasks of job {} and gets no more of it",
                        lease.job_id
                    );
                }
            }
            Some(FailureAnswer::LeaseGone(_)) | None => {}
        }
        Ok(())
    }
}

/// Heartbeats the lease every `every` until the server says it is gone (409) or refuses
/// the worker; a heartbeat that fails on the network is tried again at the next beat.
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
        match api.heartbeat(worker, token).await {
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
