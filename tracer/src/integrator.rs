//! Unidirectional path tracing with next-event estimation and multiple importance
//! sampling (power heuristic), Russian roulette and splitting, and no NaN or infinity on
//! the film; in RGB, or at four sampled wavelengths (the spectral path, `carrier.rs`).

use std::ops::Range;

use glam::{Vec2, Vec3};

mod carrier;
mod folding;
mod screen_motion;
mod surface;

use carrier::{Carrier, Colour, Rgb};
use folding::{consistent_side, eval_folded, fold, pdf_folded};
use screen_motion::screen_motion;
use surface::{surface_point, SurfacePoint};

use crate::bsdf::{Bsdf, SurfaceParams};
use crate::film::SampleValue;
use crate::frame::PreparedFrame;
use crate::geometry::{offset_ray_origin_bounded, Hit, Ray};
use crate::light::Emitter;
use crate::material::dispersive_ior;
use crate::math;
use crate::sampler::{BounceDimensions, PixelSampler, BOUNCE_DIMENSIONS};
use crate::settings::RenderSettings;
use crate::spectrum::{DenseSpectrum, SampledWavelengths, SigmoidPolynomial};

/// Sampler dimensions used by the camera before the first bounce: pixel position, then
/// the shutter time (drawn only when something moves, so a still frame skips it).
const CAMERA_DIMENSIONS: u32 = 3;
/// The sampler dimension of the spectral path's wavelengths, apart from the others so
/// that the RGB path's are where they were.
const WAVELENGTH_DIMENSION: u32 = 0xffff_0000;

/// The first of the two sampler dimensions of a fluorescent bounce at each depth (the
/// choice and the absorbed wavelength), apart from the others like the wavelengths'.
const FLUORESCENCE_DIMENSION: u32 = 0xfffe_0000;

/// What a fluorescent paint scatters as once its wavelengths are chosen: a white
/// Lambertian surface (its colour is in the choice's weight).
const WHITE_LAMBERTIAN: SurfaceParams = SurfaceParams {
    base_color: Vec3::ONE,
    metallic: 0.0,
    roughness: 1.0,
    ior: 1.5,
    specular: 0.0,
    specular_color: Vec3::ONE,
    transmission: 0.0,
    thin_walled: false,
    extensions: None,
};

/// Keeps the hero wavelength alone from here on: in the path `carrier` (its `throughput`
/// too) and in the sample's `sensor`, whose estimate then counts the hero alone. Gives
/// the wavelength the path carries; `None` on the RGB path.
fn hero_alone<W: Carrier>(
    sensor: &mut W,
    carrier: &mut W,
    throughput: &mut W::Colour,
) -> Option<f32> {
    sensor.keep_hero();
    *throughput = W::hero_only(*throughput);
    carrier.keep_hero()
}

/// Light `c` reaching the camera, clamped to `limit` in its largest RGB channel where it is
/// `indirect` (it left the light and met at least two surfaces before the camera) and the
/// settings ask for it: Cycles' "clamp indirect", which trades bias for the fireflies of
/// rare bright paths.
#[inline(always)]
fn clamped<W: Carrier>(carrier: &W, c: W::Colour, indirect: bool, limit: Option<f32>) -> W::Colour {
    match limit {
        Some(limit) if indirect => {
            let largest = carrier.to_rgb(c).max_element();
            if largest > limit {
                c * (limit / largest)
            } else {
                c
            }
        }
        _ => c,
    }
}

/// The power heuristic with exponent 2 (Veach 1997).
fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2.is_infinite() {
        return 1.0;
    }
    if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

/// A ray leaving `sp` towards `dir`, offset past the error of its position to the side of
/// the surface the direction is on.
#[inline(always)]
fn spawn(sp: &SurfacePoint, dir: Vec3, time: f32) -> Ray {
    let n = if dir.dot(sp.ng) >= 0.0 { sp.ng } else { -sp.ng };
    Ray {
        origin: offset_ray_origin_bounded(sp.p, n, sp.p_error),
        dir,
        time,
    }
}

