//! What the exporter refuses (textures, skins, a lit environment), and the materials,
//! cameras and lights it writes, each checked to read back as the same values.

use super::*;
use crate::loader::{FLUORESCENCE, LIGHTS_SPECTRUM};
use crate::spectrum::SpectrumShape;

pub(super) const NO_TEXTURES: &str = "the exporter does not write images";
pub(super) const NO_SKINS: &str = "the exporter does not write skins";

pub(super) fn refuse_unsupported(scene: &Scene) -> Result<(), ExportError> {
    for (i, m) in scene.materials.iter().enumerate() {
        let slots = m.texture_slots();
        if let Some((slot, Some(t))) = slots.iter().find(|(_, t)| t.is_some()) {
            return Err(unsupported(
                &label("material", i, m.name.as_deref()),
                format!("{slot} (texture {})", t.texture),
                NO_TEXTURES,
            ));
        }
    }
    if !scene.textures.is_empty() {
        return Err(unsupported(
            "the scene",
            format!("{} textures", scene.textures.len()),
            NO_TEXTURES,
        ));
    }
    if let Some(s) = scene.skins.first() {
        return Err(unsupported(
            &label("skin", 0, s.name.as_deref()),
            "a skin",
            NO_SKINS,
        ));
    }
    if let Some((i, n)) = scene
        .nodes
        .iter()
        .enumerate()
        .find(|(_, n)| n.skin.is_some())
    {
        return Err(unsupported(
            &label("node", i, n.name.as_deref()),
            format!("skin {}", n.skin.unwrap_or_default()),
            NO_SKINS,
        ));
    }
    for (m, mesh) in scene.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if !prim.joint_sets.is_empty() {
                return Err(unsupported(
                    &format!("{}, primitive {p}", label("mesh", m, mesh.name.as_deref())),
                    "JOINTS_n/WEIGHTS_n skinning influences",
                    NO_SKINS,
                ));
            }
        }
    }
    match &scene.environment {
        Some(Environment::Map(_)) => Err(unsupported(
            "the scene's environment",
            "an environment map",
            "glTF has no environment light and the exporter does not write images; pass it \
             to the renderer in FrameOptions::environment instead",
        )),
        Some(Environment::Constant(c)) if !c.is_finite() || c.min_element() < 0.0 => {
            Err(ExportError::Invalid {
                element: "the scene's environment".into(),
                problem: format!("radiance {c} is not finite and non-negative"),
            })
        }
        _ => Ok(()),
    }
}

/// `value` (non-negative, finite) as `factor × scale` with every factor component in
/// [0, 1] and the product exact in f32, as the loader computes it: the largest component as
/// the scale when that is exact, else the next power of two, whose division is exact.
pub(super) fn split_scale(value: Vec3) -> Option<(Vec3, f32)> {
    let max = value.max_element();
    if max <= 1.0 {
        return Some((value, 1.0));
    }
    let power_of_two = f32::from_bits(((max.to_bits() >> 23) + 1) << 23);
    [max, power_of_two].into_iter().find_map(|scale| {
        let factor = value / scale;
        (scale.is_finite() && factor * scale == value && factor.max_element() <= 1.0)
            .then_some((factor, scale))
    })
}

