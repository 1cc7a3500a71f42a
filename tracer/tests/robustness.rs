//! Robustness of ray casting through the public API: no self-intersection at any scale,
//! no leaks through closed meshes, and BVH answers equal to brute force.

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use glam::{Affine3A, Quat, Vec3};
use tracer::bvh::{Instance, MeshBvh, SceneBvh};
use tracer::geometry::{barycentric, offset_ray_origin, Ray};
use tracer::scene::{Mesh, Primitive};
use tracer::triangle::{intersect_triangle, RayPrecomputed};

mod common;
use common::Rng;

/// A mesh with one primitive holding `triangles` as a soup.
fn soup_mesh(triangles: &[[Vec3; 3]]) -> Mesh {
    let prim = Primitive {
        positions: triangles.iter().flatten().copied().collect(),
        indices: (0..triangles.len() as u32)
            .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
            .collect(),
        ..Default::default()
    };
    Mesh::new(None, vec![prim])
}

fn random_triangles(rng: &mut Rng, n: usize, scale: f32, offset: Vec3) -> Vec<[Vec3; 3]> {
    (0..n)
        .map(|_| {
            // Small triangles scattered over a region ten times their size.
            let c = offset + rng.cube() * (10.0 * scale);
            [
                c + rng.cube() * scale,
                c + rng.cube() * scale,
                c + rng.cube() * scale,
            ]
        })
        .collect()
}

/// A random rigid-plus-scale transform; `mirror` flips one axis (negative determinant).
fn random_transform(rng: &mut Rng, translation: f32, mirror: bool) -> Affine3A {
    let axis = rng.dir();
    let rotation = Quat::from_axis_angle(axis, rng.f32() * std::f32::consts::TAU);
    let mut scale = Vec3::new(
        0.5 + rng.f32() * 2.0,
        0.5 + rng.f32() * 2.0,
        0.5 + rng.f32() * 2.0,
    );
    if mirror {
        scale.x = -scale.x;
    }
    Affine3A::from_scale_rotation_translation(scale, rotation, rng.cube() * translation)
}

/// Barycentrics for a point on the triangle: mostly inside, some exactly on an edge or at
/// a vertex (where neighbours and rounding make self-intersection most likely).
fn random_barycentrics(rng: &mut Rng) -> (f32, f32) {
    let (mut u, mut v) = (rng.f32(), rng.f32());
    if u + v > 1.0 {
        (u, v) = (1.0 - u, 1.0 - v);
    }
    match rng.below(10) {
        0 => (0.0, v),
        1 => (u, 0.0),
        2 => (u, 1.0 - u),
        3 => [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)][rng.below(3)],
        _ => (u, v),
    }
}

/// A direction on the side of unit normal `n`: uniform, or grazing the surface.
fn random_direction_on_side(rng: &mut Rng, n: Vec3) -> Vec3 {
    let mut d = rng.dir();
    if rng.below(5) == 0 {
        // Nearly tangent: the hardest case for an offset along the normal.
        d = (d - n * d.dot(n)).normalize_or(n) + n * 1e-3;
    }
    if d.dot(n) < 0.0 {
        d = -d;
    }
    // Direction lengths vary: rays need not be unit length.
    d * (0.25 + 4.0 * rng.f32())
}

