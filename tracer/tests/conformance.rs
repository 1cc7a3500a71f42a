//! Conformance against the Khronos sample models in `shared/scenes` (beside the workspace):
//! every model loads, and the counts its MANIFEST.md states (triangles, cameras, lights)
//! come out. When the folder is absent the tests say so and pass.
//!
//! Hook for rendering checks: [`scene_files`] lists every model file.

use std::path::{Path, PathBuf};

use glam::Vec2;
use tracer::camera::Projection;
use tracer::loader::{self, SceneSummary};
use tracer::scene::Scene;

/// What MANIFEST.md says about one model file: triangles over all meshes, triangles the
/// default scene draws, cameras, punctual lights.
struct Expected {
    file: &'static str,
    mesh_triangles: u64,
    drawn_triangles: u64,
    cameras: usize,
    lights: usize,
}

const fn model(file: &'static str, tris: u64, cameras: usize, lights: usize) -> Expected {
    Expected {
        file,
        mesh_triangles: tris,
        drawn_triangles: tris,
        cameras,
        lights,
    }
}

/// The manifest's table. Where instancing or an unreferenced mesh makes the default scene
/// draw a different number, the second count says so.
const MANIFEST: &[Expected] = &[
    model("AlphaBlendModeTest/AlphaBlendModeTest.glb", 61, 0, 0),
    model("AnimatedCube/AnimatedCube.gltf", 12, 0, 0),
    model("AnimatedMorphCube/AnimatedMorphCube.glb", 12, 0, 0),
    model("Avocado/Avocado.gltf", 682, 0, 0),
    model("Box/Box.glb", 12, 0, 0),
    model("Box/Box.gltf", 12, 0, 0),
    model("Box/Box_embedded.gltf", 12, 0, 0),
    model("BoxAnimated/BoxAnimated.glb", 254, 0, 0),
    model("BoxInterleaved/BoxInterleaved.glb", 12, 0, 0),
    model("BoxTextured/BoxTextured.glb", 12, 0, 0),
    model("Cameras/Cameras.gltf", 2, 2, 0),
    model("Duck/Duck.glb", 4_212, 1, 0),
    model("EmissiveStrengthTest/EmissiveStrengthTest.glb", 90, 0, 0),
    model("InterpolationTest/InterpolationTest.glb", 110, 0, 0),
    model("LightsPunctualLamp/LightsPunctualLamp.gltf", 6_000, 0, 5),
    model(
        "MetalRoughSpheresNoTextures/MetalRoughSpheresNoTextures.glb",
        1_040_409,
        0,
        0,
    ),
    Expected {
        file: "MultipleScenes/MultipleScenes.gltf",
        mesh_triangles: 3,
        drawn_triangles: 2,
        cameras: 0,
        lights: 0,
    },
    model("NormalTangentTest/NormalTangentTest.glb", 7_774, 0, 0),
    model("RiggedFigure/RiggedFigure.glb", 256, 0, 0),
    model("RiggedSimple/RiggedSimple.glb", 188, 0, 0),
    model("SimpleSkin/SimpleSkin.gltf", 8, 0, 0),
    Expected {
        file: "TextureTransformTest/TextureTransformTest.gltf",
        mesh_triangles: 18,
        drawn_triangles: 24,
        cameras: 0,
        lights: 0,
    },
    model("TransmissionTest/TransmissionTest.glb", 128_775, 1, 0),
    // Added 2026-11-26.
    Expected {
        file: "AnisotropyRotationTest/AnisotropyRotationTest.glb",
        mesh_triangles: 7_476,
        drawn_triangles: 13_876,
        cameras: 0,
        lights: 0,
    },
    model(
        "AnisotropyStrengthTest/AnisotropyStrengthTest.glb",
        97_240,
        0,
        0,
    ),
    model("ClearCoatTest/ClearCoatTest.glb", 37_116, 0, 0),
    model("ClearcoatWicker/ClearcoatWicker.glb", 3_072, 0, 0),
    model("GlassBrokenWindow/GlassBrokenWindow.glb", 987, 0, 0),
    Expected {
        file: "GlassVaseFlowers/GlassVaseFlowers.glb",
        mesh_triangles: 10_218,
        drawn_triangles: 14_036,
        cameras: 0,
        lights: 0,
    },
    model("IridescenceLamp/IridescenceLamp.gltf", 18_866, 0, 0),
    model(
        "IridescentDishWithOlives/IridescentDishWithOlives.gltf",
        24_448,
        1,
        0,
    ),
    model("SheenChair/SheenChair.gltf", 39_936, 0, 0),
    model("SheenCloth/SheenCloth.gltf", 115_200, 0, 0),
    // EXT_mesh_gpu_instancing: one 12-triangle cube drawn 125 times.
    Expected {
        file: "SimpleInstancing/SimpleInstancing.glb",
        mesh_triangles: 12,
        drawn_triangles: 1_500,
        cameras: 0,
        lights: 0,
    },
    model("SpecularTest/SpecularTest.glb", 44_828, 0, 0),
];

