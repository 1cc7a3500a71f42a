//! glTF PBR metallic-roughness materials with the KHR extensions we support, and their
//! evaluation at a surface point into a [`crate::bsdf::Bsdf`].

use glam::{Vec2, Vec3, Vec4};

use crate::bsdf::{ExtensionParams, SurfaceParams};
use crate::math;
use crate::spectrum::{FluorescenceDef, SpectrumShape};
use crate::texture::{Texture, TextureRef};

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

/// TESSERA_materials_metamaterial (`docs/TESSERA_materials_metamaterial.md`): the
/// transmitting part of the material leads into a medium of negative refractive index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metamaterial {
    /// `refractiveIndex`, below 0 (e.g. −1).
    pub refractive_index: f32,
    /// `impedance` relative to the outside, above 0; default 1 (matched).
    pub impedance: f32,
}

/// The IOR at wavelength `nm` of a material of IOR `ior` and KHR_materials_dispersion
/// `dispersion` (20 / Abbe number): the extension's two-term Cauchy fit, `ior` at the
/// Fraunhofer d line (587.6 nm) and `n_F − n_C = (ior − 1) / V` between the F (486.1 nm)
/// and C (656.3 nm) lines, never below 1. `ior` itself without dispersion.
pub fn dispersive_ior(ior: f32, dispersion: f32, nm: f32) -> f32 {
    if !(dispersion > 0.0) {
        return ior;
    }
    let abbe = 20.0 / dispersion;
    (ior + (ior - 1.0) / abbe * (523_655.0 / (nm * nm) - 1.5168)).max(1.0)
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
    /// KHR_materials_volume `thicknessFactor`, default 0: a transmitting surface is a thin
    /// wall, as glTF's default is; above 0 it bounds a solid that refracts and absorbs. A
    /// path tracer measures the distance each path travels inside, which the thickness
    /// stands in for where a renderer cannot, so only 0 or not matters here.
    pub thickness: f32,
    /// Its texture (G channel); kept for export (see `thickness`).
    pub thickness_texture: Option<TextureRef>,
    /// `attenuationColor`, default white: what white light turns into over
    /// `attenuation_distance` inside the volume.
    pub attenuation_color: Vec3,
    /// `attenuationDistance` in world units, default infinite (no absorption).
    pub attenuation_distance: f32,
    /// glTF `alphaMode`.
    pub alpha_mode: AlphaMode,
    /// glTF `doubleSided`; single-sided surfaces are invisible from behind.
    pub double_sided: bool,
    /// KHR_materials_clearcoat `clearcoatFactor`, default 0 (no coat).
    pub clearcoat: f32,
    /// Its texture (R channel).
    pub clearcoat_texture: Option<TextureRef>,
    /// `clearcoatRoughnessFactor`, default 0.
    pub clearcoat_roughness: f32,
    /// Its texture (G channel).
    pub clearcoat_roughness_texture: Option<TextureRef>,
    /// `clearcoatNormalTexture`: the coat's own tangent-space normal map. Without it the
    /// coat lies on the unmapped normal (the spec: the base's normal map is not the
    /// coat's).
    pub clearcoat_normal_texture: Option<TextureRef>,
    /// Its scale.
    pub clearcoat_normal_scale: f32,
    /// KHR_materials_sheen `sheenColorFactor`, default black (no sheen).
    pub sheen_color: Vec3,
    /// Its sRGB texture (RGB).
    pub sheen_color_texture: Option<TextureRef>,
    /// `sheenRoughnessFactor`, default 0.
    pub sheen_roughness: f32,
    /// Its texture (alpha channel).
    pub sheen_roughness_texture: Option<TextureRef>,
    /// KHR_materials_iridescence `iridescenceFactor`, default 0 (no film).
    pub iridescence: f32,
    /// Its texture (R channel).
    pub iridescence_texture: Option<TextureRef>,
    /// `iridescenceIor`, default 1.3.
    pub iridescence_ior: f32,
    /// `iridescenceThicknessMinimum` in nanometres, default 100.
    pub iridescence_thickness_min: f32,
    /// `iridescenceThicknessMaximum` in nanometres, default 400: the thickness where no
    /// texture says otherwise.
    pub iridescence_thickness_max: f32,
    /// `iridescenceThicknessTexture` (G channel): the thickness from minimum to maximum.
    pub iridescence_thickness_texture: Option<TextureRef>,
    /// KHR_materials_diffuse_transmission `diffuseTransmissionFactor`, default 0: the
    /// share of the diffuse base that passes to the other side (leaves, paper).
    pub diffuse_transmission: f32,
    /// Its texture (alpha channel).
    pub diffuse_transmission_texture: Option<TextureRef>,
    /// `diffuseTransmissionColorFactor`, default white.
    pub diffuse_transmission_color: Vec3,
    /// Its sRGB texture (RGB).
    pub diffuse_transmission_color_texture: Option<TextureRef>,
    /// KHR_materials_anisotropy `anisotropyStrength`, default 0 (isotropic): how much
    /// rougher the base's microfacet lobes are along the anisotropy direction.
    pub anisotropy_strength: f32,
    /// `anisotropyRotation` in radians, default 0: the direction, counter-clockwise from
    /// the tangent in the tangent-bitangent plane (rotating the texture's directions).
    pub anisotropy_rotation: f32,
    /// `anisotropyTexture`: direction in RG (mapped from [0, 1] to [−1, 1]), strength
    /// in B (times the factor).
    pub anisotropy_texture: Option<TextureRef>,
    /// KHR_materials_dispersion `dispersion`, default 0 (none): 20 / the Abbe number, so
    /// 1 is a flint glass of Abbe number 20 and 0.33 a crown glass. It spreads the IOR of
    /// a refracting volume over wavelength ([`dispersive_ior`]), which the spectral path
    /// follows.
    pub dispersion: f32,
    /// TESSERA_lights_spectrum on the material: the spectrum its emission has (the
    /// emissive colour filtering it), in place of the white that an RGB colour lifts to.
    pub emission_spectrum: Option<SpectrumShape>,
    /// TESSERA_materials_fluorescence, where the material has it: its diffuse base is the
    /// fluorescent paint of Jung et al. 2018 (see [`crate::spectrum::Fluorescence`]), its
    /// base colour the paint's reflectance.
    pub fluorescence: Option<FluorescenceDef>,
    /// TESSERA_materials_metamaterial, where the material has it: its transmitting part
    /// refracts negatively, as the boundary of a solid.
    pub metamaterial: Option<Metamaterial>,
    /// KHR_materials_unlit: the surface shows its base colour (times texture and vertex
    /// colour) as it is, whatever lights it. A path tracer renders that as a surface that
    /// emits its base colour and scatters nothing, so it also lights what it faces.
    pub unlit: bool,
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
            thickness: 0.0,
            thickness_texture: None,
            attenuation_color: Vec3::ONE,
            attenuation_distance: f32::INFINITY,
            alpha_mode: AlphaMode::Opaque,
            double_sided: false,
            clearcoat: 0.0,
            clearcoat_texture: None,
            clearcoat_roughness: 0.0,
            clearcoat_roughness_texture: None,
            clearcoat_normal_texture: None,
            clearcoat_normal_scale: 1.0,
            sheen_color: Vec3::ZERO,
            sheen_color_texture: None,
            sheen_roughness: 0.0,
            sheen_roughness_texture: None,
            iridescence: 0.0,
            iridescence_texture: None,
            iridescence_ior: 1.3,
            iridescence_thickness_min: 100.0,
            iridescence_thickness_max: 400.0,
            iridescence_thickness_texture: None,
            diffuse_transmission: 0.0,
            diffuse_transmission_texture: None,
            diffuse_transmission_color: Vec3::ONE,
            diffuse_transmission_color_texture: None,
            anisotropy_strength: 0.0,
            anisotropy_rotation: 0.0,
            anisotropy_texture: None,
            dispersion: 0.0,
            emission_spectrum: None,
            fluorescence: None,
            metamaterial: None,
            unlit: false,
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
        self.texture_slots()
            .into_iter()
            .filter_map(|(_, t)| t.as_ref())
    }

    /// Every texture slot of the material with its glTF name, empty or not.
    pub fn texture_slots(&self) -> [(&'static str, &Option<TextureRef>); 18] {
        [
            ("baseColorTexture", &self.base_color_texture),
            ("metallicRoughnessTexture", &self.metallic_roughness_texture),
            ("normalTexture", &self.normal_texture),
            ("emissiveTexture", &self.emissive_texture),
            ("specularTexture", &self.specular_texture),
            ("specularColorTexture", &self.specular_color_texture),
            ("transmissionTexture", &self.transmission_texture),
            ("thicknessTexture", &self.thickness_texture),
            ("clearcoatTexture", &self.clearcoat_texture),
            (
                "clearcoatRoughnessTexture",
                &self.clearcoat_roughness_texture,
            ),
            ("clearcoatNormalTexture", &self.clearcoat_normal_texture),
            ("sheenColorTexture", &self.sheen_color_texture),
            ("sheenRoughnessTexture", &self.sheen_roughness_texture),
            ("iridescenceTexture", &self.iridescence_texture),
            (
                "iridescenceThicknessTexture",
                &self.iridescence_thickness_texture,
            ),
            (
                "diffuseTransmissionTexture",
                &self.diffuse_transmission_texture,
            ),
            (
                "diffuseTransmissionColorTexture",
                &self.diffuse_transmission_color_texture,
            ),
            ("anisotropyTexture", &self.anisotropy_texture),
        ]
    }

    /// Whether light it transmits crosses a thin wall (no KHR_materials_volume, or a
    /// thickness of 0, and no metamaterial) rather than entering a solid.
    pub fn is_thin_walled(&self) -> bool {
        !(self.thickness > 0.0) && self.metamaterial.is_none()
    }

    /// Whether the material transmits into a volume (KHR_materials_volume, or a
    /// metamaterial), by refraction or diffusely (KHR_materials_diffuse_transmission:
    /// "a diffuse transmission BTDF describes the transmission of light through the
    /// volume boundary").
    pub fn is_volume(&self) -> bool {
        self.transmits() && !self.is_thin_walled()
    }

    /// The absorption coefficient σ (per world unit, per channel) inside the volume the
    /// material bounds: Beer–Lambert, `attenuationColor = exp(−σ · attenuationDistance)`.
    /// Zero for a thin wall, an opaque material, or no attenuation.
    pub fn absorption(&self) -> Vec3 {
        if !self.is_volume() || !(self.attenuation_distance < f32::INFINITY) {
            return Vec3::ZERO;
        }
        // A black channel absorbs everything: e^-69 is below any radiance that counts.
        let c = self.attenuation_color.clamp(Vec3::splat(1e-30), Vec3::ONE);
        -Vec3::new(math::ln(c.x), math::ln(c.y), math::ln(c.z)) / self.attenuation_distance
    }

    /// Whether light refracting into the material bends by wavelength: KHR_materials_dispersion
    /// on a refracting volume (the extension builds on KHR_materials_volume; a thin wall
    /// bends no wavelength, and a metamaterial has its own index).
    pub fn is_dispersive(&self) -> bool {
        self.dispersion > 0.0
            && self.transmission > 0.0
            && !self.is_thin_walled()
            && self.metamaterial.is_none()
    }

    /// Whether the material fluoresces: TESSERA_materials_fluorescence with some paint
    /// that re-emits some light.
    pub fn is_fluorescent(&self) -> bool {
        self.fluorescence
            .as_ref()
            .is_some_and(FluorescenceDef::is_active)
    }

    /// Whether the material has a sheen layer.
    pub fn has_sheen(&self) -> bool {
        self.sheen_color.max_element() > 0.0
    }

    /// Whether the material uses any extension that [`ExtensionParams`] carries.
    fn has_extensions(&self) -> bool {
        self.clearcoat > 0.0
            || self.has_sheen()
            || self.iridescence > 0.0
            || self.metamaterial.is_some()
            || self.diffuse_transmission > 0.0
            || self.is_anisotropic()
    }

    /// Whether the material has KHR_materials_anisotropy with a strength above 0: its
    /// shading frames must follow the mesh's tangents.
    pub fn is_anisotropic(&self) -> bool {
        self.anisotropy_strength > 0.0
    }

    /// Whether light passes through the surface: it is seen, and lit, from behind too.
    pub fn transmits(&self) -> bool {
        self.transmission > 0.0 || self.diffuse_transmission > 0.0
    }

    /// Whether the surface emits light anywhere.
    pub fn is_emissive(&self) -> bool {
        self.emission_factor().max_element() > 0.0
    }

    /// The emitted radiance where textures and vertex colour are white: the emissive
    /// factor, or an unlit material's base colour.
    pub fn emission_factor(&self) -> Vec3 {
        if self.unlit {
            self.base_color.truncate()
        } else {
            self.emissive
        }
    }

    /// Whether the emission is the same everywhere on a primitive (no texture, nor, for an
    /// unlit material, the primitive's `vertex_colors`, changes it).
    pub fn uniform_emission(&self, vertex_colors: bool) -> bool {
        if self.unlit {
            self.base_color_texture.is_none() && !vertex_colors
        } else {
            self.emissive_texture.is_none()
        }
    }
}

