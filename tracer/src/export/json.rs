//! The JSON and binary building blocks of the exporter: objects built key by key, numbers
//! checked to read back as the same f32, the extensions a document uses, and the BIN
//! chunk with its views and accessors.

use super::*;

/// A JSON object under construction.
#[derive(Default)]
pub(super) struct Obj(pub(super) Vec<(String, Value)>);

impl Obj {
    pub(super) fn with(mut self, key: &str, value: impl Into<Value>) -> Self {
        self.0.push((key.to_owned(), value.into()));
        self
    }

    /// Adds `key` only when `values` is not empty (glTF arrays must not be empty).
    pub(super) fn nonempty(self, key: &str, values: Vec<impl Into<Value>>) -> Self {
        if values.is_empty() {
            self
        } else {
            self.with(key, values)
        }
    }

    pub(super) fn build(self) -> Value {
        Value::Object(self.0.into_iter().collect())
    }
}

/// `v` as a JSON number that the loader's parser (serde_json, reading f32 through f64)
/// gives back bit for bit: the shortest decimal when that holds, else the exact value of
/// the f32 as an f64, which always does. `v` must be finite.
pub(super) fn num(v: f32) -> Value {
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

pub(super) fn nums(v: &[f32]) -> Value {
    Value::Array(v.iter().map(|&x| num(x)).collect())
}

/// Refuses non-finite values, naming them.
pub(super) fn finite(element: &str, name: &str, values: &[f32]) -> Result<(), ExportError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(invalid(element, format!("{name} {values:?} is not finite")))
    }
}

/// The glTF extensions the document uses.
#[derive(Default)]
pub(super) struct Extensions {
    pub(super) gpu_instancing: bool,
    pub(super) lights: bool,
    pub(super) emissive_strength: bool,
    pub(super) ior: bool,
    pub(super) specular: bool,
    pub(super) transmission: bool,
    pub(super) unlit: bool,
    pub(super) clearcoat: bool,
    pub(super) sheen: bool,
    pub(super) volume: bool,
    pub(super) dispersion: bool,
    pub(super) iridescence: bool,
    pub(super) metamaterial: bool,
    pub(super) diffuse_transmission: bool,
    pub(super) anisotropy: bool,
    pub(super) light_spectra: bool,
    pub(super) fluorescence: bool,
    pub(super) animation_pointer: bool,
}

impl Extensions {
    pub(super) fn names(&self) -> Vec<&'static str> {
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
            (self.dispersion, "KHR_materials_dispersion"),
            (self.iridescence, "KHR_materials_iridescence"),
            (self.metamaterial, crate::loader::METAMATERIAL),
            (
                self.diffuse_transmission,
                "KHR_materials_diffuse_transmission",
            ),
            (self.anisotropy, "KHR_materials_anisotropy"),
            (self.light_spectra, crate::loader::LIGHTS_SPECTRUM),
            (self.fluorescence, crate::loader::FLUORESCENCE),
            (self.animation_pointer, "KHR_animation_pointer"),
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
pub(super) struct Bin {
    pub(super) bytes: Vec<u8>,
    pub(super) views: Vec<Value>,
    pub(super) accessors: Vec<Value>,
}

pub(super) const FLOAT: u32 = 5126;
pub(super) const UNSIGNED_INT: u32 = 5125;
pub(super) const ARRAY_BUFFER: u32 = 34962;
pub(super) const ELEMENT_ARRAY_BUFFER: u32 = 34963;

impl Bin {
    pub(super) fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
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
    pub(super) fn floats(
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

    pub(super) fn indices(&mut self, indices: &[[u32; 3]]) -> usize {
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
