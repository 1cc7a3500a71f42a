//! The loader's typed errors. Every message names the glTF element at fault, as pbrt's
//! `ErrorExit(loc, ...)` names file, line and column: "accessor 12: index 4096 out of range
//! for 300 vertices in mesh 'Body', primitive 0".

use std::fmt;
use std::path::PathBuf;

/// A glTF element, as errors and warnings name it ("accessor 12", "buffer 1").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Element {
    /// `buffers[i]`.
    Buffer(usize),
    /// `bufferViews[i]`.
    BufferView(usize),
    /// `accessors[i]`.
    Accessor(usize),
    /// `images[i]`.
    Image(usize),
    /// `textures[i]`.
    Texture(usize),
    /// `materials[i]`.
    Material(usize),
    /// `meshes[i]`.
    Mesh(usize),
    /// `nodes[i]`.
    Node(usize),
    /// `scenes[i]`.
    Scene(usize),
    /// `cameras[i]`.
    Camera(usize),
    /// `KHR_lights_punctual.lights[i]`.
    Light(usize),
    /// `skins[i]`.
    Skin(usize),
    /// `animations[i]`.
    Animation(usize),
}

impl fmt::Display for Element {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (kind, i) = match *self {
            Element::Buffer(i) => ("buffer", i),
            Element::BufferView(i) => ("bufferView", i),
            Element::Accessor(i) => ("accessor", i),
            Element::Image(i) => ("image", i),
            Element::Texture(i) => ("texture", i),
            Element::Material(i) => ("material", i),
            Element::Mesh(i) => ("mesh", i),
            Element::Node(i) => ("node", i),
            Element::Scene(i) => ("scene", i),
            Element::Camera(i) => ("camera", i),
            Element::Light(i) => ("light", i),
            Element::Skin(i) => ("skin", i),
            Element::Animation(i) => ("animation", i),
        };
        write!(f, "{kind} {i}")
    }
}

/// Why a scene could not be loaded or packed.
///
/// Every variant is the scene's fault (a client error, for the server) except
/// [`SceneError::Io`] on a path the caller chose, which may also be the machine's.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The scene file itself could not be read.
    #[error("cannot read '{}': {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// The bytes are neither a GLB container nor glTF JSON.
    #[error("not a glTF file: {0}")]
    NotGltf(String),
    /// The GLB container is malformed (truncated, wrong version, bad chunk).
    #[error("malformed GLB: {0}")]
    Glb(String),
    /// The JSON does not parse as a glTF document (with serde's line and column).
    #[error("malformed glTF JSON: {0}")]
    Json(String),
    /// The document breaks a rule of the glTF schema; `path` is the JSON path.
    #[error("invalid glTF: {path}: {problem}")]
    Invalid {
        /// JSON path of the offending value, e.g. `meshes[0].primitives[1].indices`.
        path: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The file lists an extension in `extensionsRequired` that the tracer does not
    /// implement, so it cannot be rendered faithfully.
    #[error("required extension '{0}' is not supported")]
    UnsupportedExtension(String),
    /// The default scene draws meshes more often than [`crate::loader::MAX_MESH_DRAWS`]
    /// (GPU instances, and nodes reached along several paths, each count).
    #[error(
        "the scene draws meshes {0} times, more than the {max} the tracer accepts (GPU \
         instances and nodes with several parents each count)",
        max = crate::loader::MAX_MESH_DRAWS
    )]
    TooManyDraws(u64),
    /// One element of the document is wrong.
    #[error("{element}: {message}")]
    Element {
        /// The element at fault.
        element: Element,
        /// What is wrong, naming related elements (mesh, primitive) where it helps.
        message: String,
    },
}

impl SceneError {
    /// An error about one element.
    pub(crate) fn at(element: Element, message: impl Into<String>) -> Self {
        SceneError::Element {
            element,
            message: message.into(),
        }
    }

    /// The element at fault, when the error is about one.
    pub fn element(&self) -> Option<Element> {
        match self {
            SceneError::Element { element, .. } => Some(*element),
            _ => None,
        }
    }
}

/// `mesh 'Body'` when the mesh is named, else `mesh 3`: how messages name a mesh.
pub(crate) fn mesh_label(index: usize, name: Option<&str>) -> String {
    match name {
        Some(n) => format!("mesh '{n}'"),
        None => format!("mesh {index}"),
    }
}
