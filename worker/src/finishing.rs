//! The steps after rendering. A denoise lease: the assembled frame is fetched, denoised
//! with Open Image Denoise on the worker's threads, and uploaded as the beauty of an EXR
//! of the whole frame. An encode lease: the frames' PNGs are fetched and FFmpeg makes the
//! job's MP4 of them.

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use proto::{Lease, ResultMetadata};
use tracer::film::{Layers, TileRect};
use tracer::output::{decode_exr, encode_exr_layers, ExrCompression, ExrMetadata, ImageLayer};

use crate::cache::sha256_hex;
use crate::render::RenderedTile;

/// The worker's denoiser: the library, and the threads it may use (the render pool's).
#[derive(Clone, Debug)]
pub struct Denoiser {
    /// Open Image Denoise, loaded.
    pub oidn: Arc<post::Oidn>,
    /// Threads it runs on.
    pub threads: u32,
}

impl Denoiser {
    /// Denoises the frame `exr` (the EXR bytes the server sent for `lease`): the
    /// denoised RGB and the milliseconds it took. Blocking: call it off the async runtime.
    pub fn denoise(&self, lease: &Lease, exr: &[u8]) -> Result<(Vec<Vec3>, u64), String> {
        let image = decode_exr(exr).map_err(|e| format!("reading the frame: {e}"))?;
        let whole = TileRect::new(0, 0, lease.width, lease.height);
        if image.frame_size != (lease.width, lease.height) || image.layers.rect != whole {
            return Err(format!(
                "the frame sent is {}x{} with data window {:?}, not the whole {}x{} frame",
                image.frame_size.0,
                image.frame_size.1,
                image.layers.rect,
                lease.width,
                lease.height
            ));
        }
        let started = Instant::now();
        let denoised = post::denoise_layers(&self.oidn, &image.layers, self.threads)
            .map_err(|e| e.to_string())?;
        Ok((denoised, started.elapsed().as_millis() as u64))
    }
}

/// The upload of a denoise lease: an EXR of the whole frame whose beauty is `denoised`
/// (alpha 1), with 0 samples and 0 rays, stored with `compression`.
pub fn encode_denoised(
    lease: &Lease,
    denoised: &[Vec3],
    denoise_ms: u64,
    compression: ExrCompression,
) -> Result<RenderedTile, String> {
    let mut layers = Layers::new(TileRect::new(0, 0, lease.width, lease.height));
    if denoised.len() != layers.beauty.len() {
        return Err(format!(
            "{} denoised pixels for a {}x{} frame",
            denoised.len(),
            lease.width,
            lease.height
        ));
    }
    for (b, d) in layers.beauty.iter_mut().zip(denoised) {
        *b = d.extend(1.0);
    }
    let exr = encode_exr_layers(
        (lease.width, lease.height),
        &layers,
        &ExrMetadata::new(),
        &[ImageLayer::Beauty],
        compression,
    )
    .map_err(|e| e.to_string())?;
    Ok(step_upload(lease, exr, denoise_ms))
}

/// The worker's video encoder.
#[derive(Clone, Debug)]
pub struct Encoder {
    /// FFmpeg with libx264.
    pub ffmpeg: post::Ffmpeg,
    /// Threads it may use.
    pub threads: u32,
}

impl Encoder {
    /// Encodes `frames` (PNG files, in order) at `fps`: the MP4's bytes and the
    /// milliseconds it took. Blocking: call it off the async runtime.
    pub fn encode(
        &self,
        frames: &[std::path::PathBuf],
        fps: f64,
    ) -> Result<(Vec<u8>, u64), String> {
        let started = Instant::now();
        let dir = tempfile::tempdir().map_err(|e| format!("a temporary folder: {e}"))?;
        let out = dir.path().join("video.mp4");
        self.ffmpeg
            .encode(frames, fps, &out, self.threads)
            .map_err(|e| e.to_string())?;
        let bytes = std::fs::read(&out).map_err(|e| format!("{}: {e}", out.display()))?;
        Ok((bytes, started.elapsed().as_millis() as u64))
    }
}

/// The side of the square frames a worker times its steps on when it starts.
const PROBE_SIDE: u32 = 256;
/// Frames of the video it times its encoder on.
const PROBE_FRAMES: i32 = 8;

/// A `PROBE_SIDE`² frame of frame `seed` whose every layer is noise (the denoiser's and
/// the encoder's hardest case: nothing in it is smooth).
fn probe_frame(seed: i32) -> Layers {
    let mut layers = Layers::new(TileRect::new(0, 0, PROBE_SIDE, PROBE_SIDE));
    let noise = |i: usize, k: u32| {
        let h = tracer::sampler::hash_combine(i as u32 ^ (seed as u32).rotate_left(20), k);
        (h >> 8) as f32 / (1u32 << 24) as f32
    };
    for i in 0..layers.beauty.len() {
        layers.beauty[i] = glam::Vec4::new(noise(i, 0), noise(i, 1), noise(i, 2), 1.0);
        layers.albedo[i] = Vec3::new(noise(i, 3), noise(i, 4), noise(i, 5));
        layers.normal[i] =
            (Vec3::new(noise(i, 6), noise(i, 7), noise(i, 8)) - 0.5).normalize_or_zero();
    }
    layers
}

/// Milliseconds per megapixel of a step that took `ms` on `frames` probe frames.
fn per_megapixel(ms: u128, frames: i32) -> u64 {
    let megapixels = f64::from(PROBE_SIDE * PROBE_SIDE) * f64::from(frames) / 1e6;
    (ms as f64 / megapixels).ceil() as u64
}

impl Denoiser {
    /// What denoising takes per megapixel on this worker (milliseconds), timed once at
    /// start on a small frame of noise: the time-budget planner's figure for its denoise
    /// steps until it has done real ones. The library's set-up counts in it, as it does in
    /// every task, so it is high for large frames. `None` if the denoiser fails.
    pub fn time_per_megapixel(&self) -> Option<u64> {
        let started = Instant::now();
        post::denoise_layers(&self.oidn, &probe_frame(0), self.threads).ok()?;
        Some(per_megapixel(started.elapsed().as_millis(), 1))
    }
}

impl Encoder {
    /// What encoding takes per megapixel of frames on this worker (milliseconds), timed
    /// once at start on a few small frames of noise (FFmpeg's start counts in it, as it
    /// does in every task). `None` if it fails.
    pub fn time_per_megapixel(&self) -> Option<u64> {
        let dir = tempfile::tempdir().ok()?;
        let frames: Vec<std::path::PathBuf> = (0..PROBE_FRAMES)
            .map(|k| {
                let png = dir.path().join(format!("{k}.png"));
                tracer::output::write_preview_png(
                    &png,
                    (PROBE_SIDE, PROBE_SIDE),
                    &probe_frame(k),
                    1.0,
                )
                .ok()
                .map(|()| png)
            })
            .collect::<Option<_>>()?;
        let (_, ms) = self.encode(&frames, 24.0).ok()?;
        Some(per_megapixel(ms.into(), PROBE_FRAMES))
    }
}

/// The upload of a step after rendering: `bytes` (the denoised frame's EXR, or the MP4)
/// with 0 samples and 0 rays, and the step's time.
pub fn step_upload(lease: &Lease, bytes: Vec<u8>, step_ms: u64) -> RenderedTile {
    let meta = ResultMetadata {
        attempt: lease.token.attempt,
        sha256: sha256_hex(&bytes),
        samples: 0,
        rays: 0,
        render_ms: step_ms,
    };
    RenderedTile { exr: bytes, meta }
}
