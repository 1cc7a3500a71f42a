//! Vertex deformation: morph targets, then linear blend skinning, evaluated per primitive
//! for one pose (see [`crate::animation::pose`]).
//!
//! The renderer calls, per skinned or morphed node instance and per time:
//!
//! ```ignore
//! let pose = animation::pose(&scene, &chosen, t);
//! let world = animation::world_transforms(&scene, &pose);
//! let joints = node.skin.map(|s| deform::joint_matrices(&scene.skins[s as usize], |j| world[j as usize]));
//! let weights = animation::morph_weights(&scene, &pose, node_index);
//! let out = deform::deform(prim, weights, joints.as_deref());
//! ```
//!
//! With joints, the result is in the space the joint matrices map to (world space when
//! they come from world transforms, as glTF wants: the skinned node's own transform does
//! not apply). Without joints it stays in the mesh's object space.
//!
//! Choices, each made where the spec leaves room or the file is broken:
//! - Skin weights are normalised by their sum over every joint set, so quantised weights
//!   (normalised bytes summing to 254/255) place vertices exactly; the spec requires sums
//!   of one, so a conforming file is unchanged.
//! - An influence is ignored when its weight is zero or not finite, or its joint index is
//!   outside the joint matrices. A vertex left with a weight sum that is not positive is
//!   not moved by any joint: its blended matrix is the identity, so it keeps its morphed
//!   mesh-space position, taken as-is in the joints' output space (glTF defines no
//!   placement for it).
//! - A blended matrix that is not finite (a broken joint transform) counts as the identity.
//! - No NaN reaches the output: a normal or tangent that becomes zero or non-finite falls
//!   back to the primitive's input one (then +Z or +X), a position to the morphed, then
//!   the input position.

use glam::{DMat3, DMat4, DVec3, Vec3, Vec4};
use rayon::prelude::*;

use crate::scene::{Primitive, Skin};

/// Primitives with more vertices than this are deformed on rayon's threads.
const PARALLEL_VERTICES: usize = 10_000;

/// Vertices per parallel work item.
const CHUNK: usize = 4096;

/// A primitive's deformed vertex attributes, indexed like its own.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Deformed {
    /// Positions.
    pub positions: Vec<Vec3>,
    /// Unit normals; empty when the primitive has none.
    pub normals: Vec<Vec3>,
    /// Tangents with unit xyz and the input's w (negated where a joint mirrors); empty when
    /// the primitive has none.
    pub tangents: Vec<Vec4>,
}

/// Per joint of `skin`, `world(joint) · inverse_bind(joint)`: mesh (bind) space to the
/// joint's current placement. `joint_world(node)` gives a joint node's world transform
/// ([`crate::animation::world_transforms`]); a joint for which it answers `None` (a node
/// the scene does not place) counts as the identity, and a missing inverse bind matrix
/// too.
pub fn joint_matrices(skin: &Skin, joint_world: impl Fn(u32) -> Option<DMat4>) -> Vec<DMat4> {
    skin.joints
        .iter()
        .enumerate()
        .map(|(j, &node)| {
            let world = joint_world(node).unwrap_or(DMat4::IDENTITY);
            let inverse_bind = skin.inverse_bind.get(j).copied().unwrap_or(DMat4::IDENTITY);
            world * inverse_bind
        })
        .collect()
}

