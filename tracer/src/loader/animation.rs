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
//! - A channel whose target this loader does not know (KHR_animation_pointer's `pointer`,
//!   or a target without a node) is dropped with a warning before the document is parsed;
//!   see [`strip_unsupported_channels`].

use std::borrow::Cow;

use glam::DMat4;
use gltf::accessor::{DataType, Dimensions as D};
use gltf::animation::Property;
use gltf::json::Value;

use super::accessor::read_floats;
use super::error::{Element, SceneError};
use super::gltf::UNIT_TOLERANCE;
use crate::animation::{Animation, Channel, Interpolation, Sampler, Target};
use crate::scene::{Mesh, Node, Skin};

/// Removes, from the untyped document, animation channels whose target is not one of
/// glTF's four node properties or has no node (KHR_animation_pointer writes
/// `"path": "pointer"` and no node, which the typed parser refuses outright). Returns a
/// warning for each, naming the animation and the channel's index in the file.
pub(crate) fn strip_unsupported_channels(raw: &mut Value) -> Vec<String> {
    let mut warnings = Vec::new();
    let Some(anims) = raw.get_mut("animations").and_then(Value::as_array_mut) else {
        return warnings;
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
            let why = match path {
                // A malformed target stays, for the schema check to report.
                None => None,
                Some("translation" | "rotation" | "scale" | "weights") if has_node => None,
                Some(p @ ("translation" | "rotation" | "scale" | "weights")) => Some(format!(
                    "its '{p}' target names no node (an extension would define it)"
                )),
                Some("pointer") => {
                    Some("target path 'pointer' (KHR_animation_pointer) is not supported".into())
                }
                Some(p) => Some(format!("target path '{p}' is not supported")),
            };
            if let Some(why) = &why {
                warnings.push(format!(
                    "animation {a}, channel {c}: {why}; channel skipped"
                ));
            }
            c += 1;
            why.is_none()
        });
    }
    warnings
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
/// weights channel's width is its node's mesh's morph target count.
pub(crate) fn convert_animations(
    doc: &gltf::Document,
    buffers: &[Cow<'_, [u8]>],
    nodes: &[Node],
    meshes: &[Mesh],
    warnings: &mut Vec<String>,
) -> Result<Vec<Animation>, SceneError> {
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
                Property::Translation => Target::Translation,
                Property::Rotation => Target::Rotation,
                Property::Scale => Target::Scale,
                Property::MorphTargetWeights => Target::Weights,
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
            let sampler = convert_sampler(&s, buffers, target, width, &what, warnings)?;
            channels.push(Channel {
                node: target_node as u32,
                target,
                sampler,
            });
        }
        out.push(Animation {
            name: anim.name().map(str::to_owned),
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
    target: Target,
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
    let (dims, name) = match target {
        Target::Translation => (D::Vec3, "translation"),
        Target::Scale => (D::Vec3, "scale"),
        Target::Rotation => (D::Vec4, "rotation"),
        Target::Weights => (D::Scalar, "weights"),
    };
    let ty = output.data_type();
    let type_ok = match (target, ty) {
        (_, DataType::F32) => true,
        (Target::Rotation | Target::Weights, DataType::I8 | DataType::U8)
        | (Target::Rotation | Target::Weights, DataType::I16 | DataType::U16) => {
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
    let per_element = if target == Target::Weights { width } else { 1 };
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
                if target == Target::Weights {
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

    if target == Target::Rotation {
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
