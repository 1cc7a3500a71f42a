//! A validated glTF document, with its buffers loaded, into a [`Scene`]: nodes, the default
//! scene's roots, materials and the textures they use, meshes (triangles only), skins,
//! animations, cameras, punctual lights, and the features the scene needs.

use std::borrow::Cow;
use std::collections::BTreeMap;

use glam::{DMat4, DQuat, DVec3, DVec4, Vec3};
use gltf::json::Value;
use rayon::prelude::*;

use super::accessor::view_bytes;
use super::animation::{convert_animations, convert_skins, PointerChannel};
use super::container::Resolver;
use super::error::{Element, SceneError};
use super::instancing;
use super::materials::{convert_material, TextureTable};
use super::meshes::{convert_mesh, fit_weights, MeshOut, SkinLimit};
use super::SUPPORTED_EXTENSIONS;
use crate::camera::Projection;
use crate::light::{Environment, PunctualLight};
use crate::material::Material;
use crate::scene::{CameraDef, Features, Mesh, Node, Scene, Skin, Trs};

/// What the conversion reads from.
pub(crate) struct Input<'a> {
    /// The validated document.
    pub doc: &'a gltf::Document,
    /// The same JSON, untyped, for what the `gltf` crate does not expose without its
    /// `extensions` feature (KHR_texture_transform on a normal texture).
    pub raw: &'a Value,
    /// Buffer bytes, one per `buffers[i]`, each cut to its byteLength.
    pub buffers: &'a [Cow<'a, [u8]>],
    /// Where image URIs are looked up.
    pub resolver: Resolver<'a>,
    /// The KHR_animation_pointer channels taken out of the JSON before it was parsed.
    pub pointers: &'a [PointerChannel],
}

/// Converts the document.
pub(crate) fn build(input: &Input<'_>) -> Result<Scene, SceneError> {
    let doc = input.doc;
    let mut warnings = Vec::new();
    for ext in doc.extensions_used() {
        if !SUPPORTED_EXTENSIONS.contains(&ext) {
            warnings.push(format!(
                "optional extension '{ext}' is not supported; ignored{}",
                materials_using(input.raw, ext)
            ));
        }
    }
    for view in doc.views() {
        view_bytes(&view, input.buffers)?;
    }

    let mut nodes = convert_nodes(input, &mut warnings)?;
    let roots = default_roots(doc, &nodes);
    let skins = convert_skins(doc, input.buffers, nodes.len())?;
    let skin_limits = skin_limits(doc.meshes().len(), &nodes, &skins);

    // Materials first: meshes need to know which primitives carry normal maps.
    let mut table = TextureTable::default();
    let mut materials = Vec::with_capacity(doc.materials().len() + 1);
    for m in doc.materials() {
        materials.push(convert_material(
            &m,
            doc,
            input.raw,
            &mut table,
            &mut warnings,
        )?);
    }
    let textures = table.decode(input)?;
    let default_material = materials.len() as u32;

    let gltf_meshes: Vec<gltf::Mesh<'_>> = doc.meshes().collect();
    let built: Vec<Result<MeshOut, SceneError>> = gltf_meshes
        .par_iter()
        .map(|m| {
            let limit = skin_limits[m.index()];
            convert_mesh(m, input.buffers, &materials, default_material, limit)
        })
        .collect();
    let mut meshes = Vec::with_capacity(built.len());
    let mut uses_default = false;
    for out in built {
        let out = out?;
        warnings.extend(out.warnings);
        uses_default |= out.uses_default;
        meshes.push(out.mesh);
    }
    if uses_default {
        materials.push(Material::default());
    }
    check_node_deformers(&mut nodes, &meshes, &mut warnings);
    let animations = convert_animations(
        doc,
        input.buffers,
        &nodes,
        &meshes,
        input.pointers,
        &mut warnings,
    )?;

    let cameras = doc
        .cameras()
        .map(|c| convert_camera(&c, doc))
        .collect::<Result<Vec<_>, _>>()?;
    let mut lights = Vec::new();
    let mut light_spectra = BTreeMap::new();
    if let Some(ls) = doc.lights() {
        for l in ls {
            lights.push(convert_light(&l, &mut warnings)?);
            let json = &input.raw["extensions"]["KHR_lights_punctual"]["lights"][l.index()];
            if let Some(s) = super::spectra::extension(json, Element::Light(l.index()))? {
                light_spectra.insert(l.index() as u32, s);
            }
        }
    }

    let mut scene = Scene {
        nodes,
        roots,
        meshes,
        materials,
        textures,
        cameras,
        lights,
        light_spectra,
        environment: tessera_environment(doc, &mut warnings),
        animations,
        skins,
        features: Features::default(),
        warnings,
    };
    let draws = scene.mesh_draw_count();
    if draws > super::MAX_MESH_DRAWS {
        return Err(SceneError::TooManyDraws(draws));
    }
    scene.features = features(&scene);
    let mut drawn = 0u64;
    scene.for_each_mesh_draw(|i, _| {
        let m = scene.nodes[i as usize].mesh.expect("draws have a mesh");
        drawn += scene.meshes[m as usize].triangle_count() as u64;
    });
    if drawn == 0 {
        scene
            .warnings
            .push("the default scene draws no triangles".into());
    }
    Ok(scene)
}

