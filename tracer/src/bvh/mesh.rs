//! The per-mesh BVH over triangles in object space.

use glam::{DVec3, Vec3};

use super::build::{self, BuildParams, BuildPrim};
use super::node::{ray_is_valid, traverse, BoxRay, Node};
use crate::geometry::{Aabb, Ray};
use crate::triangle::{intersect_triangle, RayPrecomputed};

/// SAH costs for triangles. A node visit (two slab tests) and a watertight triangle test
/// cost about the same; leaves of up to 8 triangles let SAH keep flat clusters together.
const PARAMS: BuildParams = BuildParams {
    max_leaf: 8,
    traversal_cost: 1.0,
    intersect_cost: 1.0,
};

/// A mesh's BVH over its triangles in object space, built once and shared by every
/// instance of the mesh.
///
/// The BVH owns a copy of the vertex positions, reordered so that each leaf's triangles are
/// contiguous: traversal reads nodes and positions only, never an index buffer. Triangles
/// are reported by their index in the slice given to [`MeshBvh::build`].
#[derive(Clone, Default)]
pub struct MeshBvh {
    nodes: Vec<Node>,
    /// Vertex positions in leaf order.
    triangles: Vec<[Vec3; 3]>,
    /// `ids[i]` is the caller's index of `triangles[i]`.
    ids: Vec<u32>,
}

impl std::fmt::Debug for MeshBvh {
    // A summary: a scene's debug print should not list a million nodes.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MeshBvh")
            .field("triangles", &self.triangles.len())
            .field("nodes", &self.nodes.len())
            .field("bounds", &self.bounds())
            .finish()
    }
}

/// Whether a triangle can ever be hit: finite vertices and a non-zero area. The area test
/// is done in f64, where it is exact enough that only truly collinear vertices fail; such a
/// triangle covers no area but could still produce sliver hits after the ray's shear.
fn is_usable(t: &[Vec3; 3]) -> bool {
    if !(t[0].is_finite() && t[1].is_finite() && t[2].is_finite()) {
        return false;
    }
    let [a, b, c] = t.map(|v| v.as_dvec3());
    (b - a).cross(c - a) != DVec3::ZERO
}

impl MeshBvh {
    /// Builds the hierarchy over `triangles` (vertex positions, object space) with a binned
    /// SAH (see `bvh/build.rs`). Triangles with a non-finite vertex or zero area are left
    /// out: they can never be hit. Any input is accepted, including none.
    ///
    /// # Panics
    /// If there are more than `u32::MAX` triangles (hits name triangles by `u32`).
    pub fn build(triangles: &[[Vec3; 3]]) -> Self {
        assert!(
            u32::try_from(triangles.len()).is_ok(),
            "more than 2^32 - 1 triangles in one mesh"
        );
        let mut prims: Vec<BuildPrim> = triangles
            .iter()
            .enumerate()
            .filter(|(_, t)| is_usable(t))
            .map(|(i, t)| BuildPrim {
                min: t[0].min(t[1]).min(t[2]),
                max: t[0].max(t[1]).max(t[2]),
                index: i as u32,
            })
            .collect();
        let nodes = build::build(&mut prims, &PARAMS);
        let triangles = prims.iter().map(|p| triangles[p.index as usize]).collect();
        let ids = prims.iter().map(|p| p.index).collect();
        Self {
            nodes,
            triangles,
            ids,
        }
    }

