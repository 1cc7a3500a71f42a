//! A [`Scene`] into a self-contained glTF 2.0 binary (GLB), the inverse of
//! [`crate::loader`]: what [`scene_to_glb`] writes, [`crate::loader::load_glb`] reads back
//! into the same scene. The farm accepts scenes only as GLB uploads, so scenes authored in
//! code (the built-in demo) travel this way.
//!
//! What is written: the node graph (TRS or matrix), the default scene, meshes (triangle
//! lists with POSITION, NORMAL, TANGENT, TEXCOORD_0/1, COLOR_0, u32 indices, morph targets),
//! PBR metallic-roughness materials with KHR_materials_emissive_strength, _ior, _specular,
//! _transmission, _volume, _clearcoat, _sheen and _unlit, cameras, KHR_lights_punctual
//! lights, and animations (every channel with its own sampler). Each value is written so that the loader's arithmetic gives it back
//! bit for bit: emission and light values are split into a factor and a strength whose
//! product is exact, and every JSON number is checked to parse back to its f32.
//!
//! What is refused, with an [`ExportError`] naming the element: textures, skins, an
//! environment that emits light, and values the loader would read back differently (a
//! factor it clamps, a normal it repairs, keys at equal times it merges, ...). Never a
//! silently different scene, with these documented exceptions:
//! - Node transforms are f64 in a [`Scene`] and f32 in glTF: they are rounded to the
//!   nearest f32 (and the loader renormalises rotations in f64).
//! - The loader renormalises vertex normals and tangents, so normals that were not unit to
//!   the last bit come back a few ulps apart.
//!
//! glTF has no environment light. A black or constant one travels in the scene's extras as
//! `{"tessera": {"environment": [r, g, b]}}`, which the loader reads back (other glTF
//! readers ignore it); an environment map is refused.

use glam::{DMat4, DQuat, DVec3, Vec3, Vec4};
use gltf::json::Value;

use crate::animation::{Animation, Interpolation, Target};
use crate::camera::Projection;
use crate::light::{Environment, PunctualLight};
use crate::loader::write_glb;
use crate::material::{AlphaMode, Material};
use crate::scene::{CameraDef, Mesh, Node, Primitive, Scene};

/// Why a scene cannot be written as GLB. `element` names the part of the scene at fault
/// ("material 3 'glass'", "mesh 0 'walls', primitive 2", "the scene's environment").
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ExportError {
    /// The scene uses something this exporter does not write (textures, skins, a lit
    /// environment).
    #[error("{element}: {what} cannot be exported: {why}")]
    Unsupported {
        /// The element at fault.
        element: String,
        /// What it uses.
        what: String,
        /// Why that is not written.
        why: String,
    },
    /// A value glTF cannot hold, or one the loader would read back as something else.
    #[error("{element}: {problem}")]
    Invalid {
        /// The element at fault.
        element: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The GLB would exceed the 4 GiB its 32-bit lengths can describe.
    #[error("the GLB would be {0} bytes; GLB lengths are 32-bit")]
    TooLarge(u64),
}

fn invalid(element: &str, problem: impl Into<String>) -> ExportError {
    ExportError::Invalid {
        element: element.to_owned(),
        problem: problem.into(),
    }
}

fn unsupported(element: &str, what: impl Into<String>, why: &str) -> ExportError {
    ExportError::Unsupported {
        element: element.to_owned(),
        what: what.into(),
        why: why.to_owned(),
    }
}

/// "material 3 'glass'", or "material 3" without a name.
fn label(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(n) => format!("{kind} {index} '{n}'"),
        None => format!("{kind} {index}"),
    }
}