/// ` on material 0 'Glass', material 3`: the materials whose `extensions` hold `ext`, for
/// the warning about an extension that is ignored; empty when none does.
fn materials_using(raw: &Value, ext: &str) -> String {
    let Some(materials) = raw["materials"].as_array() else {
        return String::new();
    };
    let names: Vec<String> = materials
        .iter()
        .enumerate()
        .filter(|(_, m)| m["extensions"].get(ext).is_some())
        .map(|(i, m)| match m["name"].as_str() {
            Some(n) => format!("material {i} '{n}'"),
            None => format!("material {i}"),
        })
        .collect();
    if names.is_empty() {
        String::new()
    } else {
        format!(" on {}", names.join(", "))
    }
}

// ---------------------------------------------------------------------------------------
// Nodes and scenes

fn convert_nodes(input: &Input<'_>, warnings: &mut Vec<String>) -> Result<Vec<Node>, SceneError> {
    let doc = input.doc;
    let mut nodes = Vec::with_capacity(doc.nodes().len());
    for n in doc.nodes() {
        let element = Element::Node(n.index());
        let mut trs = None;
        let local = match n.transform() {
            gltf::scene::Transform::Matrix { matrix } => {
                let mut m = DMat4::from_cols_array_2d(&matrix.map(|c| c.map(f64::from)));
                if let Some(why) = not_trs(&m) {
                    let repair = if m.row(3) == DVec4::W {
                        "the shear is kept"
                    } else {
                        // Affine placements only: the row would leak into the composition.
                        m = m.transpose();
                        m.w_axis = DVec4::W;
                        m = m.transpose();
                        "its last row is taken as (0, 0, 0, 1)"
                    };
                    warnings.push(format!(
                        "{element}: matrix {why}; glTF requires a matrix decomposable into \
                         translation, rotation and scale ({repair})"
                    ));
                }
                m
            }
            gltf::scene::Transform::Decomposed {
                translation: t,
                rotation: r,
                scale: s,
            } => {
                let q = DQuat::from_xyzw(r[0] as f64, r[1] as f64, r[2] as f64, r[3] as f64);
                // Exporters write quaternions in f32; renormalise in f64 so that composing
                // deep hierarchies adds no scale drift.
                let len = q.length();
                if !(len.is_finite() && len > 0.0) {
                    return Err(SceneError::at(
                        element,
                        format!("rotation {r:?} is not a usable quaternion"),
                    ));
                }
                if (len - 1.0).abs() > UNIT_TOLERANCE {
                    warnings.push(format!(
                        "{element}: rotation {r:?} is not a unit quaternion (length {len:.6}); \
                         normalised"
                    ));
                }
                let decomposed = Trs {
                    translation: DVec3::from_array(t.map(f64::from)),
                    rotation: q / len,
                    scale: DVec3::from_array(s.map(f64::from)),
                };
                trs = Some(decomposed);
                decomposed.matrix()
            }
        };
        if !local.is_finite() {
            return Err(SceneError::at(element, "transform is not finite"));
        }
        if let Some(bad) = n.weights().and_then(|w| w.iter().find(|w| !w.is_finite())) {
            return Err(SceneError::at(
                element,
                format!("morph weight {bad} is not finite"),
            ));
        }
        nodes.push(Node {
            name: n.name().map(str::to_owned),
            local,
            trs,
            children: n.children().map(|c| c.index() as u32).collect(),
            mesh: n.mesh().map(|m| m.index() as u32),
            camera: n.camera().map(|c| c.index() as u32),
            light: n.light().map(|l| l.index() as u32),
            skin: n.skin().map(|s| s.index() as u32),
            weights: n.weights().map(<[f32]>::to_vec),
            gpu_instances: instancing::gpu_instances(
                doc,
                input.raw,
                input.buffers,
                n.index(),
                warnings,
            )?,
        });
    }
    check_node_graph(&nodes, warnings)?;
    Ok(nodes)
}

