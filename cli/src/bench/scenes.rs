//! The report's per-scene sections: each reference scene (or the scene given) measured
//! against its own high-sample reference: ray rates, paths per second, and error against
//! time for samples per pixel, depth, Russian roulette, motion steps and the quality
//! presets.

use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;

use proto::job::Quality;
use tracer::film::{Layers, SampleRange, TileRect};
use tracer::motion::Shutter;
use tracer::output::{aces_filmic, srgb_oetf};
use tracer::render::{
    prepare_frame, render_region, FrameOptions, NoiseTarget, PreparedFrame, RenderSettings,
};
use tracer::scene::Scene;

use super::clamp::{clamp_sweep, ClampPoint};
use super::rays::{self, RayRate};
use super::{REFERENCE_SEED, RR_NEVER, SEED, SWEEP_DEPTH, TARGET_RMSE};

/// The figures of one scene.
#[derive(Serialize)]
pub struct SceneReport {
    /// Its name.
    pub name: String,
    /// What it holds, in words.
    pub description: String,
    /// Image size.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Reference samples per pixel.
    pub reference_spp: u32,
    /// Reference bounces.
    pub reference_depth: u32,
    /// Seconds the reference took.
    pub reference_seconds: f64,
    /// Camera, shadow and bounce rays per second.
    pub rays: Vec<RayRate>,
    /// Camera paths per second at 16 spp and the sweep's depth.
    pub paths_per_second: f64,
    /// Rays of every kind per second over those paths.
    pub rays_per_second: f64,
    /// Samples per pixel against time and error.
    pub spp_sweep: Vec<Point>,
    /// Seconds to reach an RMSE of [`TARGET_RMSE`], read off the spp sweep (log-log
    /// between the two points around it); absent if the sweep never got there.
    pub seconds_to_target: Option<f64>,
    /// The spp of the depth and motion sweeps.
    pub fixed_spp: u32,
    /// Bounces against time and error, at `fixed_spp`.
    pub depth_sweep: Vec<Point>,
    /// The first bounce at which Russian roulette may end a path against time and error,
    /// at `fixed_spp` and the sweep's depth; [`RR_NEVER`] never plays it.
    pub rr_sweep: Vec<Point>,
    /// The clamp on indirect light against its bias and noise, at `fixed_spp`.
    pub clamp_sweep: Vec<ClampPoint>,
    /// The spp of the clamped images that measure the clamp's bias.
    pub clamp_converged_spp: u32,
    /// Motion steps against blur error, where the scene moves.
    pub motion_sweep: Vec<Point>,
    /// The quality presets.
    pub presets: Vec<PresetPoint>,
}

/// One setting: its time and its error.
#[derive(Clone, Copy, Serialize)]
pub struct Point {
    /// The setting (spp, max depth, Russian roulette's first bounce or motion steps).
    pub value: u32,
    /// Wall seconds.
    pub seconds: f64,
    /// Root-mean-square error of the beauty RGB.
    pub rmse: f64,
    /// Mean of (x - r)² / (r² + 0.01), per channel (pbrt's relative MSE).
    pub rel_mse: f64,
}

/// One quality preset.
#[derive(Serialize)]
pub struct PresetPoint {
    /// Its name.
    pub preset: String,
    /// Its settings.
    pub max_spp: u32,
    /// Bounces.
    pub max_depth: u32,
    /// Noise threshold.
    pub threshold: f64,
    /// Wall seconds.
    pub seconds: f64,
    /// Mean samples per pixel reached.
    pub mean_spp: f64,
    /// Mean estimated error.
    pub estimated_error: Option<f64>,
    /// Measured RMSE.
    pub rmse: f64,
}

/// Root-mean-square error of the beauty RGB of `a` against `reference`.
pub fn rmse(a: &Layers, reference: &Layers) -> f64 {
    mse(a, reference).sqrt()
}

/// Mean squared error of the beauty RGB of `a` against `reference`.
pub(super) fn mse(a: &Layers, reference: &Layers) -> f64 {
    let sum: f64 = a
        .beauty
        .iter()
        .zip(&reference.beauty)
        .map(|(x, r)| (x.truncate() - r.truncate()).as_dvec3().length_squared() / 3.0)
        .sum();
    sum / a.beauty.len() as f64
}

/// MSE of what the previews show (ACES filmic, then sRGB, 0 to 1): the error a viewer
/// sees. Plain MSE is decided by a few fireflies hundreds of times the walls' radiance,
/// relative MSE by the noise of dark pixels; a denoised frame trades the two differently
/// (it spreads fireflies, and smooths dark noise away), so neither alone compares it
/// fairly with an undenoised one.
pub(super) fn display_mse(a: &Layers, reference: &Layers) -> f64 {
    let show = |v: f32| f64::from(srgb_oetf(aces_filmic(v)));
    let sum: f64 = a
        .beauty
        .iter()
        .zip(&reference.beauty)
        .map(|(x, r)| {
            (0..3)
                .map(|c| (show(x[c]) - show(r[c])).powi(2))
                .sum::<f64>()
                / 3.0
        })
        .sum();
    sum / a.beauty.len() as f64
}

