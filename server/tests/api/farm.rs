//! A whole job through the farm: scene upload, job, leases, tiles, assembled frames equal
//! to a direct render of the same pieces, status, events, metrics.

use std::collections::BTreeMap;

use proto::{FrameList, FrameRange, FrameState, JobSpec, JobState, JobStatus};
use reqwest::StatusCode;
use tracer::film::{Layers, TileBuffer, TileRect};
use tracer::output::{decode_exr, encode_preview_png};

use crate::common::*;

fn spec(digest: &str, passes: u32) -> JobSpec {
    let mut spec = JobSpec::new(digest);
    spec.frames = Some(FrameRange {
        start: 1,
        end: 2,
        step: 1,
    });
    spec.width = 24;
    spec.height = 16;
    spec.tile_size = Some(8);
    spec.spp = 4;
    spec.sample_passes = passes;
    spec.max_depth = 3;
    spec.camera = proto::CameraSpec::Name("Main".into());
    spec
}

/// Renders every lease of a job and returns the tile buffers by (frame, tile origin),
/// each merged over its sample passes.
async fn run_job(s: &TestServer, w: &mut SimWorker) -> BTreeMap<(i32, u32, u32), TileBuffer> {
    let mut tiles: BTreeMap<(i32, u32, u32), TileBuffer> = BTreeMap::new();
    while let Some(lease) = w.lease(s).await {
        let (exr, buffer) = w.render(s, &lease).await;
        let res = w.upload(s, &lease, exr).await;
        assert_eq!(res.status(), StatusCode::OK, "{:?}", res.text().await);
        tiles
            .entry((lease.frame, lease.tile.x, lease.tile.y))
            .and_modify(|t| t.merge(&buffer))
            .or_insert(buffer);
    }
    tiles
}

/// The frame a direct render of the same tiles gives.
fn expected_frame(tiles: &BTreeMap<(i32, u32, u32), TileBuffer>, frame: i32) -> Layers {
    let mut out = Layers::new(TileRect::new(0, 0, 24, 16));
    for ((f, _, _), t) in tiles {
        if *f == frame {
            out.paste(&t.resolve());
        }
    }
    out
}

async fn frame_file(
    s: &TestServer,
    c: &reqwest::Client,
    job: u64,
    frame: i32,
    ext: &str,
) -> Vec<u8> {
    let res = c
        .get(s.url(&format!("/jobs/{job}/frames/{frame}/{ext}")))
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::OK);
    res.bytes().await.unwrap().to_vec()
}

