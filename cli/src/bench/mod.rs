//! `tessera bench`: what the tracer costs and what each setting buys, on the reference
//! scenes (or any one scene). Every figure goes into a report: markdown (the form of
//! BENCHMARKS.md) on stdout and in `DIR/report.md`, and the same as JSON in
//! `DIR/report.json`, with a figure of error against time per scene in `DIR/plots/`.
//!
//! Errors are measured against a reference of the same scene rendered with many more
//! samples, another seed and the deepest preset's bounces, so no setting is measured
//! against light the reference lacks or against its own samples.
//!
//! Sections that run alone, one file each: `farm`, `overhead` (scaling.rs), `cornell`,
//! `rays`, `features`, `spectral`, `denoise`, `clamp`.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, Subcommand};
use serde::Serialize;

use tracer::render::FrameOptions;

use crate::args::parse_size;
use crate::render::load_scene;
use cornell::{cornell_efficiency, cornell_section, CornellArgs, CornellEfficiency};
use features::FeatureCost;
use rays::BigMesh;
use scaling::{FarmCosts, Work};

pub mod clamp;
pub mod cornell;
pub mod denoise;
#[cfg(feature = "embree")]
mod embree;
pub mod farm;
pub mod features;
mod plots;
pub mod rays;
pub mod scaling;
mod scenes;
pub mod spectral;

use scenes::{measure_scene, reference_subjects, Subject};
pub use scenes::{Point, SceneReport};

#[derive(Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct BenchArgs {
    /// Another benchmark instead of the tracer's.
    #[command(subcommand)]
    pub command: Option<BenchCommand>,
    /// Scene to measure; the three reference scenes when left out.
    scene: Option<PathBuf>,
    /// Image size for the measurements [default: 64x64; 32x32 with --quick].
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Samples per pixel of the reference images [default: 4096; 512 with --quick].
    #[arg(long)]
    reference_spp: Option<u32>,
    /// Smaller images, references and sweeps: the whole report in under two minutes.
    #[arg(long)]
    quick: bool,
    /// Where report.md and report.json go.
    #[arg(long, default_value = "bench-report")]
    out: PathBuf,
}

/// The benchmarks other than the tracer's.
#[derive(Subcommand)]
pub enum BenchCommand {
    /// Load-test the farm server: simulated workers long-poll for empty tasks; tasks per
    /// second, lease latency and server memory, and nothing lost or done twice.
    Farm(crate::bench::farm::FarmBenchArgs),
    /// The farm against a direct render of the same frames on this machine: one worker
    /// with every thread, then 1, 2 and 4 single-thread workers (the report's farm table).
    Overhead(scaling::OverheadArgs),
    /// The efficiency target's measurement alone: the measured Cornell box at 256x256,
    /// depth 8, in camera paths per second and MSE x seconds (the report's Cornell section).
    Cornell(CornellArgs),
    /// Closest-hit and any-hit rays per second through the BVH of one mesh on one thread,
    /// and beside native Embree's on the same rays with `--embree`.
    Rays(rays::RaysArgs),
    /// What each scene feature costs (the report's feature table alone): camera paths per
    /// second of the demo without and with it, the fastest of several runs taken in turn.
    Features(features::FeaturesArgs),
    /// The spectral path against the RGB path on the measured Cornell box: paths per
    /// second, and each one's MSE against its own reference per spp (the colour noise of
    /// hero wavelengths).
    Spectral(spectral::SpectralArgs),
    /// What Open Image Denoise buys: its time per megapixel, the spp a denoised frame
    /// needs to match an undenoised 256- or 1024-spp frame, and the flicker of denoised
    /// animation with and without the same sampling pattern on every frame.
    Denoise(denoise::DenoiseArgs),
    /// What `--clamp-indirect` buys on the demo: for each limit, the light it keeps (its
    /// bias), the noise left at the demo's 16 spp, and both before and after denoising.
    Clamp(clamp::ClampArgs),
}

