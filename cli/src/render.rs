//! `tessera render`: one frame of a scene, straight from the tracer to an EXR and a PNG.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use tracer::film::{SampleRange, TileRect};
use tracer::light::{Environment, EnvironmentMap};
use tracer::output::{self, ExrMetadata};
use tracer::render::{prepare_frame, render_region, CameraChoice, FrameOptions, RenderSettings};
use tracer::scene::Scene;

use crate::args::{parse_camera, parse_region, parse_size};

/// Most samples per pixel a single render accepts.
const MAX_SPP: u32 = 1_000_000;
/// Deepest path we accept.
const MAX_DEPTH: u32 = 1024;

#[derive(Args)]
pub struct RenderArgs {
    /// A .gltf (with its .bin and images beside it) or .glb; the built-in demo scene when
    /// left out.
    scene: Option<PathBuf>,
    /// Frame number; it sets the time (frame / fps) and keys the random numbers.
    #[arg(long, default_value_t = 1)]
    frame: i32,
    /// Frames per second.
    #[arg(long, default_value_t = 24.0)]
    fps: f64,
    /// Samples per pixel.
    #[arg(long, default_value_t = 64)]
    spp: u32,
    /// Maximum bounces (0: emitters seen directly, 1: direct light only).
    #[arg(long, default_value_t = 8)]
    max_depth: u32,
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "640x360", value_parser = parse_size)]
    size: (u32, u32),
    /// Camera by glTF index or name; the first camera, or one framing the scene, by default.
    #[arg(long, value_parser = parse_camera)]
    camera: Option<CameraChoice>,
    /// Render only this rectangle, X,Y,WIDTH,HEIGHT (the EXR keeps the full frame as its
    /// display window).
    #[arg(long, value_parser = parse_region)]
    region: Option<TileRect>,
    /// Seed mixed into every random number.
    #[arg(long, default_value_t = 0)]
    seed: u32,
    /// Environment: `black`, a radiance `R,G,B` or one number, or an equirectangular .exr.
    /// By default the scene's own; a glTF scene without punctual lights gets a uniform white
    /// environment of radiance 1, one with punctual lights none.
    #[arg(long)]
    environment: Option<String>,
    /// Worker threads (all cores by default).
    #[arg(long)]
    threads: Option<usize>,
    /// The EXR to write; a tone-mapped PNG preview is written beside it.
    #[arg(long, default_value = "out.exr")]
    out: PathBuf,
}

/// Parses `--environment`.
fn parse_environment(s: &str) -> anyhow::Result<Environment> {
    if s.eq_ignore_ascii_case("black") || s.eq_ignore_ascii_case("none") {
        return Ok(Environment::Black);
    }
    let numbers: Result<Vec<f32>, _> = s.split(',').map(|p| p.trim().parse::<f32>()).collect();
    if let Ok(v) = numbers {
        let rgb = match v[..] {
            [g] => glam::Vec3::splat(g),
            [r, g, b] => glam::Vec3::new(r, g, b),
            _ => bail!("--environment {s}: give one number or R,G,B"),
        };
        if !rgb.is_finite() || rgb.min_element() < 0.0 {
            bail!("--environment {s}: radiance must be finite and not negative");
        }
        return Ok(Environment::Constant(rgb));
    }
    let map = EnvironmentMap::load(std::path::Path::new(s))
        .with_context(|| format!("--environment {s}: not black, a colour, or a readable .exr"))?;
    Ok(Environment::Map(map))
}

/// Loads the scene named on the command line, or the demo.
pub fn load_scene(path: Option<&PathBuf>) -> anyhow::Result<Scene> {
    match path {
        Some(p) => tracer::loader::load_path(p).with_context(|| format!("loading {}", p.display())),
        None => Ok(tracer::demo::demo_scene()),
    }
}

pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    if args.spp == 0 || args.spp > MAX_SPP {
        bail!("--spp {}: must be 1..={MAX_SPP}", args.spp);
    }
    if args.max_depth > MAX_DEPTH {
        bail!(
            "--max-depth {}: must be at most {MAX_DEPTH}",
            args.max_depth
        );
    }
    if !(args.fps.is_finite() && args.fps > 0.0 && args.fps <= 1000.0) {
        bail!("--fps {}: must be in (0, 1000]", args.fps);
    }
    if let Some(n) = args.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global()?;
    }
    let (width, height) = args.size;
    let region = args.region.unwrap_or(TileRect::new(0, 0, width, height));
    if !region.fits_in(width, height) {
        bail!("--region {region:?} does not fit in the {width}x{height} frame");
    }

    let t_load = Instant::now();
    let scene = load_scene(args.scene.as_ref())?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let environment = args
        .environment
        .as_deref()
        .map(parse_environment)
        .transpose()?;
    let options = FrameOptions {
        frame: args.frame,
        fps: args.fps,
        width,
        height,
        camera: args.camera.clone().unwrap_or_default(),
        environment,
    };
    let frame = prepare_frame(Arc::new(scene), &options)?;
    for w in &frame.warnings {
        eprintln!("note: {w}");
    }
    let load_time = t_load.elapsed();

    let settings = RenderSettings {
        max_depth: args.max_depth,
        seed: args.seed,
    };
    let samples = SampleRange::new(0, args.spp);
    let bar = ProgressBar::new(region.area() as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {wide_bar} {percent}% ETA {eta}",
        )
        .expect("valid template"),
    );
    let t_render = Instant::now();
    let tile = render_region(&frame, &settings, region, samples, 32, &|t| {
        bar.inc(t.rect.area() as u64)
    });
    bar.finish_and_clear();
    let render_time = t_render.elapsed().as_secs_f64();

    let layers = tile.resolve();
    let meta = ExrMetadata::new()
        .with("tessera/version", env!("CARGO_PKG_VERSION"))
        .with("tessera/spp", args.spp.to_string())
        .with("tessera/max-depth", args.max_depth.to_string())
        .with("tessera/frame", args.frame.to_string())
        .with("tessera/seed", args.seed.to_string())
        .with("tessera/features", frame.features.names().join(","));
    output::write_exr(&args.out, (width, height), &layers, &meta)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let png = args.out.with_extension("png");
    output::write_preview_png(&png, (width, height), &layers, 1.0)
        .with_context(|| format!("writing {}", png.display()))?;

    let paths = region.area() as f64 * args.spp as f64;
    println!(
        "rendered {}x{} ({} px) at {} spp in {:.2} s (scene {:.2} s): {:.2} M samples/s, {:.2} M rays/s, {} NaN/inf samples dropped",
        region.width,
        region.height,
        region.area(),
        args.spp,
        render_time,
        load_time.as_secs_f64(),
        paths / render_time / 1e6,
        tile.rays as f64 / render_time / 1e6,
        tile.dropped
    );
    println!("wrote {} and {}", args.out.display(), png.display());
    Ok(())
}
