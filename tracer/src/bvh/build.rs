//! Binned SAH construction, shared by the mesh and instance levels: Wald, "On fast
//! Construction of SAH-based Bounding Volume Hierarchies", IEEE RT 2007.
//!
//! Each node bins its primitives' box centroids into [`BINS`] slots per axis, sweeps the
//! bins to price every split plane with the surface area heuristic, and either splits at the
//! cheapest plane or becomes a leaf when that is cheaper (MacDonald & Booth 1990). A level
//! costs O(n), so the build is O(n log n) for any sane input. Two guards keep hostile input
//! in check: below depth [`SAH_MAX_DEPTH`] (or when binning finds no usable plane, e.g. all
//! centroids equal or areas overflowing) nodes split at the object median instead, which
//! bounds the depth by 64 and the work by O(n log n) whatever the input.

use glam::{UVec3, Vec3, Vec3A};

use super::node::Node;

/// Most bins per axis. Wald reports 16 to be about as good as a full sweep; a node with
/// fewer primitives uses as many bins as primitives, since sweeping empty bins costs more
/// than binning for the millions of small nodes near the leaves.
const BINS: usize = 16;

/// Depth from which nodes split at the object median, which halves the primitive count, so
/// that no path is longer than 32 + 32 nodes for up to 2^32 primitives, whatever the input:
/// traversal stays fast, and its stack short.
pub(super) const SAH_MAX_DEPTH: u32 = 32;

/// Costs and limits for one level of the hierarchy.
#[derive(Clone, Copy, Debug)]
pub(super) struct BuildParams {
    /// Largest leaf; a larger node is split even where SAH prefers a leaf.
    pub max_leaf: u32,
    /// Cost of visiting one node (two box tests), relative to `intersect_cost`.
    pub traversal_cost: f32,
    /// Cost of testing one primitive.
    pub intersect_cost: f32,
}

/// A primitive as the builder sees it: its box and its index in the caller's order.
#[derive(Clone, Copy, Debug)]
pub(super) struct BuildPrim {
    pub min: Vec3,
    pub max: Vec3,
    pub index: u32,
}

// The builder computes in Vec3A, whose min/max are single SIMD instructions; it sees no
// NaN (primitives are finite), so their NaN behaviour does not matter here.
impl BuildPrim {
    #[inline]
    fn min(&self) -> Vec3A {
        self.min.into()
    }

    #[inline]
    fn max(&self) -> Vec3A {
        self.max.into()
    }

    /// Box centroid, written so that boxes reaching ±f32::MAX do not overflow to infinity.
    #[inline]
    fn centroid(&self) -> Vec3A {
        self.min() * 0.5 + self.max() * 0.5
    }
}

#[derive(Clone, Copy)]
struct Bin {
    min: Vec3A,
    max: Vec3A,
    count: u32,
}

const EMPTY_BIN: Bin = Bin {
    min: Vec3A::INFINITY,
    max: Vec3A::NEG_INFINITY,
    count: 0,
};