/// Deforms `prim`: morph targets first (each target's displacements times its weight in
/// `weights`; a weight without a target is ignored, a target without a weight counts 0),
/// then, with `joints` (from [`joint_matrices`]), linear blend skinning over all joint sets
/// in f64: positions by the blended matrix, normals by its inverse transpose, tangents'
/// xyz by the blended matrix with w kept (negated where the matrix mirrors), normals and
/// tangents renormalised. See the module docs for zero weight sums and degenerate results.
/// Large primitives run in parallel.
pub fn deform(prim: &Primitive, weights: &[f32], joints: Option<&[DMat4]>) -> Deformed {
    let n = prim.positions.len();
    let has_normals = prim.normals.len() == n && n > 0;
    let has_tangents = prim.tangents.len() == n && n > 0;
    let mut out = Deformed {
        positions: vec![Vec3::ZERO; n],
        normals: vec![Vec3::ZERO; if has_normals { n } else { 0 }],
        tangents: vec![Vec4::ZERO; if has_tangents { n } else { 0 }],
    };
    // Only targets that carry a weight, and only their attributes with one entry per vertex.
    let targets: Vec<Active<'_>> = prim
        .targets
        .iter()
        .zip(weights)
        .filter(|(_, &w)| w != 0.0 && w.is_finite())
        .map(|(t, &w)| Active {
            weight: w as f64,
            positions: per_vertex(&t.positions, n),
            normals: per_vertex(&t.normals, n).filter(|_| has_normals),
            tangents: per_vertex(&t.tangents, n).filter(|_| has_tangents),
        })
        .collect();
    let job = Job {
        prim,
        targets: &targets,
        joints,
    };

    if n > PARALLEL_VERTICES {
        let mut normals = out.normals.chunks_mut(CHUNK);
        let mut tangents = out.tangents.chunks_mut(CHUNK);
        let work: Vec<_> = out
            .positions
            .chunks_mut(CHUNK)
            .enumerate()
            .map(|(c, p)| {
                let nrm: &mut [Vec3] = normals.next().unwrap_or(&mut []);
                let tan: &mut [Vec4] = tangents.next().unwrap_or(&mut []);
                (c * CHUNK, p, nrm, tan)
            })
            .collect();
        work.into_par_iter()
            .for_each(|(start, p, nrm, tan)| job.run(start, p, nrm, tan));
    } else {
        job.run(0, &mut out.positions, &mut out.normals, &mut out.tangents);
    }
    out
}

/// `v` when it has one entry per vertex, else `None` (the target lacks the attribute).
fn per_vertex<T>(v: &[T], n: usize) -> Option<&[T]> {
    (v.len() == n && n > 0).then_some(v)
}

/// A morph target with a non-zero weight.
struct Active<'a> {
    weight: f64,
    positions: Option<&'a [Vec3]>,
    normals: Option<&'a [Vec3]>,
    tangents: Option<&'a [Vec3]>,
}

/// Everything one vertex needs.
struct Job<'a> {
    prim: &'a Primitive,
    targets: &'a [Active<'a>],
    joints: Option<&'a [DMat4]>,
}

impl Job<'_> {
    /// Deforms vertices `start..start + pos.len()` into the given slices (`nrm` and `tan`
    /// empty when the primitive lacks them).
    fn run(&self, start: usize, pos: &mut [Vec3], nrm: &mut [Vec3], tan: &mut [Vec4]) {
        let prim = self.prim;
        for (k, out_p) in pos.iter_mut().enumerate() {
            let v = start + k;

            // Morph: base attributes plus weighted displacements, in f64.
            let p_in = prim.positions[v];
            let mut p = p_in.as_dvec3();
            let mut n = nrm.get(k).map(|_| prim.normals[v].as_dvec3());
            let mut t = tan.get(k).map(|_| prim.tangents[v].truncate().as_dvec3());
            for target in self.targets {
                let w = target.weight;
                if let Some(d) = target.positions {
                    p += w * d[v].as_dvec3();
                }
                if let (Some(n), Some(d)) = (n.as_mut(), target.normals) {
                    *n += w * d[v].as_dvec3();
                }
                if let (Some(t), Some(d)) = (t.as_mut(), target.tangents) {
                    *t += w * d[v].as_dvec3();
                }
            }
            let p_morphed = finite_or(p, p_in.as_dvec3());

            // Skin: one blended matrix for the vertex.
            let blend = self.joints.and_then(|j| blend(prim, j, v));
            let (p, n, t, w_sign) = match blend {
                Some(m) => {
                    let m3 = DMat3::from_mat4(m);
                    let det = m3.determinant();
                    // The cofactor matrix is det · M⁻ᵀ: it gives normal directions even for a
                    // singular M, and the sign of det makes it point like M⁻ᵀ would. A mirror
                    // also reverses the bitangent, cross(normal, tangent) · w: w turns too.
                    let sign = if det < 0.0 { -1.0 } else { 1.0 };
                    (
                        m.transform_point3(p_morphed),
                        n.map(|n| cofactor(&m3) * sign * n),
                        t.map(|t| m3 * t),
                        sign as f32,
                    )
                }
                None => (p_morphed, n, t, 1.0),
            };

            *out_p = finite_or(p, p_morphed).as_vec3();
            if let (Some(o), Some(n)) = (nrm.get_mut(k), n) {
                *o = unit_or(n, prim.normals[v], Vec3::Z);
            }
            if let (Some(o), Some(t)) = (tan.get_mut(k), t) {
                let t_in = prim.tangents[v];
                *o = unit_or(t, t_in.truncate(), Vec3::X).extend(t_in.w * w_sign);
            }
        }
    }
}

