//! Why a job does not finish, as its user meets it: a worker that cannot render a job's
//! tasks says why; the reason reaches the API and `tessera status` word for word, the job
//! says it is stuck once every live worker is kept off it, `submit --wait` stops with that
//! reason instead of waiting forever, and `tessera retry` lets the worker try again.

use std::time::Duration;

use proto::{FailureKind, FailureList, JobStatus, TaskList};
use tests::{http, settings, Farm};

#[test]
fn a_job_no_worker_can_render_says_why_everywhere_and_wait_stops() {
    let mut farm = Farm::new();
    farm.start_server(60);
    // The first job on a fresh server is job 1: the only worker fails all its tasks.
    farm.start_worker_with("broken", 1, &["--inject-fault", "fail-job=1"]);
    let reason = "injected fault: every task of job 1 fails";
    let scene = farm.demo_scene();
    let url = farm.url();
    let mut args = vec![
        "submit",
        scene.to_str().unwrap(),
        "--server",
        &url,
        "--frames",
        "1-2",
        "--tile",
        "32",
        "--max-attempts",
        "5",
        "--wait",
        "--out",
        "frames",
    ];
    args.extend(settings("1"));
    let out = std::process::Command::new(tests::tessera_bin())
        .args(&args)
        .current_dir(farm.path())
        .env("RUST_BACKTRACE", "1")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    // Three failures keep the worker off the job; five attempts a task, so none ran out.
    assert!(
        stderr.contains(
            "job 1 cannot go on: no live worker may take its tasks: of 1 live \
                         worker(s), 1 blocked from this job after failing its tasks"
        ) && stderr.contains(&format!(
            "most frequent failure (3 of 3 attempt(s)): {reason}"
        )),
        "{stderr}"
    );
    // Without a terminal, progress comes as lines.
    assert!(stderr.contains("job 1: 0/"), "{stderr}");
    // One line, no backtrace, even with RUST_BACKTRACE set.
    let last = stderr.trim_end().lines().last().unwrap_or_default();
    assert!(last.starts_with("error: job 1 cannot go on"), "{stderr}");
    assert!(!stderr.to_lowercase().contains("backtrace"), "{stderr}");

    let status: JobStatus = http::get(farm.port, "/api/v1/jobs/1").json();
    assert_eq!(status.attempts_failed, 3);
    assert!(status.stuck.as_deref().unwrap_or_default().contains(reason));
    let failures: FailureList = http::get(farm.port, "/api/v1/jobs/1/failures").json();
    assert_eq!(failures.groups.len(), 1, "{failures:?}");
    let g = &failures.groups[0];
    assert_eq!(
        (g.kind, g.reason.as_str(), g.attempts, g.workers.clone()),
        (FailureKind::Reported, reason, 3, vec!["broken".to_string()])
    );
    let tasks: TaskList = http::get(farm.port, "/api/v1/jobs/1/tasks?state=queued").json();
    let failed: Vec<_> = tasks.tasks.iter().flat_map(|t| &t.failures).collect();
    assert_eq!(failed.len(), 3);
    assert!(failed
        .iter()
        .all(|f| f.reason == reason && f.worker == "broken"));
    let bad = http::get(farm.port, "/api/v1/jobs/1/tasks?state=sideways");
    assert_eq!(bad.status, 400, "{}", bad.text());

    // What the worker logged for a failed task reached the server with its failure report,
    // and `tessera logs` shows it; the job's own log lists the failures.
    let task = tasks.tasks.iter().find(|t| !t.failures.is_empty()).unwrap();
    let text = farm.client(&["logs", "1", "--task", &task.id.to_string()]);
    assert!(
        text.contains(&format!(
            "attempt {} on worker broken:",
            task.failures[0].attempt
        )) && text.contains(&format!("INFO  lease taken: job 1 frame {}", task.frame))
            && text.contains(&format!(
                "WARN  task {} (job 1 frame {}) failed: {reason}",
                task.id, task.frame
            )),
        "{text}"
    );
    let text = farm.client(&["logs", "1"]);
    assert!(
        text.contains("job_created") && text.contains("worker_blocked"),
        "{text}"
    );
    assert_eq!(text.matches("task_retry").count(), 3, "{text}");

    let text = farm.client(&["status", "1"]);
    assert!(
        text.contains("  STUCK     no live worker may take its tasks"),
        "{text}"
    );
    assert!(
        text.contains(
            "3 failed attempt(s), by reason:\n  3 attempt(s) of 2 task(s) on broken, reported"
        ) && text.contains(&format!("): {reason}"))
            && text.contains("what the worker logged: tessera logs 1 --task "),
        "{text}"
    );

    // Retry lifts the block (no task ran out of attempts, yet it is not refused) and
    // forgets the failures: the worker tries again, fails three more times, and the job
    // is stuck again.
    let retried = farm.client(&["retry", "1"]);
    assert!(retried.contains("job 1"), "{retried}");
    tests::wait_until(
        "the worker to fail three more attempts",
        Duration::from_secs(60),
        || {
            let st: JobStatus = http::get(farm.port, "/api/v1/jobs/1").json();
            st.attempts_failed == 3 && st.stuck.is_some()
        },
        || farm.logs(),
    );
    // A healthy worker joins: the job can go on, and finishes.
    farm.start_worker("healthy", 1);
    let done = farm.wait_for_job(1, Duration::from_secs(120));
    assert_eq!(done.state, proto::JobState::Done, "{done:?}");
    assert_eq!(done.stuck, None);
    // A task that went well has its worker's lines too (sent with the next lease request).
    let tasks: TaskList = http::get(farm.port, "/api/v1/jobs/1/tasks?state=done").json();
    let last = tasks.tasks.iter().max_by_key(|t| t.id).unwrap();
    let text = farm.client(&["logs", "1", "--task", &last.id.to_string()]);
    assert!(
        text.contains("on worker healthy:") && text.contains("INFO  lease taken: job 1"),
        "{text}"
    );
}

#[test]
fn a_job_that_requires_tags_no_live_worker_has_says_so_until_one_comes() {
    let mut farm = Farm::new();
    farm.start_server(60);
    farm.start_worker_with("cpu-box", 1, &["--tags", "cpu,studio-a"]);
    let scene = farm.demo_scene();
    let url = farm.url();
    let mut args = vec![
        "submit",
        scene.to_str().unwrap(),
        "--server",
        &url,
        "--frames",
        "1",
        "--require-tags",
        "gpu,studio-a",
        "--wait",
    ];
    args.extend(settings("1"));
    let out = tests::tessera(&args, farm.path());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains(
            "1 without the tags it requires (gpu, studio-a); start a worker with \
                         `--tags gpu,studio-a`"
        ),
        "{stderr}"
    );
    let workers = farm.client(&["workers"]);
    assert!(workers.contains("cpu,studio-a"), "{workers}");
    farm.start_worker_with("gpu-box", 1, &["--tags", "gpu,studio-a,fast"]);
    let done = farm.wait_for_job(1, Duration::from_secs(120));
    assert_eq!(done.state, proto::JobState::Done, "{done:?}");
    let workers = farm.worker_list().workers;
    let by = |name: &str| workers.iter().find(|w| w.name == name).unwrap().tasks_done;
    assert_eq!((by("cpu-box"), by("gpu-box")), (0, 1));
}
