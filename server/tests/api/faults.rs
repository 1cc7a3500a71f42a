//! Restarts, pause, cancel, failures, expiry and duplicates, over HTTP.

use std::collections::HashSet;
use std::time::Duration;

use proto::log::{MAX_LOG_LINE_BYTES, MAX_TASK_LOG_LINES};
use proto::{
    FailureAck, FrameRange, JobEventList, JobSpec, JobState, JobStatus, LogLevel, LogLine,
    ResultAck, TaskLog,
};
use reqwest::StatusCode;

use crate::common::*;

pub(crate) fn small(digest: &str, frames: i32) -> JobSpec {
    let mut spec = JobSpec::new(digest);
    spec.frames = Some(FrameRange {
        start: 1,
        end: frames,
        step: 1,
    });
    spec.width = 16;
    spec.height = 16;
    spec.tile_size = Some(8);
    spec.spp = 2;
    spec.max_depth = 2;
    spec
}

async fn status(s: &TestServer, c: &reqwest::Client, job: u64) -> JobStatus {
    c.get(s.url(&format!("/jobs/{job}")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap()
}

#[tokio::test(flavor = "multi_thread")]
async fn kill_and_restart_mid_job_keeps_accepted_tiles_and_finishes_every_frame() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path());
    let s = TestServer::start(cfg.clone());
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    // 3 frames × 4 tiles.
    let job = create_job(&s, &c, &small(&scene.digest, 3)).await;
    let mut w = SimWorker::register(&s, "sim").await;
    let mut leases = vec![];
    for _ in 0..6 {
        leases.push(w.lease(&s).await.unwrap());
    }
    // Five tiles accepted (frame 1 complete and assembled, one of frame 2), one lease live.
    let mut accepted = HashSet::new();
    for lease in &leases[..5] {
        let (exr, _) = w.render(&s, lease).await;
        assert_eq!(w.upload(&s, lease, exr).await.status(), StatusCode::OK);
        accepted.insert(lease.token.task_id);
    }
    let live = leases[5].clone();
    s.crash();

    let s = TestServer::start(cfg);
    // The live lease was taken back at startup: its heartbeat is refused.
    let res = w.heartbeat(&s, &live).await;
    let err = error_body(res, StatusCode::CONFLICT).await;
    assert_eq!(err.error, "lease_gone");
    let after = status(&s, &c, job.id).await;
    assert_eq!(
        (after.tasks.done, after.tasks.queued, after.tasks.leased),
        (5, 7, 0)
    );
    assert_eq!(after.frames_done, 1);

    let rest = w.work_until_idle(&s).await;
    assert_eq!(rest.len(), 7);
    assert!(
        rest.iter().all(|l| !accepted.contains(&l.token.task_id)),
        "an accepted tile was leased again"
    );
    // The revoked task came back with a new attempt: its old token is fenced off.
    let again = rest
        .iter()
        .find(|l| l.token.task_id == live.token.task_id)
        .unwrap();
    assert_eq!(again.token.attempt, live.token.attempt + 1);
    let done = status(&s, &c, job.id).await;
    assert_eq!(
        (done.state, done.frames_done, done.tasks.done),
        (JobState::Done, 3, 12)
    );
    for f in 1..=3 {
        assert!(s
            .data
            .join(format!("jobs/{}/frame_{f:04}.exr", job.id))
            .is_file());
    }
}

/// Runs a one-frame job to its last tile, then crashes the server between that tile's
/// commit and the frame's write: the tile file stored, the task done, the frame complete
/// but not assembled. Returns the job and the last tile's file.
async fn crash_before_assembly(cfg: &server::Config) -> (JobStatus, std::path::PathBuf) {
    let s = TestServer::start(cfg.clone());
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let job = create_job(&s, &c, &small(&scene.digest, 1)).await;
    let mut w = SimWorker::register(&s, "sim").await;
    let mut pending = vec![];
    while let Some(lease) = w.lease(&s).await {
        let (exr, _) = w.render(&s, &lease).await;
        pending.push((lease, exr));
    }
    let (last, last_exr) = pending.pop().unwrap();
    for (lease, exr) in pending {
        assert_eq!(w.upload(&s, &lease, exr).await.status(), StatusCode::OK);
    }
    s.crash();
    let tile = server::store::Store::unopened(&cfg.data_dir).tile(
        job.id,
        last.token.task_id,
        last.token.attempt,
    );
    std::fs::write(&tile, &last_exr).unwrap();
    let db = rusqlite::Connection::open(cfg.data_dir.join("tessera.db")).unwrap();
    db.execute(
        "UPDATE tasks SET state = 'done', done_ms = 1 WHERE id = ?1",
        [last.token.task_id],
    )
    .unwrap();
    db.execute("UPDATE frames SET tasks_done = tasks_total", [])
        .unwrap();
    (job, tile)
}

