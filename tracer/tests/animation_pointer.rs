//! KHR_animation_pointer: a light's colour and intensity, a material's emission and
//! factors animated over a shot, read from a file and rendered frame by frame.

use std::sync::Arc;

use glam::{DMat4, DVec3, Vec3, Vec4};

use tracer::animation::{self, Animation, Interpolation, Property, PropertyChannel, Sampler};
use tracer::light::PunctualLight;
use tracer::loader;
use tracer::material::Material;
use tracer::render::{prepare_frame, FrameOptions};
use tracer::scene::{Scene, SceneBuilder};

mod common;

use common::gltf_doc::Doc;

/// A quad of material 0 lit by directional light 0, with `samplers` and `channels` as
/// the one animation's.
fn document(doc: &mut Doc, samplers: &str, channels: &str) -> String {
    let p = doc.vec3(&[
        [-1.0, -1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
    ]);
    let n = doc.vec3(&[[0.0, 0.0, 1.0]; 4]);
    doc.json(&format!(
        r#","extensionsUsed":["KHR_animation_pointer","KHR_lights_punctual","KHR_materials_emissive_strength"],
        "extensions":{{"KHR_lights_punctual":{{"lights":[{{"type":"directional","color":[1,0.5,0.25],"intensity":8}}]}}}},
        "materials":[{{"emissiveFactor":[0.5,0.25,1],
            "extensions":{{"KHR_materials_emissive_strength":{{"emissiveStrength":4}}}}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n}}},"material":0}}]}}],
        "scenes":[{{"nodes":[0,1]}}],
        "nodes":[{{"mesh":0}},{{"extensions":{{"KHR_lights_punctual":{{"light":0}}}}}}],
        "animations":[{{"samplers":[{samplers}],"channels":[{channels}]}}]"#
    ))
}

fn pointer_channel(sampler: usize, pointer: &str) -> String {
    format!(
        r#"{{"sampler":{sampler},"target":{{"path":"pointer","extensions":{{"KHR_animation_pointer":{{"pointer":"{pointer}"}}}}}}}}"#
    )
}

