//! TESSERA_lights_spectrum (`docs/TESSERA_lights_spectrum.md`): a spectrum described in
//! JSON as a blackbody temperature, a Gaussian peak, or a table of (nm, value) pairs; and
//! TESSERA_materials_fluorescence (`docs/TESSERA_materials_fluorescence.md`), a paint of
//! two such spectra.

use gltf::json::Value;

use super::error::{Element, SceneError};
use super::{FLUORESCENCE, LIGHTS_SPECTRUM};
use crate::spectrum::{DenseSpectrum, FluorescenceDef, SpectrumShape, LAMBDA_MAX, LAMBDA_MIN};

/// The spectrum of `ext`, the extension's object on `element`; `what` names the object
/// in errors (for example "TESSERA_lights_spectrum").
pub(crate) fn spectrum(
    ext: &Value,
    element: Element,
    what: &str,
) -> Result<SpectrumShape, SceneError> {
    let fail = |why: String| SceneError::at(element, format!("{what}: {why}"));
    let Some(object) = ext.as_object() else {
        return Err(fail(format!("{ext} is not an object")));
    };
    let keys: Vec<&str> = ["blackbody", "gaussian", "table"]
        .into_iter()
        .filter(|k| object.contains_key(*k))
        .collect();
    let [key] = keys[..] else {
        return Err(fail(format!(
            "needs exactly one of \"blackbody\", \"gaussian\" and \"table\", has {keys:?}"
        )));
    };
    let number = |v: &Value, name: &str| {
        v.as_f64()
            .map(|x| x as f32)
            .ok_or_else(|| fail(format!("{name} {v} is not a number")))
    };
    let value = &object[key];
    let shape = match key {
        "blackbody" => SpectrumShape::Blackbody(number(value, "blackbody temperature")?),
        "gaussian" => SpectrumShape::Gaussian {
            peak: number(&value["peak"], "Gaussian peak")?,
            width: number(&value["width"], "Gaussian width")?,
        },
        _ => {
            let Some(rows) = value.as_array() else {
                return Err(fail(format!("table {value} is not an array")));
            };
            if rows.len() > crate::spectrum::MAX_TABLE_ENTRIES {
                return Err(fail(format!(
                    "a table of {} entries: at most {} are read",
                    rows.len(),
                    crate::spectrum::MAX_TABLE_ENTRIES
                )));
            }
            let pair = |row: &Value| match row.as_array().map(Vec::as_slice) {
                Some([nm, v]) => Ok((number(nm, "table wavelength")?, number(v, "table value")?)),
                _ => Err(fail(format!("table entry {row} is not [nm, value]"))),
            };
            SpectrumShape::Table(rows.iter().map(pair).collect::<Result<_, _>>()?)
        }
    };
    shape.check().map_err(fail)?;
    Ok(shape)
}

/// TESSERA_lights_spectrum of the JSON object `json` (a light or a material), if it has one.
pub(crate) fn extension(
    json: &Value,
    element: Element,
) -> Result<Option<SpectrumShape>, SceneError> {
    match json["extensions"].get(LIGHTS_SPECTRUM) {
        None => Ok(None),
        Some(ext) => {
            let shape = spectrum(ext, element, LIGHTS_SPECTRUM)?;
            if DenseSpectrum::light(&shape).is_none() {
                return Err(SceneError::at(
                    element,
                    format!(
                        "{LIGHTS_SPECTRUM}: {shape:?} has no power in {LAMBDA_MIN}–{LAMBDA_MAX} nm, \
                         the band the renderer carries"
                    ),
                ));
            }
            Ok(Some(shape))
        }
    }
}

/// TESSERA_materials_fluorescence of the material `json`, if it has it.
pub(crate) fn fluorescence(
    json: &Value,
    element: Element,
) -> Result<Option<FluorescenceDef>, SceneError> {
    let Some(ext) = json["extensions"].get(FLUORESCENCE) else {
        return Ok(None);
    };
    let fail = |why: String| SceneError::at(element, format!("{FLUORESCENCE}: {why}"));
    if !ext.is_object() {
        return Err(fail(format!("{ext} is not an object")));
    }
    let shape = |key: &str| match ext.get(key) {
        None => Err(fail(format!("needs \"{key}\", a spectrum"))),
        Some(v) => spectrum(v, element, &format!("{FLUORESCENCE} {key}")),
    };
    let number = |key: &str| match &ext[key] {
        Value::Null => Ok(1.0),
        v => v
            .as_f64()
            .map(|x| x as f32)
            .ok_or_else(|| fail(format!("{key} {v} is not a number"))),
    };
    let def = FluorescenceDef {
        excitation: shape("excitation")?,
        emission: shape("emission")?,
        concentration: number("concentration")?,
        quantum_yield: number("quantumYield")?,
    };
    def.check().map_err(fail)?;
    Ok(Some(def))
}
