//! Geometry and shading normals at the extremes, every scene loaded from glTF built in code:
//! zero-area triangles, duplicated vertices, zero or NaN normals and tangents, non-unit
//! quaternions (node rotations and animation keys), zero scale, singular and mirrored
//! transforms; and shading normals facing away from the geometry (flipped normals, a
//! normal map below the surface, interpolated normals far from the face normal).
//!
//! Where the glTF 2.0 specification calls the data invalid, or the loader repairs it, the
//! load must leave a warning naming the element; legal data (zero scale, mirrors,
//! duplicated vertices) must load without one. Every render is checked for NaN and
//! infinity and against a known answer: the same scene written the normal way (the images
//! then trace the same paths, so they agree far inside the noise), its mirror image, or
//! the white furnace.

use glam::{Mat3, Quat, Vec3, Vec4};
use tracer::film::Layers;
use tracer::light::Environment;
use tracer::loader::load_slice;
use tracer::render::{FrameOptions, RenderSettings};
use tracer::scene::Scene;

use super::support::{assert_finite, assert_same_image, mean, options, prepare, render};
use crate::common::gltf_doc::Doc;

/// Image side in pixels.
const SIZE: u32 = 32;
/// Samples per pixel of the lit comparisons: a directional light makes them noise-free
/// but for anti-aliasing at the silhouettes.
const SPP: u32 = 8;
/// Block size of image comparisons.
const BLOCK: u32 = 4;
/// Scenes that must be the same trace the same paths: blocks may differ only by rounding.
const SAME: f64 = 0.01;

// ---------------------------------------------------------------------------------------
// Documents

/// Vertex data of one primitive, written as the file has it.
#[derive(Clone, Default)]
struct MeshData {
    positions: Vec<[f32; 3]>,
    normals: Option<Vec<[f32; 3]>>,
    tangents: Option<Vec<[f32; 4]>>,
    uvs: Option<Vec<[f32; 2]>>,
    indices: Option<Vec<u16>>,
}

/// Material indices every document has.
const GREY: usize = 0;
const WHITE: usize = 1;
const LAMP: usize = 2;

/// A glTF document assembled in code: one buffer, the materials above, a perspective
/// camera at z = 4 looking at the origin, and (unless `light` is off) a directional light
/// shining down and away from the camera, symmetric about the x = 0 plane.
struct Gltf {
    doc: Doc,
    materials: Vec<String>,
    meshes: Vec<String>,
    nodes: Vec<String>,
    roots: Vec<usize>,
    images: Vec<usize>,
    animations: Vec<String>,
    light: bool,
}

/// A diffuse material (no specular layer) of albedo `c`.
fn diffuse(c: f32, extra: &str) -> String {
    format!(
        r#"{{"pbrMetallicRoughness":{{"baseColorFactor":[{c},{c},{c},1],"metallicFactor":0}}{extra},
        "extensions":{{"KHR_materials_specular":{{"specularFactor":0}}}}}}"#
    )
}

