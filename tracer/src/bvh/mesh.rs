//! The per-mesh BVH over triangles in object space, static or deforming over the shutter.

use glam::{DVec3, Vec3};

use super::build::{self, BuildParams, BuildPrim};
use super::huge_pages::on_huge_pages;
use super::motion::Segment;
use super::node::{
    ray_is_valid, traverse, with_stack, BoxRay, Deferred, MotionBoxes, Node, StepBox,
};
use super::wide::{collapse, leaves, prefetch, traverse_wide, Merge, Walk, WideNode, WideRay};
use crate::geometry::{Aabb, Ray};
#[cfg(target_arch = "x86_64")]
use crate::simd;
use crate::triangle::{intersect_triangle, LaneHit, RayLanes, RayPrecomputed, TriangleRows};

/// SAH costs for triangles. A node visit (two slab tests) and a watertight triangle test
/// cost about the same; leaves of up to 8 triangles let SAH keep flat clusters together.
const PARAMS: BuildParams = BuildParams {
    max_leaf: 8,
    traversal_cost: 1.0,
    intersect_cost: 1.0,
};

/// Eight-wide nodes (16 MiB; with their triangles, past the 32 MiB last-level cache of
/// this machine class) past which a mesh's tree is collapsed again with [`MERGE_LARGE`]. In
/// a tree that large each node a ray visits is a trip to memory, and fewer, fuller nodes
/// over larger leaves are faster: the generated 1M-triangle mesh (104,361 nodes unmerged,
/// 38,215 merged) traces 14%, 3% and 9% more coherent, incoherent and any-hit rays per
/// second merged. In a smaller one the nodes stay in cache and merging only adds triangle
/// tests: 100k, 320k and 605k triangles traced up to 20% fewer, a 4k-triangle model
/// rendered 9% slower (BENCHMARKS.md, "Merged leaves in large meshes"; the 605k mesh's tree
/// has 59,359 nodes). A fixed count, not this machine's cache size: the tree, and so the
/// bits of every hit, must not depend on the machine.
const MERGE_ABOVE: usize = 1 << 16;

/// Subtrees of up to a leaf's most triangles become one leaf where the surface area
/// heuristic prefers it, pricing a node visit (four cache lines, likely missed) at eight
/// triangle tests.
const MERGE_LARGE: Merge = Merge {
    max_leaf: PARAMS.max_leaf,
    node_cost: 8.0,
};

/// A triangle's vertices and the caller's index of it, in one 40-byte record: a leaf reads
/// its triangles' ids from the lines it reads their vertices from, not from a second array.
/// (A deforming mesh's steps; the eight-wide tree's leaves read [`TriangleRows`].)
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
struct LeafTriangle {
    v: [Vec3; 3],
    id: u32,
}

/// A mesh's BVH over its triangles in object space, built once and shared by every
/// instance of the mesh.
///
/// The BVH owns a copy of the vertex positions, reordered so that each leaf's triangles are
/// contiguous: traversal reads nodes and positions only, never an index buffer. Triangles
/// are reported by their index in the slice given to [`MeshBvh::build`].
///
/// Static queries run on eight-wide nodes (`WideNode`, the SAH tree collapsed) whose
/// leaves hold their triangles in blocks of four for the lane test ([`TriangleRows`]). A
/// deforming mesh ([`MeshBvh::build_motion`]) also keeps its positions at each of `S`
/// motion steps, step-major (all triangles at step 0, then all at step 1, ...), and the
/// binary tree, whose 32-byte `Node`s hold the union over the steps, and each binary
/// node's box at every step in a second array (`StepBox`, 24 bytes per node and step). A
/// ray at time `t` sees each triangle and box interpolated linearly between the two
/// bracketing steps.
#[derive(Clone, Default)]
pub struct MeshBvh {
    /// The eight-wide tree, for static queries (boxes over every step).
    wide: Vec<WideNode>,
    /// The eight-wide tree's triangles (at step 0) and ids, in leaf order.
    rows: TriangleRows,
    /// The binary tree, for queries at a time; empty for a static mesh.
    nodes: Vec<Node>,
    /// With motion, vertex positions and ids in leaf order at each step, step-major;
    /// empty without.
    triangles: Vec<LeafTriangle>,
    /// Number of motion steps: 1 for a static mesh (0 for the default, empty one).
    steps: u32,
    /// With motion, node `i`'s box at step `s` at `i·steps + s`; empty without.
    step_boxes: Vec<StepBox>,
}

impl std::fmt::Debug for MeshBvh {
    // A summary: a scene's debug print should not list a million nodes.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MeshBvh")
            .field("triangles", &self.triangle_count())
            .field("nodes", &self.node_count())
            .field("steps", &self.steps)
            .field("bounds", &self.bounds())
            .finish()
    }
}

