//! Meshes: each glTF primitive as triangles with its vertex attributes, checked against
//! its vertex count, normals repaired, tangents generated where a normal map needs them;
//! skinning influences (JOINTS_n/WEIGHTS_n) and morph targets read beside them.
//!
//! Vertices may be re-indexed after reading (flat-shaded primitives are unwelded, MikkTSpace
//! splits vertices at seams); every per-vertex array, joint sets and morph targets
//! included, is carried through, so they all stay one entry per vertex.
//!
//! Morph target NORMAL and TANGENT displacements are relative to the file's normals and
//! tangents, so they are dropped where the loader replaces those: all normal displacements
//! of a primitive whose normals are generated (no NORMAL: flat normals), the displacement of
//! each vertex whose zero or non-finite normal was repaired, and all tangent displacements
//! of a primitive whose tangents are generated (MikkTSpace) or absent.

use std::borrow::Cow;
use std::collections::HashMap;

use glam::{Vec2, Vec3, Vec4};
use gltf::accessor::{DataType, Dimensions as D};
use gltf::mesh::Mode;
use gltf::Semantic;

use super::accessor::{read_floats, read_indices, Floats};
use super::error::{mesh_label, Element, SceneError};
use super::tangents;
use crate::material::Material;
use crate::scene::{JointSet, Mesh, MorphTarget, Primitive};

pub(crate) struct MeshOut {
    pub mesh: Mesh,
    pub warnings: Vec<String>,
    pub uses_default: bool,
}

/// The smallest skin among the nodes that draw a mesh: JOINTS_n values must stay below its
/// joint count.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SkinLimit {
    /// Joints in the skin.
    pub joints: usize,
    /// The skin.
    pub skin: usize,
    /// A node drawing the mesh with that skin.
    pub node: usize,
}

/// The number of morph targets of `mesh`, the same for every primitive (an error naming the
/// mesh otherwise, as the spec requires them to agree).
fn morph_target_count(mesh: &gltf::Mesh<'_>) -> Result<usize, SceneError> {
    let label = mesh_label(mesh.index(), mesh.name());
    let mut first = None;
    for (p, prim) in mesh.primitives().enumerate() {
        let count = prim.morph_targets().count();
        match first {
            None => first = Some(count),
            Some(f) if f != count => {
                return Err(SceneError::at(
                    Element::Mesh(mesh.index()),
                    format!(
                        "{label}: primitive {p} has {count} morph targets but primitive 0 has \
                         {f}; glTF requires every primitive of a mesh to have the same number"
                    ),
                ))
            }
            Some(_) => {}
        }
    }
    Ok(first.unwrap_or(0))
}

