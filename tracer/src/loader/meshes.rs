//! Meshes: each glTF primitive as triangles with its vertex attributes, checked against
//! its vertex count, normals repaired, tangents generated where a normal map needs them.

use std::borrow::Cow;

use glam::{Vec2, Vec3, Vec4};
use gltf::accessor::Dimensions as D;
use gltf::mesh::Mode;
use gltf::Semantic;

use super::accessor::{read_floats, read_indices, Floats};
use super::error::{mesh_label, Element, SceneError};
use super::tangents;
use crate::material::Material;
use crate::scene::{Mesh, Primitive};

pub(crate) struct MeshOut {
    pub mesh: Mesh,
    pub warnings: Vec<String>,
    pub uses_default: bool,
}

pub(crate) fn convert_mesh(
    mesh: &gltf::Mesh<'_>,
    buffers: &[Cow<'_, [u8]>],
    materials: &[Material],
    default_material: u32,
) -> Result<MeshOut, SceneError> {
    let label = mesh_label(mesh.index(), mesh.name());
    let mut warnings = Vec::new();
    let mut primitives = Vec::new();
    let mut uses_default = false;
    for (p, prim) in mesh.primitives().enumerate() {
        let where_ = format!("{label}, primitive {p}");
        let material = match prim.material().index() {
            Some(i) => i as u32,
            None => {
                uses_default = true;
                default_material
            }
        };
        let normal_texcoord = materials
            .get(material as usize)
            .and_then(|m| m.normal_texture.as_ref())
            .map(|t| t.texcoord as usize);
        if let Some(out) = convert_primitive(
            &prim,
            buffers,
            material,
            normal_texcoord,
            &where_,
            &mut warnings,
        )? {
            primitives.push(out);
        }
    }
    // Keep a primitive-less mesh anyway so that mesh indices stay the document's.
    let mesh = Mesh::new(mesh.name().map(str::to_owned), primitives);
    Ok(MeshOut {
        mesh,
        warnings,
        uses_default,
    })
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
    normal_texcoord: Option<usize>,
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

    let mut out = Primitive {
        positions,
        indices,
        material,
        ..Primitive::default()
    };
    if let Some(f) = attribute(prim, &Semantic::Normals, &[D::Vec3], buffers, n, where_)? {
        out.normals = vec3s(&f);
        repair_normals(&mut out, where_, warnings);
    }
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
    if let Some(set) = normal_texcoord {
        if !tangents_ok {
            need_tangents(&mut out, set, where_, warnings);
        }
    }
    Ok(Some(out))
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

/// Renormalises normals; zero or non-finite ones become the area-weighted normal of the
/// faces around the vertex (+Z for a vertex no face gives one).
fn repair_normals(prim: &mut Primitive, where_: &str, warnings: &mut Vec<String>) {
    let mut bad = Vec::new();
    for (i, nrm) in prim.normals.iter_mut().enumerate() {
        match nrm.try_normalize() {
            Some(u) => *nrm = u,
            None => bad.push(i),
        }
    }
    if bad.is_empty() {
        return;
    }
    let mut sum = vec![Vec3::ZERO; prim.positions.len()];
    for &[a, b, c] in &prim.indices {
        let p = |i: u32| prim.positions[i as usize];
        let face = (p(b) - p(a)).cross(p(c) - p(a));
        for i in [a, b, c] {
            sum[i as usize] += face;
        }
    }
    for &i in &bad {
        prim.normals[i] = sum[i].try_normalize().unwrap_or(Vec3::Z);
    }
    warnings.push(format!(
        "{where_}: {} zero or non-finite normals replaced by face normals",
        bad.len()
    ));
}

/// Generates MikkTSpace tangents for a normal-mapped primitive, first giving it flat
/// normals if it has none.
fn need_tangents(prim: &mut Primitive, set: usize, where_: &str, warnings: &mut Vec<String>) {
    if set > 1 || prim.uvs[set].is_empty() {
        warnings.push(format!(
            "{where_}: normal map reads TEXCOORD_{set}, which the primitive lacks; \
             no tangents generated"
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
    let pick = |src: &[Vec2]| -> Vec<Vec2> {
        if src.is_empty() {
            Vec::new()
        } else {
            tris.iter().flatten().map(|&i| src[i as usize]).collect()
        }
    };
    let uvs = [pick(&prim.uvs[0]), pick(&prim.uvs[1])];
    let colors = if prim.colors.is_empty() {
        Vec::new()
    } else {
        tris.iter()
            .flatten()
            .map(|&i| prim.colors[i as usize])
            .collect()
    };
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
