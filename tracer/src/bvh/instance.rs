//! Instances (a mesh placed by a transform) and the top-level BVH over them.

use glam::{Affine3A, Mat3A, Vec3};

use super::build::{self, BuildParams, BuildPrim};
use super::node::{ray_is_valid, traverse, BoxRay, Node};
use crate::geometry::{Aabb, Hit, Ray};
use crate::scene::Mesh;
use crate::triangle::gamma;

/// SAH costs for instances: testing one means transforming the ray and entering a mesh
/// BVH, several box tests' worth, so SAH splits down to small leaves.
const PARAMS: BuildParams = BuildParams {
    max_leaf: 2,
    traversal_cost: 1.0,
    intersect_cost: 3.0,
};

/// One mesh placed in the prepared frame's world space.
///
/// Rays enter the mesh through [`Instance::object_ray`], which keeps the direction's length
/// as the transform makes it, so `t` means the same point in both spaces. With motion blur
/// an instance will carry several transforms over the shutter; `object_ray` (which already
/// receives the ray's time) and `bounds` (then covering the whole shutter) are the places
/// that will change.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// Index of the mesh in the scene's mesh list.
    pub mesh: u32,
    /// Object space to world space.
    pub to_world: Affine3A,
    /// World space to object space; all zeros when `to_world` is singular.
    pub to_object: Affine3A,
    /// Inverse transpose of `to_world`'s linear part, for normals (not normalised: scale
    /// the result). All zeros when `to_world` is singular.
    pub normal_to_world: Mat3A,
    /// World-space bounds, padded for the rounding of the transform; empty when the
    /// instance can never be hit.
    pub bounds: Aabb,
}

impl Instance {
    /// Places mesh `mesh`, whose object-space bounds are `mesh_bounds`, with `to_world`.
    ///
    /// A `to_world` that cannot be inverted (a zero scale, a non-finite entry, or one so
    /// small that the inverse overflows) gives an instance with empty bounds and zero
    /// inverse matrices: it is never hit, and nothing derived from it is NaN.
    pub fn new(mesh: u32, to_world: Affine3A, mesh_bounds: &Aabb) -> Instance {
        let det = to_world.matrix3.determinant();
        let to_object = if to_world.is_finite() && det != 0.0 && det.is_finite() {
            Some(to_world.inverse()).filter(|inv| inv.is_finite())
        } else {
            None
        };
        match to_object {
            Some(to_object) => Instance {
                mesh,
                to_world,
                to_object,
                normal_to_world: to_object.matrix3.transpose(),
                bounds: transform_bounds(&to_world, mesh_bounds),
            },
            None => Instance {
                mesh,
                to_world,
                to_object: Affine3A::ZERO,
                normal_to_world: Mat3A::ZERO,
                bounds: Aabb::EMPTY,
            },
        }
    }

    /// Whether any ray can hit this instance.
    pub fn is_hittable(&self) -> bool {
        !self.bounds.is_empty()
    }

    /// The world ray in the mesh's object space. The direction is transformed but not
    /// renormalised, so ray parameters agree between the two spaces.
    pub fn object_ray(&self, ray: &Ray) -> Ray {
        Ray {
            origin: self.to_object.transform_point3(ray.origin),
            dir: self.to_object.transform_vector3(ray.dir),
            time: ray.time,
        }
    }
}

/// World bounds of an object-space box: its eight corners transformed, each widened by a
/// bound on the rounding of `m·p + t` (three products and three sums: gamma(3), taken as
/// gamma(4) to cover the rounding of the bound itself), so that no world-space point of
/// the mesh can fall outside the box the top level tests.
fn transform_bounds(m: &Affine3A, b: &Aabb) -> Aabb {
    if b.is_empty() {
        return Aabb::EMPTY;
    }
    let abs_m = m.matrix3.abs();
    let abs_t = Vec3::from(m.translation.abs());
    let mut out = Aabb::EMPTY;
    for c in b.corners() {
        let p = m.transform_point3(c);
        let err = (abs_m.mul_vec3(c.abs()) + abs_t) * gamma(4);
        out.grow(p - err);
        out.grow(p + err);
    }
    out
}