    /// Bounds of every usable triangle; empty for a mesh with none.
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| Aabb {
            min: n.min,
            max: n.max,
        })
    }

    /// Number of triangles in the hierarchy (the usable ones).
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Heap and inline bytes held: nodes, reordered positions and the index map.
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.triangles.as_slice())
            + std::mem::size_of_val(self.ids.as_slice())
    }

    /// Closest hit with `0 < t < t_max` for which `accept(triangle, b1, b2)` is true,
    /// as `(t, triangle, b1, b2)`. `accept` sees candidate hits in no particular order and
    /// is meant for alpha cut-outs: a rejected hit is ignored and the search goes on.
    /// `ray.dir` need not be unit length; `t` is in its units.
    pub fn intersect(
        &self,
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, f32, f32) -> bool,
    ) -> Option<(f32, u32, f32, f32)> {
        self.search::<false>(ray, t_max, accept)
    }

    /// Whether any triangle with `0 < t < t_max` is hit and accepted by
    /// `accept(triangle, b1, b2)`; stops at the first such hit.
    pub fn occluded(
        &self,
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, f32, f32) -> bool,
    ) -> bool {
        self.search::<true>(ray, t_max, accept).is_some()
    }

    /// The closest accepted hit, or with `ANY_HIT` the first one found (traversal stops
    /// there). A const parameter, so each query compiles to its own loop.
    #[inline(always)]
    pub(super) fn search<const ANY_HIT: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
        mut accept: impl FnMut(u32, f32, f32) -> bool,
    ) -> Option<(f32, u32, f32, f32)> {
        if !ray_is_valid(ray, t_max) {
            return None;
        }
        let pre = RayPrecomputed::new(ray);
        let mut t_max = t_max;
        let mut best = None;
        traverse(
            &self.nodes,
            &BoxRay::new(ray),
            &mut t_max,
            |start, count, t_max| {
                let range = start as usize..(start + count) as usize;
                for (tri, &id) in self.triangles[range.clone()].iter().zip(&self.ids[range]) {
                    if let Some((t, b1, b2)) =
                        intersect_triangle(&pre, tri[0], tri[1], tri[2], *t_max)
                    {
                        if accept(id, b1, b2) {
                            *t_max = t;
                            best = Some((t, id, b1, b2));
                            if ANY_HIT {
                                return true;
                            }
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

    use crate::test_rng::Rng;

    fn soup(rng: &mut Rng, n: usize) -> Vec<[Vec3; 3]> {
        (0..n)
            .map(|_| {
                let c = rng.vec3() * 10.0;
                [
                    c + rng.vec3() - 0.5,
                    c + rng.vec3() - 0.5,
                    c + rng.vec3() - 0.5,
                ]
            })
            .collect()
    }

    fn brute(tris: &[[Vec3; 3]], ray: &Ray, t_max: f32) -> Option<(f32, u32)> {
        let pre = RayPrecomputed::new(ray);
        let mut best: Option<(f32, u32)> = None;
        for (i, t) in tris.iter().enumerate() {
            let limit = best.map_or(t_max, |b| b.0);
            if let Some((t, ..)) = intersect_triangle(&pre, t[0], t[1], t[2], limit) {
                best = Some((t, i as u32));
            }
        }
        best
    }

    #[test]
    fn empty_mesh_hits_nothing() {
        let bvh = MeshBvh::build(&[]);
        assert!(bvh.bounds().is_empty());
        assert_eq!(bvh.node_count(), 0);
        let ray = Ray::new(Vec3::ZERO, Vec3::X);
        assert!(bvh.intersect(&ray, f32::INFINITY, |_, _, _| true).is_none());
        assert!(!bvh.occluded(&ray, f32::INFINITY, |_, _, _| true));
    }

    #[test]
    fn nan_and_degenerate_triangles_are_skipped_and_indices_kept() {
        let good = [
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
        ];
        let tris = [
            [Vec3::NAN, Vec3::ONE, Vec3::ZERO],
            [Vec3::ONE; 3],
            [Vec3::ZERO, Vec3::ONE, Vec3::splat(2.0)],
            [Vec3::INFINITY, Vec3::ONE, Vec3::ZERO],
            good,
        ];
        let bvh = MeshBvh::build(&tris);
        assert_eq!(bvh.triangle_count(), 1);
        assert_eq!(
            bvh.bounds(),
            Aabb {
                min: Vec3::new(0.0, 0.0, 1.0),
                max: Vec3::new(1.0, 1.0, 1.0)
            }
        );
        let hit = bvh.intersect(
            &Ray::new(Vec3::new(0.25, 0.25, 0.0), Vec3::Z),
            5.0,
            |_, _, _| true,
        );
        assert_eq!(hit, Some((1.0, 4, 0.25, 0.25)));
    }

    #[test]
    fn invalid_rays_hit_nothing() {
        let bvh = MeshBvh::build(&soup(&mut Rng(7), 100));
        for (o, d, t) in [
            (Vec3::splat(5.0), Vec3::ZERO, f32::INFINITY),
            (Vec3::splat(5.0), Vec3::NAN, f32::INFINITY),
            (Vec3::NAN, Vec3::X, f32::INFINITY),
            (Vec3::splat(-1.0), Vec3::ONE, f32::NAN),
            (Vec3::splat(-1.0), Vec3::ONE, 0.0),
        ] {
            assert!(bvh.intersect(&Ray::new(o, d), t, |_, _, _| true).is_none());
            assert!(!bvh.occluded(&Ray::new(o, d), t, |_, _, _| true));
        }
    }

    #[test]
    fn matches_brute_force_on_a_soup() {
        let mut rng = Rng(0x2545f4914f6cdd1d);
        let tris = soup(&mut rng, 3000);
        let bvh = MeshBvh::build(&tris);
        assert_eq!(bvh.triangle_count(), 3000);
        for i in 0..3000 {
            let o = rng.vec3() * 14.0 - 2.0;
            let d = rng.vec3() - 0.5;
            let t_max = if i % 3 == 0 { 4.0 } else { f32::INFINITY };
            let ray = Ray::new(o, d);
            let expect = brute(&tris, &ray, t_max);
            let got = bvh
                .intersect(&ray, t_max, |_, _, _| true)
                .map(|h| (h.0, h.1));
            assert_eq!(got, expect, "ray {o} {d}");
            assert_eq!(bvh.occluded(&ray, t_max, |_, _, _| true), expect.is_some());
        }
    }

    #[test]
    fn rejected_hits_are_skipped() {
        // Three parallel quads along +z; reject the nearest, then everything.
        let quad = |z: f32| {
            let (a, b, c, d) = (
                Vec3::new(0.0, 0.0, z),
                Vec3::new(1.0, 0.0, z),
                Vec3::new(1.0, 1.0, z),
                Vec3::new(0.0, 1.0, z),
            );
            [[a, b, c], [a, c, d]]
        };
        let tris: Vec<[Vec3; 3]> = [1.0, 2.0, 3.0].into_iter().flat_map(quad).collect();
        let bvh = MeshBvh::build(&tris);
        let ray = Ray::new(Vec3::new(0.7, 0.2, 0.0), Vec3::Z);
        assert_eq!(
            bvh.intersect(&ray, 10.0, |_, _, _| true)
                .map(|h| (h.0, h.1)),
            Some((1.0, 0))
        );
        let hit = bvh.intersect(&ray, 10.0, |tri, _, _| tri >= 2);
        assert_eq!(hit.map(|h| (h.0, h.1)), Some((2.0, 2)));
        assert!(bvh.intersect(&ray, 10.0, |_, _, _| false).is_none());
        assert!(!bvh.occluded(&ray, 10.0, |_, _, _| false));
        assert!(bvh.occluded(&ray, 10.0, |tri, _, _| tri == 4));
        assert!(!bvh.occluded(&ray, 2.5, |tri, _, _| tri == 4));
    }

    #[test]
    fn memory_is_reported() {
        let bvh = MeshBvh::build(&soup(&mut Rng(3), 1000));
        assert!(bvh.memory_bytes() >= 1000 * (36 + 4) + bvh.node_count() * 32);
    }
}
