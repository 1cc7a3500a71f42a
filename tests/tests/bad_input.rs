//! Bad input at a real farm with tokens: each request (a client's, or a rogue worker's
//! upload) is refused with an error that names the problem, nothing is created or
//! accepted, and the farm goes on to render a good job exactly.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use proto::{
    Heartbeat, JobState, JobStatus, Lease, LeaseRequest, ResultAck, ResultMetadata,
    WorkerRegistered, WorkerRegistration,
};
use sha2::{Digest, Sha256};
use tests::http::{self, Answer, Request};
use tests::{render_directly, settings, tessera, wait_until, Farm};
use tracer::film::{Layers, TileRect};
use tracer::output::{encode_exr_layers, ExrCompression, ExrMetadata, ImageLayer};
use tracer::render::{prepare_frame, render_tile};

const WORKER_TOKEN: &str = "worker-secret";
const CLIENT_TOKEN: &str = "client-secret";

/// Runs a client command with `--server` and the given token; asserts it fails with
/// `expected` in its error output, and returns that output.
fn refused(farm: &Farm, args: &[&str], token: Option<&str>, expected: &str) -> String {
    let url = farm.url();
    let mut all = args.to_vec();
    all.extend(["--server", url.as_str()]);
    if let Some(t) = token {
        all.extend(["--token", t]);
    }
    let out = tessera(&all, farm.path());
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "tessera {} succeeded", all.join(" "));
    assert!(
        stderr.contains(expected) && !stderr.contains("panicked"),
        "tessera {}: expected `{expected}` in:\n{stderr}",
        all.join(" ")
    );
    stderr
}

