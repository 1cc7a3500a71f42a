use super::*;

use crate::bvh::wide::PREFETCH_ABOVE;
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

/// Random rays through `bvh` (built over `tris`) find what testing every triangle finds.
fn assert_matches_brute_force(bvh: &MeshBvh, tris: &[[Vec3; 3]], rng: &mut Rng) {
    for i in 0..3000 {
        let o = rng.vec3() * 14.0 - 2.0;
        let d = rng.vec3() - 0.5;
        let t_max = if i % 3 == 0 { 4.0 } else { f32::INFINITY };
        let ray = Ray::new(o, d);
        let expect = brute(tris, &ray, t_max);
        let got = bvh
            .intersect(&ray, t_max, |_, _, _| true)
            .map(|h| (h.0, h.1));
        assert_eq!(got, expect, "ray {o} {d}");
        assert_eq!(bvh.occluded(&ray, t_max, |_, _, _| true), expect.is_some());
    }
}

#[test]
fn matches_brute_force_on_a_soup() {
    let mut rng = Rng(0x2545f4914f6cdd1d);
    let tris = soup(&mut rng, 3000);
    let bvh = MeshBvh::build(&tris);
    assert_eq!(bvh.triangle_count(), 3000);
    assert_matches_brute_force(&bvh, &tris, &mut rng);
}

#[test]
fn trees_that_prefetch_find_the_same_hits() {
    // Past `PREFETCH_ABOVE` nodes the traversal prefetches the nodes and leaves it will
    // visit: hints that must not change what it finds.
    let mut rng = Rng(0x9e3779b97f4a7c15);
    let tris = soup(&mut rng, 8000);
    let bvh = MeshBvh::build(&tris);
    assert!(
        bvh.node_count() > PREFETCH_ABOVE,
        "{} nodes",
        bvh.node_count()
    );
    assert_matches_brute_force(&bvh, &tris, &mut rng);
}

#[test]
fn merged_trees_hold_fewer_nodes_and_find_the_same_hits() {
    let mut rng = Rng(0x2545f4914f6cdd1d);
    let tris = soup(&mut rng, 3000);
    let unmerged = MeshBvh::build_merging_above(&[&tris], usize::MAX).node_count();
    assert!(unmerged <= MERGE_ABOVE);
    assert_eq!(MeshBvh::build(&tris).node_count(), unmerged);
    let bvh = MeshBvh::build_merging_above(&[&tris], 0);
    let merged = bvh.node_count();
    assert!(
        merged < unmerged * 3 / 4,
        "{merged} nodes, {unmerged} unmerged"
    );
    assert_matches_brute_force(&bvh, &tris, &mut rng);
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

/// `steps` copies of a soup, each vertex moved by its own random offset per step
/// (up to about the triangles' size, so boxes overlap differently at each step).
fn moving_soup(rng: &mut Rng, n: usize, steps: usize) -> Vec<Vec<[Vec3; 3]>> {
    let base = soup(rng, n);
    (0..steps)
        .map(|_| {
            base.iter()
                .map(|t| t.map(|v| v + (rng.vec3() - 0.5) * 1.5))
                .collect()
        })
        .collect()
}

/// The closest hit among all triangles interpolated at `ray.time`, in index order.
fn brute_motion(steps: &[Vec<[Vec3; 3]>], ray: &Ray, t_max: f32) -> Option<(f32, u32)> {
    if steps.len() == 1 {
        return brute(&steps[0], ray, t_max);
    }
    let seg = Segment::new(ray.time, steps.len());
    let at: Vec<[Vec3; 3]> = steps[seg.index]
        .iter()
        .zip(&steps[seg.index + 1])
        .map(|(a, b)| [0, 1, 2].map(|j| a[j] * seg.w0 + b[j] * seg.w1))
        .collect();
    brute(&at, ray, t_max)
}

#[test]
fn motion_matches_brute_force_on_moving_soups() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for steps in [1, 2, 5] {
        let soups = moving_soup(&mut rng, 1500, steps);
        let bvh = MeshBvh::build_motion(&soups);
        assert_eq!(bvh.has_motion(), steps > 1);
        assert_eq!(bvh.triangle_count(), 1500);
        let mut hits = 0;
        for i in 0..3000 {
            let mut ray = Ray::new(rng.vec3() * 14.0 - 2.0, rng.vec3() - 0.5);
            // Random times, the steps themselves, and out-of-range times (clamped).
            ray.time = match i % 10 {
                0 => (i / 10 % steps) as f32 / (steps.max(2) - 1) as f32,
                1 => -0.5,
                2 => 1.5,
                _ => rng.next_f32(),
            };
            let t_max = if i % 3 == 0 { 4.0 } else { f32::INFINITY };
            let expect = brute_motion(&soups, &ray, t_max);
            let got = bvh
                .intersect(&ray, t_max, |_, _, _| true)
                .map(|h| (h.0, h.1));
            assert_eq!(got, expect, "{steps} steps, ray {ray:?}");
            assert_eq!(bvh.occluded(&ray, t_max, |_, _, _| true), expect.is_some());
            hits += expect.is_some() as u32;
        }
        assert!(hits > 300, "only {hits} hits: the test rays miss too often");
    }
}

