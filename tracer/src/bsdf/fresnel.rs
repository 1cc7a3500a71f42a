//! Fresnel reflectance: Schlick's approximation (the glTF metal and dielectric-layer
//! models) and the exact unpolarised dielectric formula (refractive transmission).

use glam::Vec3;

/// `(1 − cosθ)^5`, the Schlick weight, for a cosine clamped to [0, 1].
pub(crate) fn schlick_weight(cos: f32) -> f32 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// Schlick's Fresnel with a coloured F0 and F90 = 1.
pub(crate) fn schlick(f0: Vec3, cos: f32) -> Vec3 {
    let w = schlick_weight(cos);
    f0 + (Vec3::ONE - f0) * w
}

/// Schlick's Fresnel with a scalar F0 and F90 = 1.
pub(crate) fn schlick_scalar(f0: f32, cos: f32) -> f32 {
    f0 + (1.0 - f0) * schlick_weight(cos)
}

/// Exact Fresnel reflectance of a smooth dielectric interface for unpolarised light.
/// `cos_i` is the cosine on the incident side (>= 0), `eta` the relative index
/// (transmitted over incident side). Total internal reflection gives 1.
pub(crate) fn dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    // Both denominators vanish only for cos_i = cos_t = 0, i.e. grazing at eta = 1,
    // where the interface is invisible: report no reflection rather than NaN.
    let f = 0.5 * (r_parl * r_parl + r_perp * r_perp);
    if f.is_finite() {
        f.clamp(0.0, 1.0)
    } else {
        0.0
    }
}