/// The base's factors at a point, before clamping.
struct BaseFactors {
    color: Vec3,
    metallic: f32,
    roughness: f32,
    specular: f32,
    specular_color: Vec3,
    transmission: f32,
}

/// Layer factors (times textures) clamped to their ranges.
fn clamped(l: ExtensionParams) -> ExtensionParams {
    ExtensionParams {
        clearcoat: l.clearcoat.clamp(0.0, 1.0),
        clearcoat_roughness: l.clearcoat_roughness.clamp(0.0, 1.0),
        sheen_color: l.sheen_color.clamp(Vec3::ZERO, Vec3::ONE),
        sheen_roughness: l.sheen_roughness.clamp(0.0, 1.0),
        iridescence: l.iridescence.clamp(0.0, 1.0),
        iridescence_ior: l.iridescence_ior.max(1.0),
        iridescence_thickness: l.iridescence_thickness.max(0.0),
        metamaterial_index: l.metamaterial_index.min(0.0),
        metamaterial_impedance: l.metamaterial_impedance,
        diffuse_transmission: l.diffuse_transmission.clamp(0.0, 1.0),
        diffuse_transmission_color: l.diffuse_transmission_color.clamp(Vec3::ZERO, Vec3::ONE),
        anisotropy: l.anisotropy.clamp(0.0, 1.0),
    }
}

