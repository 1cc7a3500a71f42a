//! A [`Scene`] into a self-contained glTF 2.0 binary (GLB), the inverse of
//! [`crate::loader`]: what [`scene_to_glb`] writes, [`crate::loader::load_glb`] reads back
//! into the same scene. The farm accepts scenes only as GLB uploads, so scenes authored in
//! code (the built-in demo) travel this way.
//!
//! What is written: the node graph (TRS or matrix), the default scene, meshes (triangle
//! lists with POSITION, NORMAL, TANGENT, TEXCOORD_0/1, COLOR_0, u32 indices, morph targets),
//! PBR metallic-roughness materials with KHR_materials_emissive_strength, _ior, _specular,
//! _transmission, _volume, _clearcoat, _sheen, _iridescence, _diffuse_transmission,
//! _anisotropy and _unlit and TESSERA_materials_metamaterial, EXT_mesh_gpu_instancing,
//! cameras, KHR_lights_punctual lights, and animations (every channel with its own
//! sampler). The parts: `export/json.rs` (building blocks), `export/materials.rs` (with
//! what is refused), `export/meshes.rs`, `export/animations.rs`; nodes here. Each value
//! is written so that the loader's arithmetic gives it back
//! bit for bit: emission and light values are split into a factor and a strength whose
//! product is exact, and every JSON number is checked to parse back to its f32.
//!
//! What is refused, with an [`ExportError`] naming the element: textures, skins, an
//! environment that emits light, and values the loader would read back differently (a
//! factor it clamps, a normal it repairs, keys at equal times it merges, ...). Never a
//! silently different scene, with these documented exceptions:
//! - Node transforms are f64 in a [`Scene`] and f32 in glTF: they are rounded to the
//!   nearest f32 (and the loader renormalises rotations in f64).
//! - The loader renormalises vertex normals and tangents, so normals that were not unit to
//!   the last bit come back a few ulps apart.
//!
//! glTF has no environment light. A black or constant one travels in the scene's extras as
//! `{"tessera": {"environment": [r, g, b]}}`, which the loader reads back (other glTF
//! readers ignore it); an environment map is refused.

use glam::{DMat4, DQuat, DVec3, Vec3, Vec4};
use gltf::json::Value;

use crate::animation::{Animation, Interpolation, Property, PropertyChannel, Sampler, Target};
use crate::camera::Projection;
use crate::light::{Environment, PunctualLight};
use crate::loader::write_glb;
use crate::material::{AlphaMode, Material};
use crate::scene::{CameraDef, Mesh, Node, Primitive, Scene};

mod animations;
mod json;
mod materials;
mod meshes;

use animations::*;
use json::*;
use materials::*;
use meshes::*;

/// Why a scene cannot be written as GLB. `element` names the part of the scene at fault
/// ("material 3 'glass'", "mesh 0 'walls', primitive 2", "the scene's environment").
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ExportError {
    /// The scene uses something this exporter does not write (textures, skins, a lit
    /// environment).
    #[error("{element}: {what} cannot be exported: {why}")]
    Unsupported {
        /// The element at fault.
        element: String,
        /// What it uses.
        what: String,
        /// Why that is not written.
        why: String,
    },
    /// A value glTF cannot hold, or one the loader would read back as something else.
    #[error("{element}: {problem}")]
    Invalid {
        /// The element at fault.
        element: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The GLB would exceed the 4 GiB its 32-bit lengths can describe.
    #[error("the GLB would be {0} bytes; GLB lengths are 32-bit")]
    TooLarge(u64),
}

fn invalid(element: &str, problem: impl Into<String>) -> ExportError {
    ExportError::Invalid {
        element: element.to_owned(),
        problem: problem.into(),
    }
}

fn unsupported(element: &str, what: impl Into<String>, why: &str) -> ExportError {
    ExportError::Unsupported {
        element: element.to_owned(),
        what: what.into(),
        why: why.to_owned(),
    }
}

/// "material 3 'glass'", or "material 3" without a name.
fn label(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(n) => format!("{kind} {index} '{n}'"),
        None => format!("{kind} {index}"),
    }
}

/// Writes `scene` as a self-contained GLB: one JSON chunk and one BIN chunk holding every
/// buffer view, as the glTF 2.0 spec lays them out (chunks padded to 4 bytes).
pub fn scene_to_glb(scene: &Scene) -> Result<Vec<u8>, ExportError> {
    refuse_unsupported(scene)?;
    let mut bin = Bin::default();
    let mut used = Extensions::default();

    let materials = scene
        .materials
        .iter()
        .enumerate()
        .map(|(i, m)| material(i, m, &mut used))
        .collect::<Result<Vec<_>, _>>()?;
    let meshes = scene
        .meshes
        .iter()
        .enumerate()
        .map(|(i, m)| mesh(i, m, scene.materials.len(), &mut bin))
        .collect::<Result<Vec<_>, _>>()?;
    let nodes = scene
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| node(i, n, scene, &mut bin, &mut used))
        .collect::<Result<Vec<_>, _>>()?;
    let cameras = scene
        .cameras
        .iter()
        .enumerate()
        .map(|(i, c)| camera(i, c))
        .collect::<Result<Vec<_>, _>>()?;
    let lights = scene
        .lights
        .iter()
        .enumerate()
        .map(|(i, l)| light(i, l, scene.light_spectra.get(&(i as u32)), &mut used))
        .collect::<Result<Vec<_>, _>>()?;
    let animations = scene
        .animations
        .iter()
        .enumerate()
        .map(|(i, a)| animation(i, a, scene, &mut bin, &mut used.animation_pointer))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(&bad) = scene
        .roots
        .iter()
        .find(|&&r| r as usize >= scene.nodes.len())
    {
        return Err(invalid(
            "the default scene",
            format!(
                "root node {bad} out of range for {} nodes",
                scene.nodes.len()
            ),
        ));
    }

    let mut root = Obj::default()
        .with(
            "asset",
            Obj::default()
                .with("version", "2.0")
                .with("generator", "Tessera tracer::export")
                .build(),
        )
        .with("scene", 0)
        .with("scenes", vec![default_scene(scene)])
        .nonempty("nodes", nodes)
        .nonempty("meshes", meshes)
        .nonempty("materials", materials)
        .nonempty("cameras", cameras)
        .nonempty("animations", animations);
    if !lights.is_empty() {
        used.lights = true;
        root = root.with(
            "extensions",
            Obj::default()
                .with(
                    "KHR_lights_punctual",
                    Obj::default().with("lights", lights).build(),
                )
                .build(),
        );
    }
    root = root.nonempty("extensionsUsed", used.names());
    if !bin.bytes.is_empty() {
        root = root
            .with(
                "buffers",
                vec![Obj::default().with("byteLength", bin.bytes.len()).build()],
            )
            .with("bufferViews", std::mem::take(&mut bin.views))
            .with("accessors", std::mem::take(&mut bin.accessors));
    }
    let json = gltf::json::serialize::to_vec(&root.build())
        .expect("a JSON value of finite numbers serialises");
    let bin = (!bin.bytes.is_empty()).then_some(&bin.bytes[..]);
    write_glb(&json, bin)
        .ok_or_else(|| ExportError::TooLarge((json.len() + bin.map_or(0, <[u8]>::len)) as u64))
}

