//! `tessera server`: settings (flags, `TESSERA_*` variables, `--config` file: see
//! [`crate::settings`]) into a [`server::Config`], then [`server::serve`] until SIGINT or
//! SIGTERM.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use serde::Serialize;

use crate::settings::{Common, Layers};

/// Run the farm server: REST API, scheduler, tile assembly, dashboard.
#[derive(Args, Debug, Serialize)]
pub struct ServerArgs {
    /// Address to listen on. Loopback by default; listen wider only with tokens set.
    #[arg(long, env = "TESSERA_LISTEN", default_value = "127.0.0.1:8700")]
    pub listen: SocketAddr,
    /// Folder for the database, scenes, tiles and frames (created when missing).
    #[arg(long, env = "TESSERA_DATA", default_value = "./tessera-data")]
    pub data: PathBuf,
    /// Bearer token workers must present (default: worker routes are open).
    #[arg(long, env = "TESSERA_WORKER_TOKEN", hide_env_values = true)]
    pub worker_token: Option<String>,
    /// Bearer token clients must present (default: client routes are open).
    #[arg(long, env = "TESSERA_CLIENT_TOKEN", hide_env_values = true)]
    pub client_token: Option<String>,
    /// Serve HTTPS with this PEM certificate chain (leaf first; with --tls-key). Clients
    /// and workers then use https:// URLs, and --ca for a private CA's certificate.
    #[arg(long, env = "TESSERA_TLS_CERT", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The PEM private key of --tls-cert.
    #[arg(long, env = "TESSERA_TLS_KEY", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// Listen beyond loopback without both tokens. Refused by default: anyone who can reach
    /// the address could use the open routes.
    #[arg(long, env = "TESSERA_INSECURE_NO_AUTH", default_value_t = false,
          action = clap::ArgAction::Set, num_args = 0..=1, default_missing_value = "true")]
    pub insecure_no_auth: bool,
    /// Seconds a lease lasts without a heartbeat.
    #[arg(long, env = "TESSERA_LEASE_SECONDS", default_value_t = 60,
          value_parser = clap::value_parser!(u64).range(5..=86_400))]
    pub lease_seconds: u64,
    /// The fraction of tiles rendered again on a second worker and compared bit for bit
    /// (0 = none, 1 = all); a worker whose tiles are proven wrong is quarantined.
    #[arg(long, env = "TESSERA_VERIFY_FRACTION", default_value_t = 0.0,
          value_parser = parse_fraction)]
    pub verify_fraction: f64,
    /// Most tasks (frames × tiles × sample passes) one job may have.
    #[arg(long, env = "TESSERA_MAX_TASKS_PER_JOB",
          default_value_t = server::limits::DEFAULT_MAX_TASKS_PER_JOB)]
    pub max_tasks_per_job: u64,
    /// Largest tile upload a worker may send, bytes (a bigger one is refused with 413).
    // At most i64::MAX, so that --print-config can write it as a TOML integer.
    #[arg(long, env = "TESSERA_MAX_TILE_BYTES",
          default_value_t = server::limits::MAX_TILE_BYTES as u64,
          value_parser = clap::value_parser!(u64).range(1..=(i64::MAX as u64).min(usize::MAX as u64)))]
    pub max_tile_bytes: u64,
    /// Memory one frame's assembly may take, MiB: frames are assembled a band of rows at
    /// a time, and a job whose frames need more than this (very wide frames in big tiles)
    /// is refused when it is submitted.
    #[arg(long, env = "TESSERA_ASSEMBLY_MEMORY", value_name = "MIB",
          default_value_t = server::limits::DEFAULT_ASSEMBLY_MEMORY >> 20,
          value_parser = clap::value_parser!(u64).range(1..=(1 << 40)))]
    pub assembly_memory: u64,
    /// Which finished jobs (done, failed, cancelled) to keep: `all`, the newest N (`50`),
    /// or those finished within an age (`30d`, `12h`); the others are removed with their
    /// frames every 10 minutes, as `tessera gc` does. Jobs with work left are never
    /// removed.
    #[arg(long, env = "TESSERA_KEEP_JOBS", default_value = "all", value_name = "RULE",
          value_parser = parse_keep_jobs)]
    pub keep_jobs: String,
    /// A URL told (POST, JSON, signed) when any job ends (done, failed, its time budget
    /// reached) or a worker is quarantined; repeat it, or separate URLs with commas.
    #[arg(
        long,
        env = "TESSERA_WEBHOOK",
        value_delimiter = ',',
        value_name = "URL"
    )]
    pub webhook: Vec<String>,
    /// The key every webhook delivery is signed with: the `x-tessera-signature` header is
    /// `sha256=` and the hex HMAC-SHA256 of the body. Needed for --webhook and for jobs'
    /// own webhooks.
    #[arg(long, env = "TESSERA_WEBHOOK_SECRET", hide_env_values = true)]
    pub webhook_secret: Option<String>,
    #[command(flatten)]
    #[serde(flatten)]
    pub common: Common,
}

