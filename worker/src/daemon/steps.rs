//! The steps after rendering, as the daemon does them: finding Open Image Denoise and
//! FFmpeg at start, and a denoise or encode lease's input fetched and turned into what is
//! uploaded ([`crate::finishing`] holds the work itself).

use std::sync::Arc;

use proto::{Lease, TaskToken};

use super::{Daemon, TaskError};
use crate::api::{ApiError, InFlight};
use crate::config::WorkerConfig;
use crate::finishing::{Denoiser, Encoder};

/// Open Image Denoise where the config says to look, for denoise tasks; `None` (said in
/// the log) when it is not there.
pub(super) fn load_denoiser(config: &WorkerConfig) -> Option<Denoiser> {
    match post::Oidn::load(config.oidn.as_deref()) {
        Ok(oidn) => {
            tracing::info!(
                "denoise tasks taken: Open Image Denoise from {}",
                oidn.path().display()
            );
            Some(Denoiser {
                oidn: Arc::new(oidn),
                threads: config.threads.min(u32::MAX as usize) as u32,
            })
        }
        Err(e) => {
            tracing::info!("no denoise tasks: {e}");
            None
        }
    }
}

/// What the worker registers as its encoder.
pub(super) const ENCODER_NAME: &str = "FFmpeg with libx264";

/// FFmpeg where the config says to look, for encode tasks; `None` (said in the log) when
/// it is not there.
pub(super) fn find_encoder(config: &WorkerConfig) -> Option<Encoder> {
    match post::Ffmpeg::find(config.ffmpeg.as_deref()) {
        Ok(ffmpeg) => {
            tracing::info!(
                "encode tasks taken: FFmpeg at {}",
                ffmpeg.program().display()
            );
            Some(Encoder {
                ffmpeg,
                threads: config.threads.min(u32::MAX as usize) as u32,
            })
        }
        Err(e) => {
            tracing::info!("no encode tasks: {e}");
            None
        }
    }
}

/// What the worker's denoiser and encoder take per megapixel, timed once at start off
/// the async runtime (and said in the log), for the server's time-budget planner.
pub(super) async fn time_steps(
    denoiser: Option<Denoiser>,
    encoder: Option<Encoder>,
) -> [Option<u64>; 2] {
    let timed = tokio::task::spawn_blocking(move || {
        [
            denoiser.and_then(|d| d.time_per_megapixel()),
            encoder.and_then(|e| e.time_per_megapixel()),
        ]
    })
    .await
    .unwrap_or_default();
    for (step, ms) in ["denoising", "encoding"].iter().zip(timed) {
        if let Some(ms) = ms {
            tracing::info!("{step} takes {ms} ms per megapixel here");
        }
    }
    timed
}

impl Daemon {
    /// What a step after rendering reads from the server (`frame` for an encode lease).
    async fn step_input(
        &self,
        worker: u64,
        token: TaskToken,
        frame: Option<i32>,
    ) -> Result<Vec<u8>, TaskError> {
        match self
            .api
            .retry("frame download", &self.stop, InFlight::Drop, || {
                self.api.frame(worker, token, frame)
            })
            .await
        {
            Ok(Some(Some(bytes))) => Ok(bytes),
            Ok(Some(None)) => Err(TaskError::Failed(
                "the lease was gone when the frame was asked for".into(),
            )),
            Ok(None) => Err(TaskError::Stopped),
            Err(e @ ApiError::Unexpected { .. }) => Err(TaskError::Failed(e.to_string())),
            Err(e) => Err(TaskError::Api(e)),
        }
    }

    /// The frames of an encode lease, fetched, and their MP4.
    pub(super) async fn encode(
        &mut self,
        worker: u64,
        lease: &Lease,
    ) -> Result<(Vec<u8>, u64), TaskError> {
        let Some(encoder) = self.encoder.clone() else {
            return Err(TaskError::Failed(
                "this worker registered no encoder, yet was given an encode task".into(),
            ));
        };
        let Some(sequence) = lease.sequence else {
            return Err(TaskError::Failed("the encode lease names no frames".into()));
        };
        let dir = tempfile::tempdir()
            .map_err(|e| TaskError::Failed(format!("a temporary folder: {e}")))?;
        let mut files = Vec::new();
        for frame in sequence.frames() {
            let png = self.step_input(worker, lease.token, Some(frame)).await?;
            let path = dir.path().join(sequence.file_name(frame, "png"));
            std::fs::write(&path, png)
                .map_err(|e| TaskError::Failed(format!("{}: {e}", path.display())))?;
            files.push(path);
        }
        let fps = lease.fps;
        tokio::task::spawn_blocking(move || {
            let encoded = encoder.encode(&files, fps);
            drop(dir);
            encoded
        })
        .await
        .map_err(|e| TaskError::Failed(format!("encoding panicked: {e}")))?
        .map_err(|e| TaskError::Failed(format!("encoding the video: {e}")))
    }

    /// The frame of a denoise lease, fetched and denoised.
    pub(super) async fn denoise(
        &mut self,
        worker: u64,
        lease: &Lease,
    ) -> Result<(Vec<glam::Vec3>, u64), TaskError> {
        let Some(denoiser) = self.denoiser.clone() else {
            return Err(TaskError::Failed(
                "this worker registered no denoiser, yet was given a denoise task".into(),
            ));
        };
        let exr = self.step_input(worker, lease.token, None).await?;
        let (pool, job) = (self.pool.clone(), lease.clone());
        tokio::task::spawn_blocking(move || pool.install(|| denoiser.denoise(&job, &exr)))
            .await
            .map_err(|e| TaskError::Failed(format!("denoising panicked: {e}")))?
            .map_err(|e| TaskError::Failed(format!("denoising frame {}: {e}", lease.frame)))
    }
}
