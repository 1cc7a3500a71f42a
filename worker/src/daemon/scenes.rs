//! What a render lease needs before it renders: its scene (from memory, the disk cache,
//! or the server, verified and cached) and the frame prepared from it, both kept for the
//! next lease of the same scene and frame.

use std::sync::Arc;
use std::time::Instant;

use proto::Lease;
use tracer::render::{prepare_frame, PreparedFrame};
use tracer::scene::Scene;

use super::{Daemon, TaskError};
use crate::api::{ApiError, InFlight};
use crate::cache::{is_digest, sha256_hex, Cached};
use crate::render::{frame_key, frame_options};

impl Daemon {
    /// The prepared frame of `lease`: kept from the previous task when its key matches.
    pub(super) async fn frame(&mut self, lease: &Lease) -> Result<Arc<PreparedFrame>, TaskError> {
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
}