impl Gltf {
    fn new() -> Self {
        Self {
            doc: Doc::default(),
            materials: vec![
                diffuse(0.7, ""),
                diffuse(1.0, ""),
                r#"{"pbrMetallicRoughness":{"baseColorFactor":[0,0,0,1]},"emissiveFactor":[1,1,1],
                "extensions":{"KHR_materials_emissive_strength":{"emissiveStrength":4}}}"#
                    .into(),
            ],
            meshes: Vec::new(),
            nodes: Vec::new(),
            roots: Vec::new(),
            images: Vec::new(),
            animations: Vec::new(),
            light: true,
        }
    }

    /// A diffuse material of albedo `albedo` with a uniform normal map whose tangent-space
    /// normal is `texel`.
    fn normal_mapped(&mut self, albedo: f32, texel: Vec3) -> usize {
        let rgb = ((texel.normalize() + 1.0) * 0.5 * 255.0).round();
        let img = image::RgbaImage::from_pixel(
            2,
            2,
            image::Rgba([rgb.x as u8, rgb.y as u8, rgb.z as u8, 255]),
        );
        let mut png = std::io::Cursor::new(Vec::new());
        image::DynamicImage::ImageRgba8(img)
            .write_to(&mut png, image::ImageFormat::Png)
            .unwrap();
        let view = self.doc.view(&png.into_inner());
        self.images.push(view);
        let texture = self.images.len() - 1;
        self.materials.push(diffuse(
            albedo,
            &format!(r#","normalTexture":{{"index":{texture}}}"#),
        ));
        self.materials.len() - 1
    }

    /// One primitive's JSON, its accessors written to the buffer. Normals and tangents get
    /// no min/max, so that NaN can be written.
    fn primitive(&mut self, m: &MeshData, material: usize) -> String {
        let mut attrs = format!(r#""POSITION":{}"#, self.doc.vec3(&m.positions));
        if let Some(n) = &m.normals {
            let a = self.doc.floats(&n.concat(), "VEC3", 3);
            attrs += &format!(r#","NORMAL":{a}"#);
        }
        if let Some(t) = &m.tangents {
            attrs += &format!(r#","TANGENT":{}"#, self.doc.vec4(t));
        }
        if let Some(uv) = &m.uvs {
            attrs += &format!(r#","TEXCOORD_0":{}"#, self.doc.vec2(uv));
        }
        let indices = match &m.indices {
            Some(i) => format!(r#","indices":{}"#, self.doc.u16s(i)),
            None => String::new(),
        };
        format!(r#"{{"attributes":{{{attrs}}}{indices},"material":{material}}}"#)
    }

    /// A mesh of one primitive; returns its index.
    fn mesh(&mut self, m: &MeshData, material: usize) -> usize {
        let prim = self.primitive(m, material);
        self.meshes.push(format!(r#"{{"primitives":[{prim}]}}"#));
        self.meshes.len() - 1
    }

    fn node(&mut self, json: String) -> usize {
        self.nodes.push(json);
        self.nodes.len() - 1
    }

    fn root(&mut self, json: String) -> usize {
        let n = self.node(json);
        self.roots.push(n);
        n
    }

    /// The emissive ceiling lamp, facing down from y = 1.6, with `degenerate` extra
    /// zero-area triangles.
    fn lamp(&mut self, degenerate: bool) {
        let mut m = quad(Vec3::new(0.0, 1.6, 0.5), Vec3::X * 0.6, Vec3::Z * 0.6);
        if degenerate {
            add_degenerate_triangles(&mut m);
        }
        let mesh = self.mesh(&m, LAMP);
        self.root(format!(r#"{{"mesh":{mesh}}}"#));
    }

    fn json(&self) -> String {
        let mut nodes = self.nodes.clone();
        let mut roots = self.roots.clone();
        nodes.push(r#"{"camera":0,"translation":[0,0,4]}"#.into());
        roots.push(nodes.len() - 1);
        let mut lights = String::new();
        if self.light {
            // -Z turned 45° down about X: travelling along (0, -1, -1)/√2.
            nodes.push(
                r#"{"rotation":[-0.38268343,0,0,0.92387953],
                "extensions":{"KHR_lights_punctual":{"light":0}}}"#
                    .into(),
            );
            roots.push(nodes.len() - 1);
            lights = r#","extensions":{"KHR_lights_punctual":{"lights":[
                {"type":"directional","intensity":2}]}}"#
                .into();
        }
        let mut rest = String::new();
        if !self.images.is_empty() {
            let images: Vec<String> = self
                .images
                .iter()
                .map(|v| format!(r#"{{"bufferView":{v},"mimeType":"image/png"}}"#))
                .collect();
            let textures: Vec<String> = (0..self.images.len())
                .map(|i| format!(r#"{{"source":{i}}}"#))
                .collect();
            rest += &format!(
                r#","images":[{}],"textures":[{}]"#,
                images.join(","),
                textures.join(",")
            );
        }
        if !self.animations.is_empty() {
            rest += &format!(r#","animations":[{}]"#, self.animations.join(","));
        }
        self.doc.json(&format!(
            r#","extensionsUsed":["KHR_lights_punctual","KHR_materials_specular",
            "KHR_materials_emissive_strength"]{lights},
            "cameras":[{{"type":"perspective","perspective":{{"yfov":0.6,"znear":0.01}}}}],
            "materials":[{}],"meshes":[{}],"nodes":[{}],"scene":0,"scenes":[{{"nodes":{roots:?}}}]{rest}"#,
            self.materials.join(","),
            self.meshes.join(","),
            nodes.join(","),
        ))
    }

    fn try_load(&self) -> Result<Scene, tracer::loader::SceneError> {
        load_slice(self.json().as_bytes(), None)
    }

    fn load(&self, case: &str) -> Scene {
        self.try_load()
            .unwrap_or_else(|e| panic!("{case}: does not load: {e}"))
    }
}

// ---------------------------------------------------------------------------------------
// Meshes

/// The corners of a unit cube as 8 shared vertices, turned so that three faces face the
/// camera, moved by `offset`; 12 triangles wound counter-clockwise from outside, no normals.
fn cube_welded(offset: Vec3) -> MeshData {
    let turn = Mat3::from_rotation_y(0.5) * Mat3::from_rotation_x(0.4);
    let corner = |i: u16| {
        Vec3::new(
            (i & 1) as f32 - 0.5,
            ((i >> 1) & 1) as f32 - 0.5,
            ((i >> 2) & 1) as f32 - 0.5,
        )
    };
    let quads: [[u16; 4]; 6] = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    let mut indices = Vec::new();
    for [a, b, c, d] in quads {
        for mut tri in [[a, b, c], [a, c, d]] {
            let [p, q, r] = tri.map(corner);
            if (q - p).cross(r - p).dot(p + q + r) < 0.0 {
                tri.swap(1, 2);
            }
            indices.extend(tri);
        }
    }
    MeshData {
        positions: (0..8)
            .map(|i| (turn * corner(i) + offset).to_array())
            .collect(),
        indices: Some(indices),
        ..Default::default()
    }
}

/// A quad centred at `c` spanned by `u` and `v`, facing u × v, with flat normals, texture
/// coordinates (v = 0 at the `+v` edge, as images go) and two triangles.
fn quad(c: Vec3, u: Vec3, v: Vec3) -> MeshData {
    let n = u.cross(v).normalize();
    MeshData {
        positions: vec![
            (c - u - v).to_array(),
            (c + u - v).to_array(),
            (c + u + v).to_array(),
            (c - u + v).to_array(),
        ],
        normals: Some(vec![n.to_array(); 4]),
        uvs: Some(vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]]),
        indices: Some(vec![0, 1, 2, 0, 2, 3]),
        ..Default::default()
    }
}

/// A UV sphere of radius 0.9 with smooth normals and texture coordinates, indexed.
fn sphere() -> MeshData {
    let s = tracer::shapes::uv_sphere(0, 16, 32);
    let rows = 17;
    let cols = 33;
    MeshData {
        positions: s.positions.iter().map(|p| (*p * 0.9).to_array()).collect(),
        normals: Some(s.normals.iter().map(|n| n.to_array()).collect()),
        uvs: Some(
            (0..rows * cols)
                .map(|i| [(i % cols) as f32 / 32.0, (i / cols) as f32 / 16.0])
                .collect(),
        ),
        indices: Some(s.indices.iter().flatten().map(|&i| i as u16).collect()),
        ..Default::default()
    }
}

/// The same mesh without indices: every triangle gets its own three vertices.
fn unwelded(m: &MeshData) -> MeshData {
    let order: Vec<usize> = m
        .indices
        .as_ref()
        .unwrap()
        .iter()
        .map(|&i| i as usize)
        .collect();
    let pick = |v: &Vec<[f32; 3]>| order.iter().map(|&i| v[i]).collect();
    MeshData {
        positions: pick(&m.positions),
        normals: m.normals.as_ref().map(pick),
        tangents: None,
        uvs: m
            .uvs
            .as_ref()
            .map(|uv| order.iter().map(|&i| uv[i]).collect()),
        indices: None,
    }
}

/// Appends zero-area triangles: ones that repeat a vertex (which the spec says a mesh
/// SHOULD NOT contain), and, over duplicated vertices, ones whose distinct corners
/// coincide or lie on a line (legal).
fn add_degenerate_triangles(m: &mut MeshData) {
    let n = m.positions.len() as u16;
    let (p0, p1) = (Vec3::from(m.positions[0]), Vec3::from(m.positions[1]));
    m.positions.push(p0.to_array());
    m.positions.push(((p0 + p1) * 0.5).to_array());
    if let Some(normals) = &mut m.normals {
        let n0 = normals[0];
        normals.extend([n0, n0]);
    }
    if let Some(uvs) = &mut m.uvs {
        let uv0 = uvs[0];
        uvs.extend([uv0, uv0]);
    }
    m.indices
        .as_mut()
        .unwrap()
        .extend([0, 0, 1, 1, 2, 2, 3, 3, 3, 0, n, 1, 0, 1, n + 1]);
}

/// The sphere with every vertex normal replaced by `f(position, normal)`.
fn with_normals(mut m: MeshData, f: impl Fn(Vec3, Vec3) -> Vec3) -> MeshData {
    let normals = m.normals.take().unwrap();
    m.normals = Some(
        m.positions
            .iter()
            .zip(&normals)
            .map(|(p, n)| f(Vec3::from(*p), Vec3::from(*n)).to_array())
            .collect(),
    );
    m
}

// ---------------------------------------------------------------------------------------
// Rendering and checks

fn render_case(case: &str, scene: Scene, opts: &FrameOptions, spp: u32) -> Layers {
    let frame = prepare(scene, opts);
    let layers = render(&frame, &RenderSettings::default(), spp);
    assert_finite(case, &layers);
    layers
}

fn lit(case: &str, scene: Scene) -> Layers {
    render_case(case, scene, &options(SIZE, SIZE), SPP)
}

/// Samples per pixel and tolerance of mirror-image comparisons (8-pixel blocks): their
/// pixels are not sampled at mirrored positions, so the silhouettes differ by the noise of
/// anti-aliasing, about 0.015 of the mean at this count.
const MIRROR_SPP: u32 = 32;
const MIRROR_TOLERANCE: f64 = 0.06;

/// `scene` and `reference` rendered for a mirror-image comparison: `scene` and the mirror
/// image of `reference` must agree.
fn assert_mirror_image(case: &str, scene: Scene, reference: Scene) {
    let got = render_case(case, scene, &options(SIZE, SIZE), MIRROR_SPP);
    let want = render_case(case, reference, &options(SIZE, SIZE), MIRROR_SPP);
    let flipped = mirrored(&want);
    println!(
        "{case}: measured mean {:.4} (expected {:.4}, the unmirrored image flipped)",
        mean(&got),
        mean(&flipped)
    );
    assert_same_image(case, &got, &flipped, 8, MIRROR_TOLERANCE);
}

/// The layers mirrored left to right.
fn mirrored(l: &Layers) -> Layers {
    let mut out = Layers::new(l.rect);
    let w = l.rect.width as usize;
    for i in 0..l.beauty.len() {
        let j = i - i % w + (w - 1 - i % w);
        out.beauty[i] = l.beauty[j];
        out.albedo[i] = l.albedo[j];
        out.normal[i] = l.normal[j];
        out.depth[i] = l.depth[j];
    }
    out
}

/// Asserts that some warning contains every one of `needles`, and prints it.
fn assert_warns(case: &str, scene: &Scene, needles: &[&str]) {
    let found = scene
        .warnings
        .iter()
        .find(|w| needles.iter().all(|n| w.contains(n)));
    match found {
        Some(w) => println!("{case}: warning \"{w}\""),
        None => panic!(
            "{case}: no warning mentions {needles:?}; warnings: {:?}",
            scene.warnings
        ),
    }
}

fn assert_no_warnings(case: &str, scene: &Scene) {
    assert!(
        scene.warnings.is_empty(),
        "{case}: legal data, yet warnings {:?}",
        scene.warnings
    );
    println!("{case}: no warning (legal glTF)");
}

/// Renders `got` and `want` and compares them block by block.
fn assert_renders_like(case: &str, got: Scene, want: Scene, tolerance: f64) {
    let g = lit(case, got);
    let w = lit(&format!("{case} (reference)"), want);
    println!(
        "{case}: measured mean {:.4} (expected {:.4}, the reference scene)",
        mean(&g),
        mean(&w)
    );
    assert_same_image(case, &g, &w, BLOCK, tolerance);
}

/// Mean, minimum and maximum of the RGB average over fully covered pixels.
fn covered_stats(l: &Layers) -> (f64, f64, f64) {
    let v: Vec<f64> = l
        .beauty
        .iter()
        .filter(|b| b.w == 1.0)
        .map(|b| (b.x + b.y + b.z) as f64 / 3.0)
        .collect();
    assert!(v.len() > 100, "too few covered pixels: {}", v.len());
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let min = v.iter().copied().fold(f64::INFINITY, f64::min);
    let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (mean, min, max)
}

// ---------------------------------------------------------------------------------------
// Cases

/// A scene with `mesh` drawn by one node, lit by the directional light.
fn one_mesh(mesh: &MeshData, material: usize, node_extra: &str) -> Gltf {
    let mut g = Gltf::new();
    let m = g.mesh(mesh, material);
    g.root(format!(r#"{{"mesh":{m}{node_extra}}}"#));
    g
}

#[test]
fn zero_area_triangles_and_duplicated_vertices_draw_as_without_them() {
    let cube = cube_welded(Vec3::ZERO);
    let mut with = cube.clone();
    add_degenerate_triangles(&mut with);

    // The cube and the lamp, each with zero-area triangles: the repeated-index ones are
    // warned about, none is drawn or sampled as a light.
    let case = "zero-area triangles (cube and emissive lamp)";
    let mut g = one_mesh(&with, GREY, "");
    g.lamp(true);
    let scene = g.load(case);
    assert_warns(case, &scene, &["mesh 0, primitive 0", "degenerate"]);
    assert_warns(case, &scene, &["mesh 1, primitive 0", "degenerate"]);
    let mut reference = one_mesh(&cube, GREY, "");
    reference.lamp(false);
    let got = render_case(case, scene, &options(SIZE, SIZE), 32);
    let want = render_case(case, reference.load(case), &options(SIZE, SIZE), 32);
    println!(
        "{case}: measured mean {:.4} (expected {:.4}, without them)",
        mean(&got),
        mean(&want)
    );
    assert_same_image(case, &got, &want, BLOCK, SAME);

    // Every triangle with its own vertices (no indices) is the same smooth sphere.
    let case = "duplicated vertices (unwelded sphere)";
    let welded = sphere();
    let scene = one_mesh(&unwelded(&welded), GREY, "").load(case);
    assert_no_warnings(case, &scene);
    assert_renders_like(case, scene, one_mesh(&welded, GREY, "").load(case), SAME);
}

#[test]
fn zero_or_nan_normals_and_tangents_render_as_face_normals_and_generated_tangents() {
    // A cube of 8 shared vertices: a vertex normal averaged over the faces around a corner
    // would round it; the face normal keeps it a cube, as the file without NORMAL draws.
    let flat = cube_welded(Vec3::ZERO);
    let reference = || one_mesh(&flat, GREY, "").load("flat cube");
    for (name, bad) in [("zero", [0.0; 3]), ("NaN", [f32::NAN, 0.0, 1.0])] {
        let case = format!("{name} normals (cube of shared vertices)");
        let mut m = flat.clone();
        m.normals = Some(vec![bad; 8]);
        let scene = one_mesh(&m, GREY, "").load(&case);
        assert_warns(
            &case,
            &scene,
            &["mesh 0, primitive 0", "8 zero or non-finite normals"],
        );
        assert_renders_like(&case, scene, reference(), SAME);
    }

    // A normal-mapped quad whose TANGENT is unusable gets MikkTSpace tangents, as the one
    // without TANGENT does. The map tilts the normal diagonally, so that a wrong tangent
    // frame would light it differently.
    let texel = Vec3::new(0.35, 0.35, 0.87);
    let plain = quad(Vec3::ZERO, Vec3::X, Vec3::Y);
    for (name, bad) in [("zero", [0.0; 4]), ("NaN", [f32::NAN, 0.0, 0.0, 1.0])] {
        let case = format!("{name} tangents (normal-mapped quad)");
        let mut m = plain.clone();
        m.tangents = Some(vec![bad; 4]);
        let mut g = Gltf::new();
        let mat = g.normal_mapped(0.7, texel);
        let mesh = g.mesh(&m, mat);
        g.root(format!(r#"{{"mesh":{mesh}}}"#));
        let scene = g.load(&case);
        assert_warns(&case, &scene, &["mesh 0, primitive 0", "TANGENT"]);
        let mut r = Gltf::new();
        let mat = r.normal_mapped(0.7, texel);
        let mesh = r.mesh(&plain, mat);
        r.root(format!(r#"{{"mesh":{mesh}}}"#));
        assert_renders_like(&case, scene, r.load(&case), SAME);
    }
}

/// (x, y, z, w) of a rotation of `deg` degrees about `axis`, times `len`.
fn quat(axis: Vec3, deg: f32, len: f32) -> [f32; 4] {
    (Vec4::from(Quat::from_axis_angle(axis.normalize(), deg.to_radians())) * len).to_array()
}

#[test]
fn non_unit_quaternions_render_as_the_normalised_rotation() {
    let cube = cube_welded(Vec3::ZERO);
    let axis = Vec3::new(1.0, 2.0, 0.5);
    let unit = one_mesh(
        &cube,
        GREY,
        &format!(r#","rotation":{:?}"#, quat(axis, 40.0, 1.0)),
    );
    for len in [3.0, 0.25] {
        let case = format!("node rotation of length {len}");
        let g = one_mesh(
            &cube,
            GREY,
            &format!(r#","rotation":{:?}"#, quat(axis, 40.0, len)),
        );
        let scene = g.load(&case);
        assert_warns(&case, &scene, &["node 0", "unit quaternion"]);
        assert_renders_like(&case, scene, unit.load(&case), SAME);
    }

    // A zero quaternion is no rotation at all: the load fails naming the node.
    let g = one_mesh(&cube, GREY, r#","rotation":[0,0,0,0]"#);
    let err = g.try_load().expect_err("a zero rotation is refused");
    println!("zero node rotation: error \"{err}\"");
    assert!(err.to_string().contains("node 0"), "{err}");

    // Animation keys: 0° and 80° about `axis` at t = 0 and 1, seen at t = 0.5 (frame 12 at
    // 24 fps), written with lengths 2 and 0.5; CUBICSPLINE with zero tangents.
    let animated = |interpolation: &str, lens: [f32; 2]| {
        let mut g = one_mesh(&cube, GREY, "");
        let cubic = interpolation == "CUBICSPLINE";
        let times = g.doc.scalars(&[0.0, 1.0]);
        let mut keys = Vec::new();
        for (deg, len) in [(0.0, lens[0]), (80.0, lens[1])] {
            if cubic {
                keys.push([0.0; 4]);
            }
            keys.push(quat(axis, deg, len));
            if cubic {
                keys.push([0.0; 4]);
            }
        }
        let values = g.doc.vec4(&keys);
        g.animations.push(format!(
            r#"{{"channels":[{{"sampler":0,"target":{{"node":0,"path":"rotation"}}}}],
            "samplers":[{{"input":{times},"output":{values},"interpolation":"{interpolation}"}}]}}"#
        ));
        g
    };
    let at_half = FrameOptions {
        frame: 12,
        fps: 24.0,
        ..options(SIZE, SIZE)
    };
    for interpolation in ["STEP", "LINEAR", "CUBICSPLINE"] {
        let case = format!("{interpolation} rotation keys of lengths 2 and 0.5");
        let scene = animated(interpolation, [2.0, 0.5]).load(&case);
        assert_warns(&case, &scene, &["animation 0", "unit quaternion"]);
        let got = render_case(&case, scene, &at_half, SPP);
        let want = render_case(
            &case,
            animated(interpolation, [1.0, 1.0]).load(&case),
            &at_half,
            SPP,
        );
        println!(
            "{case}: measured mean {:.4} (expected {:.4}, unit keys)",
            mean(&got),
            mean(&want)
        );
        assert_same_image(&case, &got, &want, BLOCK, SAME);
    }
}

#[test]
fn zero_scale_singular_and_mirrored_transforms() {
    let cube = cube_welded(Vec3::new(0.3, 0.0, 0.0));
    let ball = {
        let mut s = sphere();
        for p in &mut s.positions {
            *p = (Vec3::from(*p) * 0.3 + Vec3::new(-0.7, 0.5, 0.0)).to_array();
        }
        s
    };

    // Zero scale: the node, its child and an emissive mesh under it draw nothing, which
    // the spec allows ("free to optimize away"); the rest of the scene is untouched.
    let case = "zero scale (node with a child and an emissive mesh)";
    let mut g = one_mesh(&cube, GREY, "");
    let child_mesh = g.mesh(&ball, GREY);
    let lamp = g.mesh(
        &quad(Vec3::new(0.0, 1.0, 0.0), Vec3::X * 0.5, Vec3::Z * 0.5),
        LAMP,
    );
    let child = g.node(format!(r#"{{"mesh":{child_mesh}}}"#));
    let lamp = g.node(format!(r#"{{"mesh":{lamp}}}"#));
    g.root(format!(
        r#"{{"mesh":{child_mesh},"scale":[0,0,0],"translation":[0,-0.8,0],"children":[{child},{lamp}]}}"#
    ));
    let scene = g.load(case);
    assert_no_warnings(case, &scene);
    assert_renders_like(case, scene, one_mesh(&cube, GREY, "").load(case), SAME);

    // Singular (rank 2): the cube flattened onto the plane facing the camera is the flat
    // card it becomes as its thickness goes to zero, by a zero scale or by a matrix.
    let thin = one_mesh(&cube, GREY, r#","scale":[1,1,0.001]"#);
    let case = "singular scale [1, 1, 0]";
    let scene = one_mesh(&cube, GREY, r#","scale":[1,1,0]"#).load(case);
    assert_no_warnings(case, &scene);
    assert_renders_like(case, scene, thin.load(case), 0.05);
    let case = "singular matrix (rank 2)";
    let scene = one_mesh(
        &cube,
        GREY,
        r#","matrix":[1,0,0,0, 0,1,0,0, 0,0,0,0, 0,0,0,1]"#,
    )
    .load(case);
    assert_no_warnings(case, &scene);
    assert_renders_like(case, scene, thin.load(case), 0.05);

    // A matrix that is no translation · rotation · scale breaks a MUST of the spec: it
    // loads with a warning and renders as written (a shear), or with its last row ignored.
    let shear = Mat3::from_cols(Vec3::X, Vec3::new(0.5, 1.0, 0.0), Vec3::Z);
    let mut sheared = cube.clone();
    for p in &mut sheared.positions {
        *p = (shear * Vec3::from(*p)).to_array();
    }
    for (name, matrix, reference) in [
        (
            "sheared matrix",
            "[1,0,0,0, 0.5,1,0,0, 0,0,1,0, 0,0,0,1]",
            one_mesh(&sheared, GREY, ""),
        ),
        (
            "projective matrix",
            "[1,0,0,0.2, 0,1,0,0, 0,0,1,0, 0.1,0,0,1]",
            one_mesh(&cube, GREY, r#","translation":[0.1,0,0]"#),
        ),
    ] {
        let scene = one_mesh(&cube, GREY, &format!(r#","matrix":{matrix}"#)).load(name);
        assert_warns(name, &scene, &["node 0", "matrix"]);
        assert_renders_like(name, scene, reference.load(name), SAME);
    }

    // Mirrors: a negative scale or a matrix with a negative determinant turns the winding
    // (the front faces stay front faces: the material is single-sided), so the mirrored
    // cube is the mirror image of the cube; two mirrors are none.
    for (name, node) in [
        ("mirrored by scale [-1, 1, 1]", r#","scale":[-1,1,1]"#),
        (
            "mirrored by a matrix (det -1)",
            r#","matrix":[-1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]"#,
        ),
    ] {
        let scene = one_mesh(&cube, GREY, node).load(name);
        assert_no_warnings(name, &scene);
        assert_mirror_image(name, scene, one_mesh(&cube, GREY, "").load(name));
    }
    let plain = lit("unmirrored cube", one_mesh(&cube, GREY, "").load("cube"));
    let case = "mirrored twice (parent and child scale [-1, 1, 1])";
    let mut g = Gltf::new();
    let m = g.mesh(&cube, GREY);
    let child = g.node(format!(r#"{{"mesh":{m},"scale":[-1,1,1]}}"#));
    g.root(format!(r#"{{"scale":[-1,1,1],"children":[{child}]}}"#));
    let scene = g.load(case);
    assert_no_warnings(case, &scene);
    let got = lit(case, scene);
    println!(
        "{case}: measured mean {:.4} (expected {:.4})",
        mean(&got),
        mean(&plain)
    );
    assert_same_image(case, &got, &plain, BLOCK, SAME);

    // A morphed cube (its vertices placed per frame, in world space) keeps its front faces
    // under a mirror too.
    let case = "mirrored morphed cube";
    let build = |node: &str| {
        let mut g = Gltf::new();
        let prim = g.primitive(&cube, GREY);
        let grow: Vec<[f32; 3]> = cube.positions.iter().map(|p| p.map(|c| 0.2 * c)).collect();
        let target = g.doc.vec3(&grow);
        let prim = prim.replacen(
            r#","material""#,
            &format!(r#","targets":[{{"POSITION":{target}}}],"material""#),
            1,
        );
        g.meshes
            .push(format!(r#"{{"primitives":[{prim}],"weights":[0.5]}}"#));
        g.root(format!(r#"{{"mesh":0{node}}}"#));
        g.load(case)
    };
    assert_mirror_image(case, build(r#","scale":[-1,1,1]"#), build(""));

    // A normal map on a mirrored quad: the bitangent must follow the mirror. The map tilts
    // the normal up the image, towards the light, on both.
    let case = "mirrored normal-mapped quad";
    let texel = Vec3::new(0.0, 0.5, 0.87);
    let card = quad(Vec3::new(0.4, 0.0, 0.0), Vec3::X * 0.5, Vec3::Y * 0.8);
    let build = |node: &str| {
        let mut g = Gltf::new();
        let mat = g.normal_mapped(0.7, texel);
        let mesh = g.mesh(&card, mat);
        g.root(format!(r#"{{"mesh":{mesh}{node}}}"#));
        g.load(case)
    };
    assert_mirror_image(case, build(r#","scale":[-1,1,1]"#), build(""));
}

#[test]
fn shading_normals_facing_away_from_the_geometry_create_no_energy() {
    // White furnace: radiance 1 from everywhere, white diffuse surfaces, no other light.
    // A convex white object is exactly 1; the pixels scatter around it by the noise of
    // light sampling with MIS (a pixel of FURNACE_SPP samples stays within ±PIXEL).
    const FURNACE_SPP: u32 = 16;
    const PIXEL: f64 = 0.25;
    let furnace = FrameOptions {
        environment: Some(Environment::Constant(Vec3::ONE)),
        ..options(SIZE, SIZE)
    };
    let run = |case: &str, mesh: &MeshData, texel: Option<Vec3>| {
        let mut g = Gltf::new();
        g.light = false;
        let mat = match texel {
            Some(texel) => g.normal_mapped(1.0, texel),
            None => WHITE,
        };
        let m = g.mesh(mesh, mat);
        g.root(format!(r#"{{"mesh":{m}}}"#));
        render_case(case, g.load(case), &furnace, FURNACE_SPP)
    };
    let check = |case: &str, layers: &Layers, want: f64, tol: f64| {
        let (mean, min, max) = covered_stats(layers);
        println!(
            "{case}: measured {mean:.4} (expected {want:.4}, tolerance {tol}); pixels in \
             [{min:.3}, {max:.3}] (allowed ±{PIXEL})"
        );
        assert!(
            (mean - want).abs() <= tol,
            "{case}: mean {mean}, expected {want}"
        );
        assert!(
            max <= want + PIXEL,
            "{case}: a pixel of {max} (bright speckle)"
        );
        assert!(
            min >= want - PIXEL,
            "{case}: a pixel of {min} (dark speckle)"
        );
    };
    let outward = run("outward normals (sphere)", &sphere(), None);
    check(
        "outward normals (sphere, the reference)",
        &outward,
        1.0,
        0.01,
    );

    // Flipped normals: every vertex normal points into the sphere. They are the outward
    // normals reversed, and shade as those: the same paths, the same image.
    let case = "flipped vertex normals (sphere)";
    let flipped = run(case, &with_normals(sphere(), |_, n| -n), None);
    check(case, &flipped, 1.0, 0.01);
    assert_same_image(case, &flipped, &outward, BLOCK, SAME);

    // A normal map whose normal points below the surface (tangent-space z < 0) bends the
    // shading normal under the geometry: the map is ignored there.
    let case = "normal map below the surface (sphere)";
    let below = run(case, &sphere(), Some(Vec3::new(0.9, 0.0, -0.44)));
    check(case, &below, 1.0, 0.01);

    // A normal map that tilts every shading normal 30° (and its lobe over the surface's
    // edge with it): the light sent below is folded back, and the sphere stays white.
    let case = "normal map tilted 30° (sphere)";
    let tilted_map = run(case, &sphere(), Some(Vec3::new(0.5, 0.0, 0.866)));
    check(case, &tilted_map, 1.0, 0.01);

    // Interpolated normals tilted 60° from the face of a quad facing the camera: the
    // diffuse lobe around the shading normal sends (1 − cos 60°)/2 of its light below the
    // surface. Ending those paths read (1 + cos 60°)/2 = 0.75; folded through the face
    // (`integrator.rs`, `fold`), that light stays, and a white surface stays white.
    let tilt = 60f32.to_radians();
    let tilted = with_normals(quad(Vec3::ZERO, Vec3::X, Vec3::Y), |_, _| {
        Vec3::new(tilt.sin(), 0.0, tilt.cos())
    });
    let case = "interpolated normals 60° from the face (quad)";
    check(case, &run(case, &tilted, None), 1.0, 0.01);

    // Normals 85° from the face, each turned a different way round the sphere: most views
    // see the shading normal's back. Energy may only be lost.
    let wild = with_normals(sphere(), |p, n| {
        let side = n.cross(Vec3::new(p.z + 0.3, 1.0, -p.x)).normalize();
        let t = 85f32.to_radians();
        (n * t.cos() + side * t.sin()).normalize()
    });
    let case = "interpolated normals 85° from the face (sphere)";
    let (mean, min, max) = covered_stats(&run(case, &wild, None));
    println!(
        "{case}: measured {mean:.4} (expected <= 1, tolerance 0.01); pixels in \
         [{min:.3}, {max:.3}] (allowed <= {:.1})",
        1.0 + PIXEL
    );
    assert!(mean <= 1.01, "{case}: energy created: {mean}");
    assert!(
        max <= 1.0 + PIXEL,
        "{case}: a pixel of {max} (bright speckle)"
    );
    assert!(min > 0.0, "{case}: a black pixel");
}
