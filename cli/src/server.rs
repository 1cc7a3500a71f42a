//! `tessera server`: flags into a [`server::Config`], then [`server::serve`] until SIGINT or SIGTERM.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use clap::Args;

/// Run the farm server: REST API, scheduler, tile assembly, dashboard.
#[derive(Args, Debug)]
pub struct ServerArgs {
    /// Address to listen on. Loopback by default; listen wider only with tokens set.
    #[arg(long, default_value = "127.0.0.1:8700")]
    pub listen: SocketAddr,
    /// Folder for the database, scenes, tiles and frames (created when missing).
    #[arg(long, default_value = "./tessera-data")]
    pub data: PathBuf,
    /// Bearer token workers must present (default: worker routes are open).
    #[arg(long)]
    pub worker_token: Option<String>,
    /// Bearer token clients must present (default: client routes are open).
    #[arg(long)]
    pub client_token: Option<String>,
    /// Seconds a lease lasts without a heartbeat.
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u64).range(5..=86_400))]
    pub lease_seconds: u64,
    /// Most tasks (frames × tiles × sample passes) one job may have.
    #[arg(long, default_value_t = server::limits::DEFAULT_MAX_TASKS_PER_JOB)]
    pub max_tasks_per_job: u64,
}

pub fn run(args: ServerArgs) -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "info,tower_http=warn".into()),
        )
        .init();
    let mut config = server::Config::new(&args.data);
    config.listen = args.listen;
    config.worker_token = args.worker_token;
    config.client_token = args.client_token;
    config.lease = Duration::from_secs(args.lease_seconds);
    config.max_tasks_per_job = args.max_tasks_per_job;
    if !args.listen.ip().is_loopback()
        && (config.worker_token.is_none() || config.client_token.is_none())
    {
        tracing::warn!(
            "listening on {} without both --worker-token and --client-token: anyone who can \
             reach this address can use the open routes",
            args.listen
        );
    }
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(config.listen)
            .await
            .with_context(|| format!("listening on {}", config.listen))?;
        tracing::info!(
            "Tessera farm on http://{} (data in {})",
            listener.local_addr()?,
            config.data_dir.display()
        );
        server::serve(listener, config, crate::signal::interrupted()).await?;
        anyhow::Ok(())
    })
}