/// A path between two bounces: everything needed to continue it, so that a path that
/// splits (see [`SPLIT_AT`]) can leave its copies for later.
#[derive(Clone)]
struct PathState<W: Carrier> {
    ray: Ray,
    /// Bounces so far (0: the camera ray).
    depth: u32,
    /// The wavelengths the path carries now (fluorescence changes its hero's), or RGB.
    carrier: W,
    throughput: W::Colour,
    /// Product of η² over the refractions so far: the BTDF scales radiance by 1/η² on the
    /// way into a denser medium, which is not energy lost; Russian roulette and splitting
    /// look at `throughput · eta_scale` so a path inside glass is not killed for that
    /// factor (and its survivors weighted up by η², a firefly per escaping path), as in
    /// pbrt-v4.
    eta_scale: f32,
    /// Absorption coefficient of the volume the ray travels in (KHR_materials_volume),
    /// zero outside every volume. Volumes do not nest: leaving one returns to the scene's
    /// vacuum.
    absorption: Vec3,
    /// pdf of the BSDF sample that produced `ray` (for MIS on emitters it hits), and
    /// whether it came from a delta lobe (no MIS: lights could not have sampled it).
    prev_pdf: f32,
    prev_delta: bool,
    prev_p: Vec3,
    sampler: PixelSampler,
}

/// Splitting: a path whose throughput (times `eta_scale`) reaches this is split into
/// that many copies, each carrying its share. Russian roulette keeps the throughput of
/// a surviving path at 1 or above, and this keeps it below `SPLIT_AT`, a weight window
/// as in particle transport. Without it, a path trapped for hundreds of bounces (rough
/// glass of IOR 10 reflects everything but directions near the normal back inside)
/// multiplies hundreds of per-bounce weights that only average to the albedo: most
/// paths end with little and rare ones carry the rest, and any practical sample count
/// underestimates (a white furnace read 0.78). Ordinary bounces weigh at most about 1, so
/// this rarely triggers elsewhere.
const SPLIT_AT: f32 = 2.0;
/// Copies one split may make.
const MAX_SPLIT: u32 = 8;
/// Copies one camera sample may make in all: bounds its time in the worst case. Not
/// splitting is never wrong in expectation, but past the cap path weights grow without
/// bound again, and trapped light reads low at any practical sample count: a cap of 1024
/// darkened a white rough-glass furnace at IOR 10 and metallic 0.5 by 7%, whose worst
/// camera sample needs 11,615 copies (and 80 of its 147,456 more than 1024).
const MAX_BRANCHES: u32 = 1 << 16;

/// What one camera sample has gathered so far, over all of its paths.
struct SampleWalk<W: Carrier> {
    /// The wavelengths the camera sample drew, as the film counts them (the secondary
    /// ones dropped once any of its paths keeps the hero alone), or RGB.
    carrier: W,
    /// Radiance gathered (`out.radiance` once the sample is done).
    radiance: W::Colour,
    out: SampleValue,
    albedo_done: bool,
    /// Copies of split paths not yet traced.
    pending: Vec<PathState<W>>,
    /// Copies made so far.
    branches: u32,
}

/// Whether `frame` renders on the spectral path: where the settings ask for it or the
/// scene needs it ([`crate::scene::Features::needs_spectral`]).
pub fn carries_wavelengths(frame: &PreparedFrame, settings: &RenderSettings) -> bool {
    settings.spectral || frame.features.needs_spectral()
}

/// Traces camera sample `index` of pixel (`x`, `y`): in RGB, or at four wavelengths where
/// [`carries_wavelengths`] says so.
///
/// # Panics
/// If `index` is `u32::MAX`, past every [`SampleRange`](crate::film::SampleRange).
pub fn trace_sample(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    x: u32,
    y: u32,
    index: u32,
) -> SampleValue {
    let end = index.checked_add(1).expect("a sample index below u32::MAX");
    let mut value = SampleValue::default();
    trace_samples(frame, settings, x, y, index..end, &mut |_, v| {
        value = *v;
        false
    });
    value
}

/// Traces camera samples `samples` of pixel (`x`, `y`) in order, as [`trace_sample`]
/// each, handing each to `each` with its index until `each` returns false. One call for
/// a pixel's run of samples: the path loop's set-up (the frame's and the settings' values
/// it keeps at hand, about 90 instructions) is paid once per run, not once per sample.
/// (`each` is called through a pointer: a closure of its own type would compile the path
/// loop once more for each caller.)
pub fn trace_samples(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    x: u32,
    y: u32,
    samples: Range<u32>,
    each: &mut dyn FnMut(u32, &SampleValue) -> bool,
) {
    if carries_wavelengths(frame, settings) {
        let carrier = |sampler: &mut PixelSampler| {
            sampler.start_dimension(WAVELENGTH_DIMENSION);
            SampledWavelengths::sample_visible(sampler.next_1d())
        };
        trace_samples_in(frame, settings, (x, y), samples, carrier, each)
    } else {
        trace_samples_in(frame, settings, (x, y), samples, |_| Rgb, each)
    }
}