/// Writes `scene` as a self-contained GLB: one JSON chunk and one BIN chunk holding every
/// buffer view, as the glTF 2.0 spec lays them out (chunks padded to 4 bytes).
pub fn scene_to_glb(scene: &Scene) -> Result<Vec<u8>, ExportError> {
    refuse_unsupported(scene)?;
    let mut bin = Bin::default();
    let mut used = Extensions::default();

    let materials = scene
        .materials
        .iter()
        .enumerate()
        .map(|(i, m)| material(i, m, &mut used))
        .collect::<Result<Vec<_>, _>>()?;
    let meshes = scene
        .meshes
        .iter()
        .enumerate()
        .map(|(i, m)| mesh(i, m, scene.materials.len(), &mut bin))
        .collect::<Result<Vec<_>, _>>()?;
    let nodes = scene
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| node(i, n, scene, &mut bin, &mut used))
        .collect::<Result<Vec<_>, _>>()?;
    let cameras = scene
        .cameras
        .iter()
        .enumerate()
        .map(|(i, c)| camera(i, c))
        .collect::<Result<Vec<_>, _>>()?;
    let lights = scene
        .lights
        .iter()
        .enumerate()
        .map(|(i, l)| light(i, l))
        .collect::<Result<Vec<_>, _>>()?;
    let animations = scene
        .animations
        .iter()
        .enumerate()
        .map(|(i, a)| animation(i, a, scene, &mut bin))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(&bad) = scene
        .roots
        .iter()
        .find(|&&r| r as usize >= scene.nodes.len())
    {
        return Err(invalid(
            "the default scene",
            format!(
                "root node {bad} out of range for {} nodes",
                scene.nodes.len()
            ),
        ));
    }

    let mut root = Obj::default()
        .with(
            "asset",
            Obj::default()
                .with("version", "2.0")
                .with("generator", "Tessera tracer::export")
                .build(),
        )
        .with("scene", 0)
        .with("scenes", vec![default_scene(scene)])
        .nonempty("nodes", nodes)
        .nonempty("meshes", meshes)
        .nonempty("materials", materials)
        .nonempty("cameras", cameras)
        .nonempty("animations", animations);
    if !lights.is_empty() {
        used.lights = true;
        root = root.with(
            "extensions",
            Obj::default()
                .with(
                    "KHR_lights_punctual",
                    Obj::default().with("lights", lights).build(),
                )
                .build(),
        );
    }
    root = root.nonempty("extensionsUsed", used.names());
    if !bin.bytes.is_empty() {
        root = root
            .with(
                "buffers",
                vec![Obj::default().with("byteLength", bin.bytes.len()).build()],
            )
            .with("bufferViews", std::mem::take(&mut bin.views))
            .with("accessors", std::mem::take(&mut bin.accessors));
    }
    let json = gltf::json::serialize::to_vec(&root.build())
        .expect("a JSON value of finite numbers serialises");
    let bin = (!bin.bytes.is_empty()).then_some(&bin.bytes[..]);
    write_glb(&json, bin)
        .ok_or_else(|| ExportError::TooLarge((json.len() + bin.map_or(0, <[u8]>::len)) as u64))
}

/// The one glTF scene: the root nodes, and a black or constant environment in the extras
/// the loader reads back (see [`crate::loader`]'s `tessera_extras`).
fn default_scene(scene: &Scene) -> Value {
    let radiance = match &scene.environment {
        Some(Environment::Black) => Some(Vec3::ZERO),
        Some(Environment::Constant(c)) => Some(*c),
        Some(Environment::Map(_)) | None => None,
    };
    let mut obj = Obj::default().with("nodes", scene.roots.clone());
    if let Some(c) = radiance {
        let tessera = Obj::default()
            .with("environment", nums(&c.to_array()))
            .build();
        obj = obj.with("extras", Obj::default().with("tessera", tessera).build());
    }
    obj.build()
}

// ---------------------------------------------------------------------------------------
// JSON and binary building blocks

/// A JSON object under construction.
#[derive(Default)]
struct Obj(Vec<(String, Value)>);

impl Obj {
    fn with(mut self, key: &str, value: impl Into<Value>) -> Self {
        self.0.push((key.to_owned(), value.into()));
        self
    }

    /// Adds `key` only when `values` is not empty (glTF arrays must not be empty).
    fn nonempty(self, key: &str, values: Vec<impl Into<Value>>) -> Self {
        if values.is_empty() {
            self
        } else {
            self.with(key, values)
        }
    }

    fn build(self) -> Value {
        Value::Object(self.0.into_iter().collect())
    }
}

/// `v` as a JSON number that the loader's parser (serde_json, reading f32 through f64)
/// gives back bit for bit: the shortest decimal when that holds, else the exact value of
/// the f32 as an f64, which always does. `v` must be finite.
fn num(v: f32) -> Value {
    debug_assert!(v.is_finite(), "callers check finiteness first");
    let short = Value::from(v.to_string().parse::<f64>().unwrap_or(v as f64));
    let reads_back = gltf::json::serialize::to_string(&short)
        .ok()
        .and_then(|s| gltf::json::deserialize::from_str::<f32>(&s).ok())
        .is_some_and(|r| r.to_bits() == v.to_bits());
    if reads_back {
        short
    } else {
        Value::from(v as f64)
    }
}

