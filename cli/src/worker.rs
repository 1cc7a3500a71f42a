//! `tessera worker`: flags into a [`worker::WorkerConfig`], then [`worker::run`] until
//! SIGINT or SIGTERM (the lease in hand is given back to the server before exiting).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

/// Run a worker: lease tiles from a farm server, render them, upload them.
#[derive(Args, Debug)]
pub struct WorkerArgs {
    /// The farm server's URL.
    #[arg(long, default_value = "http://127.0.0.1:8700")]
    pub server: String,
    /// The server's worker token (default: $TESSERA_WORKER_TOKEN, else none).
    #[arg(long)]
    pub token: Option<String>,
    /// Render threads (default: every core).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub threads: Option<u32>,
    /// Folder for downloaded scenes (default: $XDG_CACHE_HOME/tessera/scenes, else
    /// ~/.cache/tessera/scenes, else ./tessera-cache).
    #[arg(long)]
    pub cache: Option<PathBuf>,
    /// A name shown on the dashboard (default: the host name).
    #[arg(long)]
    pub name: Option<String>,
    /// Misbehave on purpose, for the farm's fault tests: `fail-job=JOB`.
    #[arg(long, hide = true)]
    pub inject_fault: Option<worker::Fault>,
}

pub fn run(args: WorkerArgs) -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .init();
    let token = args.token.or_else(|| {
        std::env::var("TESSERA_WORKER_TOKEN")
            .ok()
            .filter(|t| !t.is_empty())
    });
    let threads = match args.threads {
        Some(n) => n as usize,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let config = worker::WorkerConfig {
        server: args.server,
        token,
        threads,
        cache_dir: args.cache.unwrap_or_else(default_cache_dir),
        name: args.name.unwrap_or_else(host_name),
        fault: args.inject_fault,
    };
    tracing::info!(
        "Tessera worker `{}` for {} ({} threads, scenes cached in {})",
        config.name,
        config.server,
        config.threads,
        config.cache_dir.display()
    );
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let summary = runtime.block_on(worker::run(config, crate::signal::interrupted()))?;
    tracing::info!(
        "worker stopped: {} tiles uploaded, {} failed, {} taken back by the server, {} \
         interrupted, {} scenes downloaded",
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
