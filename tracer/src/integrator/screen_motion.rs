//! Motion vectors: how far the first thing a camera sample sees moves across the image
//! over the shutter, for compositors (vector motion blur) and temporal denoisers.

use glam::Vec2;

use crate::camera::ShutterEnd;
use crate::frame::PreparedFrame;
use crate::geometry::{Hit, Ray};

/// The screen-space motion, in pixels (x to the right, y down: the image's rows), from
/// shutter open to shutter close of the point the camera ray `ray` hit (`hit`), or of the
/// environment's direction where it hit nothing. The hit point keeps its barycentric
/// place on its triangle, which moves and deforms as the frame says; the camera moves
/// too. Zero where the point is behind the camera at either end of the shutter, and for
/// the environment seen by an orthographic camera.
// Not inlined: once per camera sample of a moving frame, and its cost shows apart in a
// profile.
#[inline(never)]
pub(crate) fn screen_motion(frame: &PreparedFrame, ray: &Ray, hit: Option<&Hit>) -> Vec2 {
    let camera = &frame.camera;
    let ends = [ShutterEnd::Open, ShutterEnd::Close];
    let film = match hit {
        Some(hit) => {
            let points = frame.hit_points_at_ends(hit);
            ends.map(|end| camera.film_position(points[end as usize], end))
        }
        None => ends.map(|end| camera.film_direction(ray.dir, end)),
    };
    match film {
        [Some(open), Some(close)] => {
            (close - open) * Vec2::new(frame.width as f32, frame.height as f32)
        }
        _ => Vec2::ZERO,
    }
}