/// Rays leaving random points of random triangles, with origins offset by
/// `offset_ray_origin`, never find their own triangle again, at any scale and far from the
/// origin, in object space and through instance transforms.
#[test]
fn offset_rays_never_rehit_their_triangle() {
    let cases: [(f32, Vec3); 8] = [
        (1e-4, Vec3::ZERO),
        (1e-2, Vec3::ZERO),
        (1.0, Vec3::ZERO),
        (1e2, Vec3::ZERO),
        (1e4, Vec3::ZERO),
        (1e5, Vec3::ZERO),
        (1.0, Vec3::new(1e4, -1e4, 1e4)),
        (1.0, Vec3::new(-1e5, 1e5, 1e5)),
    ];
    let mut rng = Rng(1);
    let mut report = Vec::new();
    for (scale, offset) in cases {
        let tris = random_triangles(&mut rng, 300, scale, offset);
        let mesh = soup_mesh(&tris);
        // The same soup placed by a rotation: the integrator works in world space.
        let m = Affine3A::from_rotation_translation(Quat::from_rotation_y(0.7), offset * 0.5);
        let inst = Instance::new(0, m, &mesh.bvh.bounds());
        let meshes = [mesh];
        let scene = SceneBvh::build(vec![inst.clone()], |m| &meshes[m as usize].bvh);
        let (mut rays, mut rehits_object, mut rehits_world) = (0, 0, 0);
        for _ in 0..10_000 {
            let src = rng.below(tris.len());
            let [v0, v1, v2] = tris[src];
            let ng = (v1 - v0).cross(v2 - v0);
            let Some(ng) = ng.try_normalize() else {
                continue;
            };
            let (b1, b2) = random_barycentrics(&mut rng);

            // Object space (the mesh BVH alone).
            let p = barycentric(v0, v1, v2, b1, b2);
            let dir = random_direction_on_side(&mut rng, ng);
            let n = if dir.dot(ng) < 0.0 { -ng } else { ng };
            let ray = Ray::new(offset_ray_origin(p, n), dir);
            let own = |tri: u32, _: f32, _: f32| tri == src as u32;
            if meshes[0].bvh.occluded(&ray, f32::INFINITY, own) {
                rehits_object += 1;
            }

            // World space, as the integrator computes a hit point and normal.
            let pw = inst.to_world.transform_point3(p);
            let ngw = inst.normal_to_world.mul_vec3(ng).normalize();
            let dir = random_direction_on_side(&mut rng, ngw);
            let n = if dir.dot(ngw) < 0.0 { -ngw } else { ngw };
            let ray = Ray::new(offset_ray_origin(pw, n), dir);
            if scene.occluded(
                |m| &meshes[m as usize].bvh,
                &ray,
                f32::INFINITY,
                |i, tri, _, _| i == 0 && tri == src as u32,
            ) {
                rehits_world += 1;
            }
            rays += 1;
        }
        assert!(rays > 9900);
        if rehits_object + rehits_world > 0 {
            report.push(format!(
                "scale {scale:e} at {offset}: {rehits_object} object-space and {rehits_world} \
                 world-space re-hits in {rays} rays each"
            ));
        }
    }
    assert!(
        report.is_empty(),
        "self-intersections:\n{}",
        report.join("\n")
    );
}

/// Vertex positions and triangles as vertex indices.
type IndexedMesh = (Vec<Vec3>, Vec<[u32; 3]>);

/// A closed sphere: an icosahedron subdivided `levels` times, vertices shared by index.
fn icosphere(levels: u32, radius: f32, centre: Vec3) -> IndexedMesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut verts: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut midpoints = std::collections::HashMap::new();
        let mut mid = |a: u32, b: u32, verts: &mut Vec<Vec3>| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                verts.push((verts[a as usize] + verts[b as usize]).normalize());
                verts.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let (ab, bc, ca) = (
                mid(a, b, &mut verts),
                mid(b, c, &mut verts),
                mid(c, a, &mut verts),
            );
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    (
        verts.into_iter().map(|v| centre + v * radius).collect(),
        faces,
    )
}

/// A closed cube of half-size `h` with an `n`×`n` grid of quads per face. Vertex positions
/// come from one formula of the grid coordinates, so vertices shared between faces are
/// bitwise equal even though the faces share no indices.
fn grid_cube(n: u32, h: f32, centre: Vec3) -> IndexedMesh {
    let coord = |i: u32| -h + (2.0 * h) * (i as f32 / n as f32);
    let mut verts = Vec::new();
    let mut faces = Vec::new();
    for axis in 0..3 {
        for side in [0, n] {
            let base = verts.len() as u32;
            for i in 0..=n {
                for j in 0..=n {
                    let mut p = [0.0; 3];
                    p[axis] = coord(side);
                    p[(axis + 1) % 3] = coord(i);
                    p[(axis + 2) % 3] = coord(j);
                    verts.push(centre + Vec3::from(p));
                }
            }
            let at = |i: u32, j: u32| base + i * (n + 1) + j;
            for i in 0..n {
                for j in 0..n {
                    faces.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                    faces.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
                }
            }
        }
    }
    (verts, faces)
}

