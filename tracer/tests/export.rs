//! GLB export: the built-in scenes written by `scene_to_glb` and read back by `load_glb`
//! are the same scenes (same summary, same data, the same image to the bit, animated ones
//! with motion blur too); a scene exercising the parts the demos do not use survives the
//! round trip; and what the exporter cannot write is refused with an error naming it.

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use std::sync::Arc;

use glam::{DMat4, DQuat, DVec3, Vec3, Vec4};

use tracer::animation::{
    Animation, Channel, Interpolation, Property, PropertyChannel, Sampler, Target,
};
use tracer::camera::Projection;
use tracer::demo;
use tracer::export::{scene_to_glb, ExportError};
use tracer::film::{SampleRange, TileBuffer, TileRect};
use tracer::light::{Environment, EnvironmentMap, PunctualLight};
use tracer::loader::{load_glb, SceneSummary};
use tracer::material::{AlphaMode, Material, Metamaterial};
use tracer::motion::Shutter;
use tracer::render::{prepare_frame, render_tile, FrameOptions, RenderSettings};
use tracer::scene::{CameraDef, MorphTarget, Node, Scene, SceneBuilder, Skin, Trs};
use tracer::shapes::{cube, quad};
use tracer::spectrum::{FluorescenceDef, SpectrumShape};
use tracer::texture::TextureRef;

const WIDTH: u32 = 24;
const HEIGHT: u32 = 18;
const SPP: u32 = 4;

fn round_trip(scene: &Scene) -> Scene {
    let glb = scene_to_glb(scene).expect("the scene exports");
    load_glb(&glb).unwrap_or_else(|e| panic!("the exported GLB loads: {e}"))
}

/// Renders the whole small image with the scene's own environment (the demos' black one
/// travels in the GLB's scene extras).
fn render(scene: &Arc<Scene>, frame: i32, shutter: Shutter) -> TileBuffer {
    let options = FrameOptions {
        frame,
        shutter,
        width: WIDTH,
        height: HEIGHT,
        ..Default::default()
    };
    let prepared = prepare_frame(scene.clone(), &options).expect("the frame prepares");
    render_tile(
        &prepared,
        &RenderSettings::default(),
        TileRect::new(0, 0, WIDTH, HEIGHT),
        SampleRange::new(0, SPP),
    )
}

/// Every layer bit for bit (`PartialEq` on floats would also call -0 and 0 equal).
fn assert_bit_identical(a: &TileBuffer, b: &TileBuffer, what: &str) {
    let bits = |t: &TileBuffer| {
        let mut v: Vec<u32> = Vec::new();
        v.extend(t.beauty.iter().flat_map(|p| p.to_array().map(f32::to_bits)));
        v.extend(t.albedo.iter().flat_map(|p| p.to_array().map(f32::to_bits)));
        v.extend(t.normal.iter().flat_map(|p| p.to_array().map(f32::to_bits)));
        v.extend(t.depth.iter().map(|d| d.to_bits()));
        v.extend(&t.hits);
        v.extend(&t.samples);
        v
    };
    assert!(
        a.beauty.iter().any(|p| p.truncate().max_element() > 0.0),
        "{what}: the image is black, which would prove nothing"
    );
    assert_eq!(a.dropped, b.dropped, "{what}: dropped samples");
    let (a, b) = (bits(a), bits(b));
    let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert!(differ == 0, "{what}: {differ} values differ");
}

