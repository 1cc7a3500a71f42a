//! `tessera bench spectral`: what the spectral path costs on a scene the RGB path renders
//! too (the measured Cornell box): camera paths per second of each path, and each one's
//! error against its own high-spp reference per spp, so that the colour noise of hero
//! wavelengths reads as a ratio of MSEs at equal samples and at equal time.

use std::sync::Arc;

use clap::Args;

use tracer::render::{prepare_frame, FrameOptions, PreparedFrame, RenderSettings};

use super::scenes::{mse, render};
use super::{REFERENCE_SEED, SEED};

#[derive(Args)]
pub struct SpectralArgs {
    /// Samples per pixel of the references.
    #[arg(long, default_value_t = 1024)]
    reference_spp: u32,
    /// Samples per pixel measured, each against the reference.
    #[arg(long, value_delimiter = ',', default_value = "4,16,64")]
    spp: Vec<u32>,
    /// Renders at each setting, each with its own seed: the MSE is their mean, the time
    /// the fastest's.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=20))]
    runs: u32,
    /// Image size a side (the box is square).
    #[arg(long, default_value_t = 128)]
    size: u32,
}

/// One path at one sample count.
struct Row {
    spp: u32,
    paths_per_second: f64,
    mse: f64,
}

/// Renders the box on both paths and prints the table.
pub fn run(args: SpectralArgs) -> anyhow::Result<()> {
    if args.spp.iter().any(|&s| s == 0 || s > args.reference_spp) {
        anyhow::bail!(
            "--spp: each must be 1..=--reference-spp ({})",
            args.reference_spp
        );
    }
    let options = FrameOptions {
        width: args.size,
        height: args.size,
        ..Default::default()
    };
    let frame = prepare_frame(Arc::new(tracer::demo::cornell_box()), &options)?;
    let rgb = measure(&frame, false, &args)?;
    let spectral = measure(&frame, true, &args)?;
    println!(
        "\n### The spectral path against the RGB path: Cornell box, {0}x{0}, max depth 8\n\n\
         Each against its own {1}-spp reference; MSE the mean of {2} renders with their own \
         seeds, paths per second the fastest's.\n\n\
         | spp | RGB paths/s | spectral paths/s | RGB MSE | spectral MSE | MSE ratio | \
         MSE x seconds ratio |\n|---:|---:|---:|---:|---:|---:|---:|",
        args.size, args.reference_spp, args.runs
    );
    for (r, s) in rgb.iter().zip(&spectral) {
        let ratio = s.mse / r.mse;
        println!(
            "| {} | {:.3} M | {:.3} M | {:.3e} | {:.3e} | {:.2} | {:.2} |",
            r.spp,
            r.paths_per_second / 1e6,
            s.paths_per_second / 1e6,
            r.mse,
            s.mse,
            ratio,
            ratio * r.paths_per_second / s.paths_per_second
        );
    }
    Ok(())
}

/// Each sample count of `args` on one path, against that path's reference.
fn measure(frame: &PreparedFrame, spectral: bool, args: &SpectralArgs) -> anyhow::Result<Vec<Row>> {
    let settings = RenderSettings {
        max_depth: 8,
        seed: REFERENCE_SEED,
        spectral,
        ..RenderSettings::DEFAULT
    };
    let path = if spectral { "spectral" } else { "RGB" };
    eprintln!("{path} path: reference at {} spp ...", args.reference_spp);
    let (reference, _, _) = render(frame, settings, args.reference_spp);
    let pixels = f64::from(frame.width * frame.height);
    Ok(args
        .spp
        .iter()
        .map(|&spp| {
            let (mut seconds, mut total) = (f64::INFINITY, 0.0);
            for seed in (SEED..).take(args.runs as usize) {
                let (image, _, s) = render(frame, RenderSettings { seed, ..settings }, spp);
                seconds = seconds.min(s);
                total += mse(&image, &reference);
            }
            Row {
                spp,
                paths_per_second: pixels * f64::from(spp) / seconds,
                mse: total / f64::from(args.runs),
            }
        })
        .collect())
}