/// Half the surface area of a box (the factor 2 cancels in SAH ratios); 0 when empty.
#[inline]
pub(super) fn half_area(min: Vec3A, max: Vec3A) -> f32 {
    let e = (max - min).max(Vec3A::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// A node waiting to be built: its slot in the node array and its primitive range.
struct Task {
    node: usize,
    begin: usize,
    end: usize,
    depth: u32,
}

/// A chosen split: primitives go left when their centroid's bin along `axis` (of `bins`)
/// is below `bin`.
#[derive(Clone, Copy)]
struct Split {
    axis: usize,
    bins: usize,
    bin: usize,
    /// Σ half-area × count over both children.
    cost: f32,
}

/// Subtrees with at least this many primitives build their two children in parallel.
/// Each parallel level copies its subtree's nodes once when joining, so it only pays off
/// for large ranges.
const PARALLEL_MIN: usize = 1 << 15;

/// Builds the hierarchy over `prims`, reordering them so that every leaf's primitives are
/// contiguous. Returns the nodes (empty for no primitives); node 0 is the root, and every
/// node's children come after it. The result does not depend on the thread count.
pub(super) fn build(prims: &mut [BuildPrim], params: &BuildParams) -> Vec<Node> {
    if prims.is_empty() {
        return Vec::new();
    }
    let mut nodes = build_subtree(prims, 0, 0, params);
    nodes.shrink_to_fit();
    nodes
}

/// Builds the subtree over `prims`, which start at `offset` in the whole primitive array,
/// splitting large ranges in parallel with `rayon::join`. The subtree's root is its node 0.
fn build_subtree(
    prims: &mut [BuildPrim],
    offset: usize,
    depth: u32,
    params: &BuildParams,
) -> Vec<Node> {
    if prims.len() < PARALLEL_MIN {
        return build_sequential(prims, offset, depth, params);
    }
    let (min, max, split) = split_node(prims, depth, params);
    let Some(mid) = split else {
        return vec![Node {
            min,
            start: offset as u32,
            max,
            count: prims.len() as u32,
        }];
    };
    let (left, right) = prims.split_at_mut(mid);
    let (l, r) = rayon::join(
        || build_subtree(left, offset, depth + 1, params),
        || build_subtree(right, offset + mid, depth + 1, params),
    );
    // Layout: root, both subtree roots, then the rest of the left and right subtrees.
    // Interior nodes' child indices move with their subtree.
    let shift = |n: &Node, by: usize| {
        if n.count == 0 {
            Node {
                start: n.start + by as u32,
                ..*n
            }
        } else {
            *n
        }
    };
    let (l_shift, r_shift) = (2, l.len() + 1);
    let mut nodes = Vec::with_capacity(1 + l.len() + r.len());
    nodes.push(Node {
        min,
        start: 1,
        max,
        count: 0,
    });
    nodes.push(shift(&l[0], l_shift));
    nodes.push(shift(&r[0], r_shift));
    nodes.extend(l[1..].iter().map(|n| shift(n, l_shift)));
    nodes.extend(r[1..].iter().map(|n| shift(n, r_shift)));
    nodes
}

/// Builds the subtree over `prims` (at `offset` in the whole array) on this thread,
/// depth first with an explicit stack, so lopsided inputs cannot overflow the call stack.
fn build_sequential(
    prims: &mut [BuildPrim],
    offset: usize,
    depth: u32,
    params: &BuildParams,
) -> Vec<Node> {
    // A binary tree with leaves of at least one primitive has at most 2n - 1 nodes.
    let mut nodes = Vec::with_capacity(2 * prims.len() - 1);
    nodes.push(placeholder());
    let mut tasks = vec![Task {
        node: 0,
        begin: 0,
        end: prims.len(),
        depth,
    }];
    while let Some(task) = tasks.pop() {
        let range = &mut prims[task.begin..task.end];
        let (min, max, split) = split_node(range, task.depth, params);
        let Some(mid) = split else {
            let start = (offset + task.begin) as u32;
            nodes[task.node] = Node {
                min,
                start,
                max,
                count: range.len() as u32,
            };
            continue;
        };
        let left = nodes.len();
        nodes.push(placeholder());
        nodes.push(placeholder());
        nodes[task.node] = Node {
            min,
            start: left as u32,
            max,
            count: 0,
        };
        let depth = task.depth + 1;
        // Push right first so the left subtree is built (and laid out) first.
        let (begin, mid, end) = (task.begin, task.begin + mid, task.end);
        tasks.push(Task {
            node: left + 1,
            begin: mid,
            end,
            depth,
        });
        tasks.push(Task {
            node: left,
            begin,
            end: mid,
            depth,
        });
    }
    nodes
}

/// Decides one node over `prims`: returns its bounds and, when it is to be split, the
/// number of primitives that now lie in the left child (the slice is partitioned).
fn split_node(
    prims: &mut [BuildPrim],
    depth: u32,
    params: &BuildParams,
) -> (Vec3, Vec3, Option<usize>) {
    let count = prims.len();
    // Node bounds and centroid bounds in one pass.
    let (mut min, mut max) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    let (mut cmin, mut cmax) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    for p in prims.iter() {
        min = min.min(p.min());
        max = max.max(p.max());
        let c = p.centroid();
        cmin = cmin.min(c);
        cmax = cmax.max(c);
    }
    let leaf = (min.into(), max.into(), None);
    if count == 1 {
        return leaf;
    }
    let may_be_leaf = count as u32 <= params.max_leaf;
    let split = if depth < SAH_MAX_DEPTH {
        best_split(prims, cmin, cmax)
    } else {
        None
    };
    let mid = match split {
        Some(split) => {
            let parent = half_area(min, max);
            let leaf_cost = params.intersect_cost * count as f32 * parent;
            let split_cost = params.traversal_cost * parent + params.intersect_cost * split.cost;
            // Costs are scaled by the parent's area rather than divided by it, so a
            // zero-area node compares 0 with 0 and becomes a leaf if it may.
            if may_be_leaf && leaf_cost <= split_cost {
                return leaf;
            }
            partition_at(prims, split, cmin, cmax)
        }
        None if may_be_leaf => return leaf,
        None => median_split(prims, cmin, cmax),
    };
    (min.into(), max.into(), Some(mid))
}

fn placeholder() -> Node {
    Node {
        min: Vec3::ZERO,
        start: 0,
        max: Vec3::ZERO,
        count: 0,
    }
}

/// Scale mapping a centroid coordinate to one of `bins` bins along each axis (0 for a
/// flat axis, which then puts everything in bin 0 and is skipped).
#[inline]
fn bin_scale(cmin: Vec3A, cmax: Vec3A, bins: usize) -> Vec3A {
    let extent = cmax - cmin;
    // Slightly under bins / extent so the largest centroid lands in the last bin.
    let s = Vec3A::splat(bins as f32 * (1.0 - 1e-6)) / extent;
    Vec3A::select(
        extent.cmpgt(Vec3A::ZERO) & s.is_finite_mask(),
        s,
        Vec3A::ZERO,
    )
}

/// Bins of centroid `c` along the three axes; float-to-int casts saturate, so rounding
/// at the ends still lands in a valid bin.
#[inline]
fn bins_of(c: Vec3A, cmin: Vec3A, scale: Vec3A, bins: usize) -> UVec3 {
    ((c - cmin) * scale)
        .as_uvec3()
        .min(UVec3::splat(bins as u32 - 1))
}

/// The cheapest SAH plane over all axes, or None when no plane separates the centroids
/// or every candidate's cost overflowed.
fn best_split(prims: &[BuildPrim], cmin: Vec3A, cmax: Vec3A) -> Option<Split> {
    let nb = prims.len().clamp(2, BINS);
    let scale = bin_scale(cmin, cmax, nb);
    let mut bins = [[EMPTY_BIN; BINS]; 3];
    for p in prims {
        let (pmin, pmax) = (p.min(), p.max());
        let b = bins_of(p.centroid(), cmin, scale, nb);
        for (axis, bins) in bins.iter_mut().enumerate() {
            let bin = &mut bins[b[axis] as usize];
            bin.min = bin.min.min(pmin);
            bin.max = bin.max.max(pmax);
            bin.count += 1;
        }
    }

    let mut best: Option<Split> = None;
    for (axis, bins) in bins.iter().enumerate() {
        if scale[axis] == 0.0 {
            continue;
        }
        let bins = &bins[..nb];
        // Sweep from the right: cost share of bins[i..] for each plane i.
        let mut right_cost = [0.0f32; BINS];
        let mut acc = EMPTY_BIN;
        for i in (1..nb).rev() {
            acc.min = acc.min.min(bins[i].min);
            acc.max = acc.max.max(bins[i].max);
            acc.count += bins[i].count;
            right_cost[i] = if acc.count == 0 {
                f32::NAN
            } else {
                half_area(acc.min, acc.max) * acc.count as f32
            };
        }
        // Sweep from the left, pricing plane i between bins i-1 and i.
        let mut acc = EMPTY_BIN;
        for i in 1..nb {
            acc.min = acc.min.min(bins[i - 1].min);
            acc.max = acc.max.max(bins[i - 1].max);
            acc.count += bins[i - 1].count;
            if acc.count == 0 {
                continue;
            }
            // NaN (an empty right side, or overflowing areas) never compares less.
            let cost = half_area(acc.min, acc.max) * acc.count as f32 + right_cost[i];
            if cost.is_finite() && best.is_none_or(|b| cost < b.cost) {
                best = Some(Split {
                    axis,
                    bins: nb,
                    bin: i,
                    cost,
                });
            }
        }
    }
    best
}

/// Moves the primitives left of `split` to the front; returns how many there are (never
/// 0 nor all, since the split was priced from non-empty sides).
fn partition_at(prims: &mut [BuildPrim], split: Split, cmin: Vec3A, cmax: Vec3A) -> usize {
    let scale = bin_scale(cmin, cmax, split.bins);
    let goes_left = |p: &BuildPrim| {
        (bins_of(p.centroid(), cmin, scale, split.bins)[split.axis] as usize) < split.bin
    };
    // Hoare-style in-place partition.
    let (mut i, mut j) = (0, prims.len());
    while i < j {
        if goes_left(&prims[i]) {
            i += 1;
        } else {
            j -= 1;
            prims.swap(i, j);
        }
    }
    i
}

/// Splits at the object median along the axis of largest centroid extent: always two
/// non-empty halves, whatever the centroids.
fn median_split(prims: &mut [BuildPrim], cmin: Vec3A, cmax: Vec3A) -> usize {
    let axis = (cmax - cmin).max_position();
    let mid = prims.len() / 2;
    prims.select_nth_unstable_by(mid, |a, b| {
        a.centroid()[axis].total_cmp(&b.centroid()[axis])
    });
    mid
}

#[cfg(test)]
mod tests {
    use super::*;

    const PARAMS: BuildParams = BuildParams {
        max_leaf: 4,
        traversal_cost: 1.0,
        intersect_cost: 1.0,
    };

    fn point_prims(points: &[Vec3]) -> Vec<BuildPrim> {
        points
            .iter()
            .enumerate()
            .map(|(i, &p)| BuildPrim {
                min: p,
                max: p + Vec3::splat(0.01),
                index: i as u32,
            })
            .collect()
    }

    /// Checks that every primitive is in exactly one leaf, each child box lies inside its
    /// parent's, children follow their parents, and returns the depth.
    fn check(nodes: &[Node], prims: &[BuildPrim], n: usize) -> u32 {
        let mut seen = vec![0u32; n];
        let mut stack = vec![(0usize, 0u32)];
        let mut depth = 0;
        while let Some((i, d)) = stack.pop() {
            depth = depth.max(d);
            let node = nodes[i];
            if node.count > 0 {
                for p in &prims[node.start as usize..(node.start + node.count) as usize] {
                    seen[p.index as usize] += 1;
                    assert!(p.min.cmpge(node.min).all() && p.max.cmple(node.max).all());
                }
            } else {
                for c in [node.start as usize, node.start as usize + 1] {
                    assert!(c > i);
                    assert!(nodes[c].min.cmpge(node.min).all());
                    assert!(nodes[c].max.cmple(node.max).all());
                    stack.push((c, d + 1));
                }
            }
        }
        assert!(seen.iter().all(|&s| s == 1));
        depth
    }

    #[test]
    fn empty_input_gives_no_nodes() {
        assert!(build(&mut [], &PARAMS).is_empty());
    }

    #[test]
    fn identical_centroids_split_at_the_median() {
        let mut prims = point_prims(&vec![Vec3::ONE; 1000]);
        let nodes = build(&mut prims, &PARAMS);
        let depth = check(&nodes, &prims, 1000);
        assert!(depth <= 10, "depth {depth}");
        assert!(nodes.iter().all(|n| n.count <= PARAMS.max_leaf));
    }

    #[test]
    fn exponentially_spaced_centroids_stay_shallow() {
        // Binning separates only the last point per level here; the depth guard must
        // switch to median splits.
        let points: Vec<Vec3> = (0..3000).map(|i| Vec3::splat(1.01f32.powi(i))).collect();
        let mut prims = point_prims(&points);
        let nodes = build(&mut prims, &PARAMS);
        let depth = check(&nodes, &prims, points.len());
        assert!(depth <= 2 * SAH_MAX_DEPTH, "depth {depth}");
    }

    #[test]
    fn huge_boxes_do_not_break_the_build() {
        let mut points: Vec<Vec3> = (0..100).map(|i| Vec3::splat(i as f32)).collect();
        points.push(Vec3::splat(-f32::MAX));
        let mut prims = point_prims(&points);
        prims.push(BuildPrim {
            min: Vec3::splat(-f32::MAX),
            max: Vec3::splat(f32::MAX),
            index: 101,
        });
        let nodes = build(&mut prims, &PARAMS);
        check(&nodes, &prims, 102);
    }

    #[test]
    fn parallel_build_lays_out_the_same_tree_as_the_sequential_one() {
        let mut state = 0x853c_49e6_748f_ea9bu64;
        let mut f = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let n = 3 * PARALLEL_MIN;
        let points: Vec<Vec3> = (0..n).map(|_| Vec3::new(f(), f(), f() * 0.1)).collect();
        let prims = point_prims(&points);
        let (mut a, mut b) = (prims.clone(), prims);
        let parallel = build(&mut a, &PARAMS);
        let sequential = build_sequential(&mut b, 0, 0, &PARAMS);
        assert_eq!(parallel, sequential);
        assert!(a.iter().zip(&b).all(|(a, b)| a.index == b.index));
        check(&parallel, &a, n);
    }

    #[test]
    fn sah_separates_two_clusters_at_the_root() {
        let mut points: Vec<Vec3> = (0..50)
            .map(|i| Vec3::new(i as f32 * 0.001, 0.0, 0.0))
            .collect();
        points.extend((0..50).map(|i| Vec3::new(100.0 + i as f32 * 0.001, 0.0, 0.0)));
        let mut prims = point_prims(&points);
        let nodes = build(&mut prims, &PARAMS);
        check(&nodes, &prims, 100);
        let (l, r) = (
            nodes[nodes[0].start as usize],
            nodes[nodes[0].start as usize + 1],
        );
        assert!(l.max.x < 1.0 && r.min.x > 99.0);
    }
}