/// The channels of the pointers Tessera animates become properties of lights and
/// materials, each half of a product (colour × intensity, factor × strength) multiplied
/// by the other's static value; a pointer it does not animate is skipped with a warning.
#[test]
fn pointer_channels_drive_lights_and_materials() {
    let mut doc = Doc::default();
    let t = doc.scalars(&[0.0, 1.0]);
    let intensity = doc.scalars(&[0.0, 8.0]);
    let strength = doc.scalars(&[0.0, 4.0]);
    let base = doc.vec4(&[[1.0, 1.0, 1.0, 1.0], [0.2, 0.4, 0.6, 1.0]]);
    let metallic = doc.scalars(&[0.0, 1.0]);
    let roughness = doc.scalars(&[1.0, 0.25]);
    let samplers = [
        format!(r#"{{"input":{t},"output":{intensity},"interpolation":"STEP"}}"#),
        format!(r#"{{"input":{t},"output":{strength}}}"#),
        format!(r#"{{"input":{t},"output":{base}}}"#),
        format!(r#"{{"input":{t},"output":{metallic},"interpolation":"STEP"}}"#),
        format!(r#"{{"input":{t},"output":{roughness}}}"#),
    ]
    .join(",");
    let channels = [
        pointer_channel(0, "/extensions/KHR_lights_punctual/lights/0/intensity"),
        pointer_channel(
            1,
            "/materials/0/extensions/KHR_materials_emissive_strength/emissiveStrength",
        ),
        pointer_channel(2, "/materials/0/pbrMetallicRoughness/baseColorFactor"),
        pointer_channel(3, "/materials/0/pbrMetallicRoughness/metallicFactor"),
        pointer_channel(4, "/materials/0/pbrMetallicRoughness/roughnessFactor"),
        pointer_channel(3, "/materials/0/alphaCutoff"),
    ]
    .join(",");
    let scene = loader::load_slice(document(&mut doc, &samplers, &channels).as_bytes(), None)
        .expect("loads");
    let properties = &scene.animations[0].properties;
    let kinds: Vec<Property> = properties.iter().map(|p| p.property).collect();
    assert_eq!(
        kinds,
        [
            Property::Light(0),
            Property::Emission(0),
            Property::BaseColor(0),
            Property::Metallic(0),
            Property::Roughness(0)
        ]
    );
    assert_eq!(properties[0].sampler.values, [0.0, 0.0, 0.0, 8.0, 4.0, 2.0]);
    assert_eq!(properties[1].sampler.values, [0.0, 0.0, 0.0, 2.0, 1.0, 4.0]);
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("channel 5") && w.contains("alphaCutoff")),
        "{:?}",
        scene.warnings
    );
    assert_eq!(scene.animations[0].time_range(), Some((0.0, 1.0)));

    let light = |t| match animation::lights_at(&scene, &[0], t)[0] {
        PunctualLight::Directional { illuminance } => illuminance,
        _ => unreachable!("a directional light"),
    };
    assert_eq!(light(0.5), Vec3::ZERO, "STEP holds the first key");
    assert_eq!(light(1.0), Vec3::new(8.0, 4.0, 2.0));
    let m = &animation::materials_at(&scene, &[0], 0.5).expect("animated")[0];
    assert!(
        (m.base_color - Vec4::new(0.6, 0.7, 0.8, 1.0))
            .abs()
            .max_element()
            < 1e-6
    );
    assert!((m.emissive - Vec3::new(1.0, 0.5, 2.0)).abs().max_element() < 1e-6);
    assert_eq!((m.metallic, m.roughness), (0.0, 0.625));
    // Nothing plays: the scene's own values.
    assert!(animation::materials_at(&scene, &[], 0.5).is_none());
}

/// What a file cannot mean is refused: a light or material out of range, a sampler out of
/// range, and both halves of one product animated.
#[test]
fn pointer_channels_that_cannot_be_followed_are_refused() {
    let cases = [
        (
            vec![pointer_channel(
                0,
                "/extensions/KHR_lights_punctual/lights/3/intensity",
            )],
            "light 3 out of range",
        ),
        (
            vec![pointer_channel(0, "/materials/7/emissiveFactor")],
            "material 7 out of range",
        ),
        (
            vec![pointer_channel(
                5,
                "/materials/0/pbrMetallicRoughness/metallicFactor",
            )],
            "sampler 5 out of range",
        ),
        (
            vec![
                pointer_channel(0, "/extensions/KHR_lights_punctual/lights/0/intensity"),
                pointer_channel(1, "/extensions/KHR_lights_punctual/lights/0/color"),
            ],
            "other half",
        ),
    ];
    for (channels, why) in cases {
        let mut doc = Doc::default();
        let t = doc.scalars(&[0.0, 1.0]);
        let scalar = doc.scalars(&[0.0, 1.0]);
        let colour = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]);
        let samplers =
            format!(r#"{{"input":{t},"output":{scalar}}},{{"input":{t},"output":{colour}}}"#);
        let json = document(&mut doc, &samplers, &channels.join(","));
        let err = loader::load_slice(json.as_bytes(), None)
            .expect_err(why)
            .to_string();
        assert!(err.contains(why), "{why}: {err}");
    }
}

/// A white plane under a directional light whose illuminance rises linearly from 0 to E
/// over two seconds while the plane's base colour fades from white to (0.2, 0.4, 0.6):
/// each frame shows `E(t)/π · colour(t)`, the values at the frame's time.
#[test]
fn a_light_and_a_colour_change_over_a_shot() {
    let e = 6.0;
    let mut b = SceneBuilder::default();
    let m = b.material(Material {
        base_color: Vec4::ONE,
        metallic: 0.0,
        specular: 0.0,
        ..Material::default()
    });
    common::plane_in_view(&mut b, m);
    b.light(
        PunctualLight::Directional {
            illuminance: Vec3::splat(e),
        },
        DMat4::IDENTITY,
    );
    let linear = |values: Vec<f32>, width| Sampler {
        interpolation: Interpolation::Linear,
        times: vec![0.0, 2.0],
        values,
        width,
    };
    b.animation(Animation {
        name: Some("dawn".into()),
        channels: Vec::new(),
        properties: vec![
            PropertyChannel {
                property: Property::Light(0),
                sampler: linear(vec![0.0, 0.0, 0.0, e, e, e], 3),
            },
            PropertyChannel {
                property: Property::BaseColor(m),
                sampler: linear(vec![1.0, 1.0, 1.0, 1.0, 0.2, 0.4, 0.6, 1.0], 4),
            },
        ],
    });
    let scene: Arc<Scene> = Arc::new(b.finish());
    for frame in [0, 12, 24, 48] {
        let options = FrameOptions {
            width: 8,
            height: 8,
            frame,
            fps: 24.0,
            ..Default::default()
        };
        let prepared = prepare_frame(scene.clone(), &options).expect("prepares");
        let mean = common::mean_one_bounce(&prepared, 4).as_dvec3();
        let t = (f64::from(frame) / 24.0).min(2.0) / 2.0;
        let colour = DVec3::ONE.lerp(DVec3::new(0.2, 0.4, 0.6), t);
        let want = colour * (f64::from(e) * t / std::f64::consts::PI);
        assert!(
            (mean - want).abs().max_element() < 1e-4 * (1.0 + want.max_element()),
            "frame {frame}: {mean} vs {want}"
        );
    }
}
