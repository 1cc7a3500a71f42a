//! Webhooks: a receiver on loopback is told when a job ends, with a body signed by the
//! server's secret; a receiver that fails is tried again with the same notification.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::body::Bytes;
use axum::http::{HeaderMap, StatusCode};
use hmac::{Hmac, Mac};
use proto::{FrameRange, JobSpec, JobState, Notification, NotificationKind};

use crate::common::*;

const SECRET: &str = "hook-secret";

/// What a receiver got: each request's signature, delivery id and body.
type Received = Arc<Mutex<Vec<(String, String, Vec<u8>)>>>;

/// A receiver on loopback that answers 500 to its first `failures` requests, then 200.
async fn receiver(failures: usize) -> (String, Received) {
    let got: Received = Arc::default();
    let seen = got.clone();
    let app = axum::Router::new().route(
        "/hook",
        axum::routing::post(move |headers: HeaderMap, body: Bytes| {
            let seen = seen.clone();
            async move {
                let header = |name| {
                    headers
                        .get(name)
                        .and_then(|v| v.to_str().ok())
                        .unwrap_or_default()
                        .to_string()
                };
                let mut seen = seen.lock().unwrap();
                seen.push((
                    header(Notification::SIGNATURE),
                    header(Notification::DELIVERY),
                    body.to_vec(),
                ));
                if seen.len() <= failures {
                    StatusCode::INTERNAL_SERVER_ERROR
                } else {
                    StatusCode::OK
                }
            }
        }),
    );
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let url = format!("http://{}/hook", listener.local_addr().unwrap());
    tokio::spawn(async move { axum::serve(listener, app).await.unwrap() });
    (url, got)
}

async fn wait_for(got: &Received, n: usize) {
    let until = Instant::now() + Duration::from_secs(30);
    while got.lock().unwrap().len() < n {
        assert!(
            Instant::now() < until,
            "{} deliveries, not {n}",
            got.lock().unwrap().len()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

fn hmac_hex(body: &[u8]) -> String {
    let mut mac = Hmac::<sha2::Sha256>::new_from_slice(SECRET.as_bytes()).unwrap();
    mac.update(body);
    let bytes = mac.finalize().into_bytes();
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[tokio::test(flavor = "multi_thread")]
async fn a_finished_job_is_told_signed_to_every_webhook_and_a_failed_delivery_is_retried() {
    let (farm_hook, farm_got) = receiver(1).await;
    let (job_hook, job_got) = receiver(0).await;
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.webhooks = vec![farm_hook];
    cfg.webhook_secret = Some(SECRET.into());
    cfg.sweep_interval = Duration::from_millis(50);
    let s = TestServer::start(cfg);
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut spec = JobSpec::new(&scene.digest);
    spec.frames = Some(FrameRange {
        start: 1,
        end: 1,
        step: 1,
    });
    (spec.width, spec.height, spec.spp) = (16, 16, 1);
    spec.webhook = Some(job_hook);
    let job = create_job(&s, &c, &spec).await;
    let mut w = SimWorker::register(&s, "sim").await;
    w.work_until_idle(&s).await;

    // The server's webhook failed once and was told again: the same notification, signed.
    wait_for(&farm_got, 2).await;
    wait_for(&job_got, 1).await;
    let farm_got = farm_got.lock().unwrap().clone();
    assert_eq!(farm_got[0], farm_got[1], "a retry repeats the delivery");
    let (signature, delivery, body) = &farm_got[0];
    assert_eq!(signature, &format!("sha256={}", hmac_hex(body)));
    let told: Notification = serde_json::from_slice(body).unwrap();
    assert_eq!(delivery, &told.id.to_string());
    assert_eq!(told.event, NotificationKind::JobDone);
    let status = told.job.unwrap();
    assert_eq!((status.id, status.state), (job.id, JobState::Done));
    // The job's own webhook got the same.
    assert_eq!(job_got.lock().unwrap()[0].2, *body);
    // Delivered: nothing more comes.
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(job_got.lock().unwrap().len(), 1);
}

#[tokio::test(flavor = "multi_thread")]
async fn a_job_webhook_needs_a_server_secret_and_an_http_url() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    for (url, words) in [
        ("https://hooks.example.com/t", "no webhook secret"),
        (
            "ftp://hooks.example.com/t",
            "not an http:// or https:// URL",
        ),
    ] {
        let mut spec = JobSpec::new(&scene.digest);
        spec.webhook = Some(url.into());
        let res = c.post(s.url("/jobs")).json(&spec).send().await.unwrap();
        assert_eq!(res.status(), StatusCode::UNPROCESSABLE_ENTITY);
        let text = res.text().await.unwrap();
        assert!(text.contains(words), "{text}");
    }
}
