//! The glTF loader on small documents written here, with their binary data in base64
//! data: URIs: index widths, spec defaults, textures and their transfer functions,
//! tangents, the material extensions, default scenes, packing, and errors that name the
//! element at fault.

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use std::io::Cursor;
use std::path::PathBuf;

use glam::{DVec3, Vec2, Vec3, Vec4};
use tracer::camera::Projection;
use tracer::light::PunctualLight;
use tracer::loader::{self, Element, SceneError, SceneSummary};
use tracer::material::AlphaMode;
use tracer::scene::Scene;
use tracer::texture::{srgb_to_linear, Filter, Wrap};

mod common;

use common::gltf_doc::{base64, Doc};

// ---------------------------------------------------------------------------------------
// Building documents

fn load(json: &str) -> Result<Scene, SceneError> {
    loader::load_slice(json.as_bytes(), None)
}

/// A unit quad in the XY plane facing +Z, with glTF-style upright UVs (v down the image):
/// returns (POSITION, NORMAL, TEXCOORD_0, indices) accessors.
fn quad(doc: &mut Doc) -> (usize, usize, usize, usize) {
    let p = doc.vec3(&[
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ]);
    let n = doc.vec3(&[[0.0, 0.0, 1.0]; 4]);
    let t = doc.vec2(&[[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]]);
    let i = doc.u16s(&[0, 1, 2, 0, 2, 3]);
    (p, n, t, i)
}

/// A one-node scene drawing mesh 0.
const ONE_NODE: &str = r#","scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}]"#;

fn png(img: image::DynamicImage) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("tessera-loader-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    loader::write_glb(json.as_bytes(), Some(bin)).unwrap()
}

// ---------------------------------------------------------------------------------------
// Geometry

#[test]
fn thirty_two_bit_indices_reach_past_65535_vertices() {
    // A 300 × 220 grid: 66,000 vertices.
    let (w, h) = (300u32, 220u32);
    let mut pos = Vec::new();
    for y in 0..h {
        for x in 0..w {
            pos.push([x as f32, y as f32, 0.0]);
        }
    }
    let mut idx = Vec::new();
    for y in 0..h - 1 {
        for x in 0..w - 1 {
            let v = y * w + x;
            idx.extend([v, v + 1, v + w, v + 1, v + w + 1, v + w]);
        }
    }
    let mut doc = Doc::default();
    let p = doc.vec3(&pos);
    let i = doc.u32s(&idx);
    let json = doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}},"indices":{i}}}]}}]{ONE_NODE}"#
    ));
    let scene = load(&json).unwrap();
    let prim = &scene.meshes[0].primitives[0];
    assert_eq!(prim.positions.len(), 66_000);
    assert_eq!(prim.indices.len(), idx.len() / 3);
    assert_eq!(prim.indices.last().unwrap()[1], w * h - 1);
    assert_eq!(
        SceneSummary::of(&scene).triangles,
        ((w - 1) * (h - 1) * 2) as u64
    );
}

#[test]
fn strips_and_fans_become_triangles_and_points_are_skipped() {
    let mut doc = Doc::default();
    let p = doc.vec3(&[
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 2.0, 0.0],
    ]);
    let json = doc.json(&format!(
        r#","meshes":[{{"name":"M","primitives":[
            {{"attributes":{{"POSITION":{p}}},"mode":5}},
            {{"attributes":{{"POSITION":{p}}},"mode":6}},
            {{"attributes":{{"POSITION":{p}}},"mode":0}}]}}]{ONE_NODE}"#
    ));
    let scene = load(&json).unwrap();
    let prims = &scene.meshes[0].primitives;
    assert_eq!(prims.len(), 2, "the point primitive is skipped");
    // Strip: (0,1,2), (1,3,2), (2,3,4): every triangle keeps the first one's winding.
    assert_eq!(prims[0].indices, vec![[0, 1, 2], [1, 3, 2], [2, 3, 4]]);
    // Fan around vertex 0.
    assert_eq!(prims[1].indices, vec![[1, 2, 0], [2, 3, 0], [3, 4, 0]]);
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("mesh 'M', primitive 2") && w.contains("Points")),
        "{:?}",
        scene.warnings
    );
}