/// The share of the squared error of `a` against `reference` held by its worst `fraction`
/// of pixels.
pub(super) fn share_of_worst_pixels(a: &Layers, reference: &Layers, fraction: f64) -> f64 {
    let mut errors: Vec<f64> = a
        .beauty
        .iter()
        .zip(&reference.beauty)
        .map(|(x, r)| (x.truncate() - r.truncate()).as_dvec3().length_squared())
        .collect();
    let total: f64 = errors.iter().sum();
    if total <= 0.0 {
        return 0.0;
    }
    errors.sort_by(|x, y| y.total_cmp(x));
    let worst = ((errors.len() as f64 * fraction).ceil() as usize).min(errors.len());
    errors[..worst].iter().sum::<f64>() / total
}

/// pbrt's relative MSE: (x - r)² / (r² + 0.01), averaged over pixels and channels.
pub(super) fn rel_mse(a: &Layers, reference: &Layers) -> f64 {
    let sum: f64 = a
        .beauty
        .iter()
        .zip(&reference.beauty)
        .map(|(x, r)| {
            let (x, r) = (x.truncate().as_dvec3(), r.truncate().as_dvec3());
            let d = (x - r) * (x - r) / (r * r + 0.01);
            (d.x + d.y + d.z) / 3.0
        })
        .sum();
    sum / a.beauty.len() as f64
}

/// Renders the whole frame at `settings` and `spp`: the image and the wall seconds.
pub(super) fn render(
    frame: &PreparedFrame,
    settings: RenderSettings,
    spp: u32,
) -> (Layers, u64, f64) {
    let rect = TileRect::new(0, 0, frame.width, frame.height);
    let start = Instant::now();
    let tile = render_region(
        frame,
        &settings,
        rect,
        SampleRange::new(0, spp),
        32,
        &|_| {},
    );
    let seconds = start.elapsed().as_secs_f64();
    (tile.resolve(), tile.rays, seconds)
}

pub(super) fn point(value: u32, image: &Layers, seconds: f64, reference: &Layers) -> Point {
    Point {
        value,
        seconds,
        rmse: rmse(image, reference),
        rel_mse: rel_mse(image, reference),
    }
}

/// The seconds at which the sweep reaches `target` RMSE: log-log between the last point
/// above it and the first at or below it.
pub(super) fn seconds_to_reach(sweep: &[Point], target: f64) -> Option<f64> {
    let i = sweep.iter().position(|p| p.rmse <= target)?;
    let b = sweep[i];
    let Some(a) = i.checked_sub(1).map(|j| sweep[j]) else {
        return Some(b.seconds);
    };
    let t = (a.rmse.ln() - target.ln()) / (a.rmse.ln() - b.rmse.ln());
    Some((a.seconds.ln() + t * (b.seconds.ln() - a.seconds.ln())).exp())
}

/// A scene to measure and how to frame it.
pub(super) struct Subject {
    pub(super) name: String,
    pub(super) description: String,
    pub(super) scene: Scene,
    pub(super) options: FrameOptions,
}

/// The reference scenes: the measured diffuse Cornell box; the demo with its polished
/// metal and glass spheres; the animated demo with motion blur.
pub(super) fn reference_subjects(size: (u32, u32)) -> Vec<Subject> {
    let still = FrameOptions {
        width: size.0,
        height: size.1,
        ..Default::default()
    };
    vec![
        Subject {
            name: "cornell".into(),
            description: "the measured Cornell box: white, red and green Lambertian walls, two \
                          diffuse blocks, one area light"
                .into(),
            scene: tracer::demo::cornell_box(),
            options: still.clone(),
        },
        Subject {
            name: "glossy-glass".into(),
            description: "the demo: Cornell walls, a diffuse box, a polished metal sphere \
                          (roughness 0.15) and a glass sphere (IOR 1.5)"
                .into(),
            scene: tracer::demo::demo_scene(),
            options: still.clone(),
        },
        Subject {
            name: "motion-blur".into(),
            description: "the animated demo at frame 12 (the sphere bouncing, the box turning, \
                          the glass sliding), shutter -0.25..0.25 frames"
                .into(),
            scene: tracer::demo::animated_demo_scene(),
            options: FrameOptions {
                frame: 12,
                shutter: Shutter {
                    open: -0.25,
                    close: 0.25,
                },
                ..still
            },
        },
    ]
}

