//! The glTF material and texture extensions: loaded as the specs say, and in whole renders
//! against closed forms (what the camera sees of an unlit surface, and what it lights).

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use std::io::Cursor;
use std::path::Path;

use glam::{DMat4, DVec3, Vec3, Vec4};
use tracer::camera::Projection;
use tracer::film::Layers;
use tracer::light::Environment;
use tracer::loader;
use tracer::material::Material;
use tracer::scene::{CameraDef, Scene, SceneBuilder};
use tracer::shapes::uv_sphere;

mod common;

use common::gltf_doc::{base64, Doc};

const SIZE: u32 = 32;

fn render(scene: Scene, spp: u32) -> Layers {
    common::render_square(scene, SIZE, spp, 8)
}

fn camera_at(b: &mut SceneBuilder, z: f64) {
    b.camera(
        CameraDef {
            name: None,
            projection: Projection::Perspective {
                yfov: 0.5,
                aspect_ratio: None,
                znear: 0.01,
            },
        },
        DMat4::from_translation(DVec3::new(0.0, 0.0, z)),
    );
}

/// Mean RGB over the pixels whose depth (a mean over the pixel's samples) is below
/// `near`, and over those beyond `far`; pixels on a silhouette, in between, count in
/// neither.
fn means_by_depth(layers: &Layers, near: f32, far: f32) -> (Vec3, Vec3) {
    let (mut a, mut na, mut b, mut nb) = (Vec3::ZERO, 0, Vec3::ZERO, 0);
    for (p, d) in layers.beauty.iter().zip(&layers.depth) {
        if *d < near && p.w == 1.0 {
            a += p.truncate();
            na += 1;
        } else if *d > far {
            b += p.truncate();
            nb += 1;
        }
    }
    assert!(
        na > 50 && nb > 50,
        "both parts visible: {na} and {nb} pixels"
    );
    (a / na as f32, b / nb as f32)
}

fn unlit(color: Vec3) -> Material {
    Material {
        base_color: color.extend(1.0),
        unlit: true,
        double_sided: true,
        ..Material::default()
    }
}

#[test]
fn an_unlit_surface_shows_its_colour_whatever_lights_it() {
    let color = Vec3::new(0.2, 0.5, 0.8);
    let mut b = SceneBuilder::default();
    let m = b.material(unlit(color));
    b.mesh("ball", vec![uv_sphere(m, 32, 64)], DMat4::IDENTITY);
    camera_at(&mut b, 4.0);
    // A bright environment: a lit surface would add it; an unlit one shows only its colour.
    b.environment(Environment::Constant(Vec3::splat(5.0)));
    let layers = render(b.finish(), 4);
    let (ball, background) = means_by_depth(&layers, 3.9, 1e6);
    assert!((ball - color).abs().max_element() < 1e-5, "{ball}");
    assert!((background - Vec3::splat(5.0)).abs().max_element() < 1e-4);
}

#[test]
fn an_unlit_enclosure_lights_a_diffuse_ball_as_a_uniform_environment() {
    // Inside an unlit sphere of colour c, a convex diffuse ball of albedo ρ sees radiance
    // c from every direction and nothing else (the enclosure scatters nothing): it
    // reflects ρ·c exactly, by next-event estimation on the enclosure's triangles and by
    // BSDF samples that hit them, weighted by MIS.
    let (c, rho) = (Vec3::new(1.0, 0.6, 0.3), 0.5);
    let mut b = SceneBuilder::default();
    let walls = b.material(unlit(c));
    let ball = b.material(Material {
        base_color: Vec4::new(rho, rho, rho, 1.0),
        metallic: 0.0,
        specular: 0.0,
        ..Material::default()
    });
    b.mesh(
        "enclosure",
        vec![uv_sphere(walls, 32, 64)],
        DMat4::from_scale(DVec3::splat(10.0)),
    );
    b.mesh("ball", vec![uv_sphere(ball, 64, 128)], DMat4::IDENTITY);
    camera_at(&mut b, 8.0);
    b.environment(Environment::Black);
    let scene = b.finish();
    assert!(scene.features.emissive, "an unlit surface is an emitter");
    let layers = render(scene, 256);
    let (seen, _) = means_by_depth(&layers, 7.9, 16.5);
    let last = (SIZE * SIZE - 1) as usize;
    for corner in [0, SIZE as usize - 1, last + 1 - SIZE as usize, last] {
        let enclosure = layers.beauty[corner].truncate();
        assert!((enclosure - c).abs().max_element() < 1e-5, "{enclosure}");
    }
    let want = c * rho;
    let err = ((seen - want) / want).abs().max_element();
    assert!(err < 0.01, "ball {seen}, closed form {want}");
}

