//! Bounding volume hierarchies: a binned-SAH BVH per mesh (built once, shared by every
//! instance) and a top-level BVH over the instances of a prepared frame.
//! OWNER: helper A (interface draft).

use crate::geometry::{Aabb, Ray};
use glam::Vec3;

/// A mesh's BVH over its triangles in object space.
#[derive(Debug, Default)]
pub struct MeshBvh {}

impl MeshBvh {
    /// Builds the hierarchy over `triangles` (vertex positions, object space).
    pub fn build(triangles: &[[Vec3; 3]]) -> Self {
        let _ = triangles;
        todo!("helper A")
    }

    /// Bounds of the whole mesh.
    pub fn bounds(&self) -> Aabb {
        todo!("helper A")
    }

    /// Closest hit with `t` in (0, t_max) for which `accept(triangle, b1, b2)` is true.
    pub fn intersect(
        &self,
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, f32, f32) -> bool,
    ) -> Option<(f32, u32, f32, f32)> {
        let _ = (ray, t_max, accept);
        todo!("helper A")
    }
}