#[tokio::test(flavor = "multi_thread")]
async fn single_pass_frames_equal_the_direct_render_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    assert_eq!(scene.triangles, 2);
    assert_eq!(scene.cameras[0].name.as_deref(), Some("Main"));
    let job = create_job(&s, &c, &spec(&scene.digest, 1)).await;
    // 2 frames × 3×2 tiles × 1 pass.
    assert_eq!(job.tasks.queued, 12);
    assert_eq!(job.state, JobState::Queued);

    let mut w = SimWorker::register(&s, "sim").await;
    let tiles = run_job(&s, &mut w).await;
    assert_eq!(tiles.len(), 12);

    for frame in [1, 2] {
        let expected = expected_frame(&tiles, frame);
        let exr = decode_exr(&frame_file(&s, &c, job.id, frame, "exr").await).unwrap();
        assert_eq!(exr.frame_size, (24, 16));
        assert_eq!(exr.layers, expected, "frame {frame}");
        assert_eq!(
            exr.attribute("tessera/frame"),
            Some(frame.to_string().as_str())
        );
        // The header says what the samples reached and how long the tiles took.
        assert_eq!(exr.attribute("tessera/spp-mean"), Some("4.000"));
        assert_eq!(exr.attribute("tessera/spp-min"), Some("4"));
        let noise: f64 = exr.attribute("tessera/noise").unwrap().parse().unwrap();
        assert!(noise > 0.0 && noise.is_finite(), "noise {noise}");
        let seconds: f64 = exr
            .attribute("tessera/render-seconds")
            .unwrap()
            .parse()
            .unwrap();
        assert!(seconds >= 0.0);
        assert!(exr.attribute("tessera/features").is_some());
        let png = frame_file(&s, &c, job.id, frame, "png").await;
        assert_eq!(png, encode_preview_png((24, 16), &expected, 0.0).unwrap());
        // The files sit in the job's output folder, four-digit names.
        let on_disk = s
            .data
            .join("jobs")
            .join(job.id.to_string())
            .join(format!("frame_{frame:04}.exr"));
        assert!(on_disk.is_file(), "{}", on_disk.display());
    }
    // Tiles are removed once their frame is assembled.
    let left = std::fs::read_dir(s.data.join("tiles").join(job.id.to_string()))
        .unwrap()
        .count();
    assert_eq!(left, 0);

    let status: JobStatus = get_json(&s, &c, &format!("/jobs/{}", job.id)).await;
    assert_eq!(status.state, JobState::Done);
    assert_eq!(
        (status.tasks.done, status.frames_done, status.frames_total),
        (12, 2, 2)
    );
    assert_eq!(status.progress, 1.0);
    assert_eq!(status.eta_seconds, None);
    assert!(status.finished_ms.is_some());
    let frames: FrameList = get_json(&s, &c, &format!("/jobs/{}/frames", job.id)).await;
    assert_eq!(frames.frames.len(), 2);
    assert!(frames
        .frames
        .iter()
        .all(|f| f.state == FrameState::Done && f.tasks_done == 6));
    assert_eq!(frames.frames[0].file, "frame_0001.exr");

    let metrics = metrics(&s, &c).await;
    assert!(
        metrics.contains("tessera_tiles_received_total 12"),
        "{metrics}"
    );
    assert!(
        metrics.contains("tessera_tasks{state=\"done\"} 12"),
        "{metrics}"
    );
    assert!(
        metrics.contains("tessera_jobs{state=\"done\"} 1"),
        "{metrics}"
    );
    assert!(
        metrics.contains("tessera_workers{state=\"online\"} 1"),
        "{metrics}"
    );
    assert!(
        metrics.contains("tessera_lease_latency_seconds"),
        "{metrics}"
    );
    assert!(
        metrics.contains("tessera_frames_assembled_total 2\n"),
        "{metrics}"
    );
    assert!(
        metrics.contains("tessera_frame_assembly_seconds_count 2\n"),
        "{metrics}"
    );
    assert!(
        metrics.contains("tessera_upload_seconds_count 12\n"),
        "{metrics}"
    );
    assert!(metrics.contains("tessera_demand_tasks 0\n"), "{metrics}");
    // Every series says what it is: a `# HELP` line for its family.
    let families: Vec<&str> = metrics
        .lines()
        .filter_map(|l| l.strip_prefix("# HELP "))
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    for line in metrics
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
    {
        let name = line.split(['{', ' ']).next().unwrap();
        let family = ["_sum", "_count", "_bucket"]
            .iter()
            .find_map(|s| name.strip_suffix(s))
            .filter(|f| families.contains(f))
            .unwrap_or(name);
        assert!(
            families.contains(&family),
            "no # HELP for {name}:\n{metrics}"
        );
    }
    let tile_bytes: u64 = metrics
        .lines()
        .find_map(|l| l.strip_prefix("tessera_frame_assembly_tile_bytes_total "))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{metrics}"));
    // Twelve tiles of 8x8 pixels (and every layer) were read back.
    assert!(tile_bytes > 12 * 64 * 4, "{tile_bytes}");
    let health = c.get(format!("{}/healthz", s.base)).send().await.unwrap();
    assert_eq!(health.status(), StatusCode::OK);
    // Every answer carries its request's id: a fresh UUID, or the caller's own.
    let id = |r: &reqwest::Response| r.headers()["x-request-id"].to_str().unwrap().to_string();
    assert_eq!(id(&health).len(), 36, "{:?}", health.headers());
    let mine = c
        .get(format!("{}/healthz", s.base))
        .header("x-request-id", "trace-me-7")
        .send()
        .await
        .unwrap();
    assert_eq!(id(&mine), "trace-me-7");
}

