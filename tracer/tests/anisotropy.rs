//! KHR_materials_anisotropy end to end: the loader reads strength, rotation and texture
//! (channels as the extension defines them) and gives the primitives tangents; the
//! integrator points the BSDF's rough axis along the direction in tangent space, so a
//! highlight stretches along it, and a rotation of 90° is the tangent turned by 90°.

use std::path::Path;

use glam::{DMat4, DVec3, Vec2, Vec3, Vec4};
use tracer::camera::Projection;
use tracer::film::Layers;
use tracer::light::PunctualLight;
use tracer::loader;
use tracer::material::Material;
use tracer::scene::{CameraDef, Scene, SceneBuilder};
use tracer::shapes::quad;

mod common;

use common::gltf_doc::{base64, Doc};

const SIZE: u32 = 48;

#[test]
fn anisotropy_is_read_with_its_texture_rotation_and_tangents() {
    let mut doc = Doc::default();
    let p = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let n = doc.vec3(&[[0.0, 0.0, 1.0]; 3]);
    let uv = doc.vec2(&[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]);
    // Direction (0, 1) in tangent space (R 0.5, G 1), strength × 0.5 in B.
    let mut png = Vec::new();
    image::RgbaImage::from_pixel(1, 1, image::Rgba([128, 255, 128, 255]))
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let png = base64(&png);
    let document = |material: &str, attributes: &str| {
        doc.json(&format!(
            r#","extensionsUsed":["KHR_materials_anisotropy"],
            "images":[{{"uri":"data:image/png;base64,{png}"}}],"textures":[{{"source":0}}],
            "materials":[{material}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}{attributes}}},"material":0}}]}}],
            "scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}]"#
        ))
    };
    let with_uv = format!(r#","NORMAL":{n},"TEXCOORD_0":{uv}"#);
    let json = document(
        r#"{"extensions":{"KHR_materials_anisotropy":{"anisotropyStrength":0.8,
            "anisotropyRotation":0.5,"anisotropyTexture":{"index":0}}}}"#,
        &with_uv,
    );
    let scene = loader::load_slice(json.as_bytes(), None).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert!(scene.features.anisotropy);
    let m = &scene.materials[0];
    assert_eq!((m.anisotropy_strength, m.anisotropy_rotation), (0.8, 0.5));
    // Tangents are generated (MikkTSpace) for the direction's tangent space.
    let prim = &scene.meshes[0].primitives[0];
    assert_eq!(prim.tangents.len(), 3);
    let sample = m.sample(&scene.textures, [Vec2::ZERO; 2], Vec4::ONE);
    let strength = sample
        .surface
        .extensions
        .expect("anisotropy is carried")
        .anisotropy;
    assert!((strength - 0.8 * 128.0 / 255.0).abs() < 1e-6, "{strength}");
    // The texel's direction, (2·128/255 − 1, 1) normalised, turned by 0.5 rad.
    let d = Vec2::new(2.0 * 128.0 / 255.0 - 1.0, 1.0).normalize();
    let (s, c) = tracer::math::sin_cos(0.5);
    let expected = Vec2::new(c * d.x - s * d.y, s * d.x + c * d.y);
    let got = sample.anisotropy_direction.expect("a direction");
    assert!((got - expected).length() < 1e-6, "{got} vs {expected}");

    // Without a texture the direction is the rotation itself and the strength the factor.
    let json = document(
        r#"{"extensions":{"KHR_materials_anisotropy":{"anisotropyStrength":0.3,
            "anisotropyRotation":1.0}}}"#,
        &with_uv,
    );
    let scene = loader::load_slice(json.as_bytes(), None).unwrap();
    let sample = scene.materials[0].sample(&scene.textures, [Vec2::ZERO; 2], Vec4::ONE);
    let got = sample.anisotropy_direction.unwrap();
    let (s, c) = tracer::math::sin_cos(1.0);
    assert!((got - Vec2::new(c, s)).length() < 1e-6);
    assert_eq!(sample.surface.extensions.unwrap().anisotropy, 0.3);

    // No texture coordinates: no tangent space, said so.
    let json = document(
        r#"{"extensions":{"KHR_materials_anisotropy":{"anisotropyStrength":0.3}}}"#,
        "",
    );
    let scene = loader::load_slice(json.as_bytes(), None).unwrap();
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("anisotropy") && w.contains("no tangents generated")),
        "{:?}",
        scene.warnings
    );

    let err = loader::load_slice(
        document(
            r#"{"extensions":{"KHR_materials_anisotropy":{"anisotropyStrength":"x"}}}"#,
            &with_uv,
        )
        .as_bytes(),
        None,
    )
    .unwrap_err();
    assert!(
        err.to_string()
            .contains("anisotropyStrength \"x\" is not a number"),
        "{err}"
    );
}

