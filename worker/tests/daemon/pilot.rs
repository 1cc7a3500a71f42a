//! Workers started as cluster jobs leave by themselves: when idle, after their tasks, or
//! when drained; the server lists them gone, and nothing counts as failed.

use std::time::{Duration, Instant};

use proto::JobState;
use worker::{Ending, PilotLimits, WorkerConfig};

use crate::common::*;

fn pilot(s: &TestServer, dir: &std::path::Path, limits: PilotLimits) -> TestWorker {
    TestWorker::start_config(WorkerConfig {
        pilot: limits,
        ..worker_config(&s.base, &dir.join("cache"))
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_idle_worker_leaves_by_itself_and_is_listed_gone() {
    let Setup { dir, s, .. } = setup().await;
    let started = Instant::now();
    let limits = PilotLimits {
        exit_when_idle: Some(Duration::from_secs(1)),
        max_tasks: None,
    };
    let summary = pilot(&s, dir.path(), limits).finished().await.unwrap();
    let took = started.elapsed();
    assert_eq!((summary.ended, summary.registrations), (Ending::Idle, 1));
    // The long poll is cut to the idle time left, so it leaves on time.
    assert!(
        took >= Duration::from_secs(1) && took < Duration::from_secs(8),
        "{took:?}"
    );
    let list = workers(&s).await;
    assert_eq!(list.workers.len(), 1);
    assert!(!list.workers[0].online, "{list:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_leaves_after_its_tasks_and_the_rest_stay_queued() {
    let Setup {
        dir, s, c, scene, ..
    } = setup().await;
    let job = create_job(&s, &c, &spec(&scene.digest, 1, 4, 1)).await;
    assert_eq!(job.tasks.queued, 4);
    let limits = PilotLimits {
        exit_when_idle: None,
        max_tasks: Some(2),
    };
    let summary = pilot(&s, dir.path(), limits).finished().await.unwrap();
    assert_eq!((summary.ended, summary.tasks_done), (Ending::MaxTasks, 2));
    let status = crate::common::job(&s, &c, job.id).await;
    assert_eq!(
        (status.tasks.done, status.tasks.queued, status.tasks.leased),
        (2, 2, 0),
        "{status:?}"
    );
    assert_eq!((status.tasks.failed, status.state), (0, JobState::Running));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drained_worker_finishes_the_task_in_hand_then_leaves() {
    let Setup {
        dir, s, c, scene, ..
    } = setup().await;
    // Many samples per tile, so that the drain comes while one renders.
    let job = create_job(&s, &c, &spec(&scene.digest, 2, 256, 1)).await;
    let mut w = pilot(&s, dir.path(), PilotLimits::default());
    // The task is in hand once its scene is in the worker's cache. (The server listing a
    // lease is not enough: a drain that reaches the worker before the lease's answer ends
    // the poll, and the lease is given back, not worked on.)
    let cache = dir.path().join("cache");
    let started = Instant::now();
    while !cache.is_dir() || cache_entries(&cache).0.is_empty() {
        assert!(started.elapsed() < Duration::from_secs(20), "no task taken");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    w.drain();
    let summary = w.finished().await.unwrap();
    assert_eq!(summary.ended, Ending::Drained);
    assert!(summary.tasks_done >= 1, "{summary:?}");
    assert_eq!(
        (summary.tasks_interrupted, summary.tasks_failed),
        (0, 0),
        "the task in hand was finished: {summary:?}"
    );
    let status = crate::common::job(&s, &c, job.id).await;
    assert_eq!(status.tasks.done, summary.tasks_done, "{status:?}");
    assert_eq!(
        (status.tasks.leased, status.tasks.failed),
        (0, 0),
        "{status:?}"
    );
    assert!(status.tasks.queued > 0, "it left work behind: {status:?}");
}
