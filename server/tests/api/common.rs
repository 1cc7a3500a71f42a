//! A real server on 127.0.0.1:0 in its own runtime (so a test can crash it: the shared
//! [`TestServer`]), a test scene as GLB, and a simulated worker that renders tiles with
//! the tracer.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use proto::{Lease, LeaseRequest, ResultAck, ResultMetadata, WorkerRegistered, WorkerRegistration};
use reqwest::StatusCode;
use server::Config;
use tracer::film::{Layers, SampleRange, TileBuffer, TileRect};
use tracer::output::{encode_exr, ExrMetadata};
use tracer::render::{
    prepare_frame, render_tile, CameraChoice, FrameOptions, PreparedFrame, RenderSettings,
};

pub use server::testing::TestServer;

/// A config for a fresh data folder.
pub fn config(dir: &Path) -> Config {
    Config::new(dir.join("data"))
}

/// A GLB from glTF JSON and a BIN chunk.
pub fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    tracer::loader::write_glb(json.as_bytes(), (!bin.is_empty()).then_some(bin)).unwrap()
}

/// A grey quad in front of a camera named `Main`, lit by the default environment.
pub fn quad_scene() -> Vec<u8> {
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
      "buffers": [{"byteLength": 60}],
      "bufferViews": [
        {"buffer": 0, "byteOffset": 0, "byteLength": 48},
        {"buffer": 0, "byteOffset": 48, "byteLength": 12}
      ],
      "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
         "min": [-1.0, -1.0, 0.0], "max": [1.0, 1.0, 0.0]},
        {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}
      ]
    }"#;
    glb(json, &bin)
}

/// An HTTP client; `token` as bearer when given.
pub fn client() -> reqwest::Client {
    reqwest::Client::builder()
        .timeout(Duration::from_secs(120))
        .build()
        .unwrap()
}

pub async fn upload_scene(s: &TestServer, c: &reqwest::Client, glb: Vec<u8>) -> proto::SceneInfo {
    let res = c.post(s.url("/scenes")).body(glb).send().await.unwrap();
    assert!(res.status().is_success(), "{:?}", res.text().await);
    res.json().await.unwrap()
}

pub async fn create_job(
    s: &TestServer,
    c: &reqwest::Client,
    spec: &proto::JobSpec,
) -> proto::JobStatus {
    let res = c.post(s.url("/jobs")).json(spec).send().await.unwrap();
    assert_eq!(res.status(), StatusCode::CREATED, "{:?}", res.text().await);
    res.json().await.unwrap()
}

/// A simulated worker: registers, leases, renders with the tracer, uploads.
pub struct SimWorker {
    pub id: u64,
    pub client: reqwest::Client,
    /// Its own credential, from its registration: the bearer token of its calls.
    pub credential: String,
    scene: Option<(String, Arc<tracer::scene::Scene>)>,
}

impl SimWorker {
    pub async fn register(s: &TestServer, name: &str) -> SimWorker {
        Self::register_with(s, name, None).await
    }

    pub async fn register_with(s: &TestServer, name: &str, token: Option<&str>) -> SimWorker {
        Self::join(s, name, token, WorkerRegistration::default()).await
    }

    /// A worker that says it has `denoiser`: it is given denoise tasks.
    pub async fn register_denoiser(s: &TestServer, name: &str, denoiser: &str) -> SimWorker {
        let steps = WorkerRegistration {
            denoiser: Some(denoiser.to_string()),
            ..WorkerRegistration::default()
        };
        Self::join(s, name, None, steps).await
    }

    /// A worker that says it has `encoder`: it is given encode tasks.
    pub async fn register_encoder(s: &TestServer, name: &str, encoder: &str) -> SimWorker {
        let steps = WorkerRegistration {
            encoder: Some(encoder.to_string()),
            ..WorkerRegistration::default()
        };
        Self::join(s, name, None, steps).await
    }

    /// Registers as `name` with the steps (denoiser, encoder) of `steps`.
    async fn join(
        s: &TestServer,
        name: &str,
        token: Option<&str>,
        steps: WorkerRegistration,
    ) -> SimWorker {
        let client = client();
        let mut req = client.post(s.url("/workers")).json(&WorkerRegistration {
            name: name.into(),
            threads: 2,
            version: "test".into(),
            ..steps
        });
        if let Some(t) = token {
            req = req.bearer_auth(t);
        }
        let res = req.send().await.unwrap();
        assert_eq!(res.status(), StatusCode::CREATED);
        let reg: WorkerRegistered = res.json().await.unwrap();
        SimWorker {
            id: reg.worker_id,
            client,
            credential: reg.credential,
            scene: None,
        }
    }

