//! The clamp on indirect light (`--clamp-indirect`): for each limit, the light it takes
//! away (its bias) and the noise it takes with it. In every scene section of the report,
//! and alone on the demo as `tessera bench clamp`, where it also measures what the
//! denoiser makes of each.

use clap::Args;
use serde::Serialize;

use tracer::film::Layers;
use tracer::render::{PreparedFrame, RenderSettings};

use super::denoise::{demo_frame, denoised};
use super::scenes::{display_mse, render, rmse};
use super::{REFERENCE_SEED, SEED, SWEEP_DEPTH};
use crate::args::parse_size;

/// The limits measured, from none to a harsh one.
pub(super) const LIMITS: [Option<f32>; 5] = [None, Some(16.0), Some(4.0), Some(1.0), Some(0.25)];

/// One limit: what it costs in light and what it saves in noise.
#[derive(Clone, Copy, Serialize)]
pub struct ClampPoint {
    /// The limit (`None`: no clamp).
    pub clamp: Option<f32>,
    /// Wall seconds of the noisy render.
    pub seconds: f64,
    /// The clamped converged image's light over the reference's (1: nothing lost).
    pub light_kept: f64,
    /// RMSE of the clamped converged image against the reference: the bias.
    pub bias_rmse: f64,
    /// RMSE of the noisy image against the clamped converged one: the noise left.
    pub noise_rmse: f64,
    /// RMSE of the noisy image against the reference: both together.
    pub rmse: f64,
    /// MSE of the noisy image's preview values (0-1) against the reference's: what a
    /// viewer sees.
    pub display_mse: f64,
    /// The same of the noisy image denoised, where the denoiser was measured.
    pub denoised_display_mse: Option<f64>,
}

/// Measures every limit of [`LIMITS`] on `frame` at `settings`: noisy images at `spp`,
/// converged ones at `converged_spp` (the same seed), against the unclamped `reference`;
/// with `oidn`, the noisy images denoised too.
pub(super) fn clamp_sweep(
    frame: &PreparedFrame,
    settings: RenderSettings,
    reference: &Layers,
    spp: u32,
    converged_spp: u32,
    oidn: Option<&post::Oidn>,
) -> anyhow::Result<Vec<ClampPoint>> {
    let light = |l: &Layers| -> f64 {
        l.beauty
            .iter()
            .map(|b| f64::from(b.truncate().element_sum()))
            .sum()
    };
    LIMITS
        .into_iter()
        .map(|clamp| {
            let clamped = RenderSettings {
                clamp_indirect: clamp,
                ..settings
            };
            let (converged, _, _) = render(frame, clamped, converged_spp);
            let (noisy, _, seconds) = render(frame, clamped, spp);
            let denoised_display_mse = match oidn {
                Some(oidn) => Some(display_mse(&denoised(oidn, &noisy)?.0, reference)),
                None => None,
            };
            Ok(ClampPoint {
                clamp,
                seconds,
                light_kept: light(&converged) / light(reference),
                bias_rmse: rmse(&converged, reference),
                noise_rmse: rmse(&noisy, &converged),
                rmse: rmse(&noisy, reference),
                display_mse: display_mse(&noisy, reference),
                denoised_display_mse,
            })
        })
        .collect()
}

/// The sweep as a markdown table (the denoised column where it was measured).
pub(super) fn table(points: &[ClampPoint], spp: u32, converged_spp: u32) -> String {
    let denoised = points.iter().any(|p| p.denoised_display_mse.is_some());
    let mut out = format!(
        "| clamp | light kept | bias RMSE ({converged_spp} spp) | noise RMSE ({spp} spp) | \
         RMSE | display MSE |{}\n|---|---:|---:|---:|---:|---:|{}\n",
        if denoised {
            " denoised display MSE |"
        } else {
            ""
        },
        if denoised { "---:|" } else { "" },
    );
    for p in points {
        out += &format!(
            "| {} | {:.2}% | {:.5} | {:.5} | {:.5} | {:.2e} |{}\n",
            p.clamp.map_or("off".to_string(), |c| c.to_string()),
            p.light_kept * 100.0,
            p.bias_rmse,
            p.noise_rmse,
            p.rmse,
            p.display_mse,
            p.denoised_display_mse
                .map_or(String::new(), |d| format!(" {d:.2e} |")),
        );
    }
    out
}

