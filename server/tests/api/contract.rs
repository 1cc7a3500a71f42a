//! The API contract, checked from outside: requests generated from the served OpenAPI
//! document hit every operation for a bounded time, valid ones and hostile ones (ids past
//! 64 bits, unicode, negative and huge numbers, wrong types, huge JSON, wrong content
//! types, every kind of token, in the path, the query and the body). Each answer must be a status the document lists for its
//! operation, never a 5xx, and an error must carry the JSON error body.
//!
//! `TESSERA_CONTRACT_SECONDS` sets how long it runs (default 10); `TESSERA_CONTRACT_SEED`
//! repeats a run (the seed is printed).

use std::time::{Duration, Instant};

use reqwest::{Method, StatusCode};
use serde_json::{json, Map, Value};

use crate::common::*;

const CLIENT: &str = "client-token";
const JOIN: &str = "join-token";

/// What the generator knows about the farm: ids and names that exist, so that some
/// requests get past the first checks.
struct Known {
    digest: String,
    job: u64,
    worker: u64,
    credential: String,
    task: u64,
}

/// One generated request.
struct Call {
    method: Method,
    path: String,
    token: Option<String>,
    content_type: Option<&'static str>,
    body: Option<Vec<u8>>,
}

#[tokio::test(flavor = "multi_thread")]
async fn every_answer_is_documented_and_none_is_a_server_error() {
    let seconds: u64 = env_number("TESSERA_CONTRACT_SECONDS").unwrap_or(10);
    let seed = env_number("TESSERA_CONTRACT_SEED").unwrap_or_else(|| fastrand::u64(..));
    println!("contract run: {seconds} s, TESSERA_CONTRACT_SEED={seed}");
    let mut rng = fastrand::Rng::with_seed(seed);

    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    (cfg.client_token, cfg.worker_token) = (Some(CLIENT.into()), Some(JOIN.into()));
    // Small limits, so that bodies over them are cheap to send; no long polls.
    cfg.max_scene_bytes = 64 << 10;
    cfg.max_tile_bytes = 64 << 10;
    cfg.max_tasks_per_job = 2_000;
    cfg.max_lease_wait = Duration::from_millis(50);
    let s = TestServer::start(cfg);
    // A connection per request: the server may close one after refusing a body it did
    // not read, which a pooled connection would report as a failed next request.
    let c = reqwest::Client::builder()
        .pool_max_idle_per_host(0)
        .build()
        .unwrap();
    let doc: Value = c
        .get(s.url("/openapi.json"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let known = farm_to_aim_at(&s, &c).await;

    let mut operations = Vec::new();
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            if let Ok(m) = method.to_uppercase().parse::<Method>() {
                operations.push((m, path.clone(), op.clone()));
            }
        }
    }
    let (until, mut calls) = (Instant::now() + Duration::from_secs(seconds), 0u64);
    let mut seen = std::collections::BTreeSet::new();
    while Instant::now() < until || calls < operations.len() as u64 * 4 {
        let (method, template, op) = &operations[calls as usize % operations.len()];
        let call = generate(&mut rng, method, template, op, &doc, &known);
        let described = describe(&call);
        let mut req = c
            .request(call.method.clone(), format!("{}{}", s.base, call.path))
            .timeout(Duration::from_secs(30));
        if let Some(t) = &call.token {
            req = req.bearer_auth(t);
        }
        if let Some(ct) = call.content_type {
            req = req.header("content-type", ct);
        }
        if let Some(body) = call.body {
            req = req.body(body);
        }
        let res = req
            .send()
            .await
            .unwrap_or_else(|e| panic!("{described}: {e}"));
        let status = res.status();
        let is_stream = template.ends_with("/events") && status == StatusCode::OK;
        let body = if is_stream {
            Vec::new()
        } else {
            res.bytes().await.map(|b| b.to_vec()).unwrap_or_default()
        };
        let text = String::from_utf8_lossy(&body);
        assert!(
            !status.is_server_error(),
            "{described}\n  answered {status}: {text}\n  (seed {seed})"
        );
        let listed = &op["responses"];
        assert!(
            listed.get(status.as_str()).is_some() || listed.get("default").is_some(),
            "{described}\n  answered {status}, which the document does not list for \
             {method} {template} ({:?}): {text}\n  (seed {seed})",
            listed.as_object().map(|o| o.keys().collect::<Vec<_>>())
        );
        if status.is_client_error() {
            let error: Result<proto::ErrorBody, _> = serde_json::from_slice(&body);
            assert!(
                error.is_ok(),
                "{described}\n  answered {status} without a JSON error body: {text}\n  (seed {seed})"
            );
        }
        seen.insert((method.to_string(), template.clone(), status.as_u16()));
        calls += 1;
    }
    println!("{calls} calls; statuses seen per operation:");
    for (method, path, status) in &seen {
        println!("  {method} {path} {status}");
    }
}

