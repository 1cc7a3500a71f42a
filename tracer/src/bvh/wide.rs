//! Eight-wide nodes for static hierarchies: the binary SAH tree collapsed so that slab tests
//! in SIMD lanes check a node's eight children at once (Wald et al., "Getting Rid of
//! Packets", 2008; Dammertz et al., "Shallow Bounding Volume Hierarchies", 2008; Embree's
//! BVH8).
//!
//! The same tree eight-wide is a third as deep as binary: in a large mesh, where each node
//! a ray visits is a cache miss, fewer levels are fewer misses (four-wide, as this was
//! before, traced the incoherent rays of a 1M-triangle mesh 20% slower). The eight lanes
//! are tested in one AVX register where the CPU has AVX, else as two halves of four in
//! SSE2 registers, which every x86_64 CPU has (`simd.rs` picks, once per query). Each
//! lane runs the same IEEE operations per axis as [`BoxRay::entry`](super::node::BoxRay)
//! in either, so a child is entered at the same distance, and hit, exactly when the binary
//! test says so.

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
/// (+inf minimum, -inf maximum), which no ray with a finite origin enters, and a `start`
/// and `count` of 0 (node 0, the root, is no node's child).
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

    /// The used lanes, each with its box.
    pub fn lanes(&self) -> impl Iterator<Item = (u32, Aabb)> + '_ {
        (0..WIDTH)
            .filter(|&lane| self.start[lane] | self.count[lane] != 0)
            .map(|lane| (lane as u32, self.lane_box(lane)))
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

/// What the collapse knows of a binary node's subtree.
#[derive(Clone, Copy, Debug)]
struct Subtree {
    /// Its primitives `(start, count)`: a subtree's leaves hold a contiguous range.
    range: (u32, u32),
    /// Whether, in one lane, it is a leaf of the eight-wide tree (else a node).
    leaf: bool,
    /// `cost[j]`: its least SAH cost in at most `j + 1` lanes of its parent's node.
    cost: [f64; WIDTH],
}

/// The cheapest way for two sibling subtrees to share `lanes` lanes: how many the first
/// takes (the fewest, at equal costs), and the cost.
fn share(first: &Subtree, second: &Subtree, lanes: usize) -> (usize, f64) {
    let mut best = (1, first.cost[0] + second.cost[lanes - 2]);
    for k in 2..lanes {
        let cost = first.cost[k - 1] + second.cost[lanes - k - 1];
        // (A NaN cost, from a box whose area overflows, is never taken: any choice is valid.)
        if cost < best.1 {
            best = (k, cost);
        }
    }
    best
}

/// Every binary node's [`Subtree`], by dynamic programming over the lanes each subtree
/// may take (Ylitie et al., "Efficient Incoherent Ray Traversal on GPUs Through
/// Compressed Wide BVHs", 2017): an interior node either takes one lane, as one leaf (with
/// `merge`, at most `max_leaf` primitives) or as an eight-wide node over its cheapest
/// share of eight lanes, or hands its lanes to its two children. A node visit is priced at
/// `merge`'s `node_cost` primitive tests (without `merge`, the leaves are the binary
/// leaves and any positive price gives the same tree). Costs are in double precision (a
/// box's area may overflow f32); an infinite or NaN cost only makes choices arbitrary,
/// never invalid. Children come after their parents, so one reverse pass sees children first.
fn subtrees(binary: &[Node], merge: Option<Merge>) -> Vec<Subtree> {
    let node_cost = merge.map_or(1.0, |m| m.node_cost);
    let unset = Subtree {
        range: (0, 0),
        leaf: true,
        cost: [0.0; WIDTH],
    };
    let mut subtrees = vec![unset; binary.len()];
    for (i, n) in binary.iter().enumerate().rev() {
        let area = f64::from(node_area(n));
        subtrees[i] = if n.count > 0 {
            Subtree {
                range: (n.start, n.count),
                leaf: true,
                cost: [f64::from(n.count) * area; WIDTH],
            }
        } else {
            let (l, r) = (subtrees[n.start as usize], subtrees[n.start as usize + 1]);
            let range = (l.range.0.min(r.range.0), l.range.1 + r.range.1);
            let may_merge = merge.is_some_and(|m| range.1 <= m.max_leaf);
            let as_leaf = f64::from(range.1) * area;
            // `shared[j]`: the children's least cost in `j + 1` lanes.
            let shared: [f64; WIDTH] = std::array::from_fn(|j| {
                if j == 0 {
                    f64::INFINITY
                } else {
                    share(&l, &r, j + 1).1
                }
            });
            let as_node = node_cost * area + shared[WIDTH - 1];
            let leaf = may_merge && as_leaf <= as_node;
            let mut cost = [if leaf { as_leaf } else { as_node }; WIDTH];
            for j in 1..WIDTH {
                cost[j] = if shared[j] < cost[j - 1] {
                    shared[j]
                } else {
                    cost[j - 1]
                };
            }
            Subtree { range, leaf, cost }
        };
    }
    subtrees
}

