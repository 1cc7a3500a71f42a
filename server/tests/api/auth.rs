//! Worker and client tokens: each opens only its own routes; a refusal says nothing more.

use proto::{JobSpec, LeaseRequest};
use reqwest::StatusCode;

use crate::common::*;

#[tokio::test(flavor = "multi_thread")]
async fn tokens_open_only_their_own_routes() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.worker_token = Some("worker-secret".into());
    cfg.client_token = Some("client-secret".into());
    let s = TestServer::start(cfg);
    let c = client();

    // No token, a wrong token, the other role's token: a bare 401.
    for token in [None, Some("nope"), Some("worker-secret")] {
        let mut req = c.post(s.url("/scenes")).body(quad_scene());
        if let Some(t) = token {
            req = req.bearer_auth(t);
        }
        let res = req.send().await.unwrap();
        let err = error_body(res, StatusCode::UNAUTHORIZED).await;
        assert_eq!(
            (err.error.as_str(), err.message.as_str(), err.field),
            ("unauthorized", "unauthorized", None)
        );
    }
    let res = c
        .post(s.url("/scenes"))
        .bearer_auth("client-secret")
        .body(quad_scene())
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::CREATED);
    let scene: proto::SceneInfo = res.json().await.unwrap();

    let mut spec = JobSpec::new(scene.digest.clone());
    spec.width = 8;
    spec.height = 8;
    let res = c
        .post(s.url("/jobs"))
        .bearer_auth("worker-secret")
        .json(&spec)
        .send()
        .await
        .unwrap();
    assert_eq!(
        res.status(),
        StatusCode::UNAUTHORIZED,
        "a worker token cannot create jobs"
    );
    let res = c
        .post(s.url("/jobs"))
        .bearer_auth("client-secret")
        .json(&spec)
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::CREATED);

    let w = SimWorker::register_with(&s, "w", Some("worker-secret")).await;
    let url = s.url(&format!("/workers/{}/lease", w.id));
    let res = c
        .post(&url)
        .bearer_auth("client-secret")
        .json(&LeaseRequest::default())
        .send()
        .await
        .unwrap();
    assert_eq!(
        res.status(),
        StatusCode::UNAUTHORIZED,
        "a client token cannot lease"
    );
    // The join token only registers: the worker's own routes take its credential.
    let res = c
        .post(&url)
        .bearer_auth("worker-secret")
        .json(&LeaseRequest::default())
        .send()
        .await
        .unwrap();
    assert_eq!(
        res.status(),
        StatusCode::UNAUTHORIZED,
        "the join token leases"
    );
    let res = w
        .auth(c.post(&url))
        .json(&LeaseRequest::default())
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::OK);

    // Scenes download with either token; events take the token as a query parameter.
    for t in ["worker-secret", "client-secret", w.credential.as_str()] {
        let res = c
            .get(s.url(&format!("/scenes/{}", scene.digest)))
            .bearer_auth(t)
            .send()
            .await
            .unwrap();
        assert_eq!(res.status(), StatusCode::OK);
    }
    let res = c
        .get(s.url("/events?access_token=client-secret"))
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::OK);
    let res = c
        .get(s.url("/events?access_token=worker-secret"))
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::UNAUTHORIZED);
    // Health, metrics, the OpenAPI document and the dashboard page are open.
    for path in ["/healthz", "/metrics", "/api/v1/openapi.json", "/"] {
        let res = c.get(format!("{}{path}", s.base)).send().await.unwrap();
        assert_eq!(res.status(), StatusCode::OK, "{path}");
    }
}