/// The generated mesh is a grid of this many quads a side: 1,002,528 triangles.
const BIG_MESH_SIDE: usize = 708;
/// The RMSE at which "time to reach an error" is read off each sweep.
const TARGET_RMSE: f64 = 0.05;
/// The bounces of the sweeps (the tracer's default).
const SWEEP_DEPTH: u32 = 8;
/// The Russian-roulette sweep's "never": from a bounce past [`SWEEP_DEPTH`].
pub(crate) const RR_NEVER: u32 = SWEEP_DEPTH + 1;
/// The head of the Russian-roulette table's first column.
const RR_HEAD: &str = "RR from bounce";
/// Seed of everything measured; the references use another.
const SEED: u32 = 1;
const REFERENCE_SEED: u32 = 0;

/// Everything one run measured; `report.json` is this.
#[derive(Serialize)]
pub struct Report {
    /// The machine it ran on.
    pub machine: Machine,
    /// The command line that reproduces it.
    pub command: String,
    /// One per scene measured.
    pub scenes: Vec<SceneReport>,
    /// The efficiency comparison on the measured Cornell box (reference scenes only).
    pub cornell: Option<CornellEfficiency>,
    /// The generated mesh of a million triangles (reference scenes only).
    pub big_mesh: Option<BigMesh>,
    /// What each scene feature costs (reference scenes only).
    pub features: Vec<FeatureCost>,
    /// The farm against direct renders (reference scenes only).
    pub farm: Option<FarmCosts>,
}

/// What ran the benchmark.
#[derive(Serialize)]
pub struct Machine {
    /// CPU model, from `/proc/cpuinfo` where there is one.
    pub cpu: String,
    /// Threads the tracer used.
    pub threads: usize,
    /// Operating system and architecture.
    pub os: String,
    /// Tessera's version.
    pub version: String,
}

fn machine() -> Machine {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|info| {
            info.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into());
    Machine {
        cpu,
        threads: rayon::current_num_threads(),
        os: format!("{} {}", std::env::consts::OS, std::env::consts::ARCH),
        version: env!("CARGO_PKG_VERSION").into(),
    }
}

pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    let size = args
        .size
        .unwrap_or(if args.quick { (32, 32) } else { (64, 64) });
    let reference_spp = args
        .reference_spp
        .unwrap_or(if args.quick { 512 } else { 4096 });
    let subjects = match &args.scene {
        Some(path) => vec![Subject {
            name: path.display().to_string(),
            description: "a scene given on the command line".into(),
            scene: load_scene(Some(path), tracer::demo::demo_scene)?,
            options: FrameOptions {
                width: size.0,
                height: size.1,
                ..Default::default()
            },
        }],
        None => reference_subjects(size),
    };
    let scenes = subjects
        .into_iter()
        .map(|s| measure_scene(s, reference_spp, args.quick))
        .collect::<anyhow::Result<_>>()?;
    let (cornell, big_mesh, features, farm) = match args.scene {
        None => {
            let cornell = cornell_efficiency(args.quick, 5)?;
            eprintln!("a generated mesh of 1M triangles ...");
            let mesh = rays::big_mesh(BIG_MESH_SIDE)?;
            eprintln!("feature costs ...");
            let spp = if args.quick { 8 } else { 32 };
            let features = features::feature_costs(size, spp, if args.quick { 1 } else { 2 })?;
            // The full report takes the fastest of two runs of each: a shared machine's
            // speed drifts by more than the farm's overhead.
            let farm = scaling::farm_costs(
                Work::for_report(args.quick),
                rayon::current_num_threads() as u32,
                if args.quick { 1 } else { 2 },
            )?;
            (Some(cornell), Some(mesh), features, Some(farm))
        }
        Some(_) => (None, None, Vec::new(), None),
    };
    let report = Report {
        machine: machine(),
        command: std::env::args()
            .collect::<Vec<_>>()
            .join(" ")
            .replace(&std::env::args().next().unwrap_or_default(), "tessera"),
        scenes,
        cornell,
        big_mesh,
        features,
        farm,
    };
    let markdown = markdown(&report);
    print!("{markdown}");
    write_report(&args.out, &report, &markdown)?;
    let plots = plots::write(&args.out, &report.scenes)?;
    eprintln!(
        "{} plots written to {}",
        plots.len(),
        args.out.join("plots").display()
    );
    Ok(())
}

