//! `tessera scale slurm`: a provisioner that keeps as many worker jobs in a cluster engine
//! as the farm's queue wants. Every `--interval` it reads the farm's demand (the gauge
//! autoscalers read at `/metrics`: queued and leased tasks of unpaused jobs, plus what
//! time-budget jobs could run now), wants one worker per `--tasks-per-worker` tasks of it
//! (at most `--max-workers`), submits worker jobs for what is missing and cancels pending
//! ones beyond it. Workers that run leave by themselves once idle (`--exit-when-idle`), so
//! a running job is never cancelled: its tile would be lost for a lease period.
//!
//! The engine is behind [`Engine`]: Slurm's own commands ([`slurm`]) on a cluster, a fake
//! in the tests of the decisions.

mod slurm;

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, ValueEnum};
use serde::Serialize;

use crate::client::Client;
use crate::settings::{Common, Layers};

/// The most worker jobs one provisioner keeps (Slurm's default `MaxArraySize`, 1001,
/// allows an array this large).
const MAX_WORKERS: u32 = 1000;

/// The cluster engines `tessera scale` starts workers with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum EngineKind {
    /// Slurm, through `sbatch`, `squeue` and `scancel` (they must be on the PATH).
    Slurm,
}

/// Start and stop workers as jobs of a cluster engine, following the farm's queue.
#[derive(Args, Debug, Serialize)]
pub struct ScaleArgs {
    /// The cluster engine.
    #[arg(value_enum)]
    #[serde(skip)]
    pub engine: EngineKind,
    /// The farm server's URL, as the cluster's nodes reach it (the workers get it too).
    #[arg(long, env = "TESSERA_SERVER", default_value = crate::client::DEFAULT_SERVER)]
    pub server: String,
    /// The server's worker token, handed to the worker jobs in their environment (never on
    /// a command line, where other users could read it).
    #[arg(long, env = "TESSERA_WORKER_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// A PEM file of certificate authorities to trust besides the public ones, for an
    /// https:// server; the workers get it too (a path every node sees).
    #[arg(long, env = "TESSERA_CA")]
    pub ca: Option<PathBuf>,
    /// The most worker jobs at once, pending and running (required: here, in
    /// TESSERA_MAX_WORKERS or in the config file).
    #[arg(
        long,
        env = "TESSERA_MAX_WORKERS",
        value_parser = clap::value_parser!(u32).range(1..=MAX_WORKERS as i64)
    )]
    pub max_workers: Option<u32>,
    /// One worker per this many tasks of demand (KEDA's `threshold` in
    /// deploy/kubernetes): a worker renders its tiles one at a time, on every core it has.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    pub tasks_per_worker: u32,
    /// Seconds between two looks at the queue.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..=3600))]
    pub interval: u64,
    /// A worker job leaves after this many seconds without a task (its `--exit-when-idle`).
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u64).range(1..=86_400))]
    pub exit_when_idle: u64,
    /// Cores per worker job (`sbatch --cpus-per-task`); the worker renders on as many
    /// threads.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub cpus: u32,
    /// Memory per worker job (`sbatch --mem`, e.g. `4G`) [default: the partition's].
    #[arg(long)]
    pub mem: Option<String>,
    /// The partition worker jobs run in (`sbatch --partition`) [default: the cluster's].
    #[arg(long)]
    pub partition: Option<String>,
    /// The account worker jobs are charged to (`sbatch --account`).
    #[arg(long)]
    pub account: Option<String>,
    /// Each worker job's time limit (`sbatch --time`, e.g. `4:00:00`) [default: the
    /// partition's].
    #[arg(long)]
    pub time: Option<String>,
    /// Seconds before the time limit at which a worker is asked to drain (SIGUSR1: it
    /// finishes and uploads its tile, takes no other, leaves); 0: not asked, the time
    /// limit's SIGTERM gives the tile back unfinished.
    #[arg(long, default_value_t = 120, value_parser = clap::value_parser!(u32).range(0..=65_535))]
    pub drain_seconds: u32,
    /// More `sbatch` options, one per flag (`--sbatch-arg=--qos=low`).
    #[arg(long, value_name = "OPTION", allow_hyphen_values = true)]
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sbatch_arg: Vec<String>,
    /// The tessera program the worker jobs run: a path every node sees [default: this
    /// program].
    #[arg(long, value_name = "PATH")]
    pub tessera: Option<PathBuf>,
    /// Where worker jobs write their logs (`tessera-worker-JOB_INDEX.log`) [default: the
    /// current folder].
    #[arg(long, value_name = "DIR")]
    pub log_dir: Option<PathBuf>,
    #[command(flatten)]
    #[serde(flatten)]
    pub common: Common,
}

