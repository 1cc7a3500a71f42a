//! Materials with the KHR material extensions, and the textures they use: one texture per
//! distinct (image, sampler) pair, each image decoded once.

use std::borrow::Cow;
use std::collections::HashMap;

use glam::{Vec2, Vec3, Vec4};
use gltf::json::Value;
use rayon::prelude::*;

use super::accessor::view_bytes;
use super::error::{Element, SceneError};
use super::gltf::Input;
use super::images;
use crate::material::{AlphaMode, Material};
use crate::texture::{Filter, Texture, TextureRef, UvTransform, Wrap};

/// The scene's textures: one per distinct (image, sampler settings) that a material uses.
#[derive(Default)]
pub(crate) struct TextureTable {
    index: HashMap<(usize, u8, u8, u8), u32>,
    entries: Vec<(usize, Wrap, Wrap, Filter)>,
}

fn wrap_of(w: gltf::texture::WrappingMode) -> Wrap {
    match w {
        gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
        gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
    }
}

impl TextureTable {
    fn add(&mut self, tex: &gltf::Texture<'_>) -> u32 {
        let s = tex.sampler();
        let (ws, wt) = (wrap_of(s.wrap_s()), wrap_of(s.wrap_t()));
        let filter = match s.mag_filter() {
            Some(gltf::texture::MagFilter::Nearest) => Filter::Nearest,
            _ => Filter::Linear,
        };
        let image = tex.source().index();
        let key = (image, ws as u8, wt as u8, filter as u8);
        let next = self.entries.len() as u32;
        *self.index.entry(key).or_insert_with(|| {
            self.entries.push((image, ws, wt, filter));
            next
        })
    }

    /// Decodes every image the table uses, once each and in parallel.
    pub(crate) fn decode(&self, input: &Input<'_>) -> Result<Vec<Texture>, SceneError> {
        let mut unique: Vec<usize> = self.entries.iter().map(|e| e.0).collect();
        unique.sort_unstable();
        unique.dedup();
        let decoded: Vec<Result<images::Decoded, SceneError>> =
            unique.par_iter().map(|&i| decode_image(input, i)).collect();
        let mut decoded: Vec<Option<images::Decoded>> = decoded
            .into_iter()
            .map(|d| d.map(Some))
            .collect::<Result<_, _>>()?;
        let mut uses_left: HashMap<usize, usize> = HashMap::new();
        for e in &self.entries {
            *uses_left.entry(e.0).or_default() += 1;
        }
        let mut out = Vec::with_capacity(self.entries.len());
        for &(image, wrap_s, wrap_t, filter) in &self.entries {
            let slot = unique
                .binary_search(&image)
                .expect("every entry's image was decoded");
            let left = uses_left.get_mut(&image).expect("counted above");
            *left -= 1;
            // The last texture using an image takes its texels; earlier ones copy them.
            let d = if *left == 0 {
                decoded[slot].take().expect("taken only by the last use")
            } else {
                let d = decoded[slot]
                    .as_ref()
                    .expect("not taken before the last use");
                images::Decoded {
                    width: d.width,
                    height: d.height,
                    texels: d.texels.clone(),
                }
            };
            out.push(Texture {
                width: d.width,
                height: d.height,
                texels: d.texels,
                wrap_s,
                wrap_t,
                filter,
            });
        }
        Ok(out)
    }
}

/// EXT_texture_webp: a texture naming a WebP image in the extension reads that image
/// instead of its `source` (a PNG or JPEG fallback for other viewers, or none when the
/// file requires the extension). Rewrites the untyped document before the typed parse,
/// which would refuse a texture without `source`; returns whether anything changed.
pub(crate) fn prefer_webp_sources(raw: &mut Value) -> bool {
    let Some(textures) = raw.get_mut("textures").and_then(Value::as_array_mut) else {
        return false;
    };
    let mut changed = false;
    for t in textures {
        let webp = t["extensions"]["EXT_texture_webp"]["source"].clone();
        if webp.is_u64() {
            t["source"] = webp;
            changed = true;
        }
    }
    changed
}

