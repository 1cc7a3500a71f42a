use glam::{Affine3A, DMat4, DQuat, DVec3, Quat, Vec3};

use super::{PacketStack, PACKET};
use crate::bvh::{Instance, MeshBvh, SceneBvh};
use crate::geometry::Ray;
use crate::test_rng::Rng;

/// `n` random triangles of size about `size` in the cube [-1, 1]³.
fn soup(rng: &mut Rng, n: usize, size: f32) -> Vec<[Vec3; 3]> {
    (0..n)
        .map(|_| {
            let c = (rng.vec3() - 0.5) * 2.0;
            [0; 3].map(|_| c + (rng.vec3() - 0.5) * size)
        })
        .collect()
}

/// Random packets: coherent ones (from about one point towards about another, most
/// sharing their triangle frames) and incoherent ones, with finite, infinite, zero and
/// negative bounds and some rays that cannot hit anything.
fn packet(rng: &mut Rng, coherent: bool) -> ([Ray; PACKET], [f32; PACKET]) {
    let (from, to) = ((rng.vec3() - 0.5) * 12.0, (rng.vec3() - 0.5) * 4.0);
    let rays = std::array::from_fn(|_| {
        if coherent {
            let o = from + (rng.vec3() - 0.5) * 0.3;
            Ray::new(o, to + (rng.vec3() - 0.5) * 2.0 - o)
        } else {
            Ray::new((rng.vec3() - 0.5) * 12.0, rng.vec3() - 0.5)
        }
    });
    let t_max = std::array::from_fn(|_| match (rng.next_f32() * 10.0) as u32 {
        0 => f32::INFINITY,
        1 => 0.0,
        2 => -1.0,
        _ => rng.next_f32() * 30.0,
    });
    let mut rays: [Ray; PACKET] = rays;
    match (rng.next_f32() * 8.0) as u32 {
        0 => rays[3].dir = Vec3::ZERO,
        1 => rays[6].origin.x = f32::NAN,
        2 => rays[1].dir.y = f32::INFINITY,
        _ => {}
    }
    (rays, t_max)
}

/// Three meshes placed eleven times: turned, scaled, translated only, and the same
/// placement twice.
fn scene(rng: &mut Rng) -> (Vec<MeshBvh>, Vec<Instance>) {
    let meshes = vec![
        MeshBvh::build(&soup(rng, 2000, 0.15)),
        MeshBvh::build(&soup(rng, 40, 0.6)),
        MeshBvh::build(&soup(rng, 3, 1.5)),
    ];
    let mut instances = Vec::new();
    for i in 0..11u32 {
        let mesh = i % 3;
        let at = (rng.vec3() - 0.5) * 6.0;
        let to_world = match i % 4 {
            0 => Affine3A::from_translation(at),
            1 => Affine3A::from_scale_rotation_translation(
                Vec3::splat(0.5 + rng.next_f32()),
                Quat::from_rotation_arc(Vec3::Z, (rng.vec3() - 0.5).normalize()),
                at,
            ),
            2 => Affine3A::from_scale_rotation_translation(
                Vec3::new(0.3, 2.0, 1.0),
                Quat::from_rotation_y(rng.next_f32() * 6.0),
                at,
            ),
            _ => instances
                .last()
                .map_or(Affine3A::IDENTITY, |i: &Instance| i.to_world),
        };
        instances.push(Instance::new(
            mesh,
            to_world,
            &meshes[mesh as usize].bounds(),
        ));
    }
    (meshes, instances)
}

/// An alpha cut-out's stand-in: some triangles of some instances let rays through, and
/// every triangle near one of its edges.
fn accept(instance: u32, triangle: u32, b1: f32, _: f32) -> bool {
    !(instance % 5 == 1 && triangle.is_multiple_of(3)) && b1 > 0.05
}

/// Every ray of every packet is answered as alone, for any mask, with the node test this
/// process uses and, where the CPU has it, the AVX one.
#[test]
fn each_ray_of_a_packet_is_answered_as_alone() {
    let mut rng = Rng(3);
    let (meshes, instances) = scene(&mut rng);
    let bvh = SceneBvh::build(instances, |m| &meshes[m as usize]);
    let mesh = |m: u32| &meshes[m as usize];
    let mut stack = PacketStack::new();
    let (mut blocked, mut open) = (0, 0);
    for p in 0..3000 {
        let (rays, t_max) = packet(&mut rng, p % 2 == 0);
        let mask = if p % 3 == 0 {
            0xff
        } else {
            (rng.next_f32() * 256.0) as u32
        };
        let filtered = p % 4 == 0;
        let alone = (0..PACKET)
            .filter(|&r| mask >> r & 1 == 1)
            .filter(|&r| {
                let keep = |i, t, b1, b2| !filtered || accept(i, t, b1, b2);
                bvh.occluded(mesh, &rays[r], t_max[r], keep)
            })
            .fold(0, |m, r| m | 1 << r);
        let keep = |_, i, t, b1, b2| !filtered || accept(i, t, b1, b2);
        // SAFETY: without AVX nothing is asked of the CPU; with it, only where it has AVX.
        let together =
            unsafe { bvh.occluded_packet::<false, _>(mesh, &rays, &t_max, mask, &mut stack, keep) };
        assert_eq!(together, alone, "packet {p}: {rays:?} to {t_max:?}");
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx() {
            let avx = unsafe {
                bvh.occluded_packet::<true, _>(mesh, &rays, &t_max, mask, &mut stack, keep)
            };
            assert_eq!(avx, alone, "packet {p}, AVX");
        }
        blocked += alone.count_ones();
        open += mask.count_ones() - alone.count_ones();
    }
    assert!(
        blocked > 2000 && open > 3000,
        "{blocked} blocked, {open} open"
    );
}

/// A scene where something moves answers each ray at its own time, one by one.
#[test]
fn a_scene_with_motion_answers_ray_by_ray() {
    let mut rng = Rng(8);
    let meshes = [MeshBvh::build(&soup(&mut rng, 300, 0.3))];
    let steps = [
        DMat4::IDENTITY,
        DMat4::from_rotation_translation(DQuat::from_rotation_z(0.5), DVec3::new(1.0, 0.0, 0.0)),
    ];
    let instances = vec![
        Instance::moving(0, &steps, &meshes[0].bounds()),
        Instance::new(0, Affine3A::from_translation(Vec3::Y), &meshes[0].bounds()),
    ];
    let bvh = SceneBvh::build(instances, |m| &meshes[m as usize]);
    assert!(bvh.has_motion());
    let mesh = |m: u32| &meshes[m as usize];
    let mut stack = PacketStack::new();
    let mut blocked = 0;
    for p in 0..1000 {
        let (mut rays, t_max) = packet(&mut rng, p % 2 == 0);
        for ray in &mut rays {
            ray.time = rng.next_f32();
        }
        let alone = (0..PACKET)
            .filter(|&r| bvh.occluded(mesh, &rays[r], t_max[r], |_, _, _, _| true))
            .fold(0, |m, r| m | 1 << r);
        // SAFETY: without AVX nothing is asked of the CPU.
        let together = unsafe {
            bvh.occluded_packet::<false, _>(
                mesh,
                &rays,
                &t_max,
                0xff,
                &mut stack,
                |_, _, _, _, _| true,
            )
        };
        assert_eq!(together, alone, "packet {p}");
        blocked += alone.count_ones();
    }
    assert!(blocked > 500, "{blocked}");
}
