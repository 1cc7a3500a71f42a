//! The GGX (Trowbridge-Reitz) microfacet distribution, isotropic or anisotropic: normal
//! distribution `D`, height-correlated Smith masking-shadowing, and visible-normal
//! sampling with the spherical-caps method of Dupuy & Benyoub (2023).
//!
//! Every function works in the local shading frame (normal +Z) and expects the outgoing
//! direction `wo` in the upper hemisphere (`wo.z > 0`); the BSDF mirrors directions into
//! that hemisphere before it calls in here.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, TAU};

use crate::math;

/// Smith's Λ for a direction with cosine `mu` (> 0) to the normal, on an isotropic
/// surface of roughness `alpha` (the tables' form of [`Ggx::lambda`]).
pub(crate) fn lambda(mu: f32, alpha: f32) -> f32 {
    let mu2 = mu * mu;
    lambda_of(alpha * alpha * ((1.0 - mu2).max(0.0) / mu2))
}

/// Λ from `x = α_w² tan²θ`, written as `x / (2 (1 + sqrt(1 + x)))` to avoid the
/// cancellation of `(sqrt(1 + x) − 1) / 2` near the normal; `x` may become infinite for a
/// grazing direction, which gives Λ = ∞ and G = 0, never NaN, because callers only form
/// `1 / (1 + Λ)`.
fn lambda_of(x: f32) -> f32 {
    if x.is_infinite() {
        return f32::INFINITY;
    }
    x / (2.0 * (1.0 + (1.0 + x).sqrt()))
}

/// A GGX distribution with roughness `ax` along the frame's x axis and `ay` along its
/// y axis (KHR_materials_anisotropy stretches it along the x axis; equal for the
/// isotropic distribution of every other lobe).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Ggx {
    pub ax: f32,
    pub ay: f32,
}

impl Ggx {
    pub(crate) fn isotropic(alpha: f32) -> Self {
        Self {
            ax: alpha,
            ay: alpha,
        }
    }

    /// Whether the two roughnesses differ.
    pub(crate) fn is_anisotropic(&self) -> bool {
        self.ax != self.ay
    }

    /// D(wm) for `wm.z >= 0`, written as `1 / (π ax ay (x²/ax² + y²/ay² + z²)²)` so that
    /// it stays finite for every α the BSDF lets through (it treats α < 1e-3 as a delta
    /// lobe and never calls this).
    pub(crate) fn d(&self, wm: Vec3) -> f32 {
        let t = wm.x * wm.x / (self.ax * self.ax) + wm.y * wm.y / (self.ay * self.ay) + wm.z * wm.z;
        FRAC_1_PI / (self.ax * self.ay * t * t)
    }

    /// Smith's Λ for a direction `w` (`w.z ≠ 0`; its sign does not matter).
    pub(crate) fn lambda(&self, w: Vec3) -> f32 {
        let t2 = self.ax * self.ax * w.x * w.x + self.ay * self.ay * w.y * w.y;
        lambda_of(t2 / (w.z * w.z))
    }

    /// Smith masking G1 for `w`.
    pub(crate) fn g1(&self, w: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// Height-correlated Smith masking-shadowing G2 (Heitz 2014) of two directions (the
    /// same form serves reflection and transmission, as in pbrt-v4).
    pub(crate) fn g2(&self, wo: Vec3, wi: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(wo) + self.lambda(wi))
    }

    /// The visible-normal density D_wo(wm) = G1(wo) max(0, wo·wm) D(wm) / wo.z.
    pub(crate) fn pdf_visible_normal(&self, wo: Vec3, wm: Vec3) -> f32 {
        self.g1(wo) * wo.dot(wm).max(0.0) * self.d(wm) / wo.z
    }

    /// Samples a visible microfacet normal for `wo` (`wo.z > 0`) with the spherical-caps
    /// method (Dupuy & Benyoub 2023): in the configuration stretched to α = 1, the visible
    /// normals of a hemisphere are the points of a spherical cap offset by the view
    /// direction; sample the cap uniformly, offset, and unstretch.
    pub(crate) fn sample_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3 {
        // Stretch the view direction into the α = 1 configuration.
        let wo_std = math::normalize_or(Vec3::new(wo.x * self.ax, wo.y * self.ay, wo.z), Vec3::Z);
        // Sample the spherical cap z ∈ (-wo_std.z, 1] uniformly.
        let phi = TAU * u.x;
        let z = (1.0 - u.y) * (1.0 + wo_std.z) - wo_std.z;
        let sin_theta = (1.0 - z * z).max(0.0).sqrt();
        let (sin_phi, cos_phi) = crate::math::sin_cos(phi);
        let c = Vec3::new(sin_theta * cos_phi, sin_theta * sin_phi, z);
        // Offset by the view direction to get the (stretched) half vector, then unstretch.
        let h = c + wo_std;
        let wm = Vec3::new(h.x * self.ax, h.y * self.ay, h.z.max(0.0));
        // `h` vanishes only for u.y = 1 exactly at wo.z = 0, a set of measure zero.
        math::normalize_or(wm, Vec3::Z)
    }
}

