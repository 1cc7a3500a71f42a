//! TESSERA_materials_fluorescence: the diffuse fluorescent BBRRDF of Jung et al. 2018, its
//! Stokes shift and energy bound, the wavelengths a camera path samples from it, a
//! single-bounce render against the closed form, and the JSON read and refused.

use std::sync::Arc;

use glam::{DMat4, Vec3, Vec4};

use tracer::light::PunctualLight;
use tracer::loader;
use tracer::material::Material;
use tracer::render::{prepare_frame, FrameOptions, PreparedFrame};
use tracer::scene::SceneBuilder;
use tracer::spectrum::{
    DenseSpectrum, Fluorescence, FluorescenceDef, SigmoidPolynomial, SpectrumShape, LAMBDA_MAX,
    LAMBDA_MIN,
};

mod common;

/// A paint like fluorescein: absorbs blue around 470 nm, glows green around 520 nm.
fn fluorescein(concentration: f32, quantum_yield: f32) -> FluorescenceDef {
    FluorescenceDef {
        excitation: SpectrumShape::Gaussian {
            peak: 470.0,
            width: 60.0,
        },
        emission: SpectrumShape::Gaussian {
            peak: 520.0,
            width: 40.0,
        },
        concentration,
        quantum_yield,
    }
}

/// No light leaves at a shorter wavelength than it arrived at, and what is re-emitted
/// is at most Q times what is absorbed (less where the emission band reaches below the
/// absorbed wavelength); with the reflected part, never more than arrived.
#[test]
fn the_stokes_shift_holds_and_no_energy_is_made() {
    let (c, q) = (0.8, 0.9);
    let paint = Fluorescence::new(&fluorescein(c, q)).expect("a paint");
    for from in common::band() {
        let mut reradiated = 0.0;
        for to in common::band() {
            let (_, f) = paint.bbrrdf(from, to, 1.0);
            if to <= from {
                assert_eq!(f, 0.0, "{from} nm → {to} nm");
            }
            reradiated += f64::from(f);
        }
        let absorbed = f64::from(c * paint.absorption(from));
        assert!(
            reradiated <= f64::from(q) * absorbed * (1.0 + 1e-5),
            "{from} nm"
        );
        let (reflected, _) = paint.bbrrdf(from, from, 1.0);
        assert!(f64::from(reflected) + reradiated <= 1.0 + 1e-5, "{from} nm");
    }
    // Absorbed well below the emission band, nearly all of Q comes back.
    let from = 400.5;
    let reradiated: f32 = common::band().map(|to| paint.bbrrdf(from, to, 1.0).1).sum();
    let want = q * c * paint.absorption(from);
    assert!(
        (reradiated - want).abs() < 1e-3 * want,
        "{reradiated} vs {want}"
    );
}