/// A material's values at one surface point, after textures and vertex colours.
#[derive(Clone, Copy, Debug)]
pub struct MaterialSample {
    /// Parameters for the BSDF.
    pub surface: SurfaceParams,
    /// Coverage in `[0, 1]` (base colour alpha × vertex colour alpha).
    pub alpha: f32,
    /// Emitted radiance in nits.
    pub emission: Vec3,
    /// Tangent-space normal from the normal map (unit, +Z is the surface normal), already
    /// scaled by `normal_scale`; `None` without a normal map.
    pub normal_map: Option<Vec3>,
    /// The same from the clear coat's normal map.
    pub clearcoat_normal_map: Option<Vec3>,
    /// KHR_materials_anisotropy: the direction along which the base is rougher, a unit
    /// vector in the tangent-bitangent plane; `None` for an isotropic material.
    pub anisotropy_direction: Option<Vec2>,
}

impl Material {
    /// The BSDF parameters of the factors alone: what [`Material::sample`] gives where
    /// every texture and the vertex colour are white.
    pub fn factors(&self) -> SurfaceParams {
        self.surface(
            BaseFactors {
                color: self.base_color.truncate(),
                metallic: self.metallic,
                roughness: self.roughness,
                specular: self.specular,
                specular_color: self.specular_color,
                transmission: self.transmission,
            },
            self.extension_factors(),
        )
    }

