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

use super::build::half_area;
use super::node::{Deferred, Node, FAR_SCALE};
use crate::geometry::{Aabb, Ray};

/// Children per node.
pub(super) const WIDTH: usize = 8;

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

/// How [`collapse`] turns small subtrees into leaves: those of at most `max_leaf`
/// primitives, where the surface area heuristic, pricing a node visit at `node_cost`
/// primitive tests, prefers one leaf to the subtree.
#[derive(Clone, Copy, Debug)]
pub(super) struct Merge {
    pub max_leaf: u32,
    pub node_cost: f64,
}

/// Half the surface area of a node's box.
fn node_area(n: &Node) -> f32 {
    half_area(n.min.into(), n.max.into())
}

/// Each binary node's primitives `(start, count)` where it is a leaf of the eight-wide tree:
/// a binary leaf, or an interior node whose subtree `merge` makes one leaf (a subtree's
/// leaves hold a contiguous range). `None` for an interior node that stays one.
///
/// Merging compares each subtree's least cost as a leaf with its least cost as a node over
/// its children's least costs, in double precision (a box's area may overflow f32; an
/// infinite or NaN cost never merges more than it should: the comparison fails, or the
/// leaf is as large as allowed anyway). Children come after their parents, so one reverse
/// pass sees children first.
fn leaf_ranges(binary: &[Node], merge: Option<Merge>) -> Vec<Option<(u32, u32)>> {
    let own = |n: &Node| (n.count > 0).then_some((n.start, n.count));
    let Some(merge) = merge else {
        return binary.iter().map(own).collect();
    };
    let mut range = vec![(0u32, 0u32); binary.len()];
    let mut cost = vec![0.0f64; binary.len()];
    let mut leaf = vec![None; binary.len()];
    for i in (0..binary.len()).rev() {
        let n = &binary[i];
        let area = f64::from(node_area(n));
        if n.count > 0 {
            range[i] = (n.start, n.count);
            cost[i] = n.count as f64 * area;
            leaf[i] = own(n);
            continue;
        }
        let (l, r) = (n.start as usize, n.start as usize + 1);
        range[i] = (range[l].0.min(range[r].0), range[l].1 + range[r].1);
        let as_node = merge.node_cost * area + cost[l] + cost[r];
        let as_leaf = range[i].1 as f64 * area;
        if range[i].1 <= merge.max_leaf && as_leaf <= as_node {
            leaf[i] = Some(range[i]);
            cost[i] = as_leaf;
        } else {
            cost[i] = as_node;
        }
    }
    leaf
}