/// A camera path at λo fluoresces in proportion to what fluorescence contributes, from
/// a wavelength below λo distributed as the absorption there, with the weight that the
/// closed form gives either way: a histogram of 200000 draws against the density.
#[test]
fn the_path_samples_the_absorbed_wavelength_from_the_absorption() {
    let paint = Fluorescence::new(&fluorescein(0.7, 0.8)).expect("a paint");
    let (to, r) = (530.25, 0.3);
    // ∫ a below λo over the 1 nm bins (the one holding λo in part).
    let below: f64 = common::band()
        .map(|nm| f64::from(paint.absorption(nm)) * f64::from((to - (nm - 0.5)).clamp(0.0, 1.0)))
        .sum();
    let reflected = (1.0 - 0.7 * paint.absorption(to)) * r;
    let reradiated = 0.7 * 0.8 * paint.emission(to) * below as f32;
    let mut rng = common::Rng(7);
    let n = 200_000;
    let mut bins = vec![0u32; (LAMBDA_MAX - LAMBDA_MIN) as usize];
    let mut fluoresced = 0;
    for _ in 0..n {
        let step = paint.sample(to, r, rng.f32(), rng.f32());
        let want = reflected + reradiated;
        assert!(
            (step.weight - want).abs() < 1e-5 * want,
            "{} vs {want}",
            step.weight
        );
        if step.nm != to {
            assert!(step.nm < to && step.nm >= LAMBDA_MIN, "{}", step.nm);
            fluoresced += 1;
            bins[(step.nm - LAMBDA_MIN) as usize] += 1;
        }
    }
    let p = f64::from(reradiated / (reflected + reradiated));
    let share = f64::from(fluoresced) / f64::from(n);
    let sigma = (p * (1.0 - p) / f64::from(n)).sqrt();
    assert!(
        (share - p).abs() < 4.0 * sigma,
        "fluoresced {share}, want {p}"
    );
    // Each 10 nm group of bins against its expected count.
    for group in bins.chunks(10).enumerate() {
        let (g, counts) = group;
        let expected: f64 = (0..10)
            .map(|k| {
                let nm = LAMBDA_MIN + (g * 10 + k) as f32 + 0.5;
                let part = f64::from((to - (nm - 0.5)).clamp(0.0, 1.0));
                f64::from(paint.absorption(nm)) * part / below * f64::from(fluoresced)
            })
            .sum();
        let got: u32 = counts.iter().sum();
        let tolerance = 5.0 * expected.sqrt() + 2.0;
        assert!(
            (f64::from(got) - expected).abs() < tolerance,
            "{} nm: {got} draws, {expected:.1} expected",
            LAMBDA_MIN as usize + g * 10
        );
    }
}

/// A flat plane of `material` under a directional light of `illuminance` lux and
/// spectrum `light`, filling the view.
fn lit_plane(material: Material, illuminance: f32, light: SpectrumShape) -> PreparedFrame {
    let mut b = SceneBuilder::default();
    let m = b.material(material);
    common::plane_in_view(&mut b, m);
    b.light_with_spectrum(
        PunctualLight::Directional {
            illuminance: Vec3::splat(illuminance),
        },
        light,
        DMat4::IDENTITY,
    );
    let options = FrameOptions {
        width: 16,
        height: 16,
        ..Default::default()
    };
    prepare_frame(Arc::new(b.finish()), &options).expect("prepares")
}

fn painted(base: f32, paint: FluorescenceDef) -> Material {
    Material {
        base_color: Vec4::new(base, base, base, 1.0),
        metallic: 0.0,
        specular: 0.0,
        fluorescence: Some(paint),
        ..Material::default()
    }
}

/// One bounce off a flat fluorescent plane under a directional light of spectrum S: the
/// camera sees, at each λo, `E/π [(1 − c a(λo)) r(λo) S(λo) + c Q e(λo) ∫_{λ<λo} a(λ)
/// S(λ) dλ]`. Under a narrow blue band at the excitation peak the plane glows green;
/// under light beyond its emission band (600 nm) it only reflects: no light is pushed to
/// a shorter wavelength. Each within 2% of its brightest channel.
#[test]
fn a_single_bounce_matches_the_closed_form() {
    let (c, q, base, illuminance) = (0.9, 0.8, 0.2, 4.0);
    let def = fluorescein(c, q);
    let paint = Fluorescence::new(&def).expect("a paint");
    let r = SigmoidPolynomial::reflectance(Vec3::splat(base));
    for (peak, what) in [(470.0, "excited"), (600.0, "beyond the emission")] {
        let shape = SpectrumShape::Gaussian { peak, width: 6.0 };
        let light = DenseSpectrum::light(&shape).expect("visible");
        let frame = lit_plane(painted(base, def.clone()), illuminance, shape);
        assert!(frame.features.fluorescence && frame.features.needs_spectral());
        let got = common::mean_one_bounce(&frame, 2048);
        let e_over_pi = f64::from(illuminance) / std::f64::consts::PI;
        let want = common::colour_of_spectrum(|to| {
            let (reflected, _) = paint.bbrrdf(to, to, r.eval(to));
            let excited: f64 = common::band()
                .filter(|&from| from < to)
                .map(|from| f64::from(paint.bbrrdf(from, to, 0.0).1 * light.eval(from)))
                .sum();
            e_over_pi * (f64::from(reflected * light.eval(to)) + excited)
        });
        let scale = want.abs().max_element();
        eprintln!("{what}: {got} vs {want}");
        assert!(
            ((got - want) / scale).abs().max_element() < 0.02,
            "{what}: {got} vs {want}"
        );
        if peak == 470.0 {
            assert!(want.y > want.z, "the plane glows green: {want}");
        }
    }
}

