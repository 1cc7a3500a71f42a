//! Uploads and failure reports for one registration, on a task of their own so the next
//! lease renders meanwhile.

use proto::{Lease, TaskKind};
use tracer::output::ExrCompression;

use super::{Delivered, Fate, Product};
use crate::api::{Api, ApiError, FailureAnswer, InFlight, UploadAnswer};
use crate::finishing::{encode_denoised, step_upload};
use crate::render::encode_tile;
use crate::stop::Stop;
use crate::task_log;

/// Uploads tiles and reports failures for one registration; cheap to clone into the task
/// that uploads a tile while the next renders.
pub(super) struct Courier {
    pub(super) api: Api,
    pub(super) stop: Stop,
    pub(super) worker: u64,
}

impl Courier {
    /// Encodes `tile` and uploads it; a tile that cannot be encoded, or that the server
    /// refuses, is reported as a failure.
    pub(super) async fn deliver(
        self,
        lease: Lease,
        product: Product,
        render_ms: u64,
        compression: ExrCompression,
    ) -> Delivered {
        let job = lease.clone();
        let encoded = tokio::task::spawn_blocking(move || match product {
            Product::Tile(tile) => {
                encode_tile(&job, &tile, render_ms, compression).map_err(|e| e.to_string())
            }
            Product::Denoised(denoised) => encode_denoised(&job, &denoised, render_ms, compression),
            Product::Video(mp4) => Ok(step_upload(&job, mp4, render_ms)),
        })
        .await
        .unwrap_or_else(|e| Err(format!("panicked: {e}")));
        let (exr, meta) = match encoded {
            Ok(t) => (t.exr, t.meta),
            Err(e) => {
                return self
                    .failed(&lease, &format!("encoding the tile: {e}"))
                    .await
            }
        };
        let task = lease.token.task_id;
        // Uploads are idempotent: a repeat after a lost answer is stored once.
        let answer = self
            .api
            .retry("upload", &self.stop, InFlight::Finish, || {
                self.api.upload(self.worker, task, &meta, exr.clone())
            })
            .await;
        let (fate, result) = match answer {
            Ok(Some(UploadAnswer::Stored(_))) if lease.kind == TaskKind::Encode => {
                tracing::info!(
                    "video uploaded: job {} encoded in {} ms",
                    lease.job_id,
                    meta.render_ms
                );
                (Fate::Done, Ok(()))
            }
            Ok(Some(UploadAnswer::Stored(ack))) if lease.kind == TaskKind::Denoise => {
                tracing::info!(
                    "denoised frame uploaded: job {} frame {} denoised in {} ms{}",
                    lease.job_id,
                    lease.frame,
                    meta.render_ms,
                    if ack.accepted {
                        ""
                    } else {
                        " (a repeat: ignored)"
                    },
                );
                (Fate::Done, Ok(()))
            }
            Ok(Some(UploadAnswer::Stored(ack))) => {
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
                (Fate::Done, Ok(()))
            }
            Ok(Some(UploadAnswer::LeaseGone(why))) => {
                tracing::warn!("tile of task {task} dropped: lease gone ({why})");
                (Fate::Abandoned, Ok(()))
            }
            Ok(Some(UploadAnswer::Refused(why))) => {
                let message = format!("the server refused the tile: {why}");
                return self.failed(&lease, &message).await;
            }
            Ok(None) => {
                tracing::info!("shutdown: upload of task {task} abandoned");
                (Fate::Interrupted, Ok(()))
            }
            Err(e) => (Fate::Abandoned, Err(e)),
        };
        Delivered { fate, result }
    }

    /// [`Courier::report_failure`] as a delivery's end.
    async fn failed(&self, lease: &Lease, message: &str) -> Delivered {
        Delivered {
            fate: Fate::Failed,
            result: self.report_failure(lease, message).await,
        }
    }

    pub(super) async fn report_failure(
        &self,
        lease: &Lease,
        message: &str,
    ) -> Result<(), ApiError> {
        let task = lease.token.task_id;
        tracing::warn!(
            "task {task} (job {} frame {}) failed: {message}",
            lease.job_id,
            lease.frame
        );
        let log = task_log::take(task);
        let answer = self
            .api
            .retry("failure report", &self.stop, InFlight::Finish, || {
                self.api
                    .failure(self.worker, lease.token, message, log.clone())
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