pub(crate) fn convert_mesh(
    mesh: &gltf::Mesh<'_>,
    buffers: &[Cow<'_, [u8]>],
    materials: &[Material],
    default_material: u32,
    skin: Option<SkinLimit>,
) -> Result<MeshOut, SceneError> {
    let label = mesh_label(mesh.index(), mesh.name());
    let mut warnings = Vec::new();
    let mut primitives = Vec::new();
    let mut uses_default = false;
    let targets = morph_target_count(mesh)?;
    for (p, prim) in mesh.primitives().enumerate() {
        let where_ = format!("{label}, primitive {p}");
        let material = match prim.material().index() {
            Some(i) => i as u32,
            None => {
                uses_default = true;
                default_material
            }
        };
        let tangent_texcoord = materials.get(material as usize).and_then(tangent_set);
        if let Some(out) = convert_primitive(
            &prim,
            buffers,
            material,
            tangent_texcoord,
            skin,
            &where_,
            &mut warnings,
        )? {
            primitives.push(out);
        }
    }
    let weights = default_weights(mesh, targets, &label, &mut warnings)?;
    // Keep a primitive-less mesh anyway so that mesh indices stay the document's.
    let name = mesh.name().map(str::to_owned);
    let mut mesh = Mesh::new(name, primitives);
    mesh.weights = weights;
    Ok(MeshOut {
        mesh,
        warnings,
        uses_default,
    })
}

/// The mesh's default morph weights: the file's, else zeros, one per target. A list of the
/// wrong length is cut or padded with zeros (with a warning); a non-finite weight is an
/// error.
fn default_weights(
    mesh: &gltf::Mesh<'_>,
    targets: usize,
    label: &str,
    warnings: &mut Vec<String>,
) -> Result<Vec<f32>, SceneError> {
    let Some(w) = mesh.weights() else {
        return Ok(vec![0.0; targets]);
    };
    if let Some(bad) = w.iter().find(|w| !w.is_finite()) {
        return Err(SceneError::at(
            Element::Mesh(mesh.index()),
            format!("{label}: default morph weight {bad} is not finite"),
        ));
    }
    let mut w = w.to_vec();
    fit_weights(&mut w, targets, &format!("{label}: default"), warnings);
    Ok(w)
}

/// Cuts or pads `weights` to one per morph target, with a warning starting with `what`
/// when their number was wrong (extra ones are ignored, missing ones are 0).
pub(crate) fn fit_weights(
    weights: &mut Vec<f32>,
    targets: usize,
    what: &str,
    warnings: &mut Vec<String>,
) {
    if weights.len() == targets {
        return;
    }
    warnings.push(format!(
        "{what} {} morph weights for {targets} morph targets; {}",
        weights.len(),
        if weights.len() > targets {
            "the extra ones ignored"
        } else {
            "the missing ones are 0"
        }
    ));
    weights.resize(targets, 0.0);
}

fn vec3s(f: &Floats) -> Vec<Vec3> {
    f.values
        .chunks_exact(3)
        .map(|c| Vec3::new(c[0], c[1], c[2]))
        .collect()
}

/// Reads attribute `sem` when present, checking its type and that it has one element per
/// vertex.
fn attribute(
    prim: &gltf::Primitive<'_>,
    sem: &Semantic,
    allowed: &[D],
    buffers: &[Cow<'_, [u8]>],
    vertices: usize,
    where_: &str,
) -> Result<Option<Floats>, SceneError> {
    let Some(acc) = prim.get(sem) else {
        return Ok(None);
    };
    let what = format!("{} in {where_}", sem.to_string());
    let f = read_floats(&acc, buffers, allowed, &what)?;
    if f.count() != vertices {
        return Err(SceneError::at(
            Element::Accessor(acc.index()),
            format!(
                "{what} has {} elements but POSITION has {vertices}",
                f.count()
            ),
        ));
    }
    Ok(Some(f))
}

/// One glTF primitive as triangles, or `None` (with a warning) when it draws none.
fn convert_primitive(
    prim: &gltf::Primitive<'_>,
    buffers: &[Cow<'_, [u8]>],
    material: u32,
    tangent_texcoord: Option<usize>,
    skin: Option<SkinLimit>,
    where_: &str,
    warnings: &mut Vec<String>,
) -> Result<Option<Primitive>, SceneError> {
    let mode = prim.mode();
    if !matches!(
        mode,
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    ) {
        warnings.push(format!(
            "{where_}: {mode:?} primitives are not rendered; skipped"
        ));
        return Ok(None);
    }
    let Some(pos_acc) = prim.get(&Semantic::Positions) else {
        warnings.push(format!("{where_}: no POSITION attribute; skipped"));
        return Ok(None);
    };
    let positions = vec3s(&read_floats(
        &pos_acc,
        buffers,
        &[D::Vec3],
        &format!("POSITION in {where_}"),
    )?);
    if let Some(v) = positions.iter().position(|p| !p.is_finite()) {
        return Err(SceneError::at(
            Element::Accessor(pos_acc.index()),
            format!("position {v} ({}) is not finite in {where_}", positions[v]),
        ));
    }
    let n = positions.len();

    // Indices, checked against the vertex count, then assembled into triangles.
    let flat: Vec<u32> = match prim.indices() {
        Some(acc) => {
            let idx = read_indices(&acc, buffers, where_)?;
            if let Some(&bad) = idx.iter().find(|&&i| i as usize >= n) {
                return Err(SceneError::at(
                    Element::Accessor(acc.index()),
                    format!("index {bad} out of range for {n} vertices in {where_}"),
                ));
            }
            idx
        }
        None => {
            if n > u32::MAX as usize {
                return Err(SceneError::at(
                    Element::Accessor(pos_acc.index()),
                    format!("{n} vertices is more than 32-bit indices reach in {where_}"),
                ));
            }
            (0..n as u32).collect()
        }
    };
    let indices = assemble(mode, &flat, where_, warnings);
    let repeated = indices
        .iter()
        .filter(|[a, b, c]| a == b || b == c || c == a)
        .count();
    if repeated > 0 {
        warnings.push(format!(
            "{where_}: {repeated} degenerate triangles (a vertex used twice), which glTF meshes \
             should not contain; they draw nothing"
        ));
    }

    let mut out = Primitive {
        positions,
        indices,
        material,
        ..Primitive::default()
    };
    // Joints and targets before anything re-indexes the vertices, so that it carries them.
    out.joint_sets = joint_sets(prim, buffers, n, skin, where_, warnings)?;
    out.targets = morph_targets(prim, buffers, n, where_)?;
    let mut bad_normals = Vec::new();
    if let Some(f) = attribute(prim, &Semantic::Normals, &[D::Vec3], buffers, n, where_)? {
        out.normals = vec3s(&f);
        bad_normals = normalize_normals(&mut out.normals);
        for t in out.targets.iter_mut().filter(|t| !t.normals.is_empty()) {
            for &v in &bad_normals {
                t.normals[v] = Vec3::ZERO;
            }
        }
    }
    let file_normals = !out.normals.is_empty();
    for set in 0..2 {
        if let Some(f) = attribute(
            prim,
            &Semantic::TexCoords(set),
            &[D::Vec2],
            buffers,
            n,
            where_,
        )? {
            out.uvs[set as usize] = f
                .values
                .chunks_exact(2)
                .map(|c| Vec2::new(c[0], c[1]))
                .collect();
        }
    }
    if let Some(f) = attribute(
        prim,
        &Semantic::Colors(0),
        &[D::Vec3, D::Vec4],
        buffers,
        n,
        where_,
    )? {
        out.colors = match f.components {
            3 => f
                .values
                .chunks_exact(3)
                .map(|c| Vec4::new(c[0], c[1], c[2], 1.0))
                .collect(),
            _ => f.values.chunks_exact(4).map(Vec4::from_slice).collect(),
        };
    }
    // TANGENT counts only with NORMAL beside it: without normals the spec asks for flat
    // normals and for supplied tangents to be ignored.
    let mut tangents_ok = false;
    if let Some(f) = attribute(prim, &Semantic::Tangents, &[D::Vec4], buffers, n, where_)? {
        if !out.normals.is_empty() {
            let raw: Vec<Vec4> = f.values.chunks_exact(4).map(Vec4::from_slice).collect();
            tangents_ok = raw
                .iter()
                .all(|t| t.is_finite() && t.truncate().length_squared() > 0.0);
            if tangents_ok {
                out.tangents = raw
                    .iter()
                    .map(|&t| tangents::normalize_tangent(t, Vec3::X))
                    .collect();
            } else {
                warnings.push(format!(
                    "{where_}: TANGENT has zero or non-finite vectors; regenerated"
                ));
            }
        }
    }
    // Every attribute is read: vertices may now be split.
    if !bad_normals.is_empty() {
        let split = face_normals_at(&mut out, &bad_normals);
        warnings.push(format!(
            "{where_}: {} zero or non-finite normals replaced by face normals{}",
            bad_normals.len(),
            match split {
                0 => String::new(),
                k => format!(" ({k} vertices split between faces that disagree)"),
            }
        ));
    }
    if let Some(set) = tangent_texcoord {
        if !tangents_ok {
            need_tangents(&mut out, set, where_, warnings);
        }
    }
    drop_replaced_displacements(&mut out, file_normals, tangents_ok, where_, warnings);
    Ok(Some(out))
}

/// Drops morph NORMAL and TANGENT displacements whose base the loader generated (see the
/// module docs); a warning when the file had some for generated normals or tangents.
fn drop_replaced_displacements(
    prim: &mut Primitive,
    file_normals: bool,
    file_tangents: bool,
    where_: &str,
    warnings: &mut Vec<String>,
) {
    let has = |f: fn(&MorphTarget) -> bool, prim: &Primitive| prim.targets.iter().any(f);
    if !file_normals && has(|t| !t.normals.is_empty(), prim) {
        if !prim.normals.is_empty() {
            warnings.push(format!(
                "{where_}: normals are generated (no NORMAL), so the morph targets' NORMAL \
                 displacements are ignored"
            ));
        }
        prim.targets.iter_mut().for_each(|t| t.normals.clear());
    }
    if !file_tangents && has(|t| !t.tangents.is_empty(), prim) {
        if !prim.tangents.is_empty() {
            warnings.push(format!(
                "{where_}: tangents are generated, so the morph targets' TANGENT \
                 displacements are ignored"
            ));
        }
        prim.targets.iter_mut().for_each(|t| t.tangents.clear());
    }
}

/// Reads the JOINTS_n/WEIGHTS_n pairs: joints unsigned byte or short, weights float or
/// normalised unsigned byte or short, one per vertex, and every joint with a non-zero
/// weight below the joint count of `skin` (the smallest skin drawing this mesh). A JOINTS_n
/// or WEIGHTS_n without its partner is ignored with a warning. A joint index out of range
/// whose weight is zero is kept: it influences nothing.
fn joint_sets(
    prim: &gltf::Primitive<'_>,
    buffers: &[Cow<'_, [u8]>],
    n: usize,
    skin: Option<SkinLimit>,
    where_: &str,
    warnings: &mut Vec<String>,
) -> Result<Vec<JointSet>, SceneError> {
    let mut sets: Vec<u32> = prim
        .attributes()
        .filter_map(|(sem, _)| match sem {
            Semantic::Joints(k) | Semantic::Weights(k) => Some(k),
            _ => None,
        })
        .collect();
    sets.sort_unstable();
    sets.dedup();
    let mut out = Vec::new();
    for k in sets {
        let (Some(ja), Some(wa)) = (
            prim.get(&Semantic::Joints(k)),
            prim.get(&Semantic::Weights(k)),
        ) else {
            warnings.push(format!(
                "{where_}: JOINTS_{k} and WEIGHTS_{k} must come together; the one present is \
                 ignored"
            ));
            continue;
        };
        let (jt, wt) = (ja.data_type(), wa.data_type());
        if !matches!(jt, DataType::U8 | DataType::U16) || ja.normalized() {
            return Err(SceneError::at(
                Element::Accessor(ja.index()),
                format!("JOINTS_{k} in {where_} must be unsigned byte or short, not {jt:?}"),
            ));
        }
        let weights_ok = match wt {
            DataType::F32 => true,
            DataType::U8 | DataType::U16 => wa.normalized(),
            _ => false,
        };
        if !weights_ok {
            return Err(SceneError::at(
                Element::Accessor(wa.index()),
                format!(
                    "WEIGHTS_{k} in {where_} must be float or normalized unsigned byte or \
                     short, not {wt:?}{}",
                    if wa.normalized() {
                        ""
                    } else {
                        " (not normalized)"
                    }
                ),
            ));
        }
        let read = |sem| attribute(prim, &sem, &[D::Vec4], buffers, n, where_);
        let (Some(jf), Some(wf)) = (read(Semantic::Joints(k))?, read(Semantic::Weights(k))?) else {
            unreachable!("both accessors exist");
        };
        let joints: Vec<[u16; 4]> = jf
            .values
            .chunks_exact(4)
            .map(|c| [c[0] as u16, c[1] as u16, c[2] as u16, c[3] as u16])
            .collect();
        let weights: Vec<[f32; 4]> = wf
            .values
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
        if let Some(v) = weights
            .iter()
            .position(|w| w.iter().any(|x| !x.is_finite()))
        {
            return Err(SceneError::at(
                Element::Accessor(wa.index()),
                format!(
                    "WEIGHTS_{k} in {where_}: vertex {v} has non-finite weights {:?}",
                    weights[v]
                ),
            ));
        }
        if let Some(limit) = skin {
            for (v, (js, ws)) in joints.iter().zip(&weights).enumerate() {
                if let Some(c) = (0..4).find(|&c| ws[c] != 0.0 && js[c] as usize >= limit.joints) {
                    return Err(SceneError::at(
                        Element::Accessor(ja.index()),
                        format!(
                            "JOINTS_{k} in {where_}: vertex {v} uses joint {} (weight {}), but \
                             skin {} of node {} has only {} joints",
                            js[c], ws[c], limit.skin, limit.node, limit.joints
                        ),
                    ));
                }
            }
        }
        out.push(JointSet { joints, weights });
    }
    Ok(out)
}

/// Reads the morph targets' POSITION, NORMAL and TANGENT displacements (VEC3, float or
/// normalised integers, dense or sparse), each one per vertex and finite. Other target
/// attributes (texture coordinates, colours) are not read.
fn morph_targets(
    prim: &gltf::Primitive<'_>,
    buffers: &[Cow<'_, [u8]>],
    n: usize,
    where_: &str,
) -> Result<Vec<MorphTarget>, SceneError> {
    let mut out = Vec::new();
    for (t, target) in prim.morph_targets().enumerate() {
        let read = |acc: Option<gltf::Accessor<'_>>, name: &str| {
            let Some(acc) = acc else {
                return Ok(Vec::new());
            };
            let element = Element::Accessor(acc.index());
            let what = format!("morph target {t} {name} in {where_}");
            let f = read_floats(&acc, buffers, &[D::Vec3], &what)?;
            if f.count() != n {
                return Err(SceneError::at(
                    element,
                    format!("{what} has {} elements but POSITION has {n}", f.count()),
                ));
            }
            let v = vec3s(&f);
            if let Some(bad) = v.iter().position(|d| !d.is_finite()) {
                return Err(SceneError::at(
                    element,
                    format!("{what}: displacement {bad} ({}) is not finite", v[bad]),
                ));
            }
            Ok(v)
        };
        out.push(MorphTarget {
            positions: read(target.positions(), "POSITION")?,
            normals: read(target.normals(), "NORMAL")?,
            tangents: read(target.tangents(), "TANGENT")?,
        });
    }
    Ok(out)
}

/// Triangles from a flat index list: lists in threes, strips and fans as the spec says.
fn assemble(mode: Mode, v: &[u32], where_: &str, warnings: &mut Vec<String>) -> Vec<[u32; 3]> {
    match mode {
        Mode::TriangleStrip => (0..v.len().saturating_sub(2))
            .map(|i| {
                // Every other triangle swaps two corners to keep the winding.
                if i % 2 == 0 {
                    [v[i], v[i + 1], v[i + 2]]
                } else {
                    [v[i], v[i + 2], v[i + 1]]
                }
            })
            .collect(),
        Mode::TriangleFan => (1..v.len().saturating_sub(1))
            .map(|i| [v[i], v[i + 1], v[0]])
            .collect(),
        _ => {
            let extra = v.len() % 3;
            if extra > 0 {
                warnings.push(format!(
                    "{where_}: {} indices is not a multiple of 3; the last {extra} ignored",
                    v.len()
                ));
            }
            v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
        }
    }
}

/// Renormalises normals; returns the vertices whose normal is zero or not finite, left
/// for [`face_normals_at`].
fn normalize_normals(normals: &mut [Vec3]) -> Vec<usize> {
    let mut bad = Vec::new();
    for (i, nrm) in normals.iter_mut().enumerate() {
        match nrm.try_normalize() {
            Some(u) => *nrm = u,
            None => bad.push(i),
        }
    }
    bad
}

/// Gives each corner at a vertex of `bad` the normal of its face, as the spec's flat normals
/// for a primitive without NORMAL: a vertex whose faces disagree is split into one copy per
/// face normal (every per-vertex array follows), so a welded cube stays a cube rather than
/// rounding at its corners. A vertex on no face with an area keeps +Z. Returns how many
/// copies were added.
fn face_normals_at(prim: &mut Primitive, bad: &[usize]) -> usize {
    let mut given: Vec<Option<Vec3>> = vec![None; prim.positions.len()];
    let mut is_bad = vec![false; prim.positions.len()];
    for &v in bad {
        is_bad[v] = true;
        prim.normals[v] = Vec3::Z;
    }
    // Per split vertex, its copies and their normals. Coplanar faces agree to rounding.
    let same = |a: Vec3, b: Vec3| a.dot(b) > 1.0 - 1e-6;
    let mut copies: HashMap<u32, Vec<(Vec3, u32)>> = HashMap::new();
    let mut added = 0;
    for t in 0..prim.indices.len() {
        let Some(face) = prim.face_normal(t).try_normalize() else {
            continue;
        };
        for k in 0..3 {
            let v = prim.indices[t][k];
            if !is_bad[v as usize] {
                continue;
            }
            match given[v as usize] {
                None => {
                    given[v as usize] = Some(face);
                    prim.normals[v as usize] = face;
                }
                Some(n) if same(n, face) => {}
                Some(_) => {
                    let known = copies.entry(v).or_default();
                    let copy = match known.iter().find(|(n, _)| same(*n, face)) {
                        Some(&(_, c)) => c,
                        None => {
                            let c = copy_vertex(prim, v as usize);
                            prim.normals[c as usize] = face;
                            known.push((face, c));
                            added += 1;
                            c
                        }
                    };
                    prim.indices[t][k] = copy;
                }
            }
        }
    }
    added
}

/// Appends a copy of vertex `v`, every per-vertex array included; returns its index.
fn copy_vertex(prim: &mut Primitive, v: usize) -> u32 {
    fn push<T: Copy>(a: &mut Vec<T>, v: usize) {
        if let Some(&x) = a.get(v) {
            a.push(x);
        }
    }
    push(&mut prim.positions, v);
    push(&mut prim.normals, v);
    push(&mut prim.tangents, v);
    push(&mut prim.colors, v);
    prim.uvs.iter_mut().for_each(|set| push(set, v));
    for set in &mut prim.joint_sets {
        push(&mut set.joints, v);
        push(&mut set.weights, v);
    }
    for t in &mut prim.targets {
        push(&mut t.positions, v);
        push(&mut t.normals, v);
        push(&mut t.tangents, v);
    }
    prim.positions.len() as u32 - 1
}

/// The texture coordinate set a material's tangents follow, where it needs tangents: its
/// normal map's, else, for an anisotropic material (whose direction is given in tangent
/// space), its anisotropy texture's or TEXCOORD_0.
fn tangent_set(m: &Material) -> Option<usize> {
    let set = |t: &Option<crate::texture::TextureRef>| t.as_ref().map(|t| t.texcoord as usize);
    set(&m.normal_texture).or_else(|| {
        m.is_anisotropic()
            .then(|| set(&m.anisotropy_texture).unwrap_or(0))
    })
}

/// Generates MikkTSpace tangents for a normal-mapped or anisotropic primitive, first
/// giving it flat normals if it has none.
fn need_tangents(prim: &mut Primitive, set: usize, where_: &str, warnings: &mut Vec<String>) {
    if set > 1 || prim.uvs[set].is_empty() {
        warnings.push(format!(
            "{where_}: its material needs tangents (a normal map or anisotropy) from \
             TEXCOORD_{set}, which the primitive lacks; no tangents generated"
        ));
        return;
    }
    if prim.normals.is_empty() {
        unweld_with_flat_normals(prim);
    }
    match tangents::generate(prim, set) {
        Ok(_) => {}
        Err(e) => {
            prim.tangents.clear();
            warnings.push(format!("{where_}: {e}; no tangents generated"));
        }
    }
}

/// Gives every triangle its own three vertices with the face normal: the flat shading
/// the spec asks for when NORMAL is absent, made explicit so tangents can be generated.
fn unweld_with_flat_normals(prim: &mut Primitive) {
    let tris = std::mem::take(&mut prim.indices);
    let order: Vec<u32> = tris.iter().flatten().copied().collect();
    let uvs = [gather(&prim.uvs[0], &order), gather(&prim.uvs[1], &order)];
    let colors = gather(&prim.colors, &order);
    for set in &mut prim.joint_sets {
        set.joints = gather(&set.joints, &order);
        set.weights = gather(&set.weights, &order);
    }
    for t in &mut prim.targets {
        t.positions = gather(&t.positions, &order);
        t.normals = gather(&t.normals, &order);
        t.tangents = gather(&t.tangents, &order);
    }
    let mut positions = Vec::with_capacity(tris.len() * 3);
    let mut normals = Vec::with_capacity(tris.len() * 3);
    for &[a, b, c] in &tris {
        let (pa, pb, pc) = (
            prim.positions[a as usize],
            prim.positions[b as usize],
            prim.positions[c as usize],
        );
        let nrm = (pb - pa).cross(pc - pa).try_normalize().unwrap_or(Vec3::Z);
        positions.extend([pa, pb, pc]);
        normals.extend([nrm; 3]);
    }
    prim.indices = (0..tris.len() as u32)
        .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
        .collect();
    prim.positions = positions;
    prim.normals = normals;
    prim.uvs = uvs;
    prim.colors = colors;
    prim.tangents.clear();
}

/// `src[order[0]], src[order[1]], ...`; empty for an absent (empty) attribute.
fn gather<T: Copy>(src: &[T], order: &[u32]) -> Vec<T> {
    if src.is_empty() {
        Vec::new()
    } else {
        order.iter().map(|&i| src[i as usize]).collect()
    }
}