/// Targets on a closed mesh: every vertex, points rounded onto edges, random inner points.
fn surface_targets(rng: &mut Rng, verts: &[Vec3], faces: &[[u32; 3]]) -> Vec<Vec3> {
    let mut targets = verts.to_vec();
    for _ in 0..2 * verts.len() {
        let f = faces[rng.below(faces.len())];
        let (a, b) = (
            verts[f[rng.below(3)] as usize],
            verts[f[rng.below(3)] as usize],
        );
        targets.push(a + (b - a) * rng.f32());
    }
    for _ in 0..verts.len() {
        let [a, b, c] = faces[rng.below(faces.len())].map(|i| verts[i as usize]);
        let (b1, b2) = random_barycentrics(rng);
        targets.push(barycentric(a, b, c, b1, b2));
    }
    targets
}

/// Rays from inside a closed mesh aimed exactly at its vertices and edges always hit
/// something, and rays from outside through them enter and leave: no leaks, from the
/// triangle test (shared edges) or the BVH (boxes touched only at a face or an edge).
#[test]
fn closed_meshes_do_not_leak() {
    let mut rng = Rng(2);
    let shapes: Vec<(&str, IndexedMesh, f32)> = vec![
        ("icosphere r=1e-3", icosphere(4, 1e-3, Vec3::ZERO), 1e-3),
        ("icosphere r=1", icosphere(4, 1.0, Vec3::ZERO), 1.0),
        ("icosphere r=1e3", icosphere(4, 1e3, Vec3::ZERO), 1e3),
        (
            "icosphere r=1 at 1e4",
            icosphere(4, 1.0, Vec3::new(1e4, 2e4, -1e4)),
            1.0,
        ),
        ("cube h=1", grid_cube(16, 1.0, Vec3::ZERO), 1.0),
        ("cube h=1e4", grid_cube(16, 1e4, Vec3::ZERO), 1e4),
        ("cube h=1 at 1e3", grid_cube(16, 1.0, Vec3::splat(1e3)), 1.0),
    ];
    for (name, (verts, faces), size) in shapes {
        let centre = verts.iter().sum::<Vec3>() / verts.len() as f32;
        let prim = Primitive {
            positions: verts.clone(),
            indices: faces.clone(),
            ..Default::default()
        };
        let meshes = [Mesh::new(None, vec![prim])];
        let bvh: &MeshBvh = &meshes[0].bvh;
        // The same mesh mirrored and rotated, through the top level.
        let m = Affine3A::from_scale_rotation_translation(
            Vec3::new(-1.5, 1.0, 0.75),
            Quat::from_rotation_z(0.4),
            Vec3::new(3.0, -2.0, 1.0) * size,
        );
        let scene = SceneBvh::build(vec![Instance::new(0, m, &bvh.bounds())], |_| bvh);

        let targets = surface_targets(&mut rng, &verts, &faces);
        let inside: Vec<Vec3> = (0..4)
            .map(|i| {
                if i == 0 {
                    centre
                } else {
                    centre + rng.cube() * (0.4 * size)
                }
            })
            .collect();
        let (mut escaped_object, mut escaped_world, mut bad_crossings, mut rays) = (0, 0, 0, 0);
        for &target in &targets {
            for &q in &inside {
                rays += 1;
                // From inside, exactly at the target.
                let ray = Ray::new(q, target - q);
                if bvh.intersect(&ray, f32::INFINITY, |_, _, _| true).is_none() {
                    escaped_object += 1;
                }
                let ray_w = Ray::new(
                    m.transform_point3(q),
                    m.transform_point3(target) - m.transform_point3(q),
                );
                if scene
                    .intersect(
                        |m| &meshes[m as usize].bvh,
                        &ray_w,
                        f32::INFINITY,
                        |_, _, _, _| true,
                    )
                    .is_none()
                {
                    escaped_world += 1;
                }
                // From outside through the target towards q (at t = 1 and t = 2): listing
                // every crossing with a rejecting `accept`, there must be one at the target
                // and one beyond q.
                let o = target + (target - q);
                let ray = Ray::new(o, target - o);
                let mut entry = false;
                let mut exit = false;
                bvh.occluded(&ray, f32::INFINITY, |tri, b1, b2| {
                    let [a, b, c] = faces[tri as usize].map(|i| verts[i as usize]);
                    let p = barycentric(a, b, c, b1, b2);
                    let t = (p - o).length() / (target - o).length();
                    // Far from the origin, p itself is only known to a few ulps.
                    let ulps = 64.0 * f32::EPSILON * o.abs().max_element();
                    entry |= (t - 1.0).abs() < 1e-3 + ulps / (target - o).length();
                    exit |= t > 2.0;
                    false
                });
                if !(entry && exit) {
                    bad_crossings += 1;
                }
            }
        }
        assert_eq!(
            (escaped_object, escaped_world, bad_crossings),
            (0, 0, 0),
            "{name}: rays escaping (object, world) or missing a crossing, out of {rays}"
        );
    }
}

