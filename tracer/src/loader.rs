//! glTF 2.0 (.gltf with its files, or .glb) into a [`Scene`], with errors naming the glTF
//! element at fault.
//!
//! | module | what it holds |
//! |---|---|
//! | `container` | GLB chunks, data: URIs and files beside the .gltf, [`pack_glb`] |
//! | `accessor` | accessors into vectors, every byte range checked before allocating |
//! | `gltf` | the document into a scene: nodes, default scene, cameras, lights, features |
//! | `materials` | materials and the textures they use (each image decoded once) |
//! | `meshes` | primitives into triangles: indices, normals, tangents, joints, morph targets |
//! | `animation` | skins (joints, inverse bind matrices) and animation samplers, checked |
//! | `images` | PNG/JPEG into RGBA8 |
//! | `tangents` | MikkTSpace tangents for normal-mapped primitives without TANGENT |
//! | [`framing`] | default-scene traversal, [`scene_bounds`], [`framing_camera`] |
//! | [`error`] | [`SceneError`] and the [`Element`] it names |
//!
//! Choices a user of the loader should know:
//! - Only triangle primitives are drawn (lists, strips and fans); points and lines are
//!   skipped with a warning in [`Scene::warnings`].
//! - A non-finite vertex position is an error naming its accessor, rather than a silently
//!   dropped triangle: such files are broken, and a farm should say so at upload.
//! - Zero or non-finite normals are replaced by face normals (one warning per primitive),
//!   splitting a vertex whose faces disagree. Triangles that use a vertex twice (which the
//!   spec says meshes should not contain) are kept, with a warning: they draw nothing.
//! - A node rotation that is not a unit quaternion is normalised, and so are animation
//!   rotation keys (their CUBICSPLINE tangents by the same factor), with a warning; a zero
//!   node rotation is an error. A node matrix that is not translation · rotation · scale (a
//!   shear, a last row other than (0, 0, 0, 1)) loads with a warning. Zero, singular and
//!   negative (mirroring) scales are legal and load silently.
//! - A primitive without a material gets the glTF default material, appended once at the
//!   end of [`Scene::materials`].
//! - Mesh indices are the document's, so a mesh may have no primitives (all skipped).
//! - Animations are read into [`Scene::animations`] (translation, rotation, scale and
//!   morph weight channels; STEP, LINEAR, CUBICSPLINE), evaluated by
//!   [`crate::animation::pose`]. Key times must be finite and never decrease, and an
//!   animated node must not have a `matrix` (errors); keys at equal times are merged into
//!   the later one (warning). KHR_animation_pointer channels on a light's colour or
//!   intensity, a material's emissive factor or strength, or its base colour, metallic or
//!   roughness factor go to [`crate::animation::Animation::properties`]; other pointers
//!   and targets the loader does not know are skipped with a warning.
//! - Skins are read into [`Scene::skins`] (inverse bind matrices default to identity), and
//!   JOINTS_n/WEIGHTS_n pairs into [`crate::scene::Primitive::joint_sets`], each joint with
//!   a non-zero weight checked against the skin of every node drawing the mesh. Morph
//!   targets (POSITION, NORMAL, TANGENT displacements) go to
//!   [`crate::scene::Primitive::targets`], and default weights to
//!   [`crate::scene::Mesh::weights`] (zeros when the file has none); every primitive of a
//!   mesh must have as many targets. Displacements of normals or tangents the loader
//!   generated are dropped. Meshes stay in bind pose: [`crate::deform`] applies both.
//! - A required extension outside [`SUPPORTED_EXTENSIONS`] is an error; an optional one
//!   is a warning.

use std::path::Path;

mod accessor;
mod animation;
mod container;
pub mod error;
pub mod framing;
mod gltf;
mod images;
mod instancing;
mod materials;
mod meshes;
mod spectra;
mod tangents;

pub use container::write_glb;
pub use error::{Element, SceneError};
pub use framing::{framing_camera, mesh_bounds, mesh_instances, scene_bounds};

use crate::scene::{Features, Scene};
use container::Resolver;

/// The glTF extensions the loader implements. KHR_mesh_quantization needs nothing beyond
/// the integer attribute types the accessor reader handles anyway.
pub const SUPPORTED_EXTENSIONS: &[&str] = &[
    "EXT_mesh_gpu_instancing",
    "EXT_texture_webp",
    "KHR_animation_pointer",
    "KHR_lights_punctual",
    "KHR_materials_anisotropy",
    "KHR_materials_clearcoat",
    "KHR_materials_diffuse_transmission",
    "KHR_materials_dispersion",
    "KHR_materials_emissive_strength",
    "KHR_materials_ior",
    "KHR_materials_iridescence",
    "KHR_materials_sheen",
    "KHR_materials_specular",
    "KHR_materials_transmission",
    "KHR_materials_unlit",
    "KHR_materials_volume",
    "KHR_mesh_quantization",
    "KHR_texture_transform",
    FLUORESCENCE,
    LIGHTS_SPECTRUM,
    METAMATERIAL,
];

