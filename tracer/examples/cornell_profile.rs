//! The measured Cornell box at 256x256, max depth 8, seed 7, rendered through
//! `render_tile` on all threads: camera paths per second, rays, and a hash of the image,
//! so that a change meant to leave every pixel alone can show it did.
//!
//! `cargo run --release -p tracer --example cornell_profile -- [SPP] [spectral|motion] [sse2]`
//! (default 1, RGB; `motion`: the animated demo at frame 12 with its shutter instead, for
//! what moving frames cost; `sse2`: the baseline copies of the hot loops, which a CPU
//! without AVX runs, see `tracer::simd`). Under `valgrind --tool=callgrind` it gives the
//! instruction counts in BENCHMARKS.md.
use std::sync::Arc;
use std::time::Instant;
use tracer::film::{SampleRange, TileRect};
use tracer::render::{prepare_frame, render_tile, FrameOptions, RenderSettings};

fn main() {
    let spp: u32 = std::env::args()
        .nth(1)
        .map(|s| s.parse().unwrap())
        .unwrap_or(1);
    let mode = std::env::args().nth(2);
    if std::env::args().skip(2).any(|a| a == "sse2") {
        tracer::simd::allow_avx(false);
    }
    let moving = mode.as_deref() == Some("motion");
    let options = FrameOptions {
        width: 256,
        height: 256,
        frame: if moving { 12 } else { 0 },
        shutter: tracer::motion::Shutter {
            open: if moving { -0.25 } else { 0.0 },
            close: if moving { 0.25 } else { 0.0 },
        },
        ..Default::default()
    };
    let scene = if moving {
        tracer::demo::animated_demo_scene()
    } else {
        tracer::demo::cornell_box()
    };
    let frame = prepare_frame(Arc::new(scene), &options).unwrap();
    let settings = RenderSettings {
        max_depth: 8,
        seed: 7,
        spectral: mode.as_deref() == Some("spectral"),
        ..RenderSettings::DEFAULT
    };
    let start = Instant::now();
    let tile = render_tile(
        &frame,
        &settings,
        TileRect::new(0, 0, 256, 256),
        SampleRange::new(0, spp),
    );
    let s = start.elapsed().as_secs_f64();
    let rays = tile.rays;
    let l = tile.resolve();
    let sum: f64 = l.beauty.iter().map(|p| f64::from(p.x + p.y + p.z)).sum();
    let hash = l.beauty.iter().fold(0u64, |h, p| {
        (h ^ u64::from(
            p.x.to_bits() ^ p.y.to_bits().rotate_left(11) ^ p.z.to_bits().rotate_left(22),
        ))
        .wrapping_mul(0x100000001b3)
    });
    println!(
        "{spp} spp: {:.3} s, {:.0} paths/s, {rays} rays, beauty sum {sum:.6} hash {hash:016x}",
        s,
        65536.0 * f64::from(spp) / s
    );
}
