//! TESSERA_materials_metamaterial: a smooth interface into a medium of negative refractive
//! index (Veselago 1968). Light refracts to the same side of the normal it came from
//! (Snell's law with `n < 0`: the tangential part of the direction keeps its sign), and
//! the Fresnel terms follow from `|n|` and the medium's impedance `Z` relative to the
//! outside, for each polarisation:
//!
//! ```text
//! r_s = (Z cos θi − cos θt) / (Z cos θi + cos θt)      r_p = (cos θi − Z cos θt) / (cos θi + Z cos θt)
//! ```
//!
//! with `sin θt = sin θi / |n|` (an ordinary dielectric has `Z = 1/n`, which gives the
//! usual equations). An impedance-matched medium of `n = −1` reflects nothing at any
//! angle: Pendry's perfect lens. Radiance crossing into it is scaled by `1/n²`, as for
//! any medium. The interface is always smooth: the extension has no roughness.

use glam::Vec3;

use super::{AtWo, Bsdf, BsdfSample, COS_EPS};

/// The medium's optics, as the material gives them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Metamaterial {
    /// `|n|`, clamped to [`MIN_INDEX`, `IOR_MAX`].
    pub index: f32,
    /// Impedance relative to the outside, clamped likewise.
    pub impedance: f32,
}

/// Smallest `|n|` and impedance accepted: below, the medium's optics leave f32.
pub(crate) const MIN_INDEX: f32 = 1e-2;

/// Unpolarised reflectance from `wo`'s side at `cos_i` into a medium of relative index
/// `n` and impedance `z` (both as seen from `wo`'s side), and the cosine of the refracted
/// direction; `None` for the cosine under total internal reflection.
pub(crate) fn fresnel(cos_i: f32, n: f32, z: f32) -> (f32, Option<f32>) {
    let sin_t2 = (1.0 - cos_i * cos_i).max(0.0) / (n * n);
    if sin_t2 >= 1.0 {
        return (1.0, None);
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let rs = (z * cos_i - cos_t) / (z * cos_i + cos_t);
    let rp = (cos_i - z * cos_t) / (cos_i + z * cos_t);
    (0.5 * (rs * rs + rp * rp), Some(cos_t))
}

/// Samples the interface for `wo.z > 0`; `uc` chooses reflection or refraction.
pub(super) fn sample(
    b: &Bsdf,
    m: &Metamaterial,
    wo: Vec3,
    uc: f32,
    at: &AtWo,
) -> Option<BsdfSample> {
    let p_glass = at.p[2];
    // Relative to `wo`'s side: from inside, the outside is the denser medium.
    let (n, z) = if at.inside {
        (1.0 / m.index, 1.0 / m.impedance)
    } else {
        (m.index, m.impedance)
    };
    let (r, cos_t) = fresnel(wo.z, n, z);
    let pr = b.glass_s * r;
    if uc < pr {
        return Some(b.smooth_reflection(wo, Vec3::splat(r), pr, at));
    }
    // Under total internal reflection, the 1 − specular left over is absorbed.
    let cos_t = cos_t.filter(|c| *c > COS_EPS)?;
    let t = 1.0 - pr;
    Some(BsdfSample {
        // The same side of the normal as `wo`: the tangential part keeps its sign.
        wi: Vec3::new(wo.x / n, wo.y / n, -cos_t),
        f: b.w_glass * t * b.base / (cos_t * n * n),
        pdf: p_glass * t,
        delta: true,
    })
}
