//! The glTF material and texture extensions: loaded as the specs say, and in whole renders
//! against closed forms (what the camera sees of an unlit surface, and what it lights).

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use std::io::Cursor;
use std::path::Path;
use std::sync::Arc;

use glam::{DMat4, DVec3, Vec3, Vec4};
use tracer::camera::Projection;
use tracer::film::{Layers, SampleRange, TileRect};
use tracer::light::Environment;
use tracer::loader;
use tracer::material::Material;
use tracer::render::{prepare_frame, render_region, FrameOptions, RenderSettings};
use tracer::scene::{CameraDef, Scene, SceneBuilder};
use tracer::shapes::uv_sphere;

mod common;

use common::gltf_doc::{base64, Doc};

const SIZE: u32 = 32;

fn render(scene: Scene, spp: u32) -> Layers {
    let options = FrameOptions {
        width: SIZE,
        height: SIZE,
        ..Default::default()
    };
    let frame = prepare_frame(Arc::new(scene), &options).expect("scene prepares");
    render_region(
        &frame,
        &RenderSettings::default(),
        TileRect::new(0, 0, SIZE, SIZE),
        SampleRange::new(0, spp),
        16,
        &|_| {},
    )
    .resolve()
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
