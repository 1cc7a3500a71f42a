//! Bad input gets a JSON error that names the problem, and changes nothing.

use proto::{FrameRange, JobSpec, ResultAck, ResultMetadata};
use reqwest::StatusCode;
use tracer::film::{Layers, TileRect};

use crate::common::*;

#[tokio::test(flavor = "multi_thread")]
async fn malformed_scenes_are_refused_at_upload_naming_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.max_scene_bytes = 4096;
    let s = TestServer::start(cfg);
    let c = client();

    let res = c
        .post(s.url("/scenes"))
        .body(b"glTF\x02\x00\x00\x00garbage".to_vec())
        .send()
        .await
        .unwrap();
    let err = error_body(res, StatusCode::UNPROCESSABLE_ENTITY).await;
    assert_eq!(err.error, "bad_scene");
    assert!(err.message.contains("cannot be loaded"), "{}", err.message);

    let res = c
        .post(s.url("/scenes"))
        .body(br#"{"asset":{"version":"2.0"}}"#.to_vec())
        .send()
        .await
        .unwrap();
    let err = error_body(res, StatusCode::UNPROCESSABLE_ENTITY).await;
    assert!(err.message.contains("GLB"), "{}", err.message);

    // An index past the end of its accessor's data, named by the loader.
    let json = r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
      "meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
      "buffers":[{"byteLength":12}],"bufferViews":[{"buffer":0,"byteLength":12}],
      "accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,1]}]}"#;
    let res = c
        .post(s.url("/scenes"))
        .body(glb(json, &[0u8; 12]))
        .send()
        .await
        .unwrap();
    let err = error_body(res, StatusCode::UNPROCESSABLE_ENTITY).await;
    assert!(err.message.contains("accessor"), "{}", err.message);

    let res = c
        .post(s.url("/scenes"))
        .body(vec![0u8; 5000])
        .send()
        .await
        .unwrap();
    let err = error_body(res, StatusCode::PAYLOAD_TOO_LARGE).await;
    assert!(err.message.contains("4096"), "{}", err.message);

    let res = c
        .post(s.url("/scenes"))
        .body(Vec::new())
        .send()
        .await
        .unwrap();
    assert_eq!(
        error_body(res, StatusCode::UNPROCESSABLE_ENTITY)
            .await
            .error,
        "bad_scene"
    );

    // Nothing was stored.
    assert_eq!(std::fs::read_dir(s.data.join("scenes")).unwrap().count(), 0);
    let res = c
        .get(s.url(&format!("/scenes/{}", "0".repeat(64))))
        .send()
        .await
        .unwrap();
    assert_eq!(
        error_body(res, StatusCode::NOT_FOUND).await.error,
        "not_found"
    );
    let res = c.get(s.url("/scenes/..%2F..%2Fetc")).send().await.unwrap();
    let err = error_body(res, StatusCode::BAD_REQUEST).await;
    assert!(
        err.message.contains("not a SHA-256 digest"),
        "{}",
        err.message
    );
}