#[test]
fn normalized_attributes_colours_and_repaired_normals() {
    let mut doc = Doc::default();
    let p = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    // One good normal (not unit), one zero, one NaN.
    let n = doc.vec3(&[[0.0, 0.0, 2.0], [0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0]]);
    let uv_bytes: Vec<u8> = [0u16, 65535, 32768, 0, 65535, 65535]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let uv = doc.accessor(&uv_bytes, 5123, "VEC2", 3, r#","normalized":true"#);
    // COLOR_0 as normalised unsigned bytes: VEC3 elements padded to 4 bytes, as the spec
    // asks of vertex attributes.
    let col = doc.strided_accessor(
        &[255, 0, 51, 0, 0, 255, 0, 0, 0, 0, 255, 0],
        4,
        5121,
        "VEC3",
        3,
        r#","normalized":true"#,
    );
    let json = doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n},"TEXCOORD_0":{uv},"COLOR_0":{col}}}}}]}}]{ONE_NODE}"#
    ));
    let scene = load(&json).unwrap();
    let prim = &scene.meshes[0].primitives[0];
    for nrm in &prim.normals {
        assert!((*nrm - Vec3::Z).length() < 1e-6, "{nrm}");
    }
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("2 zero or non-finite normals")),
        "{:?}",
        scene.warnings
    );
    assert_eq!(prim.uvs[0][0], Vec2::new(0.0, 1.0));
    assert!((prim.uvs[0][1].x - 32768.0 / 65535.0).abs() < 1e-7);
    assert_eq!(prim.colors[0], Vec4::new(1.0, 0.0, 0.2, 1.0));
    assert_eq!(prim.colors[2], Vec4::new(0.0, 0.0, 1.0, 1.0));
}

#[test]
fn sparse_accessors_override_their_base() {
    let mut doc = Doc::default();
    let base = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let idx_view = doc.view(&2u16.to_le_bytes());
    let val_view = doc.view(
        &[5.0f32, 6.0, 7.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<_>>(),
    );
    let view = doc.accessors[base].clone();
    doc.accessors.push(view.replace(
        r#""count":3"#,
        &format!(
            r#""count":3,"sparse":{{"count":1,"indices":{{"bufferView":{idx_view},"componentType":5123}},"values":{{"bufferView":{val_view}}}}}"#
        ),
    ));
    let p = doc.accessors.len() - 1;
    let json = doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}}}}]}}]{ONE_NODE}"#
    ));
    let scene = load(&json).unwrap();
    assert_eq!(
        scene.meshes[0].primitives[0].positions[2],
        Vec3::new(5.0, 6.0, 7.0)
    );
}

#[test]
fn a_mesh_of_lines_keeps_its_index_and_draws_nothing() {
    let mut doc = Doc::default();
    let p = doc.vec3(&[[0.0; 3], [1.0, 0.0, 0.0]]);
    let (q, _, _, i) = quad(&mut doc);
    let json = doc.json(&format!(
        r#","meshes":[{{"name":"Wire","primitives":[{{"attributes":{{"POSITION":{p}}},"mode":1}}]}},
                      {{"primitives":[{{"attributes":{{"POSITION":{q}}},"indices":{i}}}]}}],
        "scenes":[{{"nodes":[0,1]}}],"nodes":[{{"mesh":0}},{{"mesh":1}}]"#
    ));
    let scene = load(&json).unwrap();
    assert_eq!(scene.meshes.len(), 2);
    assert!(scene.meshes[0].primitives.is_empty());
    assert_eq!(scene.nodes[1].mesh, Some(1));
    assert_eq!(SceneSummary::of(&scene).triangles, 2);
    assert!(scene
        .warnings
        .iter()
        .any(|w| w.starts_with("mesh 'Wire', primitive 0: Lines")));
}

#[test]
fn images_in_data_uris_decode() {
    let (png_bytes, texels) = texels_png();
    let mut doc = Doc::default();
    let (p, _, t, i) = quad(&mut doc);
    let json = doc.json(&format!(
        r#","images":[{{"uri":"data:image/png;base64,{}"}}],"textures":[{{"source":0}}],
        "materials":[{{"pbrMetallicRoughness":{{"baseColorTexture":{{"index":0}}}}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"TEXCOORD_0":{t}}},"indices":{i},"material":0}}]}}]{ONE_NODE}"#,
        base64(&png_bytes)
    ));
    let scene = load(&json).unwrap();
    assert_eq!(scene.textures[0].texels, texels.to_vec());
    assert_eq!(
        (scene.textures[0].wrap_s, scene.textures[0].filter),
        (Wrap::Repeat, Filter::Linear)
    );
    let broken = json.replace("data:image/png;base64,", "data:image/png;base64,AAAA");
    let m = message(load(&broken));
    assert!(m.starts_with("image 0: data: URI: "), "{m}");
}

#[test]
fn an_empty_scene_loads_with_a_warning() {
    let scene = load(r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[]}]}"#).unwrap();
    assert_eq!(SceneSummary::of(&scene).triangles, 0);
    assert!(scene.warnings.iter().any(|w| w.contains("no triangles")));
    assert!(loader::scene_bounds(&scene).is_empty());
}

// ---------------------------------------------------------------------------------------
// Nodes and scenes

#[test]
fn node_transforms_compose_in_double_precision() {
    let mut doc = Doc::default();
    let (p, _, _, i) = quad(&mut doc);
    let json = doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}},"indices":{i}}}]}}],
        "scenes":[{{"nodes":[0]}}],
        "nodes":[
            {{"translation":[1e7,0,0],"children":[1]}},
            {{"rotation":[0,0.70710678,0,0.70710678],"scale":[2,2,2],"translation":[0,3,0],"mesh":0}}]"#
    ));
    let scene = load(&json).unwrap();
    let inst = loader::mesh_instances(&scene);
    assert_eq!(inst.len(), 1);
    let world = inst[0].1;
    // (1,0,0) scaled to (2,0,0), turned 90° about +Y to (0,0,-2), moved by (1e7, 3, 0).
    let p = world.transform_point3(DVec3::X);
    assert!((p - DVec3::new(1e7, 3.0, -2.0)).length() < 1e-6, "{p}");
}

