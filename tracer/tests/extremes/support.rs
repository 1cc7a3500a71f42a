//! What every case of the matrix needs: render, check finiteness, compare images.

use std::sync::Arc;

use glam::{DMat4, Vec3};
use tracer::film::{Layers, SampleRange, TileBuffer, TileRect};
use tracer::render::{prepare_frame, render_region, FrameOptions, PreparedFrame, RenderSettings};
use tracer::scene::{Node, Scene};

/// Prepares `scene` for `options`, panicking with the error if it cannot be.
pub fn prepare(scene: Scene, options: &FrameOptions) -> PreparedFrame {
    prepare_frame(Arc::new(scene), options).expect("scene prepares")
}

/// Renders the whole frame with `spp` samples per pixel in 16-pixel tiles.
pub fn render(frame: &PreparedFrame, settings: &RenderSettings, spp: u32) -> Layers {
    render_buffer(frame, settings, spp).resolve()
}

/// [`render`]'s raw sums: they count the samples dropped as NaN or infinite (which a
/// finite resolved image cannot show) and the rays traced.
pub fn render_buffer(frame: &PreparedFrame, settings: &RenderSettings, spp: u32) -> TileBuffer {
    let rect = TileRect::new(0, 0, frame.width, frame.height);
    render_region(frame, settings, rect, SampleRange::new(0, spp), 16, &|_| {})
}

/// Options for a `width` x `height` frame, everything else default.
pub fn options(width: u32, height: u32) -> FrameOptions {
    FrameOptions {
        width,
        height,
        ..Default::default()
    }
}

/// Panics naming the first pixel of any layer that is NaN or infinite. Depth is allowed
/// its "nothing hit" value, which is finite by definition.
pub fn assert_finite(case: &str, layers: &Layers) {
    let width = layers.rect.width as usize;
    let at = |i: usize| (i % width, i / width);
    for (i, b) in layers.beauty.iter().enumerate() {
        assert!(b.is_finite(), "{case}: beauty {b} at {:?}", at(i));
    }
    for (i, a) in layers.albedo.iter().enumerate() {
        assert!(a.is_finite(), "{case}: albedo {a} at {:?}", at(i));
    }
    for (i, n) in layers.normal.iter().enumerate() {
        assert!(n.is_finite(), "{case}: normal {n} at {:?}", at(i));
    }
    for (i, d) in layers.depth.iter().enumerate() {
        assert!(d.is_finite(), "{case}: depth {d} at {:?}", at(i));
    }
}

/// Mean beauty RGB over the image.
pub fn mean_rgb(layers: &Layers) -> Vec3 {
    let sum: Vec3 = layers.beauty.iter().map(|b| b.truncate()).sum();
    sum / layers.beauty.len() as f32
}

/// Mean luminance-like value (the RGB average) over the image, in f64.
pub fn mean(layers: &Layers) -> f64 {
    let rgb = mean_rgb(layers);
    (rgb.x as f64 + rgb.y as f64 + rgb.z as f64) / 3.0
}

/// Compares two renders of the same view block by block: each `block` x `block` square's
/// mean RGB must agree within `tolerance` relative to the image's mean (noise averages out
/// over a block; acne, leaks and shifted geometry do not). Returns the largest relative
/// block difference, for the table.
pub fn assert_same_image(
    case: &str,
    got: &Layers,
    want: &Layers,
    block: u32,
    tolerance: f64,
) -> f64 {
    assert_eq!(got.rect, want.rect, "{case}: image sizes differ");
    let (w, h) = (got.rect.width, got.rect.height);
    let scale = mean(want).max(1e-12);
    let mut worst = 0.0f64;
    let mut worst_at = (0, 0);
    for by in (0..h).step_by(block as usize) {
        for bx in (0..w).step_by(block as usize) {
            let (mut g, mut r, mut n) = (Vec3::ZERO, Vec3::ZERO, 0.0f32);
            for y in by..(by + block).min(h) {
                for x in bx..(bx + block).min(w) {
                    let i = (y * w + x) as usize;
                    g += got.beauty[i].truncate();
                    r += want.beauty[i].truncate();
                    n += 1.0;
                }
            }
            let diff = ((g - r) / n).abs().max_element() as f64 / scale;
            if diff > worst {
                worst = diff;
                worst_at = (bx, by);
            }
        }
    }
    println!(
        "{case}: worst {block}px block differs by {worst:.4} of the mean (allowed {tolerance})"
    );
    assert!(
        worst <= tolerance,
        "{case}: the {block}px block at {worst_at:?} differs by {worst:.4} of the image mean \
         (allowed {tolerance})"
    );
    worst
}

/// `scene` with one new root node above its roots, transformed by `root`: the whole scene,
/// camera and lights included, scaled or moved as one.
pub fn under_root(mut scene: Scene, root: DMat4) -> Scene {
    let children = std::mem::take(&mut scene.roots);
    scene.nodes.push(Node {
        name: Some("extreme root".into()),
        local: root,
        children,
        ..Default::default()
    });
    scene.roots = vec![scene.nodes.len() as u32 - 1];
    scene
}