#[tokio::test(flavor = "multi_thread")]
async fn job_spec_errors_name_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.max_tasks_per_job = 10;
    let s = TestServer::start(cfg);
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    // The same scene again is stored once.
    let res = c
        .post(s.url("/scenes"))
        .body(quad_scene())
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::OK);

    let base = || {
        let mut spec = JobSpec::new(scene.digest.clone());
        spec.frames = Some(FrameRange {
            start: 0,
            end: 0,
            step: 1,
        });
        spec.width = 16;
        spec.height = 16;
        spec
    };
    let cases: Vec<(&str, serde_json::Value)> = vec![
        ("width", {
            let mut s = base();
            s.width = 16_385;
            serde_json::to_value(s).unwrap()
        }),
        ("spp", {
            let mut s = base();
            s.spp = 1_000_001;
            serde_json::to_value(s).unwrap()
        }),
        ("frames", {
            let mut s = base();
            s.frames = Some(FrameRange {
                start: 0,
                end: 100_000,
                step: 1,
            });
            serde_json::to_value(s).unwrap()
        }),
        ("camera", {
            let mut s = base();
            s.camera = proto::CameraSpec::Name("Nope".into());
            serde_json::to_value(s).unwrap()
        }),
        ("scene", {
            let mut s = base();
            s.scene = "f".repeat(64);
            serde_json::to_value(s).unwrap()
        }),
        // 16×16 in 8-pixel tiles is 4 tasks a frame; 3 frames is over this server's 10.
        ("tile_size", {
            let mut s = base();
            s.tile_size = Some(8);
            s.frames = Some(FrameRange {
                start: 0,
                end: 2,
                step: 1,
            });
            serde_json::to_value(s).unwrap()
        }),
        (
            "spp",
            serde_json::json!({"scene": scene.digest, "spp": "many"}),
        ),
    ];
    for (field, body) in cases {
        let res = c.post(s.url("/jobs")).json(&body).send().await.unwrap();
        let err = error_body(res, StatusCode::UNPROCESSABLE_ENTITY).await;
        assert_eq!(err.field.as_deref(), Some(field), "{}", err.message);
        assert!(err.message.starts_with(field), "{}", err.message);
    }
    let res = c
        .post(s.url("/jobs"))
        .json(&serde_json::json!({"scene": scene.digest, "sppp": 4}))
        .send()
        .await
        .unwrap();
    let err = error_body(res, StatusCode::UNPROCESSABLE_ENTITY).await;
    assert_eq!(err.field.as_deref(), Some("sppp"));
    assert!(err.message.contains("unknown field"), "{}", err.message);
    let res = c
        .post(s.url("/jobs"))
        .header("content-type", "application/json")
        .body("{not json")
        .send()
        .await
        .unwrap();
    assert_eq!(
        error_body(res, StatusCode::BAD_REQUEST).await.error,
        "bad_request"
    );
    let res = c
        .post(s.url("/jobs"))
        .header("content-type", "application/json")
        .body(vec![b' '; 70_000])
        .send()
        .await
        .unwrap();
    assert_eq!(
        error_body(res, StatusCode::PAYLOAD_TOO_LARGE).await.error,
        "too_large"
    );
    let res = c.get(s.url("/jobs/abc")).send().await.unwrap();
    assert_eq!(
        error_body(res, StatusCode::BAD_REQUEST).await.error,
        "bad_request"
    );
    let res = c.get(s.url("/jobs/999")).send().await.unwrap();
    assert!(error_body(res, StatusCode::NOT_FOUND)
        .await
        .message
        .contains("999"));
    // Nothing was created.
    let list: proto::JobList = c
        .get(s.url("/jobs"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert!(list.jobs.is_empty());
}

#[tokio::test(flavor = "multi_thread")]
async fn bad_tiles_are_refused_and_the_lease_stays_good() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.max_tile_bytes = 200_000;
    let s = TestServer::start(cfg);
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut spec = JobSpec::new(scene.digest.clone());
    spec.frames = Some(FrameRange {
        start: 0,
        end: 0,
        step: 1,
    });
    (spec.width, spec.height, spec.tile_size, spec.spp) = (16, 16, Some(8), 2);
    create_job(&s, &c, &spec).await;
    let mut w = SimWorker::register(&s, "sim").await;
    let lease = w.lease(&s).await.unwrap();
    let (good, _) = w.render(&s, &lease).await;
    let meta = |bytes: &[u8]| ResultMetadata {
        attempt: lease.token.attempt,
        sha256: server::store::sha256_hex(bytes),
        samples: 2,
        rays: 1,
        render_ms: 1,
    };

    // Checksum of other bytes.
    let mut m = meta(&good);
    m.sha256 = server::store::sha256_hex(b"other");
    let err = error_body(
        w.upload_with(&s, &lease, good.clone(), &m).await,
        StatusCode::UNPROCESSABLE_ENTITY,
    )
    .await;
    assert!(err.message.contains("checksum"), "{}", err.message);
    // Not EXR.
    let junk = b"not an exr".to_vec();
    let err = error_body(
        w.upload_with(&s, &lease, junk.clone(), &meta(&junk)).await,
        StatusCode::UNPROCESSABLE_ENTITY,
    )
    .await;
    assert!(err.message.contains("OpenEXR"), "{}", err.message);
    // The wrong rectangle.
    let wrong_rect = tile_exr(&lease, &Layers::new(TileRect::new(8, 8, 8, 8)));
    let err = error_body(
        w.upload_with(&s, &lease, wrong_rect.clone(), &meta(&wrong_rect))
            .await,
        StatusCode::UNPROCESSABLE_ENTITY,
    )
    .await;
    assert!(err.message.contains("data window"), "{}", err.message);
    // A NaN.
    let mut nan = Layers::new(TileRect::new(lease.tile.x, lease.tile.y, 8, 8));
    nan.beauty[3].y = f32::NAN;
    let nan = tile_exr(&lease, &nan);
    let err = error_body(
        w.upload_with(&s, &lease, nan.clone(), &meta(&nan)).await,
        StatusCode::UNPROCESSABLE_ENTITY,
    )
    .await;
    assert!(err.message.contains("`G`"), "{}", err.message);
    // The wrong sample count.
    let mut m = meta(&good);
    m.samples = 3;
    let err = error_body(
        w.upload_with(&s, &lease, good.clone(), &m).await,
        StatusCode::UNPROCESSABLE_ENTITY,
    )
    .await;
    assert_eq!(err.field.as_deref(), Some(ResultMetadata::SAMPLES));
    // A missing header.
    let res = w
        .auth(w.client.post(s.url(&format!(
            "/workers/{}/tasks/{}/result",
            w.id, lease.token.task_id
        ))))
        .header(ResultMetadata::ATTEMPT, "1")
        .body(good.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(
        error_body(res, StatusCode::UNPROCESSABLE_ENTITY)
            .await
            .field
            .as_deref(),
        Some(ResultMetadata::SHA256)
    );
    // Over the tile limit.
    let big = vec![0u8; 200_001];
    let err = error_body(
        w.upload_with(&s, &lease, big.clone(), &meta(&big)).await,
        StatusCode::PAYLOAD_TOO_LARGE,
    )
    .await;
    assert!(err.message.contains("200000"), "{}", err.message);

    // The lease is still good: the real tile is accepted.
    let ack: ResultAck = w.upload(&s, &lease, good).await.json().await.unwrap();
    assert!(ack.accepted);
    let metrics = metrics(&s, &c).await;
    assert!(
        metrics.contains("tessera_tiles_refused_total 5"),
        "{metrics}"
    );
}

#[tokio::test(flavor = "multi_thread")]
async fn worker_calls_with_bad_ids_or_fields_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let res = c
        .post(s.url("/workers/42/lease"))
        .json(&proto::LeaseRequest::default())
        .send()
        .await
        .unwrap();
    let err = error_body(res, StatusCode::NOT_FOUND).await;
    assert!(err.message.contains("register"), "{}", err.message);
    // A step time past the limit (here 2^63 ms, past the database's integers: the API
    // contract run once got a 500 for it) is refused naming its field.
    let huge = Some(1u64 << 63);
    for (name, threads, steps, field) in [
        ("", 4, [None, None], "name"),
        ("w", 0, [None, None], "threads"),
        ("w", 1, [huge, None], "denoise_ms_per_megapixel"),
        ("w", 1, [None, huge], "encode_ms_per_megapixel"),
    ] {
        let res = c
            .post(s.url("/workers"))
            .json(&proto::WorkerRegistration {
                name: name.into(),
                threads,
                version: "1".into(),
                denoise_ms_per_megapixel: steps[0],
                encode_ms_per_megapixel: steps[1],
                ..Default::default()
            })
            .send()
            .await
            .unwrap();
        assert_eq!(
            error_body(res, StatusCode::UNPROCESSABLE_ENTITY)
                .await
                .field
                .as_deref(),
            Some(field)
        );
    }
}

