//! Animation, skins and morph targets, from small glTF documents written here (binary data
//! in base64 data: URIs) to posed nodes and deformed vertices, against values worked out by
//! hand; the loader's errors for broken animation data; and the shared sample models.

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use std::f64::consts::FRAC_1_SQRT_2;
use std::path::{Path, PathBuf};

use glam::{DMat4, DVec3, Vec3};
use tracer::animation::{self, AnimationChoice};
use tracer::deform;
use tracer::loader::{self, Element, SceneError, SceneSummary};
use tracer::scene::Scene;

mod common;

use common::gltf_doc::Doc;

// ---------------------------------------------------------------------------------------
// Building documents

fn load(json: &str) -> Result<Scene, SceneError> {
    loader::load_slice(json.as_bytes(), None)
}

/// `[x, y, z, w]` of a rotation by `deg` degrees about `axis`, as a file stores it.
fn quat(axis: DVec3, deg: f64) -> [f32; 4] {
    glam::DQuat::from_axis_angle(axis, deg.to_radians())
        .to_array()
        .map(|c| c as f32)
}

fn assert_mat(got: DMat4, want: [f64; 16], what: &str) {
    let want = DMat4::from_cols_array(&want);
    assert!(
        got.abs_diff_eq(want, 1e-6),
        "{what}: got {got}, want {want}"
    );
}

fn assert_vec(got: Vec3, want: [f32; 3], what: &str) {
    let want = Vec3::from_array(want);
    assert!(
        (got - want).abs().max_element() < 1e-5,
        "{what}: got {got}, want {want}"
    );
}

/// A triangle at the origin: POSITION, NORMAL.
fn triangle(doc: &mut Doc) -> (usize, usize) {
    let p = doc.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let n = doc.vec3(&[[0.0, 0.0, 1.0]; 3]);
    (p, n)
}

// ---------------------------------------------------------------------------------------
// Samplers and poses

/// Four animated nodes, one animation:
/// - node 0, scale 2: translation, STEP, keys t = 1, 2, 4 at x = 10, 20, 40;
/// - node 1: rotation, LINEAR, t = 0..1 from identity to 90° about Y;
/// - node 2: the same, with the end key written as -q (slerp must take the short way);
/// - node 3: translation, CUBICSPLINE, t = 1..3, x from 1 (out-tangent 3) to 2 (in-tangent
///   -1), y from 0 (out-tangent 1) to 0 (in-tangent 1); unused tangents set to 99.
fn sampler_scene() -> Scene {
    let mut doc = Doc::default();
    let (p, n) = triangle(&mut doc);
    let step_t = doc.scalars(&[1.0, 2.0, 4.0]);
    let step_v = doc.floats(&[10.0, 0.0, 0.0, 20.0, 0.0, 0.0, 40.0, 0.0, 0.0], "VEC3", 3);
    let lin_t = doc.scalars(&[0.0, 1.0]);
    let q90 = quat(DVec3::Y, 90.0);
    let lin_v = doc.vec4(&[[0.0, 0.0, 0.0, 1.0], q90]);
    let neg_v = doc.vec4(&[[0.0, 0.0, 0.0, 1.0], q90.map(|c| -c)]);
    let cub_t = doc.scalars(&[1.0, 3.0]);
    #[rustfmt::skip]
    let cub_v = doc.floats(&[
        99.0, 99.0, 99.0,   1.0, 0.0, 0.0,   3.0, 1.0, 0.0, // key 0: in, value, out
        -1.0, 1.0, 0.0,     2.0, 0.0, 0.0,   99.0, 99.0, 99.0, // key 1
    ], "VEC3", 3);
    let json = doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n}}}}}]}}],
        "scenes":[{{"nodes":[0,1,2,3]}}],
        "nodes":[{{"mesh":0,"scale":[2,2,2]}},{{"mesh":0}},{{"mesh":0}},{{"mesh":0}}],
        "animations":[{{"name":"all four","samplers":[
            {{"input":{step_t},"output":{step_v},"interpolation":"STEP"}},
            {{"input":{lin_t},"output":{lin_v}}},
            {{"input":{lin_t},"output":{neg_v},"interpolation":"LINEAR"}},
            {{"input":{cub_t},"output":{cub_v},"interpolation":"CUBICSPLINE"}}],
          "channels":[
            {{"sampler":0,"target":{{"node":0,"path":"translation"}}}},
            {{"sampler":1,"target":{{"node":1,"path":"rotation"}}}},
            {{"sampler":2,"target":{{"node":2,"path":"rotation"}}}},
            {{"sampler":3,"target":{{"node":3,"path":"translation"}}}}]}}]"#
    ));
    load(&json).unwrap()
}

