use super::*;
use crate::test_rng::Rng;
use glam::{DQuat, DVec3, Quat};

/// The square [-1, 1]² at z = 0, as two triangles.
fn quad() -> Vec<[Vec3; 3]> {
    let p = [
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(-1.0, 1.0, 0.0),
    ];
    vec![[p[0], p[1], p[2]], [p[0], p[2], p[3]]]
}

fn quad_mesh() -> MeshBvh {
    MeshBvh::build(&quad())
}

fn trs(scale: DVec3, rotation: DQuat, translation: DVec3) -> DMat4 {
    DMat4::from_scale_rotation_translation(scale, rotation, translation)
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
        let inst = Instance::new(0, m, &mesh.bounds());
        assert!(!inst.is_hittable());
        assert!(inst.to_object.is_finite() && !inst.normal_to_world.is_nan());
        let scene = SceneBvh::build(vec![inst], |_| &mesh);
        assert!(scene.bounds().is_empty());
        let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z);
        assert!(scene
            .intersect(|_| &mesh, &ray, f32::INFINITY, |_, _, _, _| true)
            .is_none());
    }
}

/// An instance that only translates takes the shortcuts its flag allows: rays enter by
/// their origin alone, and hit points leave with the translation's error bound, the
/// numbers the matrices give (as floats: a zero may change its sign).
#[test]
fn translated_instances_give_the_numbers_of_their_matrices() {
    use crate::geometry::{hit_point_error, translated_hit_point_error};
    let mesh = quad_mesh();
    let mut rng = Rng(11);
    for _ in 0..1000 {
        let t = (rng.vec3() - 0.5) * 200.0;
        let m = Affine3A::from_translation(t);
        let inst = Instance::new(0, m, &mesh.bounds());
        assert!(inst.translated);
        let ray = Ray::new((rng.vec3() - 0.5) * 50.0, rng.vec3() - 0.5);
        let (fast, matrix) = (inst.object_ray(&ray), transform_ray(&inst.to_object, &ray));
        assert_eq!((fast.origin, fast.dir), (matrix.origin, matrix.dir));
        let (p, e) = ((rng.vec3() - 0.5) * 10.0, rng.vec3() * 1e-6);
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        assert_eq!(
            bits(translated_hit_point_error(t, p, e)),
            bits(hit_point_error(&m, p, e))
        );
    }
    // A turn, a scale or a motion takes the matrices.
    let turned = Affine3A::from_rotation_translation(Quat::from_rotation_y(0.3), Vec3::X);
    assert!(!Instance::new(0, turned, &mesh.bounds()).translated);
    assert!(!Instance::new(0, Affine3A::from_scale(Vec3::splat(2.0)), &mesh.bounds()).translated);
    let steps = [DMat4::IDENTITY, DMat4::from_translation(DVec3::X)];
    assert!(!Instance::moving(0, &steps, &mesh.bounds()).translated);
    let still = [DMat4::from_translation(DVec3::X); 2];
    assert!(Instance::moving(0, &still, &mesh.bounds()).translated);
}