/// A job whose frames the server could not assemble within its assembly memory is refused
/// at submission, naming the width and the limit; a narrower one of the same height is
/// taken (what assembly holds grows with width, not height).
#[tokio::test(flavor = "multi_thread")]
async fn a_job_too_wide_to_assemble_within_the_memory_budget_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.assembly_memory = 64 << 20;
    let s = TestServer::start(cfg);
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut spec = JobSpec::new(&scene.digest);
    (spec.width, spec.height, spec.tile_size) = (16_384, 16_384, Some(1_024));
    let res = c.post(s.url("/jobs")).json(&spec).send().await.unwrap();
    let err = error_body(res, StatusCode::UNPROCESSABLE_ENTITY).await;
    assert_eq!(err.field.as_deref(), Some("width"));
    assert!(err.message.contains("64 MiB"), "{}", err.message);
    let jobs: proto::JobList = c
        .get(s.url("/jobs"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert!(jobs.jobs.is_empty());

    (spec.width, spec.tile_size) = (2_048, Some(256));
    create_job(&s, &c, &spec).await;
}

/// Ids are SQLite row ids: one past `i64::MAX` names nothing and is answered as a client
/// error on every route that takes one, in the path or in a lease token, never a 500.
#[tokio::test(flavor = "multi_thread")]
async fn ids_past_the_largest_row_id_are_client_errors_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let w = SimWorker::register(&s, "w").await;
    let me = w.id;
    for id in [i64::MAX as u64 + 1, 9_945_769_785_826_205_696, u64::MAX] {
        let routes = [
            ("GET", format!("/jobs/{id}")),
            ("DELETE", format!("/jobs/{id}")),
            ("POST", format!("/jobs/{id}/cancel")),
            ("POST", format!("/jobs/{id}/pause")),
            ("POST", format!("/jobs/{id}/resume")),
            ("POST", format!("/jobs/{id}/retry")),
            ("GET", format!("/jobs/{id}/frames")),
            ("GET", format!("/jobs/{id}/frames/1/exr")),
            ("GET", format!("/jobs/{id}/frames/1/png")),
            ("POST", format!("/workers/{id}/clear")),
            ("POST", format!("/workers/{id}/lease")),
            ("POST", format!("/workers/{id}/heartbeat")),
            ("POST", format!("/workers/{id}/leave")),
            ("POST", format!("/workers/{id}/tasks/1/failure")),
            ("POST", format!("/workers/{me}/tasks/{id}/failure")),
            ("POST", format!("/workers/{id}/tasks/1/result")),
            ("POST", format!("/workers/{me}/tasks/{id}/result")),
        ];
        for (method, path) in routes {
            let req = w.auth(c.request(method.parse().unwrap(), s.url(&path)));
            let req = match path.rsplit('/').next().unwrap() {
                "lease" => req.json(&proto::LeaseRequest::default()),
                "heartbeat" => req.json(&proto::Heartbeat {
                    token: None,
                    log: Vec::new(),
                }),
                "failure" => req.json(&proto::FailureReport {
                    attempt: 1,
                    message: "x".into(),
                    log: Vec::new(),
                }),
                "result" => req
                    .header(ResultMetadata::ATTEMPT, "1")
                    .header(ResultMetadata::SHA256, "00")
                    .header(ResultMetadata::SAMPLES, "1")
                    .body(vec![0u8; 4]),
                _ => req,
            };
            let res = req.send().await.unwrap();
            let status = res.status();
            let body = res.text().await.unwrap();
            assert!(status.is_client_error(), "{method} {path}: {status} {body}");
            assert!(body.contains(&id.to_string()), "{method} {path}: {body}");
        }
        // A heartbeat whose lease token names such a task.
        let res = w
            .auth(c.post(s.url(&format!("/workers/{me}/heartbeat"))))
            .json(&serde_json::json!({ "token": { "task_id": id, "attempt": 1 } }))
            .send()
            .await
            .unwrap();
        let err = error_body(res, StatusCode::UNPROCESSABLE_ENTITY).await;
        assert_eq!(
            err.field.as_deref(),
            Some("token.task_id"),
            "{}",
            err.message
        );
    }
}