#[test]
fn the_default_scene_is_the_scene_property_then_scene_0_then_parentless_nodes() {
    let mut doc = Doc::default();
    let (p, _, _, i) = quad(&mut doc);
    let meshes = format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}},"indices":{i}}}]}}]"#
    );
    let nodes = r#","nodes":[{"mesh":0},{"mesh":0,"children":[2]},{"mesh":0}]"#;
    let scenes = r#","scenes":[{"nodes":[0]},{"nodes":[1]}]"#;
    let with = load(&doc.json(&format!(r#"{meshes}{nodes}{scenes},"scene":1"#))).unwrap();
    assert_eq!(with.roots, vec![1]);
    assert_eq!(SceneSummary::of(&with).triangles, 4, "node 1 and its child");
    let first = load(&doc.json(&format!("{meshes}{nodes}{scenes}"))).unwrap();
    assert_eq!(first.roots, vec![0]);
    let none = load(&doc.json(&format!("{meshes}{nodes}"))).unwrap();
    assert_eq!(none.roots, vec![0, 1]);
}

#[test]
fn a_skin_whose_skeleton_is_node_0_changes_nothing() {
    let mut doc = Doc::default();
    let (p, n, _, i) = quad(&mut doc);
    let joints = doc.accessor(&[0u8; 16], 5121, "VEC4", 4, "");
    let weights = doc.floats(&[1.0, 0.0, 0.0, 0.0].repeat(4), "VEC4", 4);
    let ibm = doc.floats(&glam::Mat4::IDENTITY.to_cols_array(), "MAT4", 16);
    let json = doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n},"JOINTS_0":{joints},"WEIGHTS_0":{weights}}},"indices":{i}}}]}}],
        "skins":[{{"joints":[0],"skeleton":0,"inverseBindMatrices":{ibm}}}],
        "scenes":[{{"nodes":[0,1]}}],
        "nodes":[{{"name":"root joint","translation":[0,1,0]}},{{"mesh":0,"skin":0}}]"#
    ));
    let scene = load(&json).unwrap();
    assert_eq!(scene.roots, vec![0, 1]);
    assert_eq!(scene.nodes[1].mesh, Some(0));
    assert_eq!(scene.nodes[0].mesh, None);
    assert_eq!(SceneSummary::of(&scene).triangles, 2);
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
}

#[test]
fn instancing_counts_triangles_per_instance() {
    let mut doc = Doc::default();
    let (p, _, _, i) = quad(&mut doc);
    let json = doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}},"indices":{i}}}]}}],
        "scenes":[{{"nodes":[0,1,2]}}],"nodes":[{{"mesh":0}},{{"mesh":0}},{{"mesh":0}}]"#
    ));
    let s = SceneSummary::of(&load(&json).unwrap());
    assert_eq!(
        (s.triangles, s.unique_triangles, s.instances, s.meshes),
        (6, 2, 3, 1)
    );
}

// ---------------------------------------------------------------------------------------
// Materials and textures

#[test]
fn materials_follow_the_spec_defaults() {
    let mut doc = Doc::default();
    let (p, _, _, i) = quad(&mut doc);
    let json = doc.json(&format!(
        r#","materials":[{{}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}},"indices":{i},"material":0}},
                                   {{"attributes":{{"POSITION":{p}}},"indices":{i}}}]}}]{ONE_NODE}"#
    ));
    let scene = load(&json).unwrap();
    assert_eq!(scene.materials.len(), 2, "the default material is appended");
    assert_eq!(scene.meshes[0].primitives[1].material, 1);
    for m in &scene.materials {
        assert!(!m.double_sided);
        assert_eq!(m.alpha_mode, AlphaMode::Opaque);
        assert_eq!((m.ior, m.metallic, m.roughness), (1.5, 1.0, 1.0));
        assert_eq!(m.base_color, Vec4::ONE);
        assert_eq!(m.emissive, Vec3::ZERO);
        assert_eq!(
            (m.specular, m.specular_color, m.transmission),
            (1.0, Vec3::ONE, 0.0)
        );
        assert!(!m.has_textures());
    }
    assert_eq!(scene.features, Default::default());
}

