//! Tessera's worker daemon: register with a farm server, lease tile tasks, fetch each
//! scene once (cached on disk by SHA-256), render with the tracer on a rayon pool while
//! heartbeating, upload the tile as EXR; retry through network trouble, and on shutdown
//! hand every lease back at once.
//!
//! | module | what it holds |
//! |---|---|
//! | [`config`] | [`WorkerConfig`]: server URL, token, threads, cache folder, name, upload compression |
//! | [`api`] | the worker routes as typed calls (one outcome enum per call) and the retry loop |
//! | [`backoff`] | exponential backoff with jitter, and the wait constants |
//! | [`cache`] | scenes on disk as `<digest>.glb`: verified on read, written atomically |
//! | [`identity`] | the credential a registration answered, kept for the next start |
//! | [`render`] | a [`proto::Lease`] into tracer frame options, a tile render, its EXR bytes |
//! | [`finishing`] | the steps after rendering: a frame denoised with Open Image Denoise, a job's MP4 made with FFmpeg, their uploads |
//! | [`task_log`] | the lines logged per task, sent with its heartbeats, failure report or the next lease request |
//! | `stop` | the shutdown signal every wait listens to |
//! | `daemon` | [`run`]: the register / lease / render / upload loop; `daemon/courier.rs` the uploads, `daemon/steps.rs` a denoise or encode lease, `daemon/scenes.rs` a lease's scene and frame, `daemon/pilot.rs` leaving by itself (idle, task count, drain) |
//!
//! A binary (or a test) calls [`run`] with a config and a shutdown future; it returns a
//! [`RunSummary`] when the future completes (or the worker leaves by itself, see
//! [`PilotLimits`]; [`run_draining`] also takes a drain future) and the server has been
//! told.

pub mod api;
pub mod backoff;
pub mod cache;
pub mod config;
mod daemon;
pub mod finishing;
pub mod identity;
pub mod render;
mod stop;
pub mod task_log;

pub use api::{http_client, tls_hint};
pub use config::{platform, Fault, PilotLimits, UploadCompression, WorkerConfig};
pub use daemon::{run, run_draining, Ending, RunSummary};
