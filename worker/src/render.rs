//! A [`Lease`] in the tracer's terms: the frame options, the render settings, the tile and
//! its samples; the render itself (cancellable) and the EXR bytes that get uploaded.

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use proto::{CameraSpec, Lease, Rect, ResultMetadata, SampleSpan, TaskToken};
use tracer::animation::AnimationChoice;
use tracer::film::{SampleRange, TileBuffer, TileRect};
use tracer::motion::Shutter;
use tracer::output::{encode_exr_layers, ExrCompression, ExrMetadata, ImageLayer, OutputError};
use tracer::render::{
    render_tile_cancellable, CameraChoice, FrameOptions, NoiseTarget, PreparedFrame, RenderSettings,
};

use crate::cache::sha256_hex;

/// The tracer's options for the lease's frame. Every field is set from the lease (no
/// `..Default::default()`), so a field added to `FrameOptions` must be decided here.
pub fn frame_options(lease: &Lease) -> FrameOptions {
    FrameOptions {
        frame: lease.frame,
        fps: lease.fps,
        shutter: Shutter {
            open: lease.shutter[0],
            close: lease.shutter[1],
        },
        motion_steps: lease.motion_steps,
        // The job spec names its animation; the server checked that the scene has it.
        animation: match &lease.animation {
            None => AnimationChoice::All,
            Some(name) => AnimationChoice::Name(name.clone()),
        },
        width: lease.width,
        height: lease.height,
        camera: match &lease.camera {
            CameraSpec::Default => CameraChoice::Default,
            CameraSpec::Index(i) => CameraChoice::Index(*i as usize),
            CameraSpec::Name(n) => CameraChoice::Name(n.clone()),
        },
        // The scene's own environment (or the tracer's default), as the server's
        // previews and `tessera render` use.
        environment: None,
    }
}

/// The lease's light-transport settings.
pub fn settings(lease: &Lease) -> RenderSettings {
    RenderSettings {
        noise: lease.noise_threshold.map(|t| NoiseTarget {
            threshold: t as f32,
            min_samples: lease.min_spp,
        }),
        max_depth: lease.max_depth,
        seed: lease.seed,
        fixed_pattern: lease.fixed_pattern,
        clamp_indirect: lease.clamp_indirect,
        ..RenderSettings::DEFAULT
    }
}

/// The lease's tile.
pub fn tile_rect(lease: &Lease) -> TileRect {
    TileRect::new(
        lease.tile.x,
        lease.tile.y,
        lease.tile.width,
        lease.tile.height,
    )
}

/// The lease's samples.
pub fn sample_range(lease: &Lease) -> SampleRange {
    SampleRange::new(lease.samples.start, lease.samples.end)
}

/// What a prepared frame is kept by between tasks: the lease without the parts that vary
/// per task (token, tile, samples, deadline). Two leases with equal keys render the same
/// frame of the same scene with the same settings.
pub fn frame_key(lease: &Lease) -> Lease {
    Lease {
        token: TaskToken {
            task_id: 0,
            attempt: 0,
        },
        tile: Rect {
            x: 0,
            y: 0,
            width: 0,
            height: 0,
        },
        samples: SampleSpan { start: 0, end: 0 },
        deadline_ms: 0,
        ..lease.clone()
    }
}

/// A rendered tile, ready to upload.
#[derive(Clone, Debug)]
pub struct RenderedTile {
    /// The tile as EXR bytes.
    pub exr: Vec<u8>,
    /// The upload headers (attempt, checksum, samples, rays, time).
    pub meta: ResultMetadata,
}

/// Renders the lease's tile on the current rayon pool; `None` when `cancel` was set
/// before it finished. Call it inside `ThreadPool::install` to pick the pool.
pub fn render_lease(
    frame: &PreparedFrame,
    lease: &Lease,
    cancel: &AtomicBool,
) -> Option<(TileBuffer, u64)> {
    let started = Instant::now();
    let tile = render_tile_cancellable(
        frame,
        &settings(lease),
        tile_rect(lease),
        sample_range(lease),
        cancel,
    )?;
    Some((tile, started.elapsed().as_millis() as u64))
}