#[test]
fn khronos_unlit_test_loads_with_its_unlit_materials() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/scenes-pending/UnlitTest/UnlitTest.glb");
    if !path.exists() {
        println!("SKIPPED: {} is not on this machine", path.display());
        return;
    }
    let scene = loader::load_path(&path).unwrap();
    assert!(!scene.materials.is_empty());
    assert!(
        scene.materials.iter().all(|m| m.unlit),
        "every material is unlit"
    );
    assert!(scene.features.emissive);
}

fn encoded(img: image::RgbaImage, format: image::ImageFormat) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, format).unwrap();
    out.into_inner()
}

#[test]
fn webp_textures_are_read_in_place_of_their_fallback() {
    // The WebP image has the texels; the PNG fallback is one black texel. A file that
    // requires the extension has no fallback at all.
    let texels = [
        [255, 0, 0, 255],
        [0, 255, 0, 255],
        [0, 0, 255, 255],
        [9, 99, 199, 255],
    ];
    let img = image::RgbaImage::from_fn(2, 2, |x, y| image::Rgba(texels[(y * 2 + x) as usize]));
    let webp = base64(&encoded(img, image::ImageFormat::WebP));
    let black = base64(&encoded(
        image::RgbaImage::from_pixel(1, 1, image::Rgba([0, 0, 0, 255])),
        image::ImageFormat::Png,
    ));
    let mut doc = Doc::default();
    let p = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let uv = doc.vec2(&[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]);
    let document = |texture: &str, required: &str| {
        doc.json(&format!(
            r#","extensionsUsed":["EXT_texture_webp"]{required},
            "images":[{{"uri":"data:image/png;base64,{black}"}},{{"uri":"data:image/webp;base64,{webp}"}}],
            "textures":[{texture}],
            "materials":[{{"pbrMetallicRoughness":{{"baseColorTexture":{{"index":0}}}}}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"TEXCOORD_0":{uv}}},"material":0}}]}}],
            "scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}]"#
        ))
    };
    let with_fallback = document(
        r#"{"source":0,"extensions":{"EXT_texture_webp":{"source":1}}}"#,
        "",
    );
    let required = document(
        r#"{"extensions":{"EXT_texture_webp":{"source":1}}}"#,
        r#","extensionsRequired":["EXT_texture_webp"]"#,
    );
    for json in [with_fallback, required] {
        let scene = loader::load_slice(json.as_bytes(), None).unwrap();
        assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
        assert_eq!(scene.textures.len(), 1);
        assert_eq!(scene.textures[0].texels, texels.to_vec());
    }
}

/// Mean radiance of the pixels fully on a unit sphere of `material` in a uniform
/// environment of radiance 1.
fn furnace_radiance(material: Material, spp: u32) -> Vec3 {
    let mut b = SceneBuilder::default();
    let m = b.material(material);
    b.mesh("ball", vec![uv_sphere(m, 64, 128)], DMat4::IDENTITY);
    camera_at(&mut b, 4.0);
    b.environment(Environment::Constant(Vec3::ONE));
    let layers = render(b.finish(), spp);
    means_by_depth(&layers, 3.9, 1e6).0
}

#[test]
fn coated_and_sheened_white_spheres_are_white_furnaces() {
    // Over a white Lambertian base each layer takes from the base what it reflects: a
    // sphere in a uniform environment of radiance 1 reflects 1, bounce after bounce.
    let white = Material {
        metallic: 0.0,
        specular: 0.0,
        double_sided: true,
        ..Material::default()
    };
    let cases = [
        (
            "rough clear coat",
            Material {
                clearcoat: 1.0,
                clearcoat_roughness: 0.4,
                ..white.clone()
            },
        ),
        (
            "smooth clear coat",
            Material {
                clearcoat: 0.7,
                ..white.clone()
            },
        ),
        (
            "sheen",
            Material {
                sheen_color: Vec3::ONE,
                sheen_roughness: 0.5,
                ..white.clone()
            },
        ),
    ];
    for (name, material) in cases {
        let l = furnace_radiance(material, 64);
        assert!((l - Vec3::ONE).abs().max_element() < 0.01, "{name}: {l}");
    }
}