fn decode_image(input: &Input<'_>, index: usize) -> Result<images::Decoded, SceneError> {
    let element = Element::Image(index);
    // Read the JSON rather than `gltf::Image::source`, which panics on an image with a
    // bufferView but no mimeType, or with neither bufferView nor uri.
    let json = &input.doc.as_json().images[index];
    let declared = json.mime_type.as_ref().map(|m| m.0.clone());
    let (bytes, mime, what): (Cow<'_, [u8]>, Option<String>, String) =
        match (&json.buffer_view, &json.uri) {
            (Some(view), _) => {
                let view = input
                    .doc
                    .views()
                    .nth(view.value())
                    .expect("validated index");
                let what = format!("bufferView {}", view.index());
                (
                    Cow::Borrowed(view_bytes(&view, input.buffers)?),
                    declared,
                    what,
                )
            }
            (None, Some(uri)) => {
                let r = input.resolver.resolve(uri, element)?;
                let what = if uri.starts_with("data:") {
                    "data: URI".into()
                } else {
                    format!("'{uri}'")
                };
                (Cow::Owned(r.bytes), declared.or(r.mime), what)
            }
            (None, None) => {
                return Err(SceneError::at(
                    element,
                    "has neither a bufferView nor a uri",
                ))
            }
        };
    images::decode(&bytes, mime.as_deref())
        .map_err(|e| SceneError::at(element, format!("{what}: {e}")))
}

fn uv_transform(offset: [f32; 2], rotation: f32, scale: [f32; 2]) -> UvTransform {
    UvTransform {
        offset: Vec2::from_array(offset),
        rotation,
        scale: Vec2::from_array(scale),
    }
}

fn texture_ref(
    table: &mut TextureTable,
    info: &gltf::texture::Info<'_>,
    context: &str,
    warnings: &mut Vec<String>,
) -> TextureRef {
    let (texcoord, transform) = match info.texture_transform() {
        Some(t) => (
            t.tex_coord().unwrap_or(info.tex_coord()),
            Some(uv_transform(t.offset(), t.rotation(), t.scale())),
        ),
        None => (info.tex_coord(), None),
    };
    finish_ref(
        table,
        &info.texture(),
        texcoord,
        transform,
        context,
        warnings,
    )
}

fn finish_ref(
    table: &mut TextureTable,
    tex: &gltf::Texture<'_>,
    texcoord: u32,
    transform: Option<UvTransform>,
    context: &str,
    warnings: &mut Vec<String>,
) -> TextureRef {
    if texcoord > 1 {
        warnings.push(format!(
            "{context} reads TEXCOORD_{texcoord}; only TEXCOORD_0 and TEXCOORD_1 are loaded"
        ));
    }
    // An identity transform is no transform: skip the work per sample.
    let transform = transform.filter(|t| *t != uv_transform([0.0; 2], 0.0, [1.0; 2]));
    TextureRef {
        texture: table.add(tex),
        texcoord,
        transform,
    }
}

/// KHR_texture_transform in a textureInfo's raw JSON: (texCoord override, transform).
fn raw_texture_transform(info: &Value) -> (Option<u32>, Option<UvTransform>) {
    let t = &info["extensions"]["KHR_texture_transform"];
    if !t.is_object() {
        return (None, None);
    }
    let pair = |v: &Value, d: [f32; 2]| -> [f32; 2] {
        match (v[0].as_f64(), v[1].as_f64()) {
            (Some(a), Some(b)) => [a as f32, b as f32],
            _ => d,
        }
    };
    let offset = pair(&t["offset"], [0.0, 0.0]);
    let scale = pair(&t["scale"], [1.0, 1.0]);
    let rotation = t["rotation"].as_f64().unwrap_or(0.0) as f32;
    let texcoord = t["texCoord"]
        .as_u64()
        .map(|c| c.min(u32::MAX as u64) as u32);
    (texcoord, Some(uv_transform(offset, rotation, scale)))
}

/// What converting one material reads besides the typed material.
struct RawMaterial<'a> {
    doc: &'a gltf::Document,
    /// The material's raw JSON.
    json: &'a Value,
    index: usize,
    element: Element,
}