#[test]
fn step_samplers_hold_the_previous_key_and_keep_the_node_scale() {
    let scene = sampler_scene();
    let all = AnimationChoice::All.resolve(&scene).unwrap();
    // T(x, 0, 0) · S(2), column-major.
    let placed = |x: f64| {
        [
            2., 0., 0., 0., 0., 2., 0., 0., 0., 0., 2., 0., x, 0., 0., 1.,
        ]
    };
    for (t, x) in [
        (-1.0, 10.0),
        (1.0, 10.0),
        (1.5, 10.0),
        (2.0, 20.0),
        (3.9, 20.0),
        (4.0, 40.0),
        (5.0, 40.0),
    ] {
        let pose = animation::pose(&scene, &all, t);
        assert_mat(pose.local[0], placed(x), &format!("step at t = {t}"));
    }
}

#[test]
fn linear_rotations_slerp_the_short_way() {
    let scene = sampler_scene();
    let all = AnimationChoice::All.resolve(&scene).unwrap();
    // Rotation by θ about Y, column-major: x axis (c, 0, -s), z axis (s, 0, c).
    let rot_y = |c: f64, s: f64| [c, 0., -s, 0., 0., 1., 0., 0., s, 0., c, 0., 0., 0., 0., 1.];
    // cos 45° = sin 45° = 1/√2.
    let (c45, s45) = (FRAC_1_SQRT_2, FRAC_1_SQRT_2);
    let (c225, s225) = (0.9238795325112867, 0.3826834323650898);
    for node in [1, 2] {
        let at = |t: f64| animation::pose(&scene, &all, t).local[node];
        assert_mat(at(-1.0), rot_y(1.0, 0.0), "before the first key");
        assert_mat(at(0.0), rot_y(1.0, 0.0), "at the first key");
        assert_mat(at(0.25), rot_y(c225, s225), "22.5° at t = 0.25");
        assert_mat(at(0.5), rot_y(c45, s45), "45° at t = 0.5");
        assert_mat(at(1.0), rot_y(0.0, 1.0), "90° at the last key");
        assert_mat(at(7.0), rot_y(0.0, 1.0), "after the last key");
    }
}

#[test]
fn cubic_splines_use_the_scaled_tangents() {
    let scene = sampler_scene();
    let all = AnimationChoice::All.resolve(&scene).unwrap();
    let translation = |t: f64| animation::pose(&scene, &all, t).local[3].w_axis.truncate();
    // Hermite basis at u = 0.5: (0.5, 0.125, 0.5, -0.125); m = dt · tangent with dt = 2.
    // x: 0.5·1 + 0.125·(2·3) + 0.5·2 + (-0.125)·(2·-1) = 2.5
    // y: 0.125·(2·1) + (-0.125)·(2·1) = 0
    // At u = 0.25: (0.84375, 0.140625, 0.15625, -0.046875):
    // x: 0.84375 + 0.140625·6 + 0.15625·2 + 0.046875·2 = 2.09375
    // y: 0.140625·2 - 0.046875·2 = 0.1875
    for (t, want) in [
        (0.0, [1.0, 0.0]),
        (1.0, [1.0, 0.0]),
        (1.5, [2.09375, 0.1875]),
        (2.0, [2.5, 0.0]),
        (3.0, [2.0, 0.0]),
        (4.0, [2.0, 0.0]),
    ] {
        let got = translation(t);
        assert!(
            (got.x - want[0]).abs() < 1e-9 && (got.y - want[1]).abs() < 1e-9 && got.z == 0.0,
            "t = {t}: got {got}, want {want:?}"
        );
    }
}