/// Polls the job until `done` holds of its status.
async fn wait_for(
    s: &TestServer,
    c: &reqwest::Client,
    job: u64,
    done: impl Fn(&JobStatus) -> bool,
) -> JobStatus {
    for _ in 0..600 {
        let st = status(s, c, job).await;
        if done(&st) {
            return st;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("job {job}: {:?}", status(s, c, job).await);
}

#[tokio::test(flavor = "multi_thread")]
async fn a_frame_whose_tiles_were_in_but_not_assembled_is_assembled_after_startup() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.sweep_interval = Duration::from_millis(50);
    let (job, _) = crash_before_assembly(&cfg).await;

    // The server answers first and assembles in the background.
    let s = TestServer::start(cfg.clone());
    let c = client();
    let done = wait_for(&s, &c, job.id, |st| st.frames_done == 1).await;
    assert_eq!(done.state, JobState::Done);
    assert!(cfg
        .data_dir
        .join(format!("jobs/{}/frame_0001.exr", job.id))
        .is_file());
    assert!(cfg
        .data_dir
        .join(format!("jobs/{}/frame_0001.png", job.id))
        .is_file());
}

/// A stored tile that no longer reads (a damaged disk, a file truncated by hand) fails its
/// frame with the reason instead of being tried forever; once the file is mended, retrying
/// the job assembles the frame.
#[tokio::test(flavor = "multi_thread")]
async fn a_frame_with_an_unreadable_tile_fails_with_the_reason_and_a_retry_mends_it() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.sweep_interval = Duration::from_millis(50);
    let (job, tile) = crash_before_assembly(&cfg).await;
    let good = std::fs::read(&tile).unwrap();
    std::fs::write(&tile, &good[..good.len() / 2]).unwrap();

    let s = TestServer::start(cfg.clone());
    let c = client();
    let failed = wait_for(&s, &c, job.id, |st| st.frames_failed == 1).await;
    assert_eq!((failed.state, failed.frames_done), (JobState::Failed, 0));
    let frames: proto::FrameList = c
        .get(s.url(&format!("/jobs/{}/frames", job.id)))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let frame = &frames.frames[0];
    assert_eq!(frame.state, proto::FrameState::Failed);
    let why = frame.failure.as_deref().unwrap_or_default();
    assert!(why.contains("reading the tile of task"), "{why}");

    std::fs::write(&tile, &good).unwrap();
    let retried = c
        .post(s.url(&format!("/jobs/{}/retry", job.id)))
        .send()
        .await
        .unwrap();
    assert!(retried.status().is_success(), "{}", retried.status());
    let done = wait_for(&s, &c, job.id, |st| st.frames_done == 1).await;
    assert_eq!((done.state, done.frames_failed), (JobState::Done, 0));
}

#[tokio::test(flavor = "multi_thread")]
async fn pause_and_cancel_reach_a_working_worker_as_409() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let job = create_job(&s, &c, &small(&scene.digest, 1)).await;
    let mut w = SimWorker::register(&s, "sim").await;
    let lease = w.lease(&s).await.unwrap();
    assert_eq!(w.heartbeat(&s, &lease).await.status(), StatusCode::OK);

    let paused: JobStatus = c
        .post(s.url(&format!("/jobs/{}/pause", job.id)))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(paused.state, JobState::Paused);
    let err = error_body(w.heartbeat(&s, &lease).await, StatusCode::CONFLICT).await;
    assert_eq!(err.error, "lease_gone");
    assert!(err.message.contains("paused"), "{}", err.message);
    // Its tile is refused too, and nothing is leased while paused.
    let (exr, _) = w.render(&s, &lease).await;
    assert_eq!(
        w.upload(&s, &lease, exr).await.status(),
        StatusCode::CONFLICT
    );
    assert!(w.lease(&s).await.is_none());

    c.post(s.url(&format!("/jobs/{}/resume", job.id)))
        .send()
        .await
        .unwrap();
    let again = w.lease(&s).await.unwrap();
    assert_eq!(again.token.task_id, lease.token.task_id);
    assert_eq!(again.token.attempt, 2);

    let cancelled: JobStatus = c
        .post(s.url(&format!("/jobs/{}/cancel", job.id)))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(cancelled.state, JobState::Cancelled);
    let err = error_body(w.heartbeat(&s, &again).await, StatusCode::CONFLICT).await;
    assert!(err.message.contains("cancelled"), "{}", err.message);
    let res = c
        .post(s.url(&format!("/jobs/{}/resume", job.id)))
        .send()
        .await
        .unwrap();
    assert_eq!(
        error_body(res, StatusCode::CONFLICT).await.error,
        "conflict"
    );
    assert!(w.lease(&s).await.is_none());
}