/// Our own extension for negative-index media, documented in
/// `docs/TESSERA_materials_metamaterial.md`.
pub const METAMATERIAL: &str = "TESSERA_materials_metamaterial";

/// Our own extension for the spectrum of a light or of a material's emission, documented
/// in `docs/TESSERA_lights_spectrum.md`.
pub const LIGHTS_SPECTRUM: &str = "TESSERA_lights_spectrum";

/// Our own extension for fluorescent paint, documented in
/// `docs/TESSERA_materials_fluorescence.md`.
pub const FLUORESCENCE: &str = "TESSERA_materials_fluorescence";

/// Most mesh draws a scene may ask for: each is an instance of the frame's top-level BVH
/// (about 200 bytes with its share of the tree), so this bounds that tree near 1 GB
/// whatever a small file declares.
pub const MAX_MESH_DRAWS: u64 = 5_000_000;

/// Loads a .gltf (its buffers and images resolved relative to its folder) or a .glb file.
pub fn load_path(path: &Path) -> Result<Scene, SceneError> {
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io {
        path: path.to_owned(),
        source,
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    load_slice(&bytes, Some(base))
}

/// Loads a self-contained GLB, as the server receives uploads: every buffer and image must
/// be inside it (the BIN chunk, or data: URIs); an external file is an error naming it.
pub fn load_glb(bytes: &[u8]) -> Result<Scene, SceneError> {
    if !bytes.starts_with(b"glTF") {
        return Err(SceneError::NotGltf(if container::split(bytes).is_ok() {
            "this is glTF JSON, not a GLB; pack it and its files into one GLB first".into()
        } else {
            "expected a GLB file (starting with 'glTF')".into()
        }));
    }
    load_slice(bytes, None)
}

/// Loads glTF JSON or a GLB from memory; external files are looked up in `base_dir`, and
/// without one the scene must be self-contained.
pub fn load_slice(bytes: &[u8], base_dir: Option<&Path>) -> Result<Scene, SceneError> {
    let container = container::split(bytes)?;
    let json_error = |e: ::gltf::json::Error| SceneError::Json(e.to_string());
    let mut raw: ::gltf::json::Value =
        ::gltf::json::deserialize::from_slice(container.json).map_err(json_error)?;
    // Channels the typed parser would refuse (KHR_animation_pointer) go first; without any,
    // parse the text itself so that errors keep their line and column.
    let (pointers, skipped) = animation::strip_unsupported_channels(&mut raw);
    let webp = materials::prefer_webp_sources(&mut raw);
    let mut root: ::gltf::json::Root = if pointers.is_empty() && skipped.is_empty() && !webp {
        ::gltf::json::deserialize::from_slice(container.json)
            .map_err(|e| typed_json_error(e, || root_at_path_slice(container.json)))?
    } else {
        ::gltf::json::deserialize::from_value(raw.clone())
            .map_err(|e| typed_json_error(e, || root_at_path_value(raw.clone())))?
    };

    // Required extensions are checked against what we implement, not what the `gltf`
    // crate parses: it knows some we do not render and lacks some we do.
    for ext in &root.extensions_required {
        if !SUPPORTED_EXTENSIONS.contains(&ext.as_str()) {
            return Err(SceneError::UnsupportedExtension(ext.clone()));
        }
    }
    root.extensions_required.clear();
    check_position_indices(&root)?;
    let doc = ::gltf::Document::from_json(root).map_err(|e| match e {
        ::gltf::Error::Validation(errors) => {
            let (path, problem) = &errors[0];
            let more = match errors.len() {
                1 => String::new(),
                n => format!(" (and {} more problems)", n - 1),
            };
            SceneError::Invalid {
                path: path.to_string(),
                problem: format!("{problem}{more}"),
            }
        }
        other => SceneError::Json(other.to_string()),
    })?;

    let resolver = Resolver { base_dir };
    let buffers = container::load_buffers(&doc, container.bin, resolver)?;
    let mut scene = self::gltf::build(&self::gltf::Input {
        doc: &doc,
        raw: &raw,
        buffers: &buffers,
        resolver,
        pointers: &pointers,
    })?;
    scene.warnings.extend(skipped);
    Ok(scene)
}

/// A value of the wrong type (`"count": "three"`, `nodes` as an object) as serde reports
/// it has only a line and column, useless in a GLB's one-line JSON: parse again, tracking
/// the path (only on failure, so loading a good file costs nothing more), and name it.
fn typed_json_error(
    e: ::gltf::json::Error,
    retry: impl FnOnce() -> Option<serde_path_to_error::Path>,
) -> SceneError {
    match retry() {
        Some(path) if path.iter().next().is_some() => SceneError::Json(format!("{path}: {e}")),
        _ => SceneError::Json(e.to_string()),
    }
}

/// Where the typed parse of `json` fails, if it does.
fn root_at_path_slice(json: &[u8]) -> Option<serde_path_to_error::Path> {
    let mut de = serde_json::Deserializer::from_slice(json);
    serde_path_to_error::deserialize::<_, ::gltf::json::Root>(&mut de)
        .err()
        .map(|e| e.path().clone())
}

/// Where the typed parse of `raw` fails, if it does.
fn root_at_path_value(raw: ::gltf::json::Value) -> Option<serde_path_to_error::Path> {
    serde_path_to_error::deserialize::<_, ::gltf::json::Root>(raw)
        .err()
        .map(|e| e.path().clone())
}

/// `gltf-json` 1.4's validation indexes `accessors` with a primitive's POSITION before
/// checking it, and panics when it is out of range: check it first.
fn check_position_indices(root: &::gltf::json::Root) -> Result<(), SceneError> {
    use ::gltf::json::validation::Checked;
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let position = prim
                .attributes
                .get(&Checked::Valid(::gltf::Semantic::Positions));
            if position.is_some_and(|i| i.value() >= root.accessors.len()) {
                return Err(SceneError::Invalid {
                    path: format!("meshes[{m}].primitives[{p}].attributes.POSITION"),
                    problem: "Index out of bounds".into(),
                });
            }
        }
    }
    Ok(())
}

