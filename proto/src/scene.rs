//! What the server found in an uploaded scene.

use serde::{Deserialize, Serialize};

/// The answer to a scene upload (and to `GET /scenes/{digest}/info`). The default is an
/// empty scene, for tests to fill in what they need.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct SceneInfo {
    /// Lower-case hex SHA-256 of the GLB bytes: the scene's name on the farm.
    pub digest: String,
    /// Size of the GLB in bytes.
    pub size: u64,
    /// Camera definitions, in document order.
    pub cameras: Vec<CameraInfo>,
    /// Animations, in document order.
    pub animations: Vec<AnimationInfo>,
    /// End of the longest animation in seconds (0 for a still scene).
    pub duration_seconds: f64,
    /// Triangles drawn by the default scene, once per mesh instance.
    pub triangles: u64,
    /// Punctual lights.
    pub lights: u64,
    /// Meshes.
    pub meshes: u64,
    /// Mesh instances in the default scene.
    pub instances: u64,
    /// Materials.
    pub materials: u64,
    /// Textures.
    pub textures: u64,
    /// What the scene needs from the tracer (`textures`, `animation`, `skinning`, ...).
    pub features: Vec<String>,
    /// Problems that did not stop loading, each naming the glTF element.
    pub warnings: Vec<String>,
}

/// One camera of a scene.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct CameraInfo {
    /// glTF camera index.
    pub index: u32,
    /// glTF camera name, if any.
    pub name: Option<String>,
}

/// One animation of a scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct AnimationInfo {
    /// glTF animation index.
    pub index: u32,
    /// glTF animation name, if any.
    pub name: Option<String>,
    /// First key time in seconds.
    pub start_seconds: f64,
    /// Last key time in seconds.
    pub end_seconds: f64,
}