#[derive(Args)]
pub struct ClampArgs {
    /// Frame size.
    #[arg(long, default_value = "128x96", value_parser = parse_size)]
    size: (u32, u32),
    /// Samples per pixel of the noisy frames (the demo's).
    #[arg(long, default_value_t = 16)]
    spp: u32,
    /// Samples per pixel of the clamped converged frames, which measure the bias.
    #[arg(long, default_value_t = 1024)]
    converged_spp: u32,
    /// Samples per pixel of the unclamped reference.
    #[arg(long, default_value_t = 4096)]
    reference_spp: u32,
    /// Where Open Image Denoise is installed (default: where `tessera install oidn` puts
    /// it); without it, the denoised column is left out.
    #[arg(long, env = "TESSERA_OIDN", value_name = "DIR")]
    oidn: Option<std::path::PathBuf>,
}

/// `tessera bench clamp`: the sweep on the frame `tessera demo` shows first (the animated
/// demo at frame 12, its shutter), denoised too where Open Image Denoise is installed.
pub fn run(args: ClampArgs) -> anyhow::Result<()> {
    let oidn = match post::Oidn::load(args.oidn.as_deref()) {
        Ok(oidn) => Some(oidn),
        Err(e) => {
            eprintln!("NOTE: no denoised column: {e}");
            None
        }
    };
    let frame = demo_frame(tracer::demo::animated_demo_scene(), 12, 0.25, args.size)?;
    let settings = RenderSettings {
        max_depth: SWEEP_DEPTH,
        seed: SEED,
        ..RenderSettings::DEFAULT
    };
    eprintln!("reference at {} spp ...", args.reference_spp);
    let (reference, _, _) = render(
        &frame,
        RenderSettings {
            seed: REFERENCE_SEED,
            ..settings
        },
        args.reference_spp,
    );
    let points = clamp_sweep(
        &frame,
        settings,
        &reference,
        args.spp,
        args.converged_spp,
        oidn.as_ref(),
    )?;
    println!(
        "\n### Clamping indirect light (`--clamp-indirect`)\n\nThe demo at frame 12 ({}x{}, \
         its shutter, depth {SWEEP_DEPTH}) against an unclamped {}-spp reference: the light \
         each limit keeps and the bias it leaves (its converged image against the reference), \
         the noise left at {} spp (against its own converged image), both together, and what \
         the previews show (MSE of their 0-1 values{})\n\n{}",
        args.size.0,
        args.size.1,
        args.reference_spp,
        args.spp,
        if oidn.is_some() {
            ", before and after Open Image Denoise"
        } else {
            ""
        },
        table(&points, args.spp, args.converged_spp)
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use tracer::render::{prepare_frame, FrameOptions};

    use super::*;

    /// On a small demo frame: clamping keeps less light the lower the limit, never more
    /// than all of it, and takes noise away.
    #[test]
    fn lower_limits_keep_less_light_and_less_noise() {
        let options = FrameOptions {
            width: 24,
            height: 18,
            ..FrameOptions::default()
        };
        let frame = prepare_frame(Arc::new(tracer::demo::demo_scene()), &options).unwrap();
        let settings = RenderSettings {
            seed: SEED,
            ..RenderSettings::DEFAULT
        };
        let (reference, _, _) = render(&frame, settings, 256);
        let points = clamp_sweep(&frame, settings, &reference, 8, 256, None).unwrap();
        let kept: Vec<f64> = points.iter().map(|p| p.light_kept).collect();
        assert!(kept.windows(2).all(|w| w[1] <= w[0]), "{kept:?}");
        assert_eq!(
            kept[0], 1.0,
            "unclamped, the same seed and spp as the reference"
        );
        assert!(kept[4] < kept[0]);
        let (off, harsh) = (points[0], points[4]);
        assert!(harsh.noise_rmse < off.noise_rmse);
        let text = table(&points, 8, 256);
        assert!(text.contains("| off | 100.00% | 0.00000 |"), "{text}");
        assert!(text.contains("| 0.25 | "), "{text}");
    }
}
