//! The transcendental functions the tracer uses, the same bits on every machine.
//!
//! The farm verifies tiles by comparing their bits across workers, so a pixel must not
//! depend on the CPU that traced it. The C library's `sinf`, `expf`, `powf`... do: glibc
//! picks an FMA or an SSE2 build of each at load time, and they round differently. These
//! are the `libm` crate's (musl's algorithms), compiled into the binary from plain IEEE
//! operations, so every x86-64 machine runs the same instructions. `tracer/clippy.toml`
//! forbids the `std` and `glam` methods they replace, so a new call cannot slip back.
//!
//! The square root, `mul_add`, `abs`, `min` and `max` are exactly rounded IEEE operations
//! and need no wrapper. Last, the tests of a float that the path loop makes at every bounce
//! ([`positive_finite`], [`finite`], [`try_normalize`]), in the comparisons that x86 runs
//! fastest.

use glam::{DQuat, Quat, Vec3, Vec3A};

/// `(sin x, cos x)`: `libm::sincosf`, the same bits, with its branches for `|x| ≤ 3π/4`
/// (the angles a bounce's direction sampling draws) inline and no call. Those branches
/// evaluate musl's polynomial kernels, copied below; past them the crate's own function
/// reduces the argument. A test compares the two over the whole inline range.
#[inline(always)]
pub fn sin_cos(x: f32) -> (f32, f32) {
    use std::f64::consts::FRAC_PI_2;
    let bits = x.to_bits() & 0x7fff_ffff;
    if bits <= 0x3f49_0fda {
        // |x| ≤ π/4.
        return sin_cos_quarter(x);
    }
    if bits <= 0x4016_cbe3 {
        // |x| ≤ 3π/4: a quarter turn away.
        let x = f64::from(x);
        return if x < 0.0 {
            (-cos_kernel(x + FRAC_PI_2), sin_kernel(x + FRAC_PI_2))
        } else {
            (cos_kernel(FRAC_PI_2 - x), sin_kernel(FRAC_PI_2 - x))
        };
    }
    libm::sincosf(x)
}

/// [`sin_cos`] of an `x` known to lie within `±FRAC_PI_4` (the f32 nearest π/4, just above
/// it): musl's kernels without the branches on the argument's range, which mispredict
/// where the range varies from call to call (a cosine-weighted direction's angle, half the
/// time past π/4 when drawn whole). The same bits as [`sin_cos`] but at `±FRAC_PI_4`
/// itself, where `sin_cos` takes its next branch and the two agree to an ulp.
#[inline(always)]
pub fn sin_cos_quarter(x: f32) -> (f32, f32) {
    debug_assert!(x.is_nan() || x.abs() <= std::f32::consts::FRAC_PI_4, "{x}");
    if x.to_bits() & 0x7fff_ffff < 0x3980_0000 {
        // |x| < 2^-12: sin x rounds to x and cos x to 1.
        return (x, 1.0);
    }
    let x = f64::from(x);
    (sin_kernel(x), cos_kernel(x))
}

/// musl's `__sindf`: sin x for |x| ≤ π/4, in double precision, rounded once.
#[inline(always)]
#[allow(clippy::excessive_precision)] // musl's constants as written there
fn sin_kernel(x: f64) -> f32 {
    const S1: f64 = -0.166_666_666_416_265_235_595;
    const S2: f64 = 0.008_333_329_385_889_463_175_6;
    const S3: f64 = -0.000_198_393_348_360_966_317_347;
    const S4: f64 = 0.000_002_718_311_493_989_821_906_4;
    let z = x * x;
    let w = z * z;
    let r = S3 + z * S4;
    let s = z * x;
    ((x + s * (S1 + z * S2)) + s * w * r) as f32
}

/// musl's `__cosdf`: cos x for |x| ≤ π/4, in double precision, rounded once.
#[inline(always)]
#[allow(clippy::excessive_precision)] // musl's constants as written there
fn cos_kernel(x: f64) -> f32 {
    const C0: f64 = -0.499_999_997_251_031_003_120;
    const C1: f64 = 0.041_666_623_323_739_063_189_4;
    const C2: f64 = -0.001_388_676_377_460_992_946_92;
    const C3: f64 = 0.000_024_390_448_796_277_409_065_4;
    let z = x * x;
    let w = z * z;
    let r = C2 + z * C3;
    (((1.0 + z * C0) + w * C1) + (w * z) * r) as f32
}

