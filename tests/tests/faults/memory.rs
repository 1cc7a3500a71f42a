//! The widest frame the server accepts in its largest tiles (16384 wide: the full 16384²
//! frame is 14 GB of layers, and once took 22.7 GB of server memory and a kernel kill),
//! assembled by a server whose memory is limited to a fraction of it, killed mid-assembly
//! and restarted: the restarted server answers at once, finishes the frame in the
//! background, and neither run holds more than the limit.

use std::fs;
use std::path::Path;
use std::time::Duration;

use glam::{Vec3, Vec4};
use proto::{JobState, Lease, LeaseRequest, ResultMetadata, WorkerRegistered, WorkerRegistration};
use sha2::{Digest, Sha256};
use tests::http::{Answer, Request};
use tests::Farm;
use tracer::film::{Layers, TileRect};
use tracer::output::{encode_exr, read_exr_rows, ExrMetadata};

/// The server's data segment (`RLIMIT_DATA`). The old assembly held the whole frame, and
/// its encoded copy, at once: it died here at its first allocation.
const MEMORY_LIMIT: u64 = 1 << 30;
/// The widest frame and the largest tile the server accepts: what assembly holds grows
/// with these.
const SIZE: u32 = 16_384;
const TILE: u32 = 1_024;
/// The frame's height in CI: 2048 rows (1.7 GB of layers) take CI's two cores about two
/// minutes to assemble; the full 16384 (14 GB, about 8 minutes) is
/// `TESSERA_FULL_FRAME_TEST=1 cargo test -p tests --test faults memory`. Height does not
/// change what assembly holds, only how long it takes.
fn height() -> u32 {
    match std::env::var("TESSERA_FULL_FRAME_TEST").as_deref() {
        Ok("1") => SIZE,
        _ => 2_048,
    }
}

/// Each tile's own colour, so that the assembled frame shows every tile in its place.
fn tile_colour(rect: TileRect) -> Vec4 {
    let (i, j) = (rect.x / TILE, rect.y / TILE);
    Vec4::new(i as f32 / 16.0, j as f32 / 16.0, 0.5, 1.0)
}

/// A worker that uploads flat tiles of [`tile_colour`] instead of rendering.
struct Painter {
    port: u16,
    id: u64,
    credential: String,
}

impl Painter {
    /// Registers painter `k` (no two live workers share a name).
    fn register(port: u16, k: usize) -> Painter {
        let reg = WorkerRegistration {
            name: format!("painter-{k}"),
            threads: 1,
            version: "test".into(),
            ..Default::default()
        };
        let answer = post_json(port, "/api/v1/workers", &reg, None);
        assert_eq!(answer.status, 201, "{}", answer.text());
        let registered = answer.json::<WorkerRegistered>();
        Painter {
            port,
            id: registered.worker_id,
            credential: registered.credential,
        }
    }

    fn bearer(&self) -> (String, String) {
        (
            "Authorization".into(),
            format!("Bearer {}", self.credential),
        )
    }

    /// The next task, if any is left.
    fn lease(&self) -> Option<Lease> {
        let path = format!("/api/v1/workers/{}/lease", self.id);
        let wait = LeaseRequest {
            wait_seconds: 1,
            ..LeaseRequest::default()
        };
        let answer = post_json(self.port, &path, &wait, Some(self.bearer()));
        match answer.status {
            200 => Some(answer.json()),
            204 => None,
            _ => panic!("lease: {} {}", answer.status, answer.text()),
        }
    }

    /// Uploads the flat tile of `lease`; returns the answer.
    fn upload(&self, lease: &Lease) -> Answer {
        self.upload_request(lease, |req| req.send(self.port))
    }

    /// Makes the upload of the flat tile of `lease` and hands it to `send`.
    fn upload_request<T>(&self, lease: &Lease, send: impl FnOnce(Request) -> T) -> T {
        let rect = worker::render::tile_rect(lease);
        let mut layers = Layers::new(rect);
        layers.beauty.fill(tile_colour(rect));
        layers.albedo.fill(Vec3::splat(0.5));
        layers.normal.fill(Vec3::Z);
        layers.depth.fill(2.0);
        layers.samples.fill(1.0);
        let exr = encode_exr((lease.width, lease.height), &layers, &ExrMetadata::new()).unwrap();
        let meta = ResultMetadata {
            attempt: lease.token.attempt,
            sha256: Sha256::digest(&exr)
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect(),
            samples: lease.samples.end - lease.samples.start,
            rays: 1,
            render_ms: 1,
        };
        let path = format!(
            "/api/v1/workers/{}/tasks/{}/result",
            self.id, lease.token.task_id
        );
        send(Request {
            method: "POST",
            path: &path,
            headers: meta
                .to_headers()
                .into_iter()
                .map(|(n, v)| (n.to_string(), v))
                .chain([self.bearer()])
                .collect(),
            body: &exr,
        })
    }
}

