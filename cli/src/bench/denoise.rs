//! `tessera bench denoise`: what Open Image Denoise buys. Its time per megapixel; for the
//! reference scenes (the demo moving and still, the Cornell box), the fewest spp whose
//! denoised frame is as close to a reference as an undenoised frame at 256 and at 1024
//! spp (the speed-up users get); and
//! the flicker of a denoised animation with each frame's own sampling pattern and with
//! the same pattern on every frame (`--fixed-pattern`).

use std::sync::Arc;
use std::time::Instant;

use clap::Args;

use tracer::film::Layers;
use tracer::motion::Shutter;
use tracer::output::{aces_filmic, srgb_oetf};
use tracer::render::{prepare_frame, FrameOptions, PreparedFrame, RenderSettings};
use tracer::scene::Scene;

use super::scenes::{display_mse, mse, rel_mse, render};
use super::{REFERENCE_SEED, SEED};
use crate::args::parse_size;

#[derive(Args)]
pub struct DenoiseArgs {
    /// Frame size of the equal-error and flicker measurements.
    #[arg(long, default_value = "160x120", value_parser = parse_size)]
    size: (u32, u32),
    /// Samples per pixel of the equal-error references.
    #[arg(long, default_value_t = 4096)]
    reference_spp: u32,
    /// The demo frames whose flicker is measured, from frame 12 on.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(2..=48))]
    frames: u32,
    /// Samples per pixel of the flicker sequence.
    #[arg(long, default_value_t = 16)]
    flicker_spp: u32,
    /// Samples per pixel of the converged sequence the flicker is compared with.
    #[arg(long, default_value_t = 512)]
    converged_spp: u32,
    /// Only this section: `speed`, `equal-error` or `flicker` (default: all three).
    #[arg(long, value_enum)]
    only: Option<Section>,
    /// Where Open Image Denoise is installed (default: where `tessera install oidn` puts
    /// it, then the system's library path).
    #[arg(long, env = "TESSERA_OIDN", value_name = "DIR")]
    oidn: Option<std::path::PathBuf>,
}

/// A section of the report.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Section {
    Speed,
    EqualError,
    Flicker,
}

/// The undenoised spp whose error the denoised frames are matched against.
const TARGETS: [u32; 2] = [256, 1024];
/// The spp a denoised frame is tried at, in order.
const TRIED: [u32; 9] = [1, 2, 4, 8, 16, 32, 64, 128, 256];

pub fn run(args: DenoiseArgs) -> anyhow::Result<()> {
    let oidn = post::Oidn::load(args.oidn.as_deref())?;
    let threads = rayon::current_num_threads();
    println!(
        "\n### Denoising (Open Image Denoise 2.5.1, RT filter, albedo and normal, {threads} \
         threads)\n"
    );
    let runs = |section| args.only.is_none_or(|only| only == section);
    if runs(Section::Speed) {
        speed(&oidn)?;
    }
    if runs(Section::EqualError) {
        for (name, scene, frame, shutter) in [
            (
                "demo, frame 12",
                tracer::demo::animated_demo_scene(),
                12,
                0.25,
            ),
            ("demo, still", tracer::demo::demo_scene(), 0, 0.0),
            ("Cornell box", tracer::demo::cornell_box(), 0, 0.0),
        ] {
            equal_error(&oidn, &args, name, scene, frame, shutter)?;
        }
    }
    if runs(Section::Flicker) {
        flicker(&oidn, &args)?;
    }
    Ok(())
}

/// Seconds per megapixel at the bench's size and at 1280x720, the fastest of three.
fn speed(oidn: &post::Oidn) -> anyhow::Result<()> {
    println!("| frame | megapixels | seconds (fastest of 3) | seconds per megapixel |\n|---|---:|---:|---:|");
    for (w, h) in [(640, 360), (1280, 720)] {
        let frame = demo_frame(tracer::demo::animated_demo_scene(), 12, 0.0, (w, h))?;
        let (layers, _, _) = render(&frame, settings(SEED), 4);
        let mut best = f64::INFINITY;
        for _ in 0..3 {
            let t = Instant::now();
            post::denoise_layers(oidn, &layers, 0)?;
            best = best.min(t.elapsed().as_secs_f64());
        }
        let mp = f64::from(w * h) / 1e6;
        println!("| {w}x{h} | {mp:.2} | {best:.3} | {:.3} |", best / mp);
    }
    Ok(())
}