impl RawMaterial<'_> {
    /// A textureInfo of an extension the `gltf` crate does not parse (`info` is null
    /// when the slot is empty), with its texCoord and KHR_texture_transform.
    fn texture(
        &self,
        info: &Value,
        slot: &str,
        table: &mut TextureTable,
        warnings: &mut Vec<String>,
    ) -> Result<Option<TextureRef>, SceneError> {
        if info.is_null() {
            return Ok(None);
        }
        let tex = info["index"]
            .as_u64()
            .and_then(|i| self.doc.textures().nth(i as usize))
            .ok_or_else(|| {
                SceneError::at(self.element, format!("{slot} names no texture: {info}"))
            })?;
        let context = format!("material {} {slot}", self.index);
        let (cover, transform) = raw_texture_transform(info);
        let texcoord = cover
            .or(info["texCoord"]
                .as_u64()
                .map(|c| c.min(u32::MAX as u64) as u32))
            .unwrap_or(0);
        Ok(Some(finish_ref(
            table, &tex, texcoord, transform, &context, warnings,
        )))
    }

    /// A number of an extension object, `default` when absent.
    fn number(&self, ext: &Value, key: &str, default: f32) -> Result<f32, SceneError> {
        match &ext[key] {
            Value::Null => Ok(default),
            v => v
                .as_f64()
                .map(|x| x as f32)
                .ok_or_else(|| SceneError::at(self.element, format!("{key} {v} is not a number"))),
        }
    }

    /// An RGB factor of an extension object, `default` when absent.
    fn rgb(&self, ext: &Value, key: &str, default: Vec3) -> Result<Vec3, SceneError> {
        match &ext[key] {
            Value::Null => Ok(default),
            v => match v
                .as_array()
                .map(|a| a.iter().map(Value::as_f64).collect::<Vec<_>>())
            {
                Some(c) if c.len() == 3 && c.iter().all(Option::is_some) => Ok(Vec3::from_array(
                    [0, 1, 2].map(|i| c[i].unwrap_or(0.0) as f32),
                )),
                _ => Err(SceneError::at(
                    self.element,
                    format!("{key} {v} is not three numbers"),
                )),
            },
        }
    }
}

