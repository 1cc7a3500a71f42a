//! Cameras: glTF perspective and orthographic projections placed in the prepared frame,
//! and the primary rays they generate.

use glam::{Affine3A, Vec2, Vec3};

use crate::geometry::Ray;

/// A glTF camera projection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// glTF perspective camera.
    Perspective {
        /// Vertical field of view in radians.
        yfov: f32,
        /// Aspect ratio the file asks for; the render uses the image's instead.
        aspect_ratio: Option<f32>,
        /// Near clipping distance.
        znear: f32,
    },
    /// glTF orthographic camera.
    Orthographic {
        /// Half the view's width.
        xmag: f32,
        /// Half the view's height.
        ymag: f32,
        /// Near clipping distance.
        znear: f32,
    },
}

/// A camera placed in the prepared frame: glTF looks down its local -Z with +Y up.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    /// The projection.
    pub projection: Projection,
    /// Camera space to the prepared frame's world space. The camera sits at the origin of
    /// the prepared frame (camera-relative rendering), so this is a pure rotation-scale
    /// matrix plus, at most, a tiny translation.
    pub to_world: Affine3A,
    /// Image width over height.
    pub aspect: f32,
}

impl Camera {
    /// The primary ray through film position `film` in [0,1]² (x right, y down).
    pub fn generate_ray(&self, film: Vec2) -> Ray {
        let ndc = Vec2::new(2.0 * film.x - 1.0, 1.0 - 2.0 * film.y);
        let (origin, dir) = match self.projection {
            Projection::Perspective { yfov, .. } => {
                let h = (0.5 * yfov).tan();
                let d = Vec3::new(ndc.x * h * self.aspect, ndc.y * h, -1.0);
                (Vec3::ZERO, d)
            }
            // glTF's xmag and ymag fix both extents; the image's aspect wins, so the
            // horizontal extent follows ymag (as the perspective case follows yfov).
            Projection::Orthographic { ymag, .. } => (
                Vec3::new(ndc.x * ymag * self.aspect, ndc.y * ymag, 0.0),
                Vec3::NEG_Z,
            ),
        };
        let origin = self.to_world.transform_point3(origin);
        let dir = self.to_world.transform_vector3(dir).normalize();
        Ray::new(origin, dir)
    }
}
