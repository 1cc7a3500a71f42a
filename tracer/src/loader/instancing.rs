//! EXT_mesh_gpu_instancing: a node draws its mesh once per row of its TRANSLATION,
//! ROTATION and SCALE accessors. The rows become transforms of the node
//! ([`crate::scene::Node::gpu_instances`]), and each draw becomes its own instance of the
//! frame's top-level BVH over the one mesh BVH: nothing is copied.

use std::borrow::Cow;

use glam::{DMat4, DQuat, DVec3};
use gltf::accessor::Dimensions;
use gltf::json::Value;

use super::accessor::read_floats;
use super::error::{Element, SceneError};
use super::gltf::UNIT_TOLERANCE;

/// The extension's name, as files list it.
pub(crate) const EXTENSION: &str = "EXT_mesh_gpu_instancing";

/// The instance transforms of node `index` (empty when it has no instancing), read from
/// the raw JSON since the `gltf` crate does not parse the extension.
pub(crate) fn gpu_instances(
    doc: &gltf::Document,
    raw: &Value,
    buffers: &[Cow<'_, [u8]>],
    index: usize,
    warnings: &mut Vec<String>,
) -> Result<Vec<DMat4>, SceneError> {
    let ext = &raw["nodes"][index]["extensions"][EXTENSION];
    if ext.is_null() {
        return Ok(Vec::new());
    }
    let element = Element::Node(index);
    let attributes = ext["attributes"]
        .as_object()
        .ok_or_else(|| SceneError::at(element, format!("{EXTENSION} has no 'attributes'")))?;
    if raw["nodes"][index]["mesh"].is_null() {
        warnings.push(format!(
            "{element}: {EXTENSION} on a node without a mesh; ignored"
        ));
        return Ok(Vec::new());
    }
    // TRS rows; application-specific attributes (names starting with '_') carry nothing
    // the tracer draws.
    let read = |name: &str, dims: Dimensions| -> Result<Option<Vec<f32>>, SceneError> {
        let Some(a) = attributes.get(name) else {
            return Ok(None);
        };
        let acc = a
            .as_u64()
            .and_then(|a| doc.accessors().nth(a as usize))
            .ok_or_else(|| {
                SceneError::at(
                    element,
                    format!("{EXTENSION} {name} names no accessor: {a}"),
                )
            })?;
        let what = format!("{EXTENSION} {name} of node {index}");
        Ok(Some(read_floats(&acc, buffers, &[dims], &what)?.values))
    };
    let translation = read("TRANSLATION", Dimensions::Vec3)?;
    let rotation = read("ROTATION", Dimensions::Vec4)?;
    let scale = read("SCALE", Dimensions::Vec3)?;
    let counts = [
        translation.as_ref().map(|v| v.len() / 3),
        rotation.as_ref().map(|v| v.len() / 4),
        scale.as_ref().map(|v| v.len() / 3),
    ];
    let mut present = counts.into_iter().flatten();
    let Some(count) = present.next() else {
        return Err(SceneError::at(
            element,
            format!("{EXTENSION} has none of TRANSLATION, ROTATION and SCALE"),
        ));
    };
    if present.any(|c| c != count) {
        return Err(SceneError::at(
            element,
            format!(
                "{EXTENSION} attributes differ in count: {counts:?} (TRANSLATION, ROTATION, SCALE)"
            ),
        ));
    }
    let mut out = Vec::with_capacity(count);
    let mut renormalised = 0usize;
    for i in 0..count {
        let t = translation.as_ref().map_or(DVec3::ZERO, |v| vec3(v, i));
        let s = scale.as_ref().map_or(DVec3::ONE, |v| vec3(v, i));
        let r = match &rotation {
            Some(v) => {
                let q = DQuat::from_xyzw(
                    v[4 * i] as f64,
                    v[4 * i + 1] as f64,
                    v[4 * i + 2] as f64,
                    v[4 * i + 3] as f64,
                );
                let len = q.length();
                if !(len.is_finite() && len > 0.0) {
                    return Err(SceneError::at(
                        element,
                        format!("{EXTENSION} ROTATION {i} is not a usable quaternion"),
                    ));
                }
                // Normalised integer rotations are never exactly unit: only warn past
                // what rounding explains.
                if (len - 1.0).abs() > UNIT_TOLERANCE {
                    renormalised += 1;
                }
                q / len
            }
            None => DQuat::IDENTITY,
        };
        let m = DMat4::from_scale_rotation_translation(s, r, t);
        if !m.is_finite() {
            return Err(SceneError::at(
                element,
                format!("{EXTENSION} instance {i} is not finite"),
            ));
        }
        out.push(m);
    }
    if renormalised > 0 {
        warnings.push(format!(
            "{element}: {renormalised} {EXTENSION} rotations are not unit quaternions; normalised"
        ));
    }
    Ok(out)
}

fn vec3(v: &[f32], i: usize) -> DVec3 {
    DVec3::new(v[3 * i] as f64, v[3 * i + 1] as f64, v[3 * i + 2] as f64)
}