#[test]
fn the_summary_and_choices_describe_the_animation() {
    let scene = sampler_scene();
    let s = SceneSummary::of(&scene);
    assert_eq!(s.animations.len(), 1);
    let a = &s.animations[0];
    assert_eq!(
        (a.name.as_deref(), a.start, a.end, a.channels),
        (Some("all four"), 0.0, 4.0, 4)
    );
    assert_eq!((s.skins, s.morph_targets), (0, 0));
    assert!(s.features.animation && !s.features.skinning && !s.features.morphing);
    assert_eq!(animation::time_range(&scene, &[0]), Some((0.0, 4.0)));
    let err = AnimationChoice::Name("walk".into())
        .resolve(&scene)
        .unwrap_err();
    assert!(err.contains("0 'all four'"), "{err}");
}

// ---------------------------------------------------------------------------------------
// Skins

/// Joint 0 at the origin; joint 1 its child at (1, 0, 0), rotated about Z from 0° at t = 0
/// to 90° at t = 1. The skinned node sits at (100, 0, 0), which skinning must ignore.
/// Vertices: (2, 0, 0) on joint 1 only; (1.5, 0, 0) half on each, through two joint sets;
/// (0, 1, 0) on joint 0 only.
fn skin_scene() -> Scene {
    let mut doc = Doc::default();
    let p = doc.vec3(&[[2.0, 0.0, 0.0], [1.5, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let n = doc.vec3(&[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]);
    let j0 = doc.joints_u8(&[[1, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]]);
    let w0 = doc.vec4(&[
        [1.0, 0.0, 0.0, 0.0],
        [0.5, 0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0, 0.0],
    ]);
    let j1 = doc.joints_u8(&[[0, 0, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0]]);
    let w1 = doc.vec4(&[[0.0; 4], [0.5, 0.0, 0.0, 0.0], [0.0; 4]]);
    let ibm = doc.mat4s(&[
        DMat4::IDENTITY,
        DMat4::from_translation(DVec3::new(-1.0, 0.0, 0.0)),
    ]);
    let t = doc.scalars(&[0.0, 1.0]);
    let r = doc.vec4(&[[0.0, 0.0, 0.0, 1.0], quat(DVec3::Z, 90.0)]);
    let json = doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n},
            "JOINTS_0":{j0},"WEIGHTS_0":{w0},"JOINTS_1":{j1},"WEIGHTS_1":{w1}}}}}]}}],
        "skins":[{{"joints":[0,1],"inverseBindMatrices":{ibm}}}],
        "scenes":[{{"nodes":[0,2]}}],
        "nodes":[{{"name":"joint 0","children":[1]}},{{"name":"joint 1","translation":[1,0,0]}},
                 {{"mesh":0,"skin":0,"translation":[100,0,0]}}],
        "animations":[{{"samplers":[{{"input":{t},"output":{r}}}],
            "channels":[{{"sampler":0,"target":{{"node":1,"path":"rotation"}}}}]}}]"#
    ));
    load(&json).unwrap()
}

fn skinned(scene: &Scene, t: f64) -> deform::Deformed {
    let chosen = AnimationChoice::All.resolve(scene).unwrap();
    let pose = animation::pose(scene, &chosen, t);
    let world = animation::world_transforms(scene, &pose);
    let skin = &scene.skins[scene.nodes[2].skin.unwrap() as usize];
    let joints = deform::joint_matrices(skin, |j| world[j as usize]);
    let prim = &scene.meshes[0].primitives[0];
    deform::deform(
        prim,
        animation::morph_weights(scene, &pose, 2),
        Some(&joints),
    )
}

