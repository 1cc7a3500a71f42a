//! Camera samples, traced a batch of a pixel's at a time: each sample's paths followed to
//! their ends (the path loop, [`trace_path`]), then the batch's shadow rays traced in
//! packets, then each sample's light summed (`deferred.rs`); in the copy of the loop this
//! CPU runs (see [`crate::simd`]).

use std::ops::Range;

use glam::{Vec2, Vec3};

use super::carrier::{Carrier, Colour, Rgb};
use super::deferred::{Deferred, Gathered, SampleScratch};
use super::{
    carries_wavelengths, occluded, trace_path, PathState, SampleWalk, WAVELENGTH_DIMENSION,
};
use crate::film::SampleValue;
use crate::frame::PreparedFrame;
use crate::sampler::PixelSampler;
use crate::settings::RenderSettings;
use crate::spectrum::SampledWavelengths;

/// Camera samples that [`trace_samples`] traces together, so that their shadow rays
/// travel in packets (see `deferred.rs`).
pub const SAMPLE_BATCH: u32 = 8;

/// Traces camera sample `index` of pixel (`x`, `y`): in RGB, or at four wavelengths where
/// [`carries_wavelengths`] says so.
pub fn trace_sample(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    x: u32,
    y: u32,
    index: u32,
) -> SampleValue {
    let mut values = Vec::with_capacity(1);
    let scratch = &mut SampleScratch::new();
    trace_samples(
        frame,
        settings,
        x,
        y,
        index..index + 1,
        scratch,
        &mut values,
    );
    values[0]
}

/// Traces camera samples `indices` of pixel (`x`, `y`) into `values` (emptied first), each
/// bit for bit what [`trace_sample`] gives it alone; the shadow rays of each
/// [`SAMPLE_BATCH`] of them go eight at a time.
pub fn trace_samples(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    x: u32,
    y: u32,
    indices: Range<u32>,
    scratch: &mut SampleScratch,
    values: &mut Vec<SampleValue>,
) {
    values.clear();
    let mut first = indices.start;
    while first < indices.end {
        let batch = Batch {
            frame,
            settings,
            x,
            y,
            indices: first..indices.end.min(first.saturating_add(SAMPLE_BATCH)),
        };
        first = batch.indices.end;
        if carries_wavelengths(frame, settings) {
            trace_batch_in(batch, scratch, values, |sampler: &mut PixelSampler| {
                sampler.start_dimension(WAVELENGTH_DIMENSION);
                SampledWavelengths::sample_visible(sampler.next_1d())
            })
        } else {
            trace_batch_in(batch, scratch, values, |_: &mut PixelSampler| Rgb)
        }
    }
}

/// Camera samples of one pixel to trace together: at most [`SAMPLE_BATCH`].
struct Batch<'f> {
    frame: &'f PreparedFrame,
    settings: &'f RenderSettings,
    x: u32,
    y: u32,
    indices: Range<u32>,
}

/// [`trace_batch_with`] in the copy this process runs: compiled for AVX where the CPU
/// has it (3% fewer instructions on the Cornell box, the same bits; see [`crate::simd`]).
// One function per carrier and copy, each with its path loop inlined: both carriers' loops
// in one function cost the RGB path 1.6% more instructions on the Cornell box.
#[inline(always)]
fn trace_batch_in<W: Carrier>(
    batch: Batch<'_>,
    scratch: &mut SampleScratch,
    values: &mut Vec<SampleValue>,
    carrier: impl Fn(&mut PixelSampler) -> W,
) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx() {
        // SAFETY: the CPU has AVX (`simd::avx`).
        return unsafe { trace_batch_avx(batch, scratch, values, carrier) };
    }
    trace_batch_baseline(batch, scratch, values, carrier)
}

/// [`trace_batch_with`] compiled for AVX (a closure run by [`crate::simd::with_avx`] was
/// left out of line, compiled for the baseline).
///
/// # Safety
/// The CPU must have AVX ([`crate::simd::avx`] says so).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline(never)]
unsafe fn trace_batch_avx<W: Carrier>(
    batch: Batch<'_>,
    scratch: &mut SampleScratch,
    values: &mut Vec<SampleValue>,
    carrier: impl Fn(&mut PixelSampler) -> W,
) {
    trace_batch_with::<W, true>(batch, scratch, values, carrier)
}

