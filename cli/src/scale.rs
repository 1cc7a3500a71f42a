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

use std::collections::HashSet;
use std::path::PathBuf;
use std::time::{Duration, Instant};

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

/// Where a worker job stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JobState {
    /// Not started yet: it may be cancelled without losing work.
    Pending,
    /// Its worker runs (or is starting).
    Running,
    /// Ended with its worker's success: it left when idle, drained, or was done.
    Succeeded,
    /// Ended with a failure of its own (the worker could not start, or stopped on an
    /// error): not a time limit, a preemption or a cancellation, which stop healthy
    /// workers too.
    Failed,
}

/// A worker job as the engine lists it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WorkerJob {
    /// The engine's id (Slurm: `1234_5` for an array's element).
    pub id: String,
    pub state: JobState,
}

/// What a provisioner needs of a cluster engine. Every method touches only the jobs this
/// provisioner submitted.
pub trait Engine {
    /// The worker jobs alive (pending or running) and those that ended recently (as long
    /// as the engine remembers them), oldest first.
    fn jobs(&mut self) -> anyhow::Result<Vec<WorkerJob>>;
    /// Submits `count` worker jobs; returns what the engine calls them.
    fn submit(&mut self, count: u32) -> anyhow::Result<String>;
    /// Cancels these jobs.
    fn cancel(&mut self, ids: &[String]) -> anyhow::Result<()>;
    /// Where job `id` logs, to point a person at it.
    fn log_of(&self, id: &str) -> String;
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

/// Worker jobs that fail one after another, with no success between them, before the
/// provisioner holds its submissions: a worker that cannot start (no `tessera` on the
/// nodes, a wrong token) would otherwise be submitted again at every look.
const FAILURES_BEFORE_HOLD: u32 = 3;
/// The first hold; each further failure doubles it, up to [`LONGEST_HOLD`].
const FIRST_HOLD: Duration = Duration::from_secs(60);
const LONGEST_HOLD: Duration = Duration::from_secs(15 * 60);

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
    /// Jobs seen failed at this look.
    pub failed: Vec<String>,
    /// Submissions are held until this long from now, after failures in a row.
    pub held: Option<Duration>,
}

/// The provisioner's decisions, look after look.
pub struct Provisioner {
    sizing: Sizing,
    /// Ended jobs already counted.
    seen_ended: HashSet<String>,
    /// Failed jobs since the last one that succeeded.
    failures_in_a_row: u32,
    /// No submission before this.
    hold_until: Option<Instant>,
}

impl Provisioner {
    pub fn new(sizing: Sizing) -> Provisioner {
        Provisioner {
            sizing,
            seen_ended: HashSet::new(),
            failures_in_a_row: 0,
            hold_until: None,
        }
    }

    /// One look at `now`: brings the engine's worker jobs to what `demand` wants. Only
    /// pending jobs are cancelled, the newest first (the oldest start first). After
    /// [`FAILURES_BEFORE_HOLD`] failed jobs in a row nothing is submitted for a while.
    pub fn step(
        &mut self,
        engine: &mut dyn Engine,
        demand: u64,
        now: Instant,
    ) -> anyhow::Result<Step> {
        let jobs = engine.jobs()?;
        let mut step = Step {
            wanted: self.sizing.wanted(demand),
            ..Step::default()
        };
        for job in &jobs {
            match job.state {
                JobState::Pending => step.pending += 1,
                JobState::Running => step.running += 1,
                JobState::Succeeded | JobState::Failed => {
                    if !self.seen_ended.insert(job.id.clone()) {
                        continue;
                    }
                    if job.state == JobState::Succeeded {
                        self.failures_in_a_row = 0;
                        self.hold_until = None;
                    } else {
                        self.failures_in_a_row += 1;
                        step.failed.push(job.id.clone());
                    }
                }
            }
        }
        // Forget what the engine forgot.
        self.seen_ended
            .retain(|id| jobs.iter().any(|j| &j.id == id));
        if !step.failed.is_empty() && self.failures_in_a_row >= FAILURES_BEFORE_HOLD {
            let doublings = (self.failures_in_a_row - FAILURES_BEFORE_HOLD).min(10);
            let hold = (FIRST_HOLD * (1 << doublings)).min(LONGEST_HOLD);
            self.hold_until = Some(now + hold);
        }
        step.held = self
            .hold_until
            .and_then(|until| until.checked_duration_since(now))
            .filter(|left| !left.is_zero());

        let alive = step.pending + step.running;
        if step.wanted > alive && step.held.is_none() {
            step.submitted = step.wanted - alive;
            engine.submit(step.submitted)?;
        } else if step.wanted < alive {
            let surplus = (alive - step.wanted) as usize;
            step.cancelled = jobs
                .iter()
                .rev()
                .filter(|j| j.state == JobState::Pending)
                .take(surplus)
                .map(|j| j.id.clone())
                .collect();
            if !step.cancelled.is_empty() {
                engine.cancel(&step.cancelled)?;
            }
        }
        Ok(step)
    }
}

