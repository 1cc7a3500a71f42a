//! Eight-wide nodes for static hierarchies: the binary SAH tree collapsed so that slab tests
//! in SIMD lanes check a node's eight children at once (Wald et al., "Getting Rid of
//! Packets", 2008; Dammertz et al., "Shallow Bounding Volume Hierarchies", 2008; Embree's
//! BVH8).
//!
//! The same tree eight-wide is a third as deep as binary: in a large mesh, where each node
//! a ray visits is a cache miss, fewer levels are fewer misses (four-wide, as this was
//! before, traced the incoherent rays of a 1M-triangle mesh 20% slower). The eight lanes
//! are tested as two halves of four in SSE2 registers, which every x86_64 CPU has, so
//! there is one code path and no run-time dispatch. Each lane runs the same IEEE
//! operations per axis as [`BoxRay::entry`](super::node::BoxRay), so a child is entered
//! at the same distance, and hit, exactly when the binary test says so.

use glam::{Vec3, Vec4};

use super::node::{Deferred, Node, FAR_SCALE};
use crate::geometry::{Aabb, Ray};

/// Children per node.
const WIDTH: usize = 8;

/// Children per SIMD register: a node's lanes are tested in `WIDTH / LANES` halves.
const LANES: usize = 4;

/// Eight children in 256 bytes (four cache lines): their boxes one lane per child, then
/// what each is. A lane with `count == 0` is an interior node at index `start`; otherwise
/// it is a leaf of primitives `start .. start + count`. Unused lanes hold an empty box
/// (+inf minimum, -inf maximum), which no ray with a finite origin enters.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub(super) struct WideNode {
    /// `bounds[0][axis][h]`: the minima on `axis` of children `4h .. 4h + 4`;
    /// `bounds[1]`: their maxima.
    bounds: [[[Vec4; WIDTH / LANES]; 3]; 2],
    start: [u32; WIDTH],
    count: [u32; WIDTH],
}

impl WideNode {
    const EMPTY: WideNode = WideNode {
        bounds: [
            [[Vec4::INFINITY; WIDTH / LANES]; 3],
            [[Vec4::NEG_INFINITY; WIDTH / LANES]; 3],
        ],
        start: [0; WIDTH],
        count: [0; WIDTH],
    };

    /// The union of the children's boxes.
    pub fn bounds(&self) -> Aabb {
        (0..WIDTH).fold(Aabb::EMPTY, |mut b, lane| {
            let child = self.lane_box(lane);
            b.min = b.min.min(child.min);
            b.max = b.max.max(child.max);
            b
        })
    }

    /// The box of child `lane` (empty for an unused lane).
    fn lane_box(&self, lane: usize) -> Aabb {
        let at = |side: usize, axis: usize| self.bounds[side][axis][lane / LANES][lane % LANES];
        Aabb {
            min: Vec3::new(at(0, 0), at(0, 1), at(0, 2)),
            max: Vec3::new(at(1, 0), at(1, 1), at(1, 2)),
        }
    }

    fn set_lane(&mut self, lane: usize, node: &Node, start: u32, count: u32) {
        for axis in 0..3 {
            self.bounds[0][axis][lane / LANES][lane % LANES] = node.min[axis];
            self.bounds[1][axis][lane / LANES][lane % LANES] = node.max[axis];
        }
        self.start[lane] = start;
        self.count[lane] = count;
    }
}