/// Appends the lanes that binary node `n`'s subtree takes in at most `lanes` lanes (the
/// fewest that reach its least cost): itself, or its children's.
fn expand(binary: &[Node], subtrees: &[Subtree], n: usize, lanes: usize, out: &mut Vec<usize>) {
    let cost = &subtrees[n].cost;
    let used = 1
        + (0..lanes)
            .position(|j| cost[j] == cost[lanes - 1])
            .unwrap_or(0);
    if used == 1 || binary[n].count > 0 {
        out.push(n);
        return;
    }
    let (l, r) = (binary[n].start as usize, binary[n].start as usize + 1);
    let (k, _) = share(&subtrees[l], &subtrees[r], used);
    expand(binary, subtrees, l, k, out);
    expand(binary, subtrees, r, used - k, out);
}

/// Collapses a binary hierarchy (as [`super::build::build`] makes it) into eight-wide nodes
/// over the same leaves, or over larger ones where `merge` says so. Which binary nodes
/// become lanes of which eight-wide node is the SAH-cheapest choice (see [`subtrees`]),
/// so nodes are as full as their cost allows: opening the largest child until a node has
/// eight, as this did before, left most nodes of a large mesh with two to six lanes.
/// Node 0 is the root; children come after their parents.
pub(super) fn collapse(binary: &[Node], merge: Option<Merge>) -> Vec<WideNode> {
    if binary.is_empty() {
        return Vec::new();
    }
    let subtrees = subtrees(binary, merge);
    let mut wide = vec![WideNode::EMPTY];
    // (binary node, the wide node that takes its children)
    let mut todo = vec![(0usize, 0usize)];
    let mut lanes = Vec::with_capacity(WIDTH);
    while let Some((b, w)) = todo.pop() {
        lanes.clear();
        if binary[b].count > 0 {
            // A leaf root: one lane. (A root that could be merged into one leaf is not:
            // its own node's visit is paid either way, and it may split for less.)
            lanes.push(b);
        } else {
            let (l, r) = (binary[b].start as usize, binary[b].start as usize + 1);
            let (k, _) = share(&subtrees[l], &subtrees[r], WIDTH);
            expand(binary, &subtrees, l, k, &mut lanes);
            expand(binary, &subtrees, r, WIDTH - k, &mut lanes);
        }
        for (lane, &n) in lanes.iter().enumerate() {
            let (node, subtree) = (&binary[n], &subtrees[n]);
            if subtree.leaf {
                wide[w].set_lane(lane, node, subtree.range.0, subtree.range.1);
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

/// Each leaf's primitives `(start, count)`, in the order of the primitives: depth first,
/// lanes in order, as the collapse laid the binary tree's ranges out.
pub(super) fn leaves(nodes: &[WideNode]) -> Vec<(u32, u32)> {
    fn visit(nodes: &[WideNode], node: usize, out: &mut Vec<(u32, u32)>) {
        let node = &nodes[node];
        for lane in 0..WIDTH {
            match (node.start[lane], node.count[lane]) {
                // An unused lane: no node is the root's child.
                (0, 0) => {}
                (child, 0) => visit(nodes, child as usize, out),
                leaf => out.push(leaf),
            }
        }
    }
    let mut out = Vec::new();
    if !nodes.is_empty() {
        visit(nodes, 0, &mut out);
    }
    out
}

/// A ray prepared for a node's slab tests: per axis, its origin and reciprocal direction,
/// and which of a node's bound arrays holds the near planes. Kept as scalars and
/// broadcast into lanes where a test reads them (one instruction from memory): held as
/// lanes, eight-wide broadcasts were built and spilled for every ray and instance.
#[derive(Clone, Copy, Debug)]
pub(super) struct WideRay {
    origin: [f32; 3],
    /// 1/dir with IEEE infinities for zero components (of the zero's sign).
    inv_dir: [f32; 3],
    /// 1 where the direction is negative (the near plane is the box's maximum), else 0.
    near: [usize; 3],
}

impl WideRay {
    pub fn new(ray: &Ray) -> Self {
        // The sign bits of the direction, which are those of its reciprocal (1/±0 is ±inf;
        // a NaN, whose sign says nothing, is no valid ray's).
        let negative = ray.dir.is_negative_bitmask() as usize;
        Self {
            origin: ray.origin.to_array(),
            inv_dir: ray.dir.recip().to_array(),
            near: [negative & 1, (negative >> 1) & 1, negative >> 2],
        }
    }

    /// The distances at which the ray enters `node`'s children, and a bit per child that
    /// it enters within `[0, t_max]`: with `AVX`, in one AVX register of eight lanes,
    /// else in SSE2 halves of four. `AVX` is true only in code that
    /// [`with_avx`](crate::simd::with_avx) runs.
    #[inline(always)]
    fn enter<const AVX: bool>(&self, node: &WideNode, t_max: f32) -> ([f32; WIDTH], u32) {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: this code runs where the CPU has AVX (see above).
            return unsafe { self.enter_avx(node, t_max) };
        }
        self.enter_halves(node, t_max)
    }

    /// [`Self::enter`] in one register: the same operations, in the same order, on each
    /// lane as [`Self::enter_halves`], so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    unsafe fn enter_avx(&self, node: &WideNode, t_max: f32) -> ([f32; WIDTH], u32) {
        use std::arch::x86_64::{
            _mm256_cmp_ps, _mm256_loadu_ps, _mm256_max_ps, _mm256_min_ps, _mm256_movemask_ps,
            _mm256_mul_ps, _mm256_set1_ps, _mm256_setzero_ps, _mm256_storeu_ps, _mm256_sub_ps,
            _CMP_LE_OS,
        };
        let mut entry = [0.0; WIDTH];
        let mut t0 = _mm256_setzero_ps();
        let mut t1 = _mm256_set1_ps(t_max);
        for axis in 0..3 {
            let origin = _mm256_set1_ps(self.origin[axis]);
            let inv_dir = _mm256_set1_ps(self.inv_dir[axis]);
            // The eight lanes' planes lie in one row of 32 bytes.
            let near = &node.bounds[self.near[axis] & 1][axis];
            let far = &node.bounds[(self.near[axis] ^ 1) & 1][axis];
            // SAFETY: each row is eight f32s.
            let (near, far) = unsafe {
                (
                    _mm256_loadu_ps(near.as_ptr().cast()),
                    _mm256_loadu_ps(far.as_ptr().cast()),
                )
            };
            let near = _mm256_mul_ps(_mm256_sub_ps(near, origin), inv_dir);
            let far = _mm256_mul_ps(
                _mm256_mul_ps(_mm256_sub_ps(far, origin), inv_dir),
                _mm256_set1_ps(FAR_SCALE),
            );
            // maxps/minps return their second operand where a lane is NaN, as the SSE2
            // test's `max_or_acc` does.
            t0 = _mm256_max_ps(near, t0);
            t1 = _mm256_min_ps(far, t1);
        }
        // SAFETY: `entry` holds eight f32s.
        unsafe { _mm256_storeu_ps(entry.as_mut_ptr(), t0) };
        // `_CMP_LE_OS` is SSE2's `cmpleps`: false where a lane is NaN.
        let hits = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OS>(t0, t1)) as u32;
        (entry, hits)
    }

    /// [`Self::enter`] in SSE2 halves of four lanes.
    #[inline(always)]
    fn enter_halves(&self, node: &WideNode, t_max: f32) -> ([f32; WIDTH], u32) {
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
                let (origin, inv_dir) = (
                    Vec4::splat(self.origin[axis]),
                    Vec4::splat(self.inv_dir[axis]),
                );
                let near = (near - origin) * inv_dir;
                let far = (far - origin) * inv_dir * FAR_SCALE;
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
pub(super) const PREFETCH_ABOVE: usize = 256;

/// Asks the CPU to start loading the two cache lines from `item` on (a node, or the first
/// triangles of a leaf) into the cache.
#[inline(always)]
pub(super) fn prefetch<T>(item: &T) {
    let p = (item as *const T).cast::<u8>();
    prefetch_line(p);
    // (The address may lie past the end of `item`'s allocation: `wrapping_add` computes it
    // without the in-bounds promise that `add` makes.)
    prefetch_line(p.wrapping_add(64));
}

/// Asks the CPU to start loading the cache line that holds `p`.
#[inline(always)]
fn prefetch_line(p: *const u8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint; it reads nothing and cannot fault, wherever `p` points.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// What a traversal searches, and in what order it visits a node's children (see
/// [`traverse_wide`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Walk {
    /// The one lane of the root whose subtree (or leaf) is searched; `None`: the whole tree.
    pub root_lane: Option<u32>,
    /// Nearest first, for a closest-hit search; else in reverse lane order.
    pub nearest_first: bool,
}

/// Visits the leaves of an eight-wide hierarchy (under `walk.root_lane` alone, if given)
/// whose boxes the ray enters before `t_max`; `leaf` and `stack` work as for the binary
/// [`traverse`](super::node::traverse). Stack entries name a node's lane
/// (`8·node + lane`). In a large tree each child node entered is
/// prefetched when it is pushed, and `prefetch_leaf(start, count)` is called for each leaf
/// entered, so that its primitives can be on their way into the cache by the time it is
/// visited; not for a leaf that a closest-hit search visits at once (a node's only child
/// entered, or the nearer of two), and of a node it moves to at once, only the line of its
/// lanes' `start` and `count`.
///
/// With `walk.nearest_first` (a constant in each query, which this is inlined into), a node's
/// children are visited nearest first (at equal distances the later lane first), and one
/// that a closer hit has ruled out since it was pushed is skipped: what a closest-hit
/// search needs. Without, they are visited in reverse lane order, unsorted, as Embree's
/// occlusion queries do: a search for any hit ends at its first accepted hit, so `t_max`
/// never shrinks and the order cannot change its answer (whether there is one).
#[inline(always)]
pub(super) fn traverse_wide<const AVX: bool>(
    nodes: &[WideNode],
    ray: &WideRay,
    t_max: &mut f32,
    stack: &mut [Deferred],
    walk: Walk,
    prefetch_leaf: impl Fn(u32, u32),
    mut leaf: impl FnMut(u32, u32, &mut f32, &mut [Deferred]) -> bool,
) {
    if nodes.is_empty() {
        return;
    }
    let nearest_first = walk.nearest_first;
    let prefetching = nodes.len() > PREFETCH_ABOVE;
    // Fetch each child pushed as it is pushed: in a large tree each node is a cache miss,
    // and misses issued together overlap.
    let fetch = |node: &WideNode, lane: usize| {
        if prefetching {
            let start = node.start[lane];
            if node.count[lane] == 0 {
                // Its four lines: 0 and 1 from the start, 2 and 3 from byte 128.
                let child = &nodes[start as usize];
                prefetch(child);
                prefetch(&child.bounds[1][1]);
            } else {
                prefetch_leaf(start, node.count[lane]);
            }
        }
    };
    // Entries `..len` of `stack` are this traversal's; a leaf gets the rest.
    let mut len = 0;
    let mut current = 0u32;
    // One lane of the root searched alone is where the pop below starts, at a distance
    // that nothing rules out: whoever asked for it has tested its box.
    let mut pop_first = false;
    if let Some(lane) = walk.root_lane {
        stack[0] = (lane, f32::NEG_INFINITY);
        len = 1;
        pop_first = true;
    }
    loop {
        if !pop_first {
            let node = &nodes[current as usize];
            let (entry, hits) = ray.enter::<AVX>(node, *t_max);
            // The lane to visit next when this node decides it without the stack: its only
            // child entered, or the nearer of two (at equal distances the later lane, as the
            // sort below orders them). As Embree's traversal does: most nodes are entered by
            // one or two children, and a push, a sort and a pop mispredict where a compare
            // need not.
            let next = match ones_up_to_three(hits) {
                0 => None,
                1 if nearest_first => Some(hits.trailing_zeros() as usize),
                2 if nearest_first => {
                    let (a, b) = (
                        hits.trailing_zeros() as usize,
                        31 - hits.leading_zeros() as usize,
                    );
                    let (near, far) = if entry[a] < entry[b] { (a, b) } else { (b, a) };
                    fetch(node, far);
                    stack[len] = (current * WIDTH as u32 + far as u32, entry[far]);
                    len += 1;
                    Some(near)
                }
                _ => {
                    // Push the children entered; nearest first, kept in falling order of
                    // distance above `first`, so that the nearest is popped first.
                    let first = len;
                    let mut hits = hits;
                    while hits != 0 {
                        let lane = hits.trailing_zeros();
                        hits &= hits - 1;
                        fetch(node, lane as usize);
                        stack[len] = (current * WIDTH as u32 + lane, entry[lane as usize]);
                        let mut i = len;
                        len += 1;
                        while nearest_first && i > first && stack[i - 1].1 < stack[i].1 {
                            stack.swap(i - 1, i);
                            i -= 1;
                        }
                    }
                    None
                }
            };
            if let Some(lane) = next {
                if node.count[lane] == 0 {
                    current = node.start[lane];
                    if prefetching {
                        // The line of its lanes' `start` and `count` (the last of its four):
                        // read only once its node test has picked a lane, it would miss after
                        // the boxes' miss; asked for now, the two misses overlap.
                        prefetch_line((&nodes[current as usize].start as *const u32).cast());
                    }
                    continue;
                }
                // A leaf goes through the stack after all: the leaf's code is then inlined once.
                stack[len] = (current * WIDTH as u32 + lane as u32, entry[lane]);
                len += 1;
            }
        }
        pop_first = false;
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

/// How many bits of `bits` are set, counting three for more than two: by clearing the
/// lowest set bit twice, where `count_ones` is a dozen instructions without the POPCNT
/// instruction, which the baseline CPU lacks (3% of a closest-hit query's instructions).
#[inline(always)]
fn ones_up_to_three(bits: u32) -> u32 {
    let clear_lowest = |b: u32| b & b.wrapping_sub(1);
    if bits == 0 {
        0
    } else if clear_lowest(bits) == 0 {
        1
    } else if clear_lowest(clear_lowest(bits)) == 0 {
        2
    } else {
        3
    }
}

#[cfg(test)]
mod tests;