    /// The parameters with factors (times textures) clamped to their ranges.
    fn surface(&self, base: BaseFactors, extensions: Option<ExtensionParams>) -> SurfaceParams {
        if self.unlit {
            // Nothing scatters: the colour is emitted instead (see `Material::unlit`).
            return SurfaceParams {
                base_color: Vec3::ZERO,
                metallic: 0.0,
                specular: 0.0,
                ..SurfaceParams::default()
            };
        }
        SurfaceParams {
            base_color: base.color,
            metallic: base.metallic.clamp(0.0, 1.0),
            roughness: base.roughness.clamp(0.0, 1.0),
            ior: self.ior,
            specular: base.specular.max(0.0),
            specular_color: base.specular_color,
            transmission: base.transmission.clamp(0.0, 1.0),
            thin_walled: self.is_thin_walled(),
            extensions: extensions.map(clamped),
        }
    }

    /// The extensions' factors, for a material that has any.
    fn extension_factors(&self) -> Option<ExtensionParams> {
        self.has_extensions().then_some(ExtensionParams {
            clearcoat: self.clearcoat,
            clearcoat_roughness: self.clearcoat_roughness,
            sheen_color: self.sheen_color,
            sheen_roughness: self.sheen_roughness,
            iridescence: self.iridescence,
            iridescence_ior: self.iridescence_ior,
            iridescence_thickness: self.iridescence_thickness_max,
            metamaterial_index: self.metamaterial.map_or(0.0, |m| m.refractive_index),
            metamaterial_impedance: self.metamaterial.map_or(1.0, |m| m.impedance),
            diffuse_transmission: self.diffuse_transmission,
            diffuse_transmission_color: self.diffuse_transmission_color,
            anisotropy: self.anisotropy_strength,
        })
    }

