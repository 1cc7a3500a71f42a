//! The farm's cost in `tessera bench`: the same frames of the animated demo rendered by a
//! server and `tessera worker` processes on this machine, against `tessera render` of the
//! same scene file with as many threads. One worker with every thread gives the farm's
//! overhead; 1, 2 and 4 single-thread workers against `tessera render` with 1, 2 and 4
//! threads give its scaling. Both ways load the scene, render, and write each frame's EXR
//! and PNG. The farm's time runs from the job's creation to its end (the server's clock:
//! scene download, leases, uploads and frame assembly included; the workers are already
//! running, as on a farm); the direct one from starting `tessera render` to its exit. Each
//! farm run is followed at once by its direct render, so that both see the same machine
//! (a shared VM's speed drifts over minutes). CPU seconds compare them too: the workers'
//! and the server's (in this process) against the direct render's.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use proto::{FrameRange, JobSpec};
use serde::Serialize;

use crate::bench::farm::{children_cpu_seconds, cpu_seconds};
use crate::client::Client;
use crate::demo::{tessera_command, LocalServer, Workers};

/// How long workers get to register, and a job to finish, before the bench gives up.
const WAIT: Duration = Duration::from_secs(600);
/// How often the bench asks: the job's times come from the server's clock, so polling
/// faster would only load the server it measures.
const POLL: Duration = Duration::from_millis(250);

/// What is rendered, both ways.
#[derive(Clone, Copy, Serialize)]
pub struct Work {
    /// Frames 1 to this.
    pub frames: i32,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
}

impl Work {
    /// The report's work: the demo's first four frames, small with `quick`.
    pub fn for_report(quick: bool) -> Work {
        let (width, height, spp) = if quick { (64, 48, 16) } else { (256, 192, 32) };
        Work {
            frames: 4,
            width,
            height,
            spp,
        }
    }
}

/// `tessera bench overhead`.
#[derive(clap::Args)]
pub struct OverheadArgs {
    /// Smaller frames (64x48, 16 spp): a minute instead of several.
    #[arg(long)]
    quick: bool,
    /// Threads of the one-worker run and of its direct render [default: every core].
    #[arg(long)]
    threads: Option<u32>,
    /// Runs of each farm and of its direct render, taken in turn; the fastest of each
    /// counts, which a busy neighbour on a shared machine disturbs least.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=20))]
    runs: u32,
}

/// Measures the farm's overhead and scaling and prints the report's table.
pub fn run(args: OverheadArgs) -> anyhow::Result<()> {
    let threads = args
        .threads
        .unwrap_or(rayon::current_num_threads() as u32)
        .max(1);
    let costs = farm_costs(Work::for_report(args.quick), threads, args.runs)?;
    print!("{}", table(&costs));
    Ok(())
}

/// One farm against the direct render with the same threads.
#[derive(Serialize)]
pub struct FarmRun {
    /// Worker processes.
    pub workers: u32,
    /// Threads each.
    pub threads_each: u32,
    /// Seconds from the job's creation to its end.
    pub farm_seconds: f64,
    /// Seconds rendering the same frames in one process of `workers × threads_each`
    /// threads.
    pub direct_seconds: f64,
    /// CPU seconds of this process (the server, and the bench's polling) during the
    /// farm's run, where the platform tells.
    pub server_cpu_seconds: Option<f64>,
    /// CPU seconds of the worker processes during the farm's run.
    pub worker_cpu_seconds: Option<f64>,
    /// CPU seconds of the direct render.
    pub direct_cpu_seconds: Option<f64>,
}

impl FarmRun {
    /// The faster farm of two runs and the faster direct render, each with its CPU time.
    fn fastest(self, other: FarmRun) -> FarmRun {
        let (farm, direct) = (
            if other.farm_seconds < self.farm_seconds {
                &other
            } else {
                &self
            },
            if other.direct_seconds < self.direct_seconds {
                &other
            } else {
                &self
            },
        );
        FarmRun {
            farm_seconds: farm.farm_seconds,
            server_cpu_seconds: farm.server_cpu_seconds,
            worker_cpu_seconds: farm.worker_cpu_seconds,
            direct_seconds: direct.direct_seconds,
            direct_cpu_seconds: direct.direct_cpu_seconds,
            ..self
        }
    }

    /// The farm's throughput as a fraction of the direct render's.
    pub fn ratio(&self) -> f64 {
        self.direct_seconds / self.farm_seconds
    }

    /// The direct render's CPU seconds over the farm's (workers and server): below 1 by
    /// what the farm spends beyond rendering. It can exceed 1: idle rayon threads of the
    /// direct render spin briefly before they sleep.
    pub fn cpu_ratio(&self) -> Option<f64> {
        let farm = self.worker_cpu_seconds? + self.server_cpu_seconds?;
        Some(self.direct_cpu_seconds? / farm)
    }
}