#[test]
fn clearcoat_and_sheen_are_read_with_their_textures() {
    let mut doc = Doc::default();
    let p = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let uv = doc.vec2(&[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]);
    let png = base64(&encoded(
        image::RgbaImage::from_pixel(1, 1, image::Rgba([255, 128, 64, 32])),
        image::ImageFormat::Png,
    ));
    let document = |material: &str| {
        doc.json(&format!(
            r#","extensionsUsed":["KHR_materials_clearcoat","KHR_materials_sheen"],
            "images":[{{"uri":"data:image/png;base64,{png}"}}],"textures":[{{"source":0}}],
            "materials":[{material}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"TEXCOORD_0":{uv}}},"material":0}}]}}],
            "scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}]"#
        ))
    };
    let json = document(
        r#"{"extensions":{
            "KHR_materials_clearcoat":{"clearcoatFactor":0.8,"clearcoatRoughnessFactor":0.3,
                "clearcoatTexture":{"index":0},"clearcoatRoughnessTexture":{"index":0,"texCoord":1},
                "clearcoatNormalTexture":{"index":0,"scale":0.5}},
            "KHR_materials_sheen":{"sheenColorFactor":[1.0,0.5,0.25],"sheenRoughnessFactor":0.7,
                "sheenColorTexture":{"index":0,"extensions":{"KHR_texture_transform":{"scale":[2,2]}}},
                "sheenRoughnessTexture":{"index":0}}}}"#,
    );
    let scene = loader::load_slice(json.as_bytes(), None).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let m = &scene.materials[0];
    assert_eq!((m.clearcoat, m.clearcoat_roughness), (0.8, 0.3));
    assert_eq!(m.clearcoat_normal_scale, 0.5);
    assert_eq!(m.clearcoat_roughness_texture.as_ref().unwrap().texcoord, 1);
    assert!(m.clearcoat_texture.is_some() && m.clearcoat_normal_texture.is_some());
    assert_eq!(
        (m.sheen_color, m.sheen_roughness),
        (Vec3::new(1.0, 0.5, 0.25), 0.7)
    );
    assert!(m.sheen_color_texture.as_ref().unwrap().transform.is_some());
    assert!(m.sheen_roughness_texture.is_some());
    assert!(scene.features.clearcoat && scene.features.sheen);
    // The textures' channels: clearcoat R, its roughness G, sheen colour RGB (sRGB), sheen
    // roughness A.
    let at = m
        .sample(&scene.textures, [glam::Vec2::ZERO; 2], Vec4::ONE)
        .surface
        .extensions
        .expect("the material has layers");
    assert!((at.clearcoat - 0.8).abs() < 1e-6);
    assert!((at.clearcoat_roughness - 0.3 * 128.0 / 255.0).abs() < 1e-6);
    assert!((at.sheen_roughness - 0.7 * 32.0 / 255.0).abs() < 1e-6);
    assert!((at.sheen_color.x - 1.0).abs() < 1e-6 && at.sheen_color.y < 0.5 * 0.5);

    for (material, expected) in [
        (
            r#"{"extensions":{"KHR_materials_clearcoat":{"clearcoatFactor":"lots"}}}"#,
            "material 0: clearcoatFactor \"lots\" is not a number",
        ),
        (
            r#"{"extensions":{"KHR_materials_sheen":{"sheenColorFactor":[1,2]}}}"#,
            "material 0: sheenColorFactor [1,2] is not three numbers",
        ),
        (
            r#"{"extensions":{"KHR_materials_clearcoat":{"clearcoatTexture":{"index":7}}}}"#,
            "material 0: clearcoatTexture names no texture",
        ),
    ] {
        let err = loader::load_slice(document(material).as_bytes(), None).unwrap_err();
        assert!(err.to_string().contains(expected), "{err}");
    }
}