/// Mirror reflection of `wo` about the microfacet normal `wm`.
pub(crate) fn reflect(wo: Vec3, wm: Vec3) -> Vec3 {
    2.0 * wo.dot(wm) * wm - wo
}

/// Refraction of `wo` through a microfacet with normal `wm` (`wo·wm > 0`), where
/// `eta` is the relative index (transmitted side over `wo`'s side). `None` on total
/// internal reflection. `eta == 1` passes straight through exactly.
pub(crate) fn refract(wo: Vec3, wm: Vec3, eta: f32) -> Option<Vec3> {
    if eta == 1.0 {
        return Some(-wo);
    }
    let cos_i = wo.dot(wm);
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = sin2_i / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some(math::normalize_or(
        -wo / eta + (cos_i / eta - cos_t) * wm,
        -wm,
    ))
}

/// Cosine-weighted hemisphere sample (Malley's method on a concentric disk).
pub(crate) fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec3::Z;
    }
    // The disk point at radius `r` (the larger coordinate), at angle `a` within π/4 of that
    // coordinate's axis: θ = a from the x axis, or π/2 - a from it where y is larger, whose
    // cosine and sine are a's sine and cosine. Taken so rather than as one angle up to
    // 3π/4, no branch on the angle's range, and no rounding of π/2 - a.
    let along_x = o.x.abs() > o.y.abs();
    let (r, ratio) = if along_x {
        (o.x, o.y / o.x)
    } else {
        (o.y, o.x / o.y)
    };
    let (s, c) = crate::math::sin_cos_quarter(std::f32::consts::FRAC_PI_4 * ratio);
    let (x, y) = if along_x {
        (r * c, r * s)
    } else {
        (r * s, r * c)
    };
    Vec3::new(x, y, (1.0 - x * x - y * y).max(0.0).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Shirley and Chiu's concentric map lifted to the hemisphere, against its closed
    /// form in double precision: the square's point `o` goes to radius
    /// max(|o.x|, |o.y|) at angle π/4 · o.y/o.x from the x axis where x is larger,
    /// π/2 - π/4 · o.x/o.y where y is; on the axes, the diagonals and a grid (every
    /// sample a unit vector, upwards).
    #[test]
    fn cosine_samples_are_the_concentric_map_lifted() {
        let expected = |u: Vec2| {
            let (x, y) = (2.0 * f64::from(u.x) - 1.0, 2.0 * f64::from(u.y) - 1.0);
            let (r, theta) = if x == 0.0 && y == 0.0 {
                (0.0, 0.0)
            } else if x.abs() > y.abs() {
                (x, std::f64::consts::FRAC_PI_4 * (y / x))
            } else {
                (
                    y,
                    std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (x / y),
                )
            };
            let (px, py) = (r * theta.cos(), r * theta.sin());
            [px, py, (1.0 - px * px - py * py).max(0.0).sqrt()]
        };
        let corners = [0.0, 0.25, 0.5, 0.75, 1.0];
        let grid = (0..=40).flat_map(|i| (0..=40).map(move |j| (i as f32 / 40.0, j as f32 / 40.0)));
        let points = corners
            .iter()
            .flat_map(|&a| corners.iter().map(move |&b| (a, b)))
            .chain(grid);
        for (a, b) in points {
            let u = Vec2::new(a, b);
            let got = sample_cosine_hemisphere(u);
            let want = expected(u);
            // (z from 1 - x² - y² in f32: at the rim its square root magnifies the rounding.)
            let close = [
                f64::from(got.x) - want[0],
                f64::from(got.y) - want[1],
                f64::from(got.z * got.z) - want[2] * want[2],
            ];
            assert!(
                got.z >= 0.0 && close.iter().all(|d| d.abs() < 1e-6),
                "{u}: {got} against {want:?}"
            );
        }
        assert_eq!(sample_cosine_hemisphere(Vec2::splat(0.5)), Vec3::Z);
    }
}
