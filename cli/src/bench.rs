//! `tessera bench`: what the tracer costs and what each sample count buys, on the
//! built-in demo scene (or any scene).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use clap::{Args, Subcommand};
use glam::Vec2;
use rayon::prelude::*;

use proto::job::Quality;
use tracer::film::{Layers, SampleRange, TileRect};
use tracer::render::{
    prepare_frame, render_region, FrameOptions, NoiseTarget, PreparedFrame, RenderSettings,
};

use crate::args::parse_size;
use crate::render::load_scene;

#[derive(Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct BenchArgs {
    /// Another benchmark instead of the tracer's.
    #[command(subcommand)]
    pub command: Option<BenchCommand>,
    /// Scene to measure; the built-in demo scene when left out.
    scene: Option<PathBuf>,
    /// Image size for the measurements.
    #[arg(long, default_value = "64x64", value_parser = parse_size)]
    size: (u32, u32),
    /// Samples per pixel of the reference image that errors are measured against.
    #[arg(long, default_value_t = 4096)]
    reference_spp: u32,
    /// Smaller reference and sweep, for a first look in seconds.
    #[arg(long)]
    quick: bool,
}

/// The benchmarks other than the tracer's.
#[derive(Subcommand)]
pub enum BenchCommand {
    /// Load-test the farm server: simulated workers long-poll for empty tasks; tasks per
    /// second, lease latency and server memory, and nothing lost or done twice.
    Farm(crate::bench_farm::FarmBenchArgs),
}

/// Root-mean-square error of the beauty RGB of `a` against `reference`.
pub fn rmse(a: &Layers, reference: &Layers) -> f64 {
    let sum: f64 = a
        .beauty
        .iter()
        .zip(&reference.beauty)
        .map(|(x, r)| {
            let d = (x.truncate() - r.truncate()).as_dvec3();
            d.length_squared() / 3.0
        })
        .sum();
    (sum / a.beauty.len() as f64).sqrt()
}

/// Closest-hit rays per second for the camera rays of one pass over the image.
fn camera_rays_per_second(frame: &PreparedFrame) -> f64 {
    let (w, h) = (frame.width, frame.height);
    let rays: Vec<_> = (0..w * h)
        .map(|i| {
            let film = Vec2::new(
                ((i % w) as f32 + 0.5) / w as f32,
                ((i / w) as f32 + 0.5) / h as f32,
            );
            frame.camera.generate_ray(film, 0.0)
        })
        .collect();
    let passes = 8;
    let start = Instant::now();
    let hits: usize = (0..passes)
        .map(|_| {
            rays.par_iter()
                .filter(|r| frame.intersect(r, f32::INFINITY).is_some())
                .count()
        })
        .sum();
    std::hint::black_box(hits);
    (rays.len() * passes) as f64 / start.elapsed().as_secs_f64()
}

pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    let (width, height) = if args.quick { (32, 32) } else { args.size };
    let reference_spp = if args.quick {
        args.reference_spp.min(512)
    } else {
        args.reference_spp
    };
    // The still demo: benchmark figures stay comparable from one build to the next.
    let scene = Arc::new(load_scene(args.scene.as_ref(), tracer::demo::demo_scene)?);
    let frame = prepare_frame(
        scene,
        &FrameOptions {
            width,
            height,
            ..Default::default()
        },
    )?;
    let settings = RenderSettings::default();
    let rect = TileRect::new(0, 0, width, height);
    let threads = rayon::current_num_threads();
    println!(
        "tessera bench: {width}x{height}, max depth {}, {threads} threads",
        settings.max_depth
    );

    println!(
        "camera rays (closest hit): {:.2} M rays/s",
        camera_rays_per_second(&frame) / 1e6
    );

    // The sweep uses another seed than the reference, so that its samples are not a prefix
    // of the reference's, which would flatter the error.
    let render_with = |settings: RenderSettings, spp: u32| {
        let start = Instant::now();
        let tile = render_region(
            &frame,
            &settings,
            rect,
            SampleRange::new(0, spp),
            32,
            &|_| {},
        );
        (tile, start.elapsed().as_secs_f64())
    };
    let render = |spp: u32, seed: u32| render_with(RenderSettings { seed, ..settings }, spp);
    let (tile, secs) = render(16, 1);
    let paths = rect.area() as f64 * 16.0;
    println!(
        "full paths: {:.3} M paths/s, {:.2} M rays/s (all ray kinds, 16 spp)",
        paths / secs / 1e6,
        tile.rays as f64 / secs / 1e6
    );

    // As deep as the deepest preset, so that no preset is measured against a reference
    // that lacks light it gathers.
    let reference_depth = Quality::ALL
        .iter()
        .map(|q| q.settings().max_depth)
        .max()
        .unwrap_or(settings.max_depth)
        .max(settings.max_depth);
    println!("reference: {reference_spp} spp, max depth {reference_depth} ...");
    let reference_settings = RenderSettings {
        max_depth: reference_depth,
        ..settings
    };
    let (reference, ref_secs) = render_with(reference_settings, reference_spp);
    let reference = reference.resolve();
    println!("reference took {ref_secs:.1} s");
    println!("| spp | time (s) | RMSE | RMSE x sqrt(time) |");
    println!("|---:|---:|---:|---:|");
    let sweep: &[u32] = if args.quick {
        &[1, 4, 16, 64]
    } else {
        &[1, 4, 16, 64, 256]
    };
    for &spp in sweep {
        let (tile, secs) = render(spp, 1);
        let e = rmse(&tile.resolve(), &reference);
        println!("| {spp} | {secs:.3} | {e:.5} | {:.5} |", e * secs.sqrt());
    }

    println!();
    println!("quality presets (--quality; adaptive sampling stops each pixel at its threshold):");
    println!("| preset | max spp | max depth | threshold | time (s) | mean spp | estimated error | RMSE |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    for q in Quality::ALL {
        let p = q.settings();
        let preset = RenderSettings {
            max_depth: p.max_depth,
            seed: 1,
            noise: Some(NoiseTarget {
                threshold: p.noise_threshold as f32,
                min_samples: p.min_spp,
            }),
        };
        let (tile, secs) = render_with(preset, p.spp);
        let layers = tile.resolve();
        let reached = layers.sampling();
        println!(
            "| {} | {} | {} | {} | {secs:.3} | {:.1} | {} | {:.5} |",
            q.name(),
            p.spp,
            p.max_depth,
            p.noise_threshold,
            reached.mean_samples,
            reached
                .mean_noise
                .map_or("-".to_string(), |e| format!("{e:.4}")),
            rmse(&layers, &reference)
        );
    }
    Ok(())
}
