//! A real server (its own thread and runtime, so a test can kill it), the worker daemon
//! on the test's runtime, a small animated test scene, and job helpers.

use std::f32::consts::FRAC_1_SQRT_2;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use proto::{CameraSpec, FrameRange, JobSpec, JobState, JobStatus, SceneInfo};
use reqwest::StatusCode;
use tracer::animation::AnimationChoice;
use tracer::film::{Layers, SampleRange, TileRect};
use tracer::motion::Shutter;
use tracer::render::{prepare_frame, render_tile, CameraChoice, FrameOptions, RenderSettings};
use worker::{RunSummary, UploadCompression, WorkerConfig};

/// Logs of the worker and server when a test runs with `--nocapture` (RUST_LOG to tune).
pub fn init_logs() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "info,tower_http=warn".into()),
        )
        .with_test_writer()
        .try_init();
}

pub use server::testing::TestServer;

/// A server config for a fresh data folder under `dir`.
pub fn server_config(dir: &Path) -> server::Config {
    server::Config::new(dir.join("data"))
}

/// A worker of 2 threads for `server` (a base URL), caching scenes in `cache`, with
/// every other setting at its default.
pub fn worker_config(server: &str, cache: &Path) -> WorkerConfig {
    WorkerConfig {
        server: server.to_string(),
        token: None,
        ca: None,
        threads: 2,
        cache_dir: cache.to_path_buf(),
        cache_limit_bytes: u64::MAX,
        name: "test-worker".into(),
        tags: vec![],
        upload_compression: UploadCompression::Auto,
        denoise: true,
        oidn: None,
        encode: true,
        ffmpeg: None,
        fault: None,
        pilot: Default::default(),
    }
}

/// A worker daemon running on the test's runtime.
pub struct TestWorker {
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    drain: Option<tokio::sync::oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<anyhow::Result<RunSummary>>,
}

impl TestWorker {
    /// Starts `worker::run` against `server` (a base URL), caching scenes in `cache`.
    pub fn start(server: &str, cache: &Path, token: Option<&str>) -> TestWorker {
        Self::start_config(WorkerConfig {
            token: token.map(str::to_string),
            ..worker_config(server, cache)
        })
    }

    /// Starts `worker::run` with `config`.
    pub fn start_config(config: WorkerConfig) -> TestWorker {
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let (drain_tx, drain_rx) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(worker::run_draining(
            config,
            async {
                let _ = rx.await;
            },
            async {
                // Dropped unsent: no drain.
                if drain_rx.await.is_err() {
                    std::future::pending::<()>().await;
                }
            },
        ));
        TestWorker {
            stop: Some(tx),
            drain: Some(drain_tx),
            task,
        }
    }

    /// Asks the worker to drain, as SIGUSR1 does.
    pub fn drain(&mut self) {
        let _ = self.drain.take().unwrap().send(());
    }

    /// Completes the shutdown future and waits for `run` to return.
    pub async fn shutdown(mut self) -> anyhow::Result<RunSummary> {
        let _ = self.stop.take().unwrap().send(());
        tokio::time::timeout(Duration::from_secs(20), self.task)
            .await
            .expect("the worker stops within 20 s")
            .expect("the worker task did not panic")
    }

    /// Waits for `run` to return by itself.
    pub async fn finished(self) -> anyhow::Result<RunSummary> {
        tokio::time::timeout(Duration::from_secs(20), self.task)
            .await
            .expect("the worker stops within 20 s")
            .expect("the worker task did not panic")
    }
}

/// A server with the spinning quad uploaded: what most tests start from.
pub struct Setup {
    /// The server's data (and the workers' caches, in `cache/`).
    pub dir: tempfile::TempDir,
    pub s: TestServer,
    pub c: reqwest::Client,
    /// The scene's GLB, for direct renders.
    pub glb: Vec<u8>,
    pub scene: SceneInfo,
}

pub async fn setup() -> Setup {
    init_logs();
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(server_config(dir.path())).kill_on_drop();
    let c = client();
    let glb = spinning_quad();
    let scene = upload_scene(&s, &c, glb.clone()).await;
    Setup {
        dir,
        s,
        c,
        glb,
        scene,
    }
}