/// How far from 1 the length of a float quaternion written by an exporter may be before
/// the loader warns: f32 rounding stays far below it, and so do components printed with
/// three decimals (at most 1e-3 off; Khronos's SimpleSkin sample is 2.3e-4 off).
pub(crate) const UNIT_TOLERANCE: f64 = 2e-3;

/// Why `m` is no translation · rotation · scale, as the spec requires of a node matrix: its
/// last row is not (0, 0, 0, 1), or its columns are not orthogonal (a shear). `None` for a
/// TRS matrix, zero or negative scales included.
fn not_trs(m: &DMat4) -> Option<&'static str> {
    if m.row(3) != DVec4::W {
        return Some("has a last row other than (0, 0, 0, 1)");
    }
    let cols = [
        m.x_axis.truncate(),
        m.y_axis.truncate(),
        m.z_axis.truncate(),
    ];
    let sheared = (0..3).any(|i| {
        let (a, b) = (cols[i], cols[(i + 1) % 3]);
        a.dot(b).abs() > UNIT_TOLERANCE * a.length() * b.length()
    });
    sheared.then_some("shears (its columns are not orthogonal)")
}

/// Refuses cycles; warns about nodes with two parents (the spec wants strict trees; we
/// draw such a node once per parent).
fn check_node_graph(nodes: &[Node], warnings: &mut Vec<String>) -> Result<(), SceneError> {
    let mut parent: Vec<Option<usize>> = vec![None; nodes.len()];
    for (p, n) in nodes.iter().enumerate() {
        for &c in &n.children {
            let c = c as usize;
            match parent[c] {
                Some(other) if other != p => warnings.push(format!(
                    "node {c} has two parents (nodes {other} and {p}); it is drawn under each"
                )),
                _ => parent[c] = Some(p),
            }
        }
    }
    // Iterative depth-first search: 0 = unseen, 1 = on the current path, 2 = done.
    let mut state = vec![0u8; nodes.len()];
    for start in 0..nodes.len() {
        if state[start] != 0 {
            continue;
        }
        let mut stack = vec![(start, 0usize)];
        state[start] = 1;
        while let Some((n, next)) = stack.last_mut() {
            let n = *n;
            if let Some(&c) = nodes[n].children.get(*next) {
                *next += 1;
                let c = c as usize;
                match state[c] {
                    0 => {
                        state[c] = 1;
                        stack.push((c, 0));
                    }
                    1 => {
                        return Err(SceneError::at(
                            Element::Node(n),
                            format!(
                                "child node {c} is also its ancestor: the node graph has a cycle"
                            ),
                        ))
                    }
                    _ => {}
                }
            } else {
                state[n] = 2;
                stack.pop();
            }
        }
    }
    Ok(())
}

/// Per mesh, the skin with the fewest joints among the nodes drawing it with a skin: its
/// JOINTS_n values must stay below that count.
fn skin_limits(meshes: usize, nodes: &[Node], skins: &[Skin]) -> Vec<Option<SkinLimit>> {
    let mut limits: Vec<Option<SkinLimit>> = vec![None; meshes];
    for (i, node) in nodes.iter().enumerate() {
        let (Some(m), Some(s)) = (node.mesh, node.skin) else {
            continue;
        };
        let (Some(limit), Some(skin)) = (limits.get_mut(m as usize), skins.get(s as usize)) else {
            continue;
        };
        if limit.is_none_or(|l| skin.joints.len() < l.joints) {
            *limit = Some(SkinLimit {
                joints: skin.joints.len(),
                skin: s as usize,
                node: i,
            });
        }
    }
    limits
}