/// The loaded scene holds the same data as the original, field by field. `Debug` prints
/// floats so that they read back exactly, so equal text is equal bits.
fn assert_same_data(original: &Scene, loaded: &Scene) {
    let dbg = |v: &dyn std::fmt::Debug| format!("{v:?}");
    assert_eq!(
        dbg(&original.materials),
        dbg(&loaded.materials),
        "materials"
    );
    assert_eq!(dbg(&original.cameras), dbg(&loaded.cameras), "cameras");
    assert_eq!(dbg(&original.lights), dbg(&loaded.lights), "lights");
    assert_eq!(
        dbg(&original.light_spectra),
        dbg(&loaded.light_spectra),
        "light spectra"
    );
    assert_eq!(
        dbg(&original.animations),
        dbg(&loaded.animations),
        "animations"
    );
    assert_eq!(original.roots, loaded.roots, "roots");
    assert_eq!(original.nodes.len(), loaded.nodes.len(), "node count");
    for (i, (a, b)) in original.nodes.iter().zip(&loaded.nodes).enumerate() {
        assert_eq!(a.name, b.name, "node {i} name");
        assert_eq!(a.children, b.children, "node {i} children");
        assert_eq!(
            (a.mesh, a.camera, a.light, a.skin),
            (b.mesh, b.camera, b.light, b.skin),
            "node {i} attachments"
        );
        assert_eq!(a.weights, b.weights, "node {i} weights");
        assert_eq!(a.trs.is_some(), b.trs.is_some(), "node {i} TRS or matrix");
        // glTF stores transforms in f32: the f64 ones come back rounded to f32.
        assert!(
            a.local.abs_diff_eq(b.local, 1e-6),
            "node {i}: {} became {}",
            a.local,
            b.local
        );
    }
    assert_eq!(original.meshes.len(), loaded.meshes.len(), "mesh count");
    for (m, (a, b)) in original.meshes.iter().zip(&loaded.meshes).enumerate() {
        assert_eq!(a.name, b.name, "mesh {m} name");
        assert_eq!(a.weights, b.weights, "mesh {m} weights");
        assert_eq!(
            a.primitives.len(),
            b.primitives.len(),
            "mesh {m} primitives"
        );
        for (p, (x, y)) in a.primitives.iter().zip(&b.primitives).enumerate() {
            let at = format!("mesh {m} primitive {p}");
            assert_eq!(x.positions, y.positions, "{at} positions");
            assert_eq!(x.indices, y.indices, "{at} indices");
            assert_eq!(x.material, y.material, "{at} material");
            assert_eq!(x.uvs, y.uvs, "{at} uvs");
            assert_eq!(x.colors, y.colors, "{at} colours");
            assert_eq!(dbg(&x.targets), dbg(&y.targets), "{at} morph targets");
            // The loader renormalises normals and tangents; unit ones stay within an ulp.
            assert_eq!(x.normals.len(), y.normals.len(), "{at} normals");
            for (u, v) in x.normals.iter().zip(&y.normals) {
                assert!(u.abs_diff_eq(*v, 1e-6), "{at}: normal {u} became {v}");
            }
            assert_eq!(x.tangents.len(), y.tangents.len(), "{at} tangents");
            for (u, v) in x.tangents.iter().zip(&y.tangents) {
                assert!(u.abs_diff_eq(*v, 1e-6), "{at}: tangent {u} became {v}");
            }
        }
    }
}

/// `scene` as glTF holds it: node transforms rounded to f32 (rotations renormalised in f64,
/// as the loader does) and normals and tangents renormalised, as the loader does.
fn as_gltf_holds(mut scene: Scene) -> Scene {
    for node in &mut scene.nodes {
        match &mut node.trs {
            Some(trs) => {
                trs.translation = trs.translation.as_vec3().as_dvec3();
                let q = trs.rotation.as_quat().as_dquat();
                trs.rotation = q / q.length();
                trs.scale = trs.scale.as_vec3().as_dvec3();
                node.local = trs.matrix();
            }
            None => node.local = node.local.as_mat4().as_dmat4(),
        }
    }
    for mesh in &mut scene.meshes {
        for prim in &mut mesh.primitives {
            prim.normals.iter_mut().for_each(|n| *n = n.normalize());
            for t in &mut prim.tangents {
                *t = t.truncate().normalize().extend(t.w);
            }
        }
    }
    scene
}

/// Every float layer within a relative 1e-3 of the other (1e-4 absolute below 0.1), and
/// the same hits and samples. An ulp's difference in a transform or a normal moves hit
/// points and bounce directions by about as little, and at 4 samples no path changes its
/// course; the largest difference seen here is about 3e-4 (animated demo, frame 30).
fn assert_close(a: &TileBuffer, b: &TileBuffer, what: &str) {
    let floats = |t: &TileBuffer| {
        let mut v: Vec<f32> = Vec::new();
        v.extend(t.beauty.iter().flat_map(|p| p.to_array()));
        v.extend(t.albedo.iter().flat_map(|p| p.to_array()));
        v.extend(t.normal.iter().flat_map(|p| p.to_array()));
        v.extend(&t.depth);
        v
    };
    for (i, (x, y)) in floats(a).iter().zip(&floats(b)).enumerate() {
        assert!(
            (x - y).abs() <= 1e-3 * x.abs().max(y.abs()).max(0.1),
            "{what}: value {i} is {x} against {y}"
        );
    }
    assert_eq!((&a.hits, &a.samples), (&b.hits, &b.samples), "{what}");
}

