//! Jobs rendered by the worker daemon equal a direct render of the whole frame, whether
//! it uploads tiles uncompressed or ZIPped, and a worker started before its server waits
//! for it.

use std::time::Duration;

use proto::JobState;
use worker::{UploadCompression, WorkerConfig};

use crate::common::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_rendered_by_the_worker_equal_the_direct_render() {
    let Setup {
        dir,
        s,
        c,
        glb,
        scene,
    } = setup().await;
    // One pass: bit-identical. Two passes: merged by the server, equal within rounding.
    let single = spec(&scene.digest, 2, 4, 1);
    let passes = spec(&scene.digest, 2, 4, 2);
    let job1 = create_job(&s, &c, &single).await;
    let job2 = create_job(&s, &c, &passes).await;
    // 2 frames × 2×2 tiles × passes.
    assert_eq!((job1.tasks.queued, job2.tasks.queued), (8, 16));

    let w = TestWorker::start(&s.base, &dir.path().join("cache"), None);
    wait_until_done(&s, &c, job1.id).await;
    wait_until_done(&s, &c, job2.id).await;
    let summary = w.shutdown().await.unwrap();
    assert_eq!(summary.tasks_done, 24, "{summary:?}");
    assert_eq!(
        (
            summary.tasks_failed,
            summary.tasks_abandoned,
            summary.tasks_interrupted
        ),
        (0, 0, 0),
        "{summary:?}"
    );
    // One scene for both jobs: downloaded once.
    assert_eq!(summary.scenes_downloaded, 1);

    for frame in [1, 2] {
        let expected = direct_frame(&glb, &single, frame);
        assert_eq!(
            frame_exr(&s, &c, job1.id, frame).await,
            expected,
            "frame {frame}"
        );

        let got = frame_exr(&s, &c, job2.id, frame).await;
        for i in 0..expected.beauty.len() {
            let (a, b) = (got.beauty[i], expected.beauty[i]);
            assert!(
                (a - b).abs().max_element() <= 1e-5 * b.abs().max_element().max(1.0),
                "frame {frame} pixel {i}: {a} vs {b}"
            );
            let (a, b) = (got.albedo[i], expected.albedo[i]);
            assert!(
                (a - b).abs().max_element() <= 1e-5,
                "albedo {i}: {a} vs {b}"
            );
        }
    }
    // The shutter and animation matter in this scene: a still frame differs, so the
    // equality above shows the worker passed them on.
    let mut still = single.clone();
    still.shutter = [0.0, 0.0];
    assert_ne!(
        direct_frame(&glb, &still, 1),
        direct_frame(&glb, &single, 1)
    );

    // The worker left: the server lists it offline.
    let workers = workers(&s).await;
    assert_eq!(workers.workers.len(), 1);
    assert!(!workers.workers[0].online, "{workers:?}");
    assert_eq!(workers.workers[0].tasks_done, 24);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_started_before_its_server_waits_and_then_works() {
    init_logs();
    let dir = tempfile::tempdir().unwrap();
    // Nobody listens yet: the worker's connections are refused and it retries. (A listener
    // bound but not yet accepting would not do: the kernel completes the handshake and
    // the request just waits, so the retry path would go untested.)
    let addr = free_addr();
    // This worker ZIPs its tiles, as for a server on another machine (the others send
    // them uncompressed to the loopback server): the frame is the same bits.
    let w = TestWorker::start_config(WorkerConfig {
        upload_compression: UploadCompression::Zip,
        ..worker_config(&format!("http://{addr}"), &dir.path().join("cache"))
    });
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let s = TestServer::start_on(bind_again(addr), server_config(dir.path())).kill_on_drop();
    let c = client();
    let glb = spinning_quad();
    let scene = upload_scene(&s, &c, glb.clone()).await;
    let spec = spec(&scene.digest, 1, 2, 1);
    let job = create_job(&s, &c, &spec).await;
    let status = wait_until_done(&s, &c, job.id).await;
    assert_eq!(status.state, JobState::Done);
    assert_eq!(
        frame_exr(&s, &c, job.id, 1).await,
        direct_frame(&glb, &spec, 1)
    );
    let summary = w.shutdown().await.unwrap();
    assert_eq!((summary.registrations, summary.tasks_done), (1, 4));
}