/// The farm's figures.
#[derive(Serialize)]
pub struct FarmCosts {
    /// The work.
    pub work: Work,
    /// Runs of each farm and of its direct render; each row has the fastest of each.
    pub repeats: u32,
    /// One worker with every thread, then 1, 2 and 4 single-thread workers.
    pub runs: Vec<FarmRun>,
}

/// The shutter of both renders, in frames: motion blur on.
const SHUTTER: [f64; 2] = [-0.25, 0.25];

/// `work` rendered by `tessera render` of `scene` (a GLB) with `threads` threads, as a user
/// runs it: loading the scene, and writing each frame's EXR and PNG into `out`, as the
/// server does when it assembles a frame. Wall and CPU seconds of the process.
fn direct_seconds(
    scene: &Path,
    out: &Path,
    work: Work,
    threads: u32,
) -> anyhow::Result<(f64, Option<f64>)> {
    let log = out.with_extension("log");
    let mut cmd = tessera_command(&log)?;
    cmd.arg("render")
        .arg(scene)
        .args(["--frames", &format!("1-{}", work.frames)])
        .args(["--size", &format!("{}x{}", work.width, work.height)])
        .args(["--spp", &work.spp.to_string()])
        .args(["--shutter", &format!("{},{}", SHUTTER[0], SHUTTER[1])])
        .args(["--threads", &threads.to_string()])
        .arg("--out")
        .arg(out);
    let (start, cpu) = (Instant::now(), children_cpu_seconds());
    let status = cmd.status().context("running tessera render")?;
    let seconds = start.elapsed().as_secs_f64();
    if !status.success() {
        bail!(
            "tessera render failed ({status}); its output is in {}",
            log.display()
        );
    }
    let cpu = children_cpu_seconds().zip(cpu).map(|(b, a)| b - a);
    Ok((seconds, cpu))
}

fn spec(digest: &str, work: Work) -> JobSpec {
    let mut spec = JobSpec::new(digest);
    spec.frames = Some(FrameRange {
        start: 1,
        end: work.frames,
        step: 1,
    });
    (spec.width, spec.height, spec.spp) = (work.width, work.height, work.spp);
    spec.shutter = SHUTTER;
    spec.name = Some("bench scaling".into());
    spec
}

/// Waits until `check` says yes, polling; fails after [`WAIT`] saying `what`.
async fn wait_for(
    what: &str,
    mut check: impl AsyncFnMut() -> anyhow::Result<bool>,
) -> anyhow::Result<()> {
    let until = Instant::now() + WAIT;
    while !check().await? {
        if Instant::now() > until {
            bail!("{what} within {} s", WAIT.as_secs());
        }
        tokio::time::sleep(POLL).await;
    }
    Ok(())
}

/// `work` on a farm of `workers` worker processes of `threads` threads each: seconds from
/// the job's creation to its end, and the CPU seconds of the server and of the workers
/// meanwhile.
async fn farm_seconds(
    client: &Client,
    url: &str,
    digest: &str,
    dir: &Path,
    workers: u32,
    threads: u32,
    work: Work,
) -> anyhow::Result<(f64, Option<f64>, Option<f64>)> {
    let logs = dir.join(format!("logs-{workers}x{threads}"));
    std::fs::create_dir_all(&logs)?;
    let mut procs = Workers::spawn(url, workers, threads, &dir.join("cache"), &logs)?;
    wait_for("the workers did not register", async || {
        let list = client.workers().await?;
        Ok(list.workers.iter().filter(|w| w.online).count() >= workers as usize)
    })
    .await?;
    let cpu = |procs: &Workers| {
        let workers: Option<f64> = procs
            .pids()
            .iter()
            .map(|pid| cpu_seconds(&pid.to_string()))
            .sum();
        (cpu_seconds("self"), workers)
    };
    let before = cpu(&procs);
    let job = client.create_job(&spec(digest, work)).await?;
    let mut last = job.clone();
    wait_for("the job did not finish", async || {
        last = client.job(job.id).await?;
        Ok(last.finished_ms.is_some())
    })
    .await?;
    let after = cpu(&procs);
    procs.stop(Duration::from_secs(5));
    if last.frames_done != work.frames as u64 {
        bail!(
            "the bench job ended with {} of {} frames",
            last.frames_done,
            work.frames
        );
    }
    let end = last.finished_ms.unwrap_or(last.created_ms);
    let spent = |a: Option<f64>, b: Option<f64>| Some(b? - a?);
    Ok((
        (end - last.created_ms) as f64 / 1000.0,
        spent(before.0, after.0),
        spent(before.1, after.1),
    ))
}