/// Collapses a binary hierarchy (as [`super::build::build`] makes it) into eight-wide nodes
/// over the same leaves: each node takes its binary node's children and opens the largest
/// interior one until it has eight, so the tree keeps SAH's grouping. Node 0 is the root;
/// children come after their parents.
pub(super) fn collapse(binary: &[Node]) -> Vec<WideNode> {
    if binary.is_empty() {
        return Vec::new();
    }
    let half_area = |n: &Node| {
        let d = n.max - n.min;
        d.x * d.y + d.y * d.z + d.z * d.x
    };
    let mut wide = vec![WideNode::EMPTY];
    // (binary node, the wide node that takes its children)
    let mut todo = vec![(0usize, 0usize)];
    while let Some((b, w)) = todo.pop() {
        let mut lanes = if binary[b].count > 0 {
            // A leaf root: one lane.
            vec![b]
        } else {
            let l = binary[b].start as usize;
            vec![l, l + 1]
        };
        while lanes.len() < WIDTH {
            let widest = lanes
                .iter()
                .enumerate()
                .filter(|(_, &n)| binary[n].count == 0)
                .max_by(|(_, &x), (_, &y)| half_area(&binary[x]).total_cmp(&half_area(&binary[y])));
            let Some((k, &n)) = widest else { break };
            let l = binary[n].start as usize;
            lanes[k] = l;
            lanes.push(l + 1);
        }
        for (lane, &n) in lanes.iter().enumerate() {
            let node = &binary[n];
            if node.count > 0 {
                wide[w].set_lane(lane, node, node.start, node.count);
            } else {
                let child = wide.len();
                wide.push(WideNode::EMPTY);
                wide[w].set_lane(lane, node, child as u32, 0);
                todo.push((n, child));
            }
        }
    }
    wide
}

/// A ray prepared for a node's slab tests, four at once: per axis, its origin and
/// reciprocal direction in every lane, and which of a node's bound arrays holds the near
/// planes.
#[derive(Clone, Copy, Debug)]
pub(super) struct WideRay {
    origin: [Vec4; 3],
    /// 1/dir with IEEE infinities for zero components (of the zero's sign).
    inv_dir: [Vec4; 3],
    /// 1 where the direction is negative (the near plane is the box's maximum), else 0.
    near: [usize; 3],
}

impl WideRay {
    pub fn new(ray: &Ray) -> Self {
        let (o, inv) = (ray.origin, ray.dir.recip());
        Self {
            origin: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            inv_dir: [Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z)],
            near: [
                usize::from(inv.x < 0.0),
                usize::from(inv.y < 0.0),
                usize::from(inv.z < 0.0),
            ],
        }
    }

    /// The distances at which the ray enters `node`'s children, and a bit per child that
    /// it enters within `[0, t_max]`.
    #[inline(always)]
    fn enter(&self, node: &WideNode, t_max: f32) -> ([f32; WIDTH], u32) {
        let mut entry = [0.0; WIDTH];
        let mut hits = 0;
        // Lanes are filled in order, so a node whose fifth lane is unused (no child node
        // there, nor a leaf) has four children at most: small trees test one half.
        let halves = if node.start[LANES] | node.count[LANES] == 0 {
            1
        } else {
            WIDTH / LANES
        };
        for h in 0..halves {
            let mut t0 = Vec4::ZERO;
            let mut t1 = Vec4::splat(t_max);
            for axis in 0..3 {
                // (`& 1` spares the bounds checks: `near` is 0 or 1.)
                let near = node.bounds[self.near[axis] & 1][axis][h];
                let far = node.bounds[(self.near[axis] ^ 1) & 1][axis][h];
                let near = (near - self.origin[axis]) * self.inv_dir[axis];
                let far = (far - self.origin[axis]) * self.inv_dir[axis] * FAR_SCALE;
                // A NaN distance (0 · inf: the ray lies in the slab's plane) must not
                // constrain the interval: the accumulator stays.
                t0 = max_or_acc(t0, near);
                t1 = min_or_acc(t1, far);
            }
            t0.write_to_slice(&mut entry[h * LANES..][..LANES]);
            hits |= t0.cmple(t1).bitmask() << (h * LANES);
        }
        (entry, hits)
    }
}