#[test]
fn bad_tokens_scenes_and_specs_are_refused_and_the_farm_goes_on() {
    let mut farm = Farm::new();
    farm.client_token = Some(CLIENT_TOKEN.into());
    farm.start_server_with(
        60,
        &[
            "--worker-token",
            WORKER_TOKEN,
            "--client-token",
            CLIENT_TOKEN,
            "--max-tasks-per-job",
            "1000",
        ],
    );
    let scene = farm.demo_scene();
    let demo = scene.to_str().unwrap();

    // Auth: no token, the wrong token, the worker's token on a client route.
    refused(&farm, &["status"], None, "401");
    refused(&farm, &["status"], Some("guess"), "401");
    refused(&farm, &["submit", demo], Some(WORKER_TOKEN), "401");
    // The client's token on the worker routes: the worker stops and says why.
    let w = farm.start_worker_with("wrong-token", 1, &["--token", CLIENT_TOKEN]);
    let status = farm.workers[w].wait(Duration::from_secs(30));
    assert!(!status.success());
    assert!(
        farm.workers[w].log().contains("token"),
        "{}",
        farm.workers[w].log()
    );

    // Scenes: not glTF at all, a truncated GLB.
    std::fs::write(farm.path().join("notes.glb"), b"these are not the frames").unwrap();
    refused(
        &farm,
        &["submit", "notes.glb"],
        Some(CLIENT_TOKEN),
        "not a glTF",
    );
    let glb = std::fs::read(&scene).unwrap();
    std::fs::write(farm.path().join("cut.glb"), &glb[..glb.len() / 2]).unwrap();
    refused(
        &farm,
        &["submit", "cut.glb"],
        Some(CLIENT_TOKEN),
        "truncated",
    );

    // Job specs: each error names the field.
    for (flags, field) in [
        (&["--spp", "0"][..], "spp"),
        (&["--spp", "2000000"], "spp"),
        (&["--camera", "7"], "camera"),
        (&["--animation", "nope"], "animation"),
        (&["--frames=-5-1"], "frames.start"),
        (&["--tile", "4"], "tile_size"),
        (
            &["--frames", "1-100", "--tile", "8", "--size", "64x64"],
            "tasks",
        ),
        (&["--frames", "5-1"], "frames"),
        (&["--size", "0x10"], "size"),
        (&["--size", "20000x10"], "1..=16384"),
    ] {
        let mut args = vec!["submit", demo];
        args.extend(flags);
        refused(&farm, &args, Some(CLIENT_TOKEN), field);
    }
    // What the CLI cannot send, straight to the API: an unknown field (refused, not
    // ignored), the server's own bound on the size, a scene the server does not have.
    let refused_raw = |body: String, field: &str, says: &str| {
        let answer = Request {
            method: "POST",
            path: "/api/v1/jobs",
            headers: vec![
                ("Authorization".into(), format!("Bearer {CLIENT_TOKEN}")),
                ("Content-Type".into(), "application/json".into()),
            ],
            body: body.as_bytes(),
        }
        .send(farm.port);
        assert_eq!(answer.status, 422, "{}", answer.text());
        let error = answer.error();
        assert_eq!(error.field.as_deref(), Some(field), "{error:?}");
        assert!(error.message.contains(says), "{error:?}");
    };
    // The submits above uploaded the scene before their job was refused.
    let digest: String = Sha256::digest(std::fs::read(demo).unwrap())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    let body = format!(r#"{{"scene":"{digest}","colour":"red"}}"#);
    refused_raw(body, "colour", "unknown field");
    let body = format!(r#"{{"scene":"{digest}","width":20000}}"#);
    refused_raw(body, "width", "16384");
    let body = format!(r#"{{"scene":"{}"}}"#, "0".repeat(64));
    refused_raw(body, "scene", "no scene with digest");

    // Nothing was created, and the farm renders a good job (a tile larger than the image
    // is one tile per frame) exactly as tessera render does.
    let jobs = farm.client(&["status", "--json"]);
    let jobs: proto::JobList = serde_json::from_str(&jobs).unwrap();
    assert!(jobs.jobs.is_empty(), "{jobs:?}");
    farm.start_worker_with("good", 2, &["--token", WORKER_TOKEN]);
    let mut args = vec![demo, "--frames", "1-2", "--tile", "64"];
    args.extend(settings("2"));
    let job = farm.submit(&args);
    let st = farm.wait_for_job(job, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    for frame in 1..=2 {
        let direct = render_directly(Path::new(demo), frame, "2", farm.path());
        assert!(farm.server_frame(job, frame) == direct, "frame {frame}");
    }
}

/// A worker written by hand: registers and leases like `tessera worker`, then uploads
/// whatever the test gives it.
struct Rogue {
    port: u16,
    id: u64,
    /// The join token, then the credential its registration answered.
    token: String,
}

impl Rogue {
    fn register(farm: &Farm) -> Rogue {
        let reg = WorkerRegistration {
            name: "rogue".into(),
            threads: 1,
            version: "test".into(),
            ..Default::default()
        };
        let mut rogue = Rogue {
            port: farm.port,
            id: 0,
            token: WORKER_TOKEN.into(),
        };
        let answer = rogue.post_json("/api/v1/workers", &reg);
        assert_eq!(answer.status, 201, "{}", answer.text());
        let registered = answer.json::<WorkerRegistered>();
        (rogue.id, rogue.token) = (registered.worker_id, registered.credential);
        rogue
    }

    fn request<'a>(&self, path: &'a str, body: &'a [u8]) -> Request<'a> {
        Request {
            method: "POST",
            path,
            headers: vec![("Authorization".into(), format!("Bearer {}", self.token))],
            body,
        }
    }

    fn post_json(&self, path: &str, value: &impl serde::Serialize) -> Answer {
        let body = serde_json::to_vec(value).unwrap();
        let mut req = self.request(path, &body);
        req.headers
            .push(("Content-Type".into(), "application/json".into()));
        req.send(self.port)
    }

    fn lease(&self) -> Lease {
        let path = format!("/api/v1/workers/{}/lease", self.id);
        let answer = self.post_json(
            &path,
            &LeaseRequest {
                wait_seconds: 10,
                ..LeaseRequest::default()
            },
        );
        assert_eq!(answer.status, 200, "{}", answer.text());
        answer.json()
    }

    /// Keeps `lease` alive, so that a slow machine cannot turn a bad-tile case into an
    /// expired-lease one.
    fn heartbeat(&self, lease: &Lease) {
        let path = format!("/api/v1/workers/{}/heartbeat", self.id);
        let beat = Heartbeat {
            token: Some(lease.token),
            log: Vec::new(),
        };
        let answer = self.post_json(&path, &beat);
        assert_eq!(answer.status, 200, "{}", answer.text());
    }

    /// An upload to `path` (see [`Rogue::result_path`]) with `meta`'s headers and `body`.
    fn upload<'a>(&self, path: &'a str, meta: &ResultMetadata, body: &'a [u8]) -> Request<'a> {
        let mut req = self.request(path, body);
        for (name, value) in meta.to_headers() {
            req.headers.push((name.into(), value));
        }
        req
    }

    fn result_path(&self, task: u64) -> String {
        format!("/api/v1/workers/{}/tasks/{task}/result", self.id)
    }
}

fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The headers a worker sends with `exr` for `lease`.
fn metadata(lease: &Lease, exr: &[u8]) -> ResultMetadata {
    ResultMetadata {
        attempt: lease.token.attempt,
        sha256: sha256_hex(exr),
        samples: lease.samples.end - lease.samples.start,
        rays: 1,
        render_ms: 1,
    }
}

/// Renders `lease` with the tracer as `tessera worker` does: the resolved tile.
fn render_lease(scene: &Path, lease: &Lease) -> Layers {
    use worker::render::{frame_options, sample_range, settings, tile_rect};
    let scene = tracer::loader::load_glb(&std::fs::read(scene).unwrap()).unwrap();
    let frame = prepare_frame(Arc::new(scene), &frame_options(lease)).unwrap();
    render_tile(
        &frame,
        &settings(lease),
        tile_rect(lease),
        sample_range(lease),
    )
    .resolve()
}

/// `layers` as the EXR a worker uploads for `lease`, with only the `wanted` layers and
/// in a frame of `frame_size`.
fn tile_exr(
    lease: &Lease,
    layers: &Layers,
    frame_size: (u32, u32),
    wanted: &[ImageLayer],
) -> Vec<u8> {
    let meta = ExrMetadata::new().with(
        ExrMetadata::SPP,
        (lease.samples.end - lease.samples.start).to_string(),
    );
    encode_exr_layers(frame_size, layers, &meta, wanted, ExrCompression::Zip).unwrap()
}

/// The job's status straight from the API (cheaper to poll than `tessera status`).
fn job_status(farm: &Farm, job: u64) -> JobStatus {
    let path = format!("/api/v1/jobs/{job}");
    let answer = Request {
        method: "GET",
        path: &path,
        headers: vec![("Authorization".into(), format!("Bearer {CLIENT_TOKEN}"))],
        body: b"",
    }
    .send(farm.port);
    assert_eq!(answer.status, 200, "{}", answer.text());
    answer.json()
}

/// The tile limit the rogue's farm runs with: above any real tile of the job (about 5 kB).
const MAX_TILE_BYTES: usize = 100_000;

#[test]
fn bad_uploads_from_a_rogue_worker_are_refused_and_the_job_renders_exactly() {
    let mut farm = Farm::new();
    farm.client_token = Some(CLIENT_TOKEN.into());
    let max_tile = MAX_TILE_BYTES.to_string();
    // The shortest lease the server takes, so that one can expire while the test waits.
    farm.start_server_with(
        5,
        &[
            "--worker-token",
            WORKER_TOKEN,
            "--client-token",
            CLIENT_TOKEN,
            "--max-tile-bytes",
            &max_tile,
        ],
    );
    let scene = farm.demo_scene();
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-2", "--tile", "16"];
    args.extend(settings("2"));
    let job = farm.submit(&args);
    let total = farm.job(job).tasks.total();

    // Two leases: `expiring` is left to expire, `lease` gets every bad upload.
    let rogue = Rogue::register(&farm);
    let expiring = rogue.lease();
    let lease = rogue.lease();
    let good_layers = render_lease(&scene, &lease);
    let frame_size = (lease.width, lease.height);
    let exr = |layers: &Layers| tile_exr(&lease, layers, frame_size, &ImageLayer::RENDERED);
    let good = exr(&good_layers);
    let path = rogue.result_path(lease.token.task_id);

    let rect = good_layers.rect;
    let mut nan = good_layers.clone();
    nan.beauty[3].y = f32::NAN;
    let mut inf = good_layers.clone();
    inf.depth[5] = f32::INFINITY;
    let small = Layers::new(TileRect::new(
        rect.x,
        rect.y,
        rect.width / 2,
        rect.height / 2,
    ));
    let bodies: Vec<(&str, Vec<u8>, &[&str])> = vec![
        (
            "not EXR",
            b"these are not the pixels".to_vec(),
            &["OpenEXR"],
        ),
        (
            "EXR cut in half",
            good[..good.len() / 2].to_vec(),
            &["OpenEXR"],
        ),
        ("tile too small", exr(&small), &["data window", "16x16"]),
        (
            "frame too large",
            tile_exr(&lease, &good_layers, (64, 48), &ImageLayer::RENDERED),
            &["display window", "32x24"],
        ),
        (
            "beauty only",
            tile_exr(&lease, &good_layers, frame_size, &[ImageLayer::Beauty]),
            &["channel", "albedo.R"],
        ),
        ("NaN", exr(&nan), &["NaN", "`G`"]),
        ("infinity", exr(&inf), &["inf", "`Z`"]),
    ];
    // The server counts the tiles it checked and refused (not those refused for their
    // lease, their header syntax or their length).
    let mut refusals = 0;
    for (case, body, expected) in &bodies {
        rogue.heartbeat(&lease);
        let answer = rogue
            .upload(&path, &metadata(&lease, body), body)
            .send(farm.port);
        assert_eq!(answer.status, 422, "{case}: {}", answer.text());
        let err = answer.error();
        assert_eq!(err.error, "bad_tile", "{case}: {err:?}");
        for word in *expected {
            assert!(err.message.contains(word), "{case}: no `{word}` in {err:?}");
        }
        refusals += 1;
    }

    // Headers that do not fit the body or the lease.
    let mut wrong_sum = metadata(&lease, &good);
    wrong_sum.sha256 = sha256_hex(b"other bytes");
    let mut wrong_samples = metadata(&lease, &good);
    wrong_samples.samples += 1;
    let mut stale = metadata(&lease, &good);
    stale.attempt += 1;
    let cases: Vec<(&str, ResultMetadata, u16, &[&str])> = vec![
        (
            "wrong checksum",
            wrong_sum,
            422,
            &["checksum", ResultMetadata::SHA256],
        ),
        (
            "wrong samples",
            wrong_samples,
            422,
            &[ResultMetadata::SAMPLES],
        ),
        ("another attempt", stale, 409, &["attempt", "expired"]),
    ];
    for (case, meta, status, expected) in cases {
        rogue.heartbeat(&lease);
        let answer = rogue.upload(&path, &meta, &good).send(farm.port);
        assert_eq!(answer.status, status, "{case}: {}", answer.text());
        let err = answer.error();
        for word in expected {
            assert!(err.message.contains(word), "{case}: no `{word}` in {err:?}");
        }
        refusals += usize::from(status == 422);
    }
    let mut bad_header = rogue.upload(&path, &metadata(&lease, &good), &good);
    bad_header
        .headers
        .retain(|(n, _)| n != ResultMetadata::SHA256);
    bad_header
        .headers
        .push((ResultMetadata::SHA256.into(), "not-a-digest".into()));
    let answer = bad_header.send(farm.port);
    assert_eq!(answer.status, 422, "{}", answer.text());
    assert_eq!(
        answer.error().field.as_deref(),
        Some(ResultMetadata::SHA256)
    );

    // A body cut short, and one over this server's --max-tile-bytes.
    rogue.heartbeat(&lease);
    let half = &good[..good.len() / 2];
    let answer = rogue
        .upload(&path, &metadata(&lease, &good), half)
        .send_cut_short(farm.port, good.len());
    assert_eq!(answer.status, 400, "{}", answer.text());
    let err = answer.error();
    assert!(err.message.contains("cut short"), "{err:?}");
    let big = vec![0u8; MAX_TILE_BYTES + 1];
    let answer = rogue
        .upload(&path, &metadata(&lease, &big), &big)
        .send(farm.port);
    assert_eq!(answer.status, 413, "{}", answer.text());
    assert!(
        answer.error().message.contains(&max_tile),
        "{}",
        answer.text()
    );

    // A task that does not exist.
    let answer = rogue
        .upload(&rogue.result_path(999_999), &metadata(&lease, &good), &good)
        .send(farm.port);
    assert_eq!(answer.status, 409, "{}", answer.text());
    assert!(
        answer.error().message.contains("999999"),
        "{}",
        answer.text()
    );

    // Nothing was accepted: the two leases are still out, no task is done.
    let st = farm.job(job);
    assert_eq!((st.tasks.leased, st.tasks.done), (2, 0), "{st:?}");
    let metrics = http::get(farm.port, "/metrics").text();
    assert!(
        metrics.contains(&format!("tessera_tiles_refused_total {refusals}")),
        "{metrics}"
    );

    // The good tile is accepted once; the same upload again is answered and ignored.
    for accepted in [true, false] {
        let answer = rogue
            .upload(&path, &metadata(&lease, &good), &good)
            .send(farm.port);
        assert_eq!(answer.status, 200, "{}", answer.text());
        assert_eq!(answer.json::<ResultAck>().accepted, accepted);
    }
    let st = farm.job(job);
    assert_eq!((st.tasks.leased, st.tasks.done), (1, 1), "{st:?}");

    // The references, rendered while the other lease runs out.
    let direct: Vec<Layers> = (1..=2)
        .map(|frame| render_directly(&scene, frame, "2", farm.path()))
        .collect();
    wait_until(
        "the unrenewed lease to expire",
        Duration::from_secs(60),
        || job_status(&farm, job).tasks.leased == 0,
        || farm.logs(),
    );
    let expired_path = rogue.result_path(expiring.token.task_id);
    let expired_tile = tile_exr(
        &expiring,
        &render_lease(&scene, &expiring),
        frame_size,
        &ImageLayer::RENDERED,
    );
    let answer = rogue
        .upload(
            &expired_path,
            &metadata(&expiring, &expired_tile),
            &expired_tile,
        )
        .send(farm.port);
    assert_eq!(answer.status, 409, "{}", answer.text());
    assert!(
        answer.error().message.contains("expired"),
        "{}",
        answer.text()
    );
    let st = farm.job(job);
    assert_eq!((st.tasks.queued, st.tasks.done), (total - 1, 1), "{st:?}");

    // A real worker finishes the job, exactly as tessera render renders it.
    farm.start_worker_with("good", 2, &["--token", WORKER_TOKEN]);
    let st = farm.wait_for_job(job, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    for (frame, direct) in (1..=2).zip(&direct) {
        assert!(farm.server_frame(job, frame) == *direct, "frame {frame}");
    }
}

// ---------------------------------------------------------------------------------------
// Broken scenes from a client

/// A good one-triangle scene (mesh 'Tri'; its 44-byte buffer holds three positions, then
/// the u16 indices and two bytes of padding), which each case below breaks in one way.
fn triangle() -> serde_json::Value {
    serde_json::json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": 44}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 6}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": 3,
             "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "type": "SCALAR", "count": 3}
        ],
        "meshes": [{"name": "Tri", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "scene": 0
    })
}

/// The triangle's buffer: vertex 1 at (`x`, 0, 0), vertex 2 at (0, `y`, 0), and `indices`.
fn triangle_bin(x: f32, y: f32, indices: [u16; 3]) -> Vec<u8> {
    let positions = [0.0, 0.0, 0.0, x, 0.0, 0.0, 0.0, y, 0.0f32];
    let mut bin: Vec<u8> = positions.iter().flat_map(|v| v.to_le_bytes()).collect();
    bin.extend(indices.iter().flat_map(|i| i.to_le_bytes()));
    bin.resize(44, 0);
    bin
}

/// The triangle with `edit` applied, as a GLB around `bin`.
fn triangle_glb(edit: impl FnOnce(&mut serde_json::Value), bin: &[u8]) -> Vec<u8> {
    let mut json = triangle();
    edit(&mut json);
    tracer::loader::write_glb(&serde_json::to_vec(&json).unwrap(), Some(bin)).unwrap()
}

/// The triangle drawn with a texture from image `uri`.
fn textured(json: &mut serde_json::Value, uri: &str) {
    json["images"] = serde_json::json!([{"uri": uri}]);
    json["textures"] = serde_json::json!([{"source": 0}]);
    json["materials"] =
        serde_json::json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
    json["meshes"][0]["primitives"][0]["material"] = 0.into();
}

/// The scenes in `data/scenes/`, by file name.
fn stored_scenes(farm: &Farm) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(farm.data_dir().join("scenes"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn broken_scenes_are_refused_by_name_and_nothing_is_stored() {
    let mut farm = Farm::new();
    farm.start_server(60);
    let dir = farm.path().to_owned();
    let url = farm.url();
    let good = triangle_bin(1.0, 1.0, [0, 1, 2]);
    let json = |j: serde_json::Value| serde_json::to_vec(&j).unwrap();

    // Each case: the file a user submits, and the words its refusal must hold.
    let huge = 1u64 << 31;
    let cases: Vec<(&str, Vec<u8>, &[&str])> = vec![
        (
            "count_as_text.glb",
            triangle_glb(|j| j["accessors"][0]["count"] = "three".into(), &good),
            &["accessors[0].count", "invalid type", "\"three\""],
        ),
        (
            "nodes_as_object.glb",
            triangle_glb(
                |j| j["nodes"] = serde_json::json!({"0": {"mesh": 0}}),
                &good,
            ),
            &["nodes: invalid type: map, expected a sequence"],
        ),
        (
            "view_past_buffer.glb",
            triangle_glb(|j| j["bufferViews"][0]["byteLength"] = 400.into(), &good),
            &["bufferView 0", "0..400", "outside buffer 0 (44 bytes)"],
        ),
        (
            "accessor_past_view.glb",
            triangle_glb(|j| j["accessors"][0]["count"] = 4.into(), &good),
            &[
                "accessor 0",
                "4 elements",
                "overrun bufferView 0 (36 bytes)",
            ],
        ),
        (
            "index_out_of_range.glb",
            triangle_glb(|_| {}, &triangle_bin(1.0, 1.0, [0, 1, 7])),
            &["accessor 1: index 7 out of range for 3 vertices in mesh 'Tri', primitive 0"],
        ),
        (
            "nan.glb",
            triangle_glb(|_| {}, &triangle_bin(f32::NAN, 1.0, [0, 1, 2])),
            &[
                "accessor 0: position 1 ([NaN, 0, 0]) is not finite",
                "mesh 'Tri'",
            ],
        ),
        (
            "infinity.glb",
            triangle_glb(|_| {}, &triangle_bin(1.0, f32::INFINITY, [0, 1, 2])),
            &[
                "accessor 0: position 2 ([0, inf, 0]) is not finite",
                "mesh 'Tri'",
            ],
        ),
        // Huge declared counts are refused before anything that size is allocated (24 GiB
        // here): one over a 36-byte view, one with no view at all (zeros, then sparse
        // values).
        (
            "huge_count.glb",
            triangle_glb(|j| j["accessors"][0]["count"] = huge.into(), &good),
            &["accessor 0", "2147483648 elements", "overrun bufferView 0"],
        ),
        (
            "huge_sparse.glb",
            triangle_glb(
                |j| {
                    let a = j["accessors"][0].as_object_mut().unwrap();
                    a.remove("bufferView");
                    a.insert("count".into(), huge.into());
                    a.insert(
                        "sparse".into(),
                        serde_json::json!({"count": 1,
                            "indices": {"bufferView": 1, "componentType": 5123},
                            "values": {"bufferView": 0}}),
                    );
                },
                &good,
            ),
            &["accessor 0", "2147483648 elements", "no bufferView"],
        ),
        (
            "cycle.glb",
            triangle_glb(
                |j| {
                    j["nodes"] =
                        serde_json::json!([{"mesh": 0, "children": [1]}, {"children": [0]}])
                },
                &good,
            ),
            &["node 1: child node 0 is also its ancestor", "cycle"],
        ),
        (
            "draco.glb",
            triangle_glb(
                |j| {
                    let draco = serde_json::json!(["KHR_draco_mesh_compression"]);
                    j["extensionsUsed"] = draco.clone();
                    j["extensionsRequired"] = draco;
                },
                &good,
            ),
            &["required extension 'KHR_draco_mesh_compression' is not supported"],
        ),
        // A .gltf whose files are missing: the client's packer names the file, and the
        // server is not asked.
        (
            "missing_bin.gltf",
            json({
                let mut j = triangle();
                j["buffers"][0]["uri"] = "tri.bin".into();
                j
            }),
            &["packing missing_bin.gltf: buffer 0: file 'tri.bin' not found"],
        ),
        (
            "missing_png.gltf",
            json({
                let mut j = triangle();
                j["buffers"][0]["uri"] = "present.bin".into();
                textured(&mut j, "wood.png");
                j
            }),
            &["packing missing_png.gltf: image 0: file 'wood.png' not found"],
        ),
    ];
    std::fs::write(dir.join("present.bin"), &good).unwrap();
    for (file, bytes, expected) in &cases {
        std::fs::write(dir.join(file), bytes).unwrap();
        let mut args = vec!["submit", file, "--server", &url];
        args.extend(settings("1"));
        let out = tessera(&args, &dir);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{file} was accepted:\n{stderr}");
        for word in *expected {
            assert!(
                stderr.contains(word) && !stderr.contains("panicked"),
                "{file}: no `{word}` in:\n{stderr}"
            );
        }
    }

    // A GLB that refers to a file outside it (submit would pack the file or name it as
    // missing): the server names the image and the file.
    let outside = triangle_glb(|j| textured(j, "wood.png"), &good);
    let answer = Request {
        method: "POST",
        path: "/api/v1/scenes",
        headers: vec![("Content-Type".into(), "model/gltf-binary".into())],
        body: &outside,
    }
    .send(farm.port);
    assert_eq!(answer.status, 422, "{}", answer.text());
    let err = answer.error();
    assert_eq!(err.error, "bad_scene", "{err:?}");
    assert!(
        err.message
            .contains("image 0: refers to external file 'wood.png'")
            && err.message.contains("self-contained"),
        "{err:?}"
    );

    // The server is up, nothing was stored and no job was created.
    assert!(farm.server.as_mut().unwrap().running(), "{}", farm.logs());
    assert_eq!(http::get(farm.port, "/healthz").status, 200);
    assert_eq!(stored_scenes(&farm), Vec::<String>::new());
    let jobs: proto::JobList = serde_json::from_str(&farm.client(&["status", "--json"])).unwrap();
    assert!(jobs.jobs.is_empty(), "{jobs:?}");

    // A scene that draws no triangles is legal glTF: it is accepted, and the user sees
    // the warning.
    let empty = triangle_glb(|j| j["scenes"][0]["nodes"] = serde_json::json!([]), &good);
    std::fs::write(dir.join("empty.glb"), &empty).unwrap();
    let mut args = vec!["submit", "empty.glb", "--server", &url];
    args.extend(settings("1"));
    let out = tessera(&args, &dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("warning: empty.glb: the default scene draws no triangles"),
        "{stderr}"
    );
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("0 triangles"),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );

    // The good triangle goes in as well.
    std::fs::write(dir.join("good.glb"), triangle_glb(|_| {}, &good)).unwrap();
    let mut args = vec!["good.glb"];
    args.extend(settings("1"));
    let job = farm.submit(&args);
    assert_eq!(farm.job(job).tasks.total(), 1);
    let mut want = vec![
        format!("{}.glb", sha256_hex(&empty)),
        format!("{}.glb", sha256_hex(&triangle_glb(|_| {}, &good))),
    ];
    want.sort();
    assert_eq!(stored_scenes(&farm), want);
}

/// What can be checked without the server is checked before the upload: with no server
/// listening, a bad setting is still reported by name (not as an unreachable server).
#[test]
fn bad_settings_are_refused_before_the_scene_is_uploaded() {
    let farm = Farm::new();
    let scene = farm.demo_scene();
    let nowhere = format!("http://127.0.0.1:{}", tests::free_port());
    for (flag, value, words) in [
        ("--fps", "-5", "the job's `fps`: must be above 0"),
        ("--spp", "0", "the job's `spp`: must be 1 to"),
        ("--tile", "3", "the job's `tile_size`: must be 8 to"),
        (
            "--camera",
            "7",
            "the job's `camera`: camera 7 does not exist",
        ),
        ("--frames", "1-200000", "at most 100000"),
    ] {
        let out = tessera(
            &[
                "submit",
                scene.to_str().unwrap(),
                "--server",
                &nowhere,
                flag,
                value,
            ],
            farm.path(),
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(words) && !err.contains("cannot reach"),
            "{flag} {value}: {err}"
        );
    }
}
