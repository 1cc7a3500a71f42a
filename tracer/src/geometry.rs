//! Rays, hits, bounding boxes, shading frames and the self-intersection offset.

use glam::{Affine3A, Vec3};

/// A ray in the prepared frame's camera-relative world space (or in an object's space).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Direction; not necessarily normalised (object-space rays keep the instance's scale).
    pub dir: Vec3,
    /// Shutter position in [0, 1] (0: the shutter opens, 1: it closes); unused when
    /// nothing in the frame moves.
    pub time: f32,
}

impl Ray {
    /// A ray at time 0.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self {
            origin,
            dir,
            time: 0.0,
        }
    }

    /// The point at parameter `t`.
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// The closest intersection found along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Index of the instance in the prepared frame.
    pub instance: u32,
    /// Triangle index within the instance's mesh (over all its primitives).
    pub triangle: u32,
    /// Barycentric weight of the triangle's second vertex.
    pub b1: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub b2: f32,
}

/// An axis-aligned bounding box. The empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3,
    /// Upper corner.
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The box that contains nothing; growing it by a point gives that point.
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };

    /// The smallest box holding both points.
    pub fn from_points(a: Vec3, b: Vec3) -> Self {
        Self {
            min: a.min(b),
            max: a.max(b),
        }
    }

    /// Whether the box contains no point.
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    /// Grows the box to hold `p`.
    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// The union of two boxes.
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    /// Size along each axis (negative for the empty box).
    pub fn extent(&self) -> Vec3 {
        self.max - self.min
    }

    /// Centre point.
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Surface area, 0 for the empty box.
    pub fn area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// The eight corners.
    pub fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min, self.max);
        [
            Vec3::new(a.x, a.y, a.z),
            Vec3::new(b.x, a.y, a.z),
            Vec3::new(a.x, b.y, a.z),
            Vec3::new(b.x, b.y, a.z),
            Vec3::new(a.x, a.y, b.z),
            Vec3::new(b.x, a.y, b.z),
            Vec3::new(a.x, b.y, b.z),
            Vec3::new(b.x, b.y, b.z),
        ]
    }
}

/// An orthonormal basis whose `z` axis is a surface normal: BSDFs work in this frame.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    /// First tangent.
    pub x: Vec3,
    /// Second tangent.
    pub y: Vec3,
    /// Normal.
    pub z: Vec3,
}

impl Frame {
    /// A frame around unit normal `n` with an arbitrary but continuous tangent
    /// (Duff et al. 2017, "Building an Orthonormal Basis, Revisited").
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let x = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let y = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Self { x, y, z: n }
    }

    /// A frame around unit normal `n` whose first axis follows `tangent` as closely as
    /// possible (Gram-Schmidt); falls back to [`Frame::from_normal`] for a degenerate tangent.
    pub fn from_normal_tangent(n: Vec3, tangent: Vec3) -> Self {
        let t = tangent - n * n.dot(tangent);
        let len2 = t.length_squared();
        if !(len2 > 1e-12) || !len2.is_finite() {
            return Self::from_normal(n);
        }
        let x = t / len2.sqrt();
        Self {
            x,
            y: n.cross(x),
            z: n,
        }
    }

    /// World direction to local coordinates.
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.x), v.dot(self.y), v.dot(self.z))
    }

    /// Local coordinates to a world direction.
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.x * v.x + self.y * v.y + self.z * v.z
    }
}

/// Moves a surface point off its surface along the geometric normal by an amount that
/// scales with the point's magnitude, so that a ray leaving the surface never hits it
/// again at any scene scale. Wächter & Binder, "A Fast and Robust Method for Avoiding
/// Self-Intersection", Ray Tracing Gems ch. 6: the offset is done in integer ulps, so it
/// is relative to the coordinate's size, with a small absolute floor near the origin.
pub fn offset_ray_origin(p: Vec3, ng: Vec3) -> Vec3 {
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    let of_i = (ng * INT_SCALE).as_ivec3();
    let step = |p: f32, o: i32| {
        let bits = p.to_bits() as i32;
        f32::from_bits((bits + if p < 0.0 { -o } else { o }) as u32)
    };
    let p_i = Vec3::new(step(p.x, of_i.x), step(p.y, of_i.y), step(p.z, of_i.z));
    let pick = |p: f32, p_i: f32, n: f32| {
        if p.abs() < ORIGIN {
            p + FLOAT_SCALE * n
        } else {
            p_i
        }
    };
    Vec3::new(
        pick(p.x, p_i.x, ng.x),
        pick(p.y, p_i.y, ng.y),
        pick(p.z, p_i.z, ng.z),
    )
}

