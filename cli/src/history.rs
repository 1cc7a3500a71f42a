//! `tessera logs`: what happened to a job (its event log), or what the workers logged
//! while they held one of its tasks (`--task N`).

use std::time::{Duration, UNIX_EPOCH};

use anyhow::Context;
use clap::Args;
use proto::log::MAX_TASK_LOG_LINES;
use proto::{JobEvent, TaskLog};

use crate::client::{JobRef, ServerOpts};
use crate::control::{print_json, with_client};

/// Show a job's event log (created, paused, tasks failed and retried, frames assembled,
/// workers blocked), or with `--task` the lines the workers logged for one task.
#[derive(Args, Debug)]
pub struct LogsArgs {
    /// The job, by id or name.
    pub job: JobRef,
    /// One task's worker lines instead (task ids are in the job log, `tessera status` and
    /// `GET /jobs/{id}/tasks`).
    #[arg(long, value_name = "N")]
    pub task: Option<u64>,
    #[command(flatten)]
    pub server: ServerOpts,
    /// Print the log as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: LogsArgs) -> anyhow::Result<()> {
    with_client(&args.server, |client| async move {
        let id = client.resolve(&args.job).await?;
        match args.task {
            Some(task) => {
                let log = client
                    .task_log(id, task)
                    .await
                    .with_context(|| format!("reading the log of task {task} of job {id}"))?;
                if args.json {
                    return print_json(&log);
                }
                print!("{}", task_text(id, &log));
            }
            None => {
                let events = client
                    .job_log(id)
                    .await
                    .with_context(|| format!("reading the log of job {id}"))?;
                if args.json {
                    return print_json(&events);
                }
                print!("{}", job_text(id, &events));
            }
        }
        Ok(())
    })
}

/// A Unix-ms time as RFC 3339 UTC with milliseconds.
fn time(at_ms: i64) -> String {
    let at = UNIX_EPOCH + Duration::from_millis(at_ms.max(0) as u64);
    humantime::format_rfc3339_millis(at).to_string()
}

fn job_text(id: u64, events: &[JobEvent]) -> String {
    let mut out = format!("job {id}: {} event(s)\n", events.len());
    let width = events.iter().map(|e| e.kind.len()).max().unwrap_or(0);
    for e in events {
        let line = format!("{}  {:width$}  {}", time(e.at_ms), e.kind, e.detail);
        out.push_str(line.trim_end());
        out.push('\n');
    }
    if events.iter().any(|e| e.kind.starts_with("task_")) {
        out.push_str(&format!(
            "what a worker logged for a task: tessera logs {id} --task N\n"
        ));
    }
    out
}

fn task_text(id: u64, log: &TaskLog) -> String {
    let mut out = format!(
        "task {} of job {id} (frame {}): {} attempt(s) logged\n",
        log.task_id,
        log.frame,
        log.attempts.len()
    );
    if log.attempts.is_empty() {
        out.push_str(
            "workers send a task's lines with its heartbeats, its failure report and their \
             next lease request; a worker that stopped right after the task sent none\n",
        );
    }
    for a in &log.attempts {
        out.push_str(&format!("attempt {} on worker {}:\n", a.attempt, a.worker));
        for line in &a.lines {
            out.push_str(&format!(
                "  {} {:5} {}\n",
                time(line.at_ms),
                line.level.as_str(),
                line.text
            ));
        }
        if a.truncated {
            out.push_str(&format!(
                "  (later lines dropped: {MAX_TASK_LOG_LINES} are kept per attempt)\n"
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use proto::{AttemptLog, LogLevel, LogLine};

    use super::*;

    #[test]
    fn a_task_log_reads_attempt_by_attempt() {
        let log = TaskLog {
            task_id: 17,
            frame: 12,
            attempts: vec![AttemptLog {
                attempt: 1,
                worker_id: 2,
                worker: "render-01".into(),
                lines: vec![LogLine {
                    at_ms: 1_795_000_000_123,
                    level: LogLevel::Warn,
                    text: "task 17 failed: out of memory".into(),
                }],
                truncated: true,
            }],
        };
        assert_eq!(
            task_text(3, &log),
            "task 17 of job 3 (frame 12): 1 attempt(s) logged\n\
             attempt 1 on worker render-01:\n  \
             2026-11-18T11:06:40.123Z WARN  task 17 failed: out of memory\n  \
             (later lines dropped: 200 are kept per attempt)\n"
        );
    }

    #[test]
    fn a_job_log_aligns_kinds_and_points_at_task_logs() {
        let event = |kind: &str, detail: &str| JobEvent {
            id: 1,
            at_ms: 0,
            kind: kind.into(),
            detail: detail.into(),
        };
        let text = job_text(
            3,
            &[
                event("job_created", "4 tasks"),
                event("job_paused", ""),
                event(
                    "task_retry",
                    "task 9 attempt 1 on worker 2 (reported): boom",
                ),
            ],
        );
        assert_eq!(
            text,
            "job 3: 3 event(s)\n\
             1970-01-01T00:00:00.000Z  job_created  4 tasks\n\
             1970-01-01T00:00:00.000Z  job_paused\n\
             1970-01-01T00:00:00.000Z  task_retry   task 9 attempt 1 on worker 2 (reported): boom\n\
             what a worker logged for a task: tessera logs 3 --task N\n"
        );
    }
}