    /// The extensions' factors times their textures, `read` sampling a texture slot
    /// (sRGB-decoded when asked); `None` for a material without extensions.
    fn extensions_at(
        &self,
        read: &impl Fn(&Option<TextureRef>, bool) -> Option<Vec4>,
    ) -> Option<ExtensionParams> {
        let mut l = self.extension_factors()?;
        if l.clearcoat > 0.0 {
            if let Some(t) = read(&self.clearcoat_texture, false) {
                l.clearcoat *= t.x;
            }
            if let Some(t) = read(&self.clearcoat_roughness_texture, false) {
                l.clearcoat_roughness *= t.y;
            }
        }
        if self.has_sheen() {
            if let Some(t) = read(&self.sheen_color_texture, true) {
                l.sheen_color *= t.truncate();
            }
            if let Some(t) = read(&self.sheen_roughness_texture, false) {
                l.sheen_roughness *= t.w;
            }
        }
        if l.diffuse_transmission > 0.0 {
            if let Some(t) = read(&self.diffuse_transmission_texture, false) {
                l.diffuse_transmission *= t.w;
            }
            if let Some(t) = read(&self.diffuse_transmission_color_texture, true) {
                l.diffuse_transmission_color *= t.truncate();
            }
        }
        if l.iridescence > 0.0 {
            if let Some(t) = read(&self.iridescence_texture, false) {
                l.iridescence *= t.x;
            }
            if let Some(t) = read(&self.iridescence_thickness_texture, false) {
                l.iridescence_thickness = self.iridescence_thickness_min
                    + (self.iridescence_thickness_max - self.iridescence_thickness_min) * t.y;
            }
        }
        Some(l)
    }

    /// Only the coverage at a point: what alpha-masked shadow and camera rays need.
    pub fn alpha(&self, textures: &[Texture], uvs: [Vec2; 2], vertex_color: Vec4) -> f32 {
        let mut a = self.base_color.w * vertex_color.w;
        if let Some(t) = &self.base_color_texture {
            a *= textures[t.texture as usize].sample(t.uv(uvs), true).w;
        }
        a
    }