/// Brute force over every triangle, with the same ray set-up the BVH uses.
fn brute_mesh(
    tris: &[[Vec3; 3]],
    ray: &Ray,
    t_max: f32,
    mut accept: impl FnMut(u32) -> bool,
) -> Option<(f32, u32)> {
    let pre = RayPrecomputed::new(ray);
    let mut best: Option<(f32, u32)> = None;
    for (i, t) in tris.iter().enumerate() {
        let limit = best.map_or(t_max, |b| b.0);
        if let Some((t, ..)) = intersect_triangle(&pre, t[0], t[1], t[2], limit) {
            if accept(i as u32) {
                best = Some((t, i as u32));
            }
        }
    }
    best
}

fn random_ray(rng: &mut Rng, extent: f32) -> Ray {
    let o = rng.cube() * extent;
    let mut d = rng.dir() * (0.1 + 3.0 * rng.f32());
    // Some rays along axes or planes: zero direction components exercise the slab test's
    // infinities.
    match rng.below(8) {
        0 => d = Vec3::new(d.x, 0.0, 0.0),
        1 => d = Vec3::new(0.0, d.y, d.z),
        2 => d = Vec3::new(d.x, -0.0, d.z),
        _ => {}
    }
    Ray::new(o, d)
}

/// Whether a hash of (instance, triangle) lets the hit through: a fixed pseudo-random
/// cut-out pattern.
fn cut_out(instance: u32, triangle: u32) -> bool {
    let h = (instance as u64 * 0x9e37_79b9 + triangle as u64).wrapping_mul(0x2545_f491_4f6c_dd1d);
    (h >> 61) != 0
}

#[test]
fn mesh_bvh_matches_brute_force() {
    let mut rng = Rng(3);
    let mut tris = random_triangles(&mut rng, 4000, 1.0, Vec3::ZERO);
    // Mixed sizes, and inputs the builder must skip.
    tris.extend(random_triangles(&mut rng, 50, 8.0, Vec3::ZERO));
    tris.push([Vec3::NAN, Vec3::ONE, Vec3::ZERO]);
    tris.push([Vec3::ONE, Vec3::ONE, Vec3::ONE]);
    let bvh = MeshBvh::build(&tris);
    assert_eq!(bvh.triangle_count(), 4050);
    let mut hits = 0;
    for i in 0..8_000 {
        let ray = random_ray(&mut rng, 12.0);
        let t_max = if i % 4 == 0 {
            0.5 + rng.f32() * 10.0
        } else {
            f32::INFINITY
        };
        let expect = brute_mesh(&tris, &ray, t_max, |_| true);
        let got = bvh.intersect(&ray, t_max, |_, _, _| true);
        assert_eq!(got.map(|h| (h.0, h.1)), expect, "ray {ray:?} t_max {t_max}");
        assert_eq!(bvh.occluded(&ray, t_max, |_, _, _| true), expect.is_some());
        hits += expect.is_some() as u32;

        // Cut-outs: the closest hit that the filter lets through.
        let expect = brute_mesh(&tris, &ray, t_max, |tri| cut_out(0, tri));
        let got = bvh.intersect(&ray, t_max, |tri, _, _| cut_out(0, tri));
        assert_eq!(got.map(|h| (h.0, h.1)), expect, "filtered ray {ray:?}");
        assert_eq!(
            bvh.occluded(&ray, t_max, |tri, _, _| cut_out(0, tri)),
            expect.is_some()
        );
    }
    // The rays must actually test something.
    assert!(hits > 1500, "only {hits} hits");
}