/// `max(acc, x)` per lane, keeping `acc` where `x` is NaN.
#[inline(always)]
fn max_or_acc(acc: Vec4, x: Vec4) -> Vec4 {
    // glam's SSE2 `max` is maxps(x, acc), which returns its second operand where the
    // comparison fails: one instruction instead of a compare and a three-instruction
    // select (a test pins this down). Elsewhere (NEON's max returns the NaN) the select.
    #[cfg(target_arch = "x86_64")]
    return x.max(acc);
    #[cfg(not(target_arch = "x86_64"))]
    return Vec4::select(x.cmpgt(acc), x, acc);
}

/// `min(acc, x)` per lane, keeping `acc` where `x` is NaN.
#[inline(always)]
fn min_or_acc(acc: Vec4, x: Vec4) -> Vec4 {
    #[cfg(target_arch = "x86_64")]
    return x.min(acc);
    #[cfg(not(target_arch = "x86_64"))]
    return Vec4::select(x.cmplt(acc), x, acc);
}

/// Hierarchies of more nodes than this (32 KiB, a core's L1 data cache) prefetch the
/// children a ray enters; smaller ones stay in the cache, where a prefetch only costs
/// instructions (1.1% more on the Cornell box).
const PREFETCH_ABOVE: usize = 256;

/// Asks the CPU to start loading the two cache lines from `item` on (a node, or the first
/// triangles of a leaf) into the cache.
#[inline(always)]
pub(super) fn prefetch<T>(item: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let p = (item as *const T).cast::<i8>();
        // SAFETY: a prefetch is a hint; it reads nothing and cannot fault. The second
        // address may lie past the end of `item`'s allocation: `wrapping_add` computes it
        // without the in-bounds promise that `add` makes.
        unsafe {
            _mm_prefetch::<_MM_HINT_T0>(p);
            _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64));
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = item;
}