/// The weighted sum of vertex `v`'s joint matrices over every joint set, divided by the sum
/// of the weights used; `None` when no usable influence remains (the vertex is not moved by
/// joints) or the result is not finite.
fn blend(prim: &Primitive, joints: &[DMat4], v: usize) -> Option<DMat4> {
    let mut sum = DMat4::ZERO;
    let mut total = 0.0f64;
    for set in &prim.joint_sets {
        let (Some(js), Some(ws)) = (set.joints.get(v), set.weights.get(v)) else {
            continue;
        };
        for (&j, &w) in js.iter().zip(ws) {
            if w == 0.0 || !w.is_finite() {
                continue;
            }
            let Some(m) = joints.get(j as usize) else {
                continue;
            };
            sum += *m * w as f64;
            total += w as f64;
        }
    }
    if !(total > 1e-12) {
        return None;
    }
    let m = sum * (1.0 / total);
    m.is_finite().then_some(m)
}

/// The cofactor matrix of `m` (the transpose of its adjugate): `det(m) · m⁻ᵀ`.
fn cofactor(m: &DMat3) -> DMat3 {
    DMat3::from_cols(
        m.y_axis.cross(m.z_axis),
        m.z_axis.cross(m.x_axis),
        m.x_axis.cross(m.y_axis),
    )
}

fn finite_or(v: DVec3, fallback: DVec3) -> DVec3 {
    if v.is_finite() {
        v
    } else {
        fallback
    }
}