/// Whether a triangle has a non-zero area. The test is done in f64, where it is exact
/// enough that only truly collinear vertices fail; such a triangle covers no area but could
/// still produce sliver hits after the ray's shear.
fn has_area(t: &[Vec3; 3]) -> bool {
    let [a, b, c] = t.map(|v| v.as_dvec3());
    (b - a).cross(c - a) != DVec3::ZERO
}

fn is_finite(t: &[Vec3; 3]) -> bool {
    t[0].is_finite() && t[1].is_finite() && t[2].is_finite()
}

impl MeshBvh {
    /// Builds the hierarchy over `triangles` (vertex positions, object space) with a binned
    /// SAH (see `bvh/build.rs`). Triangles with a non-finite vertex or zero area are left
    /// out: they can never be hit. Any input is accepted, including none.
    ///
    /// # Panics
    /// If there are more than `u32::MAX` triangles (hits name triangles by `u32`).
    pub fn build(triangles: &[[Vec3; 3]]) -> Self {
        Self::build_steps(&[triangles])
    }

    /// Builds the hierarchy of a deforming mesh: `steps[s][i]` is triangle `i` at motion
    /// step `s`, the steps evenly spaced over the shutter (see [`super::MotionTransform`]
    /// for the time convention). One step gives exactly [`MeshBvh::build`]. A triangle is
    /// left out if any step has a non-finite vertex, or if it has zero area at every step.
    ///
    /// # Panics
    /// If the steps differ in length, or hold more than `u32::MAX` triangles, or if there
    /// are more than `u32::MAX` steps.
    pub fn build_motion(steps: &[Vec<[Vec3; 3]>]) -> Self {
        let steps: Vec<&[[Vec3; 3]]> = steps.iter().map(Vec::as_slice).collect();
        Self::build_steps(&steps)
    }

    fn build_steps(steps: &[&[[Vec3; 3]]]) -> Self {
        Self::build_merging_above(steps, MERGE_ABOVE)
    }

    /// [`Self::build_steps`], merging the tree's small subtrees into leaves when it has more
    /// than `merge_above` eight-wide nodes.
    fn build_merging_above(steps: &[&[[Vec3; 3]]], merge_above: usize) -> Self {
        let Some(first) = steps.first() else {
            return Self::build(&[]);
        };
        let n = first.len();
        assert!(
            steps.iter().all(|s| s.len() == n),
            "motion steps of one mesh differ in triangle count"
        );
        assert!(
            u32::try_from(n).is_ok(),
            "more than 2^32 - 1 triangles in one mesh"
        );
        let step_count = u32::try_from(steps.len()).expect("more than 2^32 - 1 motion steps");
        // Each triangle's box over all steps. The topology is built with the SAH over these
        // unions rather than over one step's boxes: the union is what a node's box spans
        // over the shutter, so SAH groups triangles that stay close *throughout* (the same
        // limb), where mid-step boxes would pair triangles that only cross at mid-shutter
        // and drift apart at both ends, blowing up the interpolated boxes near the steps.
        // For small motion the two agree, and for one step both are the static build.
        let mut prims: Vec<BuildPrim> = (0..n)
            .filter(|&i| {
                steps.iter().all(|s| is_finite(&s[i])) && steps.iter().any(|s| has_area(&s[i]))
            })
            .map(|i| {
                let (mut min, mut max) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
                for t in steps.iter().map(|s| &s[i]) {
                    min = min.min(t[0]).min(t[1]).min(t[2]);
                    max = max.max(t[0]).max(t[1]).max(t[2]);
                }
                BuildPrim {
                    min,
                    max,
                    index: i as u32,
                }
            })
            .collect();
        let nodes = build::build(&mut prims, &PARAMS);
        let wide = collapse(&nodes, None);
        let wide = if wide.len() > merge_above {
            collapse(&nodes, Some(MERGE_LARGE))
        } else {
            wide
        };
        let step_0 = prims.iter().map(|p| (first[p.index as usize], p.index));
        let rows = TriangleRows::new(step_0, &leaves(&wide));
        let (nodes, triangles, step_boxes) = if steps.len() > 1 {
            let triangles: Vec<LeafTriangle> = steps
                .iter()
                .flat_map(|s| {
                    prims.iter().map(|p| LeafTriangle {
                        v: s[p.index as usize],
                        id: p.index,
                    })
                })
                .collect();
            let boxes = step_boxes(&nodes, &triangles, prims.len(), steps.len());
            (nodes, triangles, boxes)
        } else {
            (Vec::new(), Vec::new(), Vec::new())
        };
        Self {
            wide: on_huge_pages(wide),
            rows,
            nodes: on_huge_pages(nodes),
            triangles: on_huge_pages(triangles),
            steps: step_count,
            step_boxes: on_huge_pages(step_boxes),
        }
    }

