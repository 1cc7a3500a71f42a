//! `tessera bench cornell` and the report's Cornell section: the efficiency target's
//! measurement, the measured Cornell box at 256x256 and max depth 8 in camera paths per
//! second and MSE x seconds against a reference.

use std::sync::Arc;

use clap::Args;
use serde::Serialize;

use tracer::render::{prepare_frame, FrameOptions, RenderSettings};

use super::scenes::{mse, render, share_of_worst_pixels};
use super::{REFERENCE_SEED, SEED};

#[derive(Args)]
pub struct CornellArgs {
    /// 4 spp against a 64-spp reference instead of 16 against 1024.
    #[arg(long)]
    pub quick: bool,
    /// Renders measured, each with its own seed: the MSE is their mean, the time the
    /// fastest's.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=20))]
    pub runs: u32,
}

/// Runs the Cornell box's efficiency measurement and prints the report's section.
pub fn run_cornell(args: CornellArgs) -> anyhow::Result<()> {
    print!(
        "{}",
        cornell_section(&cornell_efficiency(args.quick, args.runs)?)
    );
    Ok(())
}

/// The measured Cornell box at the comparison's setup: 256x256, max depth 8.
#[derive(Serialize)]
pub struct CornellEfficiency {
    /// Samples per pixel of the measured render.
    pub spp: u32,
    /// Samples per pixel of its reference.
    pub reference_spp: u32,
    /// Renders measured, each with its own seed; the time is the fastest's.
    pub runs: u32,
    /// Camera paths per second.
    pub paths_per_second: f64,
    /// Mean squared error of the beauty RGB, the mean over the renders.
    pub mse: f64,
    /// The standard error of that mean (0 for one render).
    pub mse_standard_error: f64,
    /// MSE times seconds: lower is more efficient.
    pub mse_times_seconds: f64,
    /// The share of the first render's squared error in its worst 0.1% of pixels: near 1
    /// when a few pixels (fireflies, an edge) decide the MSE.
    pub worst_pixels_share: f64,
}

/// The measured Cornell box at 256x256 and max depth 8, as the efficiency target states
/// it: camera paths per second, and MSE × seconds against a reference. Each of `runs`
/// renders has a seed of its own, since one render's MSE moves by about 8% from seed to
/// seed (a few pixels on the lamp's edges hold much of it): the MSE is their mean. The
/// time is the fastest render's, which a busy neighbour on a shared machine disturbs
/// least.
pub(super) fn cornell_efficiency(quick: bool, runs: u32) -> anyhow::Result<CornellEfficiency> {
    let (spp, reference_spp) = if quick { (4, 64) } else { (16, 1024) };
    let options = FrameOptions {
        width: 256,
        height: 256,
        ..Default::default()
    };
    let frame = prepare_frame(Arc::new(tracer::demo::cornell_box()), &options)?;
    let settings = RenderSettings {
        max_depth: 8,
        seed: REFERENCE_SEED,
        ..RenderSettings::DEFAULT
    };
    eprintln!("cornell 256x256: reference at {reference_spp} spp ...");
    let (reference, _, _) = render(&frame, settings, reference_spp);
    let mut seconds = f64::INFINITY;
    let mut errors = Vec::new();
    let mut worst_pixels_share = 0.0;
    for seed in (SEED..).take(runs as usize) {
        let (image, _, s) = render(&frame, RenderSettings { seed, ..settings }, spp);
        seconds = seconds.min(s);
        errors.push(mse(&image, &reference));
        if seed == SEED {
            worst_pixels_share = share_of_worst_pixels(&image, &reference, 0.001);
        }
    }
    let n = errors.len() as f64;
    let mse = errors.iter().sum::<f64>() / n;
    let variance = errors.iter().map(|e| (e - mse).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    Ok(CornellEfficiency {
        spp,
        reference_spp,
        runs,
        paths_per_second: 256.0 * 256.0 * f64::from(spp) / seconds,
        mse,
        mse_standard_error: (variance / n).sqrt(),
        mse_times_seconds: mse * seconds,
        worst_pixels_share,
    })
}

/// The report's section on the efficiency target.
pub(super) fn cornell_section(c: &CornellEfficiency) -> String {
    format!(
        "\n### Cornell box, 256x256, max depth 8\n\n\
         {:.3} M camera paths/s at {} spp (the fastest of {} renders, each with its own \
         seed); MSE {:.3e} (their mean; standard error {:.1e}) against {} spp; MSE x seconds \
         {:.3e}. The worst 0.1% of pixels hold {:.0}% of the first render's squared error.\n",
        c.paths_per_second / 1e6,
        c.spp,
        c.runs,
        c.mse,
        c.mse_standard_error,
        c.reference_spp,
        c.mse_times_seconds,
        100.0 * c.worst_pixels_share
    )
}