fn nums(v: &[f32]) -> Value {
    Value::Array(v.iter().map(|&x| num(x)).collect())
}

/// Refuses non-finite values, naming them.
fn finite(element: &str, name: &str, values: &[f32]) -> Result<(), ExportError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(invalid(element, format!("{name} {values:?} is not finite")))
    }
}

/// The glTF extensions the document uses.
#[derive(Default)]
struct Extensions {
    gpu_instancing: bool,
    lights: bool,
    emissive_strength: bool,
    ior: bool,
    specular: bool,
    transmission: bool,
    unlit: bool,
    clearcoat: bool,
    sheen: bool,
    volume: bool,
    iridescence: bool,
    metamaterial: bool,
    diffuse_transmission: bool,
    anisotropy: bool,
}

impl Extensions {
    fn names(&self) -> Vec<&'static str> {
        [
            (self.gpu_instancing, INSTANCING),
            (self.lights, "KHR_lights_punctual"),
            (self.emissive_strength, "KHR_materials_emissive_strength"),
            (self.ior, "KHR_materials_ior"),
            (self.specular, "KHR_materials_specular"),
            (self.transmission, "KHR_materials_transmission"),
            (self.unlit, "KHR_materials_unlit"),
            (self.clearcoat, "KHR_materials_clearcoat"),
            (self.sheen, "KHR_materials_sheen"),
            (self.volume, "KHR_materials_volume"),
            (self.iridescence, "KHR_materials_iridescence"),
            (self.metamaterial, crate::loader::METAMATERIAL),
            (
                self.diffuse_transmission,
                "KHR_materials_diffuse_transmission",
            ),
            (self.anisotropy, "KHR_materials_anisotropy"),
        ]
        .iter()
        .filter(|(on, _)| *on)
        .map(|(_, n)| *n)
        .collect()
    }
}

/// The BIN chunk with its buffer views and accessors: every view 4-byte aligned and
/// tightly packed, one per accessor.
#[derive(Default)]
struct Bin {
    bytes: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

impl Bin {
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        self.bytes.resize(self.bytes.len().next_multiple_of(4), 0);
        let mut view = Obj::default()
            .with("buffer", 0)
            .with("byteOffset", self.bytes.len())
            .with("byteLength", bytes.len());
        if let Some(t) = target {
            view = view.with("target", t);
        }
        self.views.push(view.build());
        self.bytes.extend_from_slice(bytes);
        self.views.len() - 1
    }

    /// A float accessor of `components` per element (SCALAR, VEC2, VEC3 or VEC4), with
    /// `min` and `max` when `bounds` (the spec wants them on POSITION and animation
    /// inputs). The values must be finite.
    fn floats(
        &mut self,
        values: &[f32],
        components: usize,
        bounds: bool,
        target: Option<u32>,
    ) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, target);
        let ty = match components {
            1 => "SCALAR",
            2 => "VEC2",
            3 => "VEC3",
            _ => "VEC4",
        };
        let mut acc = Obj::default()
            .with("bufferView", view)
            .with("componentType", FLOAT)
            .with("type", ty)
            .with("count", values.len() / components);
        if bounds {
            let mut min = vec![f32::INFINITY; components];
            let mut max = vec![f32::NEG_INFINITY; components];
            for element in values.chunks_exact(components) {
                for (c, &v) in element.iter().enumerate() {
                    min[c] = min[c].min(v);
                    max[c] = max[c].max(v);
                }
            }
            acc = acc.with("min", nums(&min)).with("max", nums(&max));
        }
        self.accessors.push(acc.build());
        self.accessors.len() - 1
    }

    fn indices(&mut self, indices: &[[u32; 3]]) -> usize {
        let bytes: Vec<u8> = indices
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        let view = self.view(&bytes, Some(ELEMENT_ARRAY_BUFFER));
        self.accessors.push(
            Obj::default()
                .with("bufferView", view)
                .with("componentType", UNSIGNED_INT)
                .with("type", "SCALAR")
                .with("count", indices.len() * 3)
                .build(),
        );
        self.accessors.len() - 1
    }
}

// ---------------------------------------------------------------------------------------
// What is not written

