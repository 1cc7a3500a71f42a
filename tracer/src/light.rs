//! Lights: glTF punctual lights (KHR_lights_punctual), emissive triangles and the
//! environment, and the light sampler that picks one of them for next-event estimation.
//! OWNER: helper D (interface draft; replace freely while keeping these type names).

use glam::Vec3;

/// A KHR_lights_punctual light in its node's space: at the origin, shining down -Z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PunctualLight {
    /// Point light: `intensity` = colour × intensity, in candela.
    Point {
        /// Linear RGB intensity in candela.
        intensity: Vec3,
        /// Optional range (a cutoff hint; we honour the physically based inverse square).
        range: Option<f32>,
    },
    /// Spot light: as a point light inside a cone, with glTF's smooth falloff.
    Spot {
        /// Linear RGB intensity in candela.
        intensity: Vec3,
        /// Optional range.
        range: Option<f32>,
        /// Inner cone angle in radians.
        inner_cone: f32,
        /// Outer cone angle in radians.
        outer_cone: f32,
    },
    /// Directional light: `illuminance` in lux arriving along -Z.
    Directional {
        /// Linear RGB illuminance in lux.
        illuminance: Vec3,
    },
}

/// Light from infinitely far away.
#[derive(Clone, Debug, Default)]
pub enum Environment {
    /// No light from outside the scene.
    #[default]
    Black,
    /// The same radiance from every direction.
    Constant(Vec3),
}