fn write_report(dir: &Path, report: &Report, markdown: &str) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    std::fs::write(dir.join("report.md"), markdown)?;
    std::fs::write(
        dir.join("report.json"),
        serde_json::to_string_pretty(report)? + "\n",
    )?;
    eprintln!(
        "report written to {} (report.md, report.json)",
        dir.display()
    );
    Ok(())
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

/// The report as markdown: the machine, then each scene's tables.
pub fn markdown(r: &Report) -> String {
    let m = &r.machine;
    let mut out = format!(
        "Machine: {}, {} threads, {}; tessera {}.\nCommand: `{}`\n",
        m.cpu, m.threads, m.os, m.version, r.command
    );
    if let Some(c) = &r.cornell {
        out += &cornell_section(c);
    }
    if let Some(b) = &r.big_mesh {
        out += &format!(
            "\n### A generated mesh of {} triangles\n\n\
             BVH build {:.2} s on 1 thread, {:.2} s on all; {:.1} bytes per triangle.\n\n{}",
            b.triangles,
            b.build_seconds_one_thread,
            b.build_seconds_all_threads,
            b.bytes_per_triangle,
            rays::table(&b.rays)
        );
    }
    if let Some(f) = &r.farm {
        out += &format!(
            "\n### The farm against a direct render\n\nThe animated demo's frames 1-{} at \
             {}x{}, {} spp, motion blur, in the server's default tiles: a server and worker \
             processes on this machine (from the job's creation to its end) against `tessera \
             render` of the same scene file and frames with as many threads (from its start to \
             its exit); both load the scene and write each frame's EXR and PNG. The fastest of \
             {} run(s) of each, taken in turn:\n\n{}",
            f.work.frames,
            f.work.width,
            f.work.height,
            f.work.spp,
            f.repeats,
            scaling::table(f)
        );
    }
    if !r.features.is_empty() {
        out += &format!(
            "\n### What each feature costs\n\nCamera paths per second of the same scene \
             without a feature and with it ({}x{}):\n\n{}",
            r.scenes.first().map_or(0, |s| s.width),
            r.scenes.first().map_or(0, |s| s.height),
            features::table(&r.features)
        );
    }
    for s in &r.scenes {
        out += &format!(
            "\n### {} ({}x{})\n\n{}. Reference: {} spp at depth {} ({:.1} s).\n\n\
             {:.3} M paths/s and {:.2} M rays/s of all kinds at 16 spp, depth \
             {SWEEP_DEPTH}. RMSE {TARGET_RMSE} is reached in {} s.\n\n{}",
            s.name,
            s.width,
            s.height,
            s.description,
            s.reference_spp,
            s.reference_depth,
            s.reference_seconds,
            s.paths_per_second / 1e6,
            s.rays_per_second / 1e6,
            opt(s.seconds_to_target, 3),
            rays::table(&s.rays),
        );
        out += &format!(
            "\n![{}: error against time for each sweep]({})\n",
            s.name,
            plots::plot_path(&s.name)
        );
        let table = |out: &mut String, title: &str, head: &str, points: &[Point]| {
            let value = |v: u32| match head {
                RR_HEAD if v == RR_NEVER => "never".to_string(),
                _ => v.to_string(),
            };
            if points.is_empty() {
                return;
            }
            *out += &format!(
                "\n{title}\n\n| {head} | time (s) | RMSE | relMSE | RMSE x sqrt(time) |\n\
                 |---:|---:|---:|---:|---:|\n"
            );
            for p in points {
                *out += &format!(
                    "| {} | {:.3} | {:.5} | {:.5} | {:.5} |\n",
                    value(p.value),
                    p.seconds,
                    p.rmse,
                    p.rel_mse,
                    p.rmse * p.seconds.sqrt()
                );
            }
        };
        table(
            &mut out,
            &format!("Samples per pixel (depth {SWEEP_DEPTH}):"),
            "spp",
            &s.spp_sweep,
        );
        table(
            &mut out,
            &format!(
                "Maximum depth ({} spp; the reference's depth is {}):",
                s.fixed_spp, s.reference_depth
            ),
            "max depth",
            &s.depth_sweep,
        );
        table(
            &mut out,
            &format!(
                "Russian roulette ({} spp, depth {SWEEP_DEPTH}; the tracer's default plays it \
                 from bounce 3): a path ends early with probability 1 - throughput, so it \
                 trades noise for time, and RMSE x sqrt(time) tells which wins:",
                s.fixed_spp
            ),
            RR_HEAD,
            &s.rr_sweep,
        );
        out += &format!(
            "\nClamping indirect light (`--clamp-indirect`, {} spp, depth {SWEEP_DEPTH}): the \
             light each limit keeps and the bias it leaves (its image at {} spp against the \
             reference), the noise left (against that image) and both together:\n\n{}",
            s.fixed_spp,
            s.clamp_converged_spp,
            clamp::table(&s.clamp_sweep, s.fixed_spp, s.clamp_converged_spp)
        );
        table(
            &mut out,
            &format!(
                "Motion steps ({} spp; error against 64 steps at the same seed and spp: the \
                 blur's interpolation more than noise):",
                s.fixed_spp
            ),
            "steps",
            &s.motion_sweep,
        );
        out += "\nQuality presets (`--quality`; adaptive sampling stops each pixel at its \
                threshold):\n\n\
                | preset | max spp | max depth | threshold | time (s) | mean spp | \
                estimated error | RMSE |\n|---|---:|---:|---:|---:|---:|---:|---:|\n";
        for p in &s.presets {
            out += &format!(
                "| {} | {} | {} | {} | {:.3} | {:.1} | {} | {:.5} |\n",
                p.preset,
                p.max_spp,
                p.max_depth,
                p.threshold,
                p.seconds,
                p.mean_spp,
                opt(p.estimated_error, 4),
                p.rmse
            );
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::scenes::{mse, rel_mse, seconds_to_reach, share_of_worst_pixels};
    use super::*;
    use tracer::film::{Layers, TileRect};

    /// One pixel in a thousand off by 30 and the rest by 1 (each of three channels): that
    /// pixel holds 900 / (900 + 999) of the squared error, and the MSE is their mean.
    #[test]
    fn the_worst_pixels_share_of_the_error() {
        let reference = Layers::new(TileRect::new(0, 0, 100, 10));
        let mut image = reference.clone();
        for (i, b) in image.beauty.iter_mut().enumerate() {
            let off = if i == 437 { 30.0 } else { 1.0 };
            *b = glam::Vec4::new(off, off, off, 1.0);
        }
        let share = share_of_worst_pixels(&image, &reference, 0.001);
        assert!((share - 900.0 / 1899.0).abs() < 1e-12, "{share}");
        assert_eq!(share_of_worst_pixels(&reference, &reference, 0.001), 0.0);
        assert!((mse(&image, &reference) - 1899.0 / 1000.0).abs() < 1e-12);
    }

    fn p(value: u32, seconds: f64, rmse: f64) -> Point {
        Point {
            value,
            seconds,
            rmse,
            rel_mse: 0.0,
        }
    }

    #[test]
    fn the_time_to_an_error_is_read_log_log_between_its_neighbours() {
        let sweep = [p(1, 1.0, 0.4), p(4, 4.0, 0.2), p(16, 16.0, 0.1)];
        // RMSE halves as time quadruples: 0.141 is half-way in log, at 8 s.
        let t = seconds_to_reach(&sweep, 0.2 / 2f64.sqrt()).unwrap();
        assert!((t - 8.0).abs() < 1e-9, "{t}");
        assert_eq!(seconds_to_reach(&sweep, 0.5), Some(1.0));
        assert_eq!(seconds_to_reach(&sweep, 0.05), None);
    }

    /// The report of a tiny motion-blurred scene: every sweep is there, errors fall with
    /// samples and with motion steps, and it reads as markdown and JSON.
    #[test]
    fn a_scene_report_has_every_sweep_and_serialises() {
        let subject = reference_subjects((8, 8)).pop().unwrap();
        let s = measure_scene(subject, 64, true).unwrap();
        assert_eq!(s.spp_sweep.len(), 4);
        assert_eq!(s.depth_sweep.len(), 6);
        assert_eq!(s.rr_sweep.len(), 5);
        assert_eq!(s.clamp_sweep.len(), clamp::LIMITS.len());
        assert_eq!(s.motion_sweep.len(), 6);
        assert_eq!(s.presets.len(), 3);
        let first = s.spp_sweep[0].rmse;
        let last = s.spp_sweep.last().unwrap().rmse;
        assert!(last < first / 2.0, "{first} -> {last}");
        let steps = &s.motion_sweep;
        assert!(steps.last().unwrap().rmse < steps[0].rmse, "motion steps");
        let report = Report {
            machine: machine(),
            command: "tessera bench".into(),
            scenes: vec![s],
            cornell: None,
            big_mesh: None,
            features: Vec::new(),
            farm: None,
        };
        let text = markdown(&report);
        assert!(text.contains("### motion-blur (8x8)"), "{text}");
        assert!(text.contains("| final | 1024 | 12 | 0.01 |"), "{text}");
        assert!(text.contains("| never | "), "{text}");
        assert!(text.contains("| 0.25 | "), "{text}");
        let json: serde_json::Value = serde_json::to_value(&report).unwrap();
        assert_eq!(json["scenes"][0]["spp_sweep"][3]["value"], 64);
        assert!(text
            .contains("![motion-blur: error against time for each sweep](plots/motion-blur.png)"));

        // Its figure: four panels of labelled points and lines on white.
        let dir = tempfile::tempdir().unwrap();
        let written = plots::write(dir.path(), &report.scenes).unwrap();
        assert_eq!(written, vec![dir.path().join("plots/motion-blur.png")]);
        let png = image::open(&written[0]).unwrap().to_rgb8();
        assert_eq!(png.dimensions(), (plots::WIDTH, plots::HEIGHT));
        let count = |f: &dyn Fn(&image::Rgb<u8>) -> bool| png.pixels().filter(|p| f(p)).count();
        let white = count(&|p| p.0 == [255, 255, 255]);
        let blue = count(&|p| p.0[2] > 200 && p.0[0] < 80 && p.0[1] < 80);
        let red = count(&|p| p.0[0] > 200 && p.0[1] < 80 && p.0[2] < 80);
        let dark = count(&|p| p.0.iter().all(|&c| c < 100));
        let area = (plots::WIDTH * plots::HEIGHT) as usize;
        assert!(white > area / 2, "{white} white pixels");
        // The four sweeps' lines and markers, the presets' markers, axes and text.
        assert!(blue > 1000, "{blue} blue pixels");
        assert!(red > 50, "{red} red pixels");
        assert!(dark > 5000, "{dark} dark pixels");
    }

    #[test]
    fn errors_compare_the_beauty_only() {
        let rect = TileRect::new(0, 0, 2, 1);
        let mut a = Layers::new(rect);
        let b = Layers::new(rect);
        a.beauty[0] = glam::Vec4::new(0.3, 0.3, 0.3, 1.0);
        a.albedo[1] = glam::Vec3::ONE;
        assert!((mse(&a, &b) - 0.045).abs() < 1e-7);
        assert!((rel_mse(&a, &b) - 0.09 / 0.01 / 2.0).abs() < 1e-6);
    }
}