#[test]
fn alpha_modes_and_material_extensions_are_read() {
    let mut doc = Doc::default();
    let (p, _, _, i) = quad(&mut doc);
    let json = doc.json(&format!(
        r#","extensionsUsed":["KHR_materials_emissive_strength","KHR_materials_specular","KHR_materials_ior","KHR_materials_transmission"],
        "materials":[
          {{"alphaMode":"MASK","alphaCutoff":0.25,"doubleSided":true,"emissiveFactor":[1,0.5,0.25],
            "extensions":{{"KHR_materials_emissive_strength":{{"emissiveStrength":4}},
                           "KHR_materials_ior":{{"ior":1.33}},
                           "KHR_materials_transmission":{{"transmissionFactor":0.75}},
                           "KHR_materials_specular":{{"specularFactor":0.3,"specularColorFactor":[0.5,0.6,0.7]}}}}}},
          {{"alphaMode":"BLEND"}},
          {{"alphaMode":"MASK"}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}},"indices":{i},"material":0}}]}}]{ONE_NODE}"#
    ));
    let scene = load(&json).unwrap();
    let m = &scene.materials[0];
    assert_eq!(
        m.emissive,
        Vec3::new(4.0, 2.0, 1.0),
        "emissive strength multiplies"
    );
    assert_eq!(m.alpha_mode, AlphaMode::Mask { cutoff: 0.25 });
    assert!(m.double_sided);
    assert_eq!(m.ior, 1.33);
    assert_eq!(m.transmission, 0.75);
    assert_eq!(m.specular, 0.3);
    assert_eq!(m.specular_color, Vec3::new(0.5, 0.6, 0.7));
    assert_eq!(scene.materials[1].alpha_mode, AlphaMode::Blend);
    assert_eq!(
        scene.materials[2].alpha_mode,
        AlphaMode::Mask { cutoff: 0.5 }
    );
    let f = scene.features;
    assert!(f.emissive && f.transmission && f.alpha_mask && !f.textures);
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
}

/// A 2×2 RGBA image with distinct texels, as a PNG data URI image entry.
fn texels_png() -> (Vec<u8>, [[u8; 4]; 4]) {
    let texels = [
        [128, 64, 200, 255],
        [10, 20, 30, 40],
        [255, 0, 0, 255],
        [0, 255, 0, 128],
    ];
    let mut img = image::RgbaImage::new(2, 2);
    for (k, t) in texels.iter().enumerate() {
        img.put_pixel(k as u32 % 2, k as u32 / 2, image::Rgba(*t));
    }
    (png(image::DynamicImage::ImageRgba8(img)), texels)
}

#[test]
fn colour_textures_decode_as_srgb_and_data_textures_stay_linear() {
    let (png_bytes, texels) = texels_png();
    let mut doc = Doc::default();
    let (p, _, t, i) = quad(&mut doc);
    let image_view = doc.view(&png_bytes);
    let json = doc.json(&format!(
        r#","images":[{{"bufferView":{image_view},"mimeType":"image/png"}}],
        "samplers":[{{"magFilter":9728,"wrapS":33071,"wrapT":33648}}],
        "textures":[{{"source":0,"sampler":0}}],
        "materials":[{{"emissiveFactor":[1,1,1],
            "emissiveTexture":{{"index":0}},
            "pbrMetallicRoughness":{{"baseColorTexture":{{"index":0}},"metallicRoughnessTexture":{{"index":0}}}}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"TEXCOORD_0":{t}}},"indices":{i},"material":0}}]}}]{ONE_NODE}"#
    ));
    let scene = load(&json).unwrap();
    assert_eq!(
        scene.textures.len(),
        1,
        "one image with one sampler is one texture"
    );
    let tex = &scene.textures[0];
    assert_eq!((tex.width, tex.height), (2, 2));
    assert_eq!(tex.texels, texels.to_vec(), "texels are stored as encoded");
    assert_eq!(
        (tex.wrap_s, tex.wrap_t, tex.filter),
        (Wrap::ClampToEdge, Wrap::MirroredRepeat, Filter::Nearest)
    );
    assert!(scene.features.textures && scene.features.emissive);

    // The top-left texel, through the material.
    let m = &scene.materials[0];
    let uv = Vec2::new(0.25, 0.25);
    let s = m.sample(&scene.textures, [uv, uv], Vec4::ONE);
    let [r, g, b, _] = texels[0].map(|c| c as f32 / 255.0);
    let base = s.surface.base_color;
    assert!(
        (base - Vec3::new(srgb_to_linear(r), srgb_to_linear(g), srgb_to_linear(b))).length() < 1e-5
    );
    assert!((s.emission - base).length() < 1e-6, "emissive is sRGB too");
    assert!(
        (s.surface.roughness - g).abs() < 1e-6,
        "roughness (G) stays linear"
    );
    assert!(
        (s.surface.metallic - b).abs() < 1e-6,
        "metallic (B) stays linear"
    );
}