#[test]
fn a_two_joint_skin_places_vertices_by_its_joints() {
    let scene = skin_scene();
    assert!(scene.features.skinning && scene.features.animation);
    assert_eq!(scene.skins[0].joints, vec![0, 1]);
    assert_eq!(scene.meshes[0].primitives[0].joint_sets.len(), 2);

    // Bind pose: every joint matrix is the identity, vertices stay put.
    let d = skinned(&scene, 0.0);
    assert_vec(d.positions[0], [2.0, 0.0, 0.0], "t = 0, vertex 0");
    assert_vec(d.positions[1], [1.5, 0.0, 0.0], "t = 0, vertex 1");

    // 90°: joint 1's matrix is T(1,0,0)·Rz(90°)·T(-1,0,0).
    // Vertex 0: (2,0,0) → (1,0,0) → (0,1,0) → (1,1,0).
    // Vertex 1: joint 0 leaves (1.5,0,0); joint 1 gives (0.5,0,0) → (0,0.5,0) → (1,0.5,0);
    // half of each is (1.25, 0.25, 0).
    let d = skinned(&scene, 1.0);
    assert_vec(d.positions[0], [1.0, 1.0, 0.0], "t = 1, vertex 0");
    assert_vec(d.positions[1], [1.25, 0.25, 0.0], "t = 1, vertex 1");
    assert_vec(d.positions[2], [0.0, 1.0, 0.0], "t = 1, vertex 2");
    assert_vec(
        d.normals[0],
        [0.0, 1.0, 0.0],
        "t = 1, normal 0 turns with joint 1",
    );
    assert_vec(d.normals[1], [0.0, 0.0, 1.0], "t = 1, normal 1");

    // 45°: vertex 0 is (1,0,0) turned 45° about Z, (1/√2, 1/√2, 0), plus (1,0,0).
    let d = skinned(&scene, 0.5);
    let h = FRAC_1_SQRT_2 as f32;
    assert_vec(d.positions[0], [1.0 + h, h, 0.0], "t = 0.5, vertex 0");
    assert_vec(d.normals[0], [h, h, 0.0], "t = 0.5, normal 0");
}

// ---------------------------------------------------------------------------------------
// Morph targets

/// A triangle with normals +Z and two targets: target 0 lifts vertex 0 by 1 in z and tilts
/// its normal by (1, 0, -1); target 1 (a sparse accessor) lifts vertex 1 by 2. Default mesh
/// weights (0.5, 0). Node 0 uses them, node 1 has its own (1, 0.25), node 2's are animated
/// linearly from (0, 0) at t = 0 to (1, 1) at t = 1.
fn morph_scene() -> Scene {
    let mut doc = Doc::default();
    let (p, n) = triangle(&mut doc);
    let d0 = doc.vec3(&[[0.0, 0.0, 1.0], [0.0; 3], [0.0; 3]]);
    let dn0 = doc.floats(&[1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], "VEC3", 3);
    let idx = doc.view(&[1u8]);
    let val = doc.view(&[0.0f32, 0.0, 2.0].map(f32::to_le_bytes).concat());
    let d1 = doc.raw_accessor(format!(
        r#"{{"componentType":5126,"type":"VEC3","count":3,"min":[0,0,0],"max":[0,0,2],
            "sparse":{{"count":1,"indices":{{"bufferView":{idx},"componentType":5121}},
            "values":{{"bufferView":{val}}}}}}}"#
    ));
    let t = doc.scalars(&[0.0, 1.0]);
    let w = doc.scalars(&[0.0, 0.0, 1.0, 1.0]);
    let json = doc.json(&format!(
        r#","meshes":[{{"weights":[0.5,0],"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n}}},
            "targets":[{{"POSITION":{d0},"NORMAL":{dn0}}},{{"POSITION":{d1}}}]}}]}}],
        "scenes":[{{"nodes":[0,1,2]}}],
        "nodes":[{{"mesh":0}},{{"mesh":0,"weights":[1,0.25]}},{{"mesh":0}}],
        "animations":[{{"samplers":[{{"input":{t},"output":{w}}}],
            "channels":[{{"sampler":0,"target":{{"node":2,"path":"weights"}}}}]}}]"#
    ));
    load(&json).unwrap()
}