/// [`trace_samples_with`] in the copy this process runs: compiled for AVX where the CPU
/// has it (3% fewer instructions on the Cornell box, the same bits; see [`crate::simd`]).
// One function per carrier and copy, each with its path loop inlined: both carriers' loops
// in one function cost the RGB path 1.6% more instructions on the Cornell box.
#[inline(always)]
fn trace_samples_in<W: Carrier>(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    pixel: (u32, u32),
    samples: Range<u32>,
    carrier: impl Fn(&mut PixelSampler) -> W,
    each: &mut dyn FnMut(u32, &SampleValue) -> bool,
) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx() {
        // SAFETY: the CPU has AVX (`simd::avx`).
        return unsafe { trace_samples_avx(frame, settings, pixel, samples, carrier, each) };
    }
    trace_samples_baseline(frame, settings, pixel, samples, carrier, each)
}

/// [`trace_samples_with`] compiled for AVX (a closure run by [`crate::simd::with_avx`] was
/// left out of line, compiled for the baseline).
///
/// # Safety
/// The CPU must have AVX ([`crate::simd::avx`] says so).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline(never)]
unsafe fn trace_samples_avx<W: Carrier>(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    pixel: (u32, u32),
    samples: Range<u32>,
    carrier: impl Fn(&mut PixelSampler) -> W,
    each: &mut dyn FnMut(u32, &SampleValue) -> bool,
) {
    trace_samples_with::<W, true>(frame, settings, pixel, samples, carrier, each)
}

/// [`trace_samples_with`] compiled for the baseline CPU.
#[inline(never)]
fn trace_samples_baseline<W: Carrier>(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    pixel: (u32, u32),
    samples: Range<u32>,
    carrier: impl Fn(&mut PixelSampler) -> W,
    each: &mut dyn FnMut(u32, &SampleValue) -> bool,
) {
    trace_samples_with::<W, false>(frame, settings, pixel, samples, carrier, each)
}

/// The run of [`trace_samples`], each sample by [`trace_sample_with`].
#[inline(always)]
fn trace_samples_with<W: Carrier, const AVX: bool>(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    (x, y): (u32, u32),
    samples: Range<u32>,
    carrier: impl Fn(&mut PixelSampler) -> W,
    each: &mut dyn FnMut(u32, &SampleValue) -> bool,
) {
    for index in samples {
        let value = trace_sample_with::<W, AVX>(frame, settings, x, y, index, &carrier);
        if !each(index, &value) {
            return;
        }
    }
}

/// [`trace_sample`] carrying what `carrier` draws from the sampler. With `AVX` (only in
/// [`trace_samples_avx`]), its ray queries are the AVX ones.
#[inline(always)]
fn trace_sample_with<W: Carrier, const AVX: bool>(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    x: u32,
    y: u32,
    index: u32,
    carrier: impl FnOnce(&mut PixelSampler) -> W,
) -> SampleValue {
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
        radiance: W::Colour::ZERO,
        out: SampleValue::EMPTY,
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
    walk.out.radiance = walk.carrier.to_rgb(walk.radiance);
    walk.out
}