/// Fits node morph weights to their mesh's target count, and drops a skin whose node draws
/// nothing it could deform, each with a warning: such files break a "MUST" of the spec, but
/// they draw fine without the part that does not fit.
fn check_node_deformers(nodes: &mut [Node], meshes: &[Mesh], warnings: &mut Vec<String>) {
    for (i, node) in nodes.iter_mut().enumerate() {
        let mesh = node.mesh.and_then(|m| meshes.get(m as usize));
        let targets = mesh.map_or(0, |m| m.weights.len());
        if let Some(w) = &mut node.weights {
            if targets == 0 {
                warnings.push(format!(
                    "node {i} has morph weights but no mesh with morph targets; ignored"
                ));
                node.weights = None;
            } else {
                fit_weights(w, targets, &format!("node {i} has"), warnings);
            }
        }
        if let Some(s) = node.skin {
            let jointed =
                mesh.is_some_and(|m| m.primitives.iter().any(|p| !p.joint_sets.is_empty()));
            if !jointed {
                warnings.push(format!(
                    "node {i} has skin {s} but {}; the skin is ignored",
                    if mesh.is_some() {
                        "its mesh has no JOINTS_0/WEIGHTS_0"
                    } else {
                        "no mesh"
                    }
                ));
                node.skin = None;
            }
        }
    }
}

/// The environment Tessera's exporter keeps in the default scene's extras,
/// `{"tessera": {"environment": [r, g, b]}}` (glTF itself has no environment light). A
/// malformed one is ignored with a warning: extras belong to whichever tool wrote them.
fn tessera_environment(doc: &gltf::Document, warnings: &mut Vec<String>) -> Option<Environment> {
    let scene = doc.default_scene().or_else(|| doc.scenes().next())?;
    let raw = scene.extras().as_ref()?;
    let extras: Value = gltf::json::deserialize::from_str(raw.get()).ok()?;
    let value = extras.get("tessera")?.get("environment")?;
    let rgb: Option<Vec<f32>> = value.as_array().filter(|a| a.len() == 3).map(|a| {
        a.iter()
            .filter_map(|v| v.as_f64())
            .map(|v| v as f32)
            .collect()
    });
    match rgb {
        Some(c) if c.len() == 3 && c.iter().all(|v| v.is_finite() && *v >= 0.0) => {
            let c = Vec3::new(c[0], c[1], c[2]);
            Some(if c == Vec3::ZERO {
                Environment::Black
            } else {
                Environment::Constant(c)
            })
        }
        _ => {
            warnings.push(format!(
                "scene extras: tessera.environment must be three finite non-negative numbers, \
                 not {value}; ignored"
            ));
            None
        }
    }
}

/// The `scene` property's scene, else scene 0, else every node without a parent.
fn default_roots(doc: &gltf::Document, nodes: &[Node]) -> Vec<u32> {
    if let Some(s) = doc.default_scene().or_else(|| doc.scenes().next()) {
        return s.nodes().map(|n| n.index() as u32).collect();
    }
    let mut has_parent = vec![false; nodes.len()];
    for n in nodes {
        for &c in &n.children {
            has_parent[c as usize] = true;
        }
    }
    (0..nodes.len() as u32)
        .filter(|&i| !has_parent[i as usize])
        .collect()
}

// ---------------------------------------------------------------------------------------
// Cameras and lights

fn convert_camera(c: &gltf::Camera<'_>, doc: &gltf::Document) -> Result<CameraDef, SceneError> {
    use gltf::json::camera::Type;
    use gltf::json::validation::Checked;
    let element = Element::Camera(c.index());
    // Read the JSON rather than `gltf::Camera::projection`, which panics when `type` names
    // a projection object that is absent.
    let json = &doc.as_json().cameras[c.index()];
    let projection = match (json.type_, &json.perspective, &json.orthographic) {
        (Checked::Valid(Type::Perspective), Some(p), _) => {
            let (yfov, znear) = (p.yfov, p.znear);
            if !(yfov.is_finite() && yfov > 0.0 && yfov < std::f32::consts::PI) {
                return Err(SceneError::at(
                    element,
                    format!("yfov {yfov} is not in (0, π)"),
                ));
            }
            if !(znear.is_finite() && znear > 0.0) {
                return Err(SceneError::at(
                    element,
                    format!("znear {znear} is not positive"),
                ));
            }
            let aspect_ratio = p.aspect_ratio.filter(|a| a.is_finite() && *a > 0.0);
            Projection::Perspective {
                yfov,
                aspect_ratio,
                znear,
            }
        }
        (Checked::Valid(Type::Orthographic), _, Some(o)) => {
            let (xmag, ymag, znear) = (o.xmag, o.ymag, o.znear);
            if ![xmag, ymag].iter().all(|m| m.is_finite() && *m != 0.0) {
                return Err(SceneError::at(
                    element,
                    format!("xmag {xmag} and ymag {ymag} must be finite and non-zero"),
                ));
            }
            if !(znear.is_finite() && znear >= 0.0) {
                return Err(SceneError::at(
                    element,
                    format!("znear {znear} is negative"),
                ));
            }
            Projection::Orthographic {
                xmag: xmag.abs(),
                ymag: ymag.abs(),
                znear,
            }
        }
        _ => {
            return Err(SceneError::at(
                element,
                "its type does not match its perspective/orthographic object",
            ))
        }
    };
    Ok(CameraDef {
        name: c.name().map(str::to_owned),
        projection,
    })
}

