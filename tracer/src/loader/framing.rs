//! Walking the default scene's node trees, its world-space bounds, and a default camera
//! that frames them for scenes that bring none.

use glam::{DMat4, DVec3};

use crate::camera::Projection;
use crate::geometry::Aabb;
use crate::math;
use crate::scene::{Mesh, Scene};

/// Vertical field of view of [`framing_camera`]: a moderate telephoto, 40°.
pub const FRAMING_YFOV: f32 = 40.0 * std::f32::consts::PI / 180.0;

/// Direction from the scene's centre towards [`framing_camera`] (normalised on use): a
/// little right, above and in front, so boxes show three faces.
pub const FRAMING_DIRECTION: DVec3 = DVec3::new(0.5, 0.35, 1.0);

/// Every mesh draw of the default scene ([`Scene::for_each_mesh_draw_with`]): (index
/// into [`Scene::meshes`], world transform), in traversal order.
pub fn mesh_instances(scene: &Scene) -> Vec<(u32, DMat4)> {
    let mut out = Vec::new();
    scene.for_each_mesh_draw(|i, world| {
        let m = scene.nodes[i as usize].mesh.expect("draws have a mesh");
        if (m as usize) < scene.meshes.len() {
            out.push((m, *world));
        }
    });
    out
}

/// The bounds of a mesh's vertices that its triangles use, in object space.
pub fn mesh_bounds(mesh: &Mesh) -> Aabb {
    let mut b = Aabb::EMPTY;
    for prim in &mesh.primitives {
        for tri in &prim.indices {
            for &v in tri {
                if let Some(&p) = prim.positions.get(v as usize) {
                    b.grow(p);
                }
            }
        }
    }
    b
}

/// World-space bounds of every mesh instance of the default scene; empty when it draws
/// nothing. Each instance's object-space box is transformed corner by corner in f64.
pub fn scene_bounds(scene: &Scene) -> Aabb {
    let mut local: Vec<Option<Aabb>> = vec![None; scene.meshes.len()];
    let mut bounds = Aabb::EMPTY;
    for (m, world) in mesh_instances(scene) {
        let b = *local[m as usize].get_or_insert_with(|| mesh_bounds(&scene.meshes[m as usize]));
        if b.is_empty() {
            continue;
        }
        for c in b.corners() {
            bounds.grow(world.transform_point3(c.as_dvec3()).as_vec3());
        }
    }
    bounds
}

/// A perspective camera for a scene without one: [`FRAMING_YFOV`] vertical field of view,
/// looking at the centre of `bounds` (for a still scene, [`scene_bounds`]) from
/// [`FRAMING_DIRECTION`], far enough that the bounding sphere fits the view at image aspect
/// `aspect` (width over height). Returns the projection and the camera-to-world transform
/// (glTF convention: the camera looks down its local -Z with +Y up). Empty bounds are
/// framed as a unit sphere at the origin.
pub fn framing_camera(bounds: &Aabb, aspect: f32) -> (Projection, DMat4) {
    let b = *bounds;
    let (center, radius) = if b.is_empty() || !b.min.is_finite() || !b.max.is_finite() {
        (DVec3::ZERO, 1.0)
    } else {
        let r = 0.5 * (b.max.as_dvec3() - b.min.as_dvec3()).length();
        // A flat or point-like scene still needs a distance to stand at.
        (b.center().as_dvec3(), if r > 0.0 { r } else { 1.0 })
    };
    let aspect = if aspect.is_finite() && aspect > 0.0 {
        aspect as f64
    } else {
        1.0
    };
    let half_v = 0.5 * FRAMING_YFOV as f64;
    let half_h = math::atan_f64(math::tan_f64(half_v) * aspect);
    // The sphere fits when its angular radius is within the narrower half-angle.
    let distance = radius / math::sin_f64(half_v.min(half_h));
    let dir = FRAMING_DIRECTION.normalize();
    let eye = center + dir * distance;
    // Columns: camera x (right), y (up), z (backwards = towards the camera), position.
    let z = dir;
    let x = DVec3::Y.cross(z).normalize();
    let y = z.cross(x);
    let to_world = DMat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), eye.extend(1.0));
    let znear = ((distance - radius) * 0.5).max(distance * 1e-4) as f32;
    let projection = Projection::Perspective {
        yfov: FRAMING_YFOV,
        aspect_ratio: Some(aspect as f32),
        znear,
    };
    (projection, to_world)
}