    pub fn auth(&self, r: reqwest::RequestBuilder) -> reqwest::RequestBuilder {
        r.bearer_auth(&self.credential)
    }

    /// One lease request without waiting: `None` on 204.
    pub async fn lease(&self, s: &TestServer) -> Option<Lease> {
        self.lease_wait(s, 0).await
    }

    /// A lease request that waits up to `wait_seconds` for work, sent from a task of its
    /// own so that the test can make work appear meanwhile; the response as it came.
    pub fn lease_waiting(
        &self,
        s: &TestServer,
        wait_seconds: u64,
    ) -> tokio::task::JoinHandle<reqwest::Response> {
        let request = self
            .auth(
                self.client
                    .post(s.url(&format!("/workers/{}/lease", self.id))),
            )
            .json(&LeaseRequest {
                wait_seconds,
                ..LeaseRequest::default()
            });
        tokio::spawn(async move { request.send().await.unwrap() })
    }

    pub async fn lease_wait(&self, s: &TestServer, wait_seconds: u64) -> Option<Lease> {
        self.lease_with(
            s,
            LeaseRequest {
                wait_seconds,
                ..LeaseRequest::default()
            },
        )
        .await
    }

    /// A lease request as given (with the previous lease's last log lines, say).
    pub async fn lease_with(&self, s: &TestServer, request: LeaseRequest) -> Option<Lease> {
        let res = self
            .auth(
                self.client
                    .post(s.url(&format!("/workers/{}/lease", self.id))),
            )
            .json(&request)
            .send()
            .await
            .unwrap();
        match res.status() {
            StatusCode::OK => Some(res.json().await.unwrap()),
            StatusCode::NO_CONTENT => None,
            other => panic!("lease: {other} {:?}", res.text().await),
        }
    }

    /// The scene of `lease`, fetched by digest once.
    pub async fn scene(&mut self, s: &TestServer, lease: &Lease) -> Arc<tracer::scene::Scene> {
        if let Some((d, scene)) = &self.scene {
            if *d == lease.scene {
                return scene.clone();
            }
        }
        let res = self
            .auth(self.client.get(s.url(&format!("/scenes/{}", lease.scene))))
            .send()
            .await
            .unwrap();
        assert_eq!(res.status(), StatusCode::OK);
        let bytes = res.bytes().await.unwrap();
        let scene = Arc::new(tracer::loader::load_glb(&bytes).unwrap());
        self.scene = Some((lease.scene.clone(), scene.clone()));
        scene
    }

    /// Renders `lease` and returns the tile as the EXR bytes a worker uploads.
    pub async fn render(&mut self, s: &TestServer, lease: &Lease) -> (Vec<u8>, TileBuffer) {
        let scene = self.scene(s, lease).await;
        let lease = lease.clone();
        tokio::task::spawn_blocking(move || {
            let frame = prepared(scene, &lease);
            let rect = TileRect::new(
                lease.tile.x,
                lease.tile.y,
                lease.tile.width,
                lease.tile.height,
            );
            let tile = render_tile(
                &frame,
                &settings(&lease),
                rect,
                SampleRange::new(lease.samples.start, lease.samples.end),
            );
            (tile_exr(&lease, &tile.resolve()), tile)
        })
        .await
        .unwrap()
    }

    /// Uploads `exr` for `lease`.
    pub async fn upload(&self, s: &TestServer, lease: &Lease, exr: Vec<u8>) -> reqwest::Response {
        let meta = ResultMetadata {
            attempt: lease.token.attempt,
            sha256: server::store::sha256_hex(&exr),
            samples: lease.samples.end - lease.samples.start,
            rays: 1000,
            render_ms: 5,
        };
        self.upload_with(s, lease, exr, &meta).await
    }

    pub async fn upload_with(
        &self,
        s: &TestServer,
        lease: &Lease,
        exr: Vec<u8>,
        meta: &ResultMetadata,
    ) -> reqwest::Response {
        let mut req = self.auth(self.client.post(s.url(&format!(
            "/workers/{}/tasks/{}/result",
            self.id, lease.token.task_id
        ))));
        for (k, v) in meta.to_headers() {
            req = req.header(k, v);
        }
        req.body(exr).send().await.unwrap()
    }

    /// Leases, renders and uploads until there is no work; returns the leases done.
    pub async fn work_until_idle(&mut self, s: &TestServer) -> Vec<Lease> {
        let mut done = vec![];
        while let Some(lease) = self.lease(s).await {
            let (exr, _) = self.render(s, &lease).await;
            let res = self.upload(s, &lease, exr).await;
            assert_eq!(res.status(), StatusCode::OK, "{:?}", res.text().await);
            let ack: ResultAck = res.json().await.unwrap();
            assert!(ack.accepted);
            done.push(lease);
        }
        done
    }