/// The round trip of `scene` (built by `build`): the same summary and data, and for each
/// (frame, shutter) the same image. The image is bit-identical to the scene as glTF holds
/// it ([`as_gltf_holds`]); against the original it is only within a tight tolerance,
/// because glTF stores the f64 node transforms in f32 and the loader renormalises the
/// spheres' normals, which `uv_sphere` computes unit to within an ulp or two.
fn check(name: &str, build: fn() -> Scene, frames: &[(i32, Shutter)]) {
    let scene = build();
    let loaded = round_trip(&scene);
    assert_eq!(
        SceneSummary::of(&scene),
        SceneSummary::of(&loaded),
        "{name}"
    );
    assert_same_data(&scene, &loaded);
    let original = Arc::new(scene);
    let held = Arc::new(as_gltf_holds(build()));
    let loaded = Arc::new(loaded);
    for &(frame, shutter) in frames {
        let what = format!("{name}, frame {frame}");
        let image = render(&loaded, frame, shutter);
        assert_bit_identical(&render(&held, frame, shutter), &image, &what);
        assert_close(&render(&original, frame, shutter), &image, &what);
    }
}

#[test]
fn cornell_box_round_trips() {
    check("cornell_box", demo::cornell_box, &[(0, Shutter::default())]);
}

#[test]
fn demo_scene_round_trips() {
    check("demo_scene", demo::demo_scene, &[(0, Shutter::default())]);
}

/// The spectral showcase (fluorescence, light spectra, dispersion, animated emission)
/// before and after the switch.
#[test]
fn the_spectral_showcase_round_trips() {
    check(
        "fluorescence",
        demo::fluorescence_scene,
        &[(12, Shutter::default()), (36, Shutter::default())],
    );
}

#[test]
fn animated_demo_round_trips_with_motion_blur() {
    // Half a frame open: every object moves while the shutter is open at these frames.
    let shutter = Shutter {
        open: -0.25,
        close: 0.25,
    };
    check(
        "animated demo",
        demo::animated_demo_scene,
        &[(7, shutter), (30, shutter)],
    );
}

