//! What the noise layers say and the settings that trade noise: adaptive sampling meets its
//! threshold and keeps tiles bit-identical, the variance layer bounds the error, and the
//! clamp on indirect light takes fireflies away with a little light.

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use tracer::film::{Layers, SampleRange, TileRect};
use tracer::render::{render_region, render_tile, NoiseTarget, RenderSettings};

mod common;
use common::{cornell_frame, demo_frame, frame, render};

/// The measured error of `layers` against `reference`, per pixel, in the units of the
/// noise estimate: `Σ|I − R| / (1e-4 + sqrt(Σ R))` over R, G, B.
fn measured_noise(layers: &Layers, reference: &Layers) -> Vec<f32> {
    layers
        .beauty
        .iter()
        .zip(&reference.beauty)
        .map(|(i, r)| {
            let (i, r) = (i.truncate(), r.truncate());
            (i - r).abs().element_sum() / (1e-4 + r.element_sum().max(0.0).sqrt())
        })
        .collect()
}

fn mean(v: &[f32]) -> f64 {
    v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64
}

#[test]
fn adaptive_sampling_meets_its_noise_threshold_on_average() {
    let f = frame(tracer::demo::demo_scene(), 32, 24);
    let reference = render(&f, &RenderSettings::default(), 4096).resolve();
    let (threshold, max_spp) = (0.05, 1024);
    let settings = RenderSettings {
        noise: Some(NoiseTarget {
            threshold,
            min_samples: 16,
        }),
        ..RenderSettings::default()
    };
    let adaptive = render(&f, &settings, max_spp).resolve();
    let reached = adaptive.sampling();
    let measured = mean(&measured_noise(&adaptive, &reference));
    let estimated = reached.mean_noise.expect("every pixel has an estimate");
    println!(
        "threshold {threshold}: measured error {measured:.4} against a 4096-spp reference, \
         estimated {estimated:.4}; spp mean {:.1}, min {}, max {}",
        reached.mean_samples, reached.min_samples, reached.max_samples
    );
    // The reference has noise of its own: at 4096 spp about a third of the threshold's
    // at the pixels' mean count, which the measured error includes.
    assert!(
        measured <= f64::from(threshold),
        "measured {measured} above {threshold}"
    );
    assert!(
        estimated <= f64::from(threshold) * 1.05,
        "estimated {estimated}"
    );
    // It is adaptive: pixels stop at different counts, and all took the minimum.
    assert!(reached.min_samples >= 16);
    assert!(reached.mean_samples < f64::from(max_spp) * 0.75);
    assert!(reached.max_samples > reached.min_samples);
    // A pixel that stopped early reached the threshold.
    for (s, e) in adaptive.samples.iter().zip(&adaptive.noise) {
        if (*s as u32) < max_spp {
            assert!(*e <= threshold, "stopped at {s} spp with noise {e}");
        }
    }
    // For the record (printed, not asserted): the same samples spread evenly.
    let uniform = render(
        &f,
        &RenderSettings::default(),
        reached.mean_samples.round() as u32,
    );
    let uniform = uniform.resolve();
    let uniform_error = mean(&measured_noise(&uniform, &reference));
    println!(
        "uniform at the same mean spp: measured error {uniform_error:.4}, estimated {:.4}",
        uniform.sampling().mean_noise.unwrap()
    );
}

#[test]
fn the_variance_layer_bounds_the_squared_error_of_the_pixels() {
    let f = cornell_frame(1);
    let reference = render(&f, &RenderSettings::default(), 4096).resolve();
    for spp in [4, 16, 64] {
        let noisy = render(&f, &RenderSettings::default(), spp).resolve();
        // Per channel, summed over every pixel: the squared error against the reference
        // and the layer's estimate of it.
        let (mut squared, mut estimated) = (0.0, 0.0);
        for i in 0..noisy.beauty.len() {
            let error = noisy.beauty[i].truncate() - reference.beauty[i].truncate();
            squared += f64::from((error * error).element_sum());
            estimated += f64::from(noisy.variance[i].element_sum());
        }
        let ratio = estimated / squared;
        println!("{spp} spp: estimated variance {estimated:.3}, squared error {squared:.3}, ratio {ratio:.1}");
        // Independent samples would make the ratio 1; the stratified sampler's error is
        // lower (and falls faster with spp), so the layer bounds it from above.
        assert!(ratio > 1.0, "{spp} spp: ratio {ratio:.2}");
    }
}

