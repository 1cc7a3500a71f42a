//! MikkTSpace tangents for normal-mapped primitives that come without a TANGENT attribute,
//! as the glTF spec asks ("client implementations SHOULD calculate tangents using default
//! MikkTSpace algorithms").
//!
//! Two details matter. MikkTSpace assumes texture space with `v` pointing up, while glTF's
//! `v` points down the image; we feed it `1 - v` so that the bitangent points up the image,
//! which is where glTF normal maps put +Y, and `w` follows glTF's
//! `bitangent = cross(normal, tangent.xyz) * w`. And MikkTSpace answers per face corner:
//! a vertex shared by faces whose corners disagree (a UV seam, a mirrored half) is split
//! into one copy per tangent.

use std::collections::HashMap;

use bevy_mikktspace::{Geometry, TangentSpace};
use glam::{Vec2, Vec3, Vec4};

use crate::geometry::Frame;
use crate::scene::Primitive;

struct Faces<'a> {
    prim: &'a Primitive,
    uvs: &'a [Vec2],
    corners: Vec<Option<[f32; 4]>>,
}

impl Faces<'_> {
    fn vertex(&self, face: usize, vert: usize) -> usize {
        self.prim.indices[face][vert] as usize
    }
}

impl Geometry for Faces<'_> {
    fn num_faces(&self) -> usize {
        self.prim.indices.len()
    }

    fn num_vertices_of_face(&self, _face: usize) -> usize {
        3
    }

    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.prim.positions[self.vertex(face, vert)].to_array()
    }

    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        self.prim.normals[self.vertex(face, vert)].to_array()
    }

    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        let uv = self.uvs[self.vertex(face, vert)];
        [uv.x, 1.0 - uv.y]
    }

    fn set_tangent(&mut self, tangent: Option<TangentSpace>, face: usize, vert: usize) {
        self.corners[face * 3 + vert] = tangent.map(|t| t.tangent_encoded());
    }
}

/// Generates unit tangents for `prim` from its normals and UV set `set`, splitting
/// vertices where faces disagree. Returns how many vertices were added. The primitive
/// must have normals and that UV set, one per vertex.
pub(crate) fn generate(prim: &mut Primitive, set: usize) -> Result<usize, String> {
    let n = prim.positions.len();
    if prim.normals.len() != n || prim.uvs[set].len() != n {
        return Err(format!(
            "tangent generation needs normals and TEXCOORD_{set}"
        ));
    }
    let corners = {
        let mut faces = Faces {
            prim,
            uvs: &prim.uvs[set],
            corners: vec![None; prim.indices.len() * 3],
        };
        bevy_mikktspace::generate_tangents(&mut faces)
            .map_err(|e| format!("MikkTSpace failed: {e:?}"))?;
        faces.corners
    };

    let mut tangents: Vec<Option<Vec4>> = vec![None; n];
    let mut copies: HashMap<(u32, [u32; 4]), u32> = HashMap::new();
    let mut added = 0;
    for (c, corner) in corners.iter().enumerate() {
        let (f, k) = (c / 3, c % 3);
        let v = prim.indices[f][k] as usize;
        let t = match corner {
            Some(t) if t[..3].iter().all(|c| c.is_finite()) => Vec4::from_array(*t),
            // No answer for this corner (a degenerate face with no neighbours): any unit
            // vector perpendicular to the normal will do.
            _ => Frame::from_normal(prim.normals[v]).x.extend(1.0),
        };
        match tangents[v] {
            None => tangents[v] = Some(t),
            Some(old) if old == t => {}
            Some(_) => {
                let key = (v as u32, t.to_array().map(f32::to_bits));
                let copy = *copies.entry(key).or_insert_with(|| {
                    added += 1;
                    duplicate_vertex(prim, v, &mut tangents, t)
                });
                prim.indices[f][k] = copy;
            }
        }
    }
    // Vertices no face uses keep a valid frame too.
    prim.tangents = tangents
        .iter()
        .zip(&prim.normals)
        .map(|(t, &nrm)| t.unwrap_or_else(|| Frame::from_normal(nrm).x.extend(1.0)))
        .map(|t| normalize_tangent(t, Vec3::ZERO))
        .collect();
    Ok(added)
}

/// Appends a copy of vertex `v` with tangent `t`, returning its index.
fn duplicate_vertex(
    prim: &mut Primitive,
    v: usize,
    tangents: &mut Vec<Option<Vec4>>,
    t: Vec4,
) -> u32 {
    let new = prim.positions.len() as u32;
    prim.positions.push(prim.positions[v]);
    prim.normals.push(prim.normals[v]);
    for set in prim.uvs.iter_mut() {
        if !set.is_empty() {
            set.push(set[v]);
        }
    }
    if !prim.colors.is_empty() {
        prim.colors.push(prim.colors[v]);
    }
    // Skinning and morphing data are per vertex too: the copy shares them.
    for set in &mut prim.joint_sets {
        set.joints.push(set.joints[v]);
        set.weights.push(set.weights[v]);
    }
    for target in &mut prim.targets {
        for d in [
            &mut target.positions,
            &mut target.normals,
            &mut target.tangents,
        ] {
            if !d.is_empty() {
                d.push(d[v]);
            }
        }
    }
    tangents.push(Some(t));
    new
}

/// A tangent with unit xyz and w = ±1; `fallback` (or any perpendicular) when degenerate.
pub(crate) fn normalize_tangent(t: Vec4, fallback: Vec3) -> Vec4 {
    let xyz = t.truncate();
    let w = if t.w < 0.0 { -1.0 } else { 1.0 };
    match xyz.try_normalize() {
        Some(u) => u.extend(w),
        None => fallback.try_normalize().unwrap_or(Vec3::X).extend(w),
    }
}