#[test]
fn motion_with_equal_steps_hits_like_static() {
    let mut rng = Rng(11);
    let tris = soup(&mut rng, 2000);
    let still = MeshBvh::build(&tris);
    let moving = MeshBvh::build_motion(&[tris.clone(), tris.clone(), tris]);
    assert!(moving.has_motion() && !still.has_motion());
    assert_eq!(moving.bounds(), still.bounds());
    for i in 0..2000 {
        let mut ray = Ray::new(rng.vec3() * 14.0 - 2.0, rng.vec3() - 0.5);
        let expect = still.intersect(&ray, f32::INFINITY, |_, _, _| true);
        // At the steps and half way between them (weight 1/2) the interpolation
        // `a·w0 + a·w1` is exact, and so are the hits; at other times the interpolated
        // vertices may round by an ulp, and so may t.
        ray.time = (i % 5) as f32 * 0.25;
        let got = moving.intersect(&ray, f32::INFINITY, |_, _, _| true);
        assert_eq!(got, expect, "time {}", ray.time);
        ray.time = rng.next_f32();
        let got = moving.intersect(&ray, f32::INFINITY, |_, _, _| true);
        assert_eq!(got.map(|h| h.1), expect.map(|h| h.1), "time {}", ray.time);
        if let (Some(got), Some(expect)) = (got, expect) {
            assert!((got.0 - expect.0).abs() <= 1e-5 * expect.0);
        }
    }
}

#[test]
fn one_motion_step_is_the_static_build() {
    let tris = soup(&mut Rng(5), 500);
    let (a, b) = (MeshBvh::build(&tris), MeshBvh::build_motion(&[tris]));
    assert!(!b.has_motion());
    assert_eq!(a.nodes, b.nodes);
    assert_eq!(a.rows, b.rows);
    assert!(a.triangles.is_empty() && b.triangles.is_empty());
    assert!(b.step_boxes.is_empty());
    assert_eq!(a.memory_bytes(), b.memory_bytes());
}

#[test]
fn motion_leaves_out_non_finite_and_always_flat_triangles() {
    let tri = |z: f32| {
        [
            Vec3::new(0.0, 0.0, z),
            Vec3::new(1.0, 0.0, z),
            Vec3::new(0.0, 1.0, z),
        ]
    };
    let flat = [Vec3::ONE; 3];
    let step0 = vec![tri(1.0), tri(1.0), flat, flat];
    let step1 = vec![tri(2.0), [Vec3::NAN; 3], flat, tri(3.0)];
    let bvh = MeshBvh::build_motion(&[step0, step1]);
    // Triangle 1 is NaN at step 1, triangle 2 is flat throughout; triangle 3 is flat
    // (a point) at step 0 only and is kept.
    assert_eq!(bvh.triangle_count(), 2);
    let mut ray = Ray::new(Vec3::new(0.2, 0.2, 0.0), Vec3::Z);
    let hit = |ray: &Ray| bvh.intersect(ray, 10.0, |_, _, _| true).map(|h| (h.0, h.1));
    assert_eq!(hit(&ray), Some((1.0, 0)));
    ray.time = 1.0;
    assert_eq!(hit(&ray), Some((2.0, 0)));
    ray.time = 0.5;
    let (t, id) = hit(&ray).unwrap();
    assert!(id == 0 && (t - 1.5).abs() < 1e-6, "{t}");
    // At t = 0.9 triangle 3 has grown from a point at (1, 1, 1) towards tri(3.0)
    // enough to cover (0.2, 0.2) behind triangle 0.
    ray.time = 0.9;
    assert_eq!(
        bvh.intersect(&ray, 10.0, |id, _, _| id == 3).map(|h| h.1),
        Some(3)
    );
}

#[test]
fn motion_node_boxes_hold_their_triangles_at_every_step() {
    let soups = moving_soup(&mut Rng(17), 800, 3);
    let bvh = MeshBvh::build_motion(&soups);
    let n = bvh.triangle_count();
    for (i, node) in bvh.nodes.iter().enumerate() {
        for s in 0..3 {
            let b = bvh.step_boxes[i * 3 + s];
            assert!(b.min.cmpge(node.min).all() && b.max.cmple(node.max).all());
            if node.count > 0 {
                let range = s * n + node.start as usize..s * n + (node.start + node.count) as usize;
                for v in bvh.triangles[range].iter().flat_map(|t| t.v) {
                    assert!(v.cmpge(b.min).all() && v.cmple(b.max).all());
                }
            }
        }
    }
}

#[test]
fn memory_is_reported() {
    let bvh = MeshBvh::build(&soup(&mut Rng(3), 1000));
    assert!(bvh.memory_bytes() >= 1000 * (36 + 4) + bvh.node_count() * 32);
    let bvh = MeshBvh::build_motion(&moving_soup(&mut Rng(3), 1000, 3));
    assert!(bvh.memory_bytes() >= 1000 * (3 * 36 + 4) + bvh.node_count() * (32 + 3 * 24));
}

#[test]
fn a_leaf_triangle_is_its_vertices_and_id_in_forty_bytes() {
    // No padding: the 36 bytes of vertices and the id that used to lie in a second array.
    assert_eq!(std::mem::size_of::<LeafTriangle>(), 40);
}