/// The one glTF scene: the root nodes, and a black or constant environment in the extras
/// the loader reads back (see [`crate::loader`]'s `tessera_extras`).
fn default_scene(scene: &Scene) -> Value {
    let radiance = match &scene.environment {
        Some(Environment::Black) => Some(Vec3::ZERO),
        Some(Environment::Constant(c)) => Some(*c),
        Some(Environment::Map(_)) | None => None,
    };
    let mut obj = Obj::default().with("nodes", scene.roots.clone());
    if let Some(c) = radiance {
        let tessera = Obj::default()
            .with("environment", nums(&c.to_array()))
            .build();
        obj = obj.with("extras", Obj::default().with("tessera", tessera).build());
    }
    obj.build()
}

// ---------------------------------------------------------------------------------------
// Nodes

fn node(
    i: usize,
    n: &Node,
    scene: &Scene,
    bin: &mut Bin,
    used: &mut Extensions,
) -> Result<Value, ExportError> {
    let el = label("node", i, n.name.as_deref());
    let in_range = |what: &str, index: Option<u32>, len: usize, all: &str| match index {
        Some(x) if x as usize >= len => Err(invalid(
            &el,
            format!("{what} {x} out of range for {len} {all}"),
        )),
        _ => Ok(()),
    };
    in_range("mesh", n.mesh, scene.meshes.len(), "meshes")?;
    in_range("camera", n.camera, scene.cameras.len(), "cameras")?;
    in_range("light", n.light, scene.lights.len(), "lights")?;
    for &c in &n.children {
        in_range("child node", Some(c), scene.nodes.len(), "nodes")?;
    }

    let mut out = Obj::default();
    if let Some(name) = &n.name {
        out = out.with("name", name.as_str());
    }
    out = out.nonempty("children", n.children.clone());
    match n.trs {
        Some(trs) => {
            // The loader rebuilds `local` from the TRS: they must agree.
            if trs.matrix() != n.local {
                return Err(invalid(
                    &el,
                    "its matrix is not the product of its translation, rotation and scale",
                ));
            }
            let t = trs.translation.as_vec3().to_array();
            let r = trs.rotation.as_quat().to_array();
            let s = trs.scale.as_vec3().to_array();
            finite(&el, "translation", &t)?;
            finite(&el, "rotation", &r)?;
            finite(&el, "scale", &s)?;
            if r == [0.0; 4] {
                return Err(invalid(&el, "rotation is a zero quaternion"));
            }
            if trs.translation != DVec3::ZERO {
                out = out.with("translation", nums(&t));
            }
            if trs.rotation != DQuat::IDENTITY {
                out = out.with("rotation", nums(&r));
            }
            if trs.scale != DVec3::ONE {
                out = out.with("scale", nums(&s));
            }
        }
        // Even an identity matrix is written: without one the loader sees a TRS node.
        None => {
            let m = n.local.as_mat4().to_cols_array();
            finite(&el, "matrix", &m)?;
            out = out.with("matrix", nums(&m));
        }
    }
    if let Some(m) = n.mesh {
        out = out.with("mesh", m);
    }
    if let Some(c) = n.camera {
        out = out.with("camera", c);
    }
    let mut extensions = Obj::default();
    if let Some(l) = n.light {
        extensions = extensions.with(
            "KHR_lights_punctual",
            Obj::default().with("light", l).build(),
        );
    }
    if !n.gpu_instances.is_empty() {
        if n.mesh.is_none() {
            return Err(invalid(&el, "GPU instances without a mesh"));
        }
        used.gpu_instancing = true;
        extensions = extensions.with(INSTANCING, gpu_instances(&el, &n.gpu_instances, bin)?);
    }
    if !extensions.0.is_empty() {
        out = out.with("extensions", extensions.build());
    }
    if let Some(w) = &n.weights {
        let targets = n.mesh.map_or(0, |m| scene.meshes[m as usize].weights.len());
        // The loader cuts, pads or drops weights that do not match the mesh.
        if w.len() != targets {
            return Err(invalid(
                &el,
                format!("{} morph weights for {targets} morph targets", w.len()),
            ));
        }
        finite(&el, "morph weights", w)?;
        out = out.with("weights", nums(w));
    }
    Ok(out.build())
}