#[test]
fn scene_bvh_matches_brute_force_over_instances() {
    let mut rng = Rng(4);
    let soups: Vec<Vec<[Vec3; 3]>> = (0..3)
        .map(|i| random_triangles(&mut rng, 150 + 150 * i, 0.3, Vec3::ZERO))
        .collect();
    let meshes: Vec<Mesh> = soups.iter().map(|s| soup_mesh(s)).collect();
    let mut instances: Vec<Instance> = (0..40)
        .map(|i| {
            let mesh = rng.below(meshes.len()) as u32;
            let m = random_transform(&mut rng, 8.0, i % 3 == 0);
            Instance::new(mesh, m, &meshes[mesh as usize].bvh.bounds())
        })
        .collect();
    // One instance that can never be hit.
    instances.push(Instance::new(
        0,
        Affine3A::from_scale(Vec3::ZERO),
        &meshes[0].bvh.bounds(),
    ));
    assert!(
        instances
            .iter()
            .filter(|i| i.to_world.matrix3.determinant() < 0.0)
            .count()
            > 5
    );
    let scene = SceneBvh::build(instances.clone(), |m| &meshes[m as usize].bvh);
    assert_eq!(scene.instances(), instances.as_slice());

    let brute = |ray: &Ray, t_max: f32, filter: bool| {
        let mut best: Option<(f32, u32, u32)> = None;
        for (i, inst) in instances.iter().enumerate() {
            if !inst.is_hittable() {
                continue;
            }
            let limit = best.map_or(t_max, |b| b.0);
            let obj = inst.object_ray(ray);
            let accept = |tri| !filter || cut_out(i as u32, tri);
            if let Some((t, tri)) = brute_mesh(&soups[inst.mesh as usize], &obj, limit, accept) {
                best = Some((t, i as u32, tri));
            }
        }
        best
    };

    let mut hits = 0;
    for i in 0..4_000 {
        let ray = random_ray(&mut rng, 14.0);
        let t_max = if i % 4 == 0 {
            1.0 + rng.f32() * 10.0
        } else {
            f32::INFINITY
        };
        for filter in [false, true] {
            let expect = brute(&ray, t_max, filter);
            let accept = |inst: u32, tri: u32, _: f32, _: f32| !filter || cut_out(inst, tri);
            let got = scene.intersect(|m| &meshes[m as usize].bvh, &ray, t_max, accept);
            assert_eq!(
                got.map(|h| (h.t, h.instance, h.triangle)),
                expect,
                "ray {ray:?} t_max {t_max} filter {filter}"
            );
            if let Some(h) = got {
                // Barycentrics are those of the hit triangle, in object space.
                let [a, b, c] =
                    soups[instances[h.instance as usize].mesh as usize][h.triangle as usize];
                let p = instances[h.instance as usize]
                    .to_world
                    .transform_point3(barycentric(a, b, c, h.b1, h.b2));
                let err = (p - ray.at(h.t)).length();
                assert!(err < 1e-3 * (1.0 + p.length()), "hit point off by {err}");
                hits += 1;
            }
            assert_eq!(
                scene.occluded(|m| &meshes[m as usize].bvh, &ray, t_max, accept),
                expect.is_some()
            );
        }
    }
    assert!(hits > 800, "only {hits} hits");
}
