//! Meshes and their primitives (with EXT_mesh_gpu_instancing for instanced draws), every
//! attribute in its own accessor.

use super::*;

pub(super) const INSTANCING: &str = "EXT_mesh_gpu_instancing";

/// EXT_mesh_gpu_instancing's TRANSLATION, ROTATION and SCALE accessors for `instances`,
/// each decomposed as the loader composes it.
pub(super) fn gpu_instances(
    el: &str,
    instances: &[DMat4],
    bin: &mut Bin,
) -> Result<Value, ExportError> {
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

pub(super) fn mesh(
    i: usize,
    m: &Mesh,
    materials: usize,
    bin: &mut Bin,
) -> Result<Value, ExportError> {
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
pub(super) fn per_vertex(
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

pub(super) fn flat3(v: &[Vec3]) -> Vec<f32> {
    v.iter().flat_map(|x| x.to_array()).collect()
}

pub(super) fn flat4(v: &[Vec4]) -> Vec<f32> {
    v.iter().flat_map(|x| x.to_array()).collect()
}

pub(super) fn primitive(
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