#[tokio::test(flavor = "multi_thread")]
async fn a_second_upload_is_accepted_once_and_ignored_after() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    create_job(&s, &c, &small(&scene.digest, 1)).await;
    let mut w = SimWorker::register(&s, "sim").await;
    let lease = w.lease(&s).await.unwrap();
    let (exr, _) = w.render(&s, &lease).await;
    let first: ResultAck = w
        .upload(&s, &lease, exr.clone())
        .await
        .json()
        .await
        .unwrap();
    assert!(first.accepted);
    let second = w.upload(&s, &lease, exr).await;
    assert_eq!(second.status(), StatusCode::OK);
    let second: ResultAck = second.json().await.unwrap();
    assert!(!second.accepted);
    let metrics = metrics(&s, &c).await;
    assert!(
        metrics.contains("tessera_tiles_received_total 1\n"),
        "{metrics}"
    );
}

#[tokio::test(flavor = "multi_thread")]
async fn failures_past_max_attempts_fail_the_job_and_retry_finishes_it() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut spec = small(&scene.digest, 2);
    spec.max_attempts = 1;
    let job = create_job(&s, &c, &spec).await;
    let mut w = SimWorker::register(&s, "sim").await;
    let lease = w.lease(&s).await.unwrap();
    let ack: FailureAck = w
        .fail(&s, &lease, "out of memory")
        .await
        .json()
        .await
        .unwrap();
    assert!(ack.task_failed && !ack.requeued);
    // The job is failed, but the other frame still finishes.
    assert_eq!(w.work_until_idle(&s).await.len(), 7);
    let st = status(&s, &c, job.id).await;
    assert_eq!(
        (st.state, st.frames_done, st.frames_failed, st.tasks.failed),
        (JobState::Failed, 1, 1, 1)
    );
    // A failure report for a lease that is no longer current is refused.
    assert_eq!(
        w.fail(&s, &lease, "again").await.status(),
        StatusCode::CONFLICT
    );

    let retried: JobStatus = c
        .post(s.url(&format!("/jobs/{}/retry", job.id)))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(retried.tasks.queued, 1);
    assert_eq!(w.work_until_idle(&s).await.len(), 1);
    let st = status(&s, &c, job.id).await;
    assert_eq!((st.state, st.frames_done), (JobState::Done, 2));
}

fn line(at_ms: i64, level: LogLevel, text: &str) -> LogLine {
    LogLine {
        at_ms,
        level,
        text: text.into(),
    }
}

