//! glTF PBR metallic-roughness materials with the KHR extensions we support, and their
//! evaluation at a surface point into a [`crate::bsdf::Bsdf`].

use glam::{Vec3, Vec4};

use crate::texture::TextureRef;

/// How a material's alpha is used (glTF `alphaMode`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AlphaMode {
    /// Alpha is ignored.
    Opaque,
    /// Alpha below the cutoff cuts the surface away, for camera and shadow rays alike.
    Mask {
        /// glTF `alphaCutoff`, default 0.5.
        cutoff: f32,
    },
    /// Blended alpha; a path tracer renders it as stochastic coverage.
    Blend,
}

/// A glTF material. Factors multiply their textures, as the spec says.
#[derive(Clone, Debug)]
pub struct Material {
    /// The material's name, if any.
    pub name: Option<String>,
    /// Linear RGBA base colour factor.
    pub base_color: Vec4,
    /// sRGB-encoded base colour texture (decoded to linear when sampled).
    pub base_color_texture: Option<TextureRef>,
    /// Metallic factor, 0..1.
    pub metallic: f32,
    /// Perceptual roughness factor, 0..1 (alpha = roughness²).
    pub roughness: f32,
    /// Roughness in G, metallic in B.
    pub metallic_roughness_texture: Option<TextureRef>,
    /// Tangent-space normal map.
    pub normal_texture: Option<TextureRef>,
    /// Scale of the normal map's XY.
    pub normal_scale: f32,
    /// Emitted radiance in nits: emissiveFactor × KHR_materials_emissive_strength.
    pub emissive: Vec3,
    /// sRGB-encoded emissive texture.
    pub emissive_texture: Option<TextureRef>,
    /// Index of refraction (KHR_materials_ior), default 1.5.
    pub ior: f32,
    /// KHR_materials_specular `specularFactor`, default 1.
    pub specular: f32,
    /// Its texture (alpha channel).
    pub specular_texture: Option<TextureRef>,
    /// KHR_materials_specular `specularColorFactor`, default 1.
    pub specular_color: Vec3,
    /// Its sRGB texture (RGB).
    pub specular_color_texture: Option<TextureRef>,
    /// KHR_materials_transmission `transmissionFactor`, default 0.
    pub transmission: f32,
    /// Its texture (R channel).
    pub transmission_texture: Option<TextureRef>,
    /// glTF `alphaMode`.
    pub alpha_mode: AlphaMode,
    /// glTF `doubleSided`; single-sided surfaces are invisible from behind.
    pub double_sided: bool,
}

impl Default for Material {
    /// The glTF spec's defaults; also the material of a primitive that names none.
    fn default() -> Self {
        Self {
            name: None,
            base_color: Vec4::ONE,
            base_color_texture: None,
            metallic: 1.0,
            roughness: 1.0,
            metallic_roughness_texture: None,
            normal_texture: None,
            normal_scale: 1.0,
            emissive: Vec3::ZERO,
            emissive_texture: None,
            ior: 1.5,
            specular: 1.0,
            specular_texture: None,
            specular_color: Vec3::ONE,
            specular_color_texture: None,
            transmission: 0.0,
            transmission_texture: None,
            alpha_mode: AlphaMode::Opaque,
            double_sided: false,
        }
    }
}

impl Material {
    /// Whether any texture is used.
    pub fn has_textures(&self) -> bool {
        self.texture_refs().next().is_some()
    }

    /// Every texture reference of the material.
    pub fn texture_refs(&self) -> impl Iterator<Item = &TextureRef> {
        [
            &self.base_color_texture,
            &self.metallic_roughness_texture,
            &self.normal_texture,
            &self.emissive_texture,
            &self.specular_texture,
            &self.specular_color_texture,
            &self.transmission_texture,
        ]
        .into_iter()
        .flatten()
    }

    /// Whether the surface emits light anywhere.
    pub fn is_emissive(&self) -> bool {
        self.emissive.max_element() > 0.0
    }
}