pub(super) fn material(
    i: usize,
    m: &Material,
    used: &mut Extensions,
) -> Result<Value, ExportError> {
    let el = label("material", i, m.name.as_deref());
    let cutoff = match m.alpha_mode {
        AlphaMode::Mask { cutoff } => cutoff,
        _ => 0.5,
    };
    let factors: [(&str, &[f32]); 17] = [
        ("baseColorFactor", &m.base_color.to_array()),
        ("metallicFactor", &[m.metallic]),
        ("roughnessFactor", &[m.roughness]),
        ("emissive", &m.emissive.to_array()),
        ("normal scale", &[m.normal_scale]),
        ("ior", &[m.ior]),
        ("specularFactor", &[m.specular]),
        ("specularColorFactor", &m.specular_color.to_array()),
        ("transmissionFactor", &[m.transmission]),
        ("alphaCutoff", &[cutoff]),
        ("thicknessFactor", &[m.thickness]),
        ("iridescenceIor", &[m.iridescence_ior]),
        (
            "iridescenceThicknessMinimum",
            &[m.iridescence_thickness_min],
        ),
        (
            "iridescenceThicknessMaximum",
            &[m.iridescence_thickness_max],
        ),
        ("anisotropyStrength", &[m.anisotropy_strength]),
        ("anisotropyRotation", &[m.anisotropy_rotation]),
        ("dispersion", &[m.dispersion]),
    ];
    for (name, values) in factors {
        finite(&el, name, values)?;
    }
    // The loader clamps these to glTF's ranges; a value outside would come back changed.
    let unit: [(&str, &[f32]); 13] = [
        ("baseColorFactor", &m.base_color.to_array()),
        ("metallicFactor", &[m.metallic]),
        ("roughnessFactor", &[m.roughness]),
        ("transmissionFactor", &[m.transmission]),
        ("clearcoatFactor", &[m.clearcoat]),
        ("clearcoatRoughnessFactor", &[m.clearcoat_roughness]),
        ("sheenColorFactor", &m.sheen_color.to_array()),
        ("sheenRoughnessFactor", &[m.sheen_roughness]),
        ("attenuationColor", &m.attenuation_color.to_array()),
        ("iridescenceFactor", &[m.iridescence]),
        ("diffuseTransmissionFactor", &[m.diffuse_transmission]),
        (
            "diffuseTransmissionColorFactor",
            &m.diffuse_transmission_color.to_array(),
        ),
        ("anisotropyStrength", &[m.anisotropy_strength]),
    ];
    for (name, values) in unit {
        if values.iter().any(|v| !(0.0..=1.0).contains(v)) {
            return Err(invalid(&el, format!("{name} {values:?} is outside [0, 1]")));
        }
    }
    let non_negative: [(&str, &[f32]); 8] = [
        ("emissive", &m.emissive.to_array()),
        ("dispersion", &[m.dispersion]),
        ("specularFactor", &[m.specular]),
        ("specularColorFactor", &m.specular_color.to_array()),
        ("alphaCutoff", &[cutoff]),
        ("thicknessFactor", &[m.thickness]),
        (
            "iridescenceThicknessMinimum",
            &[m.iridescence_thickness_min],
        ),
        (
            "iridescenceThicknessMaximum",
            &[m.iridescence_thickness_max],
        ),
    ];
    for (name, values) in non_negative {
        if values.iter().any(|v| *v < 0.0) {
            return Err(invalid(&el, format!("{name} {values:?} is negative")));
        }
    }
    if !(m.iridescence_ior >= 1.0) {
        return Err(invalid(
            &el,
            format!("iridescenceIor {} is below 1", m.iridescence_ior),
        ));
    }
    if !(m.attenuation_distance > 0.0) {
        return Err(invalid(
            &el,
            format!(
                "attenuationDistance {} is not above 0",
                m.attenuation_distance
            ),
        ));
    }
    if m.clearcoat_normal_scale != 1.0 {
        return Err(invalid(
            &el,
            format!(
                "clear coat normal scale {} without a clear coat normal texture",
                m.clearcoat_normal_scale
            ),
        ));
    }
    if m.normal_scale != 1.0 {
        // glTF keeps the scale on the normal texture, which textureless materials lack.
        return Err(invalid(
            &el,
            format!("normal scale {} without a normal texture", m.normal_scale),
        ));
    }

    let pbr = Obj::default()
        .with("baseColorFactor", nums(&m.base_color.to_array()))
        .with("metallicFactor", num(m.metallic))
        .with("roughnessFactor", num(m.roughness))
        .build();
    let mut out = Obj::default().with("pbrMetallicRoughness", pbr);
    if let Some(name) = &m.name {
        out = out.with("name", name.as_str());
    }
    let mut ext = Obj::default();
    if m.emissive != Vec3::ZERO {
        let (factor, strength) = split_scale(m.emissive).ok_or_else(|| {
            invalid(
                &el,
                format!(
                    "emissive {} has no exact emissiveFactor × emissive strength",
                    m.emissive
                ),
            )
        })?;
        out = out.with("emissiveFactor", nums(&factor.to_array()));
        if strength != 1.0 {
            used.emissive_strength = true;
            ext = ext.with(
                "KHR_materials_emissive_strength",
                Obj::default()
                    .with("emissiveStrength", num(strength))
                    .build(),
            );
        }
    }
    match m.alpha_mode {
        AlphaMode::Opaque => {}
        AlphaMode::Mask { cutoff } => {
            out = out
                .with("alphaMode", "MASK")
                .with("alphaCutoff", num(cutoff));
        }
        AlphaMode::Blend => out = out.with("alphaMode", "BLEND"),
    }
    if m.double_sided {
        out = out.with("doubleSided", true);
    }
    if m.ior != 1.5 {
        used.ior = true;
        ext = ext.with(
            "KHR_materials_ior",
            Obj::default().with("ior", num(m.ior)).build(),
        );
    }
    if m.specular != 1.0 || m.specular_color != Vec3::ONE {
        used.specular = true;
        ext = ext.with(
            "KHR_materials_specular",
            Obj::default()
                .with("specularFactor", num(m.specular))
                .with("specularColorFactor", nums(&m.specular_color.to_array()))
                .build(),
        );
    }
    if m.transmission != 0.0 {
        used.transmission = true;
        ext = ext.with(
            "KHR_materials_transmission",
            Obj::default()
                .with("transmissionFactor", num(m.transmission))
                .build(),
        );
    }
    let attenuates = m.attenuation_distance.is_finite();
    if m.thickness != 0.0 || attenuates || m.attenuation_color != Vec3::ONE {
        used.volume = true;
        let mut volume = Obj::default()
            .with("thicknessFactor", num(m.thickness))
            .with("attenuationColor", nums(&m.attenuation_color.to_array()));
        // JSON has no infinity: the spec's default stands for it.
        if attenuates {
            volume = volume.with("attenuationDistance", num(m.attenuation_distance));
        }
        ext = ext.with("KHR_materials_volume", volume.build());
    }
    if m.dispersion != 0.0 {
        used.dispersion = true;
        ext = ext.with(
            "KHR_materials_dispersion",
            Obj::default().with("dispersion", num(m.dispersion)).build(),
        );
    }
    let film_defaults = Material::default();
    if m.iridescence != 0.0
        || m.iridescence_ior != film_defaults.iridescence_ior
        || m.iridescence_thickness_min != film_defaults.iridescence_thickness_min
        || m.iridescence_thickness_max != film_defaults.iridescence_thickness_max
    {
        used.iridescence = true;
        ext = ext.with(
            "KHR_materials_iridescence",
            Obj::default()
                .with("iridescenceFactor", num(m.iridescence))
                .with("iridescenceIor", num(m.iridescence_ior))
                .with(
                    "iridescenceThicknessMinimum",
                    num(m.iridescence_thickness_min),
                )
                .with(
                    "iridescenceThicknessMaximum",
                    num(m.iridescence_thickness_max),
                )
                .build(),
        );
    }
    if m.diffuse_transmission != 0.0 || m.diffuse_transmission_color != Vec3::ONE {
        used.diffuse_transmission = true;
        ext = ext.with(
            "KHR_materials_diffuse_transmission",
            Obj::default()
                .with("diffuseTransmissionFactor", num(m.diffuse_transmission))
                .with(
                    "diffuseTransmissionColorFactor",
                    nums(&m.diffuse_transmission_color.to_array()),
                )
                .build(),
        );
    }
    if m.anisotropy_strength != 0.0 || m.anisotropy_rotation != 0.0 {
        used.anisotropy = true;
        ext = ext.with(
            "KHR_materials_anisotropy",
            Obj::default()
                .with("anisotropyStrength", num(m.anisotropy_strength))
                .with("anisotropyRotation", num(m.anisotropy_rotation))
                .build(),
        );
    }
    if let Some(meta) = m.metamaterial {
        let index_ok = meta.refractive_index < 0.0 && meta.refractive_index.is_finite();
        let impedance_ok = meta.impedance > 0.0 && meta.impedance.is_finite();
        if !(index_ok && impedance_ok) {
            return Err(invalid(
                &el,
                format!("metamaterial {meta:?} needs a negative index and a positive impedance"),
            ));
        }
        used.metamaterial = true;
        ext = ext.with(
            crate::loader::METAMATERIAL,
            Obj::default()
                .with("refractiveIndex", num(meta.refractive_index))
                .with("impedance", num(meta.impedance))
                .build(),
        );
    }
    if m.clearcoat != 0.0 || m.clearcoat_roughness != 0.0 {
        used.clearcoat = true;
        ext = ext.with(
            "KHR_materials_clearcoat",
            Obj::default()
                .with("clearcoatFactor", num(m.clearcoat))
                .with("clearcoatRoughnessFactor", num(m.clearcoat_roughness))
                .build(),
        );
    }
    if m.sheen_color != Vec3::ZERO || m.sheen_roughness != 0.0 {
        used.sheen = true;
        ext = ext.with(
            "KHR_materials_sheen",
            Obj::default()
                .with("sheenColorFactor", nums(&m.sheen_color.to_array()))
                .with("sheenRoughnessFactor", num(m.sheen_roughness))
                .build(),
        );
    }
    if m.unlit {
        used.unlit = true;
        ext = ext.with("KHR_materials_unlit", Obj::default().build());
    }
    if let Some(shape) = &m.emission_spectrum {
        used.light_spectra = true;
        ext = ext.with(LIGHTS_SPECTRUM, spectrum(&el, shape)?);
    }
    if let Some(paint) = &m.fluorescence {
        paint
            .check()
            .map_err(|why| invalid(&el, format!("{FLUORESCENCE}: {why}")))?;
        used.fluorescence = true;
        ext = ext.with(
            FLUORESCENCE,
            Obj::default()
                .with("excitation", spectrum(&el, &paint.excitation)?)
                .with("emission", spectrum(&el, &paint.emission)?)
                .with("concentration", num(paint.concentration))
                .with("quantumYield", num(paint.quantum_yield))
                .build(),
        );
    }
    if !ext.0.is_empty() {
        out = out.with("extensions", ext.build());
    }
    Ok(out.build())
}