/// Follows one path from its state `s` until it ends, adding what it gathers to `walk`.
// Inlined into its one caller, as the compiler chose before the path grew past its limit:
// 2% fewer instructions on the Cornell box (the sampler's state stays in registers).
#[inline(always)]
fn trace_path<W: Carrier, const AVX: bool>(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    view_axis: Vec3,
    mut s: PathState<W>,
    walk: &mut SampleWalk<W>,
) {
    let out = &mut walk.out;
    let radiance = &mut walk.radiance;
    while s.depth <= settings.max_depth {
        let depth = s.depth;
        let ray = s.ray;
        let sampler = &mut s.sampler;
        out.rays += 1;
        // Read in place: moved out, the hit was copied in wider loads than the query's
        // stores, which the CPU cannot forward (a stall of a dozen cycles at every hit).
        let found = closest_hit::<AVX>(frame, &ray, f32::INFINITY);
        let Some(hit) = &found else {
            // The environment.
            if s.absorption != Vec3::ZERO {
                s.throughput *= s.carrier.weight(transmittance(s.absorption, f32::INFINITY));
            }
            let le = frame.lights.environment().radiance(ray.dir);
            if le != Vec3::ZERO {
                let w = if s.prev_delta {
                    1.0
                } else {
                    power_heuristic(s.prev_pdf, frame.lights.pdf_environment(ray.dir))
                };
                let c = s.throughput * s.carrier.light(le, None) * w;
                *radiance += clamped(&s.carrier, c, depth >= 2, settings.clamp_indirect);
            }
            if !walk.albedo_done {
                out.albedo = le;
            }
            if depth == 0 && frame.motion {
                out.motion = screen_motion(frame, &ray, None);
            }
            return;
        };
        let sp = surface_point(frame, &ray, hit);
        if s.absorption != Vec3::ZERO {
            // Between the surface points, not from the ray's origin, which is offset past
            // the previous point's rounding error.
            s.throughput *= s
                .carrier
                .weight(transmittance(s.absorption, (sp.p - s.prev_p).length()));
        }
        let wo = -ray.dir.normalize();
        if depth == 0 {
            out.alpha = 1.0;
            out.normal = sp.frame.z;
            out.depth = Some((sp.p - ray.origin).dot(view_axis).abs());
            if frame.motion {
                out.motion = screen_motion(frame, &ray, Some(hit));
            }
        }

        let prepared = &frame.materials[sp.material_index as usize];
        // Light emitted by the surface (glTF emission is one-sided for single-sided
        // materials, seen from the front only).
        let le = sp.emission;
        if le != Vec3::ZERO && (sp.front || !sp.single_sided) {
            let w = if s.prev_delta {
                1.0
            } else {
                let light_pdf =
                    frame
                        .lights
                        .pdf_triangle(hit.instance, hit.triangle, s.prev_p, sp.p, sp.ng);
                power_heuristic(s.prev_pdf, light_pdf)
            };
            let spectrum = light_spectrum(frame, prepared.emission_spectrum);
            let c = s.throughput * s.carrier.light(le, spectrum) * w;
            *radiance += clamped(&s.carrier, c, depth >= 2, settings.clamp_indirect);
        }

        // The material's own BSDF where textures and vertex colour leave it as it is.
        let material_bsdf = &prepared.bsdf;
        let textured;
        let mut bsdf = match sp.varying {
            Some(params) if params != material_bsdf.params => {
                textured = Bsdf::new(params).with_albedo_curve(material_bsdf.albedo_curve());
                &textured
            }
            _ => material_bsdf,
        };
        // A dispersive interface refracts each wavelength its own way: the path follows
        // its hero wavelength alone, at that wavelength's IOR (as pbrt-v4 does).
        let dispersed;
        if W::SPECTRAL && prepared.dispersion > 0.0 {
            if let Some(nm) = hero_alone(&mut walk.carrier, &mut s.carrier, &mut s.throughput) {
                let ior = dispersive_ior(bsdf.params.ior, prepared.dispersion, nm);
                dispersed = Bsdf::new(SurfaceParams { ior, ..bsdf.params });
                bsdf = &dispersed;
            }
        }
        if !walk.albedo_done && !bsdf.is_delta() {
            out.albedo = bsdf.albedo();
            walk.albedo_done = true;
        }
        // Fluorescent paint: the path reflects at its wavelength or takes the one the
        // light was absorbed at, and the surface scatters as white Lambertian from there.
        let paint_white;
        if let Some(paint) = prepared
            .fluorescence
            .filter(|_| W::SPECTRAL)
            .and_then(|i| frame.fluorescence.get(i as usize))
        {
            if let Some(nm) = hero_alone(&mut walk.carrier, &mut s.carrier, &mut s.throughput) {
                let r = SigmoidPolynomial::reflectance(
                    bsdf.params.base_color.clamp(Vec3::ZERO, Vec3::ONE),
                )
                .eval(nm);
                sampler.start_dimension(FLUORESCENCE_DIMENSION + 2 * depth);
                let (u_choice, u_nm) = (sampler.next_1d(), sampler.next_1d());
                let step = paint.sample(nm, r, u_choice, u_nm);
                s.throughput = s.throughput * step.weight;
                s.carrier.shift_hero(step.nm);
                paint_white = Bsdf::new(WHITE_LAMBERTIAN);
                bsdf = &paint_white;
            }
        }
        if depth == settings.max_depth {
            return;
        }
        let u = next_bounce::<AVX>(sampler, CAMERA_DIMENSIONS + depth * BOUNCE_DIMENSIONS);
        let wo_local = sp.frame.to_local(wo);
        let scatter = bsdf.at_coated(wo_local, sp.coat_normal.map(|n| sp.frame.to_local(n)));

        // Next-event estimation.
        if !bsdf.is_delta() {
            if let Some(ls) = frame
                .lights
                .sample(sp.p, Some(sp.ng), u.light, u.light_point)
            {
                let wi_local = sp.frame.to_local(ls.wi);
                let (f, bsdf_pdf) = match &scatter {
                    Some(s) if consistent_side(&sp, ls.wi, wi_local) => {
                        eval_folded(&sp, s, ls.wi, wi_local)
                    }
                    _ => (Vec3::ZERO, 0.0),
                };
                if ls.pdf > 0.0 && f != Vec3::ZERO {
                    let le = match ls.emitter {
                        Emitter::Radiance(l) => l,
                        Emitter::Triangle {
                            instance,
                            triangle,
                            b1,
                            b2,
                            ..
                        } => emitted_toward(frame, instance, triangle, b1, b2, ls.wi, ray.time),
                    };
                    let mut le = s.carrier.light(le, light_spectrum(frame, ls.spectrum));
                    if s.absorption != Vec3::ZERO {
                        le *= s.carrier.weight(transmittance(s.absorption, ls.distance));
                    }
                    if le != W::Colour::ZERO {
                        let mut shadow = spawn(&sp, ls.wi, ray.time);
                        // Aim at the sampled point from the offset origin (else the offset
                        // carries the ray past the light) and stop just short of it, so
                        // that the light does not occlude itself.
                        let to_light = sp.p + ls.wi * ls.distance - shadow.origin;
                        let t_max = match math::try_normalize(to_light) {
                            Some(dir) if ls.distance.is_finite() => {
                                shadow.dir = dir;
                                to_light.length() * (1.0 - 1e-4)
                            }
                            _ => f32::INFINITY,
                        };
                        out.rays += 1;
                        if !occluded::<AVX>(frame, &shadow, t_max) {
                            let w = if ls.delta {
                                1.0
                            } else {
                                power_heuristic(ls.pdf, bsdf_pdf)
                            };
                            let c = s.throughput * s.carrier.weight(f) * le * (w / ls.pdf);
                            *radiance +=
                                clamped(&s.carrier, c, depth >= 1, settings.clamp_indirect);
                        }
                    }
                }
            }
        }

        // Continue the path by sampling the BSDF.
        let Some((scatter, bs)) = scatter
            .as_ref()
            .and_then(|s| Some((s, s.sample(u.lobe, u.direction)?)))
        else {
            return;
        };
        if !(bs.pdf > 0.0) {
            return;
        }
        let mut wi = sp.frame.to_world(bs.wi);
        let folded = !consistent_side(&sp, wi, bs.wi);
        if folded {
            wi = fold(&sp, wi);
        }
        s.throughput *= s.carrier.weight(bs.f * (bs.wi.z.abs() / bs.pdf));
        if !s.throughput.is_finite() || s.throughput == W::Colour::ZERO {
            return;
        }
        if bs.wi.z * wo_local.z < 0.0 && !bsdf.is_thin_walled() {
            // Into or out of a solid. A refracting surface keeps its front face's frame,
            // so `wo_local.z > 0` is arriving from outside; one that passes light only
            // diffusely is shaded from the side the ray came from, which its front face
            // tells, and its Lambertian crossing changes no radiance scale.
            let refracts = bsdf.params.transmission > 0.0;
            let entering = if refracts { wo_local.z > 0.0 } else { sp.front };
            if refracts {
                let eta_rel = if entering {
                    bsdf.eta()
                } else {
                    1.0 / bsdf.eta()
                };
                s.eta_scale *= eta_rel * eta_rel;
            }
            s.absorption = if entering {
                prepared.material.absorption()
            } else {
                Vec3::ZERO
            };
        }
        s.prev_pdf = if bs.delta {
            bs.pdf
        } else {
            pdf_folded(&sp, scatter, wi, folded, bs.pdf)
        };
        s.prev_delta = bs.delta;
        s.prev_p = sp.p;
        s.ray = spawn(&sp, wi, ray.time);
        s.depth += 1;

        // Russian roulette once the path has a few bounces.
        let weight = s.throughput.max_element() * s.eta_scale;
        let roulette = settings
            .russian_roulette
            .is_some_and(|from| s.depth >= from);
        if roulette && weight < 1.0 {
            if u.roulette >= weight {
                return;
            }
            s.throughput /= weight;
        } else if weight >= SPLIT_AT && walk.branches < MAX_BRANCHES {
            let copies = (weight as u32)
                .min(MAX_SPLIT)
                .min(MAX_BRANCHES - walk.branches + 1);
            s.throughput /= copies as f32;
            for _ in 1..copies {
                walk.branches += 1;
                let mut copy = s.clone();
                copy.sampler = s.sampler.branch(walk.branches);
                walk.pending.push(copy);
            }
        }
    }
}

