//! `tessera render`: a frame or a sequence of a scene, straight from the tracer to EXRs and
//! PNG previews, without the farm.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use proto::job::{Quality, DEFAULT_MIN_SPP};
use tracer::animation::AnimationChoice;
use tracer::film::{SampleRange, TileRect};
use tracer::light::{Environment, EnvironmentMap};
use tracer::limits::{MAX_DEPTH, MAX_FPS, MAX_MOTION_STEPS, MAX_SPP};
use tracer::motion::Shutter;
use tracer::output::{self, ExrMetadata};
use tracer::render::{
    prepare_frame, render_region, CameraChoice, FrameOptions, NoiseTarget, RenderSettings,
};
use tracer::scene::Scene;

use crate::args::{
    parse_animation, parse_camera, parse_frames, parse_region, parse_shutter, parse_size,
    FrameRange,
};

#[derive(Args)]
pub struct RenderArgs {
    /// A .gltf (with its .bin and images beside it) or .glb; the built-in animated demo
    /// scene when left out.
    scene: Option<PathBuf>,
    /// A built-in scene instead of a file: `demo` (the animated demo), `cornell` (the
    /// measured Cornell box) or `fluorescence` (the spectral showcase: a fluorescent ball,
    /// a light that turns ultraviolet at 1 s, a dispersive prism; frames 1-48).
    #[arg(long, value_enum, conflicts_with = "scene")]
    builtin: Option<Builtin>,
    /// Write the scene as a .glb to this path and render nothing: a built-in scene to
    /// submit to the farm (`tessera submit FILE`).
    #[arg(long)]
    export_glb: Option<PathBuf>,
    /// Frame number; it sets the time (frame / fps) and keys the random numbers.
    #[arg(
        long,
        default_value_t = 1,
        conflicts_with = "frames",
        allow_hyphen_values = true
    )]
    frame: i32,
    /// A sequence instead of one frame: A-B or A-B:STEP. `--out` is then a folder that
    /// receives frame_0001.exr, frame_0001.png, ...
    #[arg(long, value_parser = parse_frames)]
    frames: Option<FrameRange>,
    /// Frames per second.
    #[arg(long, default_value_t = 24.0, allow_hyphen_values = true)]
    fps: f64,
    /// Shutter OPEN,CLOSE in frames relative to each frame's time (e.g. -0.25,0.25 for a
    /// 180° shutter); 0,0 renders without motion blur.
    #[arg(long, default_value = "0,0", value_parser = parse_shutter, allow_hyphen_values = true)]
    shutter: Shutter,
    /// Motion steps across an open shutter (1..=64); by default chosen from how much the
    /// scene moves inside it.
    #[arg(long)]
    motion_steps: Option<u32>,
    /// Play only this animation (glTF index or name); all play together by default.
    #[arg(long, value_parser = parse_animation)]
    animation: Option<AnimationChoice>,
    /// A quality preset: draft, preview or final (see `tessera render --help` and
    /// README.md); --spp, --max-depth, --noise-threshold and --min-spp override its parts.
    #[arg(long)]
    quality: Option<Quality>,
    /// Samples per pixel; with a noise threshold, the most a pixel takes [default: 64, or
    /// the preset's].
    #[arg(long)]
    spp: Option<u32>,
    /// Maximum bounces (0: emitters seen directly, 1: direct light only) [default: 8, or
    /// the preset's].
    #[arg(long)]
    max_depth: Option<u32>,
    /// Adaptive sampling: a pixel stops once its estimated relative error (Cycles'
    /// measure; 0.01 is clean) is at most this. Off by default.
    #[arg(long)]
    noise_threshold: Option<f32>,
    /// With a noise threshold, the samples every pixel takes before it may stop
    /// [default: 16, or the preset's; at most --spp].
    #[arg(long)]
    min_spp: Option<u32>,
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
    /// The same sampling pattern on every frame (the frame number leaves the random
    /// numbers' key): the noise stays in place across a sequence, so denoised frames
    /// flicker less.
    #[arg(long)]
    fixed_pattern: bool,
    /// Clamp light that reaches the camera after two or more surfaces to at most this in
    /// its largest RGB channel (Cycles' "clamp indirect"): fewer fireflies (the caustics on
    /// the demo's walls), a little less light; `tessera bench clamp` measures both
    /// [default: off].
    #[arg(long, value_parser = crate::args::parse_clamp)]
    clamp_indirect: Option<f32>,
    /// Carry light at four sampled wavelengths even where the scene needs no spectral
    /// feature (dispersion, fluorescence, light spectra take that path by themselves): to
    /// compare with the RGB path, which converges to nearly the same image with less
    /// colour noise.
    #[arg(long)]
    spectral: bool,
    /// Environment: `black`, a radiance `R,G,B` or one number, or an equirectangular .exr.
    /// By default the scene's own; a glTF scene without punctual lights gets a uniform white
    /// environment of radiance 1, one with punctual lights none.
    #[arg(long)]
    environment: Option<String>,
    /// Also denoise each frame with Intel Open Image Denoise (guided by the albedo and
    /// normal layers): the EXR gets a `denoised` layer beside the noisy beauty, and the
    /// PNG preview shows it. Needs the library: `tessera install oidn`.
    #[arg(long)]
    denoise: bool,
    /// Where Open Image Denoise is installed (default: where `tessera install oidn` puts
    /// it, then the system's library path).
    #[arg(long, env = "TESSERA_OIDN", value_name = "DIR")]
    oidn: Option<PathBuf>,
    /// Worker threads (all cores by default).
    #[arg(long)]
    threads: Option<usize>,
    /// The EXR to write (a tone-mapped PNG preview is written beside it); with --frames,
    /// the folder to write the sequence into.
    #[arg(long)]
    out: Option<PathBuf>,
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

