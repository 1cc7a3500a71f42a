//! Skins and animations: joints and their inverse bind matrices; samplers read from their
//! accessors and checked against the node and property each channel drives.
//!
//! Choices a user of the loader should know:
//! - Key times must be finite and never decrease (an error naming the input accessor). Two
//!   keys at the same time, which the spec forbids too, are merged into the later one with
//!   a warning, so that [`Sampler::times`] is strictly increasing.
//! - Rotation keys must be unit quaternions, as node rotations are: one further from unit
//!   length than rounding explains is normalised (with its CUBICSPLINE tangents) with a
//!   warning, so that every interpolation renders the rotation the file meant.
//! - A channel that targets a node with a `matrix` is an error: the spec allows only
//!   translation, rotation and scale on animated nodes.
//! - KHR_animation_pointer channels (`"path": "pointer"`) are taken out before the
//!   document is parsed ([`strip_unsupported_channels`]) and read into
//!   [`crate::animation::PropertyChannel`]s where the pointer is one Tessera animates
//!   ([`pointer_target`]): a light's colour or intensity, a material's emissive factor or
//!   strength (each half multiplied by the other's value in the file; animating both
//!   halves of one is an error), base colour, metallic or roughness factor. Any other
//!   pointer, and a target without a node, is dropped with a warning.

use std::borrow::Cow;
use std::collections::HashMap;

use glam::{DMat4, Vec3};
use gltf::accessor::{DataType, Dimensions as D};
use gltf::animation::Property as NodeProperty;
use gltf::json::Value;

use super::accessor::read_floats;
use super::error::{Element, SceneError};
use super::gltf::UNIT_TOLERANCE;
use crate::animation::{
    Animation, Channel, Interpolation, Property, PropertyChannel, Sampler, Target,
};
use crate::scene::{Mesh, Node, Skin};

/// A KHR_animation_pointer channel, taken out of the untyped document (the typed parser
/// refuses `"path": "pointer"`) to be read once the document is parsed.
#[derive(Clone, Debug)]
pub(crate) struct PointerChannel {
    /// The animation and the channel's index in the file.
    pub animation: usize,
    pub channel: usize,
    /// The animation's sampler it uses.
    pub sampler: usize,
    /// The JSON pointer it animates.
    pub pointer: String,
}

/// Removes, from the untyped document, animation channels whose target is not one of
/// glTF's four node properties or has no node (KHR_animation_pointer writes
/// `"path": "pointer"` and no node, which the typed parser refuses outright). Gives the
/// pointer channels, for [`convert_animations`], and a warning for every other channel
/// removed, naming the animation and the channel's index in the file.
pub(crate) fn strip_unsupported_channels(raw: &mut Value) -> (Vec<PointerChannel>, Vec<String>) {
    let mut pointers = Vec::new();
    let mut warnings = Vec::new();
    let Some(anims) = raw.get_mut("animations").and_then(Value::as_array_mut) else {
        return (pointers, warnings);
    };
    for (a, anim) in anims.iter_mut().enumerate() {
        let Some(channels) = anim.get_mut("channels").and_then(Value::as_array_mut) else {
            continue;
        };
        let mut c = 0;
        channels.retain(|ch| {
            let target = ch.get("target");
            let path = target.and_then(|t| t.get("path")).and_then(Value::as_str);
            let has_node = target.and_then(|t| t.get("node")).is_some();
            let pointer = target
                .and_then(|t| t.get("extensions"))
                .and_then(|e| e.get("KHR_animation_pointer"))
                .and_then(|p| p.get("pointer"))
                .and_then(Value::as_str);
            let sampler = ch.get("sampler").and_then(Value::as_u64);
            let why = match path {
                // A malformed target stays, for the schema check to report.
                None => None,
                Some("translation" | "rotation" | "scale" | "weights") if has_node => None,
                Some(p @ ("translation" | "rotation" | "scale" | "weights")) => Some(format!(
                    "its '{p}' target names no node (an extension would define it)"
                )),
                Some("pointer") => match (pointer, sampler) {
                    (Some(pointer), Some(sampler)) => {
                        pointers.push(PointerChannel {
                            animation: a,
                            channel: c,
                            sampler: sampler as usize,
                            pointer: pointer.to_owned(),
                        });
                        Some(String::new())
                    }
                    _ => Some(
                        "target path 'pointer' without a KHR_animation_pointer pointer or a \
                         sampler"
                            .into(),
                    ),
                },
                Some(p) => Some(format!("target path '{p}' is not supported")),
            };
            if let Some(why) = why.as_ref().filter(|w| !w.is_empty()) {
                warnings.push(format!(
                    "animation {a}, channel {c}: {why}; channel skipped"
                ));
            }
            c += 1;
            why.is_none()
        });
    }
    (pointers, warnings)
}