#[tokio::test(flavor = "multi_thread")]
async fn sample_passes_merge_into_the_full_sample_average() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let job = create_job(&s, &c, &spec(&scene.digest, 2)).await;
    assert_eq!(job.tasks.queued, 24);
    let mut w = SimWorker::register(&s, "sim").await;
    let tiles = run_job(&s, &mut w).await;
    for frame in [1, 2] {
        let expected = expected_frame(&tiles, frame);
        let got = decode_exr(&frame_file(&s, &c, job.id, frame, "exr").await)
            .unwrap()
            .layers;
        // Each pass holds 2 samples per pixel; their average equals the 4-sample average
        // up to float rounding.
        for i in 0..expected.beauty.len() {
            let (a, b) = (got.beauty[i], expected.beauty[i]);
            assert!(
                (a - b).abs().max_element() <= 1e-5 * b.abs().max_element().max(1.0),
                "pixel {i}: {a} vs {b}"
            );
            let (a, b) = (got.albedo[i], expected.albedo[i]);
            assert!(
                (a - b).abs().max_element() <= 1e-5,
                "albedo {i}: {a} vs {b}"
            );
        }
    }
}

#[tokio::test(flavor = "multi_thread")]
async fn events_report_job_frame_and_worker_changes() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut events = c.get(s.url("/events")).send().await.unwrap();
    assert_eq!(events.status(), StatusCode::OK);
    assert!(events.headers()["content-type"]
        .to_str()
        .unwrap()
        .starts_with("text/event-stream"));

    let mut one = spec(&scene.digest, 1);
    one.frames = Some(FrameRange {
        start: 7,
        end: 7,
        step: 1,
    });
    let job = create_job(&s, &c, &one).await;
    let mut w = SimWorker::register(&s, "sim").await;
    run_job(&s, &mut w).await;

    // Read events until the job is reported done.
    let mut text = String::new();
    let mut seen: Vec<proto::Event> = vec![];
    while !seen.iter().any(|e| matches!(e, proto::Event::Job { job: j } if j.id == job.id && j.state == JobState::Done)) {
        let chunk = events.chunk().await.unwrap().expect("stream open");
        text.push_str(std::str::from_utf8(&chunk).unwrap());
        while let Some(end) = text.find("\n\n") {
            let block: String = text.drain(..end + 2).collect();
            let name = block.lines().find_map(|l| l.strip_prefix("event: ")).unwrap_or("");
            if let Some(data) = block.lines().find_map(|l| l.strip_prefix("data: ")) {
                let event: proto::Event = serde_json::from_str(data).unwrap();
                assert_eq!(event.name(), name);
                seen.push(event);
            }
        }
    }
    assert!(seen.iter().any(|e| matches!(e, proto::Event::Frame { job_id, frame } if *job_id == job.id && frame.frame == 7 && frame.state == FrameState::Done)));
    assert!(seen.iter().any(|e| matches!(e, proto::Event::Worker { worker } if worker.id == w.id && worker.name == "sim")));
    assert!(seen.iter().any(|e| matches!(e, proto::Event::Job { job: j } if j.id == job.id && j.state == JobState::Running)));
}

