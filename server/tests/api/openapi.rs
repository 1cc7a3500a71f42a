//! The served OpenAPI document is the one generated from the handlers, and every
//! operation it lists reaches a handler.

use reqwest::{Method, StatusCode};

use crate::common::*;

#[tokio::test(flavor = "multi_thread")]
async fn served_document_matches_the_code_and_every_operation_is_routed() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let served: serde_json::Value = c
        .get(s.url("/openapi.json"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let generated = serde_json::to_value(server::openapi()).unwrap();
    assert_eq!(served, generated);

    let paths = served["paths"].as_object().unwrap();
    let mut operations = vec![];
    for (path, item) in paths {
        for method in ["get", "post", "put", "delete", "patch"] {
            if item.get(method).is_some() {
                operations.push((method.to_uppercase(), path.clone()));
            }
        }
    }
    let expected = [
        ("POST", "/api/v1/scenes"),
        ("GET", "/api/v1/scenes/{digest}"),
        ("GET", "/api/v1/scenes/{digest}/info"),
        ("POST", "/api/v1/jobs"),
        ("GET", "/api/v1/jobs"),
        ("GET", "/api/v1/jobs/{id}"),
        ("DELETE", "/api/v1/jobs/{id}"),
        ("POST", "/api/v1/jobs/{id}/cancel"),
        ("POST", "/api/v1/jobs/{id}/pause"),
        ("POST", "/api/v1/jobs/{id}/resume"),
        ("POST", "/api/v1/jobs/{id}/retry"),
        ("POST", "/api/v1/jobs/{id}/priority"),
        ("POST", "/api/v1/jobs/{id}/rerender"),
        ("GET", "/api/v1/jobs/{id}/tasks"),
        ("GET", "/api/v1/jobs/{id}/failures"),
        ("GET", "/api/v1/jobs/{id}/tasks/{task}/log"),
        ("GET", "/api/v1/jobs/{id}/log"),
        ("GET", "/api/v1/jobs/{id}/frames"),
        ("GET", "/api/v1/jobs/{id}/frames/{frame}/exr"),
        ("GET", "/api/v1/jobs/{id}/frames/{frame}/png"),
        ("GET", "/api/v1/jobs/{id}/video"),
        ("POST", "/api/v1/workers"),
        ("GET", "/api/v1/workers"),
        ("POST", "/api/v1/workers/{id}/lease"),
        ("POST", "/api/v1/workers/{id}/heartbeat"),
        ("POST", "/api/v1/workers/{id}/leave"),
        ("POST", "/api/v1/workers/{id}/clear"),
        ("POST", "/api/v1/workers/{id}/tasks/{task}/result"),
        ("POST", "/api/v1/workers/{id}/tasks/{task}/failure"),
        ("GET", "/api/v1/workers/{id}/tasks/{task}/frame"),
        ("GET", "/api/v1/events"),
        ("POST", "/api/v1/gc"),
    ];
    let mut want: Vec<(String, String)> = expected
        .iter()
        .map(|(m, p)| (m.to_string(), p.to_string()))
        .collect();
    want.sort();
    operations.sort();
    assert_eq!(operations, want);
    // The wire types are in the document.
    for schema in [
        "JobSpec",
        "JobStatus",
        "Lease",
        "Heartbeat",
        "ErrorBody",
        "SceneInfo",
        "Event",
        "WorkerInfo",
        "TaskList",
        "FailureList",
    ] {
        assert!(
            served["components"]["schemas"].get(schema).is_some(),
            "{schema}"
        );
    }

    // Every operation reaches a handler: axum's own 404/405 have no JSON body, ours do.
    for (method, path) in operations {
        if path.ends_with("/events") {
            continue; // a stream that stays open
        }
        let concrete = path
            .replace("{digest}", &"0".repeat(64))
            .replace("{id}", "999")
            .replace("{task}", "1")
            .replace("{frame}", "1");
        let res = c
            .request(
                Method::from_bytes(method.as_bytes()).unwrap(),
                format!("{}{concrete}", s.base),
            )
            .header("content-type", "application/json")
            .body("{}")
            .send()
            .await
            .unwrap();
        assert_ne!(
            res.status(),
            StatusCode::METHOD_NOT_ALLOWED,
            "{method} {path}"
        );
        let body = res.text().await.unwrap();
        assert!(
            body.starts_with('{') || body.starts_with("glTF"),
            "{method} {path}: {body}"
        );
    }
}
