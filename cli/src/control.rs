//! `tessera status [JOB]`, `tessera cancel|pause|resume|retry JOB` and `tessera workers`:
//! read and steer the farm (a job by id or name). Plain aligned tables, or the JSON with `--json`.

use anyhow::Context;
use clap::Args;
use proto::{FailureGroup, FailureKind, FailureList, FrameList, JobList, JobStatus, WorkerList};
use serde::Serialize;

use crate::client::{Client, Control, JobRef, ServerOpts};
use crate::progress::{duration, rate, state_name};

/// Show the jobs on the farm, or one job in detail.
#[derive(Args, Debug)]
pub struct StatusArgs {
    /// A job, by id or name: its settings, tasks by state, every frame's state and why
    /// attempts failed.
    pub job: Option<JobRef>,
    #[command(flatten)]
    pub server: ServerOpts,
    /// Print JSON instead: the job list, or `{"job": ..., "frames": [...]}` for one job.
    #[arg(long)]
    pub json: bool,
}

/// Cancel, pause, resume or retry a job.
#[derive(Args, Debug)]
pub struct ControlArgs {
    /// The job, by id or name.
    pub job: JobRef,
    #[command(flatten)]
    pub server: ServerOpts,
    /// Print the job's new status as JSON.
    #[arg(long)]
    pub json: bool,
}

/// List the workers the server knows.
#[derive(Args, Debug)]
pub struct WorkersArgs {
    #[command(flatten)]
    pub server: ServerOpts,
    /// Print the worker list as JSON.
    #[arg(long)]
    pub json: bool,
    /// Clear the worker with this id of its quarantine (after checks proved its tiles
    /// wrong and its machine was repaired): it gets work again.
    #[arg(long, value_name = "ID")]
    pub clear: Option<u64>,
    /// Also list the workers gone for more than a day.
    #[arg(long)]
    pub all: bool,
}

/// Runs `f` with a client on a small single-threaded runtime.
pub fn with_client<F, Fut>(opts: &ServerOpts, f: F) -> anyhow::Result<()>
where
    F: FnOnce(Client) -> Fut,
    Fut: std::future::Future<Output = anyhow::Result<()>>,
{
    let client = opts.client()?;
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?
        .block_on(f(client))
}

/// `status JOB --json`: the job, its frames, and why its attempts failed.
#[derive(Serialize)]
struct JobDetails<'a> {
    job: &'a JobStatus,
    frames: &'a [proto::FrameStatus],
    failures: &'a [FailureGroup],
}

pub fn print_json(value: &impl Serialize) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string_pretty(value)?);
    Ok(())
}

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// `3s ago`, `2m 10s ago`; `just now` for a time at or after `now` (clocks differ a little).
fn ago(then_ms: i64, now_ms: i64) -> String {
    let seconds = (now_ms - then_ms) as f64 / 1000.0;
    if seconds < 1.0 {
        "just now".into()
    } else {
        format!("{} ago", duration(seconds))
    }
}

