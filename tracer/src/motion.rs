//! Motion blur: the shutter, how many motion steps sample it, and the per-frame geometry of
//! meshes that skinning or morphing deforms.
//!
//! Time inside a frame is the normalised shutter position in [0, 1] (0 = open, 1 = close),
//! carried by every ray ([`crate::geometry::Ray::time`]). Whatever moves is known at evenly
//! spaced motion steps over the shutter and interpolated between the two steps that bracket
//! a ray's time: rigid transforms by their decomposed parts ([`crate::bvh::MotionTransform`]),
//! the camera by position and rotation, deformed vertices linearly.

use glam::{DMat3, DMat4, DVec3, Vec3, Vec4};

use crate::bvh::{MeshBvh, Segment};
use crate::deform::Deformed;
use crate::limits::MAX_SHUTTER_FRAMES;
use crate::scene::Mesh;

/// The step counts the automatic choice tries, fewest first. Each divides the probe grid
/// ([`PROBES`] times over the shutter) evenly, so its steps fall on probe times.
const AUTO_STEPS: [u32; 5] = [2, 3, 5, 9, 17];

/// Times at which the automatic choice looks at the scene: 17 evenly spaced over the shutter.
pub(crate) const PROBES: usize = 17;

/// The shutter of a frame, in frames relative to the frame's own time: `[-0.25, 0.25]`
/// opens a quarter frame before frame f and closes a quarter frame after it (a 180° shutter).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shutter {
    /// When the shutter opens.
    pub open: f64,
    /// When it closes; equal to `open` for no motion blur.
    pub close: f64,
}

impl Default for Shutter {
    fn default() -> Self {
        Self {
            open: 0.0,
            close: 0.0,
        }
    }
}

impl Shutter {
    /// Checks the numbers: finite, `open <= close`, within [`MAX_SHUTTER_FRAMES`].
    pub fn validate(&self) -> Result<(), String> {
        let ok = |x: f64| x.is_finite() && x.abs() <= MAX_SHUTTER_FRAMES;
        if !ok(self.open) || !ok(self.close) {
            return Err(format!(
                "shutter {},{} must be finite and within ±{MAX_SHUTTER_FRAMES} frames",
                self.open, self.close
            ));
        }
        if self.open > self.close {
            return Err(format!(
                "shutter opens at {} after it closes at {}",
                self.open, self.close
            ));
        }
        Ok(())
    }

    /// Whether the shutter is open for a non-zero time.
    pub fn is_open(&self) -> bool {
        self.close > self.open
    }

    /// Scene time in seconds at shutter position `s` in [0, 1] of frame `frame`.
    pub fn seconds(&self, frame: i32, fps: f64, s: f64) -> f64 {
        (frame as f64 + self.open + (self.close - self.open) * s) / fps
    }
}

/// Shutter positions of `steps` evenly spaced motion steps; one step sits mid-shutter.
pub(crate) fn step_positions(steps: u32) -> Vec<f64> {
    match steps {
        0 | 1 => vec![0.5],
        n => (0..n).map(|k| k as f64 / (n - 1) as f64).collect(),
    }
}

/// How large a pixel looks from the camera: a point at distance `d` spans
/// `absolute + per_distance · d` world units per pixel (perspective: the angle of a pixel;
/// orthographic: its fixed width).
#[derive(Clone, Copy, Debug)]
pub(crate) struct PixelFootprint {
    pub absolute: f64,
    pub per_distance: f64,
}