fn env_number(name: &str) -> Option<u64> {
    std::env::var(name).ok()?.parse().ok()
}

/// A scene, a job with tasks and a registered worker holding a lease: real ids to aim at.
async fn farm_to_aim_at(s: &TestServer, c: &reqwest::Client) -> Known {
    let scene: proto::SceneInfo = c
        .post(s.url("/scenes"))
        .bearer_auth(CLIENT)
        .body(quad_scene())
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let mut spec = proto::JobSpec::new(scene.digest.clone());
    (spec.width, spec.height, spec.tile_size, spec.spp) = (16, 16, Some(8), 1);
    let job: proto::JobStatus = c
        .post(s.url("/jobs"))
        .bearer_auth(CLIENT)
        .json(&spec)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let w = SimWorker::register_with(s, "contract", Some(JOIN)).await;
    let lease = w.lease(s).await.expect("the job has tasks");
    Known {
        digest: scene.digest,
        job: job.id,
        worker: w.id,
        credential: w.credential.clone(),
        task: lease.token.task_id,
    }
}

fn describe(call: &Call) -> String {
    let body = call.body.as_ref().map(|b| {
        let text = String::from_utf8_lossy(&b[..b.len().min(300)]).into_owned();
        format!(" body ({} bytes) {text}", b.len())
    });
    format!(
        "{} {} token {:?} content-type {:?}{}",
        call.method,
        call.path,
        call.token.as_deref().map(|t| &t[..t.len().min(12)]),
        call.content_type,
        body.unwrap_or_default()
    )
}

fn pick<'a, T>(rng: &mut fastrand::Rng, options: &'a [T]) -> &'a T {
    &options[rng.usize(..options.len())]
}