#[test]
fn t_is_the_same_in_world_and_object_space() {
    let mesh = quad_mesh();
    let m = Affine3A::from_scale_rotation_translation(
        Vec3::splat(3.0),
        Quat::from_rotation_y(0.3),
        Vec3::new(1.0, 2.0, -4.0),
    );
    let scene = SceneBvh::build(vec![Instance::new(0, m, &mesh.bounds())], |_| &mesh);
    let target = m.transform_point3(Vec3::new(0.2, 0.1, 0.0));
    let origin = Vec3::new(0.5, 2.5, 10.0);
    let hit = scene
        .intersect(
            |_| &mesh,
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
    let m = Affine3A::from_rotation_translation(Quat::from_rotation_z(0.5), Vec3::splat(1e4));
    let inst = Instance::new(0, m, &quad_mesh().bounds());
    for p in quad().iter().flatten() {
        let w = m.transform_point3(*p);
        assert!(w.cmpge(inst.bounds.min).all() && w.cmple(inst.bounds.max).all());
    }
}

#[test]
fn equal_steps_give_a_static_instance_and_a_static_scene() {
    let mesh = quad_mesh();
    let m = trs(
        DVec3::new(1.0, 2.0, 3.0),
        DQuat::from_rotation_z(0.4),
        DVec3::new(5.0, 6.0, 7.0),
    );
    let inst = Instance::moving(3, &[m, m, m], &mesh.bounds());
    assert!(inst.motion.is_none() && !inst.has_motion());
    assert_eq!(
        inst,
        Instance::new(3, Affine3A::from_mat4(m.as_mat4()), &mesh.bounds())
    );
    // Placements of a static instance are its matrices, at any time.
    let p = inst.placement(0.7);
    assert_eq!(
        (p.to_world, p.to_object, p.normal_to_world),
        (inst.to_world, inst.to_object, inst.normal_to_world)
    );
    let scene = SceneBvh::build(vec![inst.clone(), inst], |_| &mesh);
    assert!(!scene.has_motion());

    // One moving instance, or one deforming mesh, makes the scene move.
    let moved = trs(DVec3::ONE, DQuat::IDENTITY, DVec3::X);
    let moving = Instance::moving(0, &[m, moved], &mesh.bounds());
    assert!(moving.has_motion());
    let p = moving.placement(0.0);
    assert_eq!(
        (p.to_world, p.to_object, p.normal_to_world),
        (moving.to_world, moving.to_object, moving.normal_to_world)
    );
    assert!(SceneBvh::build(vec![moving], |_| &mesh).has_motion());
    let deforming = MeshBvh::build_motion(&[quad(), quad()]);
    let still = Instance::new(0, Affine3A::IDENTITY, &deforming.bounds());
    assert!(SceneBvh::build(vec![still], |_| &deforming).has_motion());
}

#[test]
fn non_finite_steps_give_an_unhittable_instance() {
    let bad = DMat4::from_translation(DVec3::new(f64::NAN, 0.0, 0.0));
    let inst = Instance::moving(0, &[DMat4::IDENTITY, bad], &quad_mesh().bounds());
    assert!(!inst.is_hittable() && inst.motion.is_none());
    assert!(inst.to_object.is_finite());
}

#[test]
fn moving_bounds_hold_the_mesh_at_random_times() {
    let mut rng = Rng(0x5eed);
    let points: Vec<Vec3> = (0..200).map(|_| rng.vec3() * 4.0 - 1.0).collect();
    let mesh_bounds = points.iter().fold(Aabb::EMPTY, |mut b, p| {
        b.grow(*p);
        b
    });
    for case in 0..12 {
        let n = 2 + case % 4;
        let steps: Vec<DMat4> = (0..n)
            .map(|k| {
                let axis = (rng.vec3() - 0.5).as_dvec3().normalize();
                let shear = DMat4::from_cols_array(&[
                    1.0, 0.3, 0.0, 0.0, //
                    0.0, 1.0, 0.0, 0.0, //
                    -0.5, 0.0, 1.0, 0.0, //
                    0.0, 0.0, 0.0, 1.0,
                ]);
                // Large turns, scales through zero and mirrors, translations far away.
                let scale = match (case, k) {
                    (3, 1) => DVec3::ZERO,
                    (5, _) => DVec3::new(-1.0, 1.0, 2.0),
                    _ => (rng.vec3() * 3.0 + 0.2).as_dvec3(),
                };
                trs(
                    scale,
                    DQuat::from_axis_angle(axis, rng.next_f32() as f64 * 6.0),
                    (rng.vec3() * 2000.0 - 1000.0).as_dvec3(),
                ) * if case % 2 == 0 {
                    shear
                } else {
                    DMat4::IDENTITY
                }
            })
            .collect();
        let inst = Instance::moving(0, &steps, &mesh_bounds);
        let motion = inst.motion.as_ref().expect("the steps differ");
        let mut tight = Aabb::EMPTY;
        for i in 0..1000 {
            let t = if i < 10 {
                i as f32 / 9.0
            } else {
                rng.next_f32()
            };
            let m = inst.placement(t).to_world;
            assert_eq!(m, motion.at(t));
            for p in &points {
                let w = m.transform_point3(*p);
                tight.grow(w);
                assert!(
                    w.cmpge(inst.bounds.min).all() && w.cmple(inst.bounds.max).all(),
                    "case {case}: {w} at {t} outside {:?}",
                    inst.bounds
                );
            }
        }
        // Conservative, but not wastefully so.
        let (b, e) = (inst.bounds.extent(), tight.extent());
        assert!(b.cmple(e * 1.2 + 1.0).all(), "case {case}: {b} for {e}");
    }
}

#[test]
fn a_moving_instance_is_hit_where_it_is_at_the_ray_time() {
    let mesh = quad_mesh();
    let steps = [
        DMat4::IDENTITY,
        trs(DVec3::ONE, DQuat::IDENTITY, DVec3::new(10.0, 0.0, 0.0)),
    ];
    let slide = Instance::moving(0, &steps, &mesh.bounds());
    // A quarter turn about Y, from the XY plane into the YZ plane.
    let turn = [
        trs(DVec3::ONE, DQuat::IDENTITY, DVec3::new(0.0, 10.0, 0.0)),
        trs(
            DVec3::ONE,
            DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2),
            DVec3::new(0.0, 10.0, 0.0),
        ),
    ];
    let turn = Instance::moving(0, &turn, &mesh.bounds());
    let scene = SceneBvh::build(vec![slide, turn], |_| &mesh);
    assert!(scene.has_motion());
    let hit = |x: f32, y: f32, time: f32| {
        let mut ray = Ray::new(Vec3::new(x, y, 5.0), -Vec3::Z);
        ray.time = time;
        let hit = scene.intersect(|_| &mesh, &ray, f32::INFINITY, |_, _, _, _| true);
        let occluded = scene.occluded(|_| &mesh, &ray, f32::INFINITY, |_, _, _, _| true);
        assert_eq!(hit.is_some(), occluded);
        hit.map(|h| (h.instance, h.t))
    };
    // The sliding quad: at x = 0 when the shutter opens, x = 10 when it closes.
    assert_eq!(hit(0.0, 0.0, 0.0), Some((0, 5.0)));
    assert_eq!(hit(0.0, 0.0, 1.0), None);
    assert_eq!(hit(10.0, 0.0, 1.0), Some((0, 5.0)));
    assert_eq!(hit(10.0, 0.0, 0.0), None);
    assert_eq!(hit(5.0, 0.0, 0.5), Some((0, 5.0)));
    assert_eq!(hit(5.0, 0.0, 0.1), None);
    // The turning quad: at 45° the point above x = 0.5 lies at z = -0.5; at 90° the
    // quad is edge-on and x = 0.5 misses it.
    assert_eq!(hit(0.5, 10.0, 0.0), Some((1, 5.0)));
    let (i, t) = hit(0.5, 10.0, 0.5).unwrap();
    assert!(i == 1 && (t - 5.5).abs() < 1e-5, "t = {t}");
    assert_eq!(hit(0.5, 10.0, 1.0), None);
}

