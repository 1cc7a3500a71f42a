//! Cameras: glTF perspective and orthographic projections placed in the prepared frame,
//! and the primary rays they generate.

use std::sync::Arc;

use glam::{Affine3A, Quat, Vec2, Vec3};

use crate::bvh::Segment;
use crate::geometry::Ray;
use crate::math::{self, SlerpArc};

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
#[derive(Clone, Debug)]
pub struct Camera {
    /// The projection.
    projection: Projection,
    /// Half the film's height: at distance 1 for a perspective camera (`tan(yfov / 2)`),
    /// `ymag` for an orthographic one. From `projection`, once rather than per ray.
    half_height: f32,
    /// Camera space to the prepared frame's world space. The camera sits at the origin of
    /// the prepared frame (camera-relative rendering), so this is a pure rotation-scale
    /// matrix plus, at most, a tiny translation.
    pub to_world: Affine3A,
    /// Image width over height.
    pub aspect: f32,
    /// Where the camera is at evenly spaced motion steps over the shutter, when it moves
    /// inside it; `None` for a still camera (then `to_world` holds at every time).
    motion: Option<Arc<[RigidStep]>>,
    /// The arc from each motion step's rotation to the next's (empty for a still camera).
    arcs: Arc<[SlerpArc]>,
    /// The prepared frame to camera space at shutter open and close, for the motion
    /// vectors: two inverses per camera, not two per camera sample of a moving frame.
    to_camera_at_ends: [Affine3A; 2],
}

/// An end of the shutter, where the motion vectors measure the image's motion between.
/// Its value indexes `Camera::to_camera_at_ends`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShutterEnd {
    /// Shutter time 0.
    Open = 0,
    /// Shutter time 1.
    Close = 1,
}

impl ShutterEnd {
    /// Its shutter time, in [0, 1].
    pub fn time(self) -> f32 {
        match self {
            ShutterEnd::Open => 0.0,
            ShutterEnd::Close => 1.0,
        }
    }
}

/// A camera placement at one motion step: position and orientation, no scale.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidStep {
    /// Position in the prepared frame.
    pub position: Vec3,
    /// Orientation, a unit quaternion on the same hemisphere as the previous step's.
    pub rotation: Quat,
}

impl RigidStep {
    fn affine(&self) -> Affine3A {
        Affine3A::from_rotation_translation(self.rotation, self.position)
    }
}

impl Camera {
    /// A camera of `projection` placed by `to_world` (at every time, or at the `motion`
    /// steps where it moves), rendering an image `aspect` times as wide as high.
    pub fn new(
        projection: Projection,
        to_world: Affine3A,
        aspect: f32,
        motion: Option<Arc<[RigidStep]>>,
    ) -> Camera {
        let half_height = match projection {
            Projection::Perspective { yfov, .. } => math::tan(0.5 * yfov),
            Projection::Orthographic { ymag, .. } => ymag,
        };
        let arcs = motion
            .as_deref()
            .unwrap_or_default()
            .windows(2)
            .map(|w| SlerpArc::between(w[0].rotation, w[1].rotation))
            .collect();
        let mut camera = Camera {
            projection,
            half_height,
            to_world,
            aspect,
            motion,
            arcs,
            to_camera_at_ends: [Affine3A::IDENTITY; 2],
        };
        camera.to_camera_at_ends = [ShutterEnd::Open, ShutterEnd::Close]
            .map(|end| camera.to_world_at(end.time()).inverse());
        camera
    }

    /// Whether the camera moves within the shutter.
    pub fn moves(&self) -> bool {
        self.motion.is_some()
    }

    /// Camera space to the prepared frame at shutter time `time` in [0, 1]: the two
    /// bracketing steps' positions interpolated linearly, their rotations by slerp.
    #[inline]
    pub fn to_world_at(&self, time: f32) -> Affine3A {
        match self.motion.as_deref() {
            Some([only]) => only.affine(),
            Some(steps @ [_, _, ..]) => {
                let s = Segment::new(time, steps.len());
                let (a, b) = (&steps[s.index], &steps[s.index + 1]);
                Affine3A::from_rotation_translation(
                    self.arcs[s.index].slerp(a.rotation, b.rotation, s.w1),
                    s.lerp(a.position, b.position),
                )
            }
            _ => self.to_world,
        }
    }

    /// The primary ray through film position `film` in `[0, 1]²` (x right, y down) at
    /// shutter time `time` in [0, 1] (ignored by a still camera).
    pub fn generate_ray(&self, film: Vec2, time: f32) -> Ray {
        self.primary(film, time).0
    }