/// `sin x`.
#[inline]
pub fn sin(x: f32) -> f32 {
    libm::sinf(x)
}

/// `cos x`.
#[inline]
pub fn cos(x: f32) -> f32 {
    libm::cosf(x)
}

/// `tan x`.
#[inline]
pub fn tan(x: f32) -> f32 {
    libm::tanf(x)
}

/// `atan2(y, x)`.
#[inline]
pub fn atan2(y: f32, x: f32) -> f32 {
    libm::atan2f(y, x)
}

/// `acos x`.
#[inline]
pub fn acos(x: f32) -> f32 {
    libm::acosf(x)
}

/// `x^y`.
#[inline]
pub fn powf(x: f32, y: f32) -> f32 {
    libm::powf(x, y)
}

/// `2^x`.
#[inline]
pub fn exp2(x: f32) -> f32 {
    libm::exp2f(x)
}

/// `e^x`.
#[inline]
pub fn exp(x: f32) -> f32 {
    libm::expf(x)
}

/// The natural logarithm.
#[inline]
pub fn ln(x: f32) -> f32 {
    libm::logf(x)
}

/// The hyperbolic cosine.
#[inline]
pub fn cosh(x: f32) -> f32 {
    libm::coshf(x)
}

/// The inverse hyperbolic tangent.
#[inline]
pub fn atanh(x: f32) -> f32 {
    libm::atanhf(x)
}

/// Double-precision `(sin x, cos x)`.
#[inline]
pub fn sin_cos_f64(x: f64) -> (f64, f64) {
    libm::sincos(x)
}

/// Double-precision `sin x`.
#[inline]
pub fn sin_f64(x: f64) -> f64 {
    libm::sin(x)
}

/// Double-precision `cos x`.
#[inline]
pub fn cos_f64(x: f64) -> f64 {
    libm::cos(x)
}

/// Double-precision `tan x`.
#[inline]
pub fn tan_f64(x: f64) -> f64 {
    libm::tan(x)
}

/// Double-precision `atan2(y, x)`.
#[inline]
pub fn atan2_f64(y: f64, x: f64) -> f64 {
    libm::atan2(y, x)
}

/// Double-precision `atan x`.
#[inline]
pub fn atan_f64(x: f64) -> f64 {
    libm::atan(x)
}

/// Double-precision `acos x`.
#[inline]
pub fn acos_f64(x: f64) -> f64 {
    libm::acos(x)
}

/// Double-precision `e^x − 1`, exact near 0.
#[inline]
pub fn exp_m1_f64(x: f64) -> f64 {
    libm::expm1(x)
}

/// The arc between two unit quaternions on the same hemisphere, for slerp: its angle
/// and the angle's sine, the part of slerp that does not depend on how far along the arc
/// it goes. The angle comes from `atan2(|a - b|, |a + b|)`, accurate for tiny angles where
/// `acos(a·b)` is not. Motion steps keep the arc to the next step, so that the slerp of
/// each ray's time takes two sines, not an arctangent and three.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlerpArc {
    theta: f32,
    sin: f32,
}

impl SlerpArc {
    /// The arc from `a` to `b`.
    pub fn between(a: Quat, b: Quat) -> SlerpArc {
        let theta = 2.0 * atan2((a - b).length(), (a + b).length());
        SlerpArc {
            theta,
            sin: sin(theta),
        }
    }

    /// `a` to `b` along the great arc (constant angular speed), for `a` and `b` the ends
    /// of this arc.
    #[inline]
    pub fn slerp(&self, a: Quat, b: Quat, u: f32) -> Quat {
        if u == 0.0 {
            return a;
        }
        if u == 1.0 {
            return b;
        }
        let (theta, s) = (self.theta, self.sin);
        let (wa, wb) = if s > 0.0 {
            (sin((1.0 - u) * theta) / s, sin(u * theta) / s)
        } else {
            (1.0 - u, u)
        };
        (a * wa + b * wb).normalize()
    }
}