/// A worker job as the engine lists it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WorkerJob {
    /// The engine's id (Slurm: `1234_5` for an array's element).
    pub id: String,
    /// Not started yet: it may be cancelled without losing work.
    pub pending: bool,
}

/// What a provisioner needs of a cluster engine. Every method touches only the jobs this
/// provisioner submitted.
pub trait Engine {
    /// The worker jobs alive (pending or running), oldest first.
    fn jobs(&mut self) -> anyhow::Result<Vec<WorkerJob>>;
    /// Submits `count` worker jobs; returns what the engine calls them.
    fn submit(&mut self, count: u32) -> anyhow::Result<String>;
    /// Cancels these jobs.
    fn cancel(&mut self, ids: &[String]) -> anyhow::Result<()>;
}

/// How many workers a demand wants.
#[derive(Clone, Copy, Debug)]
pub struct Sizing {
    /// One worker per this many tasks.
    pub tasks_per_worker: u32,
    /// Never more than this many jobs.
    pub max_workers: u32,
}

impl Sizing {
    /// Workers wanted for `demand` tasks.
    pub fn wanted(&self, demand: u64) -> u32 {
        let per = u64::from(self.tasks_per_worker);
        demand.div_ceil(per).min(u64::from(self.max_workers)) as u32
    }
}

/// What one look at the queue changed.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Step {
    /// Workers wanted.
    pub wanted: u32,
    /// Jobs running before the changes.
    pub running: u32,
    /// Jobs pending before the changes.
    pub pending: u32,
    /// Jobs submitted.
    pub submitted: u32,
    /// Pending jobs cancelled.
    pub cancelled: Vec<String>,
}

/// One look: brings the engine's worker jobs to what `demand` wants. Only pending jobs are
/// cancelled, the newest first (the oldest start first).
pub fn step(engine: &mut dyn Engine, sizing: Sizing, demand: u64) -> anyhow::Result<Step> {
    let jobs = engine.jobs()?;
    let pending: Vec<&WorkerJob> = jobs.iter().filter(|j| j.pending).collect();
    let mut step = Step {
        wanted: sizing.wanted(demand),
        running: (jobs.len() - pending.len()) as u32,
        pending: pending.len() as u32,
        ..Step::default()
    };
    let alive = jobs.len() as u32;
    if step.wanted > alive {
        step.submitted = step.wanted - alive;
        engine.submit(step.submitted)?;
    } else if step.wanted < alive {
        let surplus = (alive - step.wanted) as usize;
        step.cancelled = pending
            .iter()
            .rev()
            .take(surplus)
            .map(|j| j.id.clone())
            .collect();
        if !step.cancelled.is_empty() {
            engine.cancel(&step.cancelled)?;
        }
    }
    Ok(step)
}