/// The top-level BVH over a prepared frame's instances, built with a binned SAH over
/// their world bounds. Hits name instances by their index in the list given to
/// [`SceneBvh::build`], which [`SceneBvh::instances`] returns unchanged.
#[derive(Clone, Default)]
pub struct SceneBvh {
    instances: Vec<Instance>,
    nodes: Vec<Node>,
    /// Instance indices in leaf order.
    order: Vec<u32>,
}

impl std::fmt::Debug for SceneBvh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SceneBvh")
            .field("instances", &self.instances.len())
            .field("nodes", &self.nodes.len())
            .field("bounds", &self.bounds())
            .finish()
    }
}

impl SceneBvh {
    /// Builds the hierarchy over `instances`. Instances that cannot be hit (empty bounds)
    /// stay in the list but not in the tree.
    ///
    /// # Panics
    /// If there are more than `u32::MAX` instances.
    pub fn build(instances: Vec<Instance>) -> SceneBvh {
        assert!(
            u32::try_from(instances.len()).is_ok(),
            "more than 2^32 - 1 instances"
        );
        // Bounds that overflowed to infinity are clamped so that centroids stay finite.
        let limit = Vec3::splat(f32::MAX);
        let mut prims: Vec<BuildPrim> = instances
            .iter()
            .enumerate()
            .filter(|(_, inst)| inst.is_hittable())
            .map(|(i, inst)| BuildPrim {
                min: inst.bounds.min.clamp(-limit, limit),
                max: inst.bounds.max.clamp(-limit, limit),
                index: i as u32,
            })
            .collect();
        let nodes = build::build(&mut prims, &PARAMS);
        let order = prims.iter().map(|p| p.index).collect();
        SceneBvh {
            instances,
            nodes,
            order,
        }
    }

    /// The instances, in the order given to [`SceneBvh::build`].
    pub fn instances(&self) -> &[Instance] {
        &self.instances
    }

