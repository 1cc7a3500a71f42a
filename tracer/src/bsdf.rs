//! The glTF metallic-roughness BSDF (glTF 2.0 Appendix B, with KHR_materials_specular,
//! _ior and _transmission) in a local shading frame whose normal is +Z.
//! OWNER: helper B (interface draft).

use glam::{Vec2, Vec3};

/// Surface parameters after textures are applied, at one shading point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceParams {
    /// Linear base colour.
    pub base_color: Vec3,
    /// Metallic, 0..1.
    pub metallic: f32,
    /// Perceptual roughness, 0..1.
    pub roughness: f32,
    /// Index of refraction of the material (the outside is assumed to be 1).
    pub ior: f32,
    /// KHR_materials_specular factor.
    pub specular: f32,
    /// KHR_materials_specular colour.
    pub specular_color: Vec3,
    /// KHR_materials_transmission factor.
    pub transmission: f32,
}

/// A sampled direction.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// Incident direction, local frame.
    pub wi: Vec3,
    /// BSDF value for (wo, wi), without the cosine.
    pub f: Vec3,
    /// Solid-angle pdf (for a delta lobe: the probability of choosing it).
    pub pdf: f32,
    /// Whether a delta (perfectly smooth) lobe was sampled.
    pub delta: bool,
}

/// The BSDF at one shading point.
#[derive(Clone, Copy, Debug)]
pub struct Bsdf {
    /// The parameters it was made from.
    pub params: SurfaceParams,
}

impl Bsdf {
    /// The BSDF for these parameters.
    pub fn new(params: SurfaceParams) -> Self {
        Self { params }
    }

    /// f(wo, wi) without the cosine; zero for delta lobes.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let _ = (wo, wi);
        todo!("helper B")
    }

    /// The solid-angle pdf with which [`Bsdf::sample`] returns `wi`; zero for delta lobes.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let _ = (wo, wi);
        todo!("helper B")
    }

    /// Samples an incident direction from `u_lobe` (lobe choice) and `u` (direction).
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let _ = (wo, u_lobe, u);
        todo!("helper B")
    }
}