/// Where `ray` meets the plane of the triangle `v`, computed in double precision from the
/// single-precision inputs and rounded once, with a bound on its error per coordinate;
/// `None` when the ray is parallel to the plane or the numbers overflow. The point is on
/// the plane and where the ray is along it to within that rounding, whatever the
/// triangle's size: barycentric interpolation, in contrast, is off by the rounding of the
/// vertices' magnitudes, which on a triangle 1e5 across is centimetres.
pub fn plane_hit_point(ray: &Ray, v: [Vec3; 3]) -> Option<(Vec3, Vec3)> {
    // The largest magnitude, taken before widening (which is exact and keeps the order).
    let magnitudes = v[0]
        .abs()
        .max(v[1].abs())
        .max(v[2].abs())
        .max(ray.origin.abs())
        .max_element();
    let [a, b, c] = v.map(|p| p.as_dvec3());
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    let n = (b - a).cross(c - a);
    let t = n.dot(a - o) / n.dot(d);
    let p = (o + d * t).as_vec3();
    // (A `t` that is not finite makes every coordinate of `d · t` infinite or NaN, so `p`
    // tells for both.)
    if !crate::math::finite(p) {
        return None;
    }
    // Rounding to single precision, and double precision's own error relative to the
    // magnitudes it worked with (far above 2^-53 of them, to cover every operation).
    let error =
        p.abs() * crate::triangle::gamma(1) + Vec3::splat((f64::from(magnitudes) * 1e-14) as f32);
    Some((p, error))
}

/// A bound on the absolute error, per coordinate, of `to_world · object` for an
/// object-space point known to within `object_error`, widened to cover moving the result
/// back into an instance's object space for the next ray. It grows with the translation's
/// magnitude, not only the point's: a mesh placed far from its node's origin is known no
/// better than that placement's rounding (pbrt-v4's error bounds for transforms).
pub fn hit_point_error(to_world: &Affine3A, object: Vec3, object_error: Vec3) -> Vec3 {
    use crate::triangle::gamma;
    let m = to_world.matrix3.abs();
    let t = Vec3::from(to_world.translation).abs();
    // The object-space error carried through the matrix; the product and sums of the
    // transform (gamma(3)); the same again for the inverse transform of the next ray.
    m * object_error * (1.0 + gamma(3)) + (m * object.abs() + t) * (2.0 * gamma(3))
}

/// [`hit_point_error`] for a `to_world` that only translates by `t`: the same numbers
/// (the identity's products and zero terms are exact), without the matrix.
pub fn translated_hit_point_error(t: Vec3, object: Vec3, object_error: Vec3) -> Vec3 {
    use crate::triangle::gamma;
    object_error * (1.0 + gamma(3)) + (object.abs() + t.abs()) * (2.0 * gamma(3))
}

/// [`offset_ray_origin`] for a point known to within `error` (per coordinate, see
/// [`hit_point_error`]): moved along `ng` past the error first (pbrt-v4's
/// `OffsetRayOrigin`), then by the same ulp steps, but without the absolute floor near the
/// origin, which would be a tenth of a whole scene 1e-4 across; the error bound covers
/// what the floor was for (a point near zero computed from larger numbers).
pub fn offset_ray_origin_bounded(p: Vec3, ng: Vec3, error: Vec3) -> Vec3 {
    let d = ng.abs().dot(error);
    step_ulps(p + ng * d, ng)
}

/// The ulps per unit of `ng`'s components that [`step_ulps`] moves a coordinate by.
const INT_SCALE: f32 = 256.0;