/// The closest hit on `ray` before `t_max`; with `AVX` (the path loop's AVX copy) by the
/// AVX query, inlined.
#[inline(always)]
fn closest_hit<const AVX: bool>(frame: &PreparedFrame, ray: &Ray, t_max: f32) -> Option<Hit> {
    #[cfg(target_arch = "x86_64")]
    if AVX {
        // SAFETY: `AVX` is true only in `trace_samples_avx`, which runs where the CPU has
        // AVX.
        return unsafe { frame.query_avx::<false>(ray, t_max) };
    }
    frame.intersect(ray, t_max)
}

/// A bounce's sampler dimensions from `dimension` on; with `AVX`, in SSE lanes (a CPU with
/// AVX has SSE4.1 and SSSE3).
#[inline(always)]
fn next_bounce<const AVX: bool>(sampler: &mut PixelSampler, dimension: u32) -> BounceDimensions {
    #[cfg(target_arch = "x86_64")]
    if AVX {
        // SAFETY: as in `closest_hit`; AVX implies SSE4.1 and SSSE3.
        return unsafe { sampler.next_bounce_sse41(dimension) };
    }
    sampler.next_bounce(dimension)
}

/// Whether anything blocks `ray` before `t_max`; with `AVX` as [`closest_hit`].
#[inline(always)]
fn occluded<const AVX: bool>(frame: &PreparedFrame, ray: &Ray, t_max: f32) -> bool {
    #[cfg(target_arch = "x86_64")]
    if AVX {
        // SAFETY: as in `closest_hit`.
        return unsafe { frame.query_avx::<true>(ray, t_max) }.is_some();
    }
    frame.occluded(ray, t_max)
}

