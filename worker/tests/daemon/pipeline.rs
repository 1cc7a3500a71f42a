//! A worker renders its next tile while the last one uploads, with one upload in flight at
//! most, and keeps the waiting tile's lease: a proxy between worker and server holds
//! uploads back until the test lets them go.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use axum::body::{Body, Bytes};
use axum::extract::{Request, State};
use axum::http::{Method, StatusCode};
use axum::response::Response;
use tokio::sync::watch;

use crate::common::*;

/// Forwards every request to the server; a tile upload waits until `open` is true.
#[derive(Clone)]
struct Gate {
    server: String,
    http: reqwest::Client,
    open: watch::Receiver<bool>,
    /// Uploads that reached the proxy.
    uploads: Arc<AtomicUsize>,
}

async fn forward(State(gate): State<Gate>, req: Request) -> Response {
    let (parts, body) = req.into_parts();
    let path = parts.uri.path_and_query().map_or("/", |p| p.as_str());
    if parts.method == Method::POST && path.ends_with("/result") {
        gate.uploads.fetch_add(1, Ordering::SeqCst);
        let _ = gate.open.clone().wait_for(|open| *open).await;
    }
    let body: Bytes = axum::body::to_bytes(body, usize::MAX).await.unwrap();
    let mut out = gate
        .http
        .request(parts.method, format!("{}{path}", gate.server));
    for (name, value) in &parts.headers {
        if name != "host" && name != "content-length" {
            out = out.header(name, value);
        }
    }
    let Ok(answer) = out.body(body).send().await else {
        return Response::builder()
            .status(StatusCode::BAD_GATEWAY)
            .body(Body::empty())
            .unwrap();
    };
    let mut res = Response::builder().status(answer.status());
    for (name, value) in answer.headers() {
        if name != "content-length" && name != "transfer-encoding" {
            res = res.header(name, value);
        }
    }
    res.body(Body::from(answer.bytes().await.unwrap())).unwrap()
}

/// A gate proxy for the server at `server`: its URL, the sender that opens it, and the
/// count of uploads that reached it.
async fn start_gate(server: &str) -> (String, watch::Sender<bool>, Arc<AtomicUsize>) {
    let (open, gate_open) = watch::channel(false);
    let gate = Gate {
        server: server.to_string(),
        http: reqwest::Client::new(),
        open: gate_open,
        uploads: Arc::new(AtomicUsize::new(0)),
    };
    let uploads = gate.uploads.clone();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    let app = axum::Router::new().fallback(forward).with_state(gate);
    // It serves until the test's runtime ends.
    tokio::spawn(async move { axum::serve(listener, app).await });
    (url, open, uploads)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_next_tile_renders_while_the_last_one_uploads() {
    let Setup {
        dir,
        s,
        c,
        glb,
        scene,
    } = setup().await;
    let (proxy, open, uploads) = start_gate(&s.base).await;
    // One frame of 2x2 tiles.
    let spec = spec(&scene.digest, 1, 2, 1);
    let created = create_job(&s, &c, &spec).await;
    let w = TestWorker::start(&proxy, &dir.path().join("cache"), None);

    // The first tile's upload is held: the worker leases and renders the second meanwhile.
    let held = wait_for(&s, &c, created.id, Duration::from_secs(30), |j| {
        j.tasks.leased == 2
    })
    .await;
    assert_eq!(held.tasks.done, 0, "{held:?}");
    // The second tile renders in milliseconds; its upload waits for the first, and no
    // third lease is taken while two tiles are unsent.
    tokio::time::sleep(Duration::from_millis(500)).await;
    let still = job(&s, &c, created.id).await;
    assert_eq!((still.tasks.leased, still.tasks.done), (2, 0), "{still:?}");
    assert_eq!(uploads.load(Ordering::SeqCst), 1);

    open.send(true).unwrap();
    wait_until_done(&s, &c, created.id).await;
    let summary = w.shutdown().await.unwrap();
    assert_eq!(
        (
            summary.tasks_done,
            summary.tasks_failed,
            summary.tasks_abandoned
        ),
        (4, 0, 0),
        "{summary:?}"
    );
    assert_eq!(uploads.load(Ordering::SeqCst), 4);
    assert_eq!(
        frame_exr(&s, &c, created.id, 1).await,
        direct_frame(&glb, &spec, 1)
    );
}

/// A rendered tile waiting for the previous tile's upload keeps its lease (its heartbeat
/// goes on); the previous tile, whose upload outlasts its lease, is rendered again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tile_waiting_for_the_upload_before_it_keeps_its_lease() {
    init_logs();
    let dir = tempfile::tempdir().unwrap();
    let config = server::Config {
        lease: Duration::from_secs(4),
        sweep_interval: Duration::from_millis(200),
        ..server_config(dir.path())
    };
    let s = TestServer::start(config).kill_on_drop();
    let c = client();
    let glb = spinning_quad();
    let scene = upload_scene(&s, &c, glb.clone()).await;
    let (proxy, open, uploads) = start_gate(&s.base).await;
    let spec = spec(&scene.digest, 1, 2, 1);
    let created = create_job(&s, &c, &spec).await;
    let w = TestWorker::start(&proxy, &dir.path().join("cache"), None);

    wait_for(&s, &c, created.id, Duration::from_secs(30), |j| {
        j.tasks.leased == 2
    })
    .await;
    // Past the lease: the first tile's lease expired while its upload was held (nothing
    // beats for a tile being uploaded); the second's is kept by its heartbeat.
    tokio::time::sleep(Duration::from_secs(6)).await;
    let waited = job(&s, &c, created.id).await;
    assert_eq!(
        (waited.tasks.leased, waited.tasks.queued, waited.tasks.done),
        (1, 3, 0),
        "{waited:?}"
    );

    open.send(true).unwrap();
    wait_until_done(&s, &c, created.id).await;
    let summary = w.shutdown().await.unwrap();
    // The first upload is answered 409 and dropped; its task is rendered again.
    assert_eq!(
        (summary.tasks_done, summary.tasks_abandoned),
        (4, 1),
        "{summary:?}"
    );
    assert_eq!(uploads.load(Ordering::SeqCst), 5);
    assert_eq!(
        frame_exr(&s, &c, created.id, 1).await,
        direct_frame(&glb, &spec, 1)
    );
}
