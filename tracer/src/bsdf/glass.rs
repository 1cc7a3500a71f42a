//! The refractive interface into a solid (KHR_materials_transmission with
//! KHR_materials_volume): smooth or rough (Walter et al. 2007) with the exact Fresnel
//! term, and its multiple-scattering lobe; the thin wall and the metamaterial take over
//! from here where the material is one of those.

use glam::{Vec2, Vec3};

use super::{flip, fresnel, metamaterial, microfacet, thin, AtWo, Bsdf, BsdfSample, COS_EPS};

impl Bsdf {
    /// A smooth interface's reflection at `wo`: its probability `s · F` (by the plain
    /// Fresnel term) and its Fresnel term per channel (the film's, where one lies over
    /// the interface).
    pub(super) fn smooth_fresnel(&self, wo: Vec3, at: &AtWo) -> (f32, Vec3) {
        let fr = if self.eta == 1.0 {
            0.0
        } else {
            fresnel::dielectric(wo.z, at.eta_rel)
        };
        (self.glass_s * fr, self.glass_fresnel(fr, wo.z, at))
    }

    /// The mirror reflection of a smooth interface, chosen with probability `pr` within
    /// the interface's share of the samples, with its Fresnel term `fresnel` per channel.
    pub(super) fn smooth_reflection(
        &self,
        wo: Vec3,
        fresnel: Vec3,
        pr: f32,
        at: &AtWo,
    ) -> BsdfSample {
        BsdfSample {
            wi: Vec3::new(-wo.x, -wo.y, wo.z),
            f: self.w_glass * fresnel * self.glass_tint / wo.z,
            pdf: at.p[2] * pr,
            delta: true,
        }
    }

    /// The refractive interface's Fresnel reflectance `fr` at `cos`, with the film over it
    /// where `wo` sees one (its F0 the specular layer's, as the extension's dielectric).
    #[inline(always)]
    pub(super) fn glass_fresnel(&self, fr: f32, cos: f32, at: &AtWo) -> Vec3 {
        match &self.film {
            Some(film) if at.film_glass => film.mix(Vec3::splat(fr), cos, self.f0_spec),
            _ => Vec3::splat(fr),
        }
    }

    /// Colour of the reflected multiple-scattering energy of the refractive interface:
    /// the reflection tint normalised to a largest channel of 1.
    pub(super) fn ms_tint(&self) -> Vec3 {
        if self.glass_s > 0.0 {
            self.glass_tint / self.glass_s
        } else {
            Vec3::ONE
        }
    }

    /// The generalised half vector of a refraction pair (`wo.z > 0 > wi.z`), oriented to
    /// +Z, with `wo·wm`, `wi·wm` and Walter's `(wi·wm + wo·wm/η)²`. `None` when the pair
    /// cannot come from a refraction through a front-facing microfacet.
    pub(super) fn refraction_half_vector(
        wo: Vec3,
        wi: Vec3,
        eta_rel: f32,
    ) -> Option<(Vec3, f32, f32, f32)> {
        let h = wo + wi * eta_rel;
        let len2 = h.length_squared();
        if !(len2 > 1e-12) {
            return None;
        }
        let mut wm = h / len2.sqrt();
        if wm.z < 0.0 {
            wm = -wm;
        }
        let cos_om = wo.dot(wm);
        let cos_im = wi.dot(wm);
        if cos_om <= 0.0 || cos_im >= 0.0 {
            return None;
        }
        let denom = (cos_im + cos_om / eta_rel).powi(2);
        if !(denom > 0.0) {
            return None;
        }
        Some((wm, cos_om, cos_im, denom))
    }

    /// Samples the dielectric interface: a microfacet normal (or the macro normal when
    /// smooth), then reflection with probability `glass_s · F`, else refraction.
    pub(super) fn sample_glass(&self, wo: Vec3, uc: f32, u: Vec2, at: &AtWo) -> Option<BsdfSample> {
        let p_glass = at.p[2];
        if self.thin {
            return thin::sample(self, wo, uc, u, at);
        }
        if let Some(m) = &self.meta {
            return metamaterial::sample(self, m, wo, uc, at);
        }
        if self.glass_smooth {
            let (pr, f_rgb) = self.smooth_fresnel(wo, at);
            if uc < pr {
                return Some(self.smooth_reflection(wo, f_rgb, pr, at));
            }
            // Total internal reflection leaves no refracted direction: with glass_s < 1
            // the remaining 1 − glass_s is absorbed.
            let wi = microfacet::refract(wo, Vec3::Z, at.eta_rel)?;
            if wi.z > -COS_EPS {
                return None;
            }
            let t = 1.0 - pr;
            return Some(BsdfSample {
                wi,
                f: self.w_glass * (Vec3::ONE - self.glass_s * f_rgb) * self.base
                    / (-wi.z * at.eta_rel * at.eta_rel),
                pdf: p_glass * t,
                delta: true,
            });
        }
        // Multiple-scattering lobe: cosine-distributed on either side.
        if uc < at.glass_ms {
            let wi = microfacet::sample_cosine_hemisphere(u);
            let reflect = uc < at.glass_ms * at.glass_ms_r;
            return self.continuous_sample(wo, if reflect { wi } else { flip(wi) }, at);
        }
        let uc = ((uc - at.glass_ms) / (1.0 - at.glass_ms)).clamp(0.0, 1.0);
        let wm = self.ggx.sample_visible_normal(wo, u);
        let fr = fresnel::dielectric(wo.dot(wm).clamp(0.0, 1.0), at.eta_rel);
        // A reflection below the horizon, or a refraction above it, is folded to its own
        // side (see `pdf_local`) rather than ending the path.
        let wi = if uc < self.glass_s * fr {
            let wi = microfacet::reflect(wo, wm);
            if wi.z < 0.0 {
                flip(wi)
            } else {
                wi
            }
        } else {
            let wi = microfacet::refract(wo, wm, at.eta_rel)?;
            if wi.z > 0.0 {
                flip(wi)
            } else {
                wi
            }
        };
        self.continuous_sample(wo, wi, at)
    }
}