/// The scenes built into the tracer.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum Builtin {
    /// The farm demo: a Cornell box with a bouncing metal sphere, a turning box and a
    /// sliding glass sphere.
    Demo,
    /// The measured Cornell box with its two blocks.
    Cornell,
    /// The spectral showcase.
    Fluorescence,
}

impl Builtin {
    /// Builds it.
    pub fn scene(self) -> Scene {
        match self {
            Builtin::Demo => tracer::demo::animated_demo_scene(),
            Builtin::Cornell => tracer::demo::cornell_box(),
            Builtin::Fluorescence => tracer::demo::fluorescence_scene(),
        }
    }
}

/// Loads the scene named on the command line, or `demo` when none is named.
pub fn load_scene(path: Option<&PathBuf>, demo: fn() -> Scene) -> anyhow::Result<Scene> {
    match path {
        Some(p) => tracer::loader::load_path(p).with_context(|| format!("loading {}", p.display())),
        None => Ok(demo()),
    }
}

/// The sampling settings of `--quality`, `--spp`, `--max-depth`, `--noise-threshold` and
/// `--min-spp`, checked: (spp, settings).
fn sampling(args: &RenderArgs) -> anyhow::Result<(u32, RenderSettings)> {
    let preset = args.quality.map(Quality::settings);
    let spp = args.spp.or(preset.map(|p| p.spp)).unwrap_or(64);
    let max_depth = args.max_depth.or(preset.map(|p| p.max_depth)).unwrap_or(8);
    if spp == 0 || spp > MAX_SPP {
        bail!("--spp {spp}: must be 1..={MAX_SPP}");
    }
    if max_depth > MAX_DEPTH {
        bail!("--max-depth {max_depth}: must be at most {MAX_DEPTH}");
    }
    let threshold = args
        .noise_threshold
        .or(preset.map(|p| p.noise_threshold as f32));
    let noise = match threshold {
        Some(t) => {
            if !(t > 0.0 && t <= 1.0) {
                bail!("--noise-threshold {t}: must be in (0, 1] (0.01 is clean, 0.1 rough)");
            }
            let min_samples = match args.min_spp {
                Some(m) if m == 0 || m > spp => {
                    bail!("--min-spp {m}: must be 1..=--spp ({spp})")
                }
                Some(m) => m,
                None => preset.map_or(DEFAULT_MIN_SPP, |p| p.min_spp).min(spp),
            };
            Some(NoiseTarget {
                threshold: t,
                min_samples,
            })
        }
        None if args.min_spp.is_some() => bail!("--min-spp needs --noise-threshold"),
        None => None,
    };
    let settings = RenderSettings {
        noise,
        max_depth,
        seed: args.seed,
        spectral: args.spectral,
        fixed_pattern: args.fixed_pattern,
        clamp_indirect: args.clamp_indirect,
        ..RenderSettings::DEFAULT
    };
    Ok((spp, settings))
}

pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    let (spp, settings) = sampling(&args)?;
    if !(args.fps.is_finite() && args.fps > 0.0 && args.fps <= MAX_FPS) {
        bail!("--fps {}: must be in (0, {MAX_FPS}]", args.fps);
    }
    if let Some(n) = args.motion_steps {
        if !(1..=MAX_MOTION_STEPS).contains(&n) {
            bail!("--motion-steps {n}: must be 1..={MAX_MOTION_STEPS}");
        }
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
    // One frame to a file, or a sequence into a folder.
    let (frames, out): (Vec<i32>, Output) = match args.frames {
        Some(range) => {
            let dir = args.out.clone().unwrap_or_else(|| PathBuf::from("out"));
            std::fs::create_dir_all(&dir)
                .with_context(|| format!("creating the output folder {}", dir.display()))?;
            (range.frames().collect(), Output::Folder(dir, range))
        }
        None => (
            vec![args.frame],
            Output::File(args.out.clone().unwrap_or_else(|| "out.exr".into())),
        ),
    };

    // Before anything is rendered: a missing library is said at once.
    let oidn = match args.denoise {
        true => Some(post::Oidn::load(args.oidn.as_deref())?),
        false => None,
    };

    let t_load = Instant::now();
    let scene = Arc::new(match args.builtin {
        Some(builtin) => builtin.scene(),
        None => load_scene(args.scene.as_ref(), tracer::demo::animated_demo_scene)?,
    });
    if let Some(path) = &args.export_glb {
        let glb = tracer::export::scene_to_glb(&scene)
            .map_err(|e| anyhow::anyhow!("exporting the scene to GLB: {e}"))?;
        std::fs::write(path, glb).with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
        return Ok(());
    }
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let environment = args
        .environment
        .as_deref()
        .map(parse_environment)
        .transpose()?;
    let load_time = t_load.elapsed();

    let bar = ProgressBar::new(region.area() as u64 * frames.len() as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {wide_bar} {percent}% ETA {eta} {msg}",
        )
        .expect("valid template"),
    );
    let t_all = Instant::now();
    for &frame_number in &frames {
        let options = FrameOptions {
            frame: frame_number,
            fps: args.fps,
            shutter: args.shutter,
            motion_steps: args.motion_steps,
            animation: args.animation.clone().unwrap_or_default(),
            width,
            height,
            camera: args.camera.clone().unwrap_or_default(),
            environment: environment.clone(),
        };
        let t_prepare = Instant::now();
        let frame = prepare_frame(scene.clone(), &options)
            .with_context(|| format!("frame {frame_number}"))?;
        let prepare_time = t_prepare.elapsed().as_secs_f64();
        if frame_number == frames[0] {
            for w in &frame.warnings {
                bar.suspend(|| eprintln!("note: {w}"));
            }
        }
        bar.set_message(format!("frame {frame_number}"));
        let t_render = Instant::now();
        let tile = render_region(
            &frame,
            &settings,
            region,
            SampleRange::new(0, spp),
            32,
            &|t| bar.inc(t.rect.area() as u64),
        );
        let render_time = t_render.elapsed().as_secs_f64();

        let mut layers = tile.resolve();
        let reached = layers.sampling();
        let denoise_time = match &oidn {
            Some(oidn) => {
                let t = Instant::now();
                let threads = args.threads.unwrap_or(0) as u32;
                layers.denoised = post::denoise_layers(oidn, &layers, threads)
                    .with_context(|| format!("denoising frame {frame_number}"))?;
                Some(t.elapsed().as_secs_f64())
            }
            None => None,
        };
        let mut meta = ExrMetadata::new()
            .with(ExrMetadata::VERSION, env!("CARGO_PKG_VERSION"))
            .with(ExrMetadata::SPP, spp.to_string())
            .with_sampling(&reached)
            .with(ExrMetadata::RENDER_SECONDS, format!("{render_time:.3}"))
            .with("tessera/max-depth", settings.max_depth.to_string())
            .with("tessera/frame", frame_number.to_string())
            .with("tessera/fps", args.fps.to_string())
            .with(
                "tessera/shutter",
                format!("{},{}", args.shutter.open, args.shutter.close),
            )
            .with("tessera/motion-steps", frame.motion_steps.to_string())
            .with("tessera/seed", args.seed.to_string())
            .with("tessera/fixed-pattern", args.fixed_pattern.to_string())
            .with(ExrMetadata::FEATURES, frame.features.names().join(","))
            .with(
                "tessera/path",
                if tracer::integrator::carries_wavelengths(&frame, &settings) {
                    "spectral"
                } else {
                    "rgb"
                },
            );
        if let Some(q) = args.quality {
            meta.set("tessera/quality", q.name());
        }
        if let Some(seconds) = denoise_time {
            meta.set(ExrMetadata::DENOISER, post::DENOISER_NAME);
            meta.set(ExrMetadata::DENOISE_SECONDS, format!("{seconds:.3}"));
        }
        if let Some(limit) = settings.clamp_indirect {
            meta.set("tessera/clamp-indirect", limit.to_string());
        }
        if let Some(t) = settings.noise {
            meta.set("tessera/noise-threshold", t.threshold.to_string());
            meta.set("tessera/min-spp", t.min_samples.to_string());
        }
        let exr = match &out {
            Output::File(path) => path.clone(),
            Output::Folder(dir, range) => dir.join(range.file_name(frame_number, "exr")),
        };
        output::write_exr(&exr, (width, height), &layers, &meta)
            .with_context(|| format!("writing {}", exr.display()))?;
        let png = exr.with_extension("png");
        output::write_preview_png(&png, (width, height), &layers, 1.0)
            .with_context(|| format!("writing {}", png.display()))?;

        let paths = region.area() as f64 * reached.mean_samples;
        let noise = reached
            .mean_noise
            .map_or("no noise estimate".to_string(), |e| format!("noise {e:.4}"));
        let line = format!(
            "frame {frame_number}: {}x{} ({} px) at {:.1} spp (pixels {}..={}), {noise}, \
             {} motion step(s), in {:.2} s (prepare {:.2} s): {:.2} M samples/s, \
             {:.2} M rays/s, {} NaN/inf samples dropped",
            region.width,
            region.height,
            region.area(),
            reached.mean_samples,
            reached.min_samples,
            reached.max_samples,
            frame.motion_steps,
            render_time,
            prepare_time,
            paths / render_time / 1e6,
            tile.rays as f64 / render_time / 1e6,
            tile.dropped
        );
        let line = match denoise_time {
            Some(t) => format!("{line}; denoised in {t:.2} s"),
            None => line,
        };
        bar.suspend(|| println!("{line}"));
        if let Output::File(_) = out {
            bar.suspend(|| println!("wrote {} and {}", exr.display(), png.display()));
        }
    }
    bar.finish_and_clear();
    if let Output::Folder(dir, _) = &out {
        println!(
            "wrote {} frame(s) to {} in {:.2} s (scene loaded in {:.2} s)",
            frames.len(),
            dir.display(),
            t_all.elapsed().as_secs_f64(),
            load_time.as_secs_f64()
        );
    }
    Ok(())
}

