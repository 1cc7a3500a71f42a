//! A thin wall: glTF's transmission without KHR_materials_volume ("the surface
//! represents a thin wall"). Light crosses it without bending and without entering a
//! medium; the glTF transmission extension's thin-walled BTDF is the reflection lobe
//! mirrored through the surface:
//!
//! ```text
//! f_r(wo, wi) = s · F(wo·h, η) · tint · D(h) G2 / (4 μo μi) · k(μo),   h = ‖wo + wi‖
//! f_t(wo, wi) = (1 − s · F(wo·h, η)) · c · D(h) G2 / (4 μo |μi|) · k(μo),   h = ‖wo + flip(wi)‖
//! ```
//!
//! with `s` the specular factor, `c` the base colour, and `k = 1 / E1(μo)` Turquin's
//! factor for a lobe whose Fresnel terms sum to 1: with a white base and specular colour
//! the wall scatters every photon it meets (a white furnace reads 1), rough or smooth.
//! Seen from either side it is the same, and no `1/η²` applies: the radiance leaves into
//! the medium it came from. A smooth wall passes `wi = −wo` with weight `(1 − s·F) c`.
//!
//! Sampling reflects `wo` about a visible normal and keeps the reflection with
//! probability `s · F`, else mirrors it to the far side; a reflection that points below
//! the horizon is folded back above it, as the solid interface folds its lobes, so each
//! direction is reached two ways and its density sums both.

use glam::{Vec2, Vec3};

use super::{flip, fresnel, microfacet, AtWo, Bsdf, BsdfSample};
use crate::math;

/// f for `wo.z > 0 > wi.z` of a rough wall (the transmitted lobe).
pub(super) fn eval_transmission(b: &Bsdf, wo: Vec3, wi: Vec3, at: &AtWo) -> Vec3 {
    let mirrored = flip(wi);
    let Some(wm) = math::try_normalize(wo + mirrored) else {
        return Vec3::ZERO;
    };
    let cos_om = wo.dot(wm);
    if wm.z <= 0.0 || cos_om <= 0.0 {
        return Vec3::ZERO;
    }
    let fr = fresnel::dielectric(cos_om, at.eta_rel);
    let t = Vec3::ONE - b.glass_s * b.glass_fresnel(fr, cos_om, at);
    let lobe = b.ggx.d(wm) * b.ggx.g2(wo, mirrored) / (4.0 * wo.z * mirrored.z);
    b.w_glass * t * lobe * at.thin_comp * b.base
}

/// Density, within the wall's lobe, of transmitting to `wi` (`wi.z < 0`): the reflection
/// of `wo` about a visible normal lands at `flip(wi)` and is mirrored, or lands at `wi`
/// (below the horizon) and is kept there.
pub(super) fn pdf_transmission(b: &Bsdf, wo: Vec3, wi: Vec3, at: &AtWo) -> f32 {
    [flip(wi), wi]
        .into_iter()
        .filter_map(|w| b.reflection_pdf(wo, w))
        .map(|(pdf, cos_om)| (1.0 - b.glass_s * fresnel::dielectric(cos_om, at.eta_rel)) * pdf)
        .sum()
}

/// Samples the wall's lobe; `uc` chooses reflection or transmission.
pub(super) fn sample(b: &Bsdf, wo: Vec3, uc: f32, u: Vec2, at: &AtWo) -> Option<BsdfSample> {
    let p_glass = at.p[2];
    if b.glass_smooth {
        let (pr, f_rgb) = b.smooth_fresnel(wo, at);
        if uc < pr {
            return Some(b.smooth_reflection(wo, f_rgb, pr, at));
        }
        let t = 1.0 - pr;
        return Some(BsdfSample {
            wi: -wo,
            f: b.w_glass * (Vec3::ONE - b.glass_s * f_rgb) * b.base / wo.z,
            pdf: p_glass * t,
            delta: true,
        });
    }
    let wm = b.ggx.sample_visible_normal(wo, u);
    let fr = fresnel::dielectric(wo.dot(wm).clamp(0.0, 1.0), at.eta_rel);
    let wr = microfacet::reflect(wo, wm);
    let above = if wr.z < 0.0 { flip(wr) } else { wr };
    let wi = if uc < b.glass_s * fr {
        above
    } else {
        flip(above)
    };
    b.continuous_sample(wo, wi, at)
}