/// The shared scenes folder, if this checkout has one.
pub fn scenes_dir() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/scenes");
    dir.is_dir().then_some(dir)
}

/// Every .gltf and .glb file under the shared scenes folder, sorted; empty without it.
pub fn scene_files() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(&p, out);
            } else if matches!(p.extension().and_then(|e| e.to_str()), Some("gltf" | "glb")) {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    if let Some(dir) = scenes_dir() {
        walk(&dir, &mut out);
    }
    out.sort();
    out
}

fn load(rel: &str) -> Option<Scene> {
    let dir = scenes_dir()?;
    Some(loader::load_path(&dir.join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}")))
}

fn skip(test: &str) {
    println!("{test}: skipped, no shared/scenes folder beside the workspace");
}

#[test]
fn every_model_loads_with_the_manifest_counts() {
    let Some(dir) = scenes_dir() else {
        return skip("manifest counts");
    };
    let files = scene_files();
    for e in MANIFEST {
        assert!(
            dir.join(e.file).is_file(),
            "{} is in the manifest but not on disk",
            e.file
        );
    }
    let mut failures = Vec::new();
    for path in &files {
        let rel = path
            .strip_prefix(&dir)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        let scene = match loader::load_path(path) {
            Ok(s) => s,
            Err(err) => {
                failures.push(format!("{rel}: {err}"));
                continue;
            }
        };
        let s = SceneSummary::of(&scene);
        println!(
            "{rel}: {} drawn / {} unique triangles, {} cameras, {} lights, {} materials, \
             {} textures, features {:?}, {} warnings",
            s.triangles,
            s.unique_triangles,
            s.cameras,
            s.lights,
            s.materials,
            s.textures,
            s.features.names(),
            s.warnings
        );
        for w in &scene.warnings {
            println!("    warning: {w}");
        }
        let Some(e) = MANIFEST.iter().find(|e| e.file == rel) else {
            println!("    (not in the manifest table: loaded, counts not checked)");
            continue;
        };
        let got = (s.unique_triangles, s.triangles, s.cameras, s.lights);
        let want = (e.mesh_triangles, e.drawn_triangles, e.cameras, e.lights);
        if got != want {
            failures.push(format!(
                "{rel}: (mesh triangles, drawn, cameras, lights) = {got:?}, manifest says {want:?}"
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn the_three_box_containers_load_alike() {
    let (Some(glb), Some(gltf), Some(embedded)) = (
        load("Box/Box.glb"),
        load("Box/Box.gltf"),
        load("Box/Box_embedded.gltf"),
    ) else {
        return skip("Box containers");
    };
    let s = SceneSummary::of(&glb);
    assert_eq!(s, SceneSummary::of(&gltf));
    assert_eq!(s, SceneSummary::of(&embedded));
    let p = |sc: &Scene| sc.meshes[0].primitives[0].positions.clone();
    assert_eq!(p(&glb), p(&gltf));
    assert_eq!(p(&glb), p(&embedded));
    // The root node's matrix turns Y-up into Z-up.
    assert_eq!(
        glb.nodes[glb.roots[0] as usize].local,
        gltf.nodes[gltf.roots[0] as usize].local
    );
}

#[test]
fn packing_every_gltf_keeps_its_counts() {
    let files: Vec<_> = scene_files()
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "gltf"))
        .collect();
    if files.is_empty() {
        return skip("packing");
    }
    for path in files {
        let direct = SceneSummary::of(&loader::load_path(&path).unwrap());
        let glb = loader::pack_glb(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let packed = loader::load_glb(&glb).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(SceneSummary::of(&packed), direct, "{}", path.display());
    }
}

#[test]
fn multiple_scenes_draws_the_default_scene() {
    let Some(scene) = load("MultipleScenes/MultipleScenes.gltf") else {
        return skip("MultipleScenes");
    };
    // The document's `scene` is 1, whose only node is node 1.
    assert_eq!(scene.roots, vec![1]);
}

#[test]
fn cameras_are_perspective_and_orthographic() {
    let Some(scene) = load("Cameras/Cameras.gltf") else {
        return skip("Cameras");
    };
    assert!(matches!(
        scene.cameras[0].projection,
        Projection::Perspective { yfov, aspect_ratio: Some(a), znear }
            if (yfov - 0.7).abs() < 1e-6 && a == 1.0 && znear == 0.01
    ));
    assert!(matches!(
        scene.cameras[1].projection,
        Projection::Orthographic { xmag: 1.0, ymag: 1.0, znear } if znear == 0.01
    ));
    assert_eq!(scene.nodes.iter().filter(|n| n.camera.is_some()).count(), 2);
}

#[test]
fn the_lamp_has_lights_and_transmission() {
    let Some(scene) = load("LightsPunctualLamp/LightsPunctualLamp.gltf") else {
        return skip("LightsPunctualLamp");
    };
    let f = scene.features;
    assert!(
        f.punctual_lights && f.transmission && f.textures && f.normal_maps,
        "{f:?}"
    );
    assert!(!f.environment);
}

#[test]
fn emissive_strength_goes_past_one() {
    let Some(scene) = load("EmissiveStrengthTest/EmissiveStrengthTest.glb") else {
        return skip("EmissiveStrengthTest");
    };
    assert!(scene.features.emissive);
    let brightest = scene
        .materials
        .iter()
        .map(|m| m.emissive.max_element())
        .fold(0.0, f32::max);
    assert!(brightest > 1.0, "brightest emissive {brightest}");
}

#[test]
fn normal_tangent_test_gets_generated_tangents() {
    let Some(scene) = load("NormalTangentTest/NormalTangentTest.glb") else {
        return skip("NormalTangentTest");
    };
    assert!(scene.features.normal_maps);
    let mut checked = 0;
    for mesh in &scene.meshes {
        for p in &mesh.primitives {
            if scene.materials[p.material as usize]
                .normal_texture
                .is_none()
            {
                continue;
            }
            assert_eq!(p.tangents.len(), p.positions.len());
            for (t, n) in p.tangents.iter().zip(&p.normals) {
                assert!((t.truncate().length() - 1.0).abs() < 1e-3, "{t}");
                assert!(t.truncate().dot(*n).abs() < 1e-3, "{t} against {n}");
                assert!(t.w == 1.0 || t.w == -1.0);
            }
            checked += 1;
        }
    }
    assert!(checked > 0);
}

/// The test model's rotation quad: the green marker (where the arrow must point) sits at
/// UV angle 67.5° from the UV origin, the red one (rotation applied the wrong way) at
/// 22.5°. The arrow texture points along UV angle 45°: sampling through the material's
/// transform along the green direction must hit the arrow; along the red one it lands on
/// the texture's top edge (grey border and white), never on the arrow.
#[test]
fn texture_transform_rotation_matches_the_sample_model() {
    let Some(scene) = load("TextureTransformTest/TextureTransformTest.gltf") else {
        return skip("TextureTransformTest");
    };
    let m = scene
        .materials
        .iter()
        .find(|m| m.name.as_deref() == Some("Rotation"))
        .unwrap();
    let tref = m.base_color_texture.unwrap();
    let t = tref
        .transform
        .expect("the Rotation material has a transform");
    assert!((t.rotation - std::f32::consts::FRAC_PI_8).abs() < 1e-6);
    let tex = &scene.textures[tref.texture as usize];
    let darkness = |deg: f32| {
        // Average over the arrow's shaft and head, 0.3 to 0.9 UV units out.
        let dir = Vec2::from_angle(deg.to_radians());
        let mut sum = 0.0;
        for k in 0..13 {
            let uv = dir * (0.3 + 0.05 * k as f32);
            sum += 1.0 - tex.sample(tref.uv([uv, uv]), true).x;
        }
        sum / 13.0
    };
    let (green, red) = (darkness(67.5), darkness(22.5));
    assert!(
        green > 0.9 && red < 0.5,
        "dark along green {green}, along red {red}"
    );
}

/// Our MikkTSpace tangents agree with those the Avocado's exporter wrote: removing its
/// TANGENT attribute and regenerating gives the same directions and handedness.
#[test]
fn generated_tangents_agree_with_exported_ones() {
    let Some(dir) = scenes_dir() else {
        return skip("Avocado tangents");
    };
    let path = dir.join("Avocado/Avocado.gltf");
    let with = loader::load_path(&path).unwrap();
    let mut json: serde_json_value::Value =
        serde_json_value::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    for mesh in json["meshes"].as_array_mut().unwrap() {
        for prim in mesh["primitives"].as_array_mut().unwrap() {
            prim["attributes"]
                .as_object_mut()
                .unwrap()
                .remove("TANGENT");
        }
    }
    let bytes = serde_json_value::to_vec(&json).unwrap();
    let without = loader::load_slice(&bytes, Some(&dir.join("Avocado"))).unwrap();
    let (a, b) = (
        &with.meshes[0].primitives[0],
        &without.meshes[0].primitives[0],
    );
    assert!(b.tangents.len() >= a.positions.len());
    let n = a.positions.len();
    let mut same = 0;
    for v in 0..n {
        let (ta, tb) = (a.tangents[v], b.tangents[v]);
        if ta.w == tb.w && ta.truncate().dot(tb.truncate()) > 0.9 {
            same += 1;
        }
    }
    assert!(same * 10 >= n * 9, "{same} of {n} vertices agree");
}

/// `serde_json` through the `gltf` crate's re-export, so the tests need no new dependency.
mod serde_json_value {
    pub use gltf::json::deserialize::from_slice;
    pub use gltf::json::serialize::to_vec;
    pub use gltf::json::Value;
}

#[test]
fn every_model_renders_one_sample_without_nan() {
    use std::sync::Arc;
    use tracer::film::{SampleRange, TileRect};
    use tracer::render::{prepare_frame, render_region, FrameOptions, RenderSettings};

    let files = scene_files();
    if files.is_empty() {
        return skip("rendering");
    }
    for file in files {
        let scene = loader::load_path(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let options = FrameOptions {
            width: 64,
            height: 64,
            ..Default::default()
        };
        let frame = prepare_frame(Arc::new(scene), &options)
            .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let rect = TileRect::new(0, 0, 64, 64);
        let tile = render_region(
            &frame,
            &RenderSettings::default(),
            rect,
            SampleRange::new(0, 1),
            16,
            &|_| {},
        );
        let layers = tile.resolve();
        let name = file.display();
        assert!(
            layers.beauty.iter().all(|b| b.is_finite()),
            "{name}: non-finite pixel"
        );
        assert!(
            layers.depth.iter().all(|d| d.is_finite()),
            "{name}: non-finite depth"
        );
        // Every model is framed by its camera or the default one, so something is seen.
        assert!(
            layers.beauty.iter().any(|b| b.w > 0.0),
            "{name}: nothing visible"
        );
        println!("{name}: {} samples dropped", tile.dropped);
    }
}

/// Every animated model, at two times inside its animation, with motion blur: no NaN, and
/// the two images differ. Both frames use the same frame number (the random numbers' key)
/// and reach their times through different frame rates, so any difference comes from the
/// animation, not from noise.
#[test]
fn every_animated_model_moves_between_frames_without_nan() {
    use std::sync::Arc;
    use tracer::animation::time_range;
    use tracer::film::{SampleRange, TileRect};
    use tracer::motion::Shutter;
    use tracer::render::{prepare_frame, render_region, FrameOptions, RenderSettings};

    let files = scene_files();
    if files.is_empty() {
        return skip("animation rendering");
    }
    const FRAME: i32 = 10;
    let mut animated = 0;
    for file in files {
        let name = file.display().to_string();
        let scene = Arc::new(loader::load_path(&file).unwrap_or_else(|e| panic!("{name}: {e}")));
        let all: Vec<usize> = (0..scene.animations.len()).collect();
        let Some((start, end)) = time_range(&scene, &all).filter(|(s, e)| e > s) else {
            continue;
        };
        animated += 1;
        let render_at = |seconds: f64| {
            let options = FrameOptions {
                frame: FRAME,
                fps: FRAME as f64 / seconds,
                shutter: Shutter {
                    open: -0.25,
                    close: 0.25,
                },
                width: 48,
                height: 48,
                ..Default::default()
            };
            let frame = prepare_frame(scene.clone(), &options)
                .unwrap_or_else(|e| panic!("{name} at {seconds} s: {e}"));
            let tile = render_region(
                &frame,
                &RenderSettings::default(),
                TileRect::new(0, 0, 48, 48),
                SampleRange::new(0, 2),
                16,
                &|_| {},
            );
            (frame.motion_steps, tile.dropped, tile.resolve())
        };
        // Times strictly inside the animation, away from t = 0 (a frame rate needs t > 0).
        let t1 = start + 0.3 * (end - start);
        let t2 = start + 0.7 * (end - start);
        let (t1, t2) = (t1.max(1e-3), t2.max(2e-3));
        let (steps1, dropped1, a) = render_at(t1);
        let (steps2, dropped2, b) = render_at(t2);
        for (t, layers) in [(t1, &a), (t2, &b)] {
            assert!(
                layers.beauty.iter().all(|p| p.is_finite())
                    && layers.depth.iter().all(|d| d.is_finite()),
                "{name} at {t:.3} s: non-finite pixel"
            );
        }
        assert_eq!((dropped1, dropped2), (0, 0), "{name}: NaN samples");
        let changed = a
            .beauty
            .iter()
            .zip(&b.beauty)
            .filter(|(p, q)| p != q)
            .count();
        println!(
            "{name}: {start:.3}..{end:.3} s, {steps1} and {steps2} motion steps, \
             {changed} of 2304 pixels change between {t1:.3} s and {t2:.3} s"
        );
        assert!(
            changed > 0,
            "{name}: frames at {t1} s and {t2} s are identical"
        );
    }
    assert!(animated >= 7, "only {animated} animated models found");
}