/// A request for `op` at `template`: each part valid most of the time, hostile otherwise.
fn generate(
    rng: &mut fastrand::Rng,
    method: &Method,
    template: &str,
    op: &Value,
    doc: &Value,
    known: &Known,
) -> Call {
    let mut path = template.to_string();
    let id = if template.contains("/workers/") {
        known.worker
    } else {
        known.job
    };
    // Deleting the job or saying goodbye for the worker would leave nothing to aim at.
    let ends_it = *method == Method::DELETE || template.ends_with("/leave");
    for (param, id) in [("{id}", id), ("{task}", known.task)] {
        if path.contains(param) {
            let value = if rng.u8(..100) < 50 && !ends_it {
                id.to_string()
            } else {
                hostile_path(rng)
            };
            path = path.replace(param, &value);
        }
    }
    if path.contains("{frame}") {
        let frame = pick(rng, &["1", "0", "-1", "2147483648", "99999999999", "x"]);
        path = path.replace("{frame}", frame);
    }
    if path.contains("{digest}") {
        let digest = if rng.bool() {
            known.digest.clone()
        } else {
            pick(
                rng,
                &[
                    "0".repeat(64),
                    "zz".into(),
                    "..%2F..%2Fetc%2Fpasswd".into(),
                    "A".repeat(64),
                    "0".repeat(65),
                    "%C3%BC".into(),
                ],
            )
            .clone()
        };
        path = path.replace("{digest}", &digest);
    }
    // Query parameters: each one left out, valid for its schema or hostile.
    let mut query = Vec::new();
    for param in op["parameters"].as_array().into_iter().flatten() {
        if param["in"] != "query" || rng.bool() {
            continue;
        }
        let value = match value_of(rng, &param["schema"], doc, 0) {
            Value::String(s) => s,
            other => other.to_string(),
        };
        let value = if rng.u8(..100) < 20 {
            hostile_path(rng)
        } else {
            value
        };
        let name = param["name"].as_str().unwrap();
        query.push(format!("{name}={}", urlencode(&value)));
    }
    if !query.is_empty() {
        path = format!("{path}?{}", query.join("&"));
    }
    let token = match rng.u8(..10) {
        0 => None,
        1 => Some("not-a-token".to_string()),
        2 => Some(JOIN.into()),
        3 => Some(CLIENT.into()),
        _ => {
            // The token the operation wants, most of the time.
            let schemes = op["security"].to_string();
            if schemes.contains("worker_credential") {
                Some(known.credential.clone())
            } else if schemes.contains("worker_token") && !schemes.contains("client_token") {
                Some(JOIN.into())
            } else {
                Some(CLIENT.into())
            }
        }
    };
    let content = &op["requestBody"]["content"];
    let (content_type, body) =
        if let Some(schema) = content.get("application/json").map(|c| &c["schema"]) {
            match rng.u8(..10) {
                0 => (Some("text/plain"), Some(b"{}".to_vec())),
                1 => (
                    Some("application/json"),
                    Some(pick(rng, &[&b"{"[..], b"", b"null", b"[1,2", b"\xff\xfe"]).to_vec()),
                ),
                2 => (
                    Some("application/json"),
                    Some(
                        json!({ "name": "x".repeat(70 << 10) })
                            .to_string()
                            .into_bytes(),
                    ),
                ),
                3 => (None, Some(b"{}".to_vec())),
                4..=6 if template.ends_with("/jobs") => {
                    // A good job spec with one field changed: past the first check, into
                    // the planning.
                    let mut spec = json!({
                        "scene": known.digest, "width": 16, "height": 16, "spp": 1,
                        "tile_size": 8, "frames": {"start": 1, "end": 2}
                    });
                    let fields = &doc["components"]["schemas"]["JobSpec"]["properties"];
                    let names: Vec<&String> = fields.as_object().unwrap().keys().collect();
                    let name = pick(rng, &names).to_string();
                    spec[&name] = value_of(rng, &fields[&name], doc, 1);
                    (
                        Some("application/json"),
                        Some(spec.to_string().into_bytes()),
                    )
                }
                _ => {
                    let mut value = value_of(rng, schema, doc, 0);
                    // A job spec names the scene there is, most of the time.
                    if let Some(scene) = value.get_mut("scene") {
                        if rng.u8(..100) < 80 {
                            *scene = json!(known.digest);
                        }
                    }
                    (
                        Some("application/json"),
                        Some(value.to_string().into_bytes()),
                    )
                }
            }
        } else if content.as_object().is_some_and(|o| !o.is_empty()) {
            let bytes = match rng.u8(..6) {
                0 => Vec::new(),
                1 => vec![0u8; 70 << 10],
                2 => quad_scene(),
                3 => b"glTF\x02\x00\x00\x00\xff\xff\xff\xff".to_vec(),
                _ => (0..rng.usize(..2048)).map(|_| rng.u8(..)).collect(),
            };
            (Some("application/octet-stream"), Some(bytes))
        } else if *method == Method::POST && rng.u8(..4) == 0 {
            (
                Some("application/json"),
                Some(b"{\"unexpected\": true}".to_vec()),
            )
        } else {
            (None, None)
        };
    Call {
        method: method.clone(),
        path,
        token,
        content_type,
        body,
    }
}

/// `value` percent-encoded for a URL query (every byte but unreserved ones).
fn urlencode(value: &str) -> String {
    value
        .bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}