#[tokio::test(flavor = "multi_thread")]
async fn a_task_log_keeps_the_lines_of_each_attempt_bounded_and_the_job_log_lists_events() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    // One task, so that the failed one is the one leased next.
    let mut spec = small(&scene.digest, 1);
    spec.tile_size = Some(16);
    let job = create_job(&s, &c, &spec).await;
    let w = SimWorker::register(&s, "sim").await;
    let first = w.lease(&s).await.unwrap();
    let task = first.token.task_id;
    let beat = w
        .heartbeat_logging(&s, &first, vec![line(1, LogLevel::Info, "lease taken")])
        .await;
    assert_eq!(beat.status(), StatusCode::OK);
    let long = "x".repeat(MAX_LOG_LINE_BYTES + 10);
    let report = vec![
        line(2, LogLevel::Error, "scene: mesh 3 has no positions"),
        line(3, LogLevel::Warn, &long),
    ];
    assert_eq!(
        w.fail_logging(&s, &first, "scene: mesh 3 has no positions", report)
            .await
            .status(),
        StatusCode::OK
    );
    // The second attempt logs more lines than are kept.
    let second = w.lease(&s).await.unwrap();
    assert_eq!(second.token.task_id, task);
    let flood: Vec<LogLine> = (0..MAX_TASK_LOG_LINES + 5)
        .map(|i| line(10 + i as i64, LogLevel::Info, &format!("line {i}")))
        .collect();
    for part in flood.chunks(90) {
        let beat = w.heartbeat_logging(&s, &second, part.to_vec()).await;
        assert_eq!(beat.status(), StatusCode::OK);
    }
    // Lines for a lease that is gone are refused with it, not kept.
    let stale = w
        .heartbeat_logging(&s, &first, vec![line(9, LogLevel::Info, "late")])
        .await;
    assert_eq!(stale.status(), StatusCode::CONFLICT);

    let log: TaskLog = c
        .get(s.url(&format!("/jobs/{}/tasks/{task}/log", job.id)))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(log.task_id, task);
    assert_eq!(log.attempts.len(), 2);
    let (a, b) = (&log.attempts[0], &log.attempts[1]);
    assert_eq!(
        (a.attempt, a.worker.as_str(), a.truncated),
        (1, "sim", false)
    );
    let texts: Vec<&str> = a.lines.iter().map(|l| &l.text[..]).collect();
    assert_eq!(
        texts[..2],
        ["lease taken", "scene: mesh 3 has no positions"]
    );
    assert_eq!(a.lines[1].level, LogLevel::Error);
    assert_eq!(texts[2].len(), MAX_LOG_LINE_BYTES, "a long line is cut");
    assert_eq!(
        (b.attempt, b.lines.len(), b.truncated),
        (2, MAX_TASK_LOG_LINES, true)
    );
    assert_eq!(
        b.lines.last().unwrap().text,
        format!("line {}", MAX_TASK_LOG_LINES - 1)
    );

    // A task of another job, and a job that does not exist: 404.
    let other = create_job(&s, &c, &small(&scene.digest, 1)).await;
    for path in [
        format!("/jobs/{}/tasks/{task}/log", other.id),
        format!("/jobs/999/tasks/{task}/log"),
        "/jobs/999/log".to_string(),
    ] {
        let res = c.get(s.url(&path)).send().await.unwrap();
        assert_eq!(res.status(), StatusCode::NOT_FOUND, "{path}");
    }

    // The job's event log, a page at a time.
    let page = |after: u64, limit: u32| {
        let url = s.url(&format!("/jobs/{}/log?after={after}&limit={limit}", job.id));
        let c = c.clone();
        async move {
            let list: JobEventList = c.get(url).send().await.unwrap().json().await.unwrap();
            list
        }
    };
    let first_page = page(0, 1).await;
    assert_eq!(first_page.events[0].kind, "job_created");
    let rest = page(first_page.next_after.unwrap(), 1000).await;
    assert_eq!(rest.next_after, None);
    let kinds: Vec<&str> = rest.events.iter().map(|e| &e.kind[..]).collect();
    assert_eq!(kinds, ["task_retry"]);
    assert!(rest.events[0]
        .detail
        .contains("scene: mesh 3 has no positions"));
}

#[tokio::test(flavor = "multi_thread")]
async fn lines_logged_after_the_last_heartbeat_come_with_the_next_lease_request() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let job = create_job(&s, &c, &small(&scene.digest, 1)).await;
    let mut w = SimWorker::register(&s, "sim").await;
    let other = SimWorker::register(&s, "other").await;
    let done = w.lease(&s).await.unwrap();
    let (exr, _) = w.render(&s, &done).await;
    assert_eq!(w.upload(&s, &done, exr).await.status(), StatusCode::OK);
    let late = |text: &str| proto::LeaseRequest {
        wait_seconds: 0,
        last_task_log: Some(proto::TaskLogLines {
            token: done.token,
            lines: vec![line(5, LogLevel::Info, text)],
        }),
    };
    // The worker that rendered it: kept. Another worker claiming it: dropped.
    assert!(w.lease_with(&s, late("tile uploaded")).await.is_some());
    assert!(other.lease_with(&s, late("not mine")).await.is_some());
    let log: TaskLog = c
        .get(s.url(&format!(
            "/jobs/{}/tasks/{}/log",
            job.id, done.token.task_id
        )))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let texts: Vec<&str> = log
        .attempts
        .iter()
        .flat_map(|a| &a.lines)
        .map(|l| &l.text[..])
        .collect();
    assert_eq!(texts, ["tile uploaded"]);
}

