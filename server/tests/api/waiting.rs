//! A worker's lease request that waits for work is answered as soon as there is some: a
//! new job, or a task that an accepted tile queued.

use std::time::Duration;

use reqwest::StatusCode;

use crate::common::*;
use crate::faults::small;

#[tokio::test(flavor = "multi_thread")]
async fn a_waiting_lease_request_wakes_when_a_job_arrives() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let w = SimWorker::register(&s, "sim").await;
    assert!(w.lease(&s).await.is_none());
    let waiting = w.lease_waiting(&s, 30);
    let job = create_job(&s, &c, &small(&scene.digest, 1)).await;
    let res = waiting.await.unwrap();
    assert_eq!(res.status(), StatusCode::OK);
    let lease: proto::Lease = res.json().await.unwrap();
    assert_eq!(lease.job_id, job.id);
}

#[tokio::test(flavor = "multi_thread")]
async fn a_waiting_lease_request_wakes_when_a_check_is_queued() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.verify_fraction = 1.0;
    let s = TestServer::start(cfg);
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut spec = small(&scene.digest, 1);
    spec.tile_size = Some(spec.width.max(spec.height));
    create_job(&s, &c, &spec).await;
    let mut a = SimWorker::register(&s, "a").await;
    let b = SimWorker::register(&s, "b").await;
    let lease = a.lease(&s).await.expect("the one tile");
    assert!(b.lease(&s).await.is_none());

    // b waits for work; a's tile, once accepted, is checked by another worker: b.
    let waiting = b.lease_waiting(&s, 30);
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(
        !waiting.is_finished(),
        "b got an answer with no work queued"
    );
    let (exr, _) = a.render(&s, &lease).await;
    assert_eq!(a.upload(&s, &lease, exr).await.status(), StatusCode::OK);
    // Without a wake-up the request ran out after 30 s and answered 204.
    let res = waiting.await.unwrap();
    assert_eq!(res.status(), StatusCode::OK);
    let check: proto::Lease = res.json().await.unwrap();
    assert_ne!(check.token.task_id, lease.token.task_id);
    assert_eq!((check.frame, check.tile), (lease.frame, lease.tile));
}