/// A GLB from glTF JSON and a BIN chunk.
pub fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    tracer::loader::write_glb(json.as_bytes(), (!bin.is_empty()).then_some(bin)).unwrap()
}

/// A coloured quad in front of a camera named `Main`, lit by the default environment,
/// turning about its vertical axis in an animation named `Spin` (so the shutter, motion
/// steps and animation of a job all change the picture).
pub fn spinning_quad() -> Vec<u8> {
    let mut bin = Vec::new();
    for p in [
        [-1.0f32, -1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
    ] {
        for c in p {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    for t in [0.0f32, 1.0] {
        bin.extend_from_slice(&t.to_le_bytes());
    }
    for q in [
        [0.0f32, 0.3826834, 0.0, 0.9238795],
        [0.0, FRAC_1_SQRT_2, 0.0, FRAC_1_SQRT_2],
    ] {
        for c in q {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    let json = r#"{
      "asset": {"version": "2.0"},
      "scene": 0,
      "scenes": [{"nodes": [0, 1]}],
      "nodes": [
        {"mesh": 0, "rotation": [0.0, 0.3826834, 0.0, 0.9238795]},
        {"camera": 0, "translation": [0.0, 0.0, 3.0], "name": "CameraNode"}
      ],
      "cameras": [{"name": "Main", "type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.01}}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
      "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.5, 0.3, 1.0], "metallicFactor": 0.0}}],
      "animations": [{
        "name": "Spin",
        "channels": [{"sampler": 0, "target": {"node": 0, "path": "rotation"}}],
        "samplers": [{"input": 2, "output": 3, "interpolation": "LINEAR"}]
      }],
      "buffers": [{"byteLength": 100}],
      "bufferViews": [
        {"buffer": 0, "byteOffset": 0, "byteLength": 48},
        {"buffer": 0, "byteOffset": 48, "byteLength": 12},
        {"buffer": 0, "byteOffset": 60, "byteLength": 8},
        {"buffer": 0, "byteOffset": 68, "byteLength": 32}
      ],
      "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
         "min": [-1.0, -1.0, 0.0], "max": [1.0, 1.0, 0.0]},
        {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"},
        {"bufferView": 2, "componentType": 5126, "count": 2, "type": "SCALAR",
         "min": [0.0], "max": [1.0]},
        {"bufferView": 3, "componentType": 5126, "count": 2, "type": "VEC4"}
      ]
    }"#;
    glb(json, &bin)
}

pub fn client() -> reqwest::Client {
    reqwest::Client::builder()
        .timeout(Duration::from_secs(60))
        .build()
        .unwrap()
}

pub async fn upload_scene(s: &TestServer, c: &reqwest::Client, glb: Vec<u8>) -> SceneInfo {
    let res = c.post(s.url("/scenes")).body(glb).send().await.unwrap();
    assert!(res.status().is_success(), "{:?}", res.text().await);
    res.json().await.unwrap()
}

/// A small job on the spinning quad: `frames` from 1, 32×24 in 16-pixel tiles, `spp`
/// samples in `passes` passes, motion blur over half a frame.
pub fn spec(digest: &str, frames: i32, spp: u32, passes: u32) -> JobSpec {
    let mut spec = JobSpec::new(digest);
    spec.frames = Some(FrameRange {
        start: 1,
        end: frames,
        step: 1,
    });
    spec.width = 32;
    spec.height = 24;
    spec.tile_size = Some(16);
    spec.spp = spp;
    spec.sample_passes = passes;
    spec.max_depth = 3;
    spec.seed = 5;
    spec.camera = CameraSpec::Name("Main".into());
    spec.shutter = [0.0, 0.5];
    spec.motion_steps = Some(2);
    spec.animation = Some("Spin".into());
    spec
}

pub async fn create_job(s: &TestServer, c: &reqwest::Client, spec: &JobSpec) -> JobStatus {
    let res = c.post(s.url("/jobs")).json(spec).send().await.unwrap();
    assert_eq!(res.status(), StatusCode::CREATED, "{:?}", res.text().await);
    res.json().await.unwrap()
}

pub async fn job(s: &TestServer, c: &reqwest::Client, id: u64) -> JobStatus {
    let res = c.get(s.url(&format!("/jobs/{id}"))).send().await.unwrap();
    assert_eq!(res.status(), StatusCode::OK);
    res.json().await.unwrap()
}

/// Polls the job until `done(status)` holds; panics with the last status after `limit`.
pub async fn wait_for(
    s: &TestServer,
    c: &reqwest::Client,
    id: u64,
    limit: Duration,
    done: impl Fn(&JobStatus) -> bool,
) -> JobStatus {
    let start = Instant::now();
    loop {
        let status = job(s, c, id).await;
        if done(&status) {
            return status;
        }
        assert!(
            start.elapsed() < limit,
            "job {id} still not there after {limit:?}: {status:?}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// The server's worker list.
pub async fn workers(s: &TestServer) -> proto::WorkerList {
    client()
        .get(s.url("/workers"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap()
}

/// Polls the server's worker list until a worker is on it (registered: a worker that
/// denoises or encodes first times those steps), for at most 10 s.
pub async fn wait_for_a_worker(s: &TestServer) {
    let start = Instant::now();
    loop {
        if !workers(s).await.workers.is_empty() {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "no worker registered"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

pub async fn wait_until_done(s: &TestServer, c: &reqwest::Client, id: u64) -> JobStatus {
    wait_for(s, c, id, Duration::from_secs(60), |j| {
        j.state == JobState::Done
    })
    .await
}

/// The assembled frame as the server serves it.
pub async fn frame_exr(s: &TestServer, c: &reqwest::Client, job: u64, frame: i32) -> Layers {
    let res = c
        .get(s.url(&format!("/jobs/{job}/frames/{frame}/exr")))
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::OK, "frame {frame}");
    let bytes = res.bytes().await.unwrap();
    tracer::output::decode_exr(&bytes).unwrap().layers
}

/// The same frame rendered whole with the tracer directly, options written out here
/// (not taken from the worker) so the worker's mapping of a lease is checked.
pub fn direct_frame(glb: &[u8], spec: &JobSpec, frame: i32) -> Layers {
    let scene = Arc::new(tracer::loader::load_glb(glb).unwrap());
    let options = FrameOptions {
        frame,
        fps: spec.fps,
        shutter: Shutter {
            open: spec.shutter[0],
            close: spec.shutter[1],
        },
        motion_steps: spec.motion_steps,
        animation: match &spec.animation {
            Some(name) => AnimationChoice::Name(name.clone()),
            None => AnimationChoice::All,
        },
        width: spec.width,
        height: spec.height,
        camera: CameraChoice::Name("Main".into()),
        environment: None,
    };
    let prepared = prepare_frame(scene, &options).unwrap();
    let settings = RenderSettings {
        noise: None,
        max_depth: spec.max_depth,
        seed: spec.seed,
        fixed_pattern: spec.fixed_pattern,
        ..RenderSettings::DEFAULT
    };
    render_tile(
        &prepared,
        &settings,
        TileRect::new(0, 0, spec.width, spec.height),
        SampleRange::new(0, spec.spp),
    )
    .resolve()
}

/// A loopback address nobody listens on, one no other test's server can be handed
/// (`tests::free_port`): connections to it are refused until the test binds it.
pub fn free_addr() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], tests::free_port()))
}

/// Binds `addr` again, retrying briefly (the OS may hold it a moment).
pub fn bind_again(addr: SocketAddr) -> std::net::TcpListener {
    for _ in 0..50 {
        if let Ok(l) = std::net::TcpListener::bind(addr) {
            return l;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    panic!("{addr} could not be bound again");
}

/// The `.glb` files in the cache folder, and any other entries (temp files).
pub fn cache_entries(dir: &Path) -> (Vec<PathBuf>, Vec<PathBuf>) {
    let mut glbs = vec![];
    let mut other = vec![];
    let identity = worker::identity::path(dir, "", "");
    let identity = identity.file_name().unwrap().to_str().unwrap();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_str().unwrap();
        // The worker's identity file (one per server and name) belongs beside the scenes.
        if name.starts_with("identity-") && name.len() == identity.len() {
            continue;
        }
        if p.extension().is_some_and(|x| x == "glb") {
            glbs.push(p);
        } else {
            other.push(p);
        }
    }
    (glbs, other)
}
