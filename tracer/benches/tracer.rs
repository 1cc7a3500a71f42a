//! Criterion benchmarks of the tracer's hot kernels: BVH build, closest hits in one mesh
//! BVH (static and deforming), closest-hit camera rays, and whole paths through the demo
//! scene. Run with `cargo bench -p tracer`.

// Test scenes use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use std::sync::Arc;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use glam::{Vec2, Vec3};

use tracer::bvh::MeshBvh;
use tracer::film::{SampleRange, TileRect};
use tracer::geometry::Ray;
use tracer::render::{prepare_frame, render_tile, FrameOptions, PreparedFrame, RenderSettings};
use tracer::shapes::bumpy_grid;

fn demo_frame(size: u32) -> PreparedFrame {
    let options = FrameOptions {
        width: size,
        height: size,
        ..Default::default()
    };
    prepare_frame(Arc::new(tracer::demo::demo_scene()), &options).expect("demo prepares")
}

fn bvh_build(c: &mut Criterion) {
    let mut g = c.benchmark_group("bvh_build");
    g.sample_size(10);
    for n in [64, 256] {
        let tris = bumpy_grid(n);
        g.throughput(Throughput::Elements(tris.len() as u64));
        g.bench_with_input(BenchmarkId::from_parameter(tris.len()), &tris, |b, t| {
            b.iter(|| MeshBvh::build(t))
        });
    }
    g.finish();
}

/// Rays from above the grid towards it, spread over its whole area, at shutter times
/// spread over [0, 1] (static BVHs ignore the time).
fn grid_rays(count: usize) -> Vec<Ray> {
    (0..count)
        .map(|i| {
            let (u, v) = ((i % 64) as f32 / 64.0, (i / 64 % 64) as f32 / 64.0);
            let origin = Vec3::new(0.5, 2.0, 0.5);
            let mut ray = Ray::new(origin, Vec3::new(u, 0.0, v) - origin);
            ray.time = ((i * 37) % count) as f32 / count as f32;
            ray
        })
        .collect()
}

fn bvh_rays(c: &mut Criterion) {
    let tris = bumpy_grid(256);
    let rays = grid_rays(64 * 64);
    let bvh = MeshBvh::build(&tris);
    // The same grid deforming over the shutter: a wave that rises and moves sideways.
    let waved: Vec<[Vec3; 3]> = tris
        .iter()
        .map(|t| t.map(|v| v + Vec3::new(0.02, 0.1 * (9.0 * v.x + 7.0 * v.z).sin(), 0.0)))
        .collect();
    let moving = MeshBvh::build_motion(&[tris.clone(), waved]);
    let mut g = c.benchmark_group("bvh_rays");
    g.throughput(Throughput::Elements(rays.len() as u64));
    for (name, bvh) in [
        ("static_closest_hit", &bvh),
        ("motion_2_steps_closest_hit", &moving),
    ] {
        g.bench_function(name, |b| {
            b.iter(|| {
                rays.iter()
                    .filter(|r| bvh.intersect(r, f32::INFINITY, |_, _, _| true).is_some())
                    .count()
            })
        });
    }
    g.finish();
}

fn camera_rays(c: &mut Criterion) {
    let frame = demo_frame(64);
    let rays: Vec<_> = (0..64 * 64)
        .map(|i| {
            frame.camera.generate_ray(
                Vec2::new((i % 64) as f32 / 64.0, (i / 64) as f32 / 64.0),
                0.0,
            )
        })
        .collect();
    let mut g = c.benchmark_group("camera_rays");
    g.throughput(Throughput::Elements(rays.len() as u64));
    g.bench_function("demo_closest_hit", |b| {
        b.iter(|| {
            rays.iter()
                .filter(|r| frame.intersect(r, f32::INFINITY).is_some())
                .count()
        })
    });
    g.finish();
}

fn paths(c: &mut Criterion) {
    let frame = demo_frame(64);
    let settings = RenderSettings::default();
    let rect = TileRect::new(16, 16, 16, 16);
    let mut g = c.benchmark_group("paths");
    g.sample_size(10);
    g.throughput(Throughput::Elements(rect.area() as u64 * 4));
    g.bench_function("demo_tile_16x16_4spp", |b| {
        b.iter(|| render_tile(&frame, &settings, rect, SampleRange::new(0, 4)))
    });
    g.finish();
}

criterion_group!(benches, bvh_build, bvh_rays, camera_rays, paths);
criterion_main!(benches);
