//! A job's video over HTTP: once its frames are finished, a worker with an encoder reads
//! each frame's PNG and uploads an MP4, which clients then download; what is not an MP4
//! is refused.

use proto::{FrameRange, JobSpec, JobStatus, Lease, ResultAck, TaskKind};
use reqwest::StatusCode;

use crate::common::*;

async fn video(s: &TestServer, c: &reqwest::Client, job: u64) -> reqwest::Response {
    c.get(s.url(&format!("/jobs/{job}/video")))
        .send()
        .await
        .unwrap()
}

async fn read_png(s: &TestServer, w: &SimWorker, lease: &Lease, frame: i32) -> reqwest::Response {
    w.auth(w.client.get(s.url(&format!(
        "/workers/{}/tasks/{}/frame?attempt={}&frame={frame}",
        w.id, lease.token.task_id, lease.token.attempt
    ))))
    .send()
    .await
    .unwrap()
}

async fn upload(s: &TestServer, w: &SimWorker, lease: &Lease, mp4: Vec<u8>) -> reqwest::Response {
    let meta = proto::ResultMetadata {
        attempt: lease.token.attempt,
        sha256: server::store::sha256_hex(&mp4),
        samples: 0,
        rays: 0,
        render_ms: 80,
    };
    w.upload_with(s, lease, mp4, &meta).await
}

/// A frame of two 8x8 tiles at 1 spp through the quad scene's camera.
fn two_tiles(digest: &str) -> JobSpec {
    let mut spec = JobSpec::new(digest);
    (spec.width, spec.height, spec.tile_size, spec.spp) = (16, 8, Some(8), 1);
    spec.camera = proto::CameraSpec::Name("Main".into());
    spec
}

#[tokio::test(flavor = "multi_thread")]
async fn the_video_is_read_from_the_frames_pngs_and_downloaded_once_encoded() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut spec = two_tiles(&scene.digest);
    spec.frames = Some(FrameRange {
        start: 1,
        end: 3,
        step: 2,
    });
    spec.video = true;
    let job = create_job(&s, &c, &spec).await.id;
    let res = video(&s, &c, job).await;
    assert_eq!(res.status(), StatusCode::NOT_FOUND);
    assert!(res.text().await.unwrap().contains("not all finished"));

    let mut plain = SimWorker::register(&s, "plain").await;
    assert_eq!(plain.work_until_idle(&s).await.len(), 4);
    let enc = SimWorker::register_encoder(&s, "ffmpeg", "FFmpeg with libx264").await;
    let lease = enc.lease(&s).await.expect("the encode task");
    assert_eq!(lease.kind, TaskKind::Encode);
    assert_eq!(lease.sequence, spec.frames);
    for frame in [1, 3] {
        let res = read_png(&s, &enc, &lease, frame).await;
        assert_eq!(res.status(), StatusCode::OK);
        let png = res.bytes().await.unwrap();
        let served = c
            .get(s.url(&format!("/jobs/{job}/frames/{frame}/png")))
            .send()
            .await
            .unwrap()
            .bytes()
            .await
            .unwrap();
        assert_eq!(png, served);
    }
    let res = read_png(&s, &enc, &lease, 2).await;
    assert_eq!(
        res.status(),
        StatusCode::UNPROCESSABLE_ENTITY,
        "frame 2 is not the job's"
    );

    let res = upload(&s, &enc, &lease, b"not a video at all".to_vec()).await;
    assert_eq!(res.status(), StatusCode::UNPROCESSABLE_ENTITY);
    assert!(res.text().await.unwrap().contains("not an MP4"));
    assert_eq!(video(&s, &c, job).await.status(), StatusCode::NOT_FOUND);

    // An ISO media file's first box: a stand-in for the MP4 the worker's FFmpeg makes.
    let mut mp4 = vec![0, 0, 0, 24];
    mp4.extend_from_slice(b"ftypisom\0\0\x02\0isomiso2");
    mp4.extend_from_slice(&[7; 100]);
    let res = upload(&s, &enc, &lease, mp4.clone()).await;
    assert_eq!(res.status(), StatusCode::OK);
    assert!(res.json::<ResultAck>().await.unwrap().accepted);
    let res = video(&s, &c, job).await;
    assert_eq!(res.status(), StatusCode::OK);
    assert_eq!(res.headers()["content-type"], "video/mp4");
    assert_eq!(res.bytes().await.unwrap(), mp4);
    let st: JobStatus = get_json(&s, &c, &format!("/jobs/{job}")).await;
    assert!(st.video && st.finished_ms.is_some());
}

#[tokio::test(flavor = "multi_thread")]
async fn an_encoder_waiting_for_work_wakes_when_the_last_frame_is_denoised() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut spec = two_tiles(&scene.digest);
    (spec.denoise, spec.video) = (true, true);
    let job = create_job(&s, &c, &spec).await.id;
    let mut plain = SimWorker::register(&s, "plain").await;
    assert_eq!(plain.work_until_idle(&s).await.len(), 2);
    let d = SimWorker::register_denoiser(&s, "oidn", "Open Image Denoise 2.5.1").await;
    let denoise = d.lease(&s).await.expect("the denoise task");
    assert_eq!(denoise.kind, TaskKind::Denoise);

    // The encoder asks for work while the frame is still being denoised, and waits for
    // up to the server's longest wait (30 s); none is there yet.
    let enc = SimWorker::register_encoder(&s, "ffmpeg", "FFmpeg with libx264").await;
    let waiting = enc.lease_waiting(&s, 30);
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    assert!(!waiting.is_finished(), "the encoder got an answer too soon");

    // The denoised frame arrives: the encode task is the waiting request's answer (a
    // request nothing wakes runs out and answers 204, and the farm idles until it asks
    // again).
    let exr = denoised_upload(spec.width, spec.height, glam::Vec3::splat(0.5));
    let res = upload(&s, &d, &denoise, exr).await;
    assert_eq!(res.status(), StatusCode::OK);
    let res = waiting.await.unwrap();
    assert_eq!(res.status(), StatusCode::OK);
    let lease: Lease = res.json().await.unwrap();
    assert_eq!((lease.kind, lease.job_id), (TaskKind::Encode, job));
}