#[test]
fn texture_transforms_and_texcoord_overrides_are_read() {
    let (png_bytes, _) = texels_png();
    let mut doc = Doc::default();
    let (p, n, t, i) = quad(&mut doc);
    let image_view = doc.view(&png_bytes);
    let json = doc.json(&format!(
        r#","extensionsUsed":["KHR_texture_transform","KHR_materials_specular"],
        "images":[{{"bufferView":{image_view},"mimeType":"image/png"}}],
        "textures":[{{"source":0}}],
        "materials":[{{
            "pbrMetallicRoughness":{{"baseColorTexture":{{"index":0,"texCoord":0,
                "extensions":{{"KHR_texture_transform":{{"offset":[0.5,0.25],"rotation":0.5,"scale":[2,3],"texCoord":1}}}}}}}},
            "normalTexture":{{"index":0,"scale":0.5,
                "extensions":{{"KHR_texture_transform":{{"rotation":1.5}}}}}},
            "extensions":{{"KHR_materials_specular":{{"specularTexture":{{"index":0}},"specularColorTexture":{{"index":0,"texCoord":1}}}}}}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n},"TEXCOORD_0":{t},"TEXCOORD_1":{t}}},"indices":{i},"material":0}}]}}]{ONE_NODE}"#
    ));
    let scene = load(&json).unwrap();
    let m = &scene.materials[0];
    let base = m.base_color_texture.unwrap();
    assert_eq!(base.texcoord, 1, "the extension's texCoord overrides");
    let tr = base.transform.unwrap();
    assert_eq!(
        (tr.offset, tr.rotation, tr.scale),
        (Vec2::new(0.5, 0.25), 0.5, Vec2::new(2.0, 3.0))
    );
    let normal = m.normal_texture.unwrap();
    assert_eq!(normal.transform.unwrap().rotation, 1.5);
    assert_eq!(m.normal_scale, 0.5);
    assert_eq!(m.specular_texture.unwrap().texcoord, 0);
    assert_eq!(m.specular_color_texture.unwrap().texcoord, 1);
    assert!(m.specular_texture.unwrap().transform.is_none());
}

#[test]
fn tangents_are_generated_for_normal_maps() {
    let (png_bytes, _) = texels_png();
    for (uvs, tangent) in [
        // Upright mapping: u along +X, image up along +Y.
        ([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]], Vec3::X),
        // Turned a quarter: u along +Y, image up along -X.
        ([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]], Vec3::Y),
    ] {
        let mut doc = Doc::default();
        let (p, n, _, i) = quad(&mut doc);
        let t = doc.vec2(&uvs);
        let image_view = doc.view(&png_bytes);
        let json = doc.json(&format!(
            r#","images":[{{"bufferView":{image_view},"mimeType":"image/png"}}],"textures":[{{"source":0}}],
            "materials":[{{"normalTexture":{{"index":0}}}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n},"TEXCOORD_0":{t}}},"indices":{i},"material":0}}]}}]{ONE_NODE}"#
        ));
        let scene = load(&json).unwrap();
        assert!(scene.features.normal_maps);
        let prim = &scene.meshes[0].primitives[0];
        assert_eq!(prim.tangents.len(), prim.positions.len());
        for (tg, nrm) in prim.tangents.iter().zip(&prim.normals) {
            let xyz = tg.truncate();
            assert!((xyz.length() - 1.0).abs() < 1e-5, "{tg}");
            assert!(xyz.dot(*nrm).abs() < 1e-5, "{tg} against {nrm}");
            assert!(
                (xyz - tangent).length() < 1e-5,
                "{tg} should follow +U ({tangent})"
            );
            // glTF: bitangent = cross(normal, tangent) * w points up the image (-v).
            let bitangent = nrm.cross(xyz) * tg.w;
            let up = if tangent == Vec3::X {
                Vec3::Y
            } else {
                Vec3::NEG_X
            };
            assert!(
                (bitangent - up).length() < 1e-5,
                "bitangent {bitangent}, want {up}"
            );
        }
    }
}

#[test]
fn a_normal_map_without_normals_gets_flat_normals_and_tangents() {
    let (png_bytes, _) = texels_png();
    let mut doc = Doc::default();
    let (p, _, t, i) = quad(&mut doc);
    let image_view = doc.view(&png_bytes);
    let json = doc.json(&format!(
        r#","images":[{{"bufferView":{image_view}, "mimeType":"image/png"}}],"textures":[{{"source":0}}],
        "materials":[{{"normalTexture":{{"index":0}}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"TEXCOORD_0":{t}}},"indices":{i},"material":0}}]}}]{ONE_NODE}"#
    ));
    let scene = load(&json).unwrap();
    let prim = &scene.meshes[0].primitives[0];
    assert_eq!(prim.indices.len(), 2);
    assert_eq!(prim.normals.len(), prim.positions.len());
    assert!(prim.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
    assert!(prim
        .tangents
        .iter()
        .all(|t| (t.truncate() - Vec3::X).length() < 1e-5));
}

// ---------------------------------------------------------------------------------------
// Cameras and lights