fn convert_light(
    l: &gltf::khr_lights_punctual::Light<'_>,
    warnings: &mut Vec<String>,
) -> Result<PunctualLight, SceneError> {
    let element = Element::Light(l.index());
    let color = Vec3::from_array(l.color());
    let value = color * l.intensity();
    if !value.is_finite() || value.min_element() < 0.0 {
        return Err(SceneError::at(
            element,
            format!(
                "colour {color} × intensity {} is not a finite, non-negative value",
                l.intensity()
            ),
        ));
    }
    let range = match l.range() {
        Some(r) if !(r.is_finite() && r > 0.0) => {
            return Err(SceneError::at(
                element,
                format!("range {r} is not positive"),
            ))
        }
        r => r,
    };
    Ok(match l.kind() {
        gltf::khr_lights_punctual::Kind::Directional => {
            PunctualLight::Directional { illuminance: value }
        }
        gltf::khr_lights_punctual::Kind::Point => PunctualLight::Point {
            intensity: value,
            range,
        },
        gltf::khr_lights_punctual::Kind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => {
            if !(inner_cone_angle.is_finite() && outer_cone_angle.is_finite()) {
                return Err(SceneError::at(element, "cone angles are not finite"));
            }
            // The spec wants 0 <= inner < outer <= π/2.
            let outer = outer_cone_angle.clamp(1e-4, std::f32::consts::FRAC_PI_2);
            let inner = inner_cone_angle.clamp(0.0, outer);
            if (inner, outer) != (inner_cone_angle, outer_cone_angle) {
                warnings.push(format!(
                    "{element}: cone angles ({inner_cone_angle}, {outer_cone_angle}) clamped to ({inner}, {outer})"
                ));
            }
            PunctualLight::Spot {
                intensity: value,
                range,
                inner_cone: inner,
                outer_cone: outer,
            }
        }
    })
}

// ---------------------------------------------------------------------------------------
// Features

/// What the default scene needs: only materials, lights, skins and morph targets its node
/// trees reach count; animation counts when any animation has a channel. Alpha BLEND counts
/// as `alpha_mask` too, since the tracer renders it as stochastic coverage, which needs the
/// same any-hit alpha test.
fn features(scene: &Scene) -> Features {
    let mut f = Features {
        animation: scene
            .animations
            .iter()
            .any(|a| !a.channels.is_empty() || !a.properties.is_empty()),
        emissive: crate::animation::animates_emission(scene),
        ..Features::default()
    };
    let mut seen_mesh = vec![false; scene.meshes.len()];
    scene.for_each_node_instance(|i, _| {
        let node = &scene.nodes[i as usize];
        if let Some(light) = node.light {
            f.punctual_lights = true;
            f.light_spectra |= scene.light_spectra.contains_key(&light);
        }
        let Some(m) = node.mesh else { return };
        let mesh = &scene.meshes[m as usize];
        if node.skin.is_some() && mesh.primitives.iter().any(|p| !p.joint_sets.is_empty()) {
            f.skinning = true;
        }
        if std::mem::replace(&mut seen_mesh[m as usize], true) {
            return;
        }
        f.morphing |= mesh.primitives.iter().any(|p| !p.targets.is_empty());
        for prim in &mesh.primitives {
            if prim.indices.is_empty() {
                continue;
            }
            let mat = &scene.materials[prim.material as usize];
            f.add_material(mat);
            f.normal_maps |= mat.normal_texture.is_some() && !prim.tangents.is_empty();
        }
    });
    f
}