/// Beyond loopback the server serves only with both tokens, or when told it may serve
/// open routes there (`insecure_no_auth`); the refusal names the missing token.
#[tokio::test(flavor = "multi_thread")]
async fn a_server_reachable_from_the_network_needs_both_tokens() {
    let dir = tempfile::tempdir().unwrap();
    let serve = |cfg: server::Config| async move {
        let listener = tokio::net::TcpListener::bind("0.0.0.0:0").await.unwrap();
        let port = listener.local_addr().unwrap().port();
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(server::serve(listener, cfg, async {
            let _ = stopped.await;
        }));
        // Either it refuses at once, or it serves: ask its health on loopback.
        let health = client()
            .get(format!("http://127.0.0.1:{port}/healthz"))
            .send()
            .await;
        let _ = stop.send(());
        (health.map(|r| r.status()).ok(), task.await.unwrap())
    };
    let mut cfg = config(dir.path());
    cfg.worker_token = Some("w".into());
    let (health, result) = serve(cfg.clone()).await;
    let refused = result.unwrap_err().to_string();
    assert_eq!(health, None);
    assert!(
        refused.starts_with("refusing to listen on 0.0.0.0:")
            && refused.contains("without --client-token:")
            && refused.contains("--insecure-no-auth"),
        "{refused}"
    );
    cfg.insecure_no_auth = true;
    let (health, result) = serve(cfg.clone()).await;
    assert_eq!((health, result.is_ok()), (Some(StatusCode::OK), true));
    cfg.insecure_no_auth = false;
    cfg.client_token = Some("c".into());
    let (health, result) = serve(cfg).await;
    assert_eq!((health, result.is_ok()), (Some(StatusCode::OK), true));
}

/// A worker acts only for itself: its credential opens its own routes and no other
/// worker's (403), the join token opens none of them (401), and on its own routes a lease
/// token of another worker's task is refused (409) and changes nothing.
#[tokio::test(flavor = "multi_thread")]
async fn a_worker_may_only_touch_its_own_leases() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    (cfg.worker_token, cfg.client_token) = (Some("join".into()), Some("client".into()));
    let s = TestServer::start(cfg);
    let c = client();
    let scene = c
        .post(s.url("/scenes"))
        .bearer_auth("client")
        .body(quad_scene())
        .send()
        .await
        .unwrap()
        .json::<proto::SceneInfo>()
        .await
        .unwrap();
    let mut spec = JobSpec::new(scene.digest);
    (spec.width, spec.height, spec.tile_size) = (16, 16, Some(8));
    let res = c
        .post(s.url("/jobs"))
        .bearer_auth("client")
        .json(&spec)
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::CREATED);
    let a = SimWorker::register_with(&s, "a", Some("join")).await;
    let b = SimWorker::register_with(&s, "b", Some("join")).await;
    let lease = a.lease(&s).await.expect("a task for a");
    let heartbeat = proto::Heartbeat {
        token: Some(lease.token),
        log: Vec::new(),
    };
    let on = |who: u64, what: &str| s.url(&format!("/workers/{who}/{what}"));

    // b's credential on a's routes: 403, naming whose credential it is.
    for what in [
        "heartbeat".to_string(),
        "leave".into(),
        format!("tasks/{}/failure", lease.token.task_id),
    ] {
        let res = b
            .auth(c.post(on(a.id, &what)))
            .json(&heartbeat)
            .send()
            .await
            .unwrap();
        let err = error_body(res, StatusCode::FORBIDDEN).await;
        assert!(
            err.message.contains(&format!("worker {}'s", b.id)),
            "{}",
            err.message
        );
    }
    // The join token, or no token: 401.
    for token in [Some("join"), None] {
        let mut req = c.post(on(a.id, "heartbeat")).json(&heartbeat);
        if let Some(t) = token {
            req = req.bearer_auth(t);
        }
        assert_eq!(req.send().await.unwrap().status(), StatusCode::UNAUTHORIZED);
    }
    // On its own route, b presenting a's lease token: the lease is not b's.
    let res = b
        .auth(c.post(on(b.id, "heartbeat")))
        .json(&heartbeat)
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::CONFLICT);
    let res = b.fail(&s, &lease, "not mine").await;
    assert_eq!(res.status(), StatusCode::CONFLICT);
    // a's lease is untouched: its own heartbeat extends it.
    assert_eq!(a.heartbeat(&s, &lease).await.status(), StatusCode::OK);
}