/// Moves each coordinate of `p` by a number of ulps proportional to `ng`'s component, away
/// from the surface (the integer part of [`offset_ray_origin`]). In SSE2 lanes on x86_64
/// (every shadow ray and bounce comes here, and the scalar conversions and branches cost
/// about 50 instructions a call): the same bits as [`step_ulps_scalar`], which other
/// targets run, for any `ng` whose components are numbers below 2^23 (a unit normal's
/// are; the lanes' conversion differs from `as` only for a NaN or past 2^31).
#[inline(always)]
fn step_ulps(p: Vec3, ng: Vec3) -> Vec3 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{
            _mm_add_epi32, _mm_add_ps, _mm_and_ps, _mm_andnot_ps, _mm_castps_si128,
            _mm_castsi128_ps, _mm_cmplt_ps, _mm_cvtepi32_ps, _mm_cvttps_epi32, _mm_movemask_ps,
            _mm_mul_ps, _mm_or_ps, _mm_set1_ps, _mm_setzero_ps, _mm_sub_epi32, _mm_xor_si128,
        };
        let (p4, ng4) = (glam::Vec4::from((p, 0.0)), glam::Vec4::from((ng, 0.0)));
        // SAFETY: SSE2 is part of every x86_64 CPU.
        let moved = unsafe {
            let p4 = p4.into();
            // Truncated, as `as` does for the values a unit normal gives.
            let o = _mm_cvttps_epi32(_mm_mul_ps(ng4.into(), _mm_set1_ps(INT_SCALE)));
            // -o where p < 0 (a NaN is not), by two's complement: (o ^ m) - m.
            let negative = _mm_castps_si128(_mm_cmplt_ps(p4, _mm_setzero_ps()));
            let signed = _mm_sub_epi32(_mm_xor_si128(o, negative), negative);
            let stepped = _mm_castsi128_ps(_mm_add_epi32(_mm_castps_si128(p4), signed));
            // Zero or subnormal: every ulp is 2^-149, and integer steps could cross zero.
            let abs = glam::Vec4::from(p4).abs().into();
            let tiny = _mm_cmplt_ps(abs, _mm_set1_ps(f32::MIN_POSITIVE));
            // Only then the float sum below: its operands are subnormal, and each
            // instruction on them costs a microcode assist (over a hundred cycles on
            // Intel), which branchless lanes paid at every call. The fourth lane is zero.
            if _mm_movemask_ps(tiny) & 0b111 == 0 {
                return glam::Vec4::from(stepped).truncate();
            }
            let ulps = _mm_mul_ps(_mm_cvtepi32_ps(o), _mm_set1_ps(f32::from_bits(1)));
            let tiny_moved = _mm_add_ps(p4, ulps);
            glam::Vec4::from(_mm_or_ps(
                _mm_and_ps(tiny, tiny_moved),
                _mm_andnot_ps(tiny, stepped),
            ))
        };
        moved.truncate()
    }
    #[cfg(not(target_arch = "x86_64"))]
    step_ulps_scalar(p, ng)
}

/// [`step_ulps`] one coordinate at a time.
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
fn step_ulps_scalar(p: Vec3, ng: Vec3) -> Vec3 {
    let of_i = (ng * INT_SCALE).as_ivec3();
    let step = |p: f32, o: i32| {
        if p.abs() < f32::MIN_POSITIVE {
            // Zero or subnormal: every ulp is 2^-149, and integer steps could cross zero.
            return p + o as f32 * f32::from_bits(1);
        }
        let bits = p.to_bits() as i32;
        // Wrapping as the lanes' sum does (only a NaN's bits can wrap).
        f32::from_bits((bits.wrapping_add(if p < 0.0 { -o } else { o })) as u32)
    };
    Vec3::new(step(p.x, of_i.x), step(p.y, of_i.y), step(p.z, of_i.z))
}

/// Interpolates three per-vertex values with barycentric weights (b1, b2).
pub fn barycentric<T>(a: T, b: T, c: T, b1: f32, b2: f32) -> T
where
    T: core::ops::Mul<f32, Output = T> + core::ops::Add<Output = T>,
{
    a * (1.0 - b1 - b2) + b * b1 + c * b2
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::Rng;

    /// The lanes move every coordinate as the scalar steps do, bit for bit: positive,
    /// negative, zero, subnormal and huge coordinates, normals along and between the axes.
    #[test]
    fn step_ulps_in_lanes_gives_the_scalar_bits() {
        let mut rng = Rng(0x57e9);
        let special = [
            0.0,
            -0.0,
            f32::from_bits(1),
            -f32::from_bits(7),
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            1e-30,
            1.0,
            -3.5,
            1e30,
            -f32::MAX,
        ];
        for i in 0..20_000 {
            let pick = |rng: &mut Rng| {
                if rng.next_f32() < 0.3 {
                    special[(rng.next_f32() * special.len() as f32) as usize]
                } else {
                    (rng.next_f32() - 0.5) * 10f32.powf(rng.next_f32() * 40.0 - 20.0)
                }
            };
            let p = Vec3::new(pick(&mut rng), pick(&mut rng), pick(&mut rng));
            let ng = match i % 4 {
                0 => Vec3::Y,
                1 => -Vec3::X,
                _ => (rng.vec3() - 0.5).normalize_or(Vec3::Z),
            };
            let bits = |v: Vec3| v.to_array().map(f32::to_bits);
            assert_eq!(
                bits(step_ulps(p, ng)),
                bits(step_ulps_scalar(p, ng)),
                "p {p:?} ng {ng:?}"
            );
        }
    }
}
