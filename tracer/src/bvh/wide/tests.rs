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

/// The binary SAH tree over `prims`, a node visit priced as one test, leaves of up to
/// `max_leaf`.
fn binary_tree(prims: &mut [BuildPrim], max_leaf: u32) -> Vec<Node> {
    let params = BuildParams {
        max_leaf,
        traversal_cost: 1.0,
        intersect_cost: 1.0,
    };
    build(prims, &params)
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
        let binary = binary_tree(&mut prims, 2);
        let wide = collapse(&binary, None);
        check_collapse(&binary, &wide);
        // In the order of their primitives.
        assert_eq!(leaves(&wide), binary_leaves(&binary), "{n} primitives");
        // Merged: every primitive in exactly one leaf still, none larger than asked.
        let merged = collapse(&binary, Some(MERGE));
        check_collapse(&binary, &merged);
        let merged_leaves = leaves(&merged);
        assert!(merged_leaves
            .iter()
            .all(|&(_, count)| count <= MERGE.max_leaf));
        assert_leaves_cover(&merged_leaves, n as u32);
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

/// `leaves`, in order, hold primitives `0..n`, each exactly once.
fn assert_leaves_cover(leaves: &[(u32, u32)], n: u32) {
    let mut next = 0;
    for &(start, count) in leaves {
        assert_eq!(start, next, "{n} primitives");
        next += count;
    }
    assert_eq!(next, n);
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
    let binary = binary_tree(&mut prims, 4);
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
            traverse_wide::<false>(
                &wide,
                &WideRay::new(&ray),
                &mut { t_max },
                &mut stack,
                Walk {
                    root_lane: None,
                    nearest_first,
                },
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

/// The leaves in the order a closest-hit search visits them when no hit lowers
/// `t_max`, by the rule the traversal keeps: every child entered goes on a stack,
/// nearest on top, and at equal distances the later lane on top.
fn reference_order(nodes: &[WideNode], ray: &WideRay, t_max: f32) -> Vec<(u32, u32)> {
    let (mut order, mut stack) = (Vec::new(), Vec::new());
    let mut current = 0;
    loop {
        let (entry, hits) = ray.enter::<false>(&nodes[current], t_max);
        let mut children: Vec<(usize, f32)> = (0..WIDTH)
            .filter(|lane| hits >> lane & 1 == 1)
            .map(|lane| (lane, entry[lane]))
            .collect();
        children.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        stack.extend(children.iter().map(|&(lane, _)| (current, lane)));
        loop {
            let Some((node, lane)) = stack.pop() else {
                return order;
            };
            let (start, count) = (nodes[node].start[lane], nodes[node].count[lane]);
            if count == 0 {
                current = start as usize;
                break;
            }
            order.push((start, count));
        }
    }
}

#[test]
fn a_closest_hit_search_visits_leaves_nearest_first_and_ties_by_lane() {
    // Boxes on an integer grid, so that many children are entered at the same
    // distance, and random ones; rays from grid points along axes and at random.
    let mut rng = Rng(5);
    let mut prims = random_prims(&mut rng, 200);
    for (i, p) in prims.iter_mut().enumerate().take(120) {
        let c = Vec3::new((i % 5) as f32, (i / 5 % 4) as f32, (i / 20) as f32);
        (p.min, p.max) = (c, c + 1.0);
    }
    let binary = binary_tree(&mut prims, 2);
    let wide = collapse(&binary, None);
    let mut stack = [(0, 0.0); STACK_CAPACITY];
    for i in 0..2000 {
        let ray = if i % 2 == 0 {
            let origin = Vec3::new((i % 7) as f32 - 1.0, (i % 3) as f32 + 0.5, -2.0);
            Ray::new(origin, [Vec3::Z, Vec3::X, Vec3::ONE][i % 3])
        } else {
            Ray::new(rng.vec3() * 14.0 - 2.0, rng.vec3() * 2.0 - 1.0)
        };
        let wide_ray = WideRay::new(&ray);
        let mut order = Vec::new();
        traverse_wide::<false>(
            &wide,
            &wide_ray,
            &mut { f32::INFINITY },
            &mut stack,
            Walk {
                root_lane: None,
                nearest_first: true,
            },
            |_, _| {},
            |s, c, _, _| {
                order.push((s, c));
                false
            },
        );
        assert_eq!(
            order,
            reference_order(&wide, &wide_ray, f32::INFINITY),
            "{ray:?}"
        );
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
    let binary = binary_tree(&mut prims, 1);
    let wide = collapse(&binary, None);
    let ray = WideRay::new(&Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X));
    // The caller's entry below the part it hands on stays as it was.
    let mut stack = [(0, 0.0); STACK_CAPACITY];
    stack[0] = (7, 1.0);
    let mut order = Vec::new();
    let mut t_max = f32::INFINITY;
    traverse_wide::<false>(
        &wide,
        &ray,
        &mut t_max,
        &mut stack[1..],
        Walk {
            root_lane: None,
            nearest_first: true,
        },
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
    traverse_wide::<false>(
        &wide,
        &ray,
        &mut t_max,
        &mut stack[1..],
        Walk {
            root_lane: None,
            nearest_first: true,
        },
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
        traverse_wide::<false>(
            &nodes,
            &ray,
            &mut t_max,
            &mut stack,
            Walk {
                root_lane: None,
                nearest_first: true,
            },
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
fn ones_up_to_three_counts_every_mask_of_a_node() {
    for bits in 0..1u32 << WIDTH {
        assert_eq!(
            ones_up_to_three(bits),
            bits.count_ones().min(3),
            "{bits:#b}"
        );
    }
}

#[test]
fn empty_lanes_are_never_entered() {
    let node = WideNode::EMPTY;
    for dir in [Vec3::X, -Vec3::Y, Vec3::new(0.0, -0.0, 1.0), Vec3::ONE] {
        for origin in [Vec3::ZERO, Vec3::splat(1e30), Vec3::splat(-3.0)] {
            let (_, hits) =
                WideRay::new(&Ray::new(origin, dir)).enter::<false>(&node, f32::INFINITY);
            assert_eq!(hits, 0, "{origin} {dir}");
        }
    }
}

/// The AVX node test gives the SSE2 test's bits: entry distances and hit masks, on nodes
/// of random, flat, empty and unused lanes, for rays along axes (zero directions: NaN
/// products in the slab planes), from on a plane, and at random.
#[test]
fn the_avx_node_test_gives_the_same_bits_as_sse2() {
    if !crate::simd::avx() {
        // Straight to stderr, past the test harness's capture: a skip must be seen.
        use std::io::Write;
        let _ = writeln!(
            std::io::stderr(),
            "WARNING: the AVX node test is not compared: this CPU has no AVX"
        );
        return;
    }
    let mut rng = Rng(29);
    let coords = [0.0, 1.0, -1.0, 2.5, f32::MAX, f32::INFINITY];
    let mut checked = 0;
    for n in 0..20_000 {
        let mut node = WideNode::EMPTY;
        for lane in 0..(n % WIDTH) + 1 {
            let (a, b) = if n % 3 == 0 {
                let pick = |r: &mut Rng| coords[(r.next_f32() * 6.0) as usize];
                let v = |r: &mut Rng| Vec3::new(pick(r), pick(r), pick(r));
                (v(&mut rng), v(&mut rng))
            } else {
                (rng.vec3() * 4.0 - 2.0, rng.vec3() * 4.0 - 2.0)
            };
            let child = Node {
                min: a.min(b),
                max: a.max(b),
                start: 0,
                count: 1,
            };
            node.set_lane(lane, &child, 0, 1);
        }
        let axis_dir = [Vec3::X, -Vec3::Y, Vec3::Z, Vec3::new(0.0, -0.0, 1.0)][n % 4];
        let dir = if n % 2 == 0 {
            axis_dir
        } else {
            rng.vec3() - 0.5
        };
        let origin = if n % 5 == 0 {
            Vec3::new(1.0, -1.0, 0.0)
        } else {
            rng.vec3() * 6.0 - 3.0
        };
        let ray = WideRay::new(&Ray::new(origin, dir));
        for t_max in [f32::INFINITY, 1.5] {
            let (sse_entry, sse_hits) = ray.enter::<false>(&node, t_max);
            // SAFETY: the CPU has AVX (checked above).
            let (avx_entry, avx_hits) = unsafe { ray.enter_avx(&node, t_max) };
            assert_eq!(avx_hits, sse_hits, "{node:?} {origin} {dir}");
            // (Only entered lanes' distances are read: the SSE2 test skips the second
            // half of a node of four children or fewer.)
            for lane in (0..WIDTH).filter(|lane| sse_hits >> lane & 1 == 1) {
                assert_eq!(avx_entry[lane].to_bits(), sse_entry[lane].to_bits());
            }
            checked += sse_hits.count_ones();
        }
    }
    assert!(checked > 10_000, "{checked} lanes entered");
}

/// The SAH cost of an eight-wide tree as [`collapse`] prices it: each node's box area
/// times `node_cost`, each leaf's area times its primitives.
fn wide_cost(wide: &[WideNode], node_cost: f64) -> f64 {
    let area = |b: Aabb| f64::from(half_area(b.min.into(), b.max.into()));
    wide.iter()
        .map(|node| {
            let leaves = (0..WIDTH).filter(|&l| node.count[l] > 0);
            node_cost * area(node.bounds())
                + leaves
                    .map(|l| f64::from(node.count[l]) * area(node.lane_box(l)))
                    .sum::<f64>()
        })
        .sum()
}

/// The least cost of any collapse of `binary`, by trying every one: each node's lanes are
/// any cut of its binary subtree into at most eight subtrees, each a leaf (a binary leaf,
/// or with `merge` a small enough subtree) or a node again.
fn cheapest_by_trying_all(binary: &[Node], merge: Option<Merge>) -> f64 {
    let node_cost = merge.map_or(1.0, |m| m.node_cost);
    let area = |n: usize| f64::from(node_area(&binary[n]));
    let count = |n: usize| -> u32 {
        let node = &binary[n];
        if node.count > 0 {
            return node.count;
        }
        let mut todo = vec![n];
        let mut total = 0;
        while let Some(n) = todo.pop() {
            let node = &binary[n];
            if node.count > 0 {
                total += node.count;
            } else {
                todo.extend([node.start as usize, node.start as usize + 1]);
            }
        }
        total
    };
    // Every cut of subtree `n` into at most eight subtrees.
    fn cuts(binary: &[Node], n: usize) -> Vec<Vec<usize>> {
        let mut all = vec![vec![n]];
        if binary[n].count == 0 {
            let l = binary[n].start as usize;
            for a in cuts(binary, l) {
                for b in cuts(binary, l + 1) {
                    if a.len() + b.len() <= WIDTH {
                        all.push([a.clone(), b].concat());
                    }
                }
            }
        }
        all
    }
    // The least cost of subtree `n` as a node over a cut of its children, and in one lane.
    fn as_node(binary: &[Node], n: usize, cost: &dyn Fn(usize) -> (f64, f64, bool)) -> f64 {
        let l = binary[n].start as usize;
        let mut best = f64::INFINITY;
        for a in cuts(binary, l) {
            for b in cuts(binary, l + 1) {
                if a.len() + b.len() <= WIDTH {
                    let lanes: f64 = a.iter().chain(&b).map(|&c| lane(binary, c, cost)).sum();
                    best = best.min(cost(n).0 + lanes);
                }
            }
        }
        best
    }
    fn lane(binary: &[Node], n: usize, cost: &dyn Fn(usize) -> (f64, f64, bool)) -> f64 {
        let (_, as_leaf, may_be_leaf) = cost(n);
        let leaf = if may_be_leaf { as_leaf } else { f64::INFINITY };
        if binary[n].count > 0 {
            return leaf;
        }
        leaf.min(as_node(binary, n, cost))
    }
    let cost = |n: usize| {
        let c = count(n);
        let may_be_leaf = binary[n].count > 0 || merge.is_some_and(|m| c <= m.max_leaf);
        (node_cost * area(n), f64::from(c) * area(n), may_be_leaf)
    };
    // The root is a node, over one lane if it is a binary leaf.
    if binary[0].count > 0 {
        cost(0).0 + cost(0).1
    } else {
        as_node(binary, 0, &cost)
    }
}

#[test]
fn collapse_is_the_cheapest_by_the_surface_area_heuristic() {
    let mut rng = Rng(9);
    for n in [2, 3, 9, 14, 17, 20] {
        let mut prims = random_prims(&mut rng, n);
        let binary = binary_tree(&mut prims, 1);
        for (merge, node_cost) in [(None, 1.0), (Some(MERGE), MERGE.node_cost)] {
            let wide = collapse(&binary, merge);
            let (got, least) = (
                wide_cost(&wide, node_cost),
                cheapest_by_trying_all(&binary, merge),
            );
            assert!(
                (got - least).abs() <= 1e-9 * least,
                "{n}: {got} against {least}"
            );
        }
    }
}

/// Lanes a node uses.
fn used_lanes(node: &WideNode) -> usize {
    (0..WIDTH).filter(|&l| !node.lane_box(l).is_empty()).count()
}

#[test]
fn no_node_fits_into_its_parents_free_lanes() {
    // A child node whose lanes fit where it sits and in its parent's free lanes costs a
    // visit that its parent could do: the cheapest collapse has none. (Opening the largest
    // child until a node has eight, as the collapse did before, had none either on these
    // trees: it wasted lanes further down, which the test above catches.)
    let mut rng = Rng(5);
    for (n, max_leaf) in [(9, 1), (100, 2), (1000, 2), (5000, 4)] {
        let mut prims = random_prims(&mut rng, n);
        let binary = binary_tree(&mut prims, max_leaf);
        for wide in [collapse(&binary, None), collapse(&binary, Some(MERGE))] {
            check_collapse(&binary, &wide);
            for node in &wide {
                let free = WIDTH - used_lanes(node);
                for lane in (0..WIDTH).filter(|&l| node.count[l] == 0 && node.start[l] != 0) {
                    let child = used_lanes(&wide[node.start[lane] as usize]);
                    assert!(
                        child > free + 1,
                        "{n}: a child of {child} lanes, {free} free"
                    );
                }
            }
        }
    }
}

#[test]
fn boxes_whose_areas_overflow_still_collapse_into_a_valid_tree() {
    // Flat boxes spanning the whole float range: their extent is infinite, their area
    // inf · 0 = NaN, and so are the costs the collapse compares.
    let mut rng = Rng(8);
    let mut prims: Vec<BuildPrim> = (0..300)
        .map(|i| {
            let y = rng.next_f32() * 1e30;
            BuildPrim {
                min: Vec3::new(-f32::MAX, y, 0.0),
                max: Vec3::new(f32::MAX, y, 0.0),
                index: i,
            }
        })
        .collect();
    let binary = binary_tree(&mut prims, 2);
    for merge in [None, Some(MERGE)] {
        let wide = collapse(&binary, merge);
        check_collapse(&binary, &wide);
        assert_leaves_cover(&leaves(&wide), 300);
    }
}
