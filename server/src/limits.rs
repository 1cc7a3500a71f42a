//! Every bound the server enforces, in one place. The job-spec bounds are checked in
//! `spec.rs`, each error naming the field; the byte limits are per-route body limits.
//! The bounds of the render itself are the tracer's own ([`tracer::limits`]), so a job
//! the tracer would refuse is refused here, at submission.

pub use tracer::limits::{
    MAX_DEPTH, MAX_FPS, MAX_MOTION_STEPS, MAX_RESOLUTION, MAX_SHUTTER_FRAMES, MAX_SPP,
};

/// Frames per job.
pub const MAX_FRAMES: u64 = 100_000;
/// Largest frame number (file names stay readable; the tracer keys frames by `i32`).
pub const MAX_FRAME_NUMBER: i32 = 9_999_999;
/// Smallest and largest tile side, pixels.
pub const MIN_TILE_SIZE: u32 = 8;
/// Largest tile side: a 1024² tile is 46 MB of f32 channels, under [`MAX_TILE_BYTES`].
pub const MAX_TILE_SIZE: u32 = 1_024;
/// Sample passes per tile.
pub const MAX_SAMPLE_PASSES: u32 = 256;
/// |priority|.
pub const MAX_PRIORITY: i32 = 1_000;
/// Attempts per task.
pub const MAX_ATTEMPTS: u32 = 100;
/// A job's time budget, seconds (30 days).
pub const MAX_TIME_BUDGET_SECONDS: f64 = 30.0 * 24.0 * 3600.0;
/// Length of a job name, bytes.
pub const MAX_NAME_BYTES: usize = 200;
/// Default bound on tasks per job (configurable in [`crate::Config`]).
pub const DEFAULT_MAX_TASKS_PER_JOB: u64 = 1_000_000;
/// Default scene upload limit: 512 MiB.
pub const DEFAULT_MAX_SCENE_BYTES: usize = 512 << 20;
/// Default memory for assembling one frame: 1 GiB. The largest frame accepted (16384
/// wide, 1024-pixel tiles) takes about 200 MiB (`assembly::assembly_bytes`).
pub const DEFAULT_ASSEMBLY_MEMORY: u64 = 1 << 30;
/// Tile upload limit: 64 MiB.
pub const MAX_TILE_BYTES: usize = 64 << 20;
/// JSON request bodies (job specs, heartbeats, registrations): 64 KiB.
pub const MAX_JSON_BYTES: usize = 64 << 10;
/// Worker name and version strings, bytes.
pub const MAX_WORKER_TEXT_BYTES: usize = 200;
/// A worker's measured denoise or encode time per megapixel at registration, ms (an
/// hour: far beyond any real machine, and within the database's signed integers).
pub const MAX_STEP_MS_PER_MEGAPIXEL: u64 = 3_600_000;
/// Failure message kept per report, bytes (longer ones are cut).
pub const MAX_FAILURE_MESSAGE_BYTES: usize = 4_096;
/// A time-budget job's default tile is sized for passes of this many samples (its passes
/// run from min_spp up to spp).
pub const BUDGET_TILE_SPP: u32 = 64;
/// Pixel samples one task should hold by default: a few seconds on a worker (64×64
/// pixels at 256 samples, about 1M camera paths).
pub const TARGET_TASK_PIXEL_SAMPLES: u64 = 1 << 20;
/// Tags one worker offers or one job requires.
pub const MAX_TAGS: usize = 32;
/// Length of one tag, bytes (ASCII letters, digits, `-`, `_` and `.`).
pub const MAX_TAG_BYTES: usize = 64;
/// Tasks one page of `GET /jobs/{id}/tasks` holds at most (and by default).
pub const MAX_TASKS_PER_PAGE: u32 = 1_000;
/// Reasons `GET /jobs/{id}/failures` lists at most: the most frequent.
pub const MAX_FAILURE_GROUPS: usize = 100;
/// Entries the event log keeps; the oldest go past this ([`crate::retention`]).
pub const MAX_EVENTS: u64 = 100_000;
/// A scene no job uses is kept this long after its last upload, so that a client can
/// upload it and then submit the job: one day, in ms.
pub const UNUSED_SCENE_GRACE_MS: i64 = 24 * 3600 * 1000;
/// A worker gone (left, or not seen) this long leaves the worker list; its rows stay for
/// the records of the jobs it worked on: one day, in ms.
pub const GONE_WORKER_LISTED_MS: i64 = 24 * 3600 * 1000;