#[test]
fn clamp_indirect_darkens_only_indirect_light_and_removes_fireflies() {
    use tracer::integrator::trace_sample;

    let f = frame(tracer::demo::demo_scene(), 32, 24);
    let free = RenderSettings::default();
    let clamped = RenderSettings {
        clamp_indirect: Some(1.0),
        ..free
    };
    // Direct light alone (one bounce) is never clamped, and a limit above every path's
    // light changes nothing, to the bit.
    let direct = RenderSettings {
        max_depth: 1,
        ..free
    };
    let direct_clamped = RenderSettings {
        clamp_indirect: Some(1e-3),
        ..direct
    };
    assert_eq!(render(&f, &direct, 4), render(&f, &direct_clamped, 4));
    let huge = RenderSettings {
        clamp_indirect: Some(f32::MAX),
        ..free
    };
    assert_eq!(render(&f, &free, 4), render(&f, &huge, 4));

    // Sample by sample, clamping only takes light away.
    let mut brightest = (0.0f32, 0.0f32);
    let mut fewer = 0;
    for (x, y, i) in (0..32)
        .flat_map(|x| (0..24).map(move |y| (x, y, 0..16)))
        .flat_map(|(x, y, r)| r.map(move |i| (x, y, i)))
    {
        let a = trace_sample(&f, &free, x, y, i).radiance;
        let b = trace_sample(&f, &clamped, x, y, i).radiance;
        assert!(
            b.cmple(a + 1e-6).all(),
            "pixel {x},{y} sample {i}: {b} above {a}"
        );
        fewer += usize::from(b != a);
        brightest = (
            brightest.0.max(a.max_element()),
            brightest.1.max(b.max_element()),
        );
    }
    println!(
        "clamped {fewer} of {} samples; brightest {brightest:?}",
        32 * 24 * 16
    );
    assert!(fewer > 0 && brightest.1 < brightest.0);

    // The fireflies go: fewer noisy pixels (the rest are the lamp's edges, seen directly),
    // for a few percent of the light (the caustics the clamped paths carried).
    let (a, b) = (
        render(&f, &free, 16).resolve(),
        render(&f, &clamped, 16).resolve(),
    );
    let noisy = |l: &Layers| l.variance.iter().filter(|v| v.max_element() > 0.01).count();
    let light = |l: &Layers| {
        l.beauty
            .iter()
            .map(|b| f64::from(b.truncate().element_sum()))
            .sum::<f64>()
    };
    let kept = light(&b) / light(&a);
    println!(
        "noisy pixels {} -> {}; clamp 1 keeps {:.1}% of the light",
        noisy(&a),
        noisy(&b),
        kept * 100.0
    );
    assert!(
        noisy(&b) < noisy(&a) && kept > 0.9 && kept < 1.0,
        "kept {kept}"
    );
}

#[test]
fn adaptive_sampling_is_bit_identical_under_any_tile_split() {
    let f = demo_frame();
    let settings = RenderSettings {
        noise: Some(NoiseTarget {
            threshold: 0.1,
            min_samples: 4,
        }),
        ..RenderSettings::default()
    };
    let rect = TileRect::new(0, 0, 24, 24);
    let samples = SampleRange::new(0, 64);
    let whole = render_tile(&f, &settings, rect, samples);
    let counts: Vec<u32> = whole.samples.clone();
    assert!(
        counts.iter().min() < counts.iter().max(),
        "pixels should stop at different counts: {counts:?}"
    );
    for tile_size in [1, 5, 16] {
        let split = render_region(&f, &settings, rect, samples, tile_size, &|_| {});
        assert!(whole == split, "tiles of {tile_size} differ");
    }
}