/// The farm's overhead with one worker of `threads` threads, and its scaling over 1, 2 and
/// 4 single-thread workers, each against a direct render with the same threads: the
/// fastest of `repeats` runs of each, taken in turn.
pub fn farm_costs(work: Work, threads: u32, repeats: u32) -> anyhow::Result<FarmCosts> {
    let (dir, _) = crate::bench::farm::data_folder(None)?;
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let result = runtime.block_on(async {
        let server = LocalServer::start(&dir.join("data")).await?;
        let client = Client::new(&server.url, None)?;
        let glb = tracer::export::scene_to_glb(&tracer::demo::animated_demo_scene())
            .map_err(|e| anyhow::anyhow!("exporting the demo scene to GLB: {e}"))?;
        let glb_path = dir.join("demo.glb");
        std::fs::write(&glb_path, &glb)?;
        let scene = client.upload_scene(glb).await?;
        let mut runs = Vec::new();
        for (workers, threads_each) in [(1, threads), (1, 1), (2, 1), (4, 1)] {
            let mut best: Option<FarmRun> = None;
            for run in 1..=repeats {
                eprintln!(
                    "farm: {workers} worker(s) of {threads_each} thread(s), run {run} of \
                     {repeats} ..."
                );
                let (farm_seconds, server_cpu_seconds, worker_cpu_seconds) = farm_seconds(
                    &client,
                    &server.url,
                    &scene.digest,
                    &dir,
                    workers,
                    threads_each,
                    work,
                )
                .await?;
                let (scene, out) = (glb_path.clone(), dir.join("direct"));
                let total = workers * threads_each;
                let (direct_seconds, direct_cpu_seconds) =
                    tokio::task::spawn_blocking(move || direct_seconds(&scene, &out, work, total))
                        .await??;
                let this = FarmRun {
                    workers,
                    threads_each,
                    farm_seconds,
                    direct_seconds,
                    server_cpu_seconds,
                    worker_cpu_seconds,
                    direct_cpu_seconds,
                };
                best = Some(match best {
                    None => this,
                    Some(b) => b.fastest(this),
                });
            }
            runs.extend(best);
        }
        server.shutdown().await?;
        Ok(FarmCosts {
            work,
            repeats,
            runs,
        })
    });
    runtime.shutdown_timeout(Duration::from_secs(1));
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// The markdown table of the runs.
pub fn table(costs: &FarmCosts) -> String {
    let mut out = "| workers x threads | farm (s) | direct, same threads (s) | farm / direct \
                   throughput | farm CPU: workers + server (s) | direct CPU (s) | direct / \
                   farm CPU |\n|---|---:|---:|---:|---:|---:|---:|\n"
        .to_string();
    let opt = |v: Option<f64>, digits: usize| v.map_or("-".into(), |v| format!("{v:.digits$}"));
    for r in &costs.runs {
        let farm_cpu = match (r.worker_cpu_seconds, r.server_cpu_seconds) {
            (Some(w), Some(s)) => format!("{w:.1} + {s:.1}"),
            _ => "-".into(),
        };
        out += &format!(
            "| {} x {} | {:.2} | {:.2} | {:.3} | {} | {} | {} |\n",
            r.workers,
            r.threads_each,
            r.farm_seconds,
            r.direct_seconds,
            r.ratio(),
            farm_cpu,
            opt(r.direct_cpu_seconds, 1),
            opt(r.cpu_ratio(), 3),
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(farm: f64, direct: f64) -> FarmRun {
        FarmRun {
            workers: 2,
            threads_each: 1,
            farm_seconds: farm,
            direct_seconds: direct,
            server_cpu_seconds: Some(farm / 10.0),
            worker_cpu_seconds: Some(farm * 2.0),
            direct_cpu_seconds: Some(direct * 2.0),
        }
    }

    #[test]
    fn the_fastest_farm_and_direct_render_count_each_with_its_cpu() {
        // The farm was faster in the second run, the direct render in the first.
        let best = run(12.0, 9.0).fastest(run(10.0, 11.0));
        assert_eq!((best.farm_seconds, best.direct_seconds), (10.0, 9.0));
        assert_eq!(best.worker_cpu_seconds, Some(20.0));
        assert_eq!(best.server_cpu_seconds, Some(1.0));
        assert_eq!(best.direct_cpu_seconds, Some(18.0));
        assert_eq!((best.workers, best.threads_each), (2, 1));
        assert_eq!(best.ratio(), 0.9);
    }
}