const NO_TEXTURES: &str = "the exporter does not write images";
const NO_SKINS: &str = "the exporter does not write skins";

fn refuse_unsupported(scene: &Scene) -> Result<(), ExportError> {
    for (i, m) in scene.materials.iter().enumerate() {
        let slots = [
            ("baseColorTexture", &m.base_color_texture),
            ("metallicRoughnessTexture", &m.metallic_roughness_texture),
            ("normalTexture", &m.normal_texture),
            ("emissiveTexture", &m.emissive_texture),
            ("specularTexture", &m.specular_texture),
            ("specularColorTexture", &m.specular_color_texture),
            ("transmissionTexture", &m.transmission_texture),
            ("thicknessTexture", &m.thickness_texture),
            ("iridescenceTexture", &m.iridescence_texture),
            (
                "diffuseTransmissionTexture",
                &m.diffuse_transmission_texture,
            ),
            (
                "diffuseTransmissionColorTexture",
                &m.diffuse_transmission_color_texture,
            ),
            (
                "iridescenceThicknessTexture",
                &m.iridescence_thickness_texture,
            ),
            ("clearcoatTexture", &m.clearcoat_texture),
            ("clearcoatRoughnessTexture", &m.clearcoat_roughness_texture),
            ("clearcoatNormalTexture", &m.clearcoat_normal_texture),
            ("sheenColorTexture", &m.sheen_color_texture),
            ("sheenRoughnessTexture", &m.sheen_roughness_texture),
            ("anisotropyTexture", &m.anisotropy_texture),
        ];
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

// ---------------------------------------------------------------------------------------
// Materials, cameras, lights

/// `value` (non-negative, finite) as `factor × scale` with every factor component in
/// [0, 1] and the product exact in f32, as the loader computes it: the largest component as
/// the scale when that is exact, else the next power of two, whose division is exact.
fn split_scale(value: Vec3) -> Option<(Vec3, f32)> {
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

fn material(i: usize, m: &Material, used: &mut Extensions) -> Result<Value, ExportError> {
    let el = label("material", i, m.name.as_deref());
    let cutoff = match m.alpha_mode {
        AlphaMode::Mask { cutoff } => cutoff,
        _ => 0.5,
    };
    let factors: [(&str, &[f32]); 16] = [
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
    let non_negative: [(&str, &[f32]); 7] = [
        ("emissive", &m.emissive.to_array()),
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
    if !ext.0.is_empty() {
        out = out.with("extensions", ext.build());
    }
    Ok(out.build())
}

fn camera(i: usize, c: &CameraDef) -> Result<Value, ExportError> {
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

fn light(i: usize, l: &PunctualLight) -> Result<Value, ExportError> {
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
    Ok(out.build())
}

// ---------------------------------------------------------------------------------------
// Nodes

fn node(
    i: usize,
    n: &Node,
    scene: &Scene,
    bin: &mut Bin,
    used: &mut Extensions,
) -> Result<Value, ExportError> {
    let el = label("node", i, n.name.as_deref());
    let in_range = |what: &str, index: Option<u32>, len: usize, all: &str| match index {
        Some(x) if x as usize >= len => Err(invalid(
            &el,
            format!("{what} {x} out of range for {len} {all}"),
        )),
        _ => Ok(()),
    };
    in_range("mesh", n.mesh, scene.meshes.len(), "meshes")?;
    in_range("camera", n.camera, scene.cameras.len(), "cameras")?;
    in_range("light", n.light, scene.lights.len(), "lights")?;
    for &c in &n.children {
        in_range("child node", Some(c), scene.nodes.len(), "nodes")?;
    }

    let mut out = Obj::default();
    if let Some(name) = &n.name {
        out = out.with("name", name.as_str());
    }
    out = out.nonempty("children", n.children.clone());
    match n.trs {
        Some(trs) => {
            // The loader rebuilds `local` from the TRS: they must agree.
            if trs.matrix() != n.local {
                return Err(invalid(
                    &el,
                    "its matrix is not the product of its translation, rotation and scale",
                ));
            }
            let t = trs.translation.as_vec3().to_array();
            let r = trs.rotation.as_quat().to_array();
            let s = trs.scale.as_vec3().to_array();
            finite(&el, "translation", &t)?;
            finite(&el, "rotation", &r)?;
            finite(&el, "scale", &s)?;
            if r == [0.0; 4] {
                return Err(invalid(&el, "rotation is a zero quaternion"));
            }
            if trs.translation != DVec3::ZERO {
                out = out.with("translation", nums(&t));
            }
            if trs.rotation != DQuat::IDENTITY {
                out = out.with("rotation", nums(&r));
            }
            if trs.scale != DVec3::ONE {
                out = out.with("scale", nums(&s));
            }
        }
        // Even an identity matrix is written: without one the loader sees a TRS node.
        None => {
            let m = n.local.as_mat4().to_cols_array();
            finite(&el, "matrix", &m)?;
            out = out.with("matrix", nums(&m));
        }
    }
    if let Some(m) = n.mesh {
        out = out.with("mesh", m);
    }
    if let Some(c) = n.camera {
        out = out.with("camera", c);
    }
    let mut extensions = Obj::default();
    if let Some(l) = n.light {
        extensions = extensions.with(
            "KHR_lights_punctual",
            Obj::default().with("light", l).build(),
        );
    }
    if !n.gpu_instances.is_empty() {
        if n.mesh.is_none() {
            return Err(invalid(&el, "GPU instances without a mesh"));
        }
        used.gpu_instancing = true;
        extensions = extensions.with(INSTANCING, gpu_instances(&el, &n.gpu_instances, bin)?);
    }
    if !extensions.0.is_empty() {
        out = out.with("extensions", extensions.build());
    }
    if let Some(w) = &n.weights {
        let targets = n.mesh.map_or(0, |m| scene.meshes[m as usize].weights.len());
        // The loader cuts, pads or drops weights that do not match the mesh.
        if w.len() != targets {
            return Err(invalid(
                &el,
                format!("{} morph weights for {targets} morph targets", w.len()),
            ));
        }
        finite(&el, "morph weights", w)?;
        out = out.with("weights", nums(w));
    }
    Ok(out.build())
}

// ---------------------------------------------------------------------------------------
// Meshes

const INSTANCING: &str = "EXT_mesh_gpu_instancing";

/// EXT_mesh_gpu_instancing's TRANSLATION, ROTATION and SCALE accessors for `instances`,
/// each decomposed as the loader composes it.
fn gpu_instances(el: &str, instances: &[DMat4], bin: &mut Bin) -> Result<Value, ExportError> {
    let (mut t, mut r, mut s) = (Vec::new(), Vec::new(), Vec::new());
    for m in instances {
        let (scale, rotation, translation) = m.to_scale_rotation_translation();
        t.extend(translation.as_vec3().to_array());
        r.extend(rotation.normalize().as_quat().to_array());
        s.extend(scale.as_vec3().to_array());
    }
    finite(el, "GPU instance translations", &t)?;
    finite(el, "GPU instance rotations", &r)?;
    finite(el, "GPU instance scales", &s)?;
    Ok(Obj::default()
        .with(
            "attributes",
            Obj::default()
                .with("TRANSLATION", bin.floats(&t, 3, false, None))
                .with("ROTATION", bin.floats(&r, 4, false, None))
                .with("SCALE", bin.floats(&s, 3, false, None))
                .build(),
        )
        .build())
}

fn mesh(i: usize, m: &Mesh, materials: usize, bin: &mut Bin) -> Result<Value, ExportError> {
    let label = label("mesh", i, m.name.as_deref());
    let mut primitives = Vec::with_capacity(m.primitives.len());
    for (p, prim) in m.primitives.iter().enumerate() {
        let el = format!("{label}, primitive {p}");
        // glTF gives every primitive of a mesh the mesh's morph targets.
        if prim.targets.len() != m.weights.len() {
            return Err(invalid(
                &el,
                format!(
                    "{} morph targets, but the mesh has {} default weights",
                    prim.targets.len(),
                    m.weights.len()
                ),
            ));
        }
        primitives.push(primitive(&el, prim, materials, bin)?);
    }
    let mut out = Obj::default().with("primitives", primitives);
    if let Some(name) = &m.name {
        out = out.with("name", name.as_str());
    }
    if !m.weights.is_empty() {
        finite(&label, "default morph weights", &m.weights)?;
        out = out.with("weights", nums(&m.weights));
    }
    Ok(out.build())
}

/// Checks that a per-vertex attribute has one entry per vertex (or none) and is finite.
fn per_vertex(
    el: &str,
    name: &str,
    values: &[f32],
    len: usize,
    n: usize,
) -> Result<(), ExportError> {
    if len != 0 && len != n {
        return Err(invalid(
            el,
            format!("{name} has {len} entries for {n} vertices"),
        ));
    }
    if let Some(bad) = values.iter().position(|v| !v.is_finite()) {
        let width = values.len() / len.max(1);
        return Err(invalid(
            el,
            format!("{name} of vertex {} is not finite", bad / width.max(1)),
        ));
    }
    Ok(())
}

fn flat3(v: &[Vec3]) -> Vec<f32> {
    v.iter().flat_map(|x| x.to_array()).collect()
}

fn flat4(v: &[Vec4]) -> Vec<f32> {
    v.iter().flat_map(|x| x.to_array()).collect()
}

fn primitive(
    el: &str,
    prim: &Primitive,
    materials: usize,
    bin: &mut Bin,
) -> Result<Value, ExportError> {
    let n = prim.positions.len();
    if prim.indices.is_empty() {
        return Err(invalid(
            el,
            "has no triangles; glTF accessors cannot be empty",
        ));
    }
    if let Some(bad) = prim.indices.iter().flatten().find(|&&v| v as usize >= n) {
        return Err(invalid(
            el,
            format!("index {bad} out of range for {n} vertices"),
        ));
    }
    if prim.material as usize >= materials {
        return Err(invalid(
            el,
            format!(
                "material {} out of range for {materials} materials",
                prim.material
            ),
        ));
    }
    let positions = flat3(&prim.positions);
    let normals = flat3(&prim.normals);
    let tangents = flat4(&prim.tangents);
    let uvs = prim
        .uvs
        .each_ref()
        .map(|set| set.iter().flat_map(|x| x.to_array()).collect::<Vec<f32>>());
    let colors = flat4(&prim.colors);
    per_vertex(el, "POSITION", &positions, n, n)?;
    per_vertex(el, "NORMAL", &normals, prim.normals.len(), n)?;
    per_vertex(el, "TANGENT", &tangents, prim.tangents.len(), n)?;
    per_vertex(el, "TEXCOORD_0", &uvs[0], prim.uvs[0].len(), n)?;
    per_vertex(el, "TEXCOORD_1", &uvs[1], prim.uvs[1].len(), n)?;
    per_vertex(el, "COLOR_0", &colors, prim.colors.len(), n)?;
    // The loader repairs zero normals, drops tangents without normals and regenerates
    // degenerate ones, and reads only the sign of w.
    if let Some(v) = prim.normals.iter().position(|v| *v == Vec3::ZERO) {
        return Err(invalid(el, format!("the normal of vertex {v} is zero")));
    }
    if !prim.tangents.is_empty() {
        if prim.normals.is_empty() {
            return Err(invalid(
                el,
                "has tangents but no normals, which glTF ignores",
            ));
        }
        if let Some(v) = prim
            .tangents
            .iter()
            .position(|t| t.truncate() == Vec3::ZERO || t.w.abs() != 1.0)
        {
            return Err(invalid(
                el,
                format!(
                    "the tangent of vertex {v} ({}) is zero or its w is not ±1",
                    prim.tangents[v]
                ),
            ));
        }
    }

    let mut attributes = Obj::default().with(
        "POSITION",
        bin.floats(&positions, 3, true, Some(ARRAY_BUFFER)),
    );
    let optional = [
        ("NORMAL", &normals, 3),
        ("TANGENT", &tangents, 4),
        ("TEXCOORD_0", &uvs[0], 2),
        ("TEXCOORD_1", &uvs[1], 2),
        ("COLOR_0", &colors, 4),
    ];
    for (name, values, width) in optional {
        if !values.is_empty() {
            attributes =
                attributes.with(name, bin.floats(values, width, false, Some(ARRAY_BUFFER)));
        }
    }
    let mut targets = Vec::with_capacity(prim.targets.len());
    for (t, target) in prim.targets.iter().enumerate() {
        let what = format!("morph target {t}");
        let displacements = [
            ("POSITION", flat3(&target.positions), target.positions.len()),
            ("NORMAL", flat3(&target.normals), target.normals.len()),
            ("TANGENT", flat3(&target.tangents), target.tangents.len()),
        ];
        let mut out = Obj::default();
        for (name, values, len) in displacements {
            per_vertex(el, &format!("{what} {name}"), &values, len, n)?;
            if len == 0 {
                continue;
            }
            // The loader drops displacements of normals or tangents it generates.
            let base_missing = match name {
                "NORMAL" => prim.normals.is_empty(),
                "TANGENT" => prim.tangents.is_empty(),
                _ => false,
            };
            if base_missing {
                return Err(invalid(
                    el,
                    format!("{what} displaces {name}, which the primitive lacks"),
                ));
            }
            out = out.with(
                name,
                bin.floats(&values, 3, name == "POSITION", Some(ARRAY_BUFFER)),
            );
        }
        targets.push(out.build());
    }

    Ok(Obj::default()
        .with("attributes", attributes.build())
        .with("indices", bin.indices(&prim.indices))
        .with("material", prim.material)
        .nonempty("targets", targets)
        .build())
}

// ---------------------------------------------------------------------------------------
// Animations

fn animation(i: usize, a: &Animation, scene: &Scene, bin: &mut Bin) -> Result<Value, ExportError> {
    let label = label("animation", i, a.name.as_deref());
    let mut channels = Vec::with_capacity(a.channels.len());
    let mut samplers = Vec::with_capacity(a.channels.len());
    for (c, ch) in a.channels.iter().enumerate() {
        let el = format!("{label}, channel {c}");
        let Some(node) = scene.nodes.get(ch.node as usize) else {
            return Err(invalid(
                &el,
                format!(
                    "node {} out of range for {} nodes",
                    ch.node,
                    scene.nodes.len()
                ),
            ));
        };
        if node.trs.is_none() {
            return Err(invalid(
                &el,
                format!(
                    "animates node {}, which has a matrix; glTF animates only translation, \
                     rotation and scale",
                    ch.node
                ),
            ));
        }
        let (path, width) = match ch.target {
            Target::Translation => ("translation", 3),
            Target::Rotation => ("rotation", 4),
            Target::Scale => ("scale", 3),
            Target::Weights => (
                "weights",
                node.mesh
                    .and_then(|m| scene.meshes.get(m as usize))
                    .map_or(0, |m| m.weights.len()),
            ),
        };
        let s = &ch.sampler;
        if width == 0 {
            return Err(invalid(
                &el,
                format!(
                    "animates the morph weights of node {}, whose mesh has no morph targets",
                    ch.node
                ),
            ));
        }
        if s.width != width {
            return Err(invalid(
                &el,
                format!(
                    "its sampler has {} values per element, but {path} needs {width}",
                    s.width
                ),
            ));
        }
        if s.times.is_empty() {
            return Err(invalid(&el, "its sampler has no keys"));
        }
        finite(&el, "key times", &s.times)?;
        // The loader refuses decreasing times and merges equal ones.
        if let Some(k) = (1..s.times.len()).find(|&k| !(s.times[k] > s.times[k - 1])) {
            return Err(invalid(
                &el,
                format!(
                    "key time {k} ({}) does not come after key time {} ({})",
                    s.times[k],
                    k - 1,
                    s.times[k - 1]
                ),
            ));
        }
        let per_key = match s.interpolation {
            Interpolation::CubicSpline => 3,
            _ => 1,
        };
        let need = s.times.len() * per_key * width;
        if s.values.len() != need {
            return Err(invalid(
                &el,
                format!(
                    "{} values, but {} keys of {path} need {need}",
                    s.values.len(),
                    s.times.len()
                ),
            ));
        }
        finite(&el, "values", &s.values)?;

        let input = bin.floats(&s.times, 1, true, None);
        let components = if ch.target == Target::Weights {
            1
        } else {
            width
        };
        let output = bin.floats(&s.values, components, false, None);
        let interpolation = match s.interpolation {
            Interpolation::Step => "STEP",
            Interpolation::Linear => "LINEAR",
            Interpolation::CubicSpline => "CUBICSPLINE",
        };
        samplers.push(
            Obj::default()
                .with("input", input)
                .with("output", output)
                .with("interpolation", interpolation)
                .build(),
        );
        channels.push(
            Obj::default()
                .with("sampler", c)
                .with(
                    "target",
                    Obj::default()
                        .with("node", ch.node)
                        .with("path", path)
                        .build(),
                )
                .build(),
        );
    }
    let mut out = Obj::default()
        .with("channels", channels)
        .with("samplers", samplers);
    if let Some(name) = &a.name {
        out = out.with("name", name.as_str());
    }
    Ok(out.build())
}