#[tokio::test(flavor = "multi_thread")]
async fn an_expired_lease_is_requeued_and_its_worker_hears_409() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.lease = Duration::from_secs(1);
    cfg.sweep_interval = Duration::from_millis(50);
    let s = TestServer::start(cfg);
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let job = create_job(&s, &c, &small(&scene.digest, 1)).await;
    let w = SimWorker::register(&s, "sim").await;
    let lease = w.lease(&s).await.unwrap();
    // Wait, without heartbeats, until the sweeper has taken the lease back.
    loop {
        let st = status(&s, &c, job.id).await;
        if st.tasks.leased == 0 {
            assert_eq!(st.tasks.queued, 4);
            break;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let err = error_body(w.heartbeat(&s, &lease).await, StatusCode::CONFLICT).await;
    assert!(err.message.contains("expired"), "{}", err.message);
    // It counts as this worker's failed attempt: with no other worker, it comes back to
    // it last, as attempt 2.
    let mut leases = vec![];
    while let Some(l) = w.lease(&s).await {
        leases.push(l.token);
    }
    assert_eq!(leases.len(), 4);
    assert_eq!(
        leases[3],
        proto::TaskToken {
            task_id: lease.token.task_id,
            attempt: 2
        }
    );
}

#[tokio::test(flavor = "multi_thread")]
async fn a_worker_that_leaves_gives_its_lease_back_at_once_without_an_attempt() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    // One attempt only: had leaving counted as a failure, the task would now be failed.
    let mut spec = small(&scene.digest, 1);
    spec.max_attempts = 1;
    let job = create_job(&s, &c, &spec).await;
    let leaving = SimWorker::register(&s, "leaving").await;
    let lease = leaving.lease(&s).await.unwrap();
    assert_eq!(status(&s, &c, job.id).await.tasks.leased, 1);

    let res = leaving
        .auth(
            leaving
                .client
                .post(s.url(&format!("/workers/{}/leave", leaving.id))),
        )
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::OK);
    let left: proto::WorkerLeft = res.json().await.unwrap();
    assert_eq!(left.jobs, vec![job.id]);
    let st = status(&s, &c, job.id).await;
    assert_eq!(
        (st.tasks.leased, st.tasks.queued, st.tasks.failed),
        (0, 4, 0)
    );
    assert_ne!(st.state, JobState::Failed);

    // The id takes no more calls, and the list shows it offline.
    let err = error_body(leaving.heartbeat(&s, &lease).await, StatusCode::NOT_FOUND).await;
    assert!(err.message.contains("left"), "{}", err.message);
    let workers: proto::WorkerList = c
        .get(s.url("/workers"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let info = workers.workers.iter().find(|w| w.id == leaving.id).unwrap();
    assert!(!info.online && info.current_task.is_none());

    // Another worker takes the task under a new fencing token and finishes the job.
    let mut other = SimWorker::register(&s, "other").await;
    let done = other.work_until_idle(&s).await;
    assert_eq!(done.len(), 4);
    let again = done
        .iter()
        .find(|l| l.token.task_id == lease.token.task_id)
        .unwrap();
    assert_eq!(again.token.attempt, lease.token.attempt + 1);
    assert_eq!(status(&s, &c, job.id).await.state, JobState::Done);
}

#[tokio::test(flavor = "multi_thread")]
async fn delete_removes_the_job_and_its_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let job = create_job(&s, &c, &small(&scene.digest, 1)).await;
    let mut w = SimWorker::register(&s, "sim").await;
    w.work_until_idle(&s).await;
    let out = s.data.join(format!("jobs/{}", job.id));
    assert!(out.join("frame_0001.exr").is_file());
    let res = c
        .delete(s.url(&format!("/jobs/{}", job.id)))
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::NO_CONTENT);
    assert!(!out.exists());
    let res = c
        .get(s.url(&format!("/jobs/{}", job.id)))
        .send()
        .await
        .unwrap();
    assert_eq!(
        error_body(res, StatusCode::NOT_FOUND).await.error,
        "not_found"
    );
}

#[tokio::test(flavor = "multi_thread")]
async fn a_frame_that_failed_to_write_is_assembled_once_the_disk_recovers() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.sweep_interval = Duration::from_millis(50);
    let s = TestServer::start(cfg);
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let job = create_job(&s, &c, &small(&scene.digest, 1)).await;
    // A file where the job's output folder should be: writing the frame fails.
    let out = s.data.join(format!("jobs/{}", job.id));
    std::fs::write(&out, b"in the way").unwrap();
    let mut w = SimWorker::register(&s, "sim").await;
    let mut last = None;
    while let Some(lease) = w.lease(&s).await {
        let (exr, _) = w.render(&s, &lease).await;
        last = Some((w.upload(&s, &lease, exr.clone()).await.status(), lease, exr));
    }
    let (status_code, lease, exr) = last.unwrap();
    assert_eq!(status_code, StatusCode::INTERNAL_SERVER_ERROR);
    // The tile itself was accepted: sending it again is a duplicate.
    let again: ResultAck = w.upload(&s, &lease, exr).await.json().await.unwrap();
    assert!(!again.accepted);
    assert_eq!(status(&s, &c, job.id).await.frames_done, 0);
    // The disk recovers; the sweeper writes the frame.
    std::fs::remove_file(&out).unwrap();
    loop {
        let st = status(&s, &c, job.id).await;
        if st.frames_done == 1 {
            assert_eq!(st.state, JobState::Done);
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(out.join("frame_0001.exr").is_file());
}
