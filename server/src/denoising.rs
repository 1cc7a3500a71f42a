//! A frame's denoise step. A job that denoises gets one denoise task per frame when the
//! frame is assembled; a worker with a denoiser leases it, reads the frame's EXR
//! (`GET /workers/{id}/tasks/{task}/frame`), and uploads the denoised RGB as the beauty of an EXR of the
//! whole frame. [`receive`] checks that upload and writes it into the frame's EXR as its
//! `denoised` layer, beside the noisy one, and redraws the PNG preview from it: band by
//! band, like assembly, so the server never holds a whole frame.

use std::path::PathBuf;

use proto::{JobSpec, ResultMetadata, TaskToken};
use tracer::film::{Layers, TileRect};
use tracer::output::{
    self, read_exr_rows, ExrCompression, ExrMetadata, ExrTarget, ImageLayer, PreviewTarget,
    BLOCK_ROWS,
};

use crate::app::App;
use crate::assembly;
use crate::db::frames;
use crate::db::tasks::{self, NewTask, TaskRow};
use crate::error::{Error, Result};
use crate::intake::{self, Received};
use crate::scheduler;
use crate::store::write_atomic;

/// Queues the denoise task of an assembled frame, in the transaction that marks it
/// assembled, when its job denoises (and it has none yet).
pub fn queue(tx: &rusqlite::Transaction, job: u64, frame: i32, spec: &JobSpec) -> Result<bool> {
    if !spec.denoise || tasks::denoise_of_frame(tx, job, frame)?.is_some() {
        return Ok(false);
    }
    tasks::insert(tx, &NewTask::denoise(job, frame, (spec.width, spec.height)))?;
    Ok(true)
}

/// The largest upload a denoise task may send for a `spec` frame: its RGBA as `f32`
/// uncompressed, plus room for the header and the offset table.
pub fn max_upload_bytes(spec: &JobSpec) -> usize {
    let pixels = spec.width as usize * spec.height as usize;
    pixels * 16 + spec.height as usize * 8 + (64 << 10)
}

/// The assembled EXR of the frame a denoise `task` denoises.
pub fn frame_exr(app: &App, task: &TaskRow, spec: &JobSpec) -> PathBuf {
    let last = spec.frames.map_or(task.frame, |f| f.last());
    app.store.frame(task.job_id, task.frame, last, "exr")
}

/// Checks and takes a denoise task's upload: the frame's EXR gets the `denoised` layer
/// and its PNG shows it, then the task is done. Nothing is written when the upload is
/// refused (wrong size, a value not finite): the worker hears why.
pub fn receive(
    app: &App,
    worker: u64,
    token: TaskToken,
    meta: &ResultMetadata,
    bytes: &[u8],
    task: &TaskRow,
    spec: &JobSpec,
) -> Result<Received> {
    assembly::check_step_upload(bytes, meta, task)?;
    let upload = app.store.tile(task.job_id, token.task_id, token.attempt);
    write_atomic(&upload, bytes)?;
    let written = {
        let _guard = app.assembly.lock().unwrap_or_else(|p| p.into_inner());
        // A stale lease writes nothing into the frame.
        app.db
            .with(|c| scheduler::check_token(c, worker, token))
            .and_then(|_| write_denoised(app, task, spec, &upload, meta.render_ms))
            .and_then(|()| intake::accept_step(app, worker, token, meta, task, bytes.len()))
    };
    let _ = std::fs::remove_file(&upload);
    written
}

/// Writes the frame's EXR again with the upload's beauty as its `denoised` layer (and
/// every layer it had), and its PNG from the denoised beauty, band by band.
fn write_denoised(
    app: &App,
    task: &TaskRow,
    spec: &JobSpec,
    upload: &std::path::Path,
    denoise_ms: u64,
) -> Result<()> {
    let exr = frame_exr(app, task, spec);
    let size = (spec.width, spec.height);
    let frame_error =
        |e: output::OutputError| Error::BadFrame(format!("frame {}: {e}", task.frame));
    let upload_error = |e: String| {
        Error::BadTile(format!(
            "the denoised frame {} of task {}: {e}",
            task.frame, task.id
        ))
    };
    // The header first: the frame's attributes carry over.
    let head = read_exr_rows(&exr, 0..0).map_err(frame_error)?;
    let mut meta = ExrMetadata::new();
    for (name, value) in &head.attributes {
        if name != "software" {
            meta.set(name.clone(), value.clone());
        }
    }
    meta.set(ExrMetadata::DENOISER, denoiser_of(app, task)?);
    meta.set(
        ExrMetadata::DENOISE_SECONDS,
        format!("{:.3}", denoise_ms as f64 / 1000.0),
    );
    // The layers the frame was assembled with, and the new one.
    let mut layers = assembly::image_layers(&spec.layers);
    layers.push(ImageLayer::Denoised);
    let png = exr.with_extension("png");
    let band_rows = assembly::band_rows(spec, app.config.assembly_memory).unwrap_or(BLOCK_ROWS);
    output::write_frame_in_bands(
        size,
        band_rows,
        Some(ExrTarget {
            path: &exr,
            meta: &meta,
            layers: &layers,
            compression: ExrCompression::Zip,
        }),
        Some(PreviewTarget {
            path: &png,
            exposure: 0.0,
        }),
        |band: TileRect| -> Result<Layers> {
            let mut frame = read_exr_rows(&exr, band.y..band.y + band.height)
                .map_err(frame_error)?
                .layers;
            let denoised = read_exr_rows(upload, band.y..band.y + band.height)
                .map_err(|e| upload_error(e.to_string()))?;
            if denoised.frame_size != size || denoised.layers.rect != band {
                return Err(upload_error(format!(
                    "it is not the whole {}x{} frame (frame {}x{}, rows {:?})",
                    size.0,
                    size.1,
                    denoised.frame_size.0,
                    denoised.frame_size.1,
                    denoised.layers.rect
                )));
            }
            if let Some(i) = denoised.layers.beauty.iter().position(|b| !b.is_finite()) {
                return Err(upload_error(format!(
                    "pixel ({}, {}) is not finite",
                    i as u32 % band.width,
                    band.y + i as u32 / band.width
                )));
            }
            frame.denoised = denoised
                .layers
                .beauty
                .iter()
                .map(|b| b.truncate())
                .collect();
            Ok(frame)
        },
    )
}

/// What the worker that holds `task` denoises with.
fn denoiser_of(app: &App, task: &TaskRow) -> Result<String> {
    let worker = task
        .worker_id
        .ok_or_else(|| Error::Internal(format!("denoise task {} has no worker", task.id)))?;
    Ok(app
        .db
        .with(|c| crate::db::workers::denoiser(c, worker))?
        .unwrap_or_else(|| "unknown".to_string()))
}

/// Marks a denoise task's frame denoised (in the task's acceptance).
pub fn mark_denoised(tx: &rusqlite::Transaction, task: &TaskRow, now: i64) -> Result<()> {
    frames::set_denoised(tx, task.job_id, task.frame, now)
}