    /// Whether the mesh deforms over the shutter (it was built from two or more steps).
    pub fn has_motion(&self) -> bool {
        self.steps > 1
    }

    /// Bounds of every usable triangle (over all motion steps); empty for a mesh with none.
    pub fn bounds(&self) -> Aabb {
        self.wide.first().map_or(Aabb::EMPTY, WideNode::bounds)
    }

    /// Number of triangles in the hierarchy (the usable ones).
    pub fn triangle_count(&self) -> usize {
        self.rows.count()
    }

    /// Number of nodes: eight-wide ones, and binary ones for a deforming mesh.
    pub fn node_count(&self) -> usize {
        self.wide.len() + self.nodes.len()
    }

    /// Heap and inline bytes held: nodes, per-step boxes, reordered positions (at every
    /// step) and the index map.
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + std::mem::size_of_val(self.wide.as_slice())
            + self.rows.memory_bytes()
            + std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.step_boxes.as_slice())
            + std::mem::size_of_val(self.triangles.as_slice())
    }

    /// Closest hit with `0 < t < t_max` for which `accept(triangle, b1, b2)` is true,
    /// as `(t, triangle, b1, b2)`. `accept` sees candidate hits in no particular order and
    /// is meant for alpha cut-outs: a rejected hit is ignored and the search goes on.
    /// `ray.dir` need not be unit length; `t` is in its units. A deforming mesh is
    /// intersected as it is at `ray.time`.
    pub fn intersect(
        &self,
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, f32, f32) -> bool,
    ) -> Option<(f32, u32, f32, f32)> {
        with_stack(|stack| {
            if self.has_motion() {
                self.search::<false, true>(ray, t_max, stack, accept)
            } else {
                self.search::<false, false>(ray, t_max, stack, accept)
            }
        })
    }

    /// Whether any triangle with `0 < t < t_max` is hit and accepted by
    /// `accept(triangle, b1, b2)`; stops at the first such hit. A deforming mesh is
    /// intersected as it is at `ray.time`.
    pub fn occluded(
        &self,
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, f32, f32) -> bool,
    ) -> bool {
        with_stack(|stack| {
            if self.has_motion() {
                self.search::<true, true>(ray, t_max, stack, accept)
            } else {
                self.search::<true, false>(ray, t_max, stack, accept)
            }
        })
        .is_some()
    }

    /// [`Self::search_with`] with the node test this process uses (see `simd.rs`).
    #[inline(always)]
    fn search<const ANY_HIT: bool, const MOTION: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
        stack: &mut [Deferred],
        accept: impl FnMut(u32, f32, f32) -> bool,
    ) -> Option<(f32, u32, f32, f32)> {
        #[cfg(target_arch = "x86_64")]
        if simd::avx() {
            let search = || {
                self.search_with::<ANY_HIT, MOTION, true>(ray, t_max, stack, Part::Whole, accept)
            };
            // SAFETY: the CPU has AVX (`simd::avx`).
            return unsafe { simd::with_avx(search) };
        }
        self.search_with::<ANY_HIT, MOTION, false>(ray, t_max, stack, Part::Whole, accept)
    }

    /// The closest accepted hit, or with `ANY_HIT` the first one found (traversal stops
    /// there). With `MOTION`, a deforming mesh is searched at `ray.time`; without, or for a
    /// static mesh, the static loop runs (on a deforming mesh it would find the mesh at
    /// time 0: step 0 comes first and the eight-wide boxes span every step). Const parameters,
    /// so each query compiles to its own loop and a static scene pays nothing for motion.
    /// With `AVX` (only where [`simd::with_avx`] runs it), nodes are tested in AVX lanes.
    /// `part` says whether the whole tree is searched or one lane of its root (see
    /// [`Self::root_parts`]).
    #[inline(always)]
    pub(super) fn search_with<const ANY_HIT: bool, const MOTION: bool, const AVX: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
        stack: &mut [Deferred],
        part: Part,
        mut accept: impl FnMut(u32, f32, f32) -> bool,
    ) -> Option<(f32, u32, f32, f32)> {
        if !ray_is_valid(ray, t_max) {
            return None;
        }
        let mut t_max = t_max;
        let mut best = None;
        if MOTION && self.has_motion() {
            debug_assert_eq!(part, Part::Whole, "a deforming mesh is searched whole");
            let pre = RayPrecomputed::new(ray);
            let steps = self.steps as usize;
            let segment = Segment::new(ray.time, steps);
            let n = self.triangle_count();
            let k = segment.index;
            let (at_k, at_next) = (
                &self.triangles[k * n..(k + 1) * n],
                &self.triangles[(k + 1) * n..(k + 2) * n],
            );
            let boxes = MotionBoxes {
                boxes: &self.step_boxes,
                steps,
                segment,
            };
            traverse(
                &self.nodes,
                &boxes,
                &BoxRay::new(ray),
                &mut t_max,
                stack,
                |start, count, t_max, _| {
                    let range = start as usize..(start + count) as usize;
                    for (a, b) in at_k[range.clone()].iter().zip(&at_next[range]) {
                        let id = a.id;
                        let [v0, v1, v2] = [0, 1, 2].map(|j| segment.lerp(a.v[j], b.v[j]));
                        if let Some((t, b1, b2)) = intersect_triangle(&pre, v0, v1, v2, *t_max) {
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
            return best;
        }
        let lanes = RayLanes::new(ray);
        traverse_wide::<AVX>(
            &self.wide,
            &WideRay::new(ray),
            &mut t_max,
            stack,
            Walk {
                root_lane: match part {
                    Part::Whole => None,
                    Part::Lane(lane) => Some(lane),
                },
                nearest_first: !ANY_HIT,
            },
            |start, count| {
                let start = start as usize;
                prefetch(self.rows.at(start));
                // A merged leaf (up to eight triangles, 320 bytes): the lines from its
                // fourth triangle on as well.
                if count > 3 {
                    prefetch(self.rows.at(start + 3));
                }
            },
            |start, count, t_max, _| {
                // Four triangles at a time through the test in SIMD lanes; those it keeps
                // but cannot decide through the whole test, in order.
                for block in self.rows.leaf(start as usize, count as usize) {
                    let hits = lanes.test(&block);
                    let mut candidates = hits.candidates;
                    while candidates != 0 {
                        let i = candidates.trailing_zeros() as usize;
                        candidates &= candidates - 1;
                        let hit = match hits.decide(i, *t_max) {
                            LaneHit::Hit(t, b1, b2) => Some((t, b1, b2)),
                            LaneHit::Miss => None,
                            // Rare (an edge function of zero, a hit single precision
                            // cannot place): the whole test's matrix is built here.
                            LaneHit::WholeTest => {
                                let [v0, v1, v2] = block.vertices(i);
                                let pre = RayPrecomputed::new(ray);
                                intersect_triangle(&pre, v0, v1, v2, *t_max)
                            }
                        };
                        if let Some((t, b1, b2)) = hit {
                            let id = block.id(i);
                            if accept(id, b1, b2) {
                                *t_max = t;
                                best = Some((t, id, b1, b2));
                                if ANY_HIT {
                                    return true;
                                }
                            }
                        }
                    }
                }
                false
            },
        );
        best
    }

    /// The lanes of the root of a static mesh's tree, each with its box: parts that the
    /// instance level may list on their own. None for a deforming mesh, whose search at a
    /// time takes its binary tree whole.
    pub(super) fn root_parts(&self) -> Vec<(Aabb, Part)> {
        match self.wide.first() {
            Some(root) if !self.has_motion() => root
                .lanes()
                .map(|(lane, bounds)| (bounds, Part::Lane(lane)))
                .collect(),
            _ => Vec::new(),
        }
    }
}

/// What a search of a mesh's tree covers: all of it, or what one lane of its root holds
/// (a child node's subtree, or a leaf), which the instance level lists on its own for an
/// instance it opens (see `SceneBvh::build`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Part {
    Whole,
    Lane(u32),
}

/// Every node's box at every step (node-major; see `MotionBoxes`), from the step-major
/// `triangles` (`n` per step), in one reverse pass: children come after their parents.
fn step_boxes(nodes: &[Node], triangles: &[LeafTriangle], n: usize, steps: usize) -> Vec<StepBox> {
    let empty = StepBox {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };
    let mut boxes = vec![empty; nodes.len() * steps];
    for (i, node) in nodes.iter().enumerate().rev() {
        for s in 0..steps {
            let mut b = empty;
            if node.count > 0 {
                let range = s * n + node.start as usize..s * n + (node.start + node.count) as usize;
                for LeafTriangle { v: t, .. } in &triangles[range] {
                    b.min = b.min.min(t[0]).min(t[1]).min(t[2]);
                    b.max = b.max.max(t[0]).max(t[1]).max(t[2]);
                }
            } else {
                for c in [node.start as usize, node.start as usize + 1] {
                    let child = boxes[c * steps + s];
                    b.min = b.min.min(child.min);
                    b.max = b.max.max(child.max);
                }
            }
            boxes[i * steps + s] = b;
        }
    }
    boxes
}

#[cfg(test)]
mod tests;
