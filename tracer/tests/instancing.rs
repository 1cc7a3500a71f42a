//! EXT_mesh_gpu_instancing: the loader reads the instance transforms, every instance is
//! an instance of the frame's top-level BVH over one mesh BVH, a frame renders bit for
//! bit as the same scene written with one node per copy, and a scene cannot ask for more
//! draws than the tracer bounds.

// Test scenes use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use std::sync::Arc;

use glam::{DMat4, DQuat, DVec3, Vec3, Vec4};
use tracer::camera::Projection;
use tracer::film::{SampleRange, TileRect};
use tracer::light::Environment;
use tracer::loader::{self, SceneError, SceneSummary, MAX_MESH_DRAWS};
use tracer::material::Material;
use tracer::render::{prepare_frame, render_region, FrameOptions, RenderSettings};
use tracer::scene::{CameraDef, Node, Scene, SceneBuilder};
use tracer::shapes::cube;

mod common;

use common::gltf_doc::Doc;

fn load(json: &str) -> Result<Scene, SceneError> {
    loader::load_slice(json.as_bytes(), None)
}

/// A one-triangle mesh drawn by node 0 with `instancing` as its extension object.
fn instanced_triangle(doc: &mut Doc, instancing: &str) -> String {
    let p = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    doc.json(&format!(
        r#","extensionsUsed":["EXT_mesh_gpu_instancing"],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}}}}]}}],
        "scenes":[{{"nodes":[0]}}],
        "nodes":[{{"mesh":0,"translation":[0,0,-5],
            "extensions":{{"EXT_mesh_gpu_instancing":{instancing}}}}}]"#
    ))
}