/// The document's skins: joint nodes (in range of `node_count`) and inverse bind matrices
/// (a MAT4 float accessor with at least one matrix per joint, finite; identity when absent).
pub(crate) fn convert_skins(
    doc: &gltf::Document,
    buffers: &[Cow<'_, [u8]>],
    node_count: usize,
) -> Result<Vec<Skin>, SceneError> {
    let mut skins = Vec::with_capacity(doc.skins().len());
    for skin in doc.skins() {
        let element = Element::Skin(skin.index());
        let joints: Vec<u32> = skin.joints().map(|j| j.index() as u32).collect();
        if let Some(&bad) = joints.iter().find(|&&j| j as usize >= node_count) {
            return Err(SceneError::at(
                element,
                format!("joint node {bad} out of range for {node_count} nodes"),
            ));
        }
        let inverse_bind = match skin.inverse_bind_matrices() {
            None => vec![DMat4::IDENTITY; joints.len()],
            Some(acc) => {
                let at = Element::Accessor(acc.index());
                let what = format!("inverseBindMatrices of skin {}", skin.index());
                if acc.data_type() != DataType::F32 {
                    return Err(SceneError::at(
                        at,
                        format!("{what} must be float, not {:?}", acc.data_type()),
                    ));
                }
                let f = read_floats(&acc, buffers, &[D::Mat4], &what)?;
                if f.count() < joints.len() {
                    return Err(SceneError::at(
                        at,
                        format!(
                            "{what} has {} matrices for {} joints",
                            f.count(),
                            joints.len()
                        ),
                    ));
                }
                if let Some(v) = f.values.iter().position(|v| !v.is_finite()) {
                    return Err(SceneError::at(
                        at,
                        format!("{what}: matrix {} is not finite", v / 16),
                    ));
                }
                f.values
                    .chunks_exact(16)
                    .take(joints.len())
                    .map(|m| DMat4::from_cols_array(&std::array::from_fn(|i| m[i] as f64)))
                    .collect()
            }
        };
        skins.push(Skin {
            name: skin.name().map(str::to_owned),
            joints,
            inverse_bind,
        });
    }
    Ok(skins)
}

/// The document's animations, each channel with its own copy of its sampler's keys.
/// `nodes` and `meshes` are the converted ones: channels must target TRS nodes, and a
/// weights channel's width is its node's mesh's morph target count. `pointers` are the
/// KHR_animation_pointer channels [`strip_unsupported_channels`] took out.
pub(crate) fn convert_animations(
    doc: &gltf::Document,
    buffers: &[Cow<'_, [u8]>],
    nodes: &[Node],
    meshes: &[Mesh],
    pointers: &[PointerChannel],
    warnings: &mut Vec<String>,
) -> Result<Vec<Animation>, SceneError> {
    let mut sources = HashMap::new();
    let mut out = Vec::with_capacity(doc.animations().len());
    for anim in doc.animations() {
        let a = anim.index();
        let element = Element::Animation(a);
        let label = match anim.name() {
            Some(n) => format!("animation {a} '{n}'"),
            None => format!("animation {a}"),
        };
        let mut channels = Vec::new();
        for (c, ch) in anim.channels().enumerate() {
            // `gltf` 1.4 never validates a channel's target node, and `Target::node` panics
            // when it is out of range: take the index from the JSON.
            let target_node = doc.as_json().animations[a].channels[c].target.node.value();
            let Some(node) = nodes.get(target_node) else {
                return Err(SceneError::at(
                    element,
                    format!(
                        "channel {c} targets node {target_node}, out of range for {} nodes",
                        nodes.len()
                    ),
                ));
            };
            if node.trs.is_none() {
                return Err(SceneError::at(
                    element,
                    format!(
                        "channel {c} animates node {target_node}{}, which has a matrix; the glTF \
                         2.0 spec (node transformations) allows only translation, rotation and \
                         scale on a node targeted by an animation",
                        node.name
                            .as_deref()
                            .map(|n| format!(" '{n}'"))
                            .unwrap_or_default()
                    ),
                ));
            }
            let target = match ch.target().property() {
                NodeProperty::Translation => Target::Translation,
                NodeProperty::Rotation => Target::Rotation,
                NodeProperty::Scale => Target::Scale,
                NodeProperty::MorphTargetWeights => Target::Weights,
            };
            let width = match target {
                Target::Translation | Target::Scale => 3,
                Target::Rotation => 4,
                Target::Weights => {
                    let targets = node
                        .mesh
                        .and_then(|m| meshes.get(m as usize))
                        .map_or(0, |m| m.weights.len());
                    if targets == 0 {
                        return Err(SceneError::at(
                            element,
                            format!(
                                "channel {c} animates the morph weights of node {target_node}, \
                                 which has no mesh with morph targets"
                            ),
                        ));
                    }
                    targets
                }
            };
            let s = ch.sampler();
            let what = format!("sampler {} of {label} (channel {c})", s.index());
            let sampler =
                convert_sampler(&s, buffers, Output::Node(target), width, &what, warnings)?;
            channels.push(Channel {
                node: target_node as u32,
                target,
                sampler,
            });
        }
        let mut properties = Vec::new();
        for p in pointers.iter().filter(|p| p.animation == a) {
            let c = p.channel;
            let Some((property, source)) = pointer_target(&p.pointer, doc)
                .map_err(|why| SceneError::at(element, format!("channel {c}: {why}")))?
            else {
                warnings.push(format!(
                    "{label}, channel {c}: KHR_animation_pointer '{}' is not one Tessera \
                     animates (light colour and intensity; material emission, base colour, \
                     metallic and roughness factors); channel skipped",
                    p.pointer
                ));
                continue;
            };
            // The light's intensity holds colour × intensity, a material's emission factor
            // × strength: a file may animate either half, not both.
            let kind = std::mem::discriminant(&source);
            if *sources.entry(property).or_insert(kind) != kind {
                return Err(SceneError::at(
                    element,
                    format!(
                        "channel {c}: {} animates the other half of a value another channel \
                         animates ({property:?}: a light's colour and its intensity, or a \
                         material's emissive factor and its strength); Tessera animates one",
                        p.pointer
                    ),
                ));
            }
            let Some(s) = anim.samplers().nth(p.sampler) else {
                return Err(SceneError::at(
                    element,
                    format!(
                        "channel {c}: sampler {} out of range for {} samplers",
                        p.sampler,
                        anim.samplers().count()
                    ),
                ));
            };
            let what = format!(
                "sampler {} of {label} (channel {c}, {})",
                s.index(),
                p.pointer
            );
            let width = source.file_width(property);
            let mut sampler =
                convert_sampler(&s, buffers, Output::Pointer(width), width, &what, warnings)?;
            source.convert(&mut sampler, property.width());
            properties.push(PropertyChannel { property, sampler });
        }
        out.push(Animation {
            name: anim.name().map(str::to_owned),
            properties,
            channels,
        });
    }
    Ok(out)
}

/// One sampler, read and checked for a channel driving `target` with `width` floats per
/// element. `what` names the sampler in errors.
fn convert_sampler(
    s: &gltf::animation::Sampler<'_>,
    buffers: &[Cow<'_, [u8]>],
    output_of: Output,
    width: usize,
    what: &str,
    warnings: &mut Vec<String>,
) -> Result<Sampler, SceneError> {
    use gltf::animation::Interpolation as I;
    let interpolation = match s.interpolation() {
        I::Step => Interpolation::Step,
        I::Linear => Interpolation::Linear,
        I::CubicSpline => Interpolation::CubicSpline,
    };

    // Input: key times.
    let input = s.input();
    let at = Element::Accessor(input.index());
    let in_what = format!("input (key times) of {what}");
    if input.data_type() != DataType::F32 {
        return Err(SceneError::at(
            at,
            format!("{in_what} must be float, not {:?}", input.data_type()),
        ));
    }
    let times = read_floats(&input, buffers, &[D::Scalar], &in_what)?.values;
    if times.is_empty() {
        return Err(SceneError::at(at, format!("{in_what} has no keys")));
    }
    if let Some(k) = times.iter().position(|t| !t.is_finite()) {
        return Err(SceneError::at(
            at,
            format!("{in_what}: key time {k} ({}) is not finite", times[k]),
        ));
    }
    if let Some(k) = (1..times.len()).find(|&k| times[k] < times[k - 1]) {
        return Err(SceneError::at(
            at,
            format!(
                "{in_what}: key time {k} ({}) comes before key time {} ({}); key times must \
                 increase",
                times[k],
                k - 1,
                times[k - 1]
            ),
        ));
    }

    // Output: values (with tangents for CUBICSPLINE).
    let output = s.output();
    let at = Element::Accessor(output.index());
    let out_what = format!("output (values) of {what}");
    let (dims, name) = match output_of {
        Output::Node(Target::Translation) => (D::Vec3, "translation"),
        Output::Node(Target::Scale) => (D::Vec3, "scale"),
        Output::Node(Target::Rotation) => (D::Vec4, "rotation"),
        Output::Node(Target::Weights) => (D::Scalar, "weights"),
        Output::Pointer(4) => (D::Vec4, "a four-component value"),
        Output::Pointer(3) => (D::Vec3, "a three-component value"),
        Output::Pointer(_) => (D::Scalar, "a scalar value"),
    };
    let ty = output.data_type();
    let rotation_or_weights = matches!(output_of, Output::Node(Target::Rotation | Target::Weights));
    let type_ok = match ty {
        DataType::F32 => true,
        DataType::I8 | DataType::U8 | DataType::I16 | DataType::U16 if rotation_or_weights => {
            output.normalized()
        }
        _ => false,
    };
    if !type_ok {
        return Err(SceneError::at(
            at,
            format!("{out_what}: {ty:?} is not a component type glTF allows for {name}"),
        ));
    }
    let mut values = read_floats(&output, buffers, &[dims], &out_what)?.values;
    let per_key = match interpolation {
        Interpolation::CubicSpline => 3,
        _ => 1,
    };
    let keys = times.len();
    let weights = output_of == Output::Node(Target::Weights);
    let per_element = if weights { width } else { 1 };
    let need = keys * per_key * per_element;
    if output.count() != need {
        return Err(SceneError::at(
            at,
            format!(
                "{out_what} has {} elements, but {keys} keys{}{} need {need}",
                output.count(),
                if per_key == 3 {
                    " × 3 (in-tangent, value, out-tangent)"
                } else {
                    ""
                },
                if weights {
                    format!(" × {width} morph targets")
                } else {
                    String::new()
                },
            ),
        ));
    }
    if let Some(v) = values.iter().position(|v| !v.is_finite()) {
        return Err(SceneError::at(
            at,
            format!("{out_what}: value {v} is not finite"),
        ));
    }

    if output_of == Output::Node(Target::Rotation) {
        // A normalised integer can only come within one quantisation step of unit length.
        let tolerance = match ty {
            DataType::I8 | DataType::U8 => 1.0 / 127.0,
            DataType::I16 | DataType::U16 => 1.0 / 32767.0,
            _ => 0.0,
        };
        let tolerance = f64::max(tolerance, UNIT_TOLERANCE);
        if let Some((bad, lo, hi)) = normalise_rotation_keys(&mut values, per_key, tolerance) {
            warnings.push(format!(
                "accessor {}: {bad} of {} rotation keys of {what} are not unit quaternions \
                 (lengths {lo:.6} to {hi:.6}); normalised (a zero one holds the previous key)",
                output.index(),
                times.len()
            ));
        }
    }

    // Keys at equal times: keep the later one, so that times strictly increase.
    let stride = per_key * width;
    let keep: Vec<usize> = (0..keys)
        .filter(|&k| k + 1 == keys || times[k + 1] != times[k])
        .collect();
    let (times, values) = if keep.len() == keys {
        (times, values)
    } else {
        warnings.push(format!(
            "accessor {}: {} of {keys} key times of {what} repeat the previous one; \
             only the last key at each time is kept",
            input.index(),
            keys - keep.len()
        ));
        (
            keep.iter().map(|&k| times[k]).collect(),
            keep.iter()
                .flat_map(|&k| values[k * stride..(k + 1) * stride].iter().copied())
                .collect(),
        )
    };
    Ok(Sampler {
        interpolation,
        times,
        values,
        width,
    })
}

/// Scales every rotation key whose length is off 1 by more than `tolerance` to unit length
/// (for CUBICSPLINE, its in- and out-tangents by the same factor, so the spline keeps its
/// shape), as glTF requires node rotations to be unit quaternions. Zero keys stay: the
/// sampler holds the previous key there. Returns how many keys were off, and the smallest
/// and largest length among them; `None` when all are unit.
fn normalise_rotation_keys(
    values: &mut [f32],
    per_key: usize,
    tolerance: f64,
) -> Option<(usize, f64, f64)> {
    let (mut bad, mut lo, mut hi) = (0, f64::INFINITY, 0.0f64);
    for key in values.chunks_exact_mut(4 * per_key) {
        // The value is the middle element of a CUBICSPLINE key.
        let v = if per_key == 3 { 4 } else { 0 };
        let len = key[v..v + 4]
            .iter()
            .map(|&c| c as f64 * c as f64)
            .sum::<f64>()
            .sqrt();
        if (len - 1.0).abs() <= tolerance {
            continue;
        }
        bad += 1;
        (lo, hi) = (lo.min(len), hi.max(len));
        if len > 0.0 {
            key.iter_mut().for_each(|c| *c = (*c as f64 / len) as f32);
        }
    }
    (bad > 0).then_some((bad, lo, hi))
}

/// What a sampler's output drives: a node property, or KHR_animation_pointer values of
/// this many floats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Output {
    Node(Target),
    Pointer(usize),
}

/// How a pointer's values become a [`Property`]'s: as they are, or multiplied by the half
/// of the value the file does not animate (a light's intensity holds colour × intensity,
/// a material's emission factor × strength).
#[derive(Clone, Copy, Debug)]
enum Source {
    Direct,
    /// A colour, times this.
    Colour(f32),
    /// A scalar, times this colour.
    Scale(Vec3),
}

impl Source {
    /// Floats per key in the file.
    fn file_width(self, property: Property) -> usize {
        match self {
            Source::Scale(_) => 1,
            _ => property.width(),
        }
    }

    /// Turns `s`'s values (tangents too: the map is linear) into the property's.
    fn convert(self, s: &mut Sampler, width: usize) {
        match self {
            Source::Direct => {}
            Source::Colour(k) => s.values.iter_mut().for_each(|v| *v *= k),
            Source::Scale(colour) => {
                s.values = s
                    .values
                    .iter()
                    .flat_map(|&v| (colour * v).to_array())
                    .collect();
            }
        }
        s.width = width;
    }
}

/// The property a KHR_animation_pointer `pointer` animates and how its values map to it;
/// `None` for a pointer Tessera does not animate, an error for an index out of range.
fn pointer_target(
    pointer: &str,
    doc: &gltf::Document,
) -> Result<Option<(Property, Source)>, String> {
    let parts: Vec<&str> = pointer.split('/').collect();
    let index = |s: &str, what: &str, count: usize| -> Result<u32, String> {
        match s.parse::<usize>() {
            Ok(i) if i < count => Ok(i as u32),
            _ => Err(format!("{pointer}: {what} {s} out of range for {count}")),
        }
    };
    Ok(Some(match parts[..] {
        ["", "extensions", "KHR_lights_punctual", "lights", i, field @ ("color" | "intensity")] => {
            let lights: Vec<_> = doc.lights().map(Iterator::collect).unwrap_or_default();
            let light = &lights[index(i, "light", lights.len())? as usize];
            let property = Property::Light(light.index() as u32);
            if field == "color" {
                (property, Source::Colour(light.intensity()))
            } else {
                (property, Source::Scale(Vec3::from_array(light.color())))
            }
        }
        ["", "materials", i, ref field @ ..] => {
            let make: fn(u32) -> Property = match field {
                ["emissiveFactor"]
                | ["extensions", "KHR_materials_emissive_strength", "emissiveStrength"] => {
                    Property::Emission
                }
                ["pbrMetallicRoughness", "baseColorFactor"] => Property::BaseColor,
                ["pbrMetallicRoughness", "metallicFactor"] => Property::Metallic,
                ["pbrMetallicRoughness", "roughnessFactor"] => Property::Roughness,
                _ => return Ok(None),
            };
            let m = index(i, "material", doc.materials().len())?;
            // The other half of the emission, read as the material loader reads it.
            let material = doc.materials().nth(m as usize).expect("in range");
            let source = match field {
                ["emissiveFactor"] => Source::Colour(material.emissive_strength().unwrap_or(1.0)),
                ["extensions", ..] => Source::Scale(Vec3::from_array(material.emissive_factor())),
                _ => Source::Direct,
            };
            (make(m), source)
        }
        _ => return Ok(None),
    }))
}