/// Collapses a binary hierarchy (as [`super::build::build`] makes it) into eight-wide nodes
/// over the same leaves, or over larger ones where `merge` says so: each node takes its
/// binary node's children and opens the largest interior one until it has eight, so the
/// tree keeps SAH's grouping. Node 0 is the root; children come after their parents.
pub(super) fn collapse(binary: &[Node], merge: Option<Merge>) -> Vec<WideNode> {
    if binary.is_empty() {
        return Vec::new();
    }
    let leaves = leaf_ranges(binary, merge);
    let is_leaf = |n: usize| leaves[n].is_some();
    let mut wide = vec![WideNode::EMPTY];
    // (binary node, the wide node that takes its children)
    let mut todo = vec![(0usize, 0usize)];
    while let Some((b, w)) = todo.pop() {
        let mut lanes = if is_leaf(b) {
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
                .filter(|(_, &n)| !is_leaf(n))
                .max_by(|(_, &x), (_, &y)| node_area(&binary[x]).total_cmp(&node_area(&binary[y])));
            let Some((k, &n)) = widest else { break };
            let l = binary[n].start as usize;
            lanes[k] = l;
            lanes.push(l + 1);
        }
        for (lane, &n) in lanes.iter().enumerate() {
            let node = &binary[n];
            if let Some((start, count)) = leaves[n] {
                wide[w].set_lane(lane, node, start, count);
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

/// Visits the leaves of an eight-wide hierarchy whose boxes the ray enters before `t_max`;
/// `leaf` and `stack` work as for the binary [`traverse`](super::node::traverse). Stack
/// entries name a node's lane (`8·node + lane`). `prefetch_leaf(start, count)` is called
/// for each leaf entered, when it is pushed, so that its primitives can be on their way
/// into the cache by the time it is visited.
///
/// With `nearest_first` (a constant in each query, which this is inlined into), a node's
/// children are visited nearest first, and one that a closer hit has ruled out since it
/// was pushed is skipped: what a closest-hit search needs. Without, they are visited in
/// reverse lane order, unsorted, as Embree's occlusion queries do: a search for any hit
/// ends at its first accepted hit, so `t_max` never shrinks and the order cannot change
/// its answer (whether there is one).
#[inline(always)]
pub(super) fn traverse_wide(
    nodes: &[WideNode],
    ray: &WideRay,
    t_max: &mut f32,
    stack: &mut [Deferred],
    nearest_first: bool,
    prefetch_leaf: impl Fn(u32, u32),
    mut leaf: impl FnMut(u32, u32, &mut f32, &mut [Deferred]) -> bool,
) {
    if nodes.is_empty() {
        return;
    }
    let prefetching = nodes.len() > PREFETCH_ABOVE;
    // Entries `..len` of `stack` are this traversal's; a leaf gets the rest.
    let mut len = 0;
    let mut current = 0u32;
    loop {
        let (entry, mut hits) = ray.enter(&nodes[current as usize], *t_max);
        // Push the children entered; nearest first, kept in falling order of distance
        // above `first`, so that the nearest is popped first.
        let first = len;
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
                    prefetch_leaf(start, node.count[lane as usize]);
                }
            }
            stack[len] = (current * WIDTH as u32 + lane, entry[lane as usize]);
            let mut i = len;
            len += 1;
            while nearest_first && i > first && stack[i - 1].1 < stack[i].1 {
                stack.swap(i - 1, i);
                i -= 1;
            }
        }
        // Pop the next child that a closer hit has not ruled out: a leaf is handled here,
        // an interior node is tested next.
        loop {
            if len == 0 {
                return;
            }
            len -= 1;
            let (lane_ref, d) = stack[len];
            if nearest_first && d > *t_max {
                continue;
            }
            let node = &nodes[(lane_ref / WIDTH as u32) as usize];
            let lane = (lane_ref % WIDTH as u32) as usize;
            let (start, count) = (node.start[lane], node.count[lane]);
            if count == 0 {
                current = start;
                break;
            }
            if leaf(start, count, t_max, &mut stack[len..]) {
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::build::SAH_MAX_DEPTH;
    use super::super::build::{build, BuildParams, BuildPrim};
    use super::super::node::{traverse, BoxRay, StaticBoxes, LEVEL_STACK, STACK_CAPACITY};
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
            let wide = collapse(&binary, None);
            check_collapse(&binary, &wide);
            let leaves = wide_leaves(&wide);
            assert_eq!(leaves, binary_leaves(&binary), "{n} primitives");
            // Merged: every primitive in exactly one leaf still, none larger than asked.
            let merged = collapse(&binary, Some(MERGE));
            check_collapse(&binary, &merged);
            let leaves = wide_leaves(&merged);
            assert!(leaves.iter().all(|&(_, count)| count <= MERGE.max_leaf));
            let mut next = 0;
            for (start, count) in leaves {
                assert_eq!(start, next, "{n} primitives");
                next += count;
            }
            assert_eq!(next, n as u32);
            // Half as deep: at most about half as many nodes as the binary tree.
            assert!(
                wide.len() <= binary.len().div_ceil(2),
                "{n}: {}",
                wide.len()
            );
        }
    }

    const MERGE: Merge = Merge {
        max_leaf: 8,
        node_cost: 4.0,
    };

    /// Every leaf of an eight-wide tree, once, as (start, count).
    fn wide_leaves(wide: &[WideNode]) -> Vec<(u32, u32)> {
        let mut leaves: Vec<_> = wide
            .iter()
            .flat_map(|node| {
                (0..WIDTH)
                    .filter(|&lane| node.count[lane] > 0)
                    .map(|lane| (node.start[lane], node.count[lane]))
            })
            .collect();
        leaves.sort();
        leaves
    }

    /// Child boxes hold their children, children come after their parents, the root's box
    /// is the binary root's, and lanes are used in order.
    fn check_collapse(binary: &[Node], wide: &[WideNode]) {
        for (i, node) in wide.iter().enumerate() {
            for lane in 0..WIDTH {
                let lane_box = node.lane_box(lane);
                if lane_box.is_empty() || node.count[lane] > 0 {
                    continue;
                }
                let child = node.start[lane] as usize;
                assert!(child > i, "children come after their parents");
                let inner = wide[child].bounds();
                assert!(lane_box.min.cmple(inner.min).all());
                assert!(lane_box.max.cmpge(inner.max).all());
            }
        }
        assert_eq!(
            wide[0].bounds(),
            Aabb {
                min: binary[0].min,
                max: binary[0].max
            }
        );
        // Lanes are used in order: `enter` tests one half of a node whose fifth is free.
        for node in wide {
            let used = (0..WIDTH).filter(|&l| !node.lane_box(l).is_empty()).count();
            assert!((0..used).all(|l| node.start[l] | node.count[l] != 0));
            assert!((used..WIDTH).all(|l| node.start[l] | node.count[l] == 0));
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
        let wide = collapse(&binary, None);
        let mut stack = [(0, 0.0); STACK_CAPACITY];
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
            seen_binary.sort();
            // Sorted or not (a search for any hit), the same leaves.
            for nearest_first in [true, false] {
                let mut seen_wide = Vec::new();
                traverse_wide(
                    &wide,
                    &WideRay::new(&ray),
                    &mut { t_max },
                    &mut stack,
                    nearest_first,
                    |_, _| {},
                    |s, c, _, _| {
                        seen_wide.push((s, c));
                        false
                    },
                );
                seen_wide.sort();
                assert_eq!(seen_wide, seen_binary, "ray {i}: {ray:?}");
            }
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
        let wide = collapse(&binary, None);
        let ray = WideRay::new(&Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X));
        // The caller's entry below the part it hands on stays as it was.
        let mut stack = [(0, 0.0); STACK_CAPACITY];
        stack[0] = (7, 1.0);
        let mut order = Vec::new();
        let mut t_max = f32::INFINITY;
        traverse_wide(
            &wide,
            &ray,
            &mut t_max,
            &mut stack[1..],
            true,
            |_, _| {},
            |start, _, t_max, _| {
                order.push(prims[start as usize].index);
                // A hit at the near face of the first leaf entered rules out the rest.
                *t_max = prims[start as usize].min.x + 1.0;
                false
            },
        );
        assert_eq!(order, [0]);
        assert_eq!(stack[0], (7, 1.0));
        let mut visits = 0;
        let mut t_max = f32::INFINITY;
        traverse_wide(
            &wide,
            &ray,
            &mut t_max,
            &mut stack[1..],
            true,
            |_, _| {},
            |_, _, _, _| {
                visits += 1;
                true
            },
        );
        assert_eq!((visits, stack[0]), (1, (7, 1.0)));
    }

    #[test]
    fn a_path_as_deep_as_the_build_allows_fits_one_level_of_the_stack() {
        // The worst case by hand: a chain of nodes as long as the build's depth guard
        // allows, each with seven leaves and, nearest the ray, the next node, so that every
        // node leaves seven entries behind.
        let nodes_on_path = 2 * SAH_MAX_DEPTH as usize + 1;
        let leaf_box = |k: usize| Node {
            min: Vec3::new(100.0 + k as f32, -1.0, -1.0),
            start: 0,
            max: Vec3::new(101.0 + k as f32, 1.0, 1.0),
            count: 1,
        };
        let mut nodes = vec![WideNode::EMPTY; nodes_on_path];
        for (k, node) in nodes.iter_mut().enumerate() {
            let last = k + 1 == nodes_on_path;
            for lane in 0..WIDTH {
                if lane + 1 == WIDTH && !last {
                    let inner = Node {
                        min: Vec3::splat(-1e3),
                        start: 0,
                        max: Vec3::splat(1e3),
                        count: 0,
                    };
                    node.set_lane(lane, &inner, k as u32 + 1, 0);
                } else {
                    node.set_lane(lane, &leaf_box(k), 0, 1);
                }
            }
        }
        let ray = WideRay::new(&Ray::new(Vec3::new(-1e4, 0.0, 0.0), Vec3::X));
        let deepest = (WIDTH - 1) * (nodes_on_path - 1) + WIDTH;
        let leaves_with = |entries: usize| {
            let mut stack = vec![(0, 0.0); entries];
            let (mut leaves, mut t_max) = (0, f32::INFINITY);
            traverse_wide(
                &nodes,
                &ray,
                &mut t_max,
                &mut stack,
                true,
                |_, _| {},
                |_, _, _, _| {
                    leaves += 1;
                    false
                },
            );
            leaves
        };
        assert!(deepest <= LEVEL_STACK);
        assert_eq!(leaves_with(LEVEL_STACK), deepest);
        // It does reach that height: one entry fewer is out of bounds.
        assert!(std::panic::catch_unwind(|| leaves_with(deepest - 1)).is_err());
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