/// `v` normalised, else `fallback` normalised, else `last`.
fn unit_or(v: DVec3, fallback: Vec3, last: Vec3) -> Vec3 {
    match v.try_normalize() {
        Some(u) => u.as_vec3(),
        None => fallback.try_normalize().unwrap_or(last),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{JointSet, MorphTarget};
    use glam::DQuat;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).abs().max_element() < 1e-6
    }

    fn tri() -> Primitive {
        Primitive {
            positions: vec![Vec3::new(1.0, 0.0, 0.0), Vec3::Y, Vec3::Z],
            normals: vec![Vec3::Z; 3],
            tangents: vec![Vec4::new(1.0, 0.0, 0.0, -1.0); 3],
            indices: vec![[0, 1, 2]],
            ..Default::default()
        }
    }

    #[test]
    fn cofactor_is_det_times_inverse_transpose() {
        let m = DMat3::from_cols_array(&[2.0, 0.5, 0.0, -1.0, 3.0, 0.25, 0.0, 1.0, 4.0]);
        let want = m.inverse().transpose() * m.determinant();
        assert!(cofactor(&m).abs_diff_eq(want, 1e-12));
    }

    #[test]
    fn morph_ignores_extra_weights_and_missing_targets_count_zero() {
        let mut p = tri();
        p.targets = vec![
            MorphTarget {
                positions: vec![Vec3::new(0.0, 0.0, 2.0); 3],
                normals: vec![Vec3::new(1.0, 0.0, -1.0); 3],
                tangents: Vec::new(),
            },
            MorphTarget {
                positions: vec![Vec3::new(10.0, 0.0, 0.0); 3],
                ..Default::default()
            },
        ];
        // One weight for two targets: the second counts 0; a third weight is ignored.
        let d = deform(&p, &[0.5], None);
        assert!(close(d.positions[0], Vec3::new(1.0, 0.0, 1.0)));
        let s = 0.5f32.sqrt();
        assert!(
            close(d.normals[0], Vec3::new(s, 0.0, s)),
            "{}",
            d.normals[0]
        );
        assert_eq!(d.tangents[0], Vec4::new(1.0, 0.0, 0.0, -1.0));
        let d = deform(&p, &[0.0, 0.0, 7.0], None);
        assert_eq!(d.positions, p.positions);
        // A normal that cancels out falls back to the input one.
        let d = deform(&p, &[1.0], None);
        assert!(close(d.normals[0], Vec3::X));
        let mut q = p.clone();
        q.targets[0].normals = vec![Vec3::new(0.0, 0.0, -1.0); 3];
        let d = deform(&q, &[1.0], None);
        assert_eq!(d.normals[0], Vec3::Z);
    }

    #[test]
    fn skinning_blends_normalises_and_leaves_zero_weight_vertices_alone() {
        let mut p = tri();
        p.joint_sets = vec![JointSet {
            joints: vec![[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0]],
            // Vertex 0: 0.25/0.25, normalised to 0.5/0.5; vertex 2: no weight at all.
            weights: vec![[0.25, 0.25, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0; 4]],
        }];
        let joints = [
            DMat4::IDENTITY,
            DMat4::from_rotation_translation(
                DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2),
                DVec3::new(0.0, 0.0, 1.0),
            ),
        ];
        let d = deform(&p, &[], Some(&joints));
        // Joint 1 takes (1,0,0) to (0,1,1); halfway with joint 0's (1,0,0).
        assert!(
            close(d.positions[0], Vec3::new(0.5, 0.5, 0.5)),
            "{}",
            d.positions[0]
        );
        // (0,1,0) rotated 90° about Z is (-1,0,0), then lifted by 1.
        assert!(close(d.positions[1], Vec3::new(-1.0, 0.0, 1.0)));
        assert_eq!(d.positions[2], Vec3::Z);
        assert!(close(d.tangents[1].truncate(), Vec3::Y));
        assert_eq!(d.tangents[1].w, -1.0);
        assert!(close(d.normals[1], Vec3::Z));
    }

    #[test]
    fn singular_and_mirrored_joints_give_no_nan() {
        let mut p = tri();
        p.joint_sets = vec![JointSet {
            joints: vec![[0; 4], [1, 0, 0, 0], [7, 0, 0, 0]],
            weights: vec![[1.0, 0.0, 0.0, 0.0]; 3],
        }];
        let joints = [
            DMat4::from_scale(DVec3::ZERO),
            DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0)),
        ];
        let d = deform(&p, &[], Some(&joints));
        assert_eq!(d.positions[0], Vec3::ZERO);
        assert_eq!(
            d.normals[0],
            Vec3::Z,
            "a collapsed normal falls back to the input"
        );
        // Mirroring in x keeps a +Z normal: M⁻ᵀ (0,0,1) = (0,0,1).
        assert!(close(d.normals[1], Vec3::Z));
        assert!(close(d.positions[1], Vec3::Y));
        // Joint 7 does not exist: vertex 2 is not moved by joints.
        assert_eq!(d.positions[2], Vec3::Z);
        let nan = [DMat4::from_scale(DVec3::splat(f64::NAN)); 2];
        let d = deform(&p, &[], Some(&nan));
        assert_eq!(d.positions, p.positions);
    }

    #[test]
    fn large_primitives_deform_in_parallel_alike() {
        let n = PARALLEL_VERTICES + 2 * CHUNK + 17;
        let positions: Vec<Vec3> = (0..n).map(|i| Vec3::new(i as f32, 1.0, 0.0)).collect();
        let p = Primitive {
            normals: vec![Vec3::Y; n],
            joint_sets: vec![JointSet {
                joints: vec![[0, 1, 0, 0]; n],
                weights: vec![[0.5, 0.5, 0.0, 0.0]; n],
            }],
            targets: vec![MorphTarget {
                positions: vec![Vec3::Z; n],
                ..Default::default()
            }],
            positions,
            ..Default::default()
        };
        let joints = [
            DMat4::IDENTITY,
            DMat4::from_translation(DVec3::new(0.0, 2.0, 0.0)),
        ];
        let d = deform(&p, &[1.0], Some(&joints));
        assert_eq!(d.positions.len(), n);
        assert!(d.tangents.is_empty());
        for (i, q) in d.positions.iter().enumerate() {
            assert!(close(*q, Vec3::new(i as f32, 2.0, 1.0)), "vertex {i}: {q}");
        }
        assert!(d.normals.iter().all(|&m| m == Vec3::Y));
    }

    #[test]
    fn joint_matrices_use_identity_for_unplaced_joints() {
        let skin = Skin {
            name: None,
            joints: vec![3, 5],
            inverse_bind: vec![DMat4::from_translation(DVec3::new(-1.0, 0.0, 0.0))],
        };
        let m = joint_matrices(&skin, |j| {
            (j == 3).then(|| DMat4::from_translation(DVec3::new(0.0, 4.0, 0.0)))
        });
        assert_eq!(m[0], DMat4::from_translation(DVec3::new(-1.0, 4.0, 0.0)));
        assert_eq!(m[1], DMat4::IDENTITY);
    }
}
