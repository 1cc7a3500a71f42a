//! `tessera worker`: settings (flags, `TESSERA_*` variables, `--config` file: see
//! [`crate::settings`]) into a [`worker::WorkerConfig`], then [`worker::run_draining`]
//! until SIGINT or SIGTERM (the lease in hand is given back to the server before
//! exiting), SIGUSR1 (the lease in hand is finished first), or until it leaves by itself
//! (`--exit-when-idle`, `--max-tasks`).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use serde::Serialize;

use crate::settings::{Common, Layers};

/// Run a worker: lease tiles from a farm server, render them, upload them.
#[derive(Args, Debug, Serialize)]
pub struct WorkerArgs {
    /// The farm server's URL.
    #[arg(long, env = "TESSERA_SERVER", default_value = "http://127.0.0.1:8700")]
    pub server: String,
    /// The server's worker token (its --worker-token; default: none).
    #[arg(long, env = "TESSERA_WORKER_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// A PEM file of certificate authorities to trust besides the public ones: the
    /// private CA that signed an https:// server's certificate.
    #[arg(long, env = "TESSERA_CA")]
    pub ca: Option<PathBuf>,
    /// Render threads (default: every core).
    #[arg(long, env = "TESSERA_THREADS", value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub threads: Option<u32>,
    /// Folder for downloaded scenes (default: $XDG_CACHE_HOME/tessera/scenes, else
    /// ~/.cache/tessera/scenes, else ./tessera-cache).
    #[arg(long, env = "TESSERA_CACHE")]
    pub cache: Option<PathBuf>,
    /// Most megabytes of scenes the cache folder keeps; the least recently used go first
    /// (the scene in use always stays).
    #[arg(
        long,
        env = "TESSERA_CACHE_LIMIT_MB",
        default_value_t = 10_240,
        value_parser = clap::value_parser!(u64).range(1..=1 << 40)
    )]
    pub cache_limit_mb: u64,
    /// A name shown on the dashboard (default: the host name).
    #[arg(long, env = "TESSERA_NAME")]
    pub name: Option<String>,
    /// What this machine offers, comma-separated (`gpu,studio-a`): it takes only jobs
    /// whose every `--require-tags` tag it has.
    #[arg(long, env = "TESSERA_TAGS", value_delimiter = ',')]
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub tags: Vec<String>,
    /// How tiles are compressed for upload: `zip` (a third of the bytes, about 25 ms of
    /// CPU per 128x128 tile), `none`, or `auto`: none for a server on this machine, zip
    /// for any other.
    #[arg(long, env = "TESSERA_UPLOAD_COMPRESSION", default_value = "auto")]
    pub upload_compression: worker::UploadCompression,
    /// Take no denoise tasks, even where Open Image Denoise is installed (it renders tiles
    /// only).
    #[arg(long, env = "TESSERA_NO_DENOISE")]
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub no_denoise: bool,
    /// Where Open Image Denoise is installed (default: where `tessera install oidn` puts
    /// it, then the system's library path). A worker that finds it takes denoise tasks.
    #[arg(long, env = "TESSERA_OIDN", value_name = "DIR")]
    pub oidn: Option<PathBuf>,
    /// Take no encode tasks, even where FFmpeg is installed.
    #[arg(long, env = "TESSERA_NO_ENCODE")]
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub no_encode: bool,
    /// The FFmpeg program, or the folder it is installed in (default: where `tessera
    /// install ffmpeg` puts it, then `ffmpeg` on the PATH). A worker that finds one with
    /// libx264 takes encode tasks (a job's MP4).
    #[arg(long, env = "TESSERA_FFMPEG", value_name = "PATH")]
    pub ffmpeg: Option<PathBuf>,
    /// Leave the farm after this many seconds without a task: for a worker started as a
    /// cluster job (Slurm, a Kubernetes Job), so that the job ends when the farm has no
    /// more work for it [default: never].
    #[arg(long, env = "TESSERA_EXIT_WHEN_IDLE", value_name = "SECONDS")]
    pub exit_when_idle: Option<u64>,
    /// Leave the farm after working on this many tasks [default: no limit].
    #[arg(long, env = "TESSERA_MAX_TASKS", value_parser = clap::value_parser!(u64).range(1..))]
    pub max_tasks: Option<u64>,
    /// Misbehave on purpose, for the farm's fault tests: `fail-job=JOB` or `perturb`.
    #[arg(long, hide = true)]
    #[serde(skip)]
    pub inject_fault: Option<worker::Fault>,
    #[command(flatten)]
    #[serde(flatten)]
    pub common: Common,
}

pub fn run(mut args: WorkerArgs, layers: Layers) -> anyhow::Result<()> {
    // The defaults worked out here, so that --print-config shows what the worker will use.
    args.token.take_if(|t| t.is_empty());
    let threads = *args.threads.get_or_insert_with(|| {
        std::thread::available_parallelism().map_or(1, |n| n.get().min(4096) as u32)
    });
    let cache = args.cache.get_or_insert_with(default_cache_dir).clone();
    let name = args.name.get_or_insert_with(host_name).clone();
    if args.common.print_config {
        print!("{}", layers.to_toml(&args)?);
        return Ok(());
    }
    crate::logs::init(
        args.common.log_format,
        "info",
        Some(worker::task_log::layer()),
    );
    let config = worker::WorkerConfig {
        server: args.server,
        token: args.token,
        ca: args.ca,
        threads: threads as usize,
        cache_dir: cache,
        cache_limit_bytes: args.cache_limit_mb << 20,
        name,
        tags: args.tags,
        upload_compression: args.upload_compression,
        denoise: !args.no_denoise,
        oidn: args.oidn,
        encode: !args.no_encode,
        ffmpeg: args.ffmpeg,
        fault: args.inject_fault,
        pilot: worker::PilotLimits {
            exit_when_idle: args.exit_when_idle.map(std::time::Duration::from_secs),
            max_tasks: args.max_tasks,
        },
    };
    tracing::info!(
        "Tessera worker `{}` for {} ({} threads, scenes cached in {}, at most {} MB)",
        config.name,
        config.server,
        config.threads,
        config.cache_dir.display(),
        config.cache_limit_bytes >> 20
    );
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let limits = config.pilot;
    let summary = runtime.block_on(worker::run_draining(
        config,
        crate::signal::interrupted(),
        crate::signal::drain_asked(),
    ))?;
    tracing::info!(
        "worker stopped ({}): {} tiles uploaded, {} failed, {} taken back by the server, {} \
         interrupted, {} scenes downloaded",
        summary.ended.describe(&limits),
        summary.tasks_done,
        summary.tasks_failed,
        summary.tasks_abandoned,
        summary.tasks_interrupted,
        summary.scenes_downloaded
    );
    // A render thread may still be finishing its last pixel; do not wait for it.
    runtime.shutdown_background();
    Ok(())
}

/// `$XDG_CACHE_HOME/tessera/scenes`, `~/.cache/tessera/scenes` (Windows:
/// `%LOCALAPPDATA%\tessera\scenes`), or `./tessera-cache` when none is set.
fn default_cache_dir() -> PathBuf {
    let env = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    env("XDG_CACHE_HOME")
        .or_else(|| env("HOME").map(|h| h.join(".cache")))
        .or_else(|| env("LOCALAPPDATA"))
        .map(|base| base.join("tessera").join("scenes"))
        .unwrap_or_else(|| PathBuf::from("tessera-cache"))
}

/// The machine's name, without a dependency: the kernel's on Linux, else the usual
/// environment variables, else `worker`.
fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .or_else(|| std::env::var("COMPUTERNAME").ok())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "worker".into())
}
