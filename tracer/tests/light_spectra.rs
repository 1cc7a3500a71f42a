//! TESSERA_lights_spectrum: lights and emissive materials of their own spectrum, against
//! the closed form of what the camera sees, and the extension's JSON read, refused and
//! written back.

use std::sync::Arc;

use glam::{DMat4, Vec3, Vec4};

use tracer::light::{Environment, PunctualLight};
use tracer::loader;
use tracer::material::Material;
use tracer::render::{prepare_frame, FrameOptions, PreparedFrame};
use tracer::scene::SceneBuilder;
use tracer::spectrum::{self, DenseSpectrum, SpectrumShape};

mod common;

fn frame(b: SceneBuilder) -> PreparedFrame {
    let options = FrameOptions {
        width: 16,
        height: 16,
        ..Default::default()
    };
    prepare_frame(Arc::new(b.finish()), &options).expect("prepares")
}

fn shapes() -> [(&'static str, SpectrumShape); 5] {
    [
        ("a warm blackbody", SpectrumShape::Blackbody(2700.0)),
        ("a blue-white blackbody", SpectrumShape::Blackbody(12000.0)),
        (
            "a green LED",
            SpectrumShape::Gaussian {
                peak: 530.0,
                width: 30.0,
            },
        ),
        (
            "an ultraviolet LED",
            SpectrumShape::Gaussian {
                peak: 365.0,
                width: 10.0,
            },
        ),
        (
            "a table",
            SpectrumShape::Table(vec![(400.0, 0.0), (600.0, 2.0), (700.0, 0.5)]),
        ),
    ]
}

/// A directional light of E lux and spectrum S on a white Lambertian plane: every pixel
/// sees radiance E/π at each wavelength times S scaled to white's power over 360–830 nm,
/// the colour of which the closed form gives. Within 1.5% of the brightest channel (an
/// ultraviolet lamp shows next to nothing, as it should); the light's colour filters its
/// spectrum.
#[test]
fn a_light_of_its_own_spectrum_lights_as_the_closed_form_says() {
    let illuminance = 3.0;
    for (colour, name_of_colour) in [(Vec3::ONE, "white"), (Vec3::new(1.0, 0.5, 0.25), "orange")] {
        for (name, shape) in shapes() {
            let mut b = SceneBuilder::default();
            let white = b.material(Material {
                base_color: Vec4::ONE,
                metallic: 0.0,
                specular: 0.0,
                ..Material::default()
            });
            common::plane_in_view(&mut b, white);
            b.light_with_spectrum(
                PunctualLight::Directional {
                    illuminance: colour * illuminance,
                },
                shape.clone(),
                DMat4::IDENTITY,
            );
            let frame = frame(b);
            assert!(frame.features.light_spectra && frame.features.needs_spectral());
            let got = common::mean_one_bounce(&frame, 256);
            let dense = DenseSpectrum::light(&shape).expect("visible power");
            let filter = spectrum::UnboundedSpectrum::new(colour);
            let want = common::colour_of_spectrum(|nm| f64::from(dense.eval(nm) * filter.eval(nm)))
                * (illuminance / std::f32::consts::PI);
            let scale = want.abs().max_element().max(0.05);
            eprintln!("{name}, {name_of_colour}: {got} vs {want}");
            assert!(
                ((got - want) / scale).abs().max_element() < 0.015,
                "{name}, {name_of_colour}: {got} vs {want}"
            );
        }
    }
}

/// An emissive quad of its own spectrum, seen head on, shows its emission's colour.
#[test]
fn an_emissive_material_of_its_own_spectrum_shows_its_colour() {
    let shape = SpectrumShape::Gaussian {
        peak: 610.0,
        width: 40.0,
    };
    let mut b = SceneBuilder::default();
    let glow = b.material(Material {
        base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
        emissive: Vec3::splat(2.0),
        emission_spectrum: Some(shape.clone()),
        ..Material::default()
    });
    common::plane_in_view(&mut b, glow);
    b.environment(Environment::Black);
    let frame = frame(b);
    assert!(frame.features.light_spectra);
    let got = common::mean_one_bounce(&frame, 256);
    let dense = DenseSpectrum::light(&shape).expect("visible power");
    let want = common::colour_of_spectrum(|nm| 2.0 * f64::from(dense.eval(nm)));
    assert!(
        ((got - want) / want.max_element()).abs().max_element() < 0.015,
        "{got} vs {want}"
    );
}

/// Blackbody light near D65's temperature lights nearly as white light does (within 8%):
/// the normalisation keeps an intensity's meaning.
#[test]
fn a_blackbody_near_d65_is_nearly_white() {
    let dense = DenseSpectrum::light(&SpectrumShape::Blackbody(6504.0)).expect("visible");
    // (0.977, 0.921, 0.970): D65 is not quite Planckian, and a blackbody spends more of
    // its power where the eye is less sensitive.
    let c = common::colour_of_spectrum(|nm| f64::from(dense.eval(nm)));
    assert!((c - Vec3::ONE).abs().max_element() < 0.09, "{c}");
}

fn doc(light_ext: &str, material_ext: &str) -> String {
    format!(
        r#"{{"asset":{{"version":"2.0"}},
        "extensionsUsed":["KHR_lights_punctual","TESSERA_lights_spectrum"],
        "extensions":{{"KHR_lights_punctual":{{"lights":[{{"type":"point","intensity":5,
            "extensions":{{"TESSERA_lights_spectrum":{light_ext}}}}}]}}}},
        "materials":[{{"emissiveFactor":[1,1,1],
            "extensions":{{"TESSERA_lights_spectrum":{material_ext}}}}}]}}"#
    )
}

