//! Lights: glTF punctual lights (KHR_lights_punctual), emissive triangles and the
//! environment, and the light sampler that picks one of them for next-event estimation.
//!
//! | item | where |
//! |---|---|
//! | [`PunctualLight`], [`Environment`], [`EmissiveTriangle`]: what a scene holds | here |
//! | [`LightSet`]: one frame's lights in world space, [`LightSample`], [`Emitter`] | [`sampler`] |
//! | point, spot and directional lights; the spot falloff | [`punctual`] |
//! | sampling a point on an emissive triangle (spherical or by area) | `triangle` |
//! | [`EnvironmentMap`]: equirectangular maps, orientation, importance sampling | [`environment`] |
//! | piecewise-constant 1D/2D distributions, the alias table | [`distribution`] |
//!
//! Units follow the glTF specs (see the crate docs): emission in nits is radiance, point
//! and spot intensities in candela, directional illuminance in lux; environment maps hold
//! radiance.

pub mod distribution;
pub mod environment;
pub mod punctual;
pub mod sampler;
mod triangle;

use glam::{Vec2, Vec3};

pub use environment::EnvironmentMap;
pub use punctual::spot_attenuation;
pub use sampler::{Emitter, LightSample, LightSet};

/// A KHR_lights_punctual light in its node's space: at the origin, shining down -Z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PunctualLight {
    /// Point light: `intensity` = colour × intensity, in candela.
    Point {
        /// Linear RGB intensity in candela.
        intensity: Vec3,
        /// Optional range. Ignored: the tracer keeps the physical inverse-square falloff
        /// at every distance (the specification's range window is for real-time engines).
        range: Option<f32>,
    },
    /// Spot light: as a point light inside a cone, with glTF's smooth falloff (see
    /// [`spot_attenuation`]).
    Spot {
        /// Linear RGB intensity in candela (inside the inner cone).
        intensity: Vec3,
        /// Optional range; ignored as for point lights.
        range: Option<f32>,
        /// Inner cone angle in radians: full intensity within it.
        inner_cone: f32,
        /// Outer cone angle in radians: no light beyond it.
        outer_cone: f32,
    },
    /// Directional light: `illuminance` in lux arriving along -Z.
    Directional {
        /// Linear RGB illuminance in lux (on a surface facing the light).
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
    /// An equirectangular image (see [`environment`] for its orientation).
    Map(EnvironmentMap),
}

impl Environment {
    /// Radiance arriving from the world direction `dir` (need not be unit).
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        match self {
            Environment::Black => Vec3::ZERO,
            Environment::Constant(c) => *c,
            Environment::Map(m) => m.radiance(dir),
        }
    }

    /// Whether this environment emits nothing that can be sampled.
    pub fn is_black(&self) -> bool {
        self.luminance_integral() <= 0.0
    }

    /// ∫ luminance(L(ω)) dω over the sphere.
    pub fn luminance_integral(&self) -> f32 {
        let v = match self {
            Environment::Black => 0.0,
            Environment::Constant(c) => 4.0 * std::f32::consts::PI * luminance(*c),
            Environment::Map(m) => m.luminance_integral(),
        };
        if v.is_finite() {
            v.max(0.0)
        } else {
            0.0
        }
    }

    /// Samples a direction of arrival. A constant environment is sampled uniformly over the
    /// sphere (pdf 1/4π: without a surface normal there is no better choice), a map by
    /// luminance. Returns (unit world direction, radiance, solid-angle pdf); `None` when
    /// the environment is black.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, Vec3, f32)> {
        if self.is_black() {
            return None;
        }
        match self {
            Environment::Black => None,
            Environment::Constant(c) => {
                let z = 1.0 - 2.0 * u.x;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let (s, co) = crate::math::sin_cos(2.0 * std::f32::consts::PI * u.y);
                Some((
                    Vec3::new(r * co, r * s, z),
                    *c,
                    1.0 / (4.0 * std::f32::consts::PI),
                ))
            }
            Environment::Map(m) => m.sample(u),
        }
    }

    /// Solid-angle density of [`Self::sample`] for the world direction `dir`.
    pub fn pdf(&self, dir: Vec3) -> f32 {
        if self.is_black() {
            return 0.0;
        }
        match self {
            Environment::Black => 0.0,
            Environment::Constant(_) => 1.0 / (4.0 * std::f32::consts::PI),
            Environment::Map(m) => m.pdf(dir),
        }
    }
}

/// One emissive triangle of a prepared frame, in (camera-relative) world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EmissiveTriangle {
    /// Vertices in world space. Barycentrics (b1, b2) returned by the sampler weight
    /// `p[1]` and `p[2]`: the point is `p[0]·(1 − b1 − b2) + p[1]·b1 + p[2]·b2`, as in
    /// [`crate::geometry::barycentric`].
    pub p: [Vec3; 3],
    /// Emitted radiance (nits): exact where `uniform`, else the factor, which only
    /// estimates the triangle's power.
    pub emission: Vec3,
    /// Whether both faces emit (glTF `doubleSided`); doubles the power estimate.
    pub double_sided: bool,
    /// Whether `emission` is the radiance at every point (no texture or vertex colour
    /// varies it): light samples then carry it, with the side it goes to checked, so the
    /// integrator need not look the triangle up again.
    pub uniform: bool,
    /// Whether the instance mirrors (negative determinant): its front face is then the
    /// one cross(p1 − p0, p2 − p0) points away from (glTF's winding rule).
    pub mirrored: bool,
    /// Instance (as in [`crate::geometry::Hit::instance`]).
    pub instance: u32,
    /// Triangle index within the instance's mesh (as in [`crate::geometry::Hit::triangle`]).
    pub triangle: u32,
    /// The spectrum of its emission, if its material has one of its own (an index the
    /// light samples carry, see [`LightSample::spectrum`]).
    pub spectrum: Option<u32>,
}

/// Errors from loading lights.
#[derive(Debug, thiserror::Error)]
pub enum LightError {
    /// An environment map file could not be read or decoded.
    #[error("environment map {path}: {source}")]
    Exr {
        /// The file (or name) that was read.
        path: String,
        /// What the EXR decoder reported.
        #[source]
        source: exr::error::Error,
    },
    /// Pixel data whose size does not match its dimensions, or an empty image.
    #[error("environment map of {width}×{height} pixels given {pixels} pixel values")]
    Size {
        /// Declared width.
        width: usize,
        /// Declared height.
        height: usize,
        /// Number of pixels given.
        pixels: usize,
    },
}

/// Luminance of linear Rec. 709 RGB (negative channels count as zero).
pub(crate) fn luminance(c: Vec3) -> f32 {
    let c = c.max(Vec3::ZERO);
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}