#[test]
fn cameras_and_punctual_lights() {
    let json = r#"{"asset":{"version":"2.0"},
        "extensionsUsed":["KHR_lights_punctual"],
        "cameras":[{"type":"perspective","perspective":{"yfov":0.8,"znear":0.1,"aspectRatio":1.5}},
                   {"type":"orthographic","orthographic":{"xmag":2,"ymag":3,"znear":0,"zfar":10}}],
        "extensions":{"KHR_lights_punctual":{"lights":[
            {"type":"point","color":[1,0.5,0.25],"intensity":8,"range":20},
            {"type":"spot","spot":{}},
            {"type":"directional","intensity":3}]}},
        "scenes":[{"nodes":[0,1,2]}],
        "nodes":[{"camera":0},{"camera":1,"children":[3]},
                 {"extensions":{"KHR_lights_punctual":{"light":1}}},
                 {"extensions":{"KHR_lights_punctual":{"light":0}}}]}"#;
    let scene = load(json).unwrap();
    assert_eq!(
        scene.cameras[0].projection,
        Projection::Perspective {
            yfov: 0.8,
            aspect_ratio: Some(1.5),
            znear: 0.1
        }
    );
    assert_eq!(
        scene.cameras[1].projection,
        Projection::Orthographic {
            xmag: 2.0,
            ymag: 3.0,
            znear: 0.0
        }
    );
    assert_eq!(
        scene.lights[0],
        PunctualLight::Point {
            intensity: Vec3::new(8.0, 4.0, 2.0),
            range: Some(20.0)
        }
    );
    assert_eq!(
        scene.lights[1],
        PunctualLight::Spot {
            intensity: Vec3::ONE,
            range: None,
            inner_cone: 0.0,
            outer_cone: std::f32::consts::FRAC_PI_4
        }
    );
    assert_eq!(
        scene.lights[2],
        PunctualLight::Directional {
            illuminance: Vec3::splat(3.0)
        }
    );
    assert_eq!(
        (
            scene.nodes[2].light,
            scene.nodes[3].light,
            scene.nodes[1].camera
        ),
        (Some(1), Some(0), Some(1))
    );
    assert!(scene.features.punctual_lights);
}

#[test]
fn the_framing_camera_sees_the_whole_scene() {
    let mut doc = Doc::default();
    let (p, _, _, i) = quad(&mut doc);
    let json = doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}},"indices":{i}}}]}}],
        "scenes":[{{"nodes":[0,1]}}],
        "nodes":[{{"mesh":0,"translation":[10,0,0]}},{{"mesh":0,"translation":[10,0,-4],"scale":[1,3,1]}}]"#
    ));
    let scene = load(&json).unwrap();
    let b = loader::scene_bounds(&scene);
    assert_eq!(
        (b.min, b.max),
        (Vec3::new(10.0, 0.0, -4.0), Vec3::new(11.0, 3.0, 0.0))
    );
    for aspect in [0.5f32, 1.0, 2.0] {
        let (proj, to_world) = loader::framing_camera(&b, aspect);
        let Projection::Perspective { yfov, znear, .. } = proj else {
            panic!("{proj:?}")
        };
        assert!((yfov.to_degrees() - 40.0).abs() < 1e-3);
        let from_world = to_world.inverse();
        // The camera looks at the centre...
        let c = from_world.transform_point3(b.center().as_dvec3());
        assert!(c.x.abs() < 1e-9 && c.y.abs() < 1e-9 && c.z < 0.0, "{c}");
        // ... from the front-right-top, upright ...
        let eye = to_world.w_axis.truncate();
        let d = (eye - b.center().as_dvec3()).normalize();
        assert!(d.x > 0.0 && d.y > 0.0 && d.z > d.x && d.z > d.y, "{d}");
        assert!(to_world.y_axis.truncate().y > 0.0);
        // ... and every corner is in view and past the near plane.
        let t = (0.5 * yfov as f64).tan();
        for corner in b.corners() {
            let q = from_world.transform_point3(corner.as_dvec3());
            assert!(
                -q.z > znear as f64,
                "corner {corner} in front of the near plane"
            );
            assert!(
                (q.x / -q.z).abs() <= t * aspect as f64 + 1e-9,
                "{corner} at aspect {aspect}"
            );
            assert!(
                (q.y / -q.z).abs() <= t + 1e-9,
                "{corner} at aspect {aspect}"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------
// Packing

#[test]
fn packing_a_gltf_with_files_gives_the_same_scene() {
    let (png_bytes, _) = texels_png();
    let mut doc = Doc::default();
    let (p, n, t, i) = quad(&mut doc);
    let dir = temp_dir("pack");
    std::fs::write(dir.join("quad data.bin"), &doc.bin).unwrap();
    std::fs::write(dir.join("tex.png"), &png_bytes).unwrap();
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},
        "buffers":[{{"byteLength":{},"uri":"quad%20data.bin"}}],
        "bufferViews":[{}],"accessors":[{}],
        "images":[{{"uri":"tex.png"}}],"textures":[{{"source":0}}],
        "materials":[{{"pbrMetallicRoughness":{{"baseColorTexture":{{"index":0}}}}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n},"TEXCOORD_0":{t}}},"indices":{i},"material":0}}]}}]{ONE_NODE}}}"#,
        doc.bin.len(),
        doc.views.join(","),
        doc.accessors.join(",")
    );
    let path = dir.join("quad.gltf");
    std::fs::write(&path, json).unwrap();

    let direct = loader::load_path(&path).unwrap();
    let glb = loader::pack_glb(&path).unwrap();
    assert!(glb.starts_with(b"glTF"));
    let packed = loader::load_glb(&glb).unwrap();
    let (a, b) = (SceneSummary::of(&direct), SceneSummary::of(&packed));
    assert_eq!((a.triangles, a.materials, a.textures), (2, 1, 1));
    assert_eq!(a, b);
    assert_eq!(direct.textures[0].texels, packed.textures[0].texels);
    // The GLB no longer needs the folder.
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(loader::load_glb(&glb).is_ok());
}