pub fn run(mut args: ScaleArgs, layers: Layers) -> anyhow::Result<()> {
    args.token.take_if(|t| t.is_empty());
    let tessera = match args.tessera.take() {
        Some(path) => path,
        None => std::env::current_exe().context("finding this program's path")?,
    };
    let tessera = std::path::absolute(&tessera).unwrap_or(tessera);
    let log_dir = std::path::absolute(args.log_dir.take().unwrap_or_else(|| ".".into()))
        .context("the log folder")?;
    // Shown as they will be used by --print-config.
    args.tessera = Some(tessera.clone());
    args.log_dir = Some(log_dir.clone());
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
        EngineKind::Slurm => slurm::Slurm::new(&args, &tessera, &log_dir)?,
    };
    let sizing = Sizing {
        tasks_per_worker: args.tasks_per_worker,
        max_workers,
    };
    tracing::info!(
        "scaling workers for {} in Slurm: one per {} tasks, at most {}, with --cpus {}; a \
         look every {} s",
        client.base(),
        sizing.tasks_per_worker,
        sizing.max_workers,
        args.cpus,
        args.interval
    );
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(watch(
        &client,
        &mut engine,
        Provisioner::new(sizing),
        args.interval,
    ));
    // Pending jobs would start workers for a farm nobody scales any more; running ones
    // finish their tiles and leave when idle.
    let pending: Vec<String> = engine
        .jobs()?
        .into_iter()
        .filter(|j| j.state == JobState::Pending)
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
async fn watch(
    client: &Client,
    engine: &mut dyn Engine,
    mut provisioner: Provisioner,
    interval: u64,
) {
    let stop = crate::signal::interrupted();
    tokio::pin!(stop);
    let mut last = None;
    loop {
        let demand = tokio::select! {
            _ = &mut stop => return,
            demand = client.demand() => demand,
        };
        match demand {
            Ok(demand) => match provisioner.step(engine, demand, Instant::now()) {
                Ok(step) => {
                    for id in &step.failed {
                        tracing::warn!("worker job {id} failed; its log: {}", engine.log_of(id));
                    }
                    let changed = step.submitted > 0 || !step.cancelled.is_empty();
                    let state = (demand, step.wanted, step.held.is_some());
                    if changed || !step.failed.is_empty() || last != Some(state) {
                        tracing::info!("{}", describe(demand, &step));
                    }
                    last = Some(state);
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
    if let Some(held) = step.held {
        line += &format!(
            "; worker jobs keep failing (see their logs): none submitted for {} s",
            held.as_secs()
        );
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
        /// The first `n` pending jobs start.
        fn start(&mut self, n: usize) {
            self.set(JobState::Pending, JobState::Running, n);
        }

        /// The first `n` jobs in state `from` go to `to`.
        fn set(&mut self, from: JobState, to: JobState, n: usize) {
            for job in self.jobs.iter_mut().filter(|j| j.state == from).take(n) {
                job.state = to;
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
                    state: JobState::Pending,
                });
            }
            self.submissions.push(count);
            Ok(format!("{count} jobs"))
        }
        fn cancel(&mut self, ids: &[String]) -> anyhow::Result<()> {
            self.jobs.retain(|j| !ids.contains(&j.id));
            Ok(())
        }
        fn log_of(&self, id: &str) -> String {
            format!("log-{id}")
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
        let mut p = Provisioner::new(Sizing {
            tasks_per_worker: 4,
            max_workers: 3,
        });
        let now = Instant::now();
        let mut engine = Fake::default();
        let mut step = |engine: &mut Fake, demand| p.step(engine, demand, now).unwrap();
        // Nothing queued: nothing submitted.
        assert_eq!(step(&mut engine, 0), Step::default());
        // 10 tasks want 3 workers; the engine starts one of them.
        let s = step(&mut engine, 10);
        assert_eq!((s.wanted, s.submitted), (3, 3));
        engine.start(1);
        // The same demand again: nothing to change while two are pending.
        let s = step(&mut engine, 10);
        assert_eq!((s.running, s.pending, s.submitted), (1, 2, 0));
        assert!(s.cancelled.is_empty());
        // Demand above the cap never goes past it.
        assert_eq!(step(&mut engine, 500).submitted, 0);
        // Demand falls to 4 tasks (1 worker): the two pending go, newest first.
        let s = step(&mut engine, 4);
        assert_eq!(s.cancelled, ["3", "2"]);
        // Demand 0: the running one is left alone (it leaves when idle).
        let s = step(&mut engine, 0);
        assert_eq!((s.running, s.cancelled.len()), (1, 0));
        assert_eq!(engine.jobs.len(), 1);
        // It leaves; demand again: two more. Ended jobs do not count as alive.
        engine.set(JobState::Running, JobState::Succeeded, 1);
        assert_eq!(step(&mut engine, 9).submitted, 3);
        assert_eq!(engine.submissions, [3, 3]);
    }

    #[test]
    fn jobs_that_keep_failing_hold_the_submissions_longer_each_time() {
        let mut p = Provisioner::new(Sizing {
            tasks_per_worker: 1,
            max_workers: 2,
        });
        let start = Instant::now();
        let mut engine = Fake::default();
        // Two jobs fail, then one more: three in a row.
        assert_eq!(p.step(&mut engine, 5, start).unwrap().submitted, 2);
        engine.set(JobState::Pending, JobState::Failed, 2);
        let s = p.step(&mut engine, 5, start).unwrap();
        assert_eq!((s.failed.len(), s.held, s.submitted), (2, None, 2));
        engine.set(JobState::Pending, JobState::Failed, 1);
        let s = p.step(&mut engine, 5, start).unwrap();
        assert_eq!((s.failed.len(), s.held), (1, Some(FIRST_HOLD)));
        assert_eq!(s.submitted, 0, "held: one job is still pending, none added");
        // Seen failures are not counted again; the hold runs out.
        let later = start + FIRST_HOLD / 2;
        let s = p.step(&mut engine, 5, later).unwrap();
        assert_eq!((s.failed.len(), s.held), (0, Some(FIRST_HOLD / 2)));
        let s = p.step(&mut engine, 5, start + FIRST_HOLD).unwrap();
        assert_eq!((s.held, s.submitted), (None, 1));
        // The next failure doubles the hold; a success ends it.
        engine.set(JobState::Pending, JobState::Failed, 1);
        let at = start + FIRST_HOLD;
        assert_eq!(
            p.step(&mut engine, 5, at).unwrap().held,
            Some(2 * FIRST_HOLD)
        );
        engine.set(JobState::Pending, JobState::Succeeded, 1);
        let s = p.step(&mut engine, 5, at).unwrap();
        assert_eq!((s.held, s.submitted), (None, 2));
        // The engine forgets ended jobs; so does the provisioner.
        engine.jobs.retain(|j| j.state == JobState::Pending);
        p.step(&mut engine, 5, at).unwrap();
        assert!(p.seen_ended.is_empty());
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
            failed: vec![],
            held: None,
        };
        assert_eq!(
            describe(10, &s),
            "demand 10 tasks, workers wanted 3, running 1, pending 0; submitted 2"
        );
    }
}
