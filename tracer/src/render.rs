//! The tracer's one entry point, [`render_tile`]: any rectangle and sample range of a
//! [`PreparedFrame`], a pure function of them. [`render_region`] splits a region into
//! tiles for progress bars.
//!
//! The frame's types are re-exported here, so that a caller needs one module:
//! [`prepare_frame`] poses the scene at the frame's time, moves it so the camera sits at
//! the origin, and builds the top-level BVH and the light set.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::film::{PixelSum, SampleRange, TileBuffer, TileRect};
use crate::integrator;

pub use crate::frame::PreparedFrame;
pub use crate::prepare::prepare_frame;
pub use crate::settings::{CameraChoice, FrameOptions, NoiseTarget, RenderError, RenderSettings};

/// Renders samples `samples` of the pixels in `rect` of `frame` (with a noise target, a
/// pixel stops early once it reaches it). Every pixel is a pure function of (pixel,
/// sample index, frame, settings), so any split into tiles and sample ranges gives the
/// same result. Parallel over rows with rayon.
pub fn render_tile(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    rect: TileRect,
    samples: SampleRange,
) -> TileBuffer {
    let never = AtomicBool::new(false);
    render_tile_cancellable(frame, settings, rect, samples, &never)
        .expect("a render nobody cancels finishes")
}

/// [`render_tile`] that gives up, returning `None`, soon after `cancel` is set: each pixel
/// checks it, so a worker whose lease is gone stops within one pixel's samples per thread.
/// When it finishes, the tile is bit-identical to [`render_tile`]'s.
pub fn render_tile_cancellable(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    rect: TileRect,
    samples: SampleRange,
    cancel: &AtomicBool,
) -> Option<TileBuffer> {
    let rows: Option<Vec<TileBuffer>> = (0..rect.height)
        .into_par_iter()
        .map(|row| {
            let mut buf = TileBuffer::new(TileRect::new(rect.x, rect.y + row, rect.width, 1));
            for col in 0..rect.width {
                if cancel.load(Ordering::Relaxed) {
                    return None;
                }
                let (pixel, mut streak) = (col as usize, 0);
                let (x, y) = (rect.x + col, rect.y + row);
                let run = samples.start..samples.end;
                let mut sum = PixelSum::default();
                integrator::trace_samples(frame, settings, x, y, run, &mut |index, s| {
                    sum.add(index, s);
                    settings.noise.as_ref().is_none_or(|target| {
                        let taken = index + 1 - samples.start;
                        !target.reached(taken, sum.noise(), &mut streak)
                    })
                });
                buf.add_pixel(pixel, &sum);
            }
            Some(buf)
        })
        .collect();
    let mut tile = TileBuffer::new(rect);
    rows?.iter().for_each(|row| tile.paste(row));
    Some(tile)
}

/// Renders `rect` split into `tile_size` tiles, in parallel, calling `tile_done` after
/// each tile (for progress bars). The result equals one [`render_tile`] of `rect`.
pub fn render_region(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    rect: TileRect,
    samples: SampleRange,
    tile_size: u32,
    tile_done: &(dyn Fn(&TileBuffer) + Sync),
) -> TileBuffer {
    let tiles: Vec<TileBuffer> = rect
        .tiles(tile_size)
        .into_par_iter()
        .map(|t| {
            let buf = render_tile(frame, settings, t, samples);
            tile_done(&buf);
            buf
        })
        .collect();
    let mut out = TileBuffer::new(rect);
    tiles.iter().for_each(|t| out.paste(t));
    out
}
