//! The tables against the figures they must give, and the wavelength estimator against
//! the integrals it estimates.
#![allow(clippy::disallowed_methods)] // the independent fit uses the platform's maths

use super::*;

/// Chromaticity (x, y) of XYZ.
fn xy(c: glam::DVec3) -> (f64, f64) {
    let s = c.x + c.y + c.z;
    (c.x / s, c.y / s)
}

#[test]
fn the_tables_give_the_standard_integrals_and_white_points() {
    let one = [1.0; SAMPLES];
    let y = integral(&Y_BAR, &one);
    assert!((y - 106.857).abs() < 0.01, "∫ȳ = {y}");
    let d65 = glam::DVec3::new(
        integral(&X_BAR, &D65),
        integral(&Y_BAR, &D65),
        integral(&Z_BAR, &D65),
    );
    let (x, y) = xy(d65);
    assert!(
        (x - 0.31271).abs() < 5e-5 && (y - 0.32902).abs() < 5e-5,
        "D65 at ({x}, {y})"
    );
    // Equal energy is white in XYZ: the three functions have (nearly) equal integrals.
    let e = glam::DVec3::new(
        integral(&X_BAR, &one),
        integral(&Y_BAR, &one),
        integral(&Z_BAR, &one),
    );
    let (x, y) = xy(e);
    assert!(
        (x - 1.0 / 3.0).abs() < 1e-3 && (y - 1.0 / 3.0).abs() < 1e-3,
        "E at ({x}, {y})"
    );
}

#[test]
fn the_colour_matching_functions_follow_an_independent_fit() {
    // Wyman, Sloan & Shirley 2013's multi-lobe fit of the same functions: a wrong digit in
    // a table shows as a spike against it.
    let lobe = |x: f64, mu: f64, left: f64, right: f64| {
        let t = (x - mu) / if x < mu { left } else { right };
        (-0.5 * t * t).exp()
    };
    let fit = |nm: f64| {
        [
            1.056 * lobe(nm, 599.8, 37.9, 31.0) + 0.362 * lobe(nm, 442.0, 16.0, 26.7)
                - 0.065 * lobe(nm, 501.1, 20.4, 26.2),
            0.821 * lobe(nm, 568.8, 46.9, 40.5) + 0.286 * lobe(nm, 530.9, 16.3, 31.1),
            1.217 * lobe(nm, 437.0, 11.8, 36.0) + 0.681 * lobe(nm, 459.0, 26.0, 13.8),
        ]
    };
    let mut worst = 0.0f64;
    for nm in (360..=830).step_by(5) {
        let table = cmf(nm as f32).to_array();
        for (t, f) in table.iter().zip(fit(f64::from(nm))) {
            worst = worst.max((f64::from(*t) - f).abs());
        }
    }
    assert!(worst < 0.03, "largest difference {worst}");
}

#[test]
fn the_visible_distribution_integrates_to_one_and_samples_invert_it() {
    // Its distribution function by the midpoint rule on a fine grid.
    let n = 47_000;
    let h = (LAMBDA_MAX - LAMBDA_MIN) as f64 / n as f64;
    let mut cdf = Vec::with_capacity(n + 1);
    let mut sum = 0.0f64;
    cdf.push(0.0);
    for i in 0..n {
        let nm = LAMBDA_MIN as f64 + (i as f64 + 0.5) * h;
        sum += f64::from(visible_pdf(nm as f32)) * h;
        cdf.push(sum);
    }
    assert!((sum - 1.0).abs() < 1e-3, "∫pdf = {sum}");
    for k in 0..100 {
        let u = (k as f32 + 0.5) / 100.0;
        let nm = sample_visible(u);
        let i = ((f64::from(nm - LAMBDA_MIN) / h) as usize).min(n);
        assert!(
            (cdf[i] - f64::from(u)).abs() < 2e-3,
            "u {u}: λ {nm}, F(λ) {}",
            cdf[i]
        );
    }
    assert_eq!(visible_pdf(359.0), 0.0);
    assert_eq!(visible_pdf(831.0), 0.0);
}

/// The mean of the estimate of `s` over `m` stratified hero wavelengths.
fn mean_rec709(m: usize, terminate: bool, s: impl Fn(f32) -> f32) -> Vec3 {
    let mut sum = glam::DVec3::ZERO;
    for k in 0..m {
        let mut w = SampledWavelengths::sample_visible((k as f32 + 0.5) / m as f32);
        if terminate {
            w.terminate_secondary();
        }
        let values = Vec4::from_array(w.lambda.map(&s));
        sum += to_rec709(values, &w).as_dvec3();
    }
    (sum / m as f64).as_vec3()
}