#[test]
fn morph_weights_come_from_the_mesh_the_node_or_the_animation() {
    let scene = morph_scene();
    assert!(scene.features.morphing);
    assert_eq!(scene.meshes[0].weights, vec![0.5, 0.0]);
    assert_eq!(SceneSummary::of(&scene).morph_targets, 2);
    let prim = &scene.meshes[0].primitives[0];
    // (1/2, 0, 1/2) normalised.
    let s = FRAC_1_SQRT_2 as f32;
    // (node, time, weights, vertex 0, normal 0, vertex 1)
    #[allow(clippy::type_complexity)]
    let cases: [(u32, f64, [f32; 2], [f32; 3], [f32; 3], [f32; 3]); 6] = [
        (
            0,
            0.0,
            [0.5, 0.0],
            [0.0, 0.0, 0.5],
            [s, 0.0, s],
            [1.0, 0.0, 0.0],
        ),
        (
            1,
            0.0,
            [1.0, 0.25],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
            [1.0, 0.0, 0.5],
        ),
        (
            2,
            -1.0,
            [0.0, 0.0],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
        ),
        (
            2,
            0.0,
            [0.0, 0.0],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
        ),
        (
            2,
            0.5,
            [0.5, 0.5],
            [0.0, 0.0, 0.5],
            [s, 0.0, s],
            [1.0, 0.0, 1.0],
        ),
        (
            2,
            1.0,
            [1.0, 1.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
            [1.0, 0.0, 2.0],
        ),
    ];
    for (node, t, weights, v0, n0, v1) in cases {
        let pose = animation::pose(&scene, &[0], t);
        let w = animation::morph_weights(&scene, &pose, node);
        assert_eq!(w, weights, "node {node} at t = {t}");
        let d = deform::deform(prim, w, None);
        let what = format!("node {node} at t = {t}");
        assert_vec(d.positions[0], v0, &what);
        assert_vec(d.normals[0], n0, &what);
        assert_vec(d.positions[1], v1, &what);
        assert_vec(d.positions[2], [0.0, 1.0, 0.0], &what);
        assert_vec(d.normals[2], [0.0, 0.0, 1.0], &what);
    }
}

/// A normal-mapped quad without NORMAL is unwelded (flat normals) and given tangents: its
/// joints and morph targets must follow every vertex, and the morph normals are dropped.
#[test]
fn re_indexed_vertices_keep_their_joints_and_targets() {
    let png = {
        let img = image::RgbaImage::from_pixel(2, 2, image::Rgba([128, 128, 255, 255]));
        let mut out = std::io::Cursor::new(Vec::new());
        image::DynamicImage::ImageRgba8(img)
            .write_to(&mut out, image::ImageFormat::Png)
            .unwrap();
        out.into_inner()
    };
    let corners = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    let mut doc = Doc::default();
    let p = doc.vec3(&corners);
    let uv = doc.floats(&[0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0], "VEC2", 2);
    let j = doc.joints_u8(&[[0, 0, 0, 0], [1, 0, 0, 0], [2, 0, 0, 0], [3, 0, 0, 0]]);
    let w = doc.vec4(&[[1.0, 0.0, 0.0, 0.0]; 4]);
    // Each corner's displacement is (0, 0, its index).
    let d = doc.vec3(&[
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, 2.0],
        [0.0, 0.0, 3.0],
    ]);
    let dn = doc.vec3(&[[1.0, 0.0, 0.0]; 4]);
    let i = doc.u16s(&[0, 1, 2, 0, 2, 3]);
    let image = doc.view(&png);
    let json = doc.json(&format!(
        r#","images":[{{"bufferView":{image},"mimeType":"image/png"}}],"textures":[{{"source":0}}],
        "materials":[{{"normalTexture":{{"index":0}}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"TEXCOORD_0":{uv},
            "JOINTS_0":{j},"WEIGHTS_0":{w}}},"indices":{i},"material":0,
            "targets":[{{"POSITION":{d},"NORMAL":{dn}}}]}}]}}],
        "skins":[{{"joints":[0,1,2,3]}}],
        "scenes":[{{"nodes":[0,1,2,3,4]}}],
        "nodes":[{{}},{{}},{{}},{{}},{{"mesh":0,"skin":0}}]"#
    ));
    let scene = load(&json).unwrap();
    let prim = &scene.meshes[0].primitives[0];
    let n = prim.positions.len();
    assert!(n >= 6, "unwelded: {n} vertices");
    assert_eq!(prim.joint_sets[0].joints.len(), n);
    assert_eq!(prim.joint_sets[0].weights.len(), n);
    assert_eq!(prim.targets[0].positions.len(), n);
    assert!(prim.targets[0].normals.is_empty(), "morph normals dropped");
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("NORMAL displacements")),
        "{:?}",
        scene.warnings
    );
    for (v, pos) in prim.positions.iter().enumerate() {
        let corner = corners
            .iter()
            .position(|c| Vec3::from_array(*c) == *pos)
            .unwrap();
        assert_eq!(
            prim.joint_sets[0].joints[v][0] as usize, corner,
            "vertex {v}"
        );
        assert_eq!(prim.targets[0].positions[v].z, corner as f32, "vertex {v}");
    }
}