pub fn run(mut args: ScaleArgs, layers: Layers) -> anyhow::Result<()> {
    args.token.take_if(|t| t.is_empty());
    let tessera = match args.tessera.take() {
        Some(path) => path,
        None => std::env::current_exe().context("finding this program's path")?,
    };
    let tessera = std::path::absolute(&tessera).unwrap_or(tessera);
    args.tessera = Some(tessera);
    let log_dir = std::path::absolute(args.log_dir.take().unwrap_or_else(|| ".".into()))
        .context("the log folder")?;
    args.log_dir = Some(log_dir);
    if args.common.print_config {
        print!("{}", layers.to_toml(&args)?);
        return Ok(());
    }
    let Some(max_workers) = args.max_workers else {
        anyhow::bail!(
            "how many worker jobs at most? Give --max-workers N (or TESSERA_MAX_WORKERS, or \
             max_workers in the [scale] table of the --config file)"
        );
    };
    crate::logs::init(args.common.log_format, "info", None);
    let client = Client::with_ca(&args.server, None, args.ca.as_deref())?;
    let mut engine = match args.engine {
        EngineKind::Slurm => slurm::Slurm::new(&args)?,
    };
    let sizing = Sizing {
        tasks_per_worker: args.tasks_per_worker,
        max_workers,
    };
    tracing::info!(
        "scaling workers for {} in Slurm: one per {} tasks, at most {}, {} cores each; a \
         look every {} s",
        client.base(),
        sizing.tasks_per_worker,
        sizing.max_workers,
        args.cpus,
        args.interval
    );
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(watch(&client, &mut engine, sizing, args.interval));
    // Pending jobs would start workers for a farm nobody scales any more; running ones
    // finish their tiles and leave when idle.
    let pending: Vec<String> = engine
        .jobs()?
        .into_iter()
        .filter(|j| j.pending)
        .map(|j| j.id)
        .collect();
    if !pending.is_empty() {
        engine.cancel(&pending)?;
    }
    tracing::info!(
        "provisioner stopped: {} pending worker jobs cancelled; running ones leave when idle",
        pending.len()
    );
    Ok(())
}

/// Looks at the queue every `interval` seconds until SIGINT or SIGTERM. A server or engine
/// that fails to answer is logged and asked again at the next look.
async fn watch(client: &Client, engine: &mut dyn Engine, sizing: Sizing, interval: u64) {
    let stop = crate::signal::interrupted();
    tokio::pin!(stop);
    let mut last = None;
    loop {
        let demand = tokio::select! {
            _ = &mut stop => return,
            demand = client.demand() => demand,
        };
        match demand {
            Ok(demand) => match step(engine, sizing, demand) {
                Ok(step) => {
                    let changed = step.submitted > 0 || !step.cancelled.is_empty();
                    if changed || last != Some((demand, step.wanted)) {
                        tracing::info!("{}", describe(demand, &step));
                    }
                    last = Some((demand, step.wanted));
                }
                Err(e) => tracing::error!("{e:#}"),
            },
            Err(e) => tracing::warn!("reading the farm's demand: {e}"),
        }
        tokio::select! {
            _ = &mut stop => return,
            _ = tokio::time::sleep(Duration::from_secs(interval)) => {}
        }
    }
}

