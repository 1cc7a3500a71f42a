//! A job that denoises, over HTTP: the frame waits for a worker with a denoiser, which
//! reads the assembled frame and uploads the denoised beauty; the server writes it into
//! the frame's EXR beside the noisy beauty and redraws the PNG from it, and refuses an
//! upload that is not the whole frame or not finite.

use glam::Vec3;
use proto::{FrameList, FrameState, JobSpec, JobState, JobStatus, Lease, ResultAck, TaskKind};
use reqwest::StatusCode;
use tracer::output::{aces_filmic, decode_exr, srgb_oetf};

use crate::common::*;

const W: u32 = 24;
const H: u32 = 16;

async fn frame_file(s: &TestServer, c: &reqwest::Client, job: u64, ext: &str) -> Vec<u8> {
    let res = c
        .get(s.url(&format!("/jobs/{job}/frames/0/{ext}")))
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::OK);
    res.bytes().await.unwrap().to_vec()
}

async fn frame_state(s: &TestServer, c: &reqwest::Client, job: u64) -> FrameState {
    get_json::<FrameList>(s, c, &format!("/jobs/{job}/frames"))
        .await
        .frames[0]
        .state
}

/// `GET /workers/{id}/tasks/{task}/frame` for `lease`, as `w`.
async fn read_frame(s: &TestServer, w: &SimWorker, lease: &Lease) -> reqwest::Response {
    w.auth(w.client.get(s.url(&format!(
        "/workers/{}/tasks/{}/frame?attempt={}",
        w.id, lease.token.task_id, lease.token.attempt
    ))))
    .send()
    .await
    .unwrap()
}

/// Uploads `exr` for the denoise `lease` with 0 samples.
async fn upload(s: &TestServer, d: &SimWorker, lease: &Lease, exr: Vec<u8>) -> reqwest::Response {
    let meta = proto::ResultMetadata {
        attempt: lease.token.attempt,
        sha256: server::store::sha256_hex(&exr),
        samples: 0,
        rays: 0,
        render_ms: 250,
    };
    d.upload_with(s, lease, exr, &meta).await
}

#[tokio::test(flavor = "multi_thread")]
async fn a_denoised_frame_keeps_its_noisy_layers_and_previews_the_denoised_one() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut spec = JobSpec::new(&scene.digest);
    (spec.width, spec.height, spec.tile_size, spec.spp) = (W, H, Some(8), 2);
    spec.camera = proto::CameraSpec::Name("Main".into());
    spec.denoise = true;
    let job = create_job(&s, &c, &spec).await.id;

    // A worker without a denoiser renders the tiles; the frame then waits.
    let mut plain = SimWorker::register(&s, "plain").await;
    assert_eq!(plain.work_until_idle(&s).await.len(), 6);
    assert_eq!(frame_state(&s, &c, job).await, FrameState::Denoising);
    let noisy = decode_exr(&frame_file(&s, &c, job, "exr").await).unwrap();
    assert!(noisy.layers.denoised.is_empty());
    let status: JobStatus = get_json(&s, &c, &format!("/jobs/{job}")).await;
    assert_eq!((status.state, status.frames_done), (JobState::Running, 0));
    assert!(status.waiting.unwrap().contains("tessera install oidn"));

    // A worker with one leases the frame and reads the assembled EXR.
    let d = SimWorker::register_denoiser(&s, "oidn", "Open Image Denoise 2.5.1").await;
    let lease = d.lease(&s).await.expect("the denoise task");
    assert_eq!(
        (lease.kind, lease.tile.width, lease.tile.height),
        (TaskKind::Denoise, W, H)
    );
    let res = read_frame(&s, &d, &lease).await;
    assert_eq!(res.status(), StatusCode::OK);
    let sent = decode_exr(&res.bytes().await.unwrap()).unwrap();
    assert_eq!(sent.layers, noisy.layers);
    // Another worker's credential, or a stale attempt, reads nothing.
    let res = read_frame(&s, &plain, &lease).await;
    assert_eq!(res.status(), StatusCode::CONFLICT);

    // What is not the whole frame, or not finite, is refused and changes nothing.
    let res = upload(&s, &d, &lease, denoised_upload(W, H - 8, Vec3::splat(0.5))).await;
    assert_eq!(res.status(), StatusCode::UNPROCESSABLE_ENTITY);
    assert!(res.text().await.unwrap().contains("not the whole"));
    let res = upload(
        &s,
        &d,
        &lease,
        denoised_upload(W, H, Vec3::new(0.5, f32::NAN, 0.5)),
    )
    .await;
    assert_eq!(res.status(), StatusCode::UNPROCESSABLE_ENTITY);
    assert!(res.text().await.unwrap().contains("not finite"));
    assert_eq!(frame_state(&s, &c, job).await, FrameState::Denoising);
    assert_eq!(
        decode_exr(&frame_file(&s, &c, job, "exr").await)
            .unwrap()
            .layers,
        noisy.layers
    );

    // The whole frame: written beside the noisy layers, and the preview shows it.
    let grey = Vec3::splat(0.18);
    let res = upload(&s, &d, &lease, denoised_upload(W, H, grey)).await;
    assert_eq!(res.status(), StatusCode::OK);
    let ack: ResultAck = res.json().await.unwrap();
    assert!(ack.accepted && ack.frame_done);
    assert_eq!(frame_state(&s, &c, job).await, FrameState::Done);
    let frame = decode_exr(&frame_file(&s, &c, job, "exr").await).unwrap();
    assert_eq!(frame.layers.denoised, vec![grey; (W * H) as usize]);
    let mut without = frame.layers.clone();
    without.denoised.clear();
    assert_eq!(
        without, noisy.layers,
        "the noisy layers are kept as they were"
    );
    assert_eq!(
        frame.attribute("tessera/denoiser"),
        Some("Open Image Denoise 2.5.1")
    );
    assert_eq!(frame.attribute("tessera/denoise-seconds"), Some("0.250"));
    assert_eq!(
        frame.attribute("tessera/spp"),
        noisy.attribute("tessera/spp")
    );
    let png = image::load_from_memory(&frame_file(&s, &c, job, "png").await)
        .unwrap()
        .to_rgba8();
    let expected = (srgb_oetf(aces_filmic(0.18)) * 255.0).round() as u8;
    assert!(png
        .pixels()
        .all(|p| p.0 == [expected, expected, expected, 255]));
    let status: JobStatus = get_json(&s, &c, &format!("/jobs/{job}")).await;
    assert_eq!((status.state, status.frames_done), (JobState::Done, 1));
}
