//! Simple shapes as triangle primitives, for the demo scene, tests and benchmarks.

use glam::Vec3;

use crate::math;
use crate::scene::Primitive;

/// A quad a, b, c, d (counter-clockwise seen from its front) as two triangles with flat
/// normals.
pub fn quad(corners: [Vec3; 4], material: u32) -> Primitive {
    let n = (corners[1] - corners[0])
        .cross(corners[2] - corners[0])
        .normalize();
    Primitive {
        positions: corners.to_vec(),
        normals: vec![n; 4],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material,
        ..Default::default()
    }
}

/// An axis-aligned unit cube [-0.5, 0.5]³ with flat normals.
pub fn cube(material: u32) -> Primitive {
    let mut prim = Primitive {
        material,
        ..Default::default()
    };
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let n = Vec3::from_array(std::array::from_fn(|i| if i == axis { sign } else { 0.0 }));
            let u = Vec3::from_array(std::array::from_fn(|i| {
                if i == (axis + 1) % 3 {
                    1.0
                } else {
                    0.0
                }
            }));
            let v = n.cross(u);
            let base = prim.positions.len() as u32;
            for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                prim.positions.push(0.5 * (n + u * su + v * sv));
                prim.normals.push(n);
            }
            prim.indices.push([base, base + 1, base + 2]);
            prim.indices.push([base, base + 2, base + 3]);
        }
    }
    prim
}

/// A triangular prism with flat normals: its cross-section in the xy plane is an
/// isosceles triangle of apex angle `apex` (radians) at (0, `height`) over a base on the
/// x axis, extruded from z = −`depth`/2 to `depth`/2. Light along +x enters the left face
/// and leaves the right one, bent towards the base.
pub fn prism(material: u32, apex: f32, height: f32, depth: f32) -> Primitive {
    let half_base = height * math::tan(apex / 2.0);
    let z = depth / 2.0;
    let [l, r, a] = [
        Vec3::new(-half_base, 0.0, 0.0),
        Vec3::new(half_base, 0.0, 0.0),
        Vec3::new(0.0, height, 0.0),
    ];
    let back = Vec3::new(0.0, 0.0, -z);
    let front = Vec3::new(0.0, 0.0, z);
    let faces: [&[Vec3]; 5] = [
        &[l + front, l + back, a + back, a + front],
        &[a + front, a + back, r + back, r + front],
        &[r + front, r + back, l + back, l + front],
        &[l + front, r + front, a + front],
        &[l + back, r + back, a + back],
    ];
    let centre = (l + r + a) / 3.0;
    let mut prim = Primitive {
        material,
        ..Default::default()
    };
    for face in faces {
        // Counter-clockwise seen from outside, as glTF's front faces are.
        let mut face = face.to_vec();
        let mut n = (face[1] - face[0]).cross(face[2] - face[0]).normalize();
        if n.dot(face[0] - centre) < 0.0 {
            face.reverse();
            n = -n;
        }
        let first = prim.positions.len() as u32;
        prim.positions.extend_from_slice(&face);
        prim.normals.extend(std::iter::repeat_n(n, face.len()));
        for i in 1..face.len() as u32 - 1 {
            prim.indices.push([first, first + i, first + i + 1]);
        }
    }
    prim
}

/// A UV sphere of radius 1 with smooth normals.
pub fn uv_sphere(material: u32, rings: u32, segments: u32) -> Primitive {
    let mut prim = Primitive {
        material,
        ..Default::default()
    };
    for r in 0..=rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..=segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            let n = Vec3::new(
                math::sin(theta) * math::cos(phi),
                math::cos(theta),
                -math::sin(theta) * math::sin(phi),
            );
            prim.positions.push(n);
            prim.normals.push(n);
        }
    }
    let row = segments + 1;
    for r in 0..rings {
        for s in 0..segments {
            let (a, b) = (r * row + s, (r + 1) * row + s);
            if r != 0 {
                prim.indices.push([a, b, a + 1]);
            }
            if r != rings - 1 {
                prim.indices.push([a + 1, b, b + 1]);
            }
        }
    }
    prim
}

/// A bumpy grid of `n`×`n` quads over the unit square (2 n² triangles): a mesh of any size,
/// for benchmarks of the BVH.
pub fn bumpy_grid(n: usize) -> Vec<[Vec3; 3]> {
    let p = |i: usize, j: usize| {
        let (x, z) = (i as f32 / n as f32, j as f32 / n as f32);
        Vec3::new(x, 0.05 * math::sin(13.0 * x) * math::cos(11.0 * z), z)
    };
    let mut tris = Vec::with_capacity(2 * n * n);
    for i in 0..n {
        for j in 0..n {
            tris.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            tris.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    tris
}
