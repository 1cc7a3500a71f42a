//! FFmpeg on real frames: an MP4 of the demo's PNG previews has their count, rate and
//! size (odd sizes padded by a pixel), is H.264, and its first frame is the first PNG
//! within H.264's error at CRF 18.
//!
//! Needs FFmpeg (`tessera install ffmpeg`; `scripts/test.sh` runs it first). Without it
//! these tests say so loudly and pass without checking anything.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use post::Ffmpeg;
use tracer::film::{SampleRange, TileRect};
use tracer::output::write_preview_png;
use tracer::render::{prepare_frame, render_region, FrameOptions, RenderSettings};

/// FFmpeg, or `None` after a loud warning.
fn ffmpeg() -> Option<Ffmpeg> {
    match Ffmpeg::find(None) {
        Ok(f) => Some(f),
        Err(e) => {
            eprintln!("\n=== WARNING: SKIPPED: the video tests need FFmpeg: {e} ===\n");
            None
        }
    }
}

/// Frames 1 to `n` of the animated demo, `w`x`h` at 64 spp, as the farm's PNG previews
/// are made (`frame_0001.png` ...).
fn write_frames(dir: &Path, n: i32, (w, h): (u32, u32)) -> Vec<PathBuf> {
    let scene = Arc::new(tracer::demo::animated_demo_scene());
    (1..=n)
        .map(|f| {
            let options = FrameOptions {
                frame: f,
                width: w,
                height: h,
                ..FrameOptions::default()
            };
            let frame = prepare_frame(scene.clone(), &options).unwrap();
            let rect = TileRect::new(0, 0, w, h);
            let layers = render_region(
                &frame,
                &RenderSettings::DEFAULT,
                rect,
                SampleRange::new(0, 64),
                32,
                &|_| {},
            )
            .resolve();
            let path = dir.join(format!("frame_{f:04}.png"));
            write_preview_png(&path, (w, h), &layers, 0.0).unwrap();
            path
        })
        .collect()
}

#[test]
fn an_mp4_has_the_frames_their_rate_and_the_first_frame_within_encoding_error() {
    let Some(ffmpeg) = ffmpeg() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (129, 97);
    let frames = write_frames(dir.path(), 5, (w, h));
    let mp4 = dir.path().join("out.mp4");
    ffmpeg.encode(&frames, 25.0, &mp4, 2).unwrap();
    let bytes = std::fs::read(&mp4).unwrap();
    assert_eq!(&bytes[4..8], b"ftyp");
    assert!(!dir.path().join("out.partial.mp4").exists());

    let info = ffmpeg.probe(&mp4).unwrap();
    assert_eq!((info.frames, info.fps, info.h264), (5, 25.0, true));
    assert_eq!(
        info.size,
        (130, 98),
        "odd sides padded by a pixel for 4:2:0"
    );

    let first = dir.path().join("first.png");
    ffmpeg.frame_png(&mp4, 0, &first).unwrap();
    let decoded = image::open(&first).unwrap().to_rgb8();
    let original = image::open(&frames[0]).unwrap().to_rgb8();
    let mut squares = 0u64;
    let mut bias = [0i64; 3];
    for (x, y, p) in original.enumerate_pixels() {
        let q = decoded.get_pixel(x, y);
        for (c, bias) in bias.iter_mut().enumerate() {
            squares += u64::from(p.0[c].abs_diff(q.0[c])).pow(2);
            *bias += i64::from(q.0[c]) - i64::from(p.0[c]);
        }
    }
    let bias = bias.map(|b| b as f64 / (w * h) as f64);
    let mse = squares as f64 / (3 * w * h) as f64;
    let psnr = 10.0 * (255.0f64 * 255.0 / mse).log10();
    eprintln!(
        "first frame against its PNG: PSNR {psnr:.1} dB (RMSE {:.2} of 255), mean difference \
         per channel {bias:.2?}",
        mse.sqrt()
    );
    // Measured 32.1 dB and at most 1.1 levels: the RMSE is the 64-spp noise, which H.264
    // smooths; a colour matrix or range mixed up between encoding and decoding would show
    // as a mean difference of several levels.
    assert!(psnr > 30.0, "PSNR {psnr} dB");
    assert!(bias.iter().all(|b| b.abs() < 2.0), "{bias:?}");
}

#[test]
fn frames_that_do_not_exist_are_an_error_and_leave_no_file() {
    let Some(ffmpeg) = ffmpeg() else { return };
    let dir = tempfile::tempdir().unwrap();
    let mp4 = dir.path().join("out.mp4");
    let err = ffmpeg
        .encode(&[dir.path().join("missing.png")], 24.0, &mp4, 1)
        .unwrap_err();
    assert!(err.to_string().contains("encoding the video"), "{err}");
    assert!(!mp4.exists() && !dir.path().join("out.partial.mp4").exists());
    assert!(ffmpeg.encode(&[], 24.0, &mp4, 1).is_err());
}