fn hostile_path(rng: &mut fastrand::Rng) -> String {
    let random = rng.u64(..1_000_000).to_string();
    pick(
        rng,
        &[
            "0".to_string(),
            "-1".into(),
            (i64::MAX as u64).to_string(),
            (i64::MAX as u64 + 1).to_string(),
            u64::MAX.to_string(),
            "18446744073709551616".into(),
            "1.5".into(),
            "abc".into(),
            "%C3%BC%F0%9F%8E%AC".into(),
            "9".repeat(40),
            random,
        ],
    )
    .clone()
}

/// A hostile JSON value: the wrong type, the wrong size, the wrong sign.
fn hostile(rng: &mut fastrand::Rng) -> Value {
    match rng.u8(..14) {
        0 => json!(i64::MAX as u64 + 1),
        1 => json!(u64::MAX),
        2 => json!(-1),
        3 => json!(-1e308),
        4 => json!(1e308),
        5 => json!(0.5),
        6 => json!("ü🎬\u{0}\u{202e}"),
        7 => json!(""),
        8 => json!("x".repeat(5000)),
        9 => Value::Null,
        10 => json!([]),
        11 => json!({}),
        12 => json!(true),
        _ => (0..40).fold(json!(1), |v, _| json!([v])),
    }
}

/// A value for `schema` (resolving `$ref`s into `doc`'s components), each part replaced
/// by a hostile one now and then.
fn value_of(rng: &mut fastrand::Rng, schema: &Value, doc: &Value, depth: u32) -> Value {
    if depth > 6 || rng.u8(..100) < 8 {
        return hostile(rng);
    }
    if let Some(r) = schema["$ref"].as_str() {
        let name = r.rsplit('/').next().unwrap();
        return value_of(rng, &doc["components"]["schemas"][name], doc, depth + 1);
    }
    for key in ["oneOf", "anyOf"] {
        if let Some(options) = schema[key].as_array() {
            let option = pick(rng, options).clone();
            return value_of(rng, &option, doc, depth + 1);
        }
    }
    if let Some(all) = schema["allOf"].as_array() {
        let mut merged = Map::new();
        for part in all {
            if let Value::Object(o) = value_of(rng, part, doc, depth + 1) {
                merged.extend(o);
            }
        }
        return Value::Object(merged);
    }
    if let Some(options) = schema["enum"].as_array() {
        return pick(rng, options).clone();
    }
    let types: Vec<&str> = match &schema["type"] {
        Value::String(t) => vec![t.as_str()],
        Value::Array(ts) => ts.iter().filter_map(Value::as_str).collect(),
        _ => vec!["object"],
    };
    match *pick(rng, &types) {
        "null" => Value::Null,
        "boolean" => json!(rng.bool()),
        "integer" => {
            let small = rng.i64(-2..300);
            let bound = |k: &str| schema[k].as_i64();
            match rng.u8(..4) {
                0 => json!(bound("maximum").unwrap_or(1 << 20)),
                1 => json!(bound("minimum").unwrap_or(0)),
                _ => json!(small),
            }
        }
        "number" => json!(pick(
            rng,
            &[0.0, 1.0, 24.0, -0.25, 0.01, 1e9, f64::MIN_POSITIVE]
        )),
        "string" => json!(pick(rng, &["", "a", "Main", "0", "ü", "0000"]).to_string()),
        "array" => {
            let n = rng.usize(..4);
            Value::Array(
                (0..n)
                    .map(|_| value_of(rng, &schema["items"], doc, depth + 1))
                    .collect(),
            )
        }
        _ => {
            let mut object = Map::new();
            let required: Vec<&str> = schema["required"]
                .as_array()
                .map(|r| r.iter().filter_map(Value::as_str).collect())
                .unwrap_or_default();
            if let Some(props) = schema["properties"].as_object() {
                for (name, prop) in props {
                    let needed = required.contains(&name.as_str());
                    // Required fields mostly there, optional ones half the time.
                    if (needed && rng.u8(..100) < 95) || (!needed && rng.bool()) {
                        object.insert(name.clone(), value_of(rng, prop, doc, depth + 1));
                    }
                }
            }
            if rng.u8(..100) < 5 {
                object.insert("unexpected".into(), json!(1));
            }
            Value::Object(object)
        }
    }
}