    /// World bounds of every hittable instance; empty when there is none.
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| Aabb {
            min: n.min,
            max: n.max,
        })
    }

    /// Number of top-level nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Bytes held by the top level (not counting the meshes' BVHs).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + std::mem::size_of_val(self.instances.as_slice())
            + std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.order.as_slice())
    }

    /// Closest hit with `0 < t < t_max` for which `accept(instance, triangle, b1, b2)` is
    /// true. `meshes` are the meshes the instances index; `ray.dir` need not be unit
    /// length and `t` is in its units. A rejected hit (an alpha cut-out) is ignored and the
    /// search goes on.
    ///
    /// # Panics
    /// If an instance names a mesh outside `meshes`.
    pub fn intersect(
        &self,
        meshes: &[Mesh],
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, u32, f32, f32) -> bool,
    ) -> Option<Hit> {
        self.search::<false>(meshes, ray, t_max, accept)
    }

    /// Whether anything with `0 < t < t_max` accepted by `accept(instance, triangle, b1,
    /// b2)` lies on the ray; stops at the first such hit (shadow rays).
    ///
    /// # Panics
    /// If an instance names a mesh outside `meshes`.
    pub fn occluded(
        &self,
        meshes: &[Mesh],
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, u32, f32, f32) -> bool,
    ) -> bool {
        self.search::<true>(meshes, ray, t_max, accept).is_some()
    }

    /// The closest accepted hit, or with `ANY_HIT` the first one found.
    #[inline(always)]
    fn search<const ANY_HIT: bool>(
        &self,
        meshes: &[Mesh],
        ray: &Ray,
        t_max: f32,
        mut accept: impl FnMut(u32, u32, f32, f32) -> bool,
    ) -> Option<Hit> {
        if !ray_is_valid(ray, t_max) {
            return None;
        }
        let mut t_max = t_max;
        let mut best = None;
        traverse(
            &self.nodes,
            &BoxRay::new(ray),
            &mut t_max,
            |start, count, t_max| {
                for &instance in &self.order[start as usize..(start + count) as usize] {
                    let inst = &self.instances[instance as usize];
                    let bvh = &meshes[inst.mesh as usize].bvh;
                    let hit =
                        bvh.search::<ANY_HIT>(&inst.object_ray(ray), *t_max, |tri, b1, b2| {
                            accept(instance, tri, b1, b2)
                        });
                    if let Some((t, triangle, b1, b2)) = hit {
                        *t_max = t;
                        best = Some(Hit {
                            t,
                            instance,
                            triangle,
                            b1,
                            b2,
                        });
                        if ANY_HIT {
                            return true;
                        }
                    }
                }
                false
            },
        );
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Primitive;
    use glam::Quat;

    fn quad_mesh() -> Mesh {
        let prim = Primitive {
            positions: vec![
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            ..Default::default()
        };
        Mesh::new(None, vec![prim])
    }

    #[test]
    fn singular_transforms_give_unhittable_instances_without_nan() {
        let mesh = quad_mesh();
        for m in [
            Affine3A::from_scale(Vec3::ZERO),
            Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0)),
            Affine3A::from_scale(Vec3::splat(1e-30)),
            Affine3A::from_translation(Vec3::new(f32::NAN, 0.0, 0.0)),
        ] {
            let inst = Instance::new(0, m, &mesh.bvh.bounds());
            assert!(!inst.is_hittable());
            assert!(inst.to_object.is_finite() && !inst.normal_to_world.is_nan());
            let scene = SceneBvh::build(vec![inst]);
            assert!(scene.bounds().is_empty());
            let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z);
            assert!(scene
                .intersect(&[quad_mesh()], &ray, f32::INFINITY, |_, _, _, _| true)
                .is_none());
        }
    }

    #[test]
    fn t_is_the_same_in_world_and_object_space() {
        let meshes = [quad_mesh()];
        let m = Affine3A::from_scale_rotation_translation(
            Vec3::splat(3.0),
            Quat::from_rotation_y(0.3),
            Vec3::new(1.0, 2.0, -4.0),
        );
        let scene = SceneBvh::build(vec![Instance::new(0, m, &meshes[0].bvh.bounds())]);
        let target = m.transform_point3(Vec3::new(0.2, 0.1, 0.0));
        let origin = Vec3::new(0.5, 2.5, 10.0);
        let hit = scene
            .intersect(
                &meshes,
                &Ray::new(origin, (target - origin) * 0.5),
                10.0,
                |_, _, _, _| true,
            )
            .unwrap();
        assert!((hit.t - 2.0).abs() < 1e-5, "t = {}", hit.t);
        assert_eq!(hit.instance, 0);
    }

    #[test]
    fn normal_matrix_is_the_inverse_transpose() {
        let m = Affine3A::from_scale_rotation_translation(
            Vec3::new(1.0, 4.0, -2.0),
            Quat::from_rotation_x(0.7),
            Vec3::ONE,
        );
        let inst = Instance::new(0, m, &Aabb::from_points(Vec3::ZERO, Vec3::ONE));
        // A normal stays perpendicular to transformed tangents.
        let (n, t) = (
            Vec3::new(1.0, 2.0, 3.0).normalize(),
            Vec3::new(2.0, -1.0, 0.0),
        );
        let nw = inst.normal_to_world.mul_vec3(n);
        assert!(nw.dot(m.transform_vector3(t)).abs() < 1e-5);
    }

    #[test]
    fn instance_bounds_hold_the_transformed_mesh() {
        let mesh = quad_mesh();
        let m = Affine3A::from_rotation_translation(Quat::from_rotation_z(0.5), Vec3::splat(1e4));
        let inst = Instance::new(0, m, &mesh.bvh.bounds());
        for p in &mesh.primitives[0].positions {
            let w = m.transform_point3(*p);
            assert!(w.cmpge(inst.bounds.min).all() && w.cmple(inst.bounds.max).all());
        }
    }
}