// ---------------------------------------------------------------------------------------
// Errors

fn message(r: Result<Scene, SceneError>) -> String {
    match r {
        Ok(_) => panic!("loaded, but should have failed"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn an_index_out_of_range_names_accessor_mesh_and_primitive() {
    let mut doc = Doc::default();
    let p = doc.vec3(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0; 3]]);
    let i = doc.u16s(&[0, 1, 2, 2, 3, 7]);
    let json = doc.json(&format!(
        r#","meshes":[{{"name":"Body","primitives":[{{"attributes":{{"POSITION":{p}}},"indices":{i}}}]}}]{ONE_NODE}"#
    ));
    let err = load(&json).unwrap_err();
    assert_eq!(err.element(), Some(Element::Accessor(i)));
    assert_eq!(
        err.to_string(),
        format!("accessor {i}: index 7 out of range for 4 vertices in mesh 'Body', primitive 0")
    );
}

#[test]
fn a_missing_buffer_file_is_named() {
    let dir = temp_dir("missing");
    let path = dir.join("Box.gltf");
    std::fs::write(
        &path,
        r#"{"asset":{"version":"2.0"},"buffers":[{"byteLength":4,"uri":"data:application/octet-stream;base64,AAAAAA=="},{"byteLength":648,"uri":"Box0.bin"}]}"#,
    )
    .unwrap();
    assert_eq!(
        message(loader::load_path(&path)),
        "buffer 1: file 'Box0.bin' not found"
    );
    let short = r#"{"asset":{"version":"2.0"},"buffers":[{"byteLength":8,"uri":"data:application/octet-stream;base64,AAAAAA=="}]}"#;
    assert_eq!(
        message(load(short)),
        "buffer 0: byteLength is 8, but its data: URI holds only 4 bytes"
    );
    let missing_scene = dir.join("nope.gltf");
    assert!(message(loader::load_path(&missing_scene)).contains("nope.gltf"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn extensions_required_and_used() {
    let required = r#"{"asset":{"version":"2.0"},"extensionsUsed":["KHR_draco_mesh_compression"],
        "extensionsRequired":["KHR_draco_mesh_compression"]}"#;
    assert_eq!(
        message(load(required)),
        "required extension 'KHR_draco_mesh_compression' is not supported"
    );
    // KHR_materials_specular is one we implement though the gltf crate does not list it.
    let ours = r#"{"asset":{"version":"2.0"},"extensionsUsed":["KHR_materials_specular","KHR_texture_transform"],
        "extensionsRequired":["KHR_materials_specular","KHR_texture_transform"]}"#;
    assert!(load(ours).is_ok());
    let optional =
        r#"{"asset":{"version":"2.0"},"extensionsUsed":["KHR_materials_pbrSpecularGlossiness"]}"#;
    let scene = load(optional).unwrap();
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("'KHR_materials_pbrSpecularGlossiness'")),
        "{:?}",
        scene.warnings
    );
}

#[test]
fn cyclic_nodes_are_refused() {
    let json = r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],
        "nodes":[{"children":[1]},{"children":[2]},{"children":[1]}]}"#;
    let err = load(json).unwrap_err();
    assert!(matches!(err.element(), Some(Element::Node(_))), "{err}");
    assert!(err.to_string().contains("cycle"), "{err}");
    let self_loop = r#"{"asset":{"version":"2.0"},"nodes":[{"children":[0]}]}"#;
    assert_eq!(
        message(load(self_loop)),
        "node 0: child node 0 is also its ancestor: the node graph has a cycle"
    );
}

#[test]
fn non_finite_positions_are_refused() {
    let mut doc = Doc::default();
    let p = doc.floats(
        &[0.0, 0.0, 0.0, 1.0, f32::INFINITY, 0.0, 0.0, 1.0, 0.0],
        "VEC3",
        3,
    );
    // JSON has no infinity: the bounds the validator insists on are finite.
    let acc = doc.accessors[p].trim_end_matches('}').to_owned();
    doc.accessors[p] = format!(r#"{acc},"min":[0,0,0],"max":[1,1,0]}}"#);
    let json = doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}}}}]}}]{ONE_NODE}"#
    ));
    let m = message(load(&json));
    assert!(
        m.starts_with(&format!("accessor {p}: position 1")) && m.contains("mesh 0, primitive 0"),
        "{m}"
    );
}