/// Rows under a header, each column as wide as its widest cell, two spaces apart; no
/// trailing spaces.
pub fn table(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut widths: Vec<usize> = header.iter().map(|h| h.chars().count()).collect();
    for row in rows {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let line = |cells: Vec<&str>| {
        let mut s = String::new();
        for (i, (cell, w)) in cells.iter().zip(&widths).enumerate() {
            if i > 0 {
                s.push_str("  ");
            }
            s.push_str(cell);
            if i + 1 < cells.len() {
                s.push_str(&" ".repeat(w - cell.chars().count()));
            }
        }
        s.trim_end().to_string()
    };
    let mut out = line(header.to_vec());
    for row in rows {
        out.push('\n');
        out.push_str(&line(row.iter().map(String::as_str).collect()));
    }
    out
}

/// The job list as a table.
pub fn jobs_table(jobs: &JobList) -> String {
    let rows: Vec<Vec<String>> = jobs
        .jobs
        .iter()
        .map(|j| {
            vec![
                j.id.to_string(),
                j.name.clone(),
                match (&j.stuck, &j.waiting) {
                    (Some(_), _) => format!("{} (stuck)", state_name(j.state)),
                    (None, Some(_)) => format!("{} (waiting)", state_name(j.state)),
                    (None, None) => state_name(j.state).to_string(),
                },
                format!("{}/{}", j.frames_done, j.frames_total),
                format!("{:.1}%", j.progress * 100.0),
                j.eta_seconds.map_or("-".into(), duration),
            ]
        })
        .collect();
    table(&["ID", "NAME", "STATE", "FRAMES", "PROGRESS", "ETA"], &rows)
}

/// One job in detail: settings, tasks by state, progress, why it is stuck, every frame,
/// then why its attempts failed (`failures`, grouped by reason).
pub fn job_details(
    j: &JobStatus,
    frames: &FrameList,
    failures: &[FailureGroup],
    now_ms: i64,
) -> String {
    let s = &j.spec;
    let frames_range = s.frames.map_or("-".into(), |f| {
        if f.step == 1 {
            format!("{}-{}", f.start, f.end)
        } else {
            format!("{}-{}:{}", f.start, f.end, f.step)
        }
    });
    let t = &j.tasks;
    let mut progress = format!("{:.1}%", j.progress * 100.0);
    if j.samples_per_second > 0.0 {
        progress.push_str(&format!(", {}", rate(j.samples_per_second)));
    }
    if let Some(eta) = j.eta_seconds {
        progress.push_str(&format!(", ETA {}", duration(eta)));
    }
    let mut when = format!("created {}", ago(j.created_ms, now_ms));
    if let Some(f) = j.finished_ms {
        when.push_str(&format!(
            ", finished {} (took {})",
            ago(f, now_ms),
            duration((f - j.created_ms) as f64 / 1000.0)
        ));
    }
    let mut fields = vec![
        ("scene", s.scene.chars().take(16).collect::<String>()),
        (
            "frames",
            format!(
                "{frames_range} at {} fps: {} of {} done, {} failed",
                s.fps, j.frames_done, j.frames_total, j.frames_failed
            ),
        ),
        (
            "render",
            format!(
                "{}x{}, {} spp in {} pass(es), tile {}, max depth {}, seed {}, shutter {},{}",
                s.width,
                s.height,
                s.spp,
                s.sample_passes,
                s.tile_size.map_or("auto".into(), |t| t.to_string()),
                s.max_depth,
                s.seed,
                s.shutter[0],
                s.shutter[1]
            ),
        ),
        (
            "tasks",
            format!(
                "{} done, {} leased, {} queued, {} failed, {} cancelled (of {})",
                t.done,
                t.leased,
                t.queued,
                t.failed,
                t.cancelled,
                t.total()
            ),
        ),
        ("progress", progress),
        ("time", when),
    ];
    if let Some(b) = &j.budget {
        let predicted = b
            .predicted_end_ms
            .map_or("not yet predicted".into(), |end| {
                let late = if end > b.deadline_ms {
                    ", past the deadline"
                } else {
                    ""
                };
                format!(
                    "predicted to end {} after submission{late}",
                    duration((end - j.created_ms) as f64 / 1000.0)
                )
            });
        fields.push((
            "budget",
            format!(
                "{}: {predicted}; {} passes added; {} on {} worker(s); {}",
                duration(b.budget_seconds),
                b.passes_added,
                rate(b.samples_per_second),
                b.workers,
                b.stage
            ),
        ));
    }
    if let Some(why) = &j.stuck {
        fields.push(("STUCK", why.clone()));
    }
    if let Some(why) = &j.waiting {
        fields.push(("WAITING", why.clone()));
    }
    if j.spec.video {
        let video = match j.video {
            true => format!("encoded: `tessera download {}` saves it as video.mp4", j.id),
            false => "not yet: it is encoded once every frame is finished".to_string(),
        };
        fields.push(("VIDEO", video));
    }
    let mut out = format!("job {} \"{}\": {}\n", j.id, j.name, state_name(j.state));
    for (k, v) in fields {
        out.push_str(&format!("  {k:<9} {v}\n"));
    }
    out.push('\n');
    let rows: Vec<Vec<String>> = frames
        .frames
        .iter()
        .map(|f| {
            vec![
                f.frame.to_string(),
                f.state.as_str().to_string(),
                format!("{}/{}", f.tasks_done, f.tasks_total),
                f.spp_mean.map_or("-".into(), |s| format!("{s:.1}")),
                f.noise.map_or("-".into(), |e| format!("{e:.4}")),
                f.file.clone(),
            ]
        })
        .collect();
    out.push_str(&table(
        &["FRAME", "STATE", "TASKS", "SPP", "NOISE", "FILE"],
        &rows,
    ));
    for f in &frames.frames {
        if let Some(why) = &f.failure {
            out.push_str(&format!("\nframe {} failed to assemble: {why}", f.frame));
        }
    }
    if !failures.is_empty() {
        out.push_str(&format!(
            "\n\n{} failed attempt(s), by reason:",
            j.attempts_failed
        ));
        for g in failures {
            let kind = match g.kind {
                FailureKind::Reported => "reported",
                FailureKind::Expired => "lease expired",
            };
            out.push_str(&format!(
                "\n  {} attempt(s) of {} task(s) on {}, {kind} (last {}): {}",
                g.attempts,
                g.tasks,
                g.workers.join(", "),
                ago(g.last_ms, now_ms),
                g.reason
            ));
        }
        let example = failures[0].example_task;
        out.push_str(&format!(
            "
  what the worker logged: tessera logs {} --task {example}",
            j.id
        ));
    }
    out
}

/// The worker list as a table.
pub fn workers_table(workers: &WorkerList, now_ms: i64) -> String {
    let rows: Vec<Vec<String>> = workers
        .workers
        .iter()
        .map(|w| {
            let current = match (w.current_job, w.current_frame) {
                (Some(job), Some(frame)) => format!("job {job} frame {frame}"),
                (Some(job), None) => format!("job {job}"),
                _ => "-".into(),
            };
            vec![
                w.id.to_string(),
                w.name.clone(),
                w.threads.to_string(),
                if w.online { "yes" } else { "no" }.to_string(),
                match (&w.quarantined, w.suspect) {
                    (Some(_), _) => "quarantined".to_string(),
                    (None, true) => "suspect".to_string(),
                    (None, false) => "ok".to_string(),
                },
                current,
                w.tasks_done.to_string(),
                w.samples_per_second
                    .map_or("-".into(), crate::progress::rate),
                match (&w.last_failure, w.recent_failures) {
                    (Some(why), n) if n > 0 => format!("{n}: {why}"),
                    _ => "-".into(),
                },
                ago(w.last_seen_ms, now_ms),
                steps(w),
                if w.tags.is_empty() {
                    "-".into()
                } else {
                    w.tags.join(",")
                },
            ]
        })
        .collect();
    table(
        &[
            "ID",
            "NAME",
            "THREADS",
            "ONLINE",
            "CHECKS",
            "CURRENT",
            "TASKS DONE",
            "SPEED",
            "FAILED (1H)",
            "LAST SEEN",
            "STEPS",
            "TAGS",
        ],
        &rows,
    )
}

/// The steps after rendering a worker takes: `denoise`, `encode`, both, or `-`.
fn steps(w: &proto::WorkerInfo) -> String {
    let steps: Vec<&str> = [
        w.denoiser.as_ref().map(|_| "denoise"),
        w.encoder.as_ref().map(|_| "encode"),
    ]
    .into_iter()
    .flatten()
    .collect();
    if steps.is_empty() {
        "-".into()
    } else {
        steps.join(",")
    }
}

pub fn status(args: StatusArgs) -> anyhow::Result<()> {
    with_client(&args.server, |client| async move {
        match args.job {
            None => {
                let jobs = client.jobs().await?;
                if args.json {
                    print_json(&jobs)
                } else if jobs.jobs.is_empty() {
                    println!(
                        "no jobs on {}; submit one with `tessera submit`",
                        client.base()
                    );
                    Ok(())
                } else {
                    println!("{}", jobs_table(&jobs));
                    Ok(())
                }
            }
            Some(job) => {
                let id = client.resolve(&job).await?;
                let job = client.job(id).await?;
                let frames = client.frames(id).await?;
                let failures = match job.attempts_failed {
                    0 => FailureList::default(),
                    _ => client.failures(id).await?,
                };
                if args.json {
                    print_json(&JobDetails {
                        job: &job,
                        frames: &frames.frames,
                        failures: &failures.groups,
                    })
                } else {
                    println!("{}", job_details(&job, &frames, &failures.groups, now_ms()));
                    Ok(())
                }
            }
        }
    })
}

pub fn control(args: ControlArgs, control: Control) -> anyhow::Result<()> {
    with_client(&args.server, |client| async move {
        let id = client.resolve(&args.job).await?;
        let job = client
            .control(id, control)
            .await
            .with_context(|| format!("{} job {id}", control.verb()))?;
        if args.json {
            return print_json(&job);
        }
        let what = match control {
            Control::Cancel => "cancelled: unfinished tasks will not run",
            Control::Pause => "paused: nothing more is leased until `tessera resume`",
            Control::Resume => "resumed",
            Control::Retry => "failed tasks and frames queued again",
        };
        println!(
            "job {} {what} (now {}, frames {}/{})",
            job.id,
            state_name(job.state),
            job.frames_done,
            job.frames_total
        );
        Ok(())
    })
}

pub fn workers(args: WorkersArgs) -> anyhow::Result<()> {
    with_client(&args.server, |client| async move {
        if let Some(id) = args.clear {
            let worker = client
                .clear_worker(id)
                .await
                .with_context(|| format!("clearing worker {id}"))?;
            return if args.json {
                print_json(&worker)
            } else {
                println!("worker {id} ({}) cleared: it gets work again", worker.name);
                Ok(())
            };
        }
        let workers = if args.all {
            client.all_workers().await?
        } else {
            client.workers().await?
        };
        if args.json {
            print_json(&workers)
        } else if workers.workers.is_empty() {
            println!(
                "no workers have registered with {}; start one with `tessera worker --server {}`",
                client.base(),
                client.base()
            );
            Ok(())
        } else {
            println!("{}", workers_table(&workers, now_ms()));
            Ok(())
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proto::{FrameState, FrameStatus, JobSpec, JobState, TaskCounts, TaskToken, WorkerInfo};

    fn job(id: u64, name: &str, state: JobState, eta: Option<f64>) -> JobStatus {
        JobStatus {
            id,
            name: name.into(),
            state,
            spec: JobSpec::new("0123456789abcdef0123"),
            created_ms: 1_000,
            finished_ms: None,
            tasks: TaskCounts {
                queued: 3,
                leased: 1,
                done: 4,
                failed: 0,
                cancelled: 0,
            },
            frames_total: 24,
            frames_done: 3,
            frames_failed: 0,
            progress: 0.125,
            samples_per_second: 2.5e6,
            eta_seconds: eta,
            budget: None,
            attempts_failed: 0,
            stuck: None,
            waiting: None,
            video: false,
        }
    }

    #[test]
    fn tables_align_columns_without_trailing_spaces() {
        let t = table(
            &["A", "LONG HEADER", "C"],
            &[
                vec!["1".into(), "x".into(), "".into()],
                vec!["wide cell".into(), "y".into(), "z".into()],
            ],
        );
        assert_eq!(
            t,
            "A          LONG HEADER  C\n\
             1          x\n\
             wide cell  y            z"
        );
    }

    #[test]
    fn the_job_table_shows_frames_progress_and_eta() {
        let mut stuck = job(13, "shot 2", JobState::Queued, None);
        stuck.stuck = Some("no live worker may take its tasks".into());
        let jobs = JobList {
            jobs: vec![
                stuck,
                job(12, "shot 1", JobState::Running, Some(65.0)),
                job(3, "job 3", JobState::Done, None),
            ],
        };
        assert_eq!(
            jobs_table(&jobs),
            "ID  NAME    STATE           FRAMES  PROGRESS  ETA\n\
             13  shot 2  queued (stuck)  3/24    12.5%     -\n\
             12  shot 1  running         3/24    12.5%     1m 05s\n\
             3   job 3   done            3/24    12.5%     -"
        );
    }

    #[test]
    fn job_details_list_tasks_and_frames() {
        let frames = FrameList {
            frames: vec![
                FrameStatus {
                    frame: 1,
                    state: FrameState::Done,
                    tasks_total: 8,
                    tasks_done: 8,
                    spp_mean: Some(37.25),
                    noise: Some(0.0123),
                    file: "frame_0001.exr".into(),
                    failure: None,
                },
                FrameStatus {
                    frame: 2,
                    state: FrameState::Rendering,
                    tasks_total: 8,
                    tasks_done: 3,
                    spp_mean: None,
                    noise: None,
                    file: "frame_0002.exr".into(),
                    failure: None,
                },
            ],
        };
        let text = job_details(
            &job(7, "walk", JobState::Running, Some(30.0)),
            &frames,
            &[],
            61_000,
        );
        assert!(text.starts_with("job 7 \"walk\": running\n"), "{text}");
        assert!(
            text.contains("4 done, 1 leased, 3 queued, 0 failed, 0 cancelled (of 8)"),
            "{text}"
        );
        assert!(text.contains("12.5%, 2.50 M samples/s, ETA 30s"), "{text}");
        assert!(text.contains("created 1m 00s ago"), "{text}");
        assert!(
            text.ends_with(
                "FRAME  STATE      TASKS  SPP   NOISE   FILE\n\
                 1      done       8/8    37.2  0.0123  frame_0001.exr\n\
                 2      rendering  3/8    -     -       frame_0002.exr"
            ),
            "{text}"
        );
    }

    #[test]
    fn a_stuck_job_and_its_failures_are_shown_by_reason() {
        let mut j = job(7, "walk", JobState::Running, None);
        j.stuck = Some("no live worker may take its tasks".into());
        j.attempts_failed = 3;
        let failures = [
            FailureGroup {
                kind: FailureKind::Reported,
                reason: "loading the scene: bad PNG".into(),
                attempts: 2,
                tasks: 2,
                workers: vec!["a".into(), "b".into()],
                example_task: 4,
                last_ms: 1_000,
            },
            FailureGroup {
                kind: FailureKind::Expired,
                reason: "lease expired without a heartbeat".into(),
                attempts: 1,
                tasks: 1,
                workers: vec!["c".into()],
                example_task: 5,
                last_ms: 31_000,
            },
        ];
        let text = job_details(&j, &FrameList { frames: vec![] }, &failures, 61_000);
        assert!(
            text.contains("\n  STUCK     no live worker may take its tasks\n"),
            "{text}"
        );
        assert!(
            text.ends_with(
                "3 failed attempt(s), by reason:\n  \
                 2 attempt(s) of 2 task(s) on a, b, reported (last 1m 00s ago): loading the \
                 scene: bad PNG\n  \
                 1 attempt(s) of 1 task(s) on c, lease expired (last 30s ago): lease expired \
                 without a heartbeat\n  \
                 what the worker logged: tessera logs 7 --task 4"
            ),
            "{text}"
        );
    }

    #[test]
    fn a_time_budget_job_shows_its_plan() {
        let mut j = job(7, "camp", JobState::Running, Some(12.0));
        j.budget = Some(proto::BudgetPlan {
            budget_seconds: 256.0,
            deadline_ms: j.created_ms + 256_000,
            planned_ms: 61_000,
            samples_per_second: 4.2e6,
            workers: 3,
            predicted_end_ms: Some(j.created_ms + 250_000),
            passes_added: 17,
            stage: "refining: the noisiest frames get more samples".into(),
        });
        let text = job_details(&j, &FrameList { frames: vec![] }, &[], 61_000);
        assert!(
            text.contains(
                "budget    4m 16s: predicted to end 4m 10s after submission; 17 passes added; \
                 4.20 M samples/s on 3 worker(s); refining: the noisiest frames get more samples"
            ),
            "{text}"
        );
        j.budget.as_mut().unwrap().predicted_end_ms = Some(j.created_ms + 300_000);
        let text = job_details(&j, &FrameList { frames: vec![] }, &[], 61_000);
        assert!(
            text.contains("5m 00s after submission, past the deadline;"),
            "{text}"
        );
    }

    #[test]
    fn the_worker_table_shows_what_each_is_doing() {
        let worker = |id, name: &str, online, job: Option<u64>, frame| WorkerInfo {
            id,
            name: name.into(),
            threads: 8,
            version: "0.1.0".into(),
            current_task: job.map(|_| TaskToken {
                task_id: 5,
                attempt: 1,
            }),
            current_job: job,
            current_frame: frame,
            last_seen_ms: 58_000,
            online,
            tasks_done: 17,
            suspect: false,
            quarantined: None,
            platform: None,
            tags: vec![],
            denoiser: None,
            encoder: None,
            samples_per_second: None,
            recent_failures: 0,
            last_failure: None,
        };
        let mut bad = worker(3, "c", true, None, None);
        bad.samples_per_second = Some(2.5e6);
        (bad.recent_failures, bad.last_failure) = (2, Some("out of memory".into()));
        bad.tags = vec!["gpu".into(), "studio-a".into()];
        bad.quarantined = Some("its tile of task 9 differs".into());
        let mut render01 = worker(1, "render-01", true, Some(3), Some(12));
        render01.denoiser = Some("Open Image Denoise 2.5.1".into());
        render01.encoder = Some("FFmpeg with libx264".into());
        let list = WorkerList {
            workers: vec![render01, worker(2, "b", false, None, None), bad],
        };
        assert_eq!(
            workers_table(&list, 60_000),
            "ID  NAME       THREADS  ONLINE  CHECKS       CURRENT         TASKS DONE  SPEED             FAILED (1H)       LAST SEEN  STEPS           TAGS\n\
             1   render-01  8        yes     ok           job 3 frame 12  17          -                 -                 2s ago     denoise,encode  -\n\
             2   b          8        no      ok           -               17          -                 -                 2s ago     -               -\n\
             3   c          8        yes     quarantined  -               17          2.50 M samples/s  2: out of memory  2s ago     -               gpu,studio-a"
        );
    }
}
