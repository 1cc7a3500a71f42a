//! `tessera scale slurm` against a real Slurm: a one-node cluster on this machine
//! (slurm/cluster.rs), a `tessera server`, and the provisioner between them. Slurm starts
//! the workers the queue wants; their frames equal a direct render bit for bit; a worker
//! job cancelled mid-tile (`scancel` sends what a time limit or a preemption sends:
//! SIGTERM, then SIGKILL) loses nothing; pending jobs go when the queue empties; the
//! workers leave when idle; deploy/slurm/tessera-workers.sbatch works by hand; worker
//! jobs that keep failing stop the submissions.
//!
//! Needs Slurm and MUNGE (`scripts/install-slurm.sh`, which `scripts/test.sh` runs) and
//! root; without them the test says loudly that it is skipped.

#[path = "slurm/cluster.rs"]
mod cluster;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use cluster::Cluster;
use proto::JobState;
use tests::{render_directly, settings, tessera_bin, wait_until, Farm, Process, FRAMES};

/// How long a worker job waits without a task before it leaves.
const EXIT_WHEN_IDLE: &str = "3";

#[test]
fn slurm_runs_the_workers_the_queue_wants_and_they_leave_when_idle() {
    if let Some(why) = Cluster::unavailable() {
        eprintln!("\n=== SKIPPED: the Slurm test needs a one-node cluster here: {why} ===\n");
        return;
    }
    let mut farm = Farm::new();
    farm.start_server(60);
    let cluster = Cluster::start(&farm);
    let scene = farm.demo_scene();
    // Worker jobs of every core of the node: one runs, a second one pends.
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let cores = cores.to_string();
    let flags = ["--cpus", &cores, "--time", "10"];
    let mut provisioner = start_provisioner(&farm, &cluster, &flags);
    std::thread::sleep(Duration::from_secs(2));
    assert!(
        our_jobs(&cluster).is_empty(),
        "nothing queued, yet: {:?}",
        cluster.jobs()
    );

    // A job of 16 tiles: Slurm starts a worker, the frames equal a direct render.
    let started = Instant::now();
    let mut args = vec![scene.to_str().unwrap(), "--frames", FRAMES, "--tile", "16"];
    args.extend(["--passes", "1"]);
    args.extend(settings("4"));
    let job = farm.submit(&args);
    let latency = first_lease(&farm, job, started);
    eprintln!("provisioner: the first tile was leased {latency:.1} s after the job's submission");
    let st = farm.wait_for_job(job, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    for frame in 1..=4 {
        let direct = render_directly(&scene, frame, "4", farm.path());
        assert!(
            farm.server_frame(job, frame) == direct,
            "frame {frame}: Slurm's workers rendered it other than `tessera render`"
        );
    }
    // The second worker job could not start beside the first (2 cores each): once the
    // queue emptied, the provisioner cancelled it.
    wait_until(
        "the provisioner to cancel the pending worker job",
        Duration::from_secs(30),
        || provisioner.log().contains("cancelled"),
        || farm.logs(),
    );

    // One long tile; its worker job cancelled mid-tile: the tile goes back, a new worker
    // job renders it, the frame equals a direct render.
    let mut args = vec![scene.to_str().unwrap(), "--frames", "2", "--tile", "32"];
    args.extend(["--passes", "1"]);
    args.extend(settings("8192"));
    let job = farm.submit(&args);
    first_lease(&farm, job, Instant::now());
    std::thread::sleep(Duration::from_secs(2));
    let running = our_jobs(&cluster);
    let [killed] = &running[..] else {
        panic!("one worker job runs the tile: {running:?}")
    };
    let killed = killed.split_whitespace().next().unwrap().to_string();
    assert!(cluster
        .command("scancel")
        .arg(&killed)
        .status()
        .unwrap()
        .success());
    let st = farm.wait_for_job(job, Duration::from_secs(300));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    assert_eq!(
        st.attempts_failed, 0,
        "a worker that was stopped failed nothing"
    );
    let direct = render_directly(&scene, 2, "8192", farm.path());
    assert!(
        farm.server_frame(job, 2) == direct,
        "the frame whose worker was cancelled differs from `tessera render`"
    );
    let log = worker_log(&farm, &killed);
    assert_eq!(
        interrupted_tiles(&log),
        1,
        "the cancelled worker gave its tile back:\n{log}"
    );

    // The queue is empty: the workers leave within their idle time, and the farm lists
    // each of them as gone, not failed.
    wait_until(
        "the worker jobs to end",
        Duration::from_secs(60),
        || our_jobs(&cluster).is_empty(),
        || farm.logs(),
    );
    let workers = farm.worker_list().workers;
    assert!(workers.len() >= 2, "{workers:?}");
    for w in &workers {
        assert!(w.name.starts_with("slurm-"), "{w:?}");
        assert!(!w.online, "worker {} left: {w:?}", w.name);
    }
    assert!(provisioner.terminate(Duration::from_secs(30)).success());
    assert!(provisioner.log().contains("provisioner stopped"));

    // deploy/slurm/tessera-workers.sbatch, submitted by hand as its comment says (the
    // node's cores instead of its eight), renders a job and leaves when idle.
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-2", "--tile", "16"];
    args.extend(["--passes", "1"]);
    args.extend(settings("4"));
    let job = farm.submit(&args);
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/slurm/tessera-workers.sbatch");
    let output = farm.path().join("slurm-jobs").join("by-hand-%A_%a.log");
    let submitted = cluster
        .command("sbatch")
        .args(["--array=1-1", &format!("--cpus-per-task={cores}")])
        .arg(format!("--output={}", output.display()))
        .arg(&script)
        .env("TESSERA_SERVER", farm.url())
        .env("TESSERA", tessera_bin())
        .env("TESSERA_EXIT_WHEN_IDLE", EXIT_WHEN_IDLE)
        .env("TESSERA_CACHE", farm.path().join("cache-slurm"))
        .output()
        .unwrap();
    assert!(submitted.status.success(), "{submitted:?}");
    let st = farm.wait_for_job(job, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    for frame in 1..=2 {
        let direct = render_directly(&scene, frame, "4", farm.path());
        assert!(farm.server_frame(job, frame) == direct, "frame {frame}");
    }
    wait_until(
        "the worker submitted by hand to leave",
        Duration::from_secs(60),
        || cluster.jobs().is_empty(),
        || farm.logs(),
    );

    // Worker jobs that cannot start their worker (no program at that path on the node)
    // fail one after another: after three in a row the provisioner submits no more for a
    // minute, and says where their logs are.
    let job = farm.submit(&args);
    let flags = ["--max-workers", "1", "--tessera", "/no/such/tessera"];
    let mut broken = start_provisioner(&farm, &cluster, &flags);
    wait_until(
        "the provisioner to hold its submissions",
        Duration::from_secs(60),
        || broken.log().contains("none submitted for 60 s"),
        || farm.logs(),
    );
    std::thread::sleep(Duration::from_secs(3));
    let log = broken.log();
    assert_eq!(log.matches("; submitted 1").count(), 3, "{log}");
    assert_eq!(log.matches("failed; its log: ").count(), 3, "{log}");
    assert!(log.contains("slurm-jobs/tessera-worker-"), "{log}");
    assert!(broken.terminate(Duration::from_secs(30)).success());
    farm.client(&["cancel", &job.to_string()]);
}

/// BENCHMARKS.md's Slurm figure for a time limit: worker jobs of one core and a one-minute
/// limit, no drain signal, tiles of about 25 s each. Slurm ends each job at its limit
/// mid-tile; the tile goes back and a new worker job renders it; every frame equals a
/// direct render. Minutes long, so not part of CI:
/// `cargo test -p tests --test slurm -- --ignored --nocapture --test-threads 1`.
#[test]
#[ignore]
fn measure_worker_jobs_killed_by_their_time_limit_mid_tile() {
    let run = time_limited_jobs("0", "16384");
    assert!(
        run.interrupted > 0,
        "no job was killed mid-tile:\n{}",
        run.logs.join("\n")
    );
}

/// The same with the drain: Slurm sends SIGUSR1 50 s before the limit (it checks signal
/// times coarsely: up to about half a minute late), and each worker finishes its tile
/// (about 12 s here) and leaves before the limit: no tile is interrupted.
#[test]
#[ignore]
fn measure_worker_jobs_drained_before_their_time_limit() {
    let run = time_limited_jobs("50", "8192");
    let logs = run.logs.join("\n");
    assert_eq!((run.killed, run.interrupted), (0, 0), "{logs}");
    assert!(run.drained > 0, "{logs}");
}

/// What a run of [`time_limited_jobs`] saw.
struct TimeLimitedRun {
    /// Every worker job's log.
    logs: Vec<String>,
    /// Tiles the workers were stopped in.
    interrupted: usize,
    /// Jobs ended by their time limit.
    killed: usize,
    /// Workers that drained (on SIGUSR1) and left.
    drained: usize,
}

/// The demo's frames 1-8 at `spp`, one tile each, by worker jobs of one core with a
/// one-minute time limit and `--drain-seconds drain`; every frame must equal a direct
/// render and nothing may fail. Prints what happened to the worker jobs.
fn time_limited_jobs(drain: &str, spp: &str) -> TimeLimitedRun {
    if let Some(why) = Cluster::unavailable() {
        panic!("the Slurm measurement needs a one-node cluster here: {why}");
    }
    let mut farm = Farm::new();
    farm.start_server(60);
    let cluster = Cluster::start(&farm);
    let scene = farm.demo_scene();
    let flags = ["--cpus", "1", "--time", "1", "--drain-seconds", drain];
    let mut provisioner = start_provisioner(&farm, &cluster, &flags);
    let started = Instant::now();
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-8", "--tile", "32"];
    args.extend(["--passes", "1"]);
    args.extend(settings(spp));
    let job = farm.submit(&args);
    let st = farm.wait_for_job(job, Duration::from_secs(900));
    let seconds = started.elapsed().as_secs_f64();
    assert_eq!(st.state, JobState::Done, "{st:?}");
    assert_eq!(st.attempts_failed, 0);
    assert!(provisioner.terminate(Duration::from_secs(30)).success());
    let logs = worker_logs(&farm);
    let killed = logs
        .iter()
        .filter(|l| l.contains("DUE TO TIME LIMIT"))
        .count();
    let drained = logs
        .iter()
        .filter(|l| l.contains("worker stopped (drained)"))
        .count();
    let interrupted: usize = logs.iter().map(|l| interrupted_tiles(l)).sum();
    for frame in 1..=8 {
        let direct = render_directly(&scene, frame, spp, farm.path());
        assert!(farm.server_frame(job, frame) == direct, "frame {frame}");
    }
    eprintln!(
        "time limit 1 min, drain {drain} s, {spp} spp: {} worker jobs, {killed} ended by the \
         time limit, {drained} drained; {interrupted} tiles interrupted; 8 of 8 frames equal \
         a direct render; the job took {seconds:.0} s",
        logs.len()
    );
    TimeLimitedRun {
        logs,
        interrupted,
        killed,
        drained,
    }
}

/// BENCHMARKS.md's Slurm throughput: one job rendered by two one-thread workers started
/// by hand (already waiting), then by two one-core worker jobs the provisioner starts.
/// `cargo test -p tests --test slurm -- --ignored --nocapture --test-threads 1`.
#[test]
#[ignore]
fn measure_slurm_started_workers_against_workers_started_by_hand() {
    if let Some(why) = Cluster::unavailable() {
        panic!("the Slurm measurement needs a one-node cluster here: {why}");
    }
    let mut farm = Farm::new();
    farm.start_server(60);
    let scene = farm.demo_scene();
    let scene = scene.to_str().unwrap();
    let args = [
        scene, "--frames", "1-8", "--size", "256x192", "--spp", "64", "--tile", "32", "--passes",
        "1", "--seed", "7",
    ];
    let tasks = 8 * 8 * 6;
    for name in ["hand-1", "hand-2"] {
        farm.start_worker(name, 1);
    }
    wait_until(
        "two workers",
        Duration::from_secs(30),
        || {
            farm.worker_list()
                .workers
                .iter()
                .filter(|w| w.online)
                .count()
                == 2
        },
        || farm.logs(),
    );
    let started = Instant::now();
    let job = farm.submit(&args);
    assert_eq!(
        farm.wait_for_job(job, Duration::from_secs(600)).state,
        JobState::Done
    );
    let by_hand = started.elapsed().as_secs_f64();
    for w in &mut farm.workers {
        w.terminate(Duration::from_secs(30));
    }

    let cluster = Cluster::start(&farm);
    let flags = ["--cpus", "1", "--time", "10"];
    let mut provisioner = start_provisioner(&farm, &cluster, &flags);
    let started = Instant::now();
    let job = farm.submit(&args);
    let latency = first_lease(&farm, job, started);
    assert_eq!(
        farm.wait_for_job(job, Duration::from_secs(600)).state,
        JobState::Done
    );
    let slurm = started.elapsed().as_secs_f64();
    assert!(provisioner.terminate(Duration::from_secs(30)).success());
    eprintln!(
        "| workers | submit to first lease | submit to done | tiles/s after the first lease |\n\
         |---|---:|---:|---:|\n\
         | 2 started by hand, waiting | - | {by_hand:.1} s | {:.2} |\n\
         | 2 Slurm jobs from `tessera scale slurm` | {latency:.1} s | {slurm:.1} s | {:.2} |",
        tasks as f64 / by_hand,
        tasks as f64 / (slurm - latency)
    );
}

/// `tessera scale slurm` for the farm in the cluster, looking every second, with `extra`
/// flags (at most 2 workers unless they say otherwise), once it has started (its sbatch options accepted). Worker jobs log to `slurm-jobs/` and cache scenes in `cache-slurm/` (the
/// provisioner's environment reaches them: `--export=ALL`).
fn start_provisioner(farm: &Farm, cluster: &Cluster, extra: &[&str]) -> Process {
    let logs = farm.path().join("slurm-jobs");
    std::fs::create_dir_all(&logs).unwrap();
    let mut cmd = Command::new(tessera_bin());
    cmd.args(["scale", "slurm", "--server", &farm.url()])
        .args(["--interval", "1"])
        .args(["--exit-when-idle", EXIT_WHEN_IDLE, "--log-dir"])
        .arg(&logs)
        .args(extra)
        .args(if extra.contains(&"--max-workers") {
            &[][..]
        } else {
            &["--max-workers", "2"]
        })
        .env("SLURM_CONF", &cluster.conf)
        .env("TESSERA_CACHE", farm.path().join("cache-slurm"));
    let mut provisioner = Process::spawn("provisioner", cmd, farm.path());
    wait_until(
        "the provisioner to start",
        Duration::from_secs(30),
        || {
            assert!(
                provisioner.running(),
                "the provisioner stopped:\n{}",
                provisioner.log()
            );
            provisioner.log().contains("scaling workers for")
        },
        || farm.logs(),
    );
    provisioner
}

/// Waits for the job's first lease; the seconds since `since`.
fn first_lease(farm: &Farm, job: u64, since: Instant) -> f64 {
    wait_until(
        "a worker started by Slurm to lease a tile",
        Duration::from_secs(60),
        || {
            let tasks = farm.job(job).tasks;
            tasks.leased + tasks.done > 0
        },
        || farm.logs(),
    );
    since.elapsed().as_secs_f64()
}

/// The provisioner's jobs in the cluster, as `ID STATE NAME` lines.
fn our_jobs(cluster: &Cluster) -> Vec<String> {
    cluster
        .jobs()
        .into_iter()
        .filter(|j| j.ends_with(" tessera-worker"))
        .collect()
}

/// Every worker job's log.
fn worker_logs(farm: &Farm) -> Vec<String> {
    let dir = farm.path().join("slurm-jobs");
    let mut logs: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .filter_map(|e| std::fs::read_to_string(e.path()).ok())
        .collect();
    logs.sort();
    logs
}

/// The tiles a worker's last line says it was interrupted in (`..., 1 interrupted, ...`).
fn interrupted_tiles(log: &str) -> usize {
    let Some((before, _)) = log.rsplit_once(" interrupted") else {
        return 0;
    };
    let count = before.rsplit(' ').next().unwrap_or_default();
    count.parse().unwrap_or(0)
}

/// The log of worker job `id` (`1234_0`).
fn worker_log(farm: &Farm, id: &str) -> String {
    let path = farm
        .path()
        .join("slurm-jobs")
        .join(format!("tessera-worker-{id}.log"));
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}