#[tokio::test(flavor = "multi_thread")]
async fn a_finished_pass_gives_a_progressive_preview_before_the_frame_is_done() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut one = spec(&scene.digest, 2);
    one.frames = Some(FrameRange {
        start: 3,
        end: 3,
        step: 1,
    });
    let job = create_job(&s, &c, &one).await;
    let mut w = SimWorker::register(&s, "sim").await;
    // Leases come pass by pass: the first six are pass 0 of every tile.
    let mut pass0 = Layers::new(TileRect::new(0, 0, 24, 16));
    for _ in 0..6 {
        let lease = w.lease(&s).await.unwrap();
        assert_eq!(lease.samples.start, 0);
        let (exr, buffer) = w.render(&s, &lease).await;
        pass0.paste(&buffer.resolve());
        assert_eq!(w.upload(&s, &lease, exr).await.status(), StatusCode::OK);
    }
    let png = frame_file(&s, &c, job.id, 3, "png").await;
    assert_eq!(png, encode_preview_png((24, 16), &pass0, 0.0).unwrap());
    let res = c
        .get(s.url(&format!("/jobs/{}/frames/3/exr", job.id)))
        .send()
        .await
        .unwrap();
    let err = error_body(res, StatusCode::NOT_FOUND).await;
    assert!(err.message.contains("rendering"), "{}", err.message);
    // The rest finishes the frame, and the final preview replaces the progressive one.
    w.work_until_idle(&s).await;
    let final_png = frame_file(&s, &c, job.id, 3, "png").await;
    assert_ne!(final_png, png);
}

#[tokio::test(flavor = "multi_thread")]
async fn a_noise_threshold_job_stops_pixels_early_and_reports_what_it_reached() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut want = spec(&scene.digest, 1);
    want.spp = 64;
    want.noise_threshold = Some(0.05);
    let job = create_job(&s, &c, &want).await;
    // The server fills in the minimum.
    assert_eq!(job.spec.min_spp, Some(16));

    let mut w = SimWorker::register(&s, "sim").await;
    let tiles = run_job(&s, &mut w).await;
    let frames: FrameList = get_json(&s, &c, &format!("/jobs/{}/frames", job.id)).await;
    for (frame, status) in [1, 2].into_iter().zip(&frames.frames) {
        // Bit for bit the tracer's adaptive render of the same tiles.
        let expected = expected_frame(&tiles, frame);
        let exr = decode_exr(&frame_file(&s, &c, job.id, frame, "exr").await).unwrap();
        assert_eq!(exr.layers, expected, "frame {frame}");
        let reached = expected.sampling();
        assert!(reached.min_samples >= 16 && reached.max_samples <= 64);
        assert!(reached.mean_samples < 64.0, "{reached:?}");
        // The frame list and the header say the same.
        let spp = status.spp_mean.unwrap();
        assert!((spp - reached.mean_samples).abs() < 1e-9, "{spp}");
        let noise = status.noise.unwrap();
        assert!((noise - reached.mean_noise.unwrap()).abs() < 1e-9);
        assert_eq!(
            exr.attribute("tessera/spp-mean"),
            Some(format!("{:.3}", reached.mean_samples).as_str())
        );
    }
}

/// Frame files are as wide as the job's last frame, so a sequence that crosses frame 9999
/// still sorts in frame order: `frame_09999` before `frame_10000`, on disk and in the API.
#[tokio::test(flavor = "multi_thread")]
async fn frame_names_of_a_sequence_past_9999_sort_in_frame_order() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut job = spec(&scene.digest, 1);
    job.frames = Some(FrameRange {
        start: 9_999,
        end: 10_000,
        step: 1,
    });
    job.spp = 1;
    let job = create_job(&s, &c, &job).await;
    SimWorker::register(&s, "w").await.work_until_idle(&s).await;
    let frames: FrameList = get_json(&s, &c, &format!("/jobs/{}/frames", job.id)).await;
    let names: Vec<&str> = frames.frames.iter().map(|f| f.file.as_str()).collect();
    assert_eq!(names, ["frame_09999.exr", "frame_10000.exr"]);
    for f in &frames.frames {
        assert_eq!(f.state, FrameState::Done);
        let on_disk = s.data.join("jobs").join(job.id.to_string()).join(&f.file);
        assert!(on_disk.is_file(), "{}", on_disk.display());
        let png = c
            .get(s.url(&format!("/jobs/{}/frames/{}/png", job.id, f.frame)))
            .send()
            .await
            .unwrap();
        assert_eq!(png.status(), StatusCode::OK);
    }
}