/// What the demos do not use: a hierarchy with a matrix node, orthographic and perspective
/// cameras, every kind of light, alpha modes, emission above 1, morph targets with a
/// weights channel, STEP and scale channels, TEXCOORD_0, TANGENT (with anisotropy),
/// COLOR_0, light spectra (TESSERA_lights_spectrum) on a light and an emission, a
/// fluorescent paint, and KHR_animation_pointer channels on lights and materials.
fn everything_else() -> Scene {
    let mut b = SceneBuilder::default();
    let masked = b.material(Material {
        name: Some("masked".into()),
        base_color: Vec4::new(0.2, 0.4, 0.6, 0.5),
        alpha_mode: AlphaMode::Mask { cutoff: 0.3 },
        emissive: Vec3::new(3.0, 0.1, 0.0),
        specular_color: Vec3::new(0.5, 0.6, 0.7),
        anisotropy_strength: 0.75,
        anisotropy_rotation: 0.5,
        emission_spectrum: Some(SpectrumShape::Table(vec![
            (400.0, 0.5),
            (500.25, 1.0),
            (700.0, 0.0),
        ])),
        fluorescence: Some(FluorescenceDef {
            excitation: SpectrumShape::Gaussian {
                peak: 380.0,
                width: 30.0,
            },
            emission: SpectrumShape::Blackbody(5000.0),
            concentration: 0.75,
            quantum_yield: 0.5,
        }),
        ..Default::default()
    });
    let blend = b.material(Material {
        alpha_mode: AlphaMode::Blend,
        emissive: Vec3::new(0.3, 1e4 / 3.0, 7.1),
        ior: 1.33,
        transmission: 0.25,
        thickness: 0.5,
        attenuation_color: Vec3::new(0.9, 0.5, 0.25),
        attenuation_distance: 2.0,
        iridescence: 0.75,
        iridescence_ior: 1.7,
        iridescence_thickness_min: 200.0,
        iridescence_thickness_max: 650.0,
        clearcoat: 0.5,
        clearcoat_roughness: 0.25,
        sheen_color: Vec3::new(0.5, 0.25, 1.0),
        sheen_roughness: 0.75,
        diffuse_transmission: 0.4,
        diffuse_transmission_color: Vec3::new(1.0, 0.75, 0.5),
        dispersion: 0.5,
        metamaterial: Some(Metamaterial {
            refractive_index: -1.25,
            impedance: 0.5,
        }),
        ..Default::default()
    });
    let mut sheet = quad(
        [
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        masked,
    );
    sheet.uvs[0] = vec![
        [0.0, 1.0].into(),
        [1.0, 1.0].into(),
        [1.0, 0.0].into(),
        [0.0, 0.0].into(),
    ];
    sheet.tangents = vec![Vec4::new(1.0, 0.0, 0.0, -1.0); 4];
    sheet.colors = vec![Vec4::new(1.0, 0.5, 0.25, 1.0); 4];
    sheet.targets = vec![MorphTarget {
        positions: vec![Vec3::Z * 0.5; 4],
        normals: vec![Vec3::ZERO; 4],
        tangents: Vec::new(),
    }];
    let sheet_node = b.mesh_trs("sheet", vec![sheet], Trs::default());
    let boxy = b.mesh(
        "box",
        vec![cube(blend)],
        DMat4::from_cols_array(&[
            1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.5, 0.25, -3.0, 1.0,
        ]),
    );
    b.camera(
        CameraDef {
            name: Some("ortho".into()),
            projection: Projection::Orthographic {
                xmag: 2.0,
                ymag: 1.5,
                znear: 0.0,
            },
        },
        DMat4::from_translation(DVec3::Z * 4.0),
    );
    b.camera(
        CameraDef {
            name: None,
            projection: Projection::Perspective {
                yfov: 0.7,
                aspect_ratio: None,
                znear: 0.05,
            },
        },
        DMat4::IDENTITY,
    );
    b.light(
        PunctualLight::Point {
            intensity: Vec3::new(40.0, 30.0, 0.1),
            range: Some(12.0),
        },
        DMat4::from_translation(DVec3::Y * 3.0),
    );
    b.light_with_spectrum(
        PunctualLight::Spot {
            intensity: Vec3::splat(0.5),
            range: None,
            inner_cone: 0.2,
            outer_cone: 0.6,
        },
        SpectrumShape::Gaussian {
            peak: 450.0,
            width: 25.0,
        },
        DMat4::IDENTITY,
    );
    b.light(
        PunctualLight::Directional {
            illuminance: Vec3::new(2.5, 2.5, 2.0),
        },
        DMat4::from_quat(DQuat::from_rotation_x(-1.0)),
    );
    let keys = |interpolation, times: Vec<f32>, values: Vec<f32>, width| Sampler {
        interpolation,
        times,
        values,
        width,
    };
    b.animation(Animation {
        name: None,
        // KHR_animation_pointer: a light's and an emission's scale (written as intensity
        // and strength), a base colour and a roughness.
        properties: vec![
            PropertyChannel {
                property: Property::Light(0),
                sampler: keys(
                    Interpolation::Linear,
                    vec![0.0, 0.5],
                    vec![20.0, 15.0, 0.05, 40.0, 30.0, 0.1],
                    3,
                ),
            },
            PropertyChannel {
                property: Property::Emission(masked),
                sampler: keys(
                    Interpolation::Step,
                    vec![0.0, 0.25],
                    vec![1.5, 0.05, 0.0, 3.0, 0.1, 0.0],
                    3,
                ),
            },
            PropertyChannel {
                property: Property::BaseColor(blend),
                sampler: keys(
                    Interpolation::Linear,
                    vec![0.0, 1.0],
                    vec![0.1, 0.2, 0.3, 0.5, 0.3, 0.4, 0.5, 0.5],
                    4,
                ),
            },
            PropertyChannel {
                property: Property::Roughness(masked),
                sampler: keys(Interpolation::Step, vec![0.25], vec![0.5], 1),
            },
        ],
        channels: vec![
            Channel::new(
                sheet_node,
                Target::Weights,
                Interpolation::Linear,
                vec![0.0, 1.0],
                vec![0.0, 1.0],
                1,
            ),
            Channel::new(
                sheet_node,
                Target::Scale,
                Interpolation::Step,
                vec![0.25, 0.5, 0.75],
                vec![1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 1.0, 0.5, 1.0],
                3,
            ),
        ],
    });
    let mut scene = b.finish();
    scene.meshes[0].weights = vec![0.25];
    scene.features.morphing = true;
    // A hierarchy: the sheet hangs under the box, and carries its own morph weights.
    scene.roots.retain(|&r| r != sheet_node);
    scene.nodes[boxy as usize].children.push(sheet_node);
    scene.nodes[sheet_node as usize].weights = Some(vec![0.75]);
    scene
}

#[test]
fn cameras_lights_hierarchies_and_morph_animation_round_trip() {
    let shutter = Shutter {
        open: 0.0,
        close: 0.5,
    };
    check(
        "everything else",
        everything_else,
        &[(6, shutter), (15, shutter)],
    );
    let loaded = round_trip(&everything_else());
    assert!(loaded.nodes[0].trs.is_some() && loaded.nodes[1].trs.is_none());
}

#[test]
fn the_glb_is_laid_out_as_the_spec_says() {
    let glb = scene_to_glb(&demo::cornell_box()).unwrap();
    let u32_at = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(&glb[0..4], b"glTF");
    assert_eq!(u32_at(4), 2, "version");
    assert_eq!(u32_at(8), glb.len(), "total length");
    let json_len = u32_at(12);
    assert_eq!(&glb[16..20], b"JSON");
    let bin_at = 20 + json_len;
    assert_eq!(&glb[bin_at + 4..bin_at + 8], b"BIN\0");
    assert_eq!(bin_at + 8 + u32_at(bin_at), glb.len());
    assert!(
        json_len % 4 == 0 && u32_at(bin_at) % 4 == 0,
        "chunks are 4-byte aligned"
    );
    let json = std::str::from_utf8(&glb[20..bin_at]).unwrap();
    // Readable numbers where they read back exactly, and the strength split out of 17 nits.
    assert!(json.contains("0.73"), "{json}");
    assert!(json.contains("KHR_materials_emissive_strength"), "{json}");
}

// ---------------------------------------------------------------------------------------
// Refusals

fn export_error(scene: &Scene) -> String {
    match scene_to_glb(scene) {
        Ok(_) => panic!("the scene was exported"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_texture_is_refused_naming_the_material_and_slot() {
    let mut scene = demo::cornell_box();
    scene.materials[1].base_color_texture = Some(TextureRef {
        texture: 0,
        texcoord: 0,
        transform: None,
    });
    let err = scene_to_glb(&scene).unwrap_err();
    assert!(matches!(err, ExportError::Unsupported { .. }), "{err:?}");
    assert_eq!(
        err.to_string(),
        "material 1 'red': baseColorTexture (texture 0) cannot be exported: the exporter \
         does not write images"
    );
}

#[test]
fn skins_and_environment_maps_are_refused() {
    let mut skinned = demo::demo_scene();
    skinned.skins.push(Skin {
        name: Some("rig".into()),
        joints: vec![0],
        inverse_bind: vec![DMat4::IDENTITY],
    });
    let err = export_error(&skinned);
    assert!(
        err.starts_with("skin 0 'rig': a skin cannot be exported"),
        "{err}"
    );

    let mut mapped = demo::demo_scene();
    let map = EnvironmentMap::from_pixels(2, 1, vec![Vec3::ONE, Vec3::X]).unwrap();
    mapped.environment = Some(Environment::Map(map));
    let err = export_error(&mapped);
    assert!(
        err.starts_with("the scene's environment: an environment map cannot be exported"),
        "{err}"
    );
}

#[test]
fn black_and_constant_environments_travel_in_the_scene_extras() {
    let mut lit = demo::demo_scene();
    lit.environment = Some(Environment::Constant(Vec3::new(0.25, 0.5, 3.0)));
    let loaded = round_trip(&lit);
    assert!(
        matches!(loaded.environment, Some(Environment::Constant(c)) if c == Vec3::new(0.25, 0.5, 3.0))
    );
    let loaded = round_trip(&demo::demo_scene());
    assert!(matches!(loaded.environment, Some(Environment::Black)));
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
}

#[test]
fn values_the_loader_would_change_are_refused() {
    let mut bright = demo::cornell_box();
    bright.materials[0].base_color.x = 1.5;
    let err = export_error(&bright);
    assert!(
        err.starts_with("material 0 'white': baseColorFactor [1.5, 0.73"),
        "{err}"
    );

    let mut matrix_animated = demo::animated_demo_scene();
    let node = matrix_animated.animations[0].channels[0].node as usize;
    matrix_animated.nodes[node].trs = None;
    let err = export_error(&matrix_animated);
    assert!(
        err.starts_with("animation 0 'demo', channel 0: animates node"),
        "{err}"
    );

    let mut merged = demo::animated_demo_scene();
    merged.animations[0].channels[2].sampler.times[1] = 0.0;
    let err = export_error(&merged);
    assert!(
        err.contains("key time 1 (0) does not come after key time 0 (0)"),
        "{err}"
    );

    let mut orphan = demo::cornell_box();
    orphan.nodes.push(Node {
        mesh: Some(99),
        ..Default::default()
    });
    let err = export_error(&orphan);
    assert!(err.contains("mesh 99 out of range"), "{err}");
}