/// Where the EXRs go.
enum Output {
    File(PathBuf),
    /// A sequence's folder, and the sequence (its file names are as wide as its last frame).
    Folder(PathBuf, FrameRange),
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        render: RenderArgs,
    }

    fn sampling_of(args: &[&str]) -> anyhow::Result<(u32, RenderSettings)> {
        let cli = Cli::try_parse_from(std::iter::once("render").chain(args.iter().copied()))?;
        sampling(&cli.render)
    }

    fn error_of(args: &[&str]) -> String {
        format!("{:#}", sampling_of(args).unwrap_err())
    }

    /// `--builtin` names a scene built into the tracer, never together with a file, and
    /// `--export-glb` writes it out as a GLB that loads back as the same scene.
    #[test]
    fn a_builtin_scene_is_named_and_exported() {
        assert!(Cli::try_parse_from(["render", "x.glb", "--builtin", "demo"]).is_err());
        assert!(Cli::try_parse_from(["render", "--builtin", "teapot"]).is_err());
        let dir = std::env::temp_dir().join(format!("tessera-builtin-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("showcase.glb");
        let cli = Cli::try_parse_from([
            "render",
            "--builtin",
            "fluorescence",
            "--export-glb",
            path.to_str().unwrap(),
        ])
        .unwrap();
        run(cli.render).unwrap();
        let scene = tracer::loader::load_path(&path).unwrap();
        assert!(scene.features.fluorescence && scene.features.dispersion);
        assert!(scene.features.light_spectra && scene.features.needs_spectral());
        assert_eq!(scene.animations[0].properties.len(), 3);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The frame says which path rendered it: the RGB path for a scene without spectral
    /// features, the spectral one with `--spectral` or a scene that needs it.
    #[test]
    fn the_exr_names_the_path_it_took() {
        let dir = std::env::temp_dir().join(format!("tessera-path-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (scene, spectral, path) in [
            ("cornell", false, "rgb"),
            ("cornell", true, "spectral"),
            ("fluorescence", false, "spectral"),
        ] {
            let out = dir.join(format!("{scene}-{spectral}.exr"));
            let mut args = vec!["render", "--builtin", scene, "--size", "8x8", "--spp", "1"];
            if spectral {
                args.push("--spectral");
            }
            args.extend(["--out", out.to_str().unwrap()]);
            run(Cli::try_parse_from(args).unwrap().render).unwrap();
            let image = tracer::output::read_exr(&out).unwrap();
            assert_eq!(
                image.attribute("tessera/path"),
                Some(path),
                "{scene} {spectral}"
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A negative number is a value, not a flag: its range is checked (with a message
    /// naming the flag), not refused by the parser.
    #[test]
    fn negative_numbers_reach_the_range_checks() {
        let cli = Cli::try_parse_from(["render", "--fps", "-5", "--frame", "-3"]).unwrap();
        assert_eq!((cli.render.fps, cli.render.frame), (-5.0, -3));
        let e = format!("{:#}", run(cli.render).unwrap_err());
        assert!(e.starts_with("--fps -5: must be in (0, "), "{e}");
    }

    #[test]
    fn defaults_render_64_spp_without_a_noise_target() {
        let (spp, settings) = sampling_of(&[]).unwrap();
        assert_eq!((spp, settings.max_depth, settings.noise), (64, 8, None));
    }

    #[test]
    fn a_quality_preset_sets_everything_and_options_override_it() {
        let (spp, settings) = sampling_of(&["--quality", "draft"]).unwrap();
        let draft = Quality::Draft.settings();
        assert_eq!((spp, settings.max_depth), (draft.spp, draft.max_depth));
        let target = settings.noise.unwrap();
        assert_eq!(target.threshold, draft.noise_threshold as f32);
        assert_eq!(target.min_samples, draft.min_spp);

        let (spp, settings) = sampling_of(&[
            "--quality",
            "final",
            "--spp",
            "8",
            "--max-depth",
            "3",
            "--noise-threshold",
            "0.2",
        ])
        .unwrap();
        assert_eq!((spp, settings.max_depth), (8, 3));
        // The preset's minimum is cut to the maximum.
        assert_eq!(
            settings.noise,
            Some(NoiseTarget {
                threshold: 0.2,
                min_samples: 8
            })
        );
    }

    #[test]
    fn absurd_sampling_settings_are_refused_by_name() {
        for (args, expected) in [
            (&["--spp", "0"][..], "--spp 0"),
            (&["--max-depth", "5000"], "--max-depth 5000"),
            (&["--noise-threshold", "0"], "--noise-threshold 0"),
            (&["--noise-threshold=-1"], "--noise-threshold -1"),
            (&["--noise-threshold", "NaN"], "--noise-threshold NaN"),
            (&["--noise-threshold", "2"], "--noise-threshold 2"),
            (
                &[
                    "--noise-threshold",
                    "0.1",
                    "--min-spp",
                    "100",
                    "--spp",
                    "64",
                ],
                "--min-spp 100",
            ),
            (
                &["--noise-threshold", "0.1", "--min-spp", "0"],
                "--min-spp 0",
            ),
            (&["--min-spp", "4"], "--min-spp needs --noise-threshold"),
        ] {
            let e = error_of(args);
            assert!(e.contains(expected), "{args:?}: {e}");
        }
        assert!(error_of(&["--quality", "best"]).contains("draft, preview or final"));
    }
}