/// KHR_materials_clearcoat, _sheen, _volume, _iridescence, _diffuse_transmission and
/// _anisotropy, and our own TESSERA_materials_metamaterial, which the `gltf` crate does
/// not parse
/// (or, for the volume, parses behind a feature that would pull the rest of its
/// extension set).
fn read_raw_extensions(
    raw: &RawMaterial<'_>,
    out: &mut Material,
    table: &mut TextureTable,
    warnings: &mut Vec<String>,
) -> Result<(), SceneError> {
    let mut texture = |ext: &Value, slot: &str| raw.texture(&ext[slot], slot, table, warnings);
    let cc = &raw.json["extensions"]["KHR_materials_clearcoat"];
    if cc.is_object() {
        out.clearcoat = raw.number(cc, "clearcoatFactor", 0.0)?;
        out.clearcoat_roughness = raw.number(cc, "clearcoatRoughnessFactor", 0.0)?;
        out.clearcoat_texture = texture(cc, "clearcoatTexture")?;
        out.clearcoat_roughness_texture = texture(cc, "clearcoatRoughnessTexture")?;
        out.clearcoat_normal_texture = texture(cc, "clearcoatNormalTexture")?;
        out.clearcoat_normal_scale = raw.number(&cc["clearcoatNormalTexture"], "scale", 1.0)?;
    }
    let sheen = &raw.json["extensions"]["KHR_materials_sheen"];
    if sheen.is_object() {
        out.sheen_color = raw.rgb(sheen, "sheenColorFactor", Vec3::ZERO)?;
        out.sheen_roughness = raw.number(sheen, "sheenRoughnessFactor", 0.0)?;
        out.sheen_color_texture = texture(sheen, "sheenColorTexture")?;
        out.sheen_roughness_texture = texture(sheen, "sheenRoughnessTexture")?;
    }
    let film = &raw.json["extensions"]["KHR_materials_iridescence"];
    if film.is_object() {
        out.iridescence = raw.number(film, "iridescenceFactor", 0.0)?;
        out.iridescence_texture = texture(film, "iridescenceTexture")?;
        out.iridescence_ior = raw.number(film, "iridescenceIor", 1.3)?;
        out.iridescence_thickness_min = raw.number(film, "iridescenceThicknessMinimum", 100.0)?;
        out.iridescence_thickness_max = raw.number(film, "iridescenceThicknessMaximum", 400.0)?;
        out.iridescence_thickness_texture = texture(film, "iridescenceThicknessTexture")?;
    }
    let dt = &raw.json["extensions"]["KHR_materials_diffuse_transmission"];
    if dt.is_object() {
        out.diffuse_transmission = raw.number(dt, "diffuseTransmissionFactor", 0.0)?;
        out.diffuse_transmission_texture = texture(dt, "diffuseTransmissionTexture")?;
        out.diffuse_transmission_color =
            raw.rgb(dt, "diffuseTransmissionColorFactor", Vec3::ONE)?;
        out.diffuse_transmission_color_texture = texture(dt, "diffuseTransmissionColorTexture")?;
    }
    let aniso = &raw.json["extensions"]["KHR_materials_anisotropy"];
    if aniso.is_object() {
        out.anisotropy_strength = raw.number(aniso, "anisotropyStrength", 0.0)?;
        out.anisotropy_rotation = raw.number(aniso, "anisotropyRotation", 0.0)?;
        out.anisotropy_texture = texture(aniso, "anisotropyTexture")?;
    }
    let meta = &raw.json["extensions"][crate::loader::METAMATERIAL];
    if meta.is_object() {
        let n = raw.number(meta, "refractiveIndex", f32::NAN)?;
        let z = raw.number(meta, "impedance", 1.0)?;
        if !(n < 0.0) || !n.is_finite() {
            return Err(SceneError::at(
                raw.element,
                format!(
                    "{} refractiveIndex {n} is not a negative number (a positive index is \
                     KHR_materials_ior's)",
                    crate::loader::METAMATERIAL
                ),
            ));
        }
        if !(z > 0.0) || !z.is_finite() {
            return Err(SceneError::at(
                raw.element,
                format!(
                    "{} impedance {z} is not above 0",
                    crate::loader::METAMATERIAL
                ),
            ));
        }
        out.metamaterial = Some(crate::material::Metamaterial {
            refractive_index: n,
            impedance: z,
        });
    }
    out.emission_spectrum = super::spectra::extension(raw.json, raw.element)?;
    out.fluorescence = super::spectra::fluorescence(raw.json, raw.element)?;
    let dispersion = &raw.json["extensions"]["KHR_materials_dispersion"];
    if dispersion.is_object() {
        out.dispersion = raw.number(dispersion, "dispersion", 0.0)?;
        if !(out.dispersion >= 0.0) || !out.dispersion.is_finite() {
            return Err(SceneError::at(
                raw.element,
                format!(
                    "dispersion {} is not a finite number of at least 0 \
                     (KHR_materials_dispersion: 20 / the Abbe number)",
                    out.dispersion
                ),
            ));
        }
    }
    let volume = &raw.json["extensions"]["KHR_materials_volume"];
    if volume.is_object() {
        out.thickness = raw.number(volume, "thicknessFactor", 0.0)?;
        out.thickness_texture = texture(volume, "thicknessTexture")?;
        out.attenuation_color = raw.rgb(volume, "attenuationColor", Vec3::ONE)?;
        out.attenuation_distance = raw.number(volume, "attenuationDistance", f32::INFINITY)?;
        if !(out.attenuation_distance > 0.0) {
            return Err(SceneError::at(
                raw.element,
                format!(
                    "attenuationDistance {} is not above 0 (KHR_materials_volume: the \
                     distance light travels before it turns attenuationColor)",
                    out.attenuation_distance
                ),
            ));
        }
    }
    Ok(())
}