/// A rule for `--keep-jobs`, checked (kept as written, for --print-config).
fn parse_keep_jobs(s: &str) -> Result<String, String> {
    s.parse::<server::retention::KeepJobs>()?;
    Ok(s.to_string())
}

/// A fraction from 0 to 1.
fn parse_fraction(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(f) if (0.0..=1.0).contains(&f) => Ok(f),
        _ => Err(format!("`{s}` is not a fraction from 0 to 1")),
    }
}

pub fn run(mut args: ServerArgs, layers: Layers) -> anyhow::Result<()> {
    // An empty token is no token (an empty bearer token could never be presented).
    for token in [
        &mut args.worker_token,
        &mut args.client_token,
        &mut args.webhook_secret,
    ] {
        token.take_if(|t| t.is_empty());
    }
    if args.common.print_config {
        print!("{}", layers.to_toml(&args)?);
        return Ok(());
    }
    crate::logs::init(args.common.log_format, "info,tower_http=warn", None);
    let mut config = server::Config::new(&args.data);
    config.listen = args.listen;
    config.worker_token = args.worker_token;
    config.client_token = args.client_token;
    config.insecure_no_auth = args.insecure_no_auth;
    config.tls = match (args.tls_cert, args.tls_key) {
        (Some(cert), Some(key)) => Some(server::tls::TlsFiles { cert, key }),
        _ => None,
    };
    config.lease = Duration::from_secs(args.lease_seconds);
    config.max_tasks_per_job = args.max_tasks_per_job;
    config.verify_fraction = args.verify_fraction;
    config.max_tile_bytes = args.max_tile_bytes as usize;
    config.assembly_memory = args.assembly_memory << 20;
    config.keep_jobs = args.keep_jobs.parse().map_err(anyhow::Error::msg)?;
    for url in &args.webhook {
        server::webhooks::check_url("--webhook", url)?;
    }
    if !args.webhook.is_empty() && args.webhook_secret.is_none() {
        anyhow::bail!(
            "--webhook needs --webhook-secret (TESSERA_WEBHOOK_SECRET): deliveries are signed \
             with it so that receivers can tell them from forgeries"
        );
    }
    config.webhooks = args.webhook;
    config.webhook_secret = args.webhook_secret;
    // Refused before binding, so the message comes first; `serve` checks again.
    config
        .check_exposure(config.listen)
        .map_err(anyhow::Error::msg)?;
    if config.insecure_no_auth && !config.listen.ip().is_loopback() {
        tracing::warn!(
            "listening on {} with --insecure-no-auth: the routes without a token are open \
             to anyone who can reach it",
            config.listen
        );
    }
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(config.listen)
            .await
            .with_context(|| format!("listening on {}", config.listen))?;
        tracing::info!(
            "Tessera farm on {}://{} (data in {})",
            if config.tls.is_some() {
                "https"
            } else {
                "http"
            },
            listener.local_addr()?,
            config.data_dir.display()
        );
        server::serve(listener, config, crate::signal::interrupted()).await?;
        anyhow::Ok(())
    })
}