/// `q` or `-q` (the same rotation), whichever lies on `previous`'s hemisphere, so that
/// [`SlerpArc::slerp`] from `previous` takes the shorter arc; `q` itself when there is no
/// previous. Motion steps are aligned with this once, when prepared, rather than per ray.
pub fn same_hemisphere(previous: Option<Quat>, q: Quat) -> Quat {
    match previous {
        Some(p) if p.dot(q) < 0.0 => -q,
        _ => q,
    }
}

/// A rotation by `angle` radians about the y axis (`glam`'s own computes its sine with
/// the C library).
pub fn rotation_y(angle: f32) -> Quat {
    let (s, c) = sin_cos(0.5 * angle);
    Quat::from_xyzw(0.0, s, 0.0, c)
}

/// Double-precision [`rotation_y`].
pub fn rotation_y_f64(angle: f64) -> DQuat {
    let (s, c) = sin_cos_f64(0.5 * angle);
    DQuat::from_xyzw(0.0, s, 0.0, c)
}

/// A rotation by `angle` radians about the x axis, in double precision.
pub fn rotation_x_f64(angle: f64) -> DQuat {
    let (s, c) = sin_cos_f64(0.5 * angle);
    DQuat::from_xyzw(s, 0.0, 0.0, c)
}

/// A rotation by `angle` radians about the z axis.
pub fn rotation_z(angle: f32) -> Quat {
    let (s, c) = sin_cos(0.5 * angle);
    Quat::from_xyzw(0.0, 0.0, s, c)
}

/// Whether `x` is positive and finite, in two float comparisons. Written as `x > 0.0 &&
/// x.is_finite()`, LLVM folds the test into a floating-point class test, which it computes
/// on x86 in a dozen integer instructions; a comparison with `f32::MAX` is no class test.
#[inline(always)]
pub fn positive_finite(x: f32) -> bool {
    x > 0.0 && x <= f32::MAX
}

/// Whether every component of `v` is finite, in SIMD lanes: `x · 0` is ±0 for a finite `x`
/// and NaN for an infinity or a NaN. (glam's `is_finite` makes a class test of each
/// component, in integer instructions.)
#[inline(always)]
pub fn finite(v: Vec3) -> bool {
    (Vec3A::from(v) * 0.0).cmpeq(Vec3A::ZERO).all()
}

/// `v` at unit length, or `None` where its length is zero or not finite: glam's
/// `try_normalize`, the same bits, with its test by [`positive_finite`].
#[inline(always)]
pub fn try_normalize(v: Vec3) -> Option<Vec3> {
    let rcp = v.length_recip();
    positive_finite(rcp).then(|| v * rcp)
}

