//! The KHR_materials_clearcoat lobe: a GGX reflection of its own roughness with the
//! Fresnel of an IOR 1.5 coat (Schlick, F0 = 0.04, as the extension defines it), with
//! Turquin's multiple-scattering compensation like the base's specular layer. It works in
//! the coat's own frame (its normal can differ from the base's), with `wo` above.

use glam::{Vec2, Vec3};

use super::{compensated_albedo, fresnel, microfacet, tables, ALPHA_MIN};
use crate::math;

/// F0 of the coat: an IOR 1.5 dielectric, ((1.5 − 1)/(1.5 + 1))².
pub(crate) const F0: f32 = 0.04;

/// The coat at one shading point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Coat {
    /// clearcoatFactor (× texture), in (0, 1].
    pub weight: f32,
    /// Its GGX distribution, α = clearcoatRoughness².
    ggx: microfacet::Ggx,
    /// Whether the coat is a mirror (α below [`ALPHA_MIN`]): a delta lobe.
    pub smooth: bool,
    /// Conductor-table position for α.
    cond: tables::ConductorCoord,
}

/// What the coat's terms are for one `wo`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct CoatAt {
    /// The coat's albedo at `wo`, weight included: the energy it takes from what is under it.
    pub albedo: f32,
    /// Turquin's factor `1 + F0 (1 − E1)/E1`.
    comp: f32,
}

impl Coat {
    /// The coat for a factor and a perceptual roughness (both in [0, 1]).
    pub(crate) fn new(weight: f32, roughness: f32) -> Self {
        let alpha = roughness * roughness;
        let smooth = alpha < ALPHA_MIN;
        Self {
            weight,
            ggx: microfacet::Ggx::isotropic(alpha),
            smooth,
            cond: if smooth {
                Default::default()
            } else {
                tables::ConductorTable::coord(alpha)
            },
        }
    }

    /// Its albedo and compensation at `wo` (coat frame, `wo.z > 0`).
    pub(crate) fn at(&self, wo: Vec3) -> CoatAt {
        if self.smooth {
            return CoatAt {
                albedo: self.weight * fresnel::schlick_scalar(F0, wo.z),
                comp: 1.0,
            };
        }
        let [e1, ew] = tables::conductor().lookup(wo.z, self.cond);
        let e1 = e1.clamp(0.05, 1.0);
        let ew = ew.clamp(0.0, e1);
        let k = (1.0 - e1) / e1;
        CoatAt {
            albedo: (self.weight * compensated_albedo(F0, e1, ew, k)).clamp(0.0, 1.0),
            comp: 1.0 + F0 * k,
        }
    }

    /// f(wo, wi) of the rough coat, without the cosine; zero for a smooth one or a
    /// direction below the coat.
    pub(crate) fn eval(&self, wo: Vec3, wi: Vec3, at: &CoatAt) -> f32 {
        if self.smooth || wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let wm = math::normalize_or(wo + wi, Vec3::Z);
        let cos_om = wo.dot(wm).clamp(0.0, 1.0);
        self.weight
            * self.ggx.d(wm)
            * self.ggx.g2(wo, wi)
            * fresnel::schlick_scalar(F0, cos_om)
            * at.comp
            / (4.0 * wo.z * wi.z)
    }

    /// The density with which [`Coat::sample`] returns `wi` (zero for a smooth coat).
    pub(crate) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.smooth || wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let Some(wm) = math::try_normalize(wo + wi) else {
            return 0.0;
        };
        if wo.dot(wm) <= 0.0 {
            return 0.0;
        }
        self.ggx.g1(wo) * self.ggx.d(wm) / (4.0 * wo.z)
    }

    /// A direction off the coat: the mirror direction of a smooth coat, else the
    /// reflection about a visible normal; `None` below the coat.
    pub(crate) fn sample(&self, wo: Vec3, u: Vec2) -> Option<Vec3> {
        let wi = if self.smooth {
            Vec3::new(-wo.x, -wo.y, wo.z)
        } else {
            microfacet::reflect(wo, self.ggx.sample_visible_normal(wo, u))
        };
        (wi.z > 0.0).then_some(wi)
    }

    /// The weight `f · cos / pdf` of a smooth coat's mirror direction, per unit
    /// probability of choosing it.
    pub(crate) fn mirror_weight(&self, wo: Vec3) -> f32 {
        self.weight * fresnel::schlick_scalar(F0, wo.z)
    }
}