fn settings(seed: u32) -> RenderSettings {
    RenderSettings {
        max_depth: 8,
        seed,
        ..RenderSettings::DEFAULT
    }
}

pub(super) fn demo_frame(
    scene: Scene,
    frame: i32,
    shutter: f64,
    (width, height): (u32, u32),
) -> anyhow::Result<PreparedFrame> {
    let options = FrameOptions {
        frame,
        width,
        height,
        shutter: Shutter {
            open: -shutter,
            close: shutter,
        },
        ..FrameOptions::default()
    };
    Ok(prepare_frame(Arc::new(scene), &options)?)
}

/// `layers` with the denoiser's output as its beauty.
pub(super) fn denoised(oidn: &post::Oidn, layers: &Layers) -> anyhow::Result<(Layers, f64)> {
    let t = Instant::now();
    let rgb = post::denoise_layers(oidn, layers, 0)?;
    let seconds = t.elapsed().as_secs_f64();
    let mut out = layers.clone();
    for (b, d) in out.beauty.iter_mut().zip(rgb) {
        *b = d.extend(b.w);
    }
    Ok((out, seconds))
}

/// For each target spp, the fewest tried spp whose denoised frame's display MSE is at
/// most the undenoised target's, and what that saves in samples and in time.
fn equal_error(
    oidn: &post::Oidn,
    args: &DenoiseArgs,
    name: &str,
    scene: Scene,
    frame: i32,
    shutter: f64,
) -> anyhow::Result<()> {
    let frame = demo_frame(scene, frame, shutter, args.size)?;
    eprintln!("{name}: reference at {} spp ...", args.reference_spp);
    let (reference, _, _) = render(&frame, settings(REFERENCE_SEED), args.reference_spp);
    let mut tried = Vec::new();
    for spp in TRIED {
        let (noisy, _, render_s) = render(&frame, settings(SEED), spp);
        let (clean, denoise_s) = denoised(oidn, &noisy)?;
        tried.push((spp, Errors::of(&clean, &reference), render_s + denoise_s));
    }
    println!(
        "\n**{name}**, {}x{}, against {} spp: the fewest spp whose denoised frame shows an \
         error (MSE of the preview's values, 0-1) at most the undenoised frame's; relative \
         and plain MSE of the linear radiance beside\n\n| undenoised spp | display MSE \
         (relative, plain) | denoised spp | display MSE (relative, plain) | samples saved | \
         time saved (render + denoise) |\n|---:|---:|---:|---:|---:|---:|",
        args.size.0, args.size.1, args.reference_spp
    );
    for target in TARGETS.into_iter().filter(|&t| t < args.reference_spp) {
        let (noisy, _, target_s) = render(&frame, settings(SEED), target);
        let want = Errors::of(&noisy, &reference);
        match tried.iter().find(|t| t.1.display <= want.display) {
            Some((spp, got, seconds)) => println!(
                "| {target} | {want} | {spp} | {got} | {:.0}x | {:.1}x |",
                f64::from(target) / f64::from(*spp),
                target_s / seconds
            ),
            None => println!(
                "| {target} | {want} | more than {} | - | - | - |",
                TRIED[TRIED.len() - 1]
            ),
        }
    }
    Ok(())
}

/// A frame's errors against a reference.
#[derive(Clone, Copy)]
struct Errors {
    display: f64,
    relative: f64,
    plain: f64,
}

impl Errors {
    fn of(image: &Layers, reference: &Layers) -> Errors {
        Errors {
            display: display_mse(image, reference),
            relative: rel_mse(image, reference),
            plain: mse(image, reference),
        }
    }
}