/// The EXR bytes of a rendered tile and the headers that go with them: the tile is
/// resolved (sums to averages) and written as the data window of the frame, with
/// `tessera/spp` set to the samples rendered, which is what the server merges passes by,
/// and stored with `compression`. `rays` is the tracer's own count (camera, bounce and
/// shadow rays).
pub fn encode_tile(
    lease: &Lease,
    tile: &TileBuffer,
    render_ms: u64,
    compression: ExrCompression,
) -> Result<RenderedTile, OutputError> {
    let samples = lease.samples.end - lease.samples.start;
    let meta = ExrMetadata::new().with(ExrMetadata::SPP, samples.to_string());
    let exr = encode_exr_layers(
        (lease.width, lease.height),
        &tile.resolve(),
        &meta,
        &ImageLayer::RENDERED,
        compression,
    )?;
    let meta = ResultMetadata {
        attempt: lease.token.attempt,
        sha256: sha256_hex(&exr),
        samples,
        rays: tile.rays,
        render_ms,
    };
    Ok(RenderedTile { exr, meta })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lease() -> Lease {
        Lease {
            token: TaskToken {
                task_id: 7,
                attempt: 2,
            },
            kind: proto::TaskKind::Render,
            job_id: 3,
            scene: "ab".repeat(32),
            frame: 12,
            fps: 30.0,
            width: 64,
            height: 48,
            camera: CameraSpec::Name("Main".into()),
            shutter: [-0.25, 0.25],
            motion_steps: Some(3),
            animation: Some("Walk".into()),
            max_depth: 5,
            seed: 9,
            fixed_pattern: true,
            clamp_indirect: Some(4.0),
            noise_threshold: Some(0.02),
            min_spp: 6,
            tile: Rect {
                x: 16,
                y: 32,
                width: 16,
                height: 16,
            },
            samples: SampleSpan { start: 4, end: 12 },
            sequence: None,
            deadline_ms: 1000,
        }
    }

    #[test]
    fn every_lease_field_reaches_the_tracer() {
        let l = lease();
        let o = frame_options(&l);
        assert_eq!((o.frame, o.fps, o.width, o.height), (12, 30.0, 64, 48));
        assert_eq!(o.camera, CameraChoice::Name("Main".into()));
        assert_eq!((o.shutter.open, o.shutter.close), (-0.25, 0.25));
        assert_eq!(o.motion_steps, Some(3));
        assert_eq!(o.animation, AnimationChoice::Name("Walk".into()));
        assert_eq!(
            settings(&l),
            RenderSettings {
                noise: Some(NoiseTarget {
                    threshold: 0.02,
                    min_samples: 6
                }),
                max_depth: 5,
                seed: 9,
                fixed_pattern: true,
                clamp_indirect: Some(4.0),
                ..RenderSettings::DEFAULT
            }
        );
        assert_eq!(tile_rect(&l), TileRect::new(16, 32, 16, 16));
        assert_eq!(sample_range(&l), SampleRange::new(4, 12));

        let mut l2 = l.clone();
        l2.camera = CameraSpec::Index(1);
        l2.animation = None;
        let o = frame_options(&l2);
        assert_eq!(o.camera, CameraChoice::Index(1));
        assert_eq!(o.animation, AnimationChoice::All);
    }

    #[test]
    fn the_frame_key_ignores_only_what_varies_per_task() {
        let a = lease();
        let mut b = a.clone();
        b.token.task_id = 8;
        b.token.attempt = 1;
        b.tile.x = 0;
        b.samples = SampleSpan { start: 0, end: 4 };
        b.deadline_ms = 5;
        assert_eq!(frame_key(&a), frame_key(&b));
        for change in [
            |l: &mut Lease| l.frame = 13,
            |l: &mut Lease| l.shutter = [0.0, 0.5],
            |l: &mut Lease| l.motion_steps = None,
            |l: &mut Lease| l.scene = "cd".repeat(32),
            |l: &mut Lease| l.width = 65,
            |l: &mut Lease| l.animation = None,
        ] {
            let mut c = a.clone();
            change(&mut c);
            assert_ne!(frame_key(&a), frame_key(&c));
        }
    }
}