/// `n` random triangles, their vertices within `size / 2` of a centre in
/// [-`spread`, `spread`]³.
fn soup(rng: &mut Rng, n: usize, spread: f32, size: f32) -> Vec<[Vec3; 3]> {
    (0..n)
        .map(|_| {
            let c = rng.vec3() * (2.0 * spread) - spread;
            [(); 3].map(|_| c + (rng.vec3() - 0.5) * size)
        })
        .collect()
}

/// Checks that `scene` finds, for `ray` before `t_max`, the closest hit that testing every
/// instance (placed at the ray's time) finds, and that it is occluded exactly then;
/// returns the instance hit.
fn check_against_every_instance<'m>(
    scene: &SceneBvh,
    instances: &[Instance],
    mesh: impl Fn(u32) -> &'m MeshBvh + Copy,
    ray: &Ray,
    t_max: f32,
) -> Option<u32> {
    let mut expect: Option<(f32, u32, u32)> = None;
    for (i, inst) in instances.iter().enumerate() {
        let limit = expect.map_or(t_max, |e| e.0);
        let object_ray = transform_ray(&inst.placement(ray.time).to_object, ray);
        if let Some((t, tri, ..)) = mesh(inst.mesh).intersect(&object_ray, limit, |_, _, _| true) {
            expect = Some((t, i as u32, tri));
        }
    }
    let got = scene
        .intersect(mesh, ray, t_max, |_, _, _, _| true)
        .map(|h| (h.t, h.instance, h.triangle));
    assert_eq!(got, expect, "ray {ray:?}");
    let occluded = scene.occluded(mesh, ray, t_max, |_, _, _, _| true);
    assert_eq!(occluded, expect.is_some(), "ray {ray:?}");
    expect.map(|e| e.1)
}