/// Packs a .gltf (or .glb) and every file it refers to into one self-contained GLB, for
/// upload: buffers become the BIN chunk and images buffer views inside it. The document is
/// otherwise kept as written.
pub fn pack_glb(path: &Path) -> Result<Vec<u8>, SceneError> {
    container::pack(path)
}

/// Counts that describe a loaded scene, for the server's answer to an upload and for
/// conformance tests.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneSummary {
    /// Triangles the default scene draws, once per mesh instance.
    pub triangles: u64,
    /// Triangles over all meshes, each mesh counted once, whether drawn or not.
    pub unique_triangles: u64,
    /// Meshes in the document.
    pub meshes: usize,
    /// Mesh instances in the default scene.
    pub instances: usize,
    /// Nodes in the document.
    pub nodes: usize,
    /// Camera definitions in the document.
    pub cameras: usize,
    /// Punctual light definitions in the document.
    pub lights: usize,
    /// Materials, including an appended default material.
    pub materials: usize,
    /// Decoded textures.
    pub textures: usize,
    /// Animations in the document, in order.
    pub animations: Vec<AnimationSummary>,
    /// Skins in the document.
    pub skins: usize,
    /// Morph targets over all meshes, each mesh counted once.
    pub morph_targets: usize,
    /// What the scene needs from the tracer.
    pub features: Features,
    /// Number of entries in [`Scene::warnings`].
    pub warnings: usize,
}

/// One animation as [`SceneSummary`] describes it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AnimationSummary {
    /// Its name, if any.
    pub name: Option<String>,
    /// First key time over its channels, in seconds (0 without channels).
    pub start: f64,
    /// Last key time over its channels, in seconds (0 without channels).
    pub end: f64,
    /// Number of channels (skipped ones not counted).
    pub channels: usize,
}

impl SceneSummary {
    /// Counts `scene`.
    pub fn of(scene: &Scene) -> Self {
        let instances = mesh_instances(scene);
        SceneSummary {
            triangles: instances
                .iter()
                .map(|&(m, _)| scene.meshes[m as usize].triangle_count() as u64)
                .sum(),
            unique_triangles: scene.meshes.iter().map(|m| m.triangle_count() as u64).sum(),
            meshes: scene.meshes.len(),
            instances: instances.len(),
            nodes: scene.nodes.len(),
            cameras: scene.cameras.len(),
            lights: scene.lights.len(),
            materials: scene.materials.len(),
            textures: scene.textures.len(),
            animations: scene
                .animations
                .iter()
                .map(|a| {
                    let (start, end) = a.time_range().unwrap_or((0.0, 0.0));
                    AnimationSummary {
                        name: a.name.clone(),
                        start,
                        end,
                        channels: a.channels.len(),
                    }
                })
                .collect(),
            skins: scene.skins.len(),
            morph_targets: scene.meshes.iter().map(|m| m.weights.len()).sum(),
            features: scene.features,
            warnings: scene.warnings.len(),
        }
    }
}