/// The spectrum `id` names among the frame's light spectra (`get`, not an index: the RGB
/// path drops the lookup it never reads).
#[inline(always)]
fn light_spectrum(frame: &PreparedFrame, id: Option<u32>) -> Option<&DenseSpectrum> {
    frame.light_spectra.get(id? as usize)
}

/// Beer–Lambert transmittance over `distance` through a medium of absorption `sigma`; a
/// channel that absorbs nothing passes everything, even to infinity.
fn transmittance(sigma: Vec3, distance: f32) -> Vec3 {
    Vec3::from_array(sigma.to_array().map(|s| {
        if s > 0.0 {
            crate::math::exp(-s * distance)
        } else {
            1.0
        }
    }))
}

/// Radiance leaving emissive triangle `triangle` of `instance` at barycentrics (b1, b2)
/// towards a point in direction `-wi` from it, honouring one-sided emission. Only
/// textured or vertex-coloured emission comes here: the light sampler answers for
/// uniform emitters itself ([`Emitter::Radiance`]).
fn emitted_toward(
    frame: &PreparedFrame,
    instance: u32,
    triangle: u32,
    b1: f32,
    b2: f32,
    wi: Vec3,
    time: f32,
) -> Vec3 {
    let scene = &*frame.scene;
    let mut moved = None;
    let tri = frame.triangle_at(instance, triangle, time, &mut moved);
    let material = frame.material(tri.prim.material);
    if !material.double_sided && tri.front_normal(tri.positions()).dot(wi) >= 0.0 {
        return Vec3::ZERO;
    }
    let uvs = tri.prim.uvs_at(tri.t, b1, b2);
    let color = tri.prim.color_at(tri.t, b1, b2);
    material.sample(&scene.textures, uvs, color).emission
}