/// TESSERA_lights_spectrum's object for `shape`.
fn spectrum(el: &str, shape: &SpectrumShape) -> Result<Value, ExportError> {
    shape
        .check()
        .map_err(|why| invalid(el, format!("{LIGHTS_SPECTRUM}: {why}")))?;
    Ok(match shape {
        SpectrumShape::Blackbody(kelvin) => Obj::default().with("blackbody", num(*kelvin)),
        SpectrumShape::Gaussian { peak, width } => Obj::default().with(
            "gaussian",
            Obj::default()
                .with("peak", num(*peak))
                .with("width", num(*width))
                .build(),
        ),
        SpectrumShape::Table(entries) => Obj::default().with(
            "table",
            entries
                .iter()
                .map(|&(nm, v)| nums(&[nm, v]))
                .collect::<Vec<_>>(),
        ),
    }
    .build())
}

pub(super) fn camera(i: usize, c: &CameraDef) -> Result<Value, ExportError> {
    let el = label("camera", i, c.name.as_deref());
    let mut out = Obj::default();
    if let Some(name) = &c.name {
        out = out.with("name", name.as_str());
    }
    // The ranges are the loader's: it refuses or changes anything outside them.
    let out = match c.projection {
        Projection::Perspective {
            yfov,
            aspect_ratio,
            znear,
        } => {
            if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
                return Err(invalid(&el, format!("yfov {yfov} is not in (0, π)")));
            }
            if !(znear > 0.0 && znear.is_finite()) {
                return Err(invalid(&el, format!("znear {znear} is not positive")));
            }
            let mut p = Obj::default()
                .with("yfov", num(yfov))
                .with("znear", num(znear));
            if let Some(a) = aspect_ratio {
                if !(a > 0.0 && a.is_finite()) {
                    return Err(invalid(&el, format!("aspect ratio {a} is not positive")));
                }
                p = p.with("aspectRatio", num(a));
            }
            out.with("type", "perspective")
                .with("perspective", p.build())
        }
        Projection::Orthographic { xmag, ymag, znear } => {
            if !(xmag > 0.0 && ymag > 0.0 && xmag.is_finite() && ymag.is_finite()) {
                return Err(invalid(
                    &el,
                    format!("xmag {xmag} and ymag {ymag} must be positive"),
                ));
            }
            if !(znear >= 0.0 && znear.is_finite()) {
                return Err(invalid(&el, format!("znear {znear} is negative")));
            }
            // glTF requires a far plane; the tracer has none, so it goes as far as f32 does.
            let o = Obj::default()
                .with("xmag", num(xmag))
                .with("ymag", num(ymag))
                .with("znear", num(znear))
                .with("zfar", num(f32::MAX));
            out.with("type", "orthographic")
                .with("orthographic", o.build())
        }
    };
    Ok(out.build())
}