/// Visits the leaves of an eight-wide hierarchy whose boxes the ray enters before `t_max`,
/// nearest child first; `leaf` and `stack` work as for the binary
/// [`traverse`](super::node::traverse). Stack entries name a node's lane (`8·node + lane`).
/// `prefetch_leaf(start)` is called for each leaf entered, when it is pushed, so that its
/// primitives can be on their way into the cache by the time it is visited.
#[inline(always)]
pub(super) fn traverse_wide(
    nodes: &[WideNode],
    ray: &WideRay,
    t_max: &mut f32,
    stack: &mut Vec<Deferred>,
    prefetch_leaf: impl Fn(u32),
    mut leaf: impl FnMut(u32, u32, &mut f32, &mut Vec<Deferred>) -> bool,
) {
    if nodes.is_empty() {
        return;
    }
    let base = stack.len();
    let prefetching = nodes.len() > PREFETCH_ABOVE;
    let mut current = 0u32;
    loop {
        let (entry, mut hits) = ray.enter(&nodes[current as usize], *t_max);
        // Push the children entered, kept in falling order of distance above `first`, so
        // that the nearest is popped first.
        let first = stack.len();
        let node = &nodes[current as usize];
        while hits != 0 {
            let lane = hits.trailing_zeros();
            hits &= hits - 1;
            if prefetching {
                // Fetch every child entered at once: in a large tree each node is a cache
                // miss, and misses issued together overlap.
                let start = node.start[lane as usize];
                if node.count[lane as usize] == 0 {
                    // Its four lines: 0 and 1 from the start, 2 and 3 from byte 128.
                    let child = &nodes[start as usize];
                    prefetch(child);
                    prefetch(&child.bounds[1][1]);
                } else {
                    prefetch_leaf(start);
                }
            }
            stack.push((current * WIDTH as u32 + lane, entry[lane as usize]));
            let mut i = stack.len() - 1;
            while i > first && stack[i - 1].1 < stack[i].1 {
                stack.swap(i - 1, i);
                i -= 1;
            }
        }
        // Pop the next child that a closer hit has not ruled out: a leaf is handled here,
        // an interior node is tested next.
        loop {
            if stack.len() == base {
                return;
            }
            let Some((lane_ref, d)) = stack.pop() else {
                return;
            };
            if d > *t_max {
                continue;
            }
            let node = &nodes[(lane_ref / WIDTH as u32) as usize];
            let lane = (lane_ref % WIDTH as u32) as usize;
            let (start, count) = (node.start[lane], node.count[lane]);
            if count == 0 {
                current = start;
                break;
            }
            if leaf(start, count, t_max, stack) {
                stack.truncate(base);
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::build::{build, BuildParams, BuildPrim};
    use super::super::node::{traverse, BoxRay, StaticBoxes};
    use super::*;
    use crate::test_rng::Rng;

    #[test]
    fn node_is_four_cache_lines() {
        assert_eq!(std::mem::size_of::<WideNode>(), 256);
        assert_eq!(std::mem::align_of::<WideNode>(), 64);
    }

    fn random_prims(rng: &mut Rng, n: usize) -> Vec<BuildPrim> {
        (0..n)
            .map(|i| {
                let c = rng.vec3() * 10.0;
                let h = rng.vec3() * 0.5;
                BuildPrim {
                    min: c - h,
                    max: c + h,
                    index: i as u32,
                }
            })
            .collect()
    }

    /// Every leaf of the binary tree, once, as (start, count).
    fn binary_leaves(nodes: &[Node]) -> Vec<(u32, u32)> {
        let mut leaves: Vec<_> = nodes
            .iter()
            .filter(|n| n.count > 0)
            .map(|n| (n.start, n.count))
            .collect();
        leaves.sort();
        leaves
    }

    #[test]
    fn collapse_keeps_every_leaf_once_and_boxes_hold_their_children() {
        let mut rng = Rng(3);
        for n in [1, 2, 3, 5, 8, 9, 40, 1000] {
            let mut prims = random_prims(&mut rng, n);
            let params = BuildParams {
                max_leaf: 2,
                traversal_cost: 1.0,
                intersect_cost: 1.0,
            };
            let binary = build(&mut prims, &params);
            let wide = collapse(&binary);
            let mut leaves = Vec::new();
            for (i, node) in wide.iter().enumerate() {
                for lane in 0..WIDTH {
                    let lane_box = node.lane_box(lane);
                    if lane_box.is_empty() {
                        continue;
                    }
                    if node.count[lane] > 0 {
                        leaves.push((node.start[lane], node.count[lane]));
                    } else {
                        let child = node.start[lane] as usize;
                        assert!(child > i, "children come after their parents");
                        let inner = wide[child].bounds();
                        assert!(lane_box.min.cmple(inner.min).all());
                        assert!(lane_box.max.cmpge(inner.max).all());
                    }
                }
            }
            leaves.sort();
            assert_eq!(leaves, binary_leaves(&binary), "{n} primitives");
            assert_eq!(
                wide[0].bounds(),
                Aabb {
                    min: binary[0].min,
                    max: binary[0].max
                }
            );
            // Lanes are used in order: `enter` tests one half of a node whose fifth is free.
            for node in &wide {
                let used = (0..WIDTH).filter(|&l| !node.lane_box(l).is_empty()).count();
                assert!((0..used).all(|l| node.start[l] | node.count[l] != 0));
                assert!((used..WIDTH).all(|l| node.start[l] | node.count[l] == 0));
            }
            // Half as deep: at most about a third as many nodes as the binary tree.
            assert!(
                wide.len() <= binary.len().div_ceil(2),
                "{n}: {}",
                wide.len()
            );
        }
    }

    #[test]
    fn visits_the_same_leaves_at_the_same_distances_as_the_binary_traversal() {
        let mut rng = Rng(11);
        let mut prims = random_prims(&mut rng, 300);
        let params = BuildParams {
            max_leaf: 4,
            traversal_cost: 1.0,
            intersect_cost: 1.0,
        };
        let binary = build(&mut prims, &params);
        let wide = collapse(&binary);
        let mut stack = Vec::new();
        for i in 0..2000 {
            let origin = rng.vec3() * 14.0 - 2.0;
            let mut dir = rng.vec3() * 2.0 - 1.0;
            // Axis-parallel rays too, some of them in a box's face plane.
            if i % 5 == 0 {
                dir = Vec3::new(0.0, 0.0, if i % 2 == 0 { 1.0 } else { -0.0 });
            }
            let origin = if i % 7 == 0 {
                Vec3::new(prims[i % 300].min.x, origin.y, origin.z)
            } else {
                origin
            };
            let ray = Ray::new(origin, dir);
            let t_max = if i % 3 == 0 { 4.0 } else { f32::INFINITY };
            let mut seen_binary = Vec::new();
            traverse(
                &binary,
                &StaticBoxes,
                &BoxRay::new(&ray),
                &mut { t_max },
                &mut stack,
                |start, count, _, _| {
                    seen_binary.push((start, count));
                    false
                },
            );
            let mut seen_wide = Vec::new();
            traverse_wide(
                &wide,
                &WideRay::new(&ray),
                &mut { t_max },
                &mut stack,
                |_| {},
                |s, c, _, _| {
                    seen_wide.push((s, c));
                    false
                },
            );
            assert!(stack.is_empty());
            seen_binary.sort();
            seen_wide.sort();
            assert_eq!(seen_wide, seen_binary, "ray {i}: {ray:?}");
        }
    }

    #[test]
    fn a_closer_hit_prunes_and_any_hit_stops() {
        // Five leaves in a row along x; a ray down the row finds the nearest first.
        let mut prims: Vec<BuildPrim> = (0..5)
            .map(|i| BuildPrim {
                min: Vec3::new(i as f32 * 2.0, 0.0, 0.0),
                max: Vec3::new(i as f32 * 2.0 + 1.0, 1.0, 1.0),
                index: i,
            })
            .collect();
        let params = BuildParams {
            max_leaf: 1,
            traversal_cost: 1.0,
            intersect_cost: 1.0,
        };
        let binary = build(&mut prims, &params);
        let wide = collapse(&binary);
        let ray = WideRay::new(&Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X));
        let mut stack = vec![(7, 1.0)];
        let mut order = Vec::new();
        let mut t_max = f32::INFINITY;
        traverse_wide(
            &wide,
            &ray,
            &mut t_max,
            &mut stack,
            |_| {},
            |start, _, t_max, _| {
                order.push(prims[start as usize].index);
                // A hit at the near face of the first leaf entered rules out the rest.
                *t_max = prims[start as usize].min.x + 1.0;
                false
            },
        );
        assert_eq!(order, [0]);
        assert_eq!(
            stack,
            [(7, 1.0)],
            "the caller's entries are left as they were"
        );
        let mut visits = 0;
        let mut t_max = f32::INFINITY;
        traverse_wide(
            &wide,
            &ray,
            &mut t_max,
            &mut stack,
            |_| {},
            |_, _, _, _| {
                visits += 1;
                true
            },
        );
        assert_eq!((visits, stack.len()), (1, 1));
    }

    #[test]
    fn nan_lanes_keep_the_accumulator() {
        let acc = Vec4::new(1.0, 2.0, 3.0, 4.0);
        let x = Vec4::new(f32::NAN, 5.0, f32::NAN, 0.5);
        assert_eq!(max_or_acc(acc, x).to_array(), [1.0, 5.0, 3.0, 4.0]);
        assert_eq!(min_or_acc(acc, x).to_array(), [1.0, 2.0, 3.0, 0.5]);
    }

    #[test]
    fn empty_lanes_are_never_entered() {
        let node = WideNode::EMPTY;
        for dir in [Vec3::X, -Vec3::Y, Vec3::new(0.0, -0.0, 1.0), Vec3::ONE] {
            for origin in [Vec3::ZERO, Vec3::splat(1e30), Vec3::splat(-3.0)] {
                let (_, hits) = WideRay::new(&Ray::new(origin, dir)).enter(&node, f32::INFINITY);
                assert_eq!(hits, 0, "{origin} {dir}");
            }
        }
    }
}