/// The fewest motion steps whose linear interpolation follows `probes` within half a pixel.
///
/// `probes[i]` holds camera-space points (corners of moving boxes, vertices of deforming
/// meshes) at shutter position i / (PROBES - 1). One step when nothing moves at all;
/// otherwise the first of 2, 3, 5, 9, 17 steps for which every point, interpolated linearly
/// between the steps around each probe time, lands within half a pixel of where it truly
/// is. Linear interpolation of points is never better than the decomposed interpolation of
/// rigid transforms, so this errs on the side of more steps.
pub(crate) fn auto_steps(probes: &[Vec<DVec3>], pixel: PixelFootprint) -> u32 {
    debug_assert_eq!(probes.len(), PROBES);
    let first = &probes[0];
    if probes.iter().all(|p| p == first) {
        return 1;
    }
    let last = (PROBES - 1) as u32;
    'candidates: for steps in AUTO_STEPS {
        let stride = (last / (steps - 1)) as usize;
        for (i, probe) in probes.iter().enumerate() {
            let k = (i / stride).min(steps as usize - 2);
            let f = (i - k * stride) as f64 / stride as f64;
            let (a, b) = (&probes[k * stride], &probes[(k + 1) * stride]);
            for ((p, a), b) in probe.iter().zip(a).zip(b) {
                let err = (a.lerp(*b, f) - *p).length();
                let tolerance = 0.5 * (pixel.absolute + pixel.per_distance * p.length());
                if !(err <= tolerance) {
                    continue 'candidates;
                }
            }
        }
        return steps;
    }
    *AUTO_STEPS.last().unwrap()
}

/// A mesh deformed (skinned or morphed) for one frame: its vertices at every motion step in
/// the prepared frame's camera-relative world space, and a BVH over them. Its instance
/// uses the identity transform; texture coordinates, colours and materials stay with the
/// scene's mesh, `source`.
pub struct DeformedMesh {
    /// Index of the scene mesh this deforms.
    pub source: u32,
    /// Per motion step, per primitive: deformed positions, normals and tangents.
    pub steps: Vec<Vec<Deformed>>,
    /// Hierarchy over the deformed triangles (with per-step bounds when it moves).
    pub bvh: MeshBvh,
    /// Whether the node placing these vertices mirrors them (negative determinant): glTF
    /// then turns the front face, which the vertices' winding alone no longer tells.
    pub mirrored: bool,
}

impl DeformedMesh {
    /// Builds the BVH over `steps` of `mesh`'s primitives. Steps that equal the first are
    /// dropped as a whole, so a deformation that does not change inside the shutter costs
    /// what a static mesh costs.
    pub fn new(source: u32, mesh: &Mesh, mut steps: Vec<Vec<Deformed>>) -> Self {
        if steps.iter().all(|s| same_positions(s, &steps[0])) {
            steps.truncate(1);
        }
        let triangles: Vec<Vec<[Vec3; 3]>> = steps
            .iter()
            .map(|step| {
                mesh.primitives
                    .iter()
                    .zip(step)
                    .flat_map(|(prim, d)| {
                        prim.indices
                            .iter()
                            .map(|&[a, b, c]| [a, b, c].map(|i| d.positions[i as usize]))
                    })
                    .collect()
            })
            .collect();
        let bvh = if triangles.len() == 1 {
            MeshBvh::build(&triangles[0])
        } else {
            MeshBvh::build_motion(&triangles)
        };
        Self {
            source,
            steps,
            bvh,
            mirrored: false,
        }
    }

    /// Whether the vertices move inside the shutter.
    pub fn moves(&self) -> bool {
        self.steps.len() > 1
    }

    /// Attribute `get` of vertices `v` of primitive `prim`, interpolated at shutter time
    /// `time` between the bracketing steps.
    fn at<T, const N: usize>(
        &self,
        prim: usize,
        v: [usize; N],
        time: f32,
        get: impl Fn(&Deformed, usize) -> T,
        lerp: impl Fn(T, T, f32) -> T,
    ) -> [T; N] {
        if self.steps.len() == 1 {
            return v.map(|i| get(&self.steps[0][prim], i));
        }
        let s = Segment::new(time, self.steps.len());
        let (a, b) = (&self.steps[s.index][prim], &self.steps[s.index + 1][prim]);
        v.map(|i| lerp(get(a, i), get(b, i), s.w1))
    }

    /// Positions of vertices `v` of primitive `prim` at shutter time `time`.
    pub fn positions(&self, prim: usize, v: [usize; 3], time: f32) -> [Vec3; 3] {
        self.at(prim, v, time, |d, i| d.positions[i], Vec3::lerp)
    }