pub(super) fn light(
    i: usize,
    l: &PunctualLight,
    shape: Option<&SpectrumShape>,
    used: &mut Extensions,
) -> Result<Value, ExportError> {
    let el = format!("light {i}");
    let (kind, value, range) = match *l {
        PunctualLight::Point { intensity, range } => ("point", intensity, range),
        PunctualLight::Spot {
            intensity, range, ..
        } => ("spot", intensity, range),
        PunctualLight::Directional { illuminance } => ("directional", illuminance, None),
    };
    finite(&el, "intensity", &value.to_array())?;
    if value.min_element() < 0.0 {
        return Err(invalid(&el, format!("intensity {value} is negative")));
    }
    let (color, intensity) = split_scale(value).ok_or_else(|| {
        invalid(
            &el,
            format!("intensity {value} has no exact colour × intensity"),
        )
    })?;
    let mut out = Obj::default()
        .with("type", kind)
        .with("color", nums(&color.to_array()))
        .with("intensity", num(intensity));
    if let Some(r) = range {
        if !(r > 0.0 && r.is_finite()) {
            return Err(invalid(&el, format!("range {r} is not positive")));
        }
        out = out.with("range", num(r));
    }
    if let PunctualLight::Spot {
        inner_cone,
        outer_cone,
        ..
    } = *l
    {
        // The loader clamps the cones to 0 <= inner <= outer <= π/2 (outer at least 1e-4).
        let outer = outer_cone.clamp(1e-4, std::f32::consts::FRAC_PI_2);
        if (outer, inner_cone.clamp(0.0, outer)) != (outer_cone, inner_cone) {
            return Err(invalid(
                &el,
                format!(
                    "cone angles ({inner_cone}, {outer_cone}) are not 0 <= inner <= outer <= π/2"
                ),
            ));
        }
        out = out.with(
            "spot",
            Obj::default()
                .with("innerConeAngle", num(inner_cone))
                .with("outerConeAngle", num(outer_cone))
                .build(),
        );
    }
    if let Some(shape) = shape {
        used.light_spectra = true;
        out = out.with(
            "extensions",
            Obj::default()
                .with(LIGHTS_SPECTRUM, spectrum(&el, shape)?)
                .build(),
        );
    }
    Ok(out.build())
}