// ---------------------------------------------------------------------------------------
// Errors and warnings

/// A one-node scene drawing a triangle, with `node` as its node's JSON and `rest` added.
fn one_node(doc: &mut Doc, node: &str, rest: &str) -> String {
    let (p, n) = triangle(doc);
    doc.json(&format!(
        r#","meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n}}}}}]}}],
        "scenes":[{{"nodes":[0]}}],"nodes":[{node}]{rest}"#
    ))
}

fn translation_animation(doc: &mut Doc, times: &[f32]) -> String {
    let t = doc.scalars(times);
    let v = doc.floats(&vec![0.0; 3 * times.len()], "VEC3", 3);
    format!(
        r#","animations":[{{"name":"move","samplers":[{{"input":{t},"output":{v}}}],
            "channels":[{{"sampler":0,"target":{{"node":0,"path":"translation"}}}}]}}]"#
    )
}

#[test]
fn a_channel_on_a_matrix_node_is_an_error() {
    let mut doc = Doc::default();
    let anim = translation_animation(&mut doc, &[0.0, 1.0]);
    let json = one_node(
        &mut doc,
        r#"{"name":"Box","mesh":0,"matrix":[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}"#,
        &anim,
    );
    let err = load(&json).unwrap_err();
    assert_eq!(err.element(), Some(Element::Animation(0)), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("node 0 'Box'") && msg.contains("matrix") && msg.contains("spec"),
        "{msg}"
    );
}