    pub async fn heartbeat(&self, s: &TestServer, lease: &Lease) -> reqwest::Response {
        self.heartbeat_logging(s, lease, Vec::new()).await
    }

    /// A heartbeat that carries log lines of the lease.
    pub async fn heartbeat_logging(
        &self,
        s: &TestServer,
        lease: &Lease,
        log: Vec<proto::LogLine>,
    ) -> reqwest::Response {
        self.auth(
            self.client
                .post(s.url(&format!("/workers/{}/heartbeat", self.id))),
        )
        .json(&proto::Heartbeat {
            token: Some(lease.token),
            log,
        })
        .send()
        .await
        .unwrap()
    }

    pub async fn fail(&self, s: &TestServer, lease: &Lease, message: &str) -> reqwest::Response {
        self.fail_logging(s, lease, message, Vec::new()).await
    }

    /// A failure report that carries log lines of the lease.
    pub async fn fail_logging(
        &self,
        s: &TestServer,
        lease: &Lease,
        message: &str,
        log: Vec<proto::LogLine>,
    ) -> reqwest::Response {
        self.auth(self.client.post(s.url(&format!(
            "/workers/{}/tasks/{}/failure",
            self.id, lease.token.task_id
        ))))
        .json(&proto::FailureReport {
            attempt: lease.token.attempt,
            message: message.into(),
            log,
        })
        .send()
        .await
        .unwrap()
    }
}

/// The tracer's frame for a lease.
pub fn prepared(scene: Arc<tracer::scene::Scene>, lease: &Lease) -> PreparedFrame {
    let options = FrameOptions {
        frame: lease.frame,
        fps: lease.fps,
        width: lease.width,
        height: lease.height,
        camera: match &lease.camera {
            proto::CameraSpec::Default => CameraChoice::Default,
            proto::CameraSpec::Index(i) => CameraChoice::Index(*i as usize),
            proto::CameraSpec::Name(n) => CameraChoice::Name(n.clone()),
        },
        ..FrameOptions::default()
    };
    prepare_frame(scene, &options).unwrap()
}

pub fn settings(lease: &Lease) -> RenderSettings {
    RenderSettings {
        noise: lease.noise_threshold.map(|t| tracer::render::NoiseTarget {
            threshold: t as f32,
            min_samples: lease.min_spp,
        }),
        max_depth: lease.max_depth,
        seed: lease.seed,
        fixed_pattern: lease.fixed_pattern,
        ..RenderSettings::DEFAULT
    }
}

/// An EXR of a `w`x`h` frame whose beauty is `rgb` everywhere: what a denoise lease uploads.
pub fn denoised_upload(w: u32, h: u32, rgb: glam::Vec3) -> Vec<u8> {
    let mut layers = Layers::new(TileRect::new(0, 0, w, h));
    layers.beauty.fill(rgb.extend(1.0));
    tracer::output::encode_exr_layers(
        (w, h),
        &layers,
        &ExrMetadata::new(),
        &[tracer::output::ImageLayer::Beauty],
        tracer::output::ExrCompression::Zip,
    )
    .unwrap()
}

/// The EXR bytes of a resolved tile, as a worker encodes them.
pub fn tile_exr(lease: &Lease, layers: &Layers) -> Vec<u8> {
    let meta = ExrMetadata::new().with(
        ExrMetadata::SPP,
        (lease.samples.end - lease.samples.start).to_string(),
    );
    encode_exr((lease.width, lease.height), layers, &meta).unwrap()
}

/// `GET path` answered 200, its JSON body.
pub async fn get_json<T: serde::de::DeserializeOwned>(
    s: &TestServer,
    c: &reqwest::Client,
    path: &str,
) -> T {
    let res = c.get(s.url(path)).send().await.unwrap();
    assert_eq!(res.status(), StatusCode::OK, "GET {path}");
    res.json().await.unwrap()
}

/// The server's Prometheus text.
pub async fn metrics(s: &TestServer, c: &reqwest::Client) -> String {
    let res = c.get(format!("{}/metrics", s.base)).send().await.unwrap();
    res.text().await.unwrap()
}

/// Reads an error body and checks its kind.
pub async fn error_body(res: reqwest::Response, status: StatusCode) -> proto::ErrorBody {
    assert_eq!(res.status(), status);
    res.json().await.unwrap()
}