#[test]
fn not_gltf_at_all() {
    for bytes in [&b"hello"[..], b"", b"\x89PNG\r\n\x1a\n", b"[1,2]"] {
        let err = loader::load_slice(bytes, None).unwrap_err();
        assert!(matches!(err, SceneError::NotGltf(_)), "{err}");
    }
    assert!(matches!(
        loader::load_slice(b"{\"asset\":", None),
        Err(SceneError::Json(_))
    ));
    assert!(
        matches!(load(r#"{"nodes":[]}"#), Err(SceneError::Json(_))),
        "asset is required"
    );
    let m = message(load(r#"{"asset":{"version":"2.0"},"nodes":[{"mesh":3}]}"#));
    assert!(m.starts_with("invalid glTF: nodes[0].mesh"), "{m}");
    let json_as_glb = loader::load_glb(br#"{"asset":{"version":"2.0"}}"#).unwrap_err();
    assert!(
        json_as_glb.to_string().contains("not a GLB"),
        "{json_as_glb}"
    );
}

#[test]
fn json_of_the_wrong_type_names_its_path() {
    // A one-line document (as in a GLB): line and column alone do not say where.
    let count = r#"{"asset":{"version":"2.0"},"buffers":[{"byteLength":12}],"accessors":[{"componentType":5126,"type":"VEC3","count":"three"}]}"#;
    assert_eq!(
        message(load(count)),
        "malformed glTF JSON: accessors[0].count: invalid type: string \"three\", \
         expected u64 at line 1 column 121"
    );
    let nodes = r#"{"asset":{"version":"2.0"},"nodes":{"0":{"mesh":0}}}"#;
    let m = message(load(nodes));
    assert!(
        m.starts_with("malformed glTF JSON: nodes: invalid type: map, expected a sequence"),
        "{m}"
    );
    // The same through the path taken when unsupported animation channels are stripped.
    let stripped = r#"{"asset":{"version":"2.0"},"nodes":{"0":{}},"animations":[{"samplers":[],
        "channels":[{"sampler":0,"target":{"path":"pointer"}}]}]}"#;
    let m = message(load(stripped));
    assert!(
        m.starts_with("malformed glTF JSON: nodes: invalid type: map"),
        "{m}"
    );
}

/// A small valid GLB: a quad with its data in the BIN chunk.
fn quad_glb() -> Vec<u8> {
    let mut doc = Doc::default();
    let (p, n, t, i) = quad(&mut doc);
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"byteLength":{}}}],"bufferViews":[{}],"accessors":[{}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n},"TEXCOORD_0":{t}}},"indices":{i}}}]}}]{ONE_NODE}}}"#,
        doc.bin.len(),
        doc.views.join(","),
        doc.accessors.join(",")
    );
    glb(&json, &doc.bin)
}

#[test]
fn truncated_glbs_are_refused_by_name() {
    let bytes = quad_glb();
    assert_eq!(
        SceneSummary::of(&loader::load_glb(&bytes).unwrap()).triangles,
        2
    );
    for cut in [4, 11, 12, 19, 40, bytes.len() / 2, bytes.len() - 1] {
        let err = loader::load_glb(&bytes[..cut]).unwrap_err();
        assert!(matches!(err, SceneError::Glb(_)), "cut at {cut}: {err}");
        assert!(err.to_string().contains("truncated"), "cut at {cut}: {err}");
    }
}

#[test]
fn a_glb_may_not_refer_to_outside_files() {
    let json = r#"{"asset":{"version":"2.0"},"buffers":[{"byteLength":4,"uri":"outside.bin"}]}"#;
    let err = loader::load_glb(&glb(json, &[])).unwrap_err();
    assert_eq!(err.element(), Some(Element::Buffer(0)));
    assert!(err.to_string().contains("'outside.bin'"), "{err}");
}

#[test]
fn damaged_glbs_fail_cleanly_and_never_panic() {
    let good = quad_glb();
    // A deterministic stream of single-byte and four-byte corruptions over the whole file.
    let mut state = 0x2545_f491_u32;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state
    };
    let mut failures = 0;
    let json_end = 20 + u32::from_le_bytes(good[12..16].try_into().unwrap()) as usize;
    let digits: Vec<usize> = (20..json_end)
        .filter(|&i| good[i].is_ascii_digit())
        .collect();
    for _ in 0..3000 {
        let mut bytes = good.clone();
        let at = next() as usize % bytes.len();
        match next() % 3 {
            0 => bytes[at] = next() as u8,
            1 => {
                let end = (at + 4).min(bytes.len());
                bytes[at..end].fill(0xFF);
            }
            // A different number in the JSON: still JSON, but other indices and counts.
            _ => {
                bytes[digits[next() as usize % digits.len()]] = b"0123456789"[next() as usize % 10]
            }
        }
        if let Err(e) = loader::load_glb(&bytes) {
            assert!(!e.to_string().is_empty());
            failures += 1;
        }
    }
    assert!(failures > 0);
}