pub(crate) fn convert_material(
    m: &gltf::Material<'_>,
    doc: &gltf::Document,
    raw: &Value,
    table: &mut TextureTable,
    warnings: &mut Vec<String>,
) -> Result<Material, SceneError> {
    let index = m.index().expect("document materials have an index");
    let element = Element::Material(index);
    let raw = RawMaterial {
        doc,
        json: &raw["materials"][index],
        index,
        element,
    };
    let ctx = |slot: &str| format!("material {index} {slot}");
    let pbr = m.pbr_metallic_roughness();

    let mut out = Material {
        name: m.name().map(str::to_owned),
        base_color: Vec4::from_array(pbr.base_color_factor()),
        metallic: pbr.metallic_factor(),
        roughness: pbr.roughness_factor(),
        emissive: Vec3::from_array(m.emissive_factor()) * m.emissive_strength().unwrap_or(1.0),
        ior: m.ior().unwrap_or(1.5),
        alpha_mode: match m.alpha_mode() {
            gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
            gltf::material::AlphaMode::Mask => AlphaMode::Mask {
                cutoff: m.alpha_cutoff().unwrap_or(0.5),
            },
            gltf::material::AlphaMode::Blend => AlphaMode::Blend,
        },
        double_sided: m.double_sided(),
        unlit: m.unlit(),
        ..Material::default()
    };
    out.base_color_texture = pbr
        .base_color_texture()
        .map(|i| texture_ref(table, &i, &ctx("baseColorTexture"), warnings));
    out.metallic_roughness_texture = pbr
        .metallic_roughness_texture()
        .map(|i| texture_ref(table, &i, &ctx("metallicRoughnessTexture"), warnings));
    out.emissive_texture = m
        .emissive_texture()
        .map(|i| texture_ref(table, &i, &ctx("emissiveTexture"), warnings));
    if let Some(n) = m.normal_texture() {
        // The gltf crate exposes KHR_texture_transform only for `textureInfo`.
        let (cover, transform) = raw_texture_transform(&raw.json["normalTexture"]);
        let texcoord = cover.unwrap_or(n.tex_coord());
        out.normal_texture = Some(finish_ref(
            table,
            &n.texture(),
            texcoord,
            transform,
            &ctx("normalTexture"),
            warnings,
        ));
        out.normal_scale = n.scale();
    }
    if let Some(s) = m.specular() {
        out.specular = s.specular_factor();
        out.specular_color = Vec3::from_array(s.specular_color_factor());
        out.specular_texture = s
            .specular_texture()
            .map(|i| texture_ref(table, &i, &ctx("specularTexture"), warnings));
        out.specular_color_texture = s
            .specular_color_texture()
            .map(|i| texture_ref(table, &i, &ctx("specularColorTexture"), warnings));
    }
    if let Some(t) = m.transmission() {
        out.transmission = t.transmission_factor();
        out.transmission_texture = t
            .transmission_texture()
            .map(|i| texture_ref(table, &i, &ctx("transmissionTexture"), warnings));
    }

    read_raw_extensions(&raw, &mut out, table, warnings)?;

    // A NaN factor would reach every pixel the material covers: refuse it here.
    let cutoff = match out.alpha_mode {
        AlphaMode::Mask { cutoff } => cutoff,
        _ => 0.5,
    };
    let factors = [
        ("baseColorFactor", out.base_color.to_array().to_vec()),
        ("metallicFactor", vec![out.metallic]),
        ("roughnessFactor", vec![out.roughness]),
        (
            "emissive (factor × strength)",
            out.emissive.to_array().to_vec(),
        ),
        ("normalTexture.scale", vec![out.normal_scale]),
        ("ior", vec![out.ior]),
        ("specularFactor", vec![out.specular]),
        (
            "specularColorFactor",
            out.specular_color.to_array().to_vec(),
        ),
        ("transmissionFactor", vec![out.transmission]),
        ("alphaCutoff", vec![cutoff]),
        ("clearcoatFactor", vec![out.clearcoat]),
        ("clearcoatRoughnessFactor", vec![out.clearcoat_roughness]),
        (
            "clearcoatNormalTexture.scale",
            vec![out.clearcoat_normal_scale],
        ),
        ("sheenColorFactor", out.sheen_color.to_array().to_vec()),
        ("sheenRoughnessFactor", vec![out.sheen_roughness]),
        ("thicknessFactor", vec![out.thickness]),
        ("iridescenceFactor", vec![out.iridescence]),
        ("diffuseTransmissionFactor", vec![out.diffuse_transmission]),
        (
            "diffuseTransmissionColorFactor",
            out.diffuse_transmission_color.to_array().to_vec(),
        ),
        ("iridescenceIor", vec![out.iridescence_ior]),
        ("anisotropyStrength", vec![out.anisotropy_strength]),
        ("anisotropyRotation", vec![out.anisotropy_rotation]),
        (
            "iridescenceThicknessMinimum/Maximum",
            vec![out.iridescence_thickness_min, out.iridescence_thickness_max],
        ),
        (
            "attenuationColor",
            out.attenuation_color.to_array().to_vec(),
        ),
    ];
    for (name, values) in factors {
        if values.iter().any(|v| !v.is_finite()) {
            return Err(SceneError::at(
                element,
                format!("{name} {values:?} is not finite"),
            ));
        }
    }
    if out.emissive.min_element() < 0.0 {
        return Err(SceneError::at(
            element,
            format!("emissive {} is negative", out.emissive),
        ));
    }
    // Factors outside the spec's ranges are clamped, as renderers commonly do.
    out.base_color = out.base_color.clamp(Vec4::ZERO, Vec4::ONE);
    out.metallic = out.metallic.clamp(0.0, 1.0);
    out.roughness = out.roughness.clamp(0.0, 1.0);
    out.transmission = out.transmission.clamp(0.0, 1.0);
    out.clearcoat = out.clearcoat.clamp(0.0, 1.0);
    out.clearcoat_roughness = out.clearcoat_roughness.clamp(0.0, 1.0);
    out.sheen_color = out.sheen_color.clamp(Vec3::ZERO, Vec3::ONE);
    out.sheen_roughness = out.sheen_roughness.clamp(0.0, 1.0);
    out.thickness = out.thickness.max(0.0);
    out.iridescence = out.iridescence.clamp(0.0, 1.0);
    out.anisotropy_strength = out.anisotropy_strength.clamp(0.0, 1.0);
    out.diffuse_transmission = out.diffuse_transmission.clamp(0.0, 1.0);
    out.diffuse_transmission_color = out.diffuse_transmission_color.clamp(Vec3::ZERO, Vec3::ONE);
    out.iridescence_ior = out.iridescence_ior.max(1.0);
    out.iridescence_thickness_min = out.iridescence_thickness_min.max(0.0);
    out.iridescence_thickness_max = out.iridescence_thickness_max.max(0.0);
    out.attenuation_color = out.attenuation_color.clamp(Vec3::ZERO, Vec3::ONE);
    out.specular = out.specular.max(0.0);
    out.specular_color = out.specular_color.max(Vec3::ZERO);
    Ok(out)
}