/// A paint of concentration 0 (or quantum yield 0) is the plain diffuse surface: the
/// scene needs no spectral path and renders the same image, bit for bit.
#[test]
fn no_paint_is_the_plain_surface() {
    let shape = SpectrumShape::Blackbody(4000.0);
    let plain = lit_plane(painted(0.5, fluorescein(0.0, 1.0)), 2.0, shape.clone());
    let mut without = painted(0.5, fluorescein(0.0, 1.0));
    without.fluorescence = None;
    let reference = lit_plane(without, 2.0, shape.clone());
    assert!(!plain.features.fluorescence);
    assert_eq!(
        common::mean_one_bounce(&plain, 16),
        common::mean_one_bounce(&reference, 16)
    );
    let dark = lit_plane(painted(0.5, fluorescein(1.0, 0.0)), 2.0, shape);
    assert!(!dark.features.fluorescence);
}

fn doc(ext: &str) -> String {
    format!(
        r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["TESSERA_materials_fluorescence"],
        "materials":[{{"extensions":{{"TESSERA_materials_fluorescence":{ext}}}}}]}}"#
    )
}

/// The JSON as `docs/TESSERA_materials_fluorescence.md` gives it, and what is refused.
#[test]
fn the_extension_is_read_and_refused_as_documented() {
    let scene = loader::load_slice(
        doc(r#"{"excitation":{"gaussian":{"peak":365,"width":20}},
            "emission":{"table":[[480,0],[520,1],[600,0]]},"concentration":0.5}"#)
        .as_bytes(),
        None,
    )
    .expect("loads");
    let paint = scene.materials[0].fluorescence.as_ref().expect("read");
    assert_eq!(paint.concentration, 0.5);
    assert_eq!(paint.quantum_yield, 1.0, "the default");
    assert!(scene.materials[0].is_fluorescent());

    let bad = [
        (r#"{"emission":{"blackbody":3000}}"#, "excitation"),
        (
            r#"{"excitation":{"blackbody":3000},"emission":{"blackbody":3000},"concentration":2}"#,
            "concentration",
        ),
        (
            r#"{"excitation":{"blackbody":3000},"emission":{"blackbody":3000},"quantumYield":-1}"#,
            "quantumYield",
        ),
        (
            r#"{"excitation":{"blackbody":3000},"emission":{"blackbody":3000},"quantumYield":1.5}"#,
            "quantumYield",
        ),
        (
            r#"{"excitation":{"table":[]},"emission":{"blackbody":3000}}"#,
            "2 to",
        ),
        (
            r#"{"excitation":{"blackbody":3000},"emission":{"gaussian":{"peak":520,"width":-4}}}"#,
            "not above 0",
        ),
        (
            r#"{"excitation":{"gaussian":{"peak":320,"width":5}},"emission":{"blackbody":3000}}"#,
            "is 0 over",
        ),
        (
            r#"{"excitation":{"blackbody":3000},"emission":{"gaussian":{"peak":-5,"width":5}}}"#,
            "outside",
        ),
        ("[]", "not an object"),
    ];
    for (json, why) in bad {
        let err = loader::load_slice(doc(json).as_bytes(), None)
            .expect_err(json)
            .to_string();
        assert!(
            err.contains("TESSERA_materials_fluorescence")
                && err.contains(why)
                && err.contains("material 0"),
            "{json}: {err}"
        );
    }
}
