//! Animations: every channel with its own sampler; channels driving lights and materials
//! as KHR_animation_pointer channels.

use super::*;

pub(super) fn animation(
    i: usize,
    a: &Animation,
    scene: &Scene,
    bin: &mut Bin,
    used: &mut bool,
) -> Result<Value, ExportError> {
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
        let components = if ch.target == Target::Weights {
            1
        } else {
            width
        };
        samplers.push(sampler(&el, s, path, width, &s.values, components, bin)?);
        channels.push(
            Obj::default()
                .with("sampler", samplers.len() - 1)
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
    for (c, ch) in a.properties.iter().enumerate() {
        let el = format!("{label}, pointer channel {c}");
        let s = &ch.sampler;
        if s.width != ch.property.width() {
            return Err(invalid(
                &el,
                format!(
                    "its sampler has {} values per element, but {:?} needs {}",
                    s.width,
                    ch.property,
                    ch.property.width()
                ),
            ));
        }
        let (pointer, values, components) = pointer_values(&el, ch, scene)?;
        samplers.push(sampler(
            &el, s, &pointer, components, &values, components, bin,
        )?);
        *used = true;
        channels.push(
            Obj::default()
                .with("sampler", samplers.len() - 1)
                .with(
                    "target",
                    Obj::default()
                        .with("path", "pointer")
                        .with(
                            "extensions",
                            Obj::default()
                                .with(
                                    "KHR_animation_pointer",
                                    Obj::default().with("pointer", pointer).build(),
                                )
                                .build(),
                        )
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

/// A sampler's JSON, its keys and `values` (`width` floats per key, written as elements of
/// `components` floats) checked as the loader would.
fn sampler(
    el: &str,
    s: &Sampler,
    path: &str,
    width: usize,
    values: &[f32],
    components: usize,
    bin: &mut Bin,
) -> Result<Value, ExportError> {
    if s.times.is_empty() {
        return Err(invalid(el, "its sampler has no keys"));
    }
    finite(el, "key times", &s.times)?;
    // The loader refuses decreasing times and merges equal ones.
    if let Some(k) = (1..s.times.len()).find(|&k| !(s.times[k] > s.times[k - 1])) {
        return Err(invalid(
            el,
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
    if values.len() != need {
        return Err(invalid(
            el,
            format!(
                "{} values, but {} keys of {path} need {need}",
                values.len(),
                s.times.len()
            ),
        ));
    }
    finite(el, "values", values)?;
    let input = bin.floats(&s.times, 1, true, None);
    let output = bin.floats(values, components, false, None);
    let interpolation = match s.interpolation {
        Interpolation::Step => "STEP",
        Interpolation::Linear => "LINEAR",
        Interpolation::CubicSpline => "CUBICSPLINE",
    };
    Ok(Obj::default()
        .with("input", input)
        .with("output", output)
        .with("interpolation", interpolation)
        .build())
}

/// The KHR_animation_pointer pointer a property channel is written to, its values there
/// and the floats per element. A light's colour × intensity, and a material's emission,
/// are written as the scalar half (intensity, emissive strength) where every key is the
/// static colour the light or material is written with times a scalar, else as the
/// colour half (colour, emissive factor) where every key over the static scale is a
/// colour within [0, 1]; in both cases exactly, so that the file loads back to the same
/// values.
fn pointer_values(
    el: &str,
    ch: &PropertyChannel,
    scene: &Scene,
) -> Result<(String, Vec<f32>, usize), ExportError> {
    let values = &ch.sampler.values;
    let out_of_range =
        |what: &str, i: u32, n: usize| invalid(el, format!("{what} {i} out of range for {n}"));
    let (static_value, scalar, colour) = match ch.property {
        Property::Light(i) => {
            let light = scene
                .lights
                .get(i as usize)
                .ok_or_else(|| out_of_range("light", i, scene.lights.len()))?;
            let value = match *light {
                PunctualLight::Point { intensity, .. } | PunctualLight::Spot { intensity, .. } => {
                    intensity
                }
                PunctualLight::Directional { illuminance } => illuminance,
            };
            let base = format!("/extensions/KHR_lights_punctual/lights/{i}");
            (value, format!("{base}/intensity"), format!("{base}/color"))
        }
        Property::Emission(m) => {
            let material = scene
                .materials
                .get(m as usize)
                .ok_or_else(|| out_of_range("material", m, scene.materials.len()))?;
            (
                material.emissive,
                format!(
                    "/materials/{m}/extensions/KHR_materials_emissive_strength/emissiveStrength"
                ),
                format!("/materials/{m}/emissiveFactor"),
            )
        }
        Property::BaseColor(m) | Property::Metallic(m) | Property::Roughness(m) => {
            if m as usize >= scene.materials.len() {
                return Err(out_of_range("material", m, scene.materials.len()));
            }
            let field = match ch.property {
                Property::BaseColor(_) => "baseColorFactor",
                Property::Metallic(_) => "metallicFactor",
                _ => "roughnessFactor",
            };
            let width = ch.property.width();
            if values.iter().any(|v| !(0.0..=1.0).contains(v)) {
                return Err(invalid(el, format!("{field} keys outside [0, 1]")));
            }
            return Ok((
                format!("/materials/{m}/pbrMetallicRoughness/{field}"),
                values.clone(),
                width,
            ));
        }
    };
    let (static_colour, static_scale) = split_scale(static_value)
        .ok_or_else(|| invalid(el, format!("{static_value} has no exact colour × scale")))?;
    let keys = values.chunks_exact(3).map(Vec3::from_slice);
    // The scalar half: every key the static colour times one number.
    let j = (0..3).fold(0, |j, k| {
        if static_colour[k] > static_colour[j] {
            k
        } else {
            j
        }
    });
    let scalars: Option<Vec<f32>> = keys
        .clone()
        .map(|k| {
            let s = k[j] / static_colour[j];
            (static_colour * s == k).then_some(s)
        })
        .collect();
    if let Some(scalars) = scalars.filter(|_| static_colour[j] > 0.0) {
        return Ok((scalar, scalars, 1));
    }
    let colours: Option<Vec<f32>> = keys
        .map(|k| {
            let c = k / static_scale;
            (c * static_scale == k && c.max_element() <= 1.0 && c.min_element() >= 0.0)
                .then_some(c.to_array())
        })
        .collect::<Option<Vec<[f32; 3]>>>()
        .map(|c| c.concat());
    colours.map(|c| (colour, c, 3)).ok_or_else(|| {
        invalid(
            el,
            format!(
                "{:?} keys are neither {static_colour} times a number nor colours within \
                 [0, 1] times {static_scale}: glTF has no pointer for them",
                ch.property
            ),
        )
    })
}
