//! A job's video on a farm of real processes: `tessera submit --video --wait --out DIR`
//! ends with DIR/video.mp4, which has the job's frame count and fps and whose first frame
//! is the first PNG preview within H.264's error.
//!
//! Needs FFmpeg (`tessera install ffmpeg`, which `scripts/test.sh` runs); without it the
//! test says so loudly and checks nothing.

use std::time::Duration;

use proto::JobState;
use tests::{settings, Farm, FRAMES};

#[test]
fn submit_wait_downloads_the_jobs_video_with_its_frames() {
    let ffmpeg = match post::Ffmpeg::find(None) {
        Ok(f) => f,
        Err(e) => {
            eprintln!("\n=== WARNING: SKIPPED: the farm's video test needs FFmpeg: {e} ===\n");
            return;
        }
    };
    let mut farm = Farm::new();
    farm.start_server(60);
    farm.start_worker("w", 2);
    let scene = farm.demo_scene();
    let mut args = vec![scene.to_str().unwrap(), "--frames", FRAMES, "--video"];
    args.extend(settings("16"));
    args.extend(["--wait", "--out", "shot"]);
    let job = farm.submit(&args);
    let st = farm.wait_for_job(job, Duration::from_secs(120));
    assert_eq!((st.state, st.video), (JobState::Done, true), "{st:?}");

    let mp4 = farm.path().join("shot").join("video.mp4");
    let info = ffmpeg.probe(&mp4).unwrap();
    assert_eq!(
        (info.frames, info.fps, info.size, info.h264),
        (4, 24.0, (32, 24), true)
    );

    let first = farm.path().join("first.png");
    ffmpeg.frame_png(&mp4, 0, &first).unwrap();
    let decoded = image::open(&first).unwrap().to_rgb8();
    let png = image::open(farm.path().join("shot/frame_0001.png"))
        .unwrap()
        .to_rgb8();
    let squares: u64 = png
        .pixels()
        .zip(decoded.pixels())
        .flat_map(|(p, q)| (0..3).map(move |c| u64::from(p.0[c].abs_diff(q.0[c])).pow(2)))
        .sum();
    let mse = squares as f64 / (3 * png.width() * png.height()) as f64;
    let psnr = 10.0 * (255.0f64 * 255.0 / mse).log10();
    eprintln!("the video's first frame against frame_0001.png: PSNR {psnr:.1} dB");
    // Measured 30.1 dB: these 32x24 frames at 16 spp are mostly noise, which H.264
    // smooths (post/tests/video.rs checks larger frames, and the colour, closer).
    assert!(psnr > 27.0, "PSNR {psnr} dB");
}