pub(super) fn measure_scene(
    subject: Subject,
    reference_spp: u32,
    quick: bool,
) -> anyhow::Result<SceneReport> {
    let scene = Arc::new(subject.scene);
    let frame = prepare_frame(scene.clone(), &subject.options)?;
    let settings = RenderSettings {
        max_depth: SWEEP_DEPTH,
        seed: SEED,
        ..RenderSettings::DEFAULT
    };
    // As deep as the deepest preset, so that no preset is measured against a reference
    // that lacks light it gathers.
    let reference_depth = Quality::ALL
        .iter()
        .map(|q| q.settings().max_depth)
        .fold(SWEEP_DEPTH, u32::max);
    eprintln!(
        "{}: reference at {reference_spp} spp, depth {reference_depth} ...",
        subject.name
    );
    let (reference, _, reference_seconds) = render(
        &frame,
        RenderSettings {
            max_depth: reference_depth,
            seed: REFERENCE_SEED,
            ..RenderSettings::DEFAULT
        },
        reference_spp,
    );

    let rays = rays::scene_rates(&frame);
    let (_, path_rays, seconds) = render(&frame, settings, 16);
    let paths = f64::from(frame.width * frame.height) * 16.0;

    let spps: &[u32] = if quick {
        &[1, 4, 16, 64]
    } else {
        &[1, 4, 16, 64, 256, 1024]
    };
    let spp_sweep: Vec<Point> = spps
        .iter()
        .map(|&spp| {
            let (image, _, secs) = render(&frame, settings, spp);
            point(spp, &image, secs, &reference)
        })
        .collect();

    let fixed_spp = if quick { 16 } else { 64 };
    let depth_sweep = [0, 1, 2, 4, 8, 12]
        .into_iter()
        .map(|max_depth| {
            let (image, _, secs) = render(
                &frame,
                RenderSettings {
                    max_depth,
                    ..settings
                },
                fixed_spp,
            );
            point(max_depth, &image, secs, &reference)
        })
        .collect();

    // Russian roulette from the first bounce on, to never (from past the sweep's depth).
    let rr_sweep = [1, 2, 3, 5, RR_NEVER]
        .into_iter()
        .map(|from| {
            let (image, _, secs) = render(
                &frame,
                RenderSettings {
                    russian_roulette: (from <= SWEEP_DEPTH).then_some(from),
                    ..settings
                },
                fixed_spp,
            );
            point(from, &image, secs, &reference)
        })
        .collect();

    let clamp_converged_spp = (reference_spp / 4).max(fixed_spp);
    let clamp_sweep = clamp_sweep(
        &frame,
        settings,
        &reference,
        fixed_spp,
        clamp_converged_spp,
        None,
    )?;

    // Motion steps: every render uses the same seed and spp as one with many steps, so
    // their difference is the interpolation's error more than noise.
    let moves = subject.options.shutter.open != subject.options.shutter.close;
    let motion_sweep = if moves {
        let at_steps = |steps: u32| -> anyhow::Result<(Layers, f64)> {
            let options = FrameOptions {
                motion_steps: Some(steps),
                ..subject.options.clone()
            };
            let f = prepare_frame(scene.clone(), &options)?;
            let (image, _, secs) = render(&f, settings, fixed_spp);
            Ok((image, secs))
        };
        let (fine, _) = at_steps(64)?;
        [1, 2, 3, 5, 9, 17]
            .into_iter()
            .map(|steps| {
                let (image, secs) = at_steps(steps)?;
                Ok(point(steps, &image, secs, &fine))
            })
            .collect::<anyhow::Result<_>>()?
    } else {
        Vec::new()
    };

    let presets = Quality::ALL
        .into_iter()
        .map(|q| {
            let p = q.settings();
            let preset = RenderSettings {
                max_depth: p.max_depth,
                seed: SEED,
                noise: Some(NoiseTarget {
                    threshold: p.noise_threshold as f32,
                    min_samples: p.min_spp,
                }),
                ..RenderSettings::DEFAULT
            };
            let (image, _, secs) = render(&frame, preset, p.spp);
            let reached = image.sampling();
            PresetPoint {
                preset: q.name().into(),
                max_spp: p.spp,
                max_depth: p.max_depth,
                threshold: p.noise_threshold,
                seconds: secs,
                mean_spp: reached.mean_samples,
                estimated_error: reached.mean_noise,
                rmse: rmse(&image, &reference),
            }
        })
        .collect();

    Ok(SceneReport {
        name: subject.name,
        description: subject.description,
        width: frame.width,
        height: frame.height,
        reference_spp,
        reference_depth,
        reference_seconds,
        rays,
        paths_per_second: paths / seconds,
        rays_per_second: path_rays as f64 / seconds,
        seconds_to_target: seconds_to_reach(&spp_sweep, TARGET_RMSE),
        spp_sweep,
        fixed_spp,
        depth_sweep,
        rr_sweep,
        clamp_sweep,
        clamp_converged_spp,
        motion_sweep,
        presets,
    })
}