/// [`try_normalize`], or `fallback` where it gives `None` (glam's `normalize_or`).
#[inline(always)]
pub fn normalize_or(v: Vec3, fallback: Vec3) -> Vec3 {
    try_normalize(v).unwrap_or(fallback)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// How many floats apart `a` and `b` are (for values of one sign).
    fn ulps(a: f32, b: f32) -> u64 {
        (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs()
    }

    /// `positive_finite` is `x > 0 && x.is_finite()`, `finite` glam's `is_finite`, and the
    /// normalisations are glam's bit for bit: on the edges (zeros, subnormals, the largest
    /// float, infinities, NaNs) and on vectors whose lengths underflow, overflow or are
    /// ordinary.
    #[test]
    fn float_tests_are_the_class_tests() {
        let edges = [
            0.0,
            -0.0,
            f32::from_bits(1),
            f32::MIN_POSITIVE,
            1.0,
            f32::MAX,
            f32::INFINITY,
            f32::NAN,
            -f32::NAN,
        ];
        for x in edges.into_iter().flat_map(|x| [x, -x]) {
            assert_eq!(positive_finite(x), x > 0.0 && x.is_finite(), "{x:e}");
            for v in [
                Vec3::new(x, 1.0, -2.0),
                Vec3::new(0.5, x, 3.0),
                Vec3::new(-1.0, 0.0, x),
            ] {
                assert_eq!(finite(v), v.is_finite(), "{v}");
            }
        }
        let mut rng = crate::test_rng::Rng(11);
        let scales = [0.0, 1e-30, 1e-20, 1.0, 1e20, 1e30, f32::INFINITY];
        for i in 0..10_000 {
            let v = (rng.vec3() - 0.5) * scales[i % scales.len()];
            let v = if i % 97 == 0 { v.with_y(f32::NAN) } else { v };
            let bits = |v: Vec3| v.to_array().map(f32::to_bits);
            assert_eq!(
                try_normalize(v).map(bits),
                v.try_normalize().map(bits),
                "{v}"
            );
            let fallback = Vec3::new(0.0, 0.0, -1.0);
            assert_eq!(
                bits(normalize_or(v, fallback)),
                bits(v.normalize_or(fallback)),
                "{v}"
            );
        }
    }

    /// Within a couple of ulps of the platform's over the ranges the tracer uses.
    #[test]
    fn agrees_with_the_platform_library() {
        for i in 0..=10_000 {
            let x = -7.0 + 14.0 * i as f32 / 10_000.0;
            let (s, c) = sin_cos(x);
            assert!(
                (s - x.sin()).abs() <= 1e-7 && (c - x.cos()).abs() <= 1e-7,
                "{x}"
            );
            assert_eq!((sin(x), cos(x)), (s, c), "{x}");
            let u = i as f32 / 10_000.0;
            assert!(
                ulps(acos(2.0 * u - 1.0), (2.0 * u - 1.0).acos()) <= 2,
                "{u}"
            );
            assert!(ulps(atan2(x, 1.5), x.atan2(1.5)) <= 2, "{x}");
            assert!(ulps(powf(u, 2.4), u.powf(2.4)) <= 2, "{u}");
            assert!(ulps(exp2(x), x.exp2()) <= 2, "{x}");
            let d = f64::from(x);
            assert!((tan_f64(0.2 * d) - (0.2 * d).tan()).abs() <= 1e-15);
            assert!((atan_f64(d) - d.atan()).abs() <= 1e-15);
        }
    }

    /// The inline branches of `sin_cos` are `libm::sincosf` to the bit: every float of
    /// `[-2.5, 2.5]` at a stride, and every one near each branch's edge.
    #[test]
    fn sin_cos_is_libms_to_the_bit() {
        let check = |x: f32| {
            let (s, c) = sin_cos(x);
            let (ls, lc) = libm::sincosf(x);
            assert_eq!(
                (s.to_bits(), c.to_bits()),
                (ls.to_bits(), lc.to_bits()),
                "{x:e}"
            );
        };
        for bits in (0..=2.5f32.to_bits()).step_by(997) {
            check(f32::from_bits(bits));
            check(-f32::from_bits(bits));
        }
        for bits in (0..0x3f49_0fdb)
            .step_by(101)
            .chain(0x3f49_0fda..0x3f49_0fdb)
        {
            for x in [f32::from_bits(bits), -f32::from_bits(bits)] {
                assert_eq!(sin_cos_quarter(x), sin_cos(x), "{x:e}");
            }
        }
        for x in [std::f32::consts::FRAC_PI_4, -std::f32::consts::FRAC_PI_4] {
            let ((s, c), (ls, lc)) = (sin_cos_quarter(x), sin_cos(x));
            assert!(ulps(s, ls) <= 1 && ulps(c, lc) <= 1, "{x:e}");
        }
        for edge in [0x3980_0000u32, 0x3f49_0fda, 0x4016_cbe3] {
            for bits in edge - 2000..edge + 2000 {
                check(f32::from_bits(bits));
                check(-f32::from_bits(bits));
            }
        }
        for x in [0.0, f32::MIN_POSITIVE, 1e-40, f32::INFINITY, f32::NAN, 1e30] {
            check(x);
            check(-x);
        }
    }

    #[test]
    fn rotations_match_glam() {
        for angle in [-3.0f32, -0.3, 0.0, 0.29, 1.0, 2.5] {
            let ours = rotation_y(angle);
            assert!(ours.abs_diff_eq(Quat::from_rotation_y(angle), 1e-7));
            let ours = rotation_y_f64(f64::from(angle));
            assert!(ours.abs_diff_eq(DQuat::from_rotation_y(f64::from(angle)), 1e-15));
        }
    }
}
