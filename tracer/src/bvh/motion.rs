//! Motion over the shutter: the time convention shared by both BVH levels, and
//! [`MotionTransform`], a rigid-ish transform interpolated between motion steps.
//!
//! Time is the normalised shutter position `t` in [0, 1] (0 = shutter open, 1 = close),
//! as carried by [`crate::geometry::Ray::time`]. `S` motion steps are evenly spaced: step
//! `k` is at `k / (S - 1)`. A time between two steps interpolates the two bracketing steps;
//! times outside [0, 1] (and NaN) are clamped, NaN to 0.

use glam::{Affine3A, DMat3, DMat4, DQuat, DVec3, Mat3A, Quat, Vec3, Vec3A};

use super::instance::transform_bounds;
use crate::geometry::Aabb;
use crate::math::SlerpArc;

/// Where a time falls among evenly spaced motion steps: between steps `index` and
/// `index + 1`, with weights `w0` and `w1` (`w0 + w1 ≈ 1`, both in [0, 1]).
///
/// Every interpolation of the BVH goes through [`Segment::lerp`] with the same weights,
/// so that a vertex and the node boxes holding it round the same way (see
/// `node::MotionBoxes`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// The earlier bracketing step.
    pub index: usize,
    /// Weight of step `index`.
    pub w0: f32,
    /// Weight of step `index + 1`.
    pub w1: f32,
}

impl Segment {
    /// The segment holding `time` among `steps` (at least 2) evenly spaced steps.
    #[inline(always)]
    pub fn new(time: f32, steps: usize) -> Segment {
        debug_assert!(steps >= 2);
        // Written so that NaN goes to 0.
        let t = if time > 0.0 { time.min(1.0) } else { 0.0 };
        let x = t * (steps - 1) as f32;
        // The float-to-int cast truncates (x ≥ 0); t = 1 lands at the end of the last
        // segment rather than the start of a segment that does not exist.
        let index = (x as usize).min(steps - 2);
        // Exact: x and index are within 1 of each other.
        let w1 = x - index as f32;
        Segment {
            index,
            w0: 1.0 - w1,
            w1,
        }
    }

    /// `a·w0 + b·w1`. Rounding is monotone in `a` and `b` (both weights are non-negative
    /// and nothing is fused), so `a ≤ a'` and `b ≤ b'` give `lerp(a, b) ≤ lerp(a', b')`
    /// componentwise, bit for bit: interpolated boxes hold interpolated vertices exactly.
    #[inline(always)]
    pub fn lerp(&self, a: Vec3, b: Vec3) -> Vec3 {
        a * self.w0 + b * self.w1
    }
}

/// One motion step, decomposed: `M = T · R · S`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Step {
    translation: Vec3A,
    /// Unit quaternion, on the same hemisphere as the previous step's, so that slerp between
    /// neighbours takes the shortest path.
    rotation: Quat,
    /// The stretch: symmetric (it keeps scale and shear) except at singular steps, where it
    /// is `Rᵀ·M` for a rotation borrowed from a neighbour.
    stretch: Mat3A,
    /// `T · R · S` composed, as [`MotionTransform::at`] gives it at the step's own time
    /// (the shutter's ends are steps, and the motion vectors place hits there).
    affine: Affine3A,
}

/// A transform known at evenly spaced motion steps and interpolated in between as
/// translation, rotation and stretch: `T` lerped, `R` slerped (shortest path), `S` lerped
/// elementwise. Lerping matrices instead would shrink a rotating object half way (a 180°
/// turn would pass through a zero matrix).
///
/// Each step's matrix is split by polar decomposition, `M = T·R·S`, with `R` a rotation and
/// `S` symmetric (scale and shear). A mirroring step (negative determinant) decomposes `-M`
/// and folds the sign into `S`, so `R` stays a proper rotation and slerps. A singular step
/// (a zero scale) has no unique rotation; it borrows the nearest regular step's rotation
/// (`S = Rᵀ·M`), so an object that scales down to nothing does not spin on the way.
///
/// Matrices are camera-relative world transforms; the decomposition runs in f64 and the
/// steps are stored in f32, which [`MotionTransform::at`] interpolates per ray.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionTransform {
    steps: Vec<Step>,
    /// The arc from each step's rotation to the next's, for the slerp between them.
    arcs: Vec<SlerpArc>,
}