/// Found by `fuzz/scene_loader`: the `gltf` crate does not check a channel's target node
/// and panicked reading one out of range.
#[test]
fn a_channel_on_a_missing_node_is_an_error() {
    let mut doc = Doc::default();
    let anim = translation_animation(&mut doc, &[0.0, 1.0]).replace(r#""node":0"#, r#""node":5"#);
    let json = one_node(&mut doc, r#"{"mesh":0}"#, &anim);
    let err = load(&json).unwrap_err();
    assert_eq!(err.element(), Some(Element::Animation(0)), "{err}");
    assert!(
        err.to_string()
            .contains("channel 0 targets node 5, out of range for 1 nodes"),
        "{err}"
    );
}

#[test]
fn decreasing_key_times_are_an_error() {
    let mut doc = Doc::default();
    let anim = translation_animation(&mut doc, &[0.0, 2.0, 1.0]);
    let input = doc.accessors.len() - 2;
    let json = one_node(&mut doc, r#"{"mesh":0}"#, &anim);
    let err = load(&json).unwrap_err();
    assert_eq!(err.element(), Some(Element::Accessor(input)), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("key time 2 (1)") && msg.contains("animation 0 'move'"),
        "{msg}"
    );
}

#[test]
fn non_finite_key_times_are_an_error_and_repeated_ones_merge() {
    let mut doc = Doc::default();
    let anim = translation_animation(&mut doc, &[0.0, f32::NAN]);
    let json = one_node(&mut doc, r#"{"mesh":0}"#, &anim);
    let err = load(&json).unwrap_err();
    assert!(err.to_string().contains("not finite"), "{err}");

    let mut doc = Doc::default();
    let t = doc.scalars(&[0.0, 1.0, 1.0, 2.0]);
    let v = doc.floats(&[0., 0., 0., 1., 0., 0., 5., 0., 0., 6., 0., 0.], "VEC3", 3);
    let anim = format!(
        r#","animations":[{{"samplers":[{{"input":{t},"output":{v}}}],
            "channels":[{{"sampler":0,"target":{{"node":0,"path":"translation"}}}}]}}]"#
    );
    let scene = load(&one_node(&mut doc, r#"{"mesh":0}"#, &anim)).unwrap();
    let s = &scene.animations[0].channels[0].sampler;
    assert_eq!(s.times, vec![0.0, 1.0, 2.0]);
    assert_eq!(s.values, vec![0., 0., 0., 5., 0., 0., 6., 0., 0.]);
    assert!(
        scene.warnings.iter().any(|w| w.contains("repeat")),
        "{:?}",
        scene.warnings
    );
}

#[test]
fn a_joint_index_beyond_the_skin_is_an_error() {
    let mut doc = Doc::default();
    let (p, n) = triangle(&mut doc);
    let j = doc.joints_u8(&[[0, 0, 0, 0], [1, 0, 0, 0], [0, 2, 0, 0]]);
    let w = doc.vec4(&[
        [1.0, 0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0, 0.0],
        [0.5, 0.5, 0.0, 0.0],
    ]);
    let json = doc.json(&format!(
        r#","meshes":[{{"name":"Body","primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n},"JOINTS_0":{j},"WEIGHTS_0":{w}}}}}]}}],
        "skins":[{{"joints":[0,1]}}],
        "scenes":[{{"nodes":[0,2]}}],"nodes":[{{"children":[1]}},{{}},{{"mesh":0,"skin":0}}]"#
    ));
    let err = load(&json).unwrap_err();
    assert_eq!(err.element(), Some(Element::Accessor(j)), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("JOINTS_0 in mesh 'Body', primitive 0")
            && msg.contains("vertex 2 uses joint 2")
            && msg.contains("skin 0 of node 2 has only 2 joints"),
        "{msg}"
    );
}

#[test]
fn too_few_inverse_bind_matrices_are_an_error() {
    let mut doc = Doc::default();
    let ibm = doc.mat4s(&[DMat4::IDENTITY]);
    let json = one_node(
        &mut doc,
        r#"{"mesh":0},{}"#,
        &format!(r#","skins":[{{"joints":[0,1],"inverseBindMatrices":{ibm}}}]"#),
    );
    let err = load(&json).unwrap_err();
    assert_eq!(err.element(), Some(Element::Accessor(ibm)), "{err}");
    assert!(err.to_string().contains("1 matrices for 2 joints"), "{err}");
}

#[test]
fn primitives_with_different_target_counts_are_an_error() {
    let mut doc = Doc::default();
    let (p, n) = triangle(&mut doc);
    let d = doc.vec3(&[[0.0; 3]; 3]);
    let json = doc.json(&format!(
        r#","meshes":[{{"name":"Face","primitives":[
            {{"attributes":{{"POSITION":{p},"NORMAL":{n}}},"targets":[{{"POSITION":{d}}}]}},
            {{"attributes":{{"POSITION":{p},"NORMAL":{n}}}}}]}}],
        "scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}]"#
    ));
    let err = load(&json).unwrap_err();
    assert_eq!(err.element(), Some(Element::Mesh(0)), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("mesh 'Face'") && msg.contains("primitive 1 has 0 morph targets"),
        "{msg}"
    );
}

#[test]
fn a_weights_channel_needs_morph_targets() {
    let mut doc = Doc::default();
    let t = doc.scalars(&[0.0, 1.0]);
    let v = doc.scalars(&[0.0, 1.0]);
    let json = one_node(
        &mut doc,
        r#"{"mesh":0}"#,
        &format!(
            r#","animations":[{{"samplers":[{{"input":{t},"output":{v}}}],
                "channels":[{{"sampler":0,"target":{{"node":0,"path":"weights"}}}}]}}]"#
        ),
    );
    let err = load(&json).unwrap_err();
    assert_eq!(err.element(), Some(Element::Animation(0)), "{err}");
    assert!(
        err.to_string().contains("no mesh with morph targets"),
        "{err}"
    );
}

#[test]
fn a_wrong_output_count_names_the_accessor() {
    let mut doc = Doc::default();
    let t = doc.scalars(&[0.0, 1.0]);
    let v = doc.floats(&[0.0; 6], "VEC3", 3);
    let json = one_node(
        &mut doc,
        r#"{"mesh":0}"#,
        &format!(
            r#","animations":[{{"samplers":[{{"input":{t},"output":{v},"interpolation":"CUBICSPLINE"}}],
                "channels":[{{"sampler":0,"target":{{"node":0,"path":"translation"}}}}]}}]"#
        ),
    );
    let err = load(&json).unwrap_err();
    assert_eq!(err.element(), Some(Element::Accessor(v)), "{err}");
    assert!(
        err.to_string().contains("has 2 elements, but 2 keys × 3"),
        "{err}"
    );
}