/// A brushed-metal floor seen from above with a point light beside the camera; the quad's
/// tangent is `tangent` and the material turns the direction by `rotation`.
fn brushed_floor(tangent: Vec3, rotation: f32) -> Scene {
    let mut b = SceneBuilder::default();
    let m = b.material(Material {
        base_color: Vec4::ONE,
        metallic: 1.0,
        roughness: 0.2,
        anisotropy_strength: 0.9,
        anisotropy_rotation: rotation,
        double_sided: true,
        ..Material::default()
    });
    let mut floor = quad(
        [
            Vec3::new(-2.0, -2.0, 0.0),
            Vec3::new(2.0, -2.0, 0.0),
            Vec3::new(2.0, 2.0, 0.0),
            Vec3::new(-2.0, 2.0, 0.0),
        ],
        m,
    );
    floor.tangents = vec![tangent.extend(1.0); 4];
    b.mesh("floor", vec![floor], DMat4::IDENTITY);
    b.light(
        PunctualLight::Point {
            intensity: Vec3::splat(4.0),
            range: None,
        },
        DMat4::from_translation(DVec3::new(0.0, 0.0, 1.0)),
    );
    b.camera(
        CameraDef {
            name: None,
            projection: Projection::Perspective {
                yfov: 1.2,
                aspect_ratio: None,
                znear: 0.01,
            },
        },
        DMat4::from_translation(DVec3::new(0.0, 0.0, 2.0)),
    );
    b.finish()
}

/// Second moments of the image's luminance about its centroid, along x and y.
fn spread(layers: &Layers) -> (f64, f64) {
    let (mut w, mut mx, mut my) = (0.0f64, 0.0f64, 0.0f64);
    let lum = |i: usize| f64::from(layers.beauty[i].truncate().dot(Vec3::ONE));
    let at = |i: usize| ((i % SIZE as usize) as f64, (i / SIZE as usize) as f64);
    for i in 0..layers.beauty.len() {
        let (x, y) = at(i);
        w += lum(i);
        mx += lum(i) * x;
        my += lum(i) * y;
    }
    let (cx, cy) = (mx / w, my / w);
    let (mut sx, mut sy) = (0.0, 0.0);
    for i in 0..layers.beauty.len() {
        let (x, y) = at(i);
        sx += lum(i) * (x - cx) * (x - cx);
        sy += lum(i) * (y - cy) * (y - cy);
    }
    (sx / w, sy / w)
}

#[test]
fn the_highlight_stretches_along_the_direction_and_turns_with_it() {
    let along_x = common::render_square(brushed_floor(Vec3::X, 0.0), SIZE, 64, 2);
    let (sx, sy) = spread(&along_x);
    assert!(sx > 2.0 * sy, "rough along x: spread x {sx:.1}, y {sy:.1}");

    // Rotated by 90°, the direction is the bitangent: as if the tangent were +Y.
    let rotated = common::render_square(
        brushed_floor(Vec3::X, std::f32::consts::FRAC_PI_2),
        SIZE,
        64,
        2,
    );
    let turned = common::render_square(brushed_floor(Vec3::Y, 0.0), SIZE, 64, 2);
    let (rx, ry) = spread(&rotated);
    assert!(ry > 2.0 * rx, "rough along y: spread x {rx:.1}, y {ry:.1}");
    let mean = |l: &Layers| l.beauty.iter().map(|p| p.truncate()).sum::<Vec3>().x;
    let diff: f32 = rotated
        .beauty
        .iter()
        .zip(&turned.beauty)
        .map(|(a, b)| (a.truncate() - b.truncate()).abs().x)
        .sum();
    assert!(
        diff < 1e-4 * mean(&turned),
        "rotation 90° and tangent +Y differ by {diff} (image sum {})",
        mean(&turned)
    );
}

#[test]
fn khronos_anisotropy_models_load_with_it() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/scenes");
    for file in [
        "AnisotropyStrengthTest/AnisotropyStrengthTest.glb",
        "AnisotropyRotationTest/AnisotropyRotationTest.glb",
    ] {
        let path = dir.join(file);
        if !path.exists() {
            println!("SKIPPED: {} is not on this machine", path.display());
            continue;
        }
        let scene = loader::load_path(&path).unwrap();
        assert!(scene.features.anisotropy, "{file}");
        let lacking = scene
            .warnings
            .iter()
            .find(|w| w.contains("anisotropy") || w.contains("tangents"));
        assert!(lacking.is_none(), "{file}: {lacking:?}");
    }
}