    /// [`Camera::generate_ray`] and the camera's view axis at that time (its -Z in the
    /// prepared frame, unit), from one placement.
    pub fn primary(&self, film: Vec2, time: f32) -> (Ray, Vec3) {
        let ndc = Vec2::new(2.0 * film.x - 1.0, 1.0 - 2.0 * film.y);
        let h = self.half_height;
        // glTF's xmag and ymag fix both extents; the image's aspect wins, so the horizontal
        // extent follows ymag (as the perspective case follows yfov).
        let (origin, dir) = match self.projection {
            Projection::Perspective { .. } => (
                Vec3::ZERO,
                Vec3::new(ndc.x * h * self.aspect, ndc.y * h, -1.0),
            ),
            Projection::Orthographic { .. } => (
                Vec3::new(ndc.x * h * self.aspect, ndc.y * h, 0.0),
                Vec3::NEG_Z,
            ),
        };
        let to_world = self.to_world_at(time);
        let origin = to_world.transform_point3(origin);
        let dir = to_world.transform_vector3(dir).normalize();
        let axis = to_world.transform_vector3(Vec3::NEG_Z).normalize();
        (Ray { origin, dir, time }, axis)
    }

    /// Where the camera at shutter end `end` sees the point `p` of the prepared frame, as
    /// a film position (the inverse of [`Camera::generate_ray`]); `None` behind a
    /// perspective camera.
    pub fn film_position(&self, p: Vec3, end: ShutterEnd) -> Option<Vec2> {
        let local = self.to_camera_at_ends[end as usize].transform_point3(p);
        self.film_of(local, false)
    }

    /// Where a perspective camera at shutter end `end` sees the direction `dir` (a point
    /// at infinity, as the environment is); `None` behind it, and for an orthographic
    /// camera, whose film holds no directions.
    pub fn film_direction(&self, dir: Vec3, end: ShutterEnd) -> Option<Vec2> {
        let local = self.to_camera_at_ends[end as usize].transform_vector3(dir);
        self.film_of(local, true)
    }

    /// The film position of camera-space `local`, a point or (`direction`) a direction.
    fn film_of(&self, local: Vec3, direction: bool) -> Option<Vec2> {
        let h = self.half_height;
        let ndc = match self.projection {
            Projection::Perspective { .. } => {
                if local.z >= 0.0 {
                    return None;
                }
                Vec2::new(local.x / (h * self.aspect), local.y / h) / -local.z
            }
            Projection::Orthographic { .. } if direction => return None,
            Projection::Orthographic { .. } => Vec2::new(local.x / (h * self.aspect), local.y / h),
        };
        Some(Vec2::new(0.5 * (ndc.x + 1.0), 0.5 * (1.0 - ndc.y)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(projection: Projection) -> Camera {
        Camera::new(
            projection,
            Affine3A::from_rotation_translation(
                Quat::from_rotation_y(0.3),
                Vec3::new(0.1, -0.2, 0.3),
            ),
            1.5,
            None,
        )
    }

    /// A moving camera's rotation between two steps is their slerp, from the arc kept for
    /// that segment: bit for bit the slerp of a fresh arc, in every segment.
    #[test]
    fn a_moving_camera_slerps_each_segment_along_its_own_arc() {
        let steps: Vec<RigidStep> = (0..4)
            .map(|k| RigidStep {
                position: Vec3::new(k as f32, 0.5, -1.0),
                rotation: Quat::from_axis_angle(
                    Vec3::new(1.0, 2.0, k as f32).normalize(),
                    0.3 + 0.5 * k as f32,
                ),
            })
            .collect();
        let projection = Projection::Perspective {
            yfov: 0.8,
            aspect_ratio: None,
            znear: 0.01,
        };
        let cam = Camera::new(
            projection,
            Affine3A::IDENTITY,
            1.0,
            Some(steps.clone().into()),
        );
        assert!(cam.moves());
        for i in 0..=60 {
            let t = i as f32 / 60.0;
            let s = Segment::new(t, steps.len());
            let (a, b) = (&steps[s.index], &steps[s.index + 1]);
            let expect = Affine3A::from_rotation_translation(
                SlerpArc::between(a.rotation, b.rotation).slerp(a.rotation, b.rotation, s.w1),
                s.lerp(a.position, b.position),
            );
            assert_eq!(cam.to_world_at(t), expect, "time {t}");
        }
    }

    #[test]
    fn film_position_inverts_generate_ray() {
        let perspective = Projection::Perspective {
            yfov: 0.8,
            aspect_ratio: None,
            znear: 0.01,
        };
        let orthographic = Projection::Orthographic {
            xmag: 1.0,
            ymag: 2.0,
            znear: 0.01,
        };
        for projection in [perspective, orthographic] {
            let cam = camera(projection);
            for film in [Vec2::new(0.25, 0.75), Vec2::new(0.9, 0.1)] {
                let ray = cam.generate_ray(film, 0.0);
                let p = ray.origin + ray.dir * 7.0;
                let back = cam.film_position(p, ShutterEnd::Open).unwrap();
                assert!((back - film).abs().max_element() < 1e-5, "{back} {film}");
                if matches!(projection, Projection::Perspective { .. }) {
                    let back = cam.film_direction(ray.dir, ShutterEnd::Open).unwrap();
                    assert!((back - film).abs().max_element() < 1e-5, "{back} {film}");
                    assert_eq!(
                        cam.film_position(ray.origin - ray.dir, ShutterEnd::Open),
                        None
                    );
                } else {
                    assert_eq!(cam.film_direction(ray.dir, ShutterEnd::Open), None);
                }
            }
        }
    }
}