fn post_json(
    port: u16,
    path: &str,
    value: &impl serde::Serialize,
    auth: Option<(String, String)>,
) -> Answer {
    let body = serde_json::to_vec(value).unwrap();
    let mut headers = vec![("Content-Type".into(), "application/json".into())];
    headers.extend(auth);
    Request {
        method: "POST",
        path,
        headers,
        body: &body,
    }
    .send(port)
}

/// Whether the server is writing the frame: its temp file is in the job's folder.
fn writing_frame(data: &Path, job: u64) -> bool {
    fs::read_dir(data.join("jobs").join(job.to_string()))
        .map(|entries| {
            entries.flatten().any(|e| {
                e.file_name()
                    .to_string_lossy()
                    .starts_with(".frame_0001.exr")
            })
        })
        .unwrap_or(false)
}

#[test]
fn the_largest_frame_is_assembled_within_a_memory_limit_across_a_restart() {
    let mut farm = Farm::new();
    farm.start_server_limited(60, &[], Some(MEMORY_LIMIT));
    let scene = farm.demo_scene();
    let height = height();
    let size = format!("{SIZE}x{height}");
    let tile = TILE.to_string();
    let job = farm.submit(&[
        scene.to_str().unwrap(),
        "--frames",
        "1-1",
        "--size",
        &size,
        "--spp",
        "1",
        "--tile",
        &tile,
    ]);
    let tasks = farm.job(job).tasks.total();
    assert_eq!(tasks, u64::from((SIZE / TILE) * (height / TILE)));

    // Two painters upload every tile but the last; the last one's upload starts the
    // assembly, and its answer never comes: the server is killed mid-frame.
    let port = farm.port;
    let mut last = None;
    std::thread::scope(|s| {
        let painters: Vec<_> = (0..2)
            .map(|k| {
                s.spawn(move || {
                    let painter = Painter::register(port, k);
                    let mut held = None;
                    while let Some(lease) = painter.lease() {
                        if let Some(previous) = held.replace(lease) {
                            let answer = painter.upload(&previous);
                            assert_eq!(answer.status, 200, "{}", answer.text());
                        }
                    }
                    held.map(|lease| (painter, lease))
                })
            })
            .collect();
        let mut left: Vec<_> = painters
            .into_iter()
            .filter_map(|p| p.join().unwrap())
            .collect();
        let (painter, lease) = left.pop().unwrap();
        for (other, lease) in left {
            assert_eq!(other.upload(&lease).status, 200);
        }
        last = Some((painter, lease));
    });
    let (painter, lease) = last.unwrap();
    let _unanswered = painter.upload_request(&lease, |req| req.send_unanswered(port));
    let data = farm.data_dir();
    tests::wait_until(
        "the frame's assembly to start",
        Duration::from_secs(120),
        || writing_frame(&data, job),
        || farm.logs(),
    );
    std::thread::sleep(Duration::from_secs(2));
    let server = farm.server.as_mut().unwrap();
    assert!(server.running(), "the server died:\n{}", server.log());
    let first_peak = server.peak_memory_bytes();
    server.kill9();

    // The restarted server answers before the frame is assembled.
    farm.start_server_limited(60, &[], Some(MEMORY_LIMIT));
    let answered = farm.job(job);
    assert_eq!(answered.frames_done, 0, "{answered:?}");
    let done = farm.wait_for_job(job, Duration::from_secs(600));
    assert_eq!(
        (done.state, done.frames_done),
        (JobState::Done, 1),
        "{done:?}"
    );
    let second_peak = farm.server.as_ref().unwrap().peak_memory_bytes();
    eprintln!(
        "peak server memory: {} MiB before the kill, {} MiB after the restart \
         (the frame's layers: {} MiB)",
        first_peak >> 20,
        second_peak >> 20,
        (u64::from(SIZE) * u64::from(height) * 52) >> 20
    );
    for peak in [first_peak, second_peak] {
        assert!(peak < MEMORY_LIMIT, "{peak} bytes");
    }

    // Every tile in its place: a band at the top, one across the middle, the last rows.
    let frame = data
        .join("jobs")
        .join(job.to_string())
        .join("frame_0001.exr");
    for rows in [0..64, height / 2 - 8..height / 2 + 8, height - 3..height] {
        let band = read_exr_rows(&frame, rows.clone()).unwrap().layers;
        assert_eq!(
            (band.rect.width, band.rect.height),
            (SIZE, rows.len() as u32)
        );
        for (i, b) in band.beauty.iter().enumerate() {
            let (x, y) = (i as u32 % SIZE, band.rect.y + i as u32 / SIZE);
            assert_eq!(
                *b,
                tile_colour(TileRect::new(x, y, 1, 1)),
                "pixel ({x}, {y})"
            );
        }
    }
    let png = data
        .join("jobs")
        .join(job.to_string())
        .join("frame_0001.png");
    assert_eq!(image::image_dimensions(&png).unwrap(), (SIZE, height));
    let leftovers: Vec<_> = fs::read_dir(frame.parent().unwrap())
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "temp files left: {leftovers:?}");
}