#[test]
fn khronos_models_load_with_their_material_extensions() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared");
    let models = [
        ("scenes/ClearCoatTest/ClearCoatTest.glb", "clearcoat"),
        ("scenes/ClearcoatWicker/ClearcoatWicker.glb", "clearcoat"),
        (
            "scenes-pending/ClearCoatCarPaint/ClearCoatCarPaint.glb",
            "clearcoat",
        ),
        ("scenes/SheenCloth/SheenCloth.gltf", "sheen"),
        ("scenes/SheenChair/SheenChair.gltf", "sheen"),
        ("scenes/GlassVaseFlowers/GlassVaseFlowers.glb", "volume"),
        ("scenes/IridescenceLamp/IridescenceLamp.gltf", "iridescence"),
        (
            "scenes/IridescentDishWithOlives/IridescentDishWithOlives.gltf",
            "iridescence",
        ),
    ];
    for (file, feature) in models {
        let path = dir.join(file);
        if !path.exists() {
            println!("SKIPPED: {} is not on this machine", path.display());
            continue;
        }
        let scene = loader::load_path(&path).unwrap();
        assert!(
            scene.features.names().contains(&feature),
            "{file}: features {:?}",
            scene.features.names()
        );
        let ignored = scene
            .warnings
            .iter()
            .find(|w| w.contains(&format!("KHR_materials_{feature}")));
        assert!(ignored.is_none(), "{file}: {ignored:?}");
    }
}

#[test]
fn a_sheet_passes_its_diffuse_transmission_to_the_side_it_does_not_face() {
    // A single-sided sheet facing away from the camera, lit head-on from its front by a
    // directional light of illuminance π: seen from behind, a Lambertian transmission of
    // dt · colour shows radiance dt · colour · E / π = dt · colour, in every pixel. A
    // single-sided surface is otherwise invisible from behind; one that transmits is not.
    let (dt, color) = (0.6, Vec3::new(1.0, 0.5, 0.25));
    let mut b = SceneBuilder::default();
    let leaf = b.material(Material {
        base_color: Vec4::new(0.2, 0.9, 0.3, 1.0),
        metallic: 0.0,
        specular: 0.0,
        diffuse_transmission: dt,
        diffuse_transmission_color: color,
        ..Material::default()
    });
    // Its front faces −z, away from the camera at +z.
    let sheet = tracer::shapes::quad(
        [
            Vec3::new(-5.0, -5.0, 0.0),
            Vec3::new(-5.0, 5.0, 0.0),
            Vec3::new(5.0, 5.0, 0.0),
            Vec3::new(5.0, -5.0, 0.0),
        ],
        leaf,
    );
    b.mesh("sheet", vec![sheet], DMat4::IDENTITY);
    // Shining along +z, onto the sheet's front.
    b.light(
        tracer::light::PunctualLight::Directional {
            illuminance: Vec3::splat(std::f32::consts::PI),
        },
        DMat4::from_rotation_y(std::f64::consts::PI),
    );
    camera_at(&mut b, 4.0);
    b.environment(Environment::Black);
    let scene = b.finish();
    assert!(scene.features.diffuse_transmission);
    let layers = render(scene, 4);
    let want = dt * color;
    for p in &layers.beauty {
        assert!(
            (p.truncate() - want).abs().max_element() < 1e-5,
            "{p}, closed form {want}"
        );
    }
}

#[test]
fn an_ignored_material_extension_is_named_with_its_materials() {
    let mut doc = Doc::default();
    let p = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let json = doc.json(&format!(
        r#","extensionsUsed":["KHR_materials_pbrSpecularGlossiness"],
        "materials":[{{"name":"Glass","extensions":{{"KHR_materials_pbrSpecularGlossiness":{{"glossinessFactor":0.5}}}}}},{{}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}},"material":0}}]}}],
        "scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}]"#
    ));
    let scene = loader::load_slice(json.as_bytes(), None).unwrap();
    assert_eq!(
        scene.warnings,
        ["optional extension 'KHR_materials_pbrSpecularGlossiness' is not supported; ignored on material 0 'Glass'"]
    );
    let required = json.replace(
        r#""extensionsUsed""#,
        r#""extensionsRequired":["KHR_materials_pbrSpecularGlossiness"],"extensionsUsed""#,
    );
    let err = loader::load_slice(required.as_bytes(), None).unwrap_err();
    assert_eq!(
        err.to_string(),
        "required extension 'KHR_materials_pbrSpecularGlossiness' is not supported"
    );
}