#[test]
fn d65_is_rec709_white_and_a_flat_spectrum_has_unit_luminance() {
    for terminate in [false, true] {
        let white = mean_rec709(4096, terminate, d65);
        assert!(
            (white - Vec3::ONE).abs().max_element() < 2e-3,
            "D65 gives {white} (hero alone: {terminate})"
        );
        let flat = mean_rec709(4096, terminate, |_| 1.0);
        let luminance = (flat.dot(Vec3::new(0.2126, 0.7152, 0.0722)) - 1.0).abs();
        assert!(
            luminance < 2e-3,
            "flat spectrum: {flat}, hero alone: {terminate}"
        );
    }
}

#[test]
fn the_four_wavelengths_stratify_the_distribution_and_the_hero_can_go_alone() {
    let mut w = SampledWavelengths::sample_visible(0.9);
    // u = 0.9, 0.15, 0.4, 0.65: one in each quarter of the distribution.
    let mut sorted = w.lambda;
    sorted.sort_by(f32::total_cmp);
    for (q, nm) in sorted.iter().enumerate() {
        let quarter = sample_visible(0.25 * q as f32)..sample_visible(0.25 * (q + 1) as f32);
        assert!(quarter.contains(nm), "{nm} outside {quarter:?}");
    }
    assert_eq!(w.lambda[0], sample_visible(0.9));
    assert!(!w.secondary_terminated());
    let hero = (w.lambda[0], w.pdf[0]);
    w.terminate_secondary();
    w.terminate_secondary();
    assert!(w.secondary_terminated());
    assert_eq!(w.lambda[0], hero.0);
    assert_eq!(w.pdf, [hero.1 / 4.0, 0.0, 0.0, 0.0]);
}

/// Linear Rec. 709 of light with spectrum `s`, by the midpoint rule at 0.5 nm.
fn rec709_of(s: impl Fn(f32) -> f32) -> Vec3 {
    let mut xyz = glam::DVec3::ZERO;
    let h = 0.5;
    let mut nm = LAMBDA_MIN + 0.5 * h;
    while nm < LAMBDA_MAX {
        xyz += cmf(nm).as_dvec3() * f64::from(s(nm)) * f64::from(h);
        nm += h;
    }
    XYZ_TO_REC709 * (xyz / f64::from(*Y_INTEGRAL)).as_vec3()
}

#[test]
fn reflectance_spectra_under_d65_give_their_colour_back() {
    let mut rng = crate::test_rng::Rng(17);
    let (mut worst, mut total) = (0.0f32, 0.0f32);
    let n = 500;
    for _ in 0..n {
        let rgb = rng.vec3();
        let s = SigmoidPolynomial::reflectance(rgb);
        let back = rec709_of(|nm| s.eval(nm) * d65(nm));
        let err = (back - rgb).abs().max_element();
        worst = worst.max(err);
        total += err;
    }
    // The table's resolution (64) bounds this: 0.003 at worst, 1e-4 on average.
    assert!(worst < 0.005, "worst {worst}");
    assert!(total / (n as f32) < 5e-4, "mean {}", total / n as f32);
}

#[test]
fn greys_are_flat_and_every_reflectance_stays_in_zero_one() {
    for r in [0.0, 0.25, 0.5, 0.73, 1.0] {
        let s = SigmoidPolynomial::reflectance(Vec3::splat(r));
        for nm in (360..=830).step_by(10) {
            assert!(
                (s.eval(nm as f32) - r).abs() < 1e-6,
                "{r} at {nm}: {}",
                s.eval(nm as f32)
            );
        }
    }
    let mut rng = crate::test_rng::Rng(3);
    for _ in 0..200 {
        // Saturated and out-of-range colours too: channels are clamped.
        let rgb = rng.vec3() * 1.5 - 0.2;
        let s = SigmoidPolynomial::reflectance(rgb);
        for nm in (360..=830).step_by(10) {
            let v = s.eval(nm as f32);
            assert!((0.0..=1.0).contains(&v), "{rgb} at {nm}: {v}");
        }
    }
}

#[test]
fn light_of_any_strength_gives_its_colour_back() {
    for rgb in [
        Vec3::ONE,
        Vec3::new(17.0, 12.0, 4.0),
        Vec3::new(0.02, 0.5, 3.0),
        Vec3::new(1e4, 0.0, 0.0),
    ] {
        let l = IlluminantSpectrum::new(rgb);
        let back = rec709_of(|nm| l.eval(nm));
        let err = ((back - rgb).abs() / rgb.max_element()).max_element();
        assert!(err < 0.005, "{rgb} came back {back}");
    }
    // Exactly D65 for white, so that a white surface under white light is the same in the
    // spectral path as in the RGB one.
    let white = IlluminantSpectrum::new(Vec3::ONE);
    for nm in (360..=830).step_by(10) {
        let nm = nm as f32;
        assert!((white.eval(nm) - d65(nm)).abs() <= 1e-6 * d65(nm));
    }
    assert_eq!(IlluminantSpectrum::new(Vec3::ZERO).eval(550.0), 0.0);
}