/// Frobenius norm.
fn norm(m: &DMat3) -> f64 {
    m.to_cols_array().iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Polar decomposition `m = R·S` of an invertible matrix with positive determinant, by
/// Higham's scaled Newton iteration `X ← (γX + X⁻ᵀ/γ) / 2` ("Computing the polar
/// decomposition — with applications", 1986), which converges quadratically to `R` once
/// close, and in about log2 of the condition number steps before that thanks to the
/// scaling. Returns None where the iteration breaks down (a numerically singular matrix).
fn polar(m: &DMat3) -> Option<(DQuat, DMat3)> {
    let mut x = *m;
    for _ in 0..100 {
        let inv_t = x.inverse().transpose();
        if !inv_t.is_finite() {
            return None;
        }
        let (nx, ni) = (norm(&x), norm(&inv_t));
        let diff_before = norm(&(x - inv_t));
        // Scaling speeds up the first steps; near convergence it only adds rounding.
        let gamma = if diff_before > 1e-2 * nx {
            (ni / nx).sqrt()
        } else {
            1.0
        };
        let next = (x * gamma + inv_t * (1.0 / gamma)) * 0.5;
        let change = norm(&(next - x));
        x = next;
        if change <= 1e-14 * norm(&x) {
            break;
        }
    }
    let rotation = DQuat::from_mat3(&x).normalize();
    if !rotation.is_finite() {
        return None;
    }
    // S = Rᵀ·M, symmetrised (it is symmetric up to rounding).
    let s = DMat3::from_quat(rotation).transpose() * *m;
    Some((rotation, (s + s.transpose()) * 0.5))
}

/// The decomposition of one step, or None where the step is singular.
fn decompose(m: &DMat3) -> Option<(DQuat, DMat3)> {
    let det = m.determinant();
    if !(det != 0.0 && det.is_finite() && m.is_finite()) {
        return None;
    }
    // det(-M) = -det(M) in 3D: decompose -M for a mirror and fold the sign into S.
    let sign = det.signum();
    let (rotation, stretch) = polar(&(*m * sign))?;
    Some((rotation, stretch * sign))
}

impl MotionTransform {
    /// Decomposes `steps` (at least one; evenly spaced over the shutter, affine: the last
    /// row is ignored). Non-finite steps give non-finite transforms.
    ///
    /// # Panics
    /// If `steps` is empty.
    pub fn new(steps: &[DMat4]) -> MotionTransform {
        assert!(
            !steps.is_empty(),
            "a motion transform needs at least one step"
        );
        let decomposed: Vec<Option<(DQuat, DMat3)>> = steps
            .iter()
            .map(|m| decompose(&DMat3::from_mat4(*m)))
            .collect();
        let regular: Vec<usize> = (0..steps.len())
            .filter(|&i| decomposed[i].is_some())
            .collect();
        let mut out: Vec<Step> = Vec::with_capacity(steps.len());
        for (i, m) in steps.iter().enumerate() {
            let linear = DMat3::from_mat4(*m);
            let (rotation, stretch) = match decomposed[i] {
                Some(d) => d,
                None => {
                    // Borrow the nearest regular step's rotation (the earlier on a tie).
                    let rotation = regular
                        .iter()
                        .min_by_key(|&&j| j.abs_diff(i))
                        .and_then(|&j| decomposed[j])
                        .map_or(DQuat::IDENTITY, |d| d.0);
                    (rotation, DMat3::from_quat(rotation).transpose() * linear)
                }
            };
            let rotation =
                crate::math::same_hemisphere(out.last().map(|p| p.rotation), rotation.as_quat());
            let (translation, stretch) = (
                m.w_axis.truncate().as_vec3().into(),
                stretch.as_mat3().into(),
            );
            out.push(Step {
                translation,
                rotation,
                stretch,
                affine: compose(translation, rotation, stretch),
            });
        }
        let arcs = out
            .windows(2)
            .map(|w| SlerpArc::between(w[0].rotation, w[1].rotation))
            .collect();
        MotionTransform { steps: out, arcs }
    }

    /// Number of motion steps.
    pub fn step_count(&self) -> usize {
        self.steps.len()
    }

    /// The transform at normalised shutter time `time` (clamped to [0, 1]).
    pub fn at(&self, time: f32) -> Affine3A {
        if self.steps.len() == 1 {
            return self.steps[0].affine;
        }
        self.interpolate(Segment::new(time, self.steps.len()))
    }

    /// The transform at a point of a segment.
    #[inline]
    fn interpolate(&self, seg: Segment) -> Affine3A {
        let (a, b) = (&self.steps[seg.index], &self.steps[seg.index + 1]);
        if seg.w1 == 0.0 {
            return a.affine;
        }
        if seg.w0 == 0.0 {
            return b.affine;
        }
        compose(
            a.translation * seg.w0 + b.translation * seg.w1,
            self.arcs[seg.index].slerp(a.rotation, b.rotation, seg.w1),
            a.stretch * seg.w0 + b.stretch * seg.w1,
        )
    }

    /// Conservative world bounds of `b` (object space) over the whole shutter.
    ///
    /// Each segment is cut into `n` sub-intervals; each sub-interval `[a, b]` contributes the
    /// union of the boxes at its ends, padded by `r`. Why that holds every point: for a
    /// point `x` of the box, `A(u)x = T(u) + R(u)S(u)x` with `u ∈ [0, 1]` across the
    /// sub-interval. `T` and `S` are linear in `u`, so `A(u)x` differs from the straight
    /// line between `A(a)x` and `A(b)x` (which lies in the union box, a convex set) only by
    /// the interpolation error of `g(u) = R(u)v(u)`, `v = S(u)x`. The error of linear
    /// interpolation is at most `max|g''| / 8`, and with `R` turning at constant speed `φ`
    /// (radians per sub-interval, slerp) and `v' = δ`: `|g''| ≤ φ²·max|v| + 2φ·|δ|`. The
    /// error is linear in `x`, so its largest value over the box is at a corner. Hence
    /// `r = max over corners of (φ²·max(|v_a|, |v_b|) + 2φ|δ|) / 8`, which vanishes for
    /// motion without rotation (then the ends' boxes are exact) and shrinks as `1/n²` for
    /// pure rotation; `n` is picked so that `φ ≤ 0.05`.
    ///
    /// The sub-intervals are cut by segment weight, not by time, so that they meet at the
    /// steps exactly whatever the rounding of `time · (S - 1)`. On top, each end box is
    /// padded for the rounding of `M·p + t` (as for static instances) and of
    /// [`MotionTransform::at`] itself ([`AT_ROUNDING`], relative to the size of the two
    /// steps' translations and stretched corners, which bound every term `at` rounds).
    pub(super) fn bounds(&self, b: &Aabb) -> Aabb {
        if b.is_empty() {
            return Aabb::EMPTY;
        }
        let corners = b.corners();
        let padded = |m: &Affine3A, pad: f32| {
            let mut out = transform_bounds(m, b);
            out.min -= Vec3::splat(pad);
            out.max += Vec3::splat(pad);
            out
        };
        // The size of the numbers `at` rounds between steps `a` and `b`.
        let reach = |a: &Step, b: &Step| {
            let stretched = corners
                .iter()
                .map(|&c| {
                    let c = Vec3A::from(c.abs());
                    (a.stretch.abs() * c).length() + (b.stretch.abs() * c).length()
                })
                .fold(0.0f32, f32::max);
            a.translation.abs().max_element() + b.translation.abs().max_element() + stretched
        };
        if self.steps.len() == 1 {
            let s = &self.steps[0];
            return padded(&s.affine, reach(s, s) * AT_ROUNDING);
        }
        let mut out = Aabb::EMPTY;
        for k in 0..self.steps.len() - 1 {
            let (sa, sb) = (&self.steps[k], &self.steps[k + 1]);
            let pad = reach(sa, sb) * AT_ROUNDING;
            let (qa, qb) = (sa.rotation.as_dquat(), sb.rotation.as_dquat());
            // Rotation angle over the segment (twice the quaternions' angle).
            let theta = 4.0 * crate::math::atan2_f64((qa - qb).length(), (qa + qb).length());
            let n = ((theta / 0.05).ceil() as usize).clamp(1, 1024);
            let phi = theta / n as f64;
            let (s0, s1) = (sa.stretch.as_dmat3(), sb.stretch.as_dmat3());
            let end_box = |j: usize| {
                let w1 = j as f32 / n as f32;
                let seg = Segment {
                    index: k,
                    w0: 1.0 - w1,
                    w1,
                };
                padded(&self.interpolate(seg), pad)
            };
            let mut prev = end_box(0);
            for j in 1..=n {
                let next = end_box(j);
                let (ua, ub) = ((j - 1) as f64 / n as f64, j as f64 / n as f64);
                let mut r = 0.0f64;
                for c in corners.map(|c| c.as_dvec3()) {
                    let va: DVec3 = (s0 * (1.0 - ua) + s1 * ua) * c;
                    let vb: DVec3 = (s0 * (1.0 - ub) + s1 * ub) * c;
                    let delta = (vb - va).length();
                    let v = va.length().max(vb.length());
                    r = r.max((phi * phi * v + 2.0 * phi * delta) / 8.0);
                }
                // A little extra for the rounding of these f64 sums, of `j / n` in f32,
                // and of the cast.
                let r = (r * (1.0 + 1e-5)) as f32;
                let mut sub = prev.union(&next);
                sub.min -= Vec3::splat(r);
                sub.max += Vec3::splat(r);
                out = out.union(&sub);
                prev = next;
            }
        }
        out
    }
}

/// Relative padding for the rounding of [`MotionTransform::at`] (the lerps, slerp,
/// quaternion to matrix, the product with the stretch), each a few ulps: 2⁻¹⁷, 64 ulps of
/// f32, leaves a wide margin.
const AT_ROUNDING: f32 = 64.0 * f32::EPSILON;

/// `T·R·S` as an affine transform.
#[inline]
fn compose(translation: Vec3A, rotation: Quat, stretch: Mat3A) -> Affine3A {
    Affine3A {
        matrix3: Mat3A::from_quat(rotation) * stretch,
        translation,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use glam::{DQuat, DVec3, Vec3};

    use crate::test_rng::Rng;

    /// Largest entry difference, relative to the largest entry of `b` (at least 1).
    fn rel_diff(a: &Affine3A, b: &Affine3A) -> f32 {
        let (a, b) = (a.to_cols_array(), b.to_cols_array());
        let scale = b.iter().fold(1.0f32, |m, x| m.max(x.abs()));
        a.iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
            / scale
    }

    fn trs(scale: DVec3, rotation: DQuat, translation: DVec3) -> DMat4 {
        DMat4::from_scale_rotation_translation(scale, rotation, translation)
    }

    fn is_orthonormal(m: &Mat3A) -> bool {
        let p = m.transpose() * *m;
        (p - Mat3A::IDENTITY)
            .to_cols_array()
            .iter()
            .all(|x| x.abs() < 1e-5)
    }

    #[test]
    fn segments_bracket_the_time_and_clamp() {
        assert_eq!(
            Segment::new(0.0, 2),
            Segment {
                index: 0,
                w0: 1.0,
                w1: 0.0
            }
        );
        assert_eq!(Segment::new(1.0, 2).w1, 1.0);
        let s = Segment::new(0.6, 3);
        assert_eq!(s.index, 1);
        assert!((s.w1 - 0.2).abs() < 1e-6 && (s.w0 - 0.8).abs() < 1e-6);
        // The last step, out-of-range and NaN times.
        assert_eq!(Segment::new(1.0, 5).index, 3);
        assert_eq!(Segment::new(1.0, 5).w1, 1.0);
        assert_eq!(Segment::new(7.0, 5), Segment::new(1.0, 5));
        assert_eq!(Segment::new(-1.0, 5), Segment::new(0.0, 5));
        assert_eq!(Segment::new(f32::NAN, 5), Segment::new(0.0, 5));
    }

    #[test]
    fn steps_are_reproduced_at_step_times() {
        let mut rng = Rng(21);
        for n in [1, 2, 5] {
            let steps: Vec<DMat4> = (0..n)
                .map(|_| {
                    let axis = (rng.vec3() - 0.5).as_dvec3().normalize();
                    trs(
                        (rng.vec3() * 3.0 + 0.1).as_dvec3(),
                        DQuat::from_axis_angle(axis, rng.next_f32() as f64 * 6.0),
                        (rng.vec3() * 100.0 - 50.0).as_dvec3(),
                    )
                })
                .collect();
            let motion = MotionTransform::new(&steps);
            assert_eq!(motion.step_count(), n);
            for (k, m) in steps.iter().enumerate() {
                let t = if n == 1 {
                    0.0
                } else {
                    k as f32 / (n - 1) as f32
                };
                let expect = Affine3A::from_mat4(m.as_mat4());
                let d = rel_diff(&motion.at(t), &expect);
                assert!(d < 1e-5, "{n} steps, step {k}: {d}");
            }
        }
    }

    /// Between steps, each segment's rotation is the slerp of its own two ends (from the
    /// arc kept for that segment), bit for bit the slerp of a fresh arc.
    #[test]
    fn each_segment_slerps_along_its_own_arc() {
        let mut rng = Rng(5);
        let steps: Vec<DMat4> = (0..4)
            .map(|k| {
                let axis = (rng.vec3() - 0.5).as_dvec3().normalize();
                trs(
                    DVec3::splat(1.0 + k as f64),
                    DQuat::from_axis_angle(axis, 0.4 + k as f64),
                    DVec3::new(k as f64, 0.0, 0.0),
                )
            })
            .collect();
        let motion = MotionTransform::new(&steps);
        for i in 0..=60 {
            let t = i as f32 / 60.0;
            let seg = Segment::new(t, steps.len());
            let (a, b) = (&motion.steps[seg.index], &motion.steps[seg.index + 1]);
            let expect = compose(
                a.translation * seg.w0 + b.translation * seg.w1,
                SlerpArc::between(a.rotation, b.rotation).slerp(a.rotation, b.rotation, seg.w1),
                a.stretch * seg.w0 + b.stretch * seg.w1,
            );
            assert_eq!(motion.at(t), expect, "time {t}");
        }
    }

    #[test]
    fn a_quarter_turn_is_slerped_not_lerped() {
        // 0° to 90° about Y, at scale 2, moving along X.
        let a = trs(DVec3::splat(2.0), DQuat::IDENTITY, DVec3::ZERO);
        let b = trs(
            DVec3::splat(2.0),
            DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2),
            DVec3::new(4.0, 0.0, 0.0),
        );
        let half = MotionTransform::new(&[a, b]).at(0.5);
        // Orthonormal times the scale (a lerped matrix would be scaled by cos 45° here).
        let r = half.matrix3 * 0.5;
        assert!(is_orthonormal(&r), "{r}");
        let expect = Mat3A::from_rotation_y(std::f32::consts::FRAC_PI_4);
        assert!((r - expect).to_cols_array().iter().all(|x| x.abs() < 1e-6));
        assert!((Vec3::from(half.translation) - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-6);
        // Shortest path: 0° to 270° turns back by 90° through -45°.
        let c = trs(
            DVec3::ONE,
            DQuat::from_rotation_y(1.5 * std::f64::consts::PI),
            DVec3::ZERO,
        );
        let half = MotionTransform::new(&[DMat4::IDENTITY, c]).at(0.5);
        let expect = Mat3A::from_rotation_y(-std::f32::consts::FRAC_PI_4);
        assert!((half.matrix3 - expect)
            .to_cols_array()
            .iter()
            .all(|x| x.abs() < 1e-6));
    }

    #[test]
    fn mirrored_and_sheared_steps_round_trip() {
        let mirror = DMat4::from_scale(DVec3::new(-1.0, 2.0, 3.0));
        let shear = DMat4::from_cols_array(&[
            1.0, 0.0, 0.0, 0.0, //
            0.7, 1.0, 0.0, 0.0, //
            0.0, -0.4, 2.0, 0.0, //
            1.0, 2.0, 3.0, 1.0,
        ]);
        let turned = DMat4::from_quat(DQuat::from_rotation_z(1.0)) * shear * mirror;
        let steps = [mirror, shear, turned];
        let motion = MotionTransform::new(&steps);
        for (k, m) in steps.iter().enumerate() {
            let d = rel_diff(
                &motion.at(k as f32 / 2.0),
                &Affine3A::from_mat4(m.as_mat4()),
            );
            assert!(d < 1e-5, "step {k}: {d}");
        }
        // The rotations are proper and the stretches symmetric (but for the sign).
        for s in &motion.steps {
            let r = Mat3A::from_quat(s.rotation);
            assert!(is_orthonormal(&r) && r.determinant() > 0.0);
            let asym = s.stretch - s.stretch.transpose();
            assert!(asym.to_cols_array().iter().all(|x| x.abs() < 1e-5));
        }
        // Half way between the mirror and the shear the stretch passes through a singular
        // matrix at some time: nothing there may be NaN.
        for i in 0..=100 {
            assert!(motion.at(i as f32 / 100.0).is_finite());
        }
    }

    #[test]
    fn zero_scale_steps_give_no_nan() {
        let turn = trs(
            DVec3::ONE,
            DQuat::from_rotation_x(0.8),
            DVec3::new(1.0, 2.0, 3.0),
        );
        let flat = trs(
            DVec3::new(1.0, 0.0, 1.0),
            DQuat::from_rotation_x(0.8),
            DVec3::ZERO,
        );
        for steps in [
            vec![turn, DMat4::ZERO],
            vec![DMat4::ZERO, turn, flat],
            vec![DMat4::ZERO, DMat4::ZERO],
            vec![flat, DMat4::from_translation(DVec3::X)],
        ] {
            let motion = MotionTransform::new(&steps);
            for i in 0..=64 {
                let m = motion.at(i as f32 / 64.0);
                assert!(m.is_finite(), "{steps:?} at {i}: {m}");
            }
            let b = motion.bounds(&Aabb::from_points(-Vec3::ONE, Vec3::ONE));
            assert!(b.min.is_finite() && b.max.is_finite());
            for (k, m) in steps.iter().enumerate() {
                let t = k as f32 / (steps.len() - 1) as f32;
                let d = rel_diff(&motion.at(t), &Affine3A::from_mat4(m.as_mat4()));
                assert!(d < 1e-5, "{steps:?} step {k}: {d}");
            }
        }
        // A step that scales to nothing keeps the rotation of its neighbour: no spin.
        let motion = MotionTransform::new(&[turn, DMat4::ZERO]);
        let r = motion.at(0.5).matrix3 * 2.0;
        assert!(is_orthonormal(&r));
        assert!((r - Mat3A::from_rotation_x(0.8))
            .to_cols_array()
            .iter()
            .all(|x| x.abs() < 1e-5));
    }
}