/// The JSON as `docs/TESSERA_lights_spectrum.md` gives it, on a light and a material.
#[test]
fn the_extension_is_read_as_documented() {
    let scene = loader::load_slice(
        doc(
            r#"{"blackbody":3200}"#,
            r#"{"table":[[380,0],[550,1],[780,0.25]]}"#,
        )
        .as_bytes(),
        None,
    )
    .expect("loads");
    assert_eq!(scene.light_spectra[&0], SpectrumShape::Blackbody(3200.0));
    assert_eq!(
        scene.materials[0].emission_spectrum,
        Some(SpectrumShape::Table(vec![
            (380.0, 0.0),
            (550.0, 1.0),
            (780.0, 0.25)
        ]))
    );
    let scene = loader::load_slice(
        doc(
            r#"{"gaussian":{"peak":365,"width":12}}"#,
            r#"{"blackbody":2000}"#,
        )
        .as_bytes(),
        None,
    )
    .expect("loads");
    assert_eq!(
        scene.light_spectra[&0],
        SpectrumShape::Gaussian {
            peak: 365.0,
            width: 12.0
        }
    );
}

/// What is no spectrum is refused, naming the extension and what is wrong.
#[test]
fn what_is_no_spectrum_is_refused() {
    let bad = [
        (r#"{}"#, "exactly one"),
        (
            r#"{"blackbody":3000,"gaussian":{"peak":500,"width":10}}"#,
            "exactly one",
        ),
        (r#"{"blackbody":"warm"}"#, "not a number"),
        (r#"{"blackbody":20}"#, "outside"),
        (r#"{"gaussian":{"peak":500}}"#, "Gaussian width"),
        (r#"{"gaussian":{"peak":500,"width":0}}"#, "not above 0"),
        (r#"{"gaussian":{"peak":500,"width":-20}}"#, "not above 0"),
        (r#"{"gaussian":{"peak":290,"width":10}}"#, "outside"),
        (r#"{"gaussian":{"peak":1200,"width":10}}"#, "outside"),
        (r#"{"gaussian":{"peak":320,"width":5}}"#, "no power"),
        (r#"{"table":[]}"#, "2 to"),
        (r#"{"table":[[500,1]]}"#, "2 to"),
        (r#"{"table":[[500,1],[1500,1]]}"#, "outside"),
        (r#"{"table":[[500,1],[400,1]]}"#, "do not increase"),
        (r#"{"table":[[500,1],[600,-1]]}"#, "at least 0"),
        (r#"{"table":[[500,1],[600]]}"#, "[nm, value]"),
        (r#"{"table":"flat"}"#, "not an array"),
        ("3", "not an object"),
    ];
    for (json, why) in bad {
        for (light, material) in [
            (json, r#"{"blackbody":3000}"#),
            (r#"{"blackbody":3000}"#, json),
        ] {
            let err = loader::load_slice(doc(light, material).as_bytes(), None)
                .expect_err(json)
                .to_string();
            let named = if light == json {
                "light 0"
            } else {
                "material 0"
            };
            assert!(
                err.contains("TESSERA_lights_spectrum") && err.contains(why) && err.contains(named),
                "{json}: {err}"
            );
        }
    }
    let rows = vec!["[500,1]"; spectrum::MAX_TABLE_ENTRIES + 1].join(",");
    let err = loader::load_slice(
        doc(&format!(r#"{{"table":[{rows}]}}"#), "{\"blackbody\":3000}").as_bytes(),
        None,
    )
    .expect_err("too long")
    .to_string();
    assert!(err.contains("at most"), "{err}");
}