/// One log line for a look at the queue.
fn describe(demand: u64, step: &Step) -> String {
    let mut line = format!(
        "demand {demand} tasks, workers wanted {}, running {}, pending {}",
        step.wanted, step.running, step.pending
    );
    if step.submitted > 0 {
        line += &format!("; submitted {}", step.submitted);
    }
    if !step.cancelled.is_empty() {
        line += &format!("; cancelled {}", step.cancelled.join(" "));
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An engine that starts jobs only when told, and records what it was asked.
    #[derive(Default)]
    struct Fake {
        jobs: Vec<WorkerJob>,
        next: u32,
        submissions: Vec<u32>,
    }

    impl Fake {
        fn start(&mut self, n: usize) {
            for job in self.jobs.iter_mut().filter(|j| j.pending).take(n) {
                job.pending = false;
            }
        }
    }

    impl Engine for Fake {
        fn jobs(&mut self) -> anyhow::Result<Vec<WorkerJob>> {
            Ok(self.jobs.clone())
        }
        fn submit(&mut self, count: u32) -> anyhow::Result<String> {
            for _ in 0..count {
                self.next += 1;
                self.jobs.push(WorkerJob {
                    id: self.next.to_string(),
                    pending: true,
                });
            }
            self.submissions.push(count);
            Ok(format!("{count} jobs"))
        }
        fn cancel(&mut self, ids: &[String]) -> anyhow::Result<()> {
            self.jobs.retain(|j| !ids.contains(&j.id));
            Ok(())
        }
    }

    #[test]
    fn one_worker_per_tasks_per_worker_rounded_up_and_capped() {
        let sizing = Sizing {
            tasks_per_worker: 4,
            max_workers: 5,
        };
        let wanted: Vec<u32> = [0, 1, 4, 5, 8, 9, 20, 21, 1000]
            .iter()
            .map(|&d| sizing.wanted(d))
            .collect();
        assert_eq!(wanted, [0, 1, 1, 2, 2, 3, 5, 5, 5]);
        let huge = Sizing {
            tasks_per_worker: 1,
            max_workers: MAX_WORKERS,
        };
        assert_eq!(huge.wanted(u64::MAX), MAX_WORKERS);
    }

    #[test]
    fn submits_what_is_missing_and_cancels_only_pending_jobs_newest_first() {
        let sizing = Sizing {
            tasks_per_worker: 4,
            max_workers: 3,
        };
        let mut engine = Fake::default();
        // Nothing queued: nothing submitted.
        assert_eq!(step(&mut engine, sizing, 0).unwrap(), Step::default());
        // 10 tasks want 3 workers; the engine starts one of them.
        let s = step(&mut engine, sizing, 10).unwrap();
        assert_eq!((s.wanted, s.submitted), (3, 3));
        engine.start(1);
        // The same demand again: nothing to change while two are pending.
        let s = step(&mut engine, sizing, 10).unwrap();
        assert_eq!((s.running, s.pending, s.submitted), (1, 2, 0));
        assert!(s.cancelled.is_empty());
        // Demand above the cap never goes past it.
        assert_eq!(step(&mut engine, sizing, 500).unwrap().submitted, 0);
        // Demand falls to 4 tasks (1 worker): the two pending go, newest first.
        let s = step(&mut engine, sizing, 4).unwrap();
        assert_eq!(s.cancelled, ["3", "2"]);
        // Demand 0: the running one is left alone (it leaves when idle).
        let s = step(&mut engine, sizing, 0).unwrap();
        assert_eq!((s.running, s.cancelled.len()), (1, 0));
        assert_eq!(engine.jobs.len(), 1);
        // Demand again: two more, beside the running one.
        assert_eq!(step(&mut engine, sizing, 9).unwrap().submitted, 2);
        assert_eq!(engine.submissions, [3, 2]);
    }

    #[test]
    fn settings_come_from_flags_over_the_config_files_scale_table() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("tessera.toml");
        std::fs::write(
            &file,
            "[scale]\nmax_workers = 3\npartition = \"gpu\"\ncpus = 2\n",
        )
        .unwrap();
        let argv = ["tessera", "scale", "slurm", "--cpus", "4", "--config"];
        let (cli, _) = crate::settings::parse_from::<crate::Cli, _, _>(
            argv.iter()
                .map(|a| a.to_string())
                .chain([file.display().to_string()]),
        )
        .unwrap();
        let crate::Command::Scale(args) = cli.command else {
            panic!("parsed as another command")
        };
        assert_eq!(args.engine, EngineKind::Slurm);
        assert_eq!(args.max_workers, Some(3));
        assert_eq!(args.partition.as_deref(), Some("gpu"));
        assert_eq!(args.cpus, 4, "the flag beats the file");
    }

    #[test]
    fn a_look_is_described_in_one_line() {
        let s = Step {
            wanted: 3,
            running: 1,
            pending: 0,
            submitted: 2,
            cancelled: vec![],
        };
        assert_eq!(
            describe(10, &s),
            "demand 10 tasks, workers wanted 3, running 1, pending 0; submitted 2"
        );
    }
}