#[test]
fn instance_transforms_apply_in_the_node_space() {
    let mut doc = Doc::default();
    let t = doc.vec3(&[[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]]);
    // A quarter turn about Z as normalised signed shorts (32767 is 1), as the spec allows.
    let half = (std::f32::consts::FRAC_1_SQRT_2 * 32767.0).round() as i16;
    let shorts: Vec<u8> = [[0, 0, 0, 32767], [0, 0, half, half], [0, 0, 0, 32767]]
        .iter()
        .flatten()
        .flat_map(|c: &i16| c.to_le_bytes())
        .collect();
    let r = doc.accessor(&shorts, 5122, "VEC4", 3, r#","normalized":true"#);
    let s = doc.vec3(&[[1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]]);
    let json = instanced_triangle(
        &mut doc,
        &format!(r#"{{"attributes":{{"TRANSLATION":{t},"ROTATION":{r},"SCALE":{s}}}}}"#),
    );
    let scene = load(&json).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let draws = loader::mesh_instances(&scene);
    assert_eq!(draws.len(), 3);
    // The vertex (1, 0, 0) of each copy, in world space: node translation after instance.
    let at = |k: usize| draws[k].1.transform_point3(DVec3::X);
    let close = |a: DVec3, b: DVec3| (a - b).length() < 1e-4;
    assert!(close(at(0), DVec3::new(2.0, 0.0, -5.0)), "{}", at(0));
    assert!(close(at(1), DVec3::new(0.0, 3.0, -5.0)), "{}", at(1));
    assert!(close(at(2), DVec3::new(2.0, 0.0, -2.0)), "{}", at(2));
    let summary = SceneSummary::of(&scene);
    assert_eq!(
        (
            summary.instances,
            summary.triangles,
            summary.unique_triangles
        ),
        (3, 3, 1)
    );
}

#[test]
fn malformed_instancing_is_refused_by_node() {
    let mut doc = Doc::default();
    let t = doc.vec3(&[[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]]);
    let s = doc.vec3(&[[1.0, 1.0, 1.0]]);
    let cases = [
        (
            format!(r#"{{"attributes":{{"TRANSLATION":{t},"SCALE":{s}}}}}"#),
            "node 0: EXT_mesh_gpu_instancing attributes differ in count",
        ),
        (
            r#"{"attributes":{}}"#.to_string(),
            "node 0: EXT_mesh_gpu_instancing has none of TRANSLATION, ROTATION and SCALE",
        ),
        (
            r#"{"attributes":{"TRANSLATION":99}}"#.to_string(),
            "node 0: EXT_mesh_gpu_instancing TRANSLATION names no accessor: 99",
        ),
        (
            format!(r#"{{"attributes":{{"ROTATION":{t}}}}}"#),
            "type VEC3 for EXT_mesh_gpu_instancing ROTATION of node 0, expected VEC4",
        ),
        (
            "{}".to_string(),
            "node 0: EXT_mesh_gpu_instancing has no 'attributes'",
        ),
    ];
    for (ext, expected) in cases {
        let mut d = Doc {
            bin: doc.bin.clone(),
            views: doc.views.clone(),
            accessors: doc.accessors.clone(),
        };
        let err = load(&instanced_triangle(&mut d, &ext))
            .unwrap_err()
            .to_string();
        assert!(err.contains(expected), "{ext}: {err}");
    }
}

/// A lit floor of cubes seen from above: a 5 × 5 grid of unit cubes, drawn by `grid`
/// (which adds the cube nodes to the builder's scene).
fn cube_scene(grid: impl FnOnce(&mut Scene, u32)) -> Scene {
    let mut b = SceneBuilder::default();
    let white = b.material(Material {
        base_color: Vec4::new(0.8, 0.7, 0.6, 1.0),
        metallic: 0.0,
        roughness: 0.5,
        ..Material::default()
    });
    let node = b.mesh("cube", vec![cube(white)], DMat4::IDENTITY);
    b.camera(
        CameraDef {
            name: None,
            projection: Projection::Perspective {
                yfov: 0.9,
                aspect_ratio: None,
                znear: 0.01,
            },
        },
        DMat4::look_at_rh(DVec3::new(3.0, 9.0, 7.0), DVec3::ZERO, DVec3::Y).inverse(),
    );
    b.environment(Environment::Constant(Vec3::new(1.0, 0.9, 0.8)));
    let mut scene = b.finish();
    grid(&mut scene, node);
    scene
}

fn grid_transforms() -> Vec<DMat4> {
    (0..25)
        .map(|k| {
            let (x, z) = ((k % 5) as f64 - 2.0, (k / 5) as f64 - 2.0);
            DMat4::from_scale_rotation_translation(
                DVec3::splat(0.3 + 0.02 * k as f64),
                DQuat::from_rotation_y(0.1 * k as f64),
                DVec3::new(1.5 * x, 0.0, 1.5 * z),
            )
        })
        .collect()
}

#[test]
fn gpu_instances_render_as_one_node_per_copy_bit_for_bit() {
    let instanced = cube_scene(|scene, node| {
        scene.nodes[node as usize].gpu_instances = grid_transforms();
    });
    let copies = cube_scene(|scene, node| {
        let first = scene.nodes[node as usize].clone();
        scene.nodes[node as usize].local = grid_transforms()[0];
        for t in &grid_transforms()[1..] {
            scene.nodes.push(Node {
                local: *t,
                ..first.clone()
            });
            scene.roots.push(scene.nodes.len() as u32 - 1);
        }
    });
    let options = FrameOptions {
        width: 48,
        height: 32,
        ..Default::default()
    };
    let render = |scene: Scene| {
        let frame = prepare_frame(Arc::new(scene), &options).expect("scene prepares");
        let image = render_region(
            &frame,
            &RenderSettings::default(),
            TileRect::new(0, 0, 48, 32),
            SampleRange::new(0, 4),
            16,
            &|_| {},
        );
        (frame.bvh.instances().len(), frame.scene.meshes.len(), image)
    };
    let (n_instanced, meshes_instanced, a) = render(instanced);
    let (n_copies, _, b) = render(copies);
    assert_eq!((n_instanced, meshes_instanced), (25, 1));
    assert_eq!(n_copies, 25);
    let (a, b) = (a.resolve(), b.resolve());
    let covered = a.beauty.iter().filter(|p| p.w > 0.0).count();
    assert!(covered > 100, "the cubes cover {covered} pixels");
    assert!(a.beauty == b.beauty, "instanced and copied cubes differ");
}

#[test]
fn instances_survive_export() {
    let scene = cube_scene(|scene, node| {
        scene.nodes[node as usize].gpu_instances = grid_transforms();
    });
    let glb = tracer::export::scene_to_glb(&scene).unwrap();
    let back = loader::load_glb(&glb).unwrap();
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    let theirs = &back.nodes[0].gpu_instances;
    assert_eq!(theirs.len(), 25);
    for (a, b) in theirs.iter().zip(grid_transforms()) {
        assert!(a.abs_diff_eq(b, 1e-6), "{a} vs {b}");
    }
}

#[test]
fn a_scene_may_not_draw_more_than_the_bound() {
    // 23 levels of two nodes, each the parent of both nodes below it: 2^22 paths reach each
    // mesh node of the last level, a few hundred bytes of JSON asking for 8 million draws.
    let mut doc = Doc::default();
    let p = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let levels = 23;
    let mut nodes = Vec::new();
    for level in 0..levels {
        for _ in 0..2 {
            nodes.push(if level + 1 < levels {
                format!(r#"{{"children":[{},{}]}}"#, 2 * level + 2, 2 * level + 3)
            } else {
                r#"{"mesh":0}"#.to_string()
            });
        }
    }
    let json = doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}}}}]}}],
        "scenes":[{{"nodes":[0,1]}}],"nodes":[{}]"#,
        nodes.join(",")
    ));
    let err = load(&json).unwrap_err();
    assert!(
        matches!(err, SceneError::TooManyDraws(n) if n == 1 << 23),
        "{err}"
    );
    assert!(
        err.to_string().contains(&MAX_MESH_DRAWS.to_string()),
        "{err}"
    );
}
