//! Animations: every channel with its own sampler.

use super::*;

pub(super) fn animation(
    i: usize,
    a: &Animation,
    scene: &Scene,
    bin: &mut Bin,
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