impl std::fmt::Display for Errors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:.2e} ({:.2e}, {:.2e})",
            self.display, self.relative, self.plain
        )
    }
}

/// Flicker of `frames` against `converged` (the same frames denoised from many samples):
/// the mean absolute difference between their frame-to-frame changes, on the previews'
/// values (ACES filmic, sRGB, 0-255). The motion changes both alike; what noise changes
/// from frame to frame is left.
fn flicker_of(frames: &[Layers], converged: &[Layers]) -> f64 {
    let show = |v: glam::Vec4| v.truncate().to_array().map(|c| srgb_oetf(aces_filmic(c)));
    let mut total = 0.0;
    for (pair, truth) in frames.windows(2).zip(converged.windows(2)) {
        let pixels = pair[0].beauty.len();
        let sum: f64 = (0..pixels)
            .map(|i| {
                let (a0, a1) = (show(pair[0].beauty[i]), show(pair[1].beauty[i]));
                let (r0, r1) = (show(truth[0].beauty[i]), show(truth[1].beauty[i]));
                (0..3)
                    .map(|c| f64::from(((a1[c] - a0[c]) - (r1[c] - r0[c])).abs()))
                    .sum::<f64>()
                    / 3.0
            })
            .sum();
        total += sum / pixels as f64;
    }
    255.0 * total / (frames.len() - 1) as f64
}

/// The demo's frames 12 on, rendered at `spp` with `fixed_pattern`, denoised or not.
fn sequence(
    oidn: &post::Oidn,
    args: &DenoiseArgs,
    spp: u32,
    fixed_pattern: bool,
) -> anyhow::Result<(Vec<Layers>, Vec<Layers>)> {
    let scene = Arc::new(tracer::demo::animated_demo_scene());
    let (mut noisy, mut clean) = (Vec::new(), Vec::new());
    for f in 12..12 + args.frames as i32 {
        let options = FrameOptions {
            frame: f,
            width: args.size.0,
            height: args.size.1,
            shutter: Shutter {
                open: -0.25,
                close: 0.25,
            },
            ..FrameOptions::default()
        };
        let frame = prepare_frame(scene.clone(), &options)?;
        let s = RenderSettings {
            fixed_pattern,
            ..settings(SEED)
        };
        let (layers, _, _) = render(&frame, s, spp);
        clean.push(denoised(oidn, &layers)?.0);
        noisy.push(layers);
    }
    Ok((noisy, clean))
}

/// Flicker of the demo's frames (a still camera, the balls moving): how their changes from
/// frame to frame differ from those of the converged frames, noisy and denoised, with each
/// frame's own pattern and with a fixed one.
fn flicker(oidn: &post::Oidn, args: &DenoiseArgs) -> anyhow::Result<()> {
    eprintln!(
        "flicker: demo frames 12-{} at {} spp, and converged at {} spp ...",
        11 + args.frames,
        args.flicker_spp,
        args.converged_spp
    );
    let (_, converged) = sequence(oidn, args, args.converged_spp, false)?;
    println!(
        "\n**Flicker**: the demo's frames 12-{} ({}x{}, a still camera, the balls moving) \
         at {} spp: the mean difference between each frame-to-frame change and the \
         converged frames' ({} spp, denoised), in the previews' values (0-255)\n\n| pattern \
         | noisy | denoised |\n|---|---:|---:|",
        11 + args.frames,
        args.size.0,
        args.size.1,
        args.flicker_spp,
        args.converged_spp
    );
    for (name, fixed) in [("each frame its own", false), ("`--fixed-pattern`", true)] {
        let (noisy, clean) = sequence(oidn, args, args.flicker_spp, fixed)?;
        println!(
            "| {name} | {:.2} | {:.2} |",
            flicker_of(&noisy, &converged),
            flicker_of(&clean, &converged)
        );
    }
    Ok(())
}