    /// Whether a hit with this coverage is cut away. `u` is a uniform number used for
    /// stochastic coverage of blended materials.
    pub fn cuts_away(&self, alpha: f32, u: f32) -> bool {
        match self.alpha_mode {
            AlphaMode::Opaque => false,
            AlphaMode::Mask { cutoff } => alpha < cutoff,
            AlphaMode::Blend => u >= alpha,
        }
    }

    /// Evaluates factors × textures at a point with texture coordinates `uvs` and vertex
    /// colour `vertex_color` (white when the primitive has none).
    // Inlined into the integrator, as the compiler chose before the layers grew it: its
    // result then never goes through memory (Cornell box: 0.3% fewer instructions).
    #[inline(always)]
    pub fn sample(
        &self,
        textures: &[Texture],
        uvs: [Vec2; 2],
        vertex_color: Vec4,
    ) -> MaterialSample {
        let read = |r: &Option<TextureRef>, srgb: bool| {
            r.as_ref()
                .map(|t| textures[t.texture as usize].sample(t.uv(uvs), srgb))
        };
        let mut base = self.base_color * vertex_color;
        if let Some(t) = read(&self.base_color_texture, true) {
            base *= t;
        }
        let (mut metallic, mut roughness) = (self.metallic, self.roughness);
        if let Some(t) = read(&self.metallic_roughness_texture, false) {
            roughness *= t.y;
            metallic *= t.z;
        }
        let mut emission = self.emissive;
        if self.unlit {
            emission = base.truncate();
        } else if let Some(t) = read(&self.emissive_texture, true) {
            emission *= t.truncate();
        }
        let mut specular = self.specular;
        if let Some(t) = read(&self.specular_texture, false) {
            specular *= t.w;
        }
        let mut specular_color = self.specular_color;
        if let Some(t) = read(&self.specular_color_texture, true) {
            specular_color *= t.truncate();
        }
        let mut transmission = self.transmission;
        if let Some(t) = read(&self.transmission_texture, false) {
            transmission *= t.x;
        }
        let tangent_normal = |t: Vec4, scale: f32| {
            let n = Vec3::new(
                (2.0 * t.x - 1.0) * scale,
                (2.0 * t.y - 1.0) * scale,
                2.0 * t.z - 1.0,
            );
            math::normalize_or(n, Vec3::Z)
        };
        let normal_map =
            read(&self.normal_texture, false).map(|t| tangent_normal(t, self.normal_scale));
        let mut extensions = self.extensions_at(&read);
        let mut anisotropy_direction = None;
        if self.is_anisotropic() {
            let (strength, direction) = self.anisotropy_at(read(&self.anisotropy_texture, false));
            if let Some(l) = extensions.as_mut() {
                l.anisotropy = strength;
            }
            anisotropy_direction = Some(direction);
        }
        MaterialSample {
            surface: self.surface(
                BaseFactors {
                    color: base.truncate(),
                    metallic,
                    roughness,
                    specular,
                    specular_color,
                    transmission,
                },
                extensions,
            ),
            alpha: base.w,
            emission,
            normal_map,
            clearcoat_normal_map: read(&self.clearcoat_normal_texture, false)
                .map(|t| tangent_normal(t, self.clearcoat_normal_scale)),
            anisotropy_direction,
        }
    }

    /// KHR_materials_anisotropy's strength and direction (unit, tangent-bitangent plane)
    /// for the texel of `anisotropyTexture` at a point, as the extension defines them:
    /// the texel's RG direction (default +X) rotated by `anisotropyRotation`, its B times
    /// the strength factor.
    fn anisotropy_at(&self, texel: Option<Vec4>) -> (f32, Vec2) {
        let (sin, cos) = math::sin_cos(self.anisotropy_rotation);
        let (strength, d) = match texel {
            None => (self.anisotropy_strength, Vec2::X),
            Some(t) => (
                self.anisotropy_strength * t.z,
                (2.0 * Vec2::new(t.x, t.y) - Vec2::ONE).normalize_or(Vec2::X),
            ),
        };
        let direction = Vec2::new(cos * d.x - sin * d.y, sin * d.x + cos * d.y);
        (strength.clamp(0.0, 1.0), direction)
    }
}
