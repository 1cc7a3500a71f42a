//! The isotropic GGX (Trowbridge-Reitz) microfacet distribution: normal distribution
//! `D`, height-correlated Smith masking-shadowing, and visible-normal sampling with the
//! spherical-caps method of Dupuy & Benyoub (2023).
//!
//! Every function works in the local shading frame (normal +Z) and expects the outgoing
//! direction `wo` in the upper hemisphere (`wo.z > 0`); the BSDF mirrors directions into
//! that hemisphere before it calls in here.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, TAU};

/// GGX normal distribution D(wm) for `wm.z >= 0`, written as
/// `1 / (π α² ((x² + y²)/α² + z²)²)` so that it stays finite for every `alpha` the BSDF
/// lets through (it treats `alpha < 1e-3` as a delta lobe and never calls this).
pub(crate) fn d(wm: Vec3, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let t = (wm.x * wm.x + wm.y * wm.y) / a2 + wm.z * wm.z;
    FRAC_1_PI / (a2 * t * t)
}

/// Smith's Λ for a direction with cosine `mu` (> 0) to the normal. Written as
/// `x / (2 (1 + sqrt(1 + x)))` with `x = α² tan²θ` to avoid the cancellation of
/// `(sqrt(1 + x) − 1) / 2` near the normal; `x` may become infinite for `mu → 0`, which
/// gives Λ = ∞ and G = 0, never NaN, because callers only form `1 / (1 + Λ)`.
pub(crate) fn lambda(mu: f32, alpha: f32) -> f32 {
    let mu2 = mu * mu;
    let x = alpha * alpha * ((1.0 - mu2).max(0.0) / mu2);
    if x.is_infinite() {
        return f32::INFINITY;
    }
    x / (2.0 * (1.0 + (1.0 + x).sqrt()))
}

/// Smith masking G1 for a direction with cosine `mu` (> 0).
pub(crate) fn g1(mu: f32, alpha: f32) -> f32 {
    1.0 / (1.0 + lambda(mu, alpha))
}

/// Height-correlated Smith masking-shadowing G2 (Heitz 2014) for the cosines of the two
/// directions (absolute values; the same form serves reflection and transmission, as in
/// pbrt-v4).
pub(crate) fn g2(mu_o: f32, mu_i: f32, alpha: f32) -> f32 {
    1.0 / (1.0 + lambda(mu_o, alpha) + lambda(mu_i, alpha))
}

/// The visible-normal density D_wo(wm) = G1(wo) max(0, wo·wm) D(wm) / wo.z.
pub(crate) fn pdf_visible_normal(wo: Vec3, wm: Vec3, alpha: f32) -> f32 {
    g1(wo.z, alpha) * wo.dot(wm).max(0.0) * d(wm, alpha) / wo.z
}

/// Samples a visible microfacet normal for `wo` (`wo.z > 0`) with the spherical-caps
/// method (Dupuy & Benyoub 2023): in the configuration stretched to α = 1, the visible
/// normals of a hemisphere are the points of a spherical cap offset by the view
/// direction; sample the cap uniformly, offset, and unstretch.
pub(crate) fn sample_visible_normal(wo: Vec3, alpha: f32, u: Vec2) -> Vec3 {
    // Stretch the view direction into the α = 1 configuration.
    let wo_std = Vec3::new(wo.x * alpha, wo.y * alpha, wo.z).normalize_or(Vec3::Z);
    // Sample the spherical cap z ∈ (-wo_std.z, 1] uniformly.
    let phi = TAU * u.x;
    let z = (1.0 - u.y) * (1.0 + wo_std.z) - wo_std.z;
    let sin_theta = (1.0 - z * z).max(0.0).sqrt();
    let (sin_phi, cos_phi) = crate::math::sin_cos(phi);
    let c = Vec3::new(sin_theta * cos_phi, sin_theta * sin_phi, z);
    // Offset by the view direction to get the (stretched) half vector, then unstretch.
    let h = c + wo_std;
    let wm = Vec3::new(h.x * alpha, h.y * alpha, h.z.max(0.0));
    // `h` vanishes only for u.y = 1 exactly at wo.z = 0, a set of measure zero.
    wm.normalize_or(Vec3::Z)
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
    Some((-wo / eta + (cos_i / eta - cos_t) * wm).normalize_or(-wm))
}

/// Cosine-weighted hemisphere sample (Malley's method on a concentric disk).
pub(crate) fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let o = 2.0 * u - Vec2::ONE;
    let (r, theta) = if o.x == 0.0 && o.y == 0.0 {
        (0.0, 0.0)
    } else if o.x.abs() > o.y.abs() {
        (o.x, std::f32::consts::FRAC_PI_4 * (o.y / o.x))
    } else {
        (
            o.y,
            std::f32::consts::FRAC_PI_2 - std::f32::consts::FRAC_PI_4 * (o.x / o.y),
        )
    };
    let (s, c) = crate::math::sin_cos(theta);
    let x = r * c;
    let y = r * s;
    Vec3::new(x, y, (1.0 - x * x - y * y).max(0.0).sqrt())
}