/// [`trace_batch_with`] compiled for the baseline CPU.
#[inline(never)]
fn trace_batch_baseline<W: Carrier>(
    batch: Batch<'_>,
    scratch: &mut SampleScratch,
    values: &mut Vec<SampleValue>,
    carrier: impl Fn(&mut PixelSampler) -> W,
) {
    trace_batch_with::<W, false>(batch, scratch, values, carrier)
}

/// [`trace_samples`] carrying what `carrier` draws from each sample's sampler: every
/// sample's paths followed to their ends, then the batch's shadow rays traced, then each
/// sample's light summed. With `AVX` (only in [`trace_batch_avx`]), its ray queries are
/// the AVX ones, inlined.
#[inline(always)]
fn trace_batch_with<W: Carrier, const AVX: bool>(
    batch: Batch<'_>,
    scratch: &mut SampleScratch,
    values: &mut Vec<SampleValue>,
    carrier: impl Fn(&mut PixelSampler) -> W,
) {
    let Batch {
        frame,
        settings,
        x,
        y,
        indices,
    } = batch;
    let first = values.len();
    let (light, stack) = W::Colour::parts(scratch);
    // Per sample: where its terms start, and the wavelengths the film counts.
    let mut walks = [(0, None); SAMPLE_BATCH as usize];
    for (walk, index) in walks.iter_mut().zip(indices) {
        let start = light.mark();
        let (out, carrier) =
            trace_sample_paths::<W, AVX>(frame, settings, x, y, index, &carrier, light);
        *walk = (start, Some(carrier));
        values.push(out);
    }
    light.trace_shadows(
        frame,
        stack,
        |frame, rays, t_max, mask, stack| {
            // SAFETY: `AVX` is true only in `trace_batch_avx`, which runs where the CPU
            // has AVX.
            unsafe { frame.occluded_packet_with::<AVX>(rays, t_max, mask, stack) }
        },
        |frame, ray, t_max| occluded::<AVX>(frame, ray, t_max),
    );
    let values = &mut values[first..];
    let ends = walks.iter().skip(1).map(|w| w.0);
    let ends = ends.take(values.len() - 1).chain([light.mark()]);
    for ((value, (start, carrier)), end) in values.iter_mut().zip(&walks).zip(ends) {
        if let Some(carrier) = carrier {
            value.radiance = carrier.to_rgb(light.sum(*start..end));
        }
    }
}

/// Follows every path of camera sample `index` of pixel (`x`, `y`), its light into `light`:
/// the sample's value but for its radiance, and the wavelengths the film counts.
#[inline(always)]
fn trace_sample_paths<W: Carrier, const AVX: bool>(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    x: u32,
    y: u32,
    index: u32,
    carrier: &impl Fn(&mut PixelSampler) -> W,
    light: &mut Deferred<W::Colour>,
) -> (SampleValue, W) {
    let pattern = if settings.fixed_pattern {
        0
    } else {
        frame.frame
    };
    let mut sampler = PixelSampler::new(x, y, index, pattern, settings.seed);
    let jitter = sampler.next_2d();
    let film = Vec2::new(
        (x as f32 + jitter.x) / frame.width as f32,
        (y as f32 + jitter.y) / frame.height as f32,
    );
    // Owen-scrambled Sobol points stratify this dimension over the pixel's samples too.
    let time = if frame.motion { sampler.next_1d() } else { 0.0 };
    let (ray, view_axis) = frame.camera.primary(film, time);
    let carrier = carrier(&mut sampler);

    let mut walk = SampleWalk {
        carrier,
        light,
        out: SampleValue::default(),
        albedo_done: false,
        pending: Vec::new(),
        branches: 0,
    };
    let mut next = Some(PathState {
        ray,
        depth: 0,
        carrier,
        throughput: W::Colour::ONE,
        eta_scale: 1.0,
        absorption: Vec3::ZERO,
        prev_pdf: 0.0,
        prev_delta: true,
        prev_p: ray.origin,
        sampler,
    });
    while let Some(path) = next {
        trace_path::<W, AVX>(frame, settings, view_axis, path, &mut walk);
        next = walk.pending.pop();
    }
    (walk.out, walk.carrier)
}