#[test]
fn animation_pointer_channels_are_skipped_with_a_warning() {
    let mut doc = Doc::default();
    let t = doc.scalars(&[0.0, 1.0]);
    let v = doc.floats(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0], "VEC3", 3);
    let c = doc.scalars(&[0.0, 1.0]);
    let json = one_node(
        &mut doc,
        r#"{"mesh":0}"#,
        &format!(
            r#","extensionsUsed":["KHR_animation_pointer"],
            "animations":[{{"samplers":[{{"input":{t},"output":{v}}},{{"input":{t},"output":{c}}}],
                "channels":[
                  {{"sampler":1,"target":{{"path":"pointer","extensions":{{"KHR_animation_pointer":{{"pointer":"/materials/0/alphaCutoff"}}}}}}}},
                  {{"sampler":0,"target":{{"node":0,"path":"translation"}}}}]}}]"#
        ),
    );
    let scene = load(&json).unwrap();
    assert_eq!(scene.animations[0].channels.len(), 1);
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("animation 0, channel 0") && w.contains("KHR_animation_pointer")),
        "{:?}",
        scene.warnings
    );
    let pose = animation::pose(&scene, &[0], 0.5);
    assert_eq!(pose.local[0].w_axis.x, 0.5);
}

// ---------------------------------------------------------------------------------------
// The shared sample models

fn scenes_dir() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/scenes");
    dir.is_dir().then_some(dir)
}

/// Every shared model with animations, skins or morph targets loads, and posing and
/// deforming it across its time range gives finite vertices. Prints what each has.
#[test]
fn shared_models_pose_and_deform_without_nan() {
    let Some(dir) = scenes_dir() else {
        println!("shared models: skipped, no shared/scenes folder beside the workspace");
        return;
    };
    let models = [
        "AnimatedCube/AnimatedCube.gltf",
        "AnimatedMorphCube/AnimatedMorphCube.glb",
        "BoxAnimated/BoxAnimated.glb",
        "InterpolationTest/InterpolationTest.glb",
        "RiggedFigure/RiggedFigure.glb",
        "RiggedSimple/RiggedSimple.glb",
        "SimpleSkin/SimpleSkin.gltf",
    ];
    for rel in models {
        let scene = loader::load_path(&dir.join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"));
        let s = SceneSummary::of(&scene);
        println!(
            "{rel}: {} skins, {} morph targets, features {:?}",
            s.skins,
            s.morph_targets,
            s.features.names()
        );
        for a in &s.animations {
            println!(
                "    animation {:?}: {} channels, {}..{} s",
                a.name, a.channels, a.start, a.end
            );
        }
        assert!(s.features.animation, "{rel}");
        let all = AnimationChoice::All.resolve(&scene).unwrap();
        let (start, end) = animation::time_range(&scene, &all).unwrap();
        for k in 0..=8 {
            let t = start + (end - start) * k as f64 / 8.0;
            let pose = animation::pose(&scene, &all, t);
            assert!(pose.local.iter().all(|m| m.is_finite()), "{rel} at {t}");
            let world = animation::world_transforms(&scene, &pose);
            for (i, node) in scene.nodes.iter().enumerate() {
                let Some(m) = node.mesh else { continue };
                let joints = node.skin.map(|s| {
                    deform::joint_matrices(&scene.skins[s as usize], |j| world[j as usize])
                });
                let weights = animation::morph_weights(&scene, &pose, i as u32);
                for prim in &scene.meshes[m as usize].primitives {
                    let d = deform::deform(prim, weights, joints.as_deref());
                    assert!(
                        d.positions.iter().all(|p| p.is_finite())
                            && d.normals.iter().all(|n| n.is_finite() && n.length() > 0.99)
                            && d.tangents.iter().all(|t| t.is_finite()),
                        "{rel}, node {i} at {t}"
                    );
                }
            }
        }
    }
}
