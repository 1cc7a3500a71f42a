//! Shutdown in the middle of a task, a server that forgets the worker, a wrong token.

use std::time::{Duration, Instant};

use proto::JobState;

use crate::common::*;

/// Samples per pixel that keep a 16×16 tile busy for a good second on two threads (2048
/// did when the tracer was four times slower; by now it renders in about 0.25 s, near the
/// 200 ms the shutdown test waits before it stops the worker).
const SLOW_SPP: u32 = 8192;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_mid_task_gives_the_lease_back_at_once() {
    let Setup {
        dir, s, c, scene, ..
    } = setup().await;
    let mut slow = spec(&scene.digest, 2, SLOW_SPP, 1);
    slow.width = 16;
    slow.height = 16;
    slow.max_depth = 1;
    let slow_job = create_job(&s, &c, &slow).await;
    assert_eq!(slow_job.tasks.queued, 2);

    let cache = dir.path().join("cache");
    let first = TestWorker::start(&s.base, &cache, None);
    wait_for(&s, &c, slow_job.id, Duration::from_secs(20), |j| {
        j.tasks.leased == 1
    })
    .await;
    // Let the render get going (the scene is tiny: fetched and prepared at once).
    tokio::time::sleep(Duration::from_millis(200)).await;
    let asked = Instant::now();
    let summary = first.shutdown().await.unwrap();
    let took = asked.elapsed();
    // The render was cancelled, not finished and uploaded.
    assert_eq!(summary.tasks_done, 0, "{summary:?}");
    assert_eq!(summary.tasks_interrupted, 1, "{summary:?}");
    assert!(took < Duration::from_secs(5), "shutdown took {took:?}");
    // The lease is back in the queue now, not after the 60 s lease expires, and no
    // attempt was counted against it.
    let status = job(&s, &c, slow_job.id).await;
    assert_eq!(status.tasks.leased, 0, "{status:?}");
    assert_eq!(status.tasks.queued, 2, "{status:?}");

    let second = TestWorker::start(&s.base, &cache, None);
    let done = wait_until_done(&s, &c, slow_job.id).await;
    assert_eq!((done.frames_done, done.frames_total), (2, 2));
    let summary = second.shutdown().await.unwrap();
    assert_eq!(summary.tasks_done, 2);
    // The first worker cached the scene; the second found it there.
    assert_eq!(summary.scenes_downloaded, 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_heartbeat_answered_409_stops_the_render() {
    init_logs();
    let dir = tempfile::tempdir().unwrap();
    let mut config = server_config(dir.path());
    // 4 s leases: a heartbeat every second.
    config.lease = Duration::from_secs(4);
    let s = TestServer::start(config).kill_on_drop();
    let c = client();
    let scene = upload_scene(&s, &c, spinning_quad()).await;
    // One tile that takes several seconds.
    let mut slow = spec(&scene.digest, 1, 4 * SLOW_SPP, 1);
    slow.width = 16;
    slow.height = 16;
    slow.max_depth = 1;
    let slow_job = create_job(&s, &c, &slow).await;
    let w = TestWorker::start(&s.base, &dir.path().join("cache"), None);
    wait_for(&s, &c, slow_job.id, Duration::from_secs(20), |j| {
        j.tasks.leased == 1
    })
    .await;
    let res = c
        .post(s.url(&format!("/jobs/{}/cancel", slow_job.id)))
        .send()
        .await
        .unwrap();
    assert!(res.status().is_success());
    // The next heartbeat (within a second) hears 409 and the render stops; it would take
    // several seconds to finish.
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let summary = w.shutdown().await.unwrap();
    assert_eq!(
        (
            summary.tasks_done,
            summary.tasks_abandoned,
            summary.tasks_interrupted
        ),
        (0, 1, 0),
        "{summary:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_whose_server_lost_its_data_registers_again() {
    init_logs();
    let dir = tempfile::tempdir().unwrap();
    let mut config = server_config(&dir.path().join("a"));
    // Short long polls, so the killed server's last answer comes quickly.
    config.max_lease_wait = Duration::from_secs(1);
    // An address no other test's server takes while this one is down between the two.
    let addr = free_addr();
    let first = TestServer::start_on(bind_again(addr), config.clone()).kill_on_drop();
    let w = TestWorker::start(&first.base, &dir.path().join("cache"), None);
    // Registered and polling.
    wait_for_a_worker(&first).await;
    let c = client();
    // The server lists the worker as soon as it commits the registration; give the answer
    // time to reach the worker (else it registers only once, with the second server).
    tokio::time::sleep(Duration::from_millis(300)).await;
    first.crash();
    // A new server with an empty data folder on the same address: worker 1 is unknown
    // there, so the worker's next lease is answered 404 and it registers again.
    tokio::time::sleep(Duration::from_millis(500)).await;
    let mut config = server_config(&dir.path().join("b"));
    config.max_lease_wait = Duration::from_secs(1);
    let s = TestServer::start_on(bind_again(addr), config).kill_on_drop();
    let glb = spinning_quad();
    let scene = upload_scene(&s, &c, glb).await;
    let job = create_job(&s, &c, &spec(&scene.digest, 1, 1, 1)).await;
    let status = wait_until_done(&s, &c, job.id).await;
    assert_eq!(status.state, JobState::Done);
    let summary = w.shutdown().await.unwrap();
    assert_eq!(summary.registrations, 2, "{summary:?}");
    assert_eq!(summary.tasks_done, 4);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_wrong_token_stops_the_worker_with_a_clear_error() {
    init_logs();
    let dir = tempfile::tempdir().unwrap();
    let mut config = server_config(dir.path());
    config.worker_token = Some("right".into());
    let s = TestServer::start(config).kill_on_drop();
    let w = TestWorker::start(&s.base, &dir.path().join("cache"), Some("wrong"));
    let err = w.finished().await.unwrap_err();
    let text = format!("{err:#}");
    assert!(text.contains("401") && text.contains("token"), "{text}");

    // The right token works.
    let w = TestWorker::start(&s.base, &dir.path().join("cache"), Some("right"));
    wait_for_a_worker(&s).await;
    let summary = w.shutdown().await.unwrap();
    assert_eq!(summary.registrations, 1);
}