#[test]
fn motion_scene_matches_brute_force() {
    let mut rng = Rng(0xfeed);
    let soup = soup(&mut rng, 200, 2.0, 1.0);
    let wobble: Vec<Vec<[Vec3; 3]>> = (0..3)
        .map(|_| {
            soup.iter()
                .map(|t| t.map(|v| v + (rng.vec3() - 0.5) * 0.8))
                .collect()
        })
        .collect();
    let meshes = [MeshBvh::build(&soup), MeshBvh::build_motion(&wobble)];
    let mut instances = Vec::new();
    for i in 0..40 {
        let mut place = || {
            trs(
                DVec3::splat(0.5 + rng.next_f32() as f64),
                DQuat::from_axis_angle(
                    (rng.vec3() - 0.5).as_dvec3().normalize(),
                    rng.next_f32() as f64 * 3.0,
                ),
                (rng.vec3() * 30.0 - 15.0).as_dvec3(),
            )
        };
        let mesh = i % 2;
        let bounds = meshes[mesh as usize].bounds();
        instances.push(if i % 3 == 0 {
            Instance::new(mesh, Affine3A::from_mat4(place().as_mat4()), &bounds)
        } else {
            let steps: Vec<DMat4> = (0..1 + i % 3).map(|_| place()).collect();
            Instance::moving(mesh, &steps, &bounds)
        });
    }
    let mesh = |m: u32| &meshes[m as usize];
    let scene = SceneBvh::build(instances.clone(), mesh);
    assert!(scene.has_motion());
    let mut hits = 0;
    for _ in 0..3000 {
        let mut ray = Ray::new(rng.vec3() * 40.0 - 20.0, rng.vec3() - 0.5);
        ray.time = rng.next_f32();
        let hit = check_against_every_instance(&scene, &instances, mesh, &ray, f32::INFINITY);
        hits += hit.is_some() as u32;
    }
    assert!(hits > 200, "only {hits} hits");
}

/// A room's walls, a quad per side of the cube [-10, 10]³ (two triangles each).
fn room() -> Vec<[Vec3; 3]> {
    let mut walls = Vec::new();
    for axis in 0..3 {
        for side in [-10.0f32, 10.0] {
            let corner = |u: f32, v: f32| {
                let mut p = [0.0; 3];
                p[axis] = side;
                p[(axis + 1) % 3] = u;
                p[(axis + 2) % 3] = v;
                Vec3::from_array(p)
            };
            let [a, b, c, d] =
                [(-10., -10.), (10., -10.), (10., 10.), (-10., 10.)].map(|(u, v)| corner(u, v));
            walls.push([a, b, c]);
            walls.push([a, c, d]);
        }
    }
    walls
}