    /// Normals of vertices `v` (not renormalised), or `None` without normals.
    pub fn normals(&self, prim: usize, v: [usize; 3], time: f32) -> Option<[Vec3; 3]> {
        (!self.steps[0][prim].normals.is_empty())
            .then(|| self.at(prim, v, time, |d, i| d.normals[i], Vec3::lerp))
    }

    /// Tangents of vertices `v`, or `None` without tangents.
    pub fn tangents(&self, prim: usize, v: [usize; 3], time: f32) -> Option<[Vec4; 3]> {
        (!self.steps[0][prim].tangents.is_empty())
            .then(|| self.at(prim, v, time, |d, i| d.tangents[i], Vec4::lerp))
    }
}

fn same_positions(a: &[Deformed], b: &[Deformed]) -> bool {
    a.iter().zip(b).all(|(a, b)| a.positions == b.positions)
}

/// Moves object-space deformed attributes into the prepared frame with `to_world`
/// (morph-only meshes deform in object space; skinned ones are already placed by their
/// joints).
pub(crate) fn place(d: &mut Deformed, to_world: &DMat4) {
    let linear = DMat3::from_mat4(*to_world);
    let normal_matrix = linear.inverse().transpose();
    let normal_matrix = if normal_matrix.is_finite() {
        normal_matrix
    } else {
        DMat3::ZERO
    };
    for p in &mut d.positions {
        *p = to_world.transform_point3(p.as_dvec3()).as_vec3();
    }
    for n in &mut d.normals {
        *n = (normal_matrix * n.as_dvec3()).as_vec3();
    }
    // A mirror reverses the bitangent, cross(normal, tangent) · w: w turns with it.
    let w_sign = if linear.determinant() < 0.0 {
        -1.0
    } else {
        1.0
    };
    for t in &mut d.tangents {
        let v = (linear * t.truncate().as_dvec3()).as_vec3();
        *t = v.extend(t.w * w_sign);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shutter_limits() {
        assert!(Shutter::default().validate().is_ok());
        assert!(!Shutter::default().is_open());
        let s = Shutter {
            open: -0.25,
            close: 0.25,
        };
        assert!(s.validate().is_ok() && s.is_open());
        assert_eq!(s.seconds(12, 24.0, 0.5), 0.5);
        assert_eq!(s.seconds(12, 24.0, 0.0), 11.75 / 24.0);
        for bad in [
            (0.5, 0.0),
            (f64::NAN, 0.0),
            (0.0, f64::INFINITY),
            (-2e4, 0.0),
        ] {
            let s = Shutter {
                open: bad.0,
                close: bad.1,
            };
            assert!(s.validate().is_err(), "{bad:?}");
        }
    }

    fn probes(path: impl Fn(f64) -> DVec3) -> Vec<Vec<DVec3>> {
        (0..PROBES)
            .map(|i| vec![path(i as f64 / (PROBES - 1) as f64)])
            .collect()
    }

    #[test]
    fn auto_steps_follow_how_the_scene_moves() {
        let pixel = PixelFootprint {
            absolute: 0.0,
            per_distance: 1e-3,
        };
        // Still, then straight-line motion: one step, then two.
        assert_eq!(
            auto_steps(&probes(|_| DVec3::new(0.0, 0.0, -5.0)), pixel),
            1
        );
        assert_eq!(
            auto_steps(&probes(|s| DVec3::new(s * 3.0, 0.0, -5.0)), pixel),
            2
        );
        // A point swinging round an arc needs more steps the wider the arc.
        let arc = |angle: f64| {
            move |s: f64| {
                let a = angle * s;
                DVec3::new(a.sin(), 0.0, -5.0 + a.cos())
            }
        };
        let narrow = auto_steps(&probes(arc(0.05)), pixel);
        let wide = auto_steps(&probes(arc(3.0)), pixel);
        assert!(narrow <= 3, "{narrow}");
        assert!(wide > narrow && wide >= 9, "{wide}");
    }
}