/// A room around its furniture is listed by its root's lanes (and so are pieces of
/// furniture around smaller ones), and the scene finds what testing every instance finds:
/// from inside the room and from outside, closest hits and occlusion, static and moving.
#[test]
fn a_room_around_others_is_opened_and_finds_the_same_hits() {
    let mut rng = Rng(0x5eed);
    // Enough triangles that the root's lanes hold nodes as well as leaves.
    let soup = soup(&mut rng, 400, 1.0, 0.4);
    let meshes = [MeshBvh::build(&room()), MeshBvh::build(&soup)];
    let mut instances = vec![Instance::new(
        0,
        Affine3A::from_mat4(trs(DVec3::ONE, DQuat::from_rotation_y(0.3), DVec3::X).as_mat4()),
        &meshes[0].bounds(),
    )];
    for i in 0..16 {
        let place = trs(
            DVec3::splat(0.5 + rng.next_f32() as f64),
            DQuat::from_axis_angle(DVec3::Y, rng.next_f32() as f64 * 3.0),
            (rng.vec3() * 12.0 - 6.0).as_dvec3(),
        );
        instances.push(if i % 4 == 3 {
            let later = place * DMat4::from_translation(DVec3::new(0.0, 1.0, 0.0));
            Instance::moving(1, &[place, later], &meshes[1].bounds())
        } else {
            Instance::new(1, Affine3A::from_mat4(place.as_mat4()), &meshes[1].bounds())
        });
    }
    let mesh = |m: u32| &meshes[m as usize];
    // The room, and pieces of furniture whose boxes hold another's centre.
    let open = opened(&instances, &mesh);
    assert!(
        open.contains(&0) && open.len() < instances.len(),
        "{open:?}"
    );
    let scene = SceneBvh::build(instances.clone(), mesh);
    assert!(meshes[0].root_parts().len() >= 2);
    // Eight lanes of leaves of at most eight triangles could not hold them all: some of
    // the furniture's root lanes are nodes, searched as subtrees.
    assert!(meshes[1].triangle_count() > 8 * 8);
    let entries: usize = (0..instances.len() as u32)
        .map(|i| match open.contains(&i) {
            true => mesh(instances[i as usize].mesh).root_parts().len(),
            false => 1,
        })
        .sum();
    assert_eq!(scene.entries.len(), entries);
    let mut hits = 0;
    for k in 0..4000 {
        let from = if k % 2 == 0 { 8.0 } else { 40.0 };
        let mut ray = Ray::new(rng.vec3() * 2.0 * from - from, rng.vec3() - 0.5);
        ray.time = rng.next_f32();
        let t_max = if k % 3 == 0 { 5.0 } else { f32::INFINITY };
        let hit = check_against_every_instance(&scene, &instances, mesh, &ray, t_max);
        hits += hit.is_some_and(|i| i > 0) as u32;
    }
    assert!(hits > 100, "only {hits} hits on the furniture");
}

/// Only the largest static instances that hold a smaller one's centre are opened: not one
/// beside the others, not one inside, not a moving one, and none past `OPEN_AT_MOST`.
#[test]
fn only_large_static_instances_around_others_are_opened() {
    let meshes = [MeshBvh::build(&room()), quad_mesh()];
    let mesh = |m: u32| &meshes[m as usize];
    let at = |m: u32, scale: f64, x: f64| {
        let place = trs(
            DVec3::splat(scale),
            DQuat::IDENTITY,
            DVec3::new(x, 3.0, 3.0),
        );
        Instance::new(
            m,
            Affine3A::from_mat4(place.as_mat4()),
            &meshes[m as usize].bounds(),
        )
    };
    // A room, a room far beside it (around nothing), and a quad inside the first (whose
    // box, off the room's centre, holds no other's centre).
    let rooms = vec![at(0, 1.0, 0.0), at(0, 1.0, 100.0), at(1, 1.0, 2.0)];
    assert_eq!(opened(&rooms, &mesh), [0]);
    // A quad at the room's centre holds that centre, but is not around the room.
    let centred = vec![at(0, 1.0, 0.0), at(1, 1.0, 0.0)];
    assert_eq!(opened(&centred, &mesh), [0]);
    // Moving, the room is not opened.
    let mut moving = rooms.clone();
    let place = trs(DVec3::ONE, DQuat::IDENTITY, DVec3::new(0.0, 3.0, 3.0));
    let later = trs(DVec3::ONE, DQuat::IDENTITY, DVec3::new(1.0, 3.0, 3.0));
    moving[0] = Instance::moving(0, &[place, later], &meshes[0].bounds());
    assert_eq!(opened(&moving, &mesh), Vec::<u32>::new());
    // Nested rooms, each around a quad: the largest `OPEN_AT_MOST` are opened.
    let mut nested: Vec<Instance> = (0..OPEN_AT_MOST + 4)
        .map(|i| at(0, 1.0 + i as f64, 0.0))
        .collect();
    nested.push(at(1, 1.0, 2.0));
    let want: Vec<u32> = (4..OPEN_AT_MOST as u32 + 4).collect();
    assert_eq!(opened(&nested, &mesh), want);
}
