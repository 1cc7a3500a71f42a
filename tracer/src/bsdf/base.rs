//! The base's lobes (the metal, the specular layer over the diffuse base, the refractive
//! interface; the layers over them aside): sampled, evaluated and their densities, in the
//! frame where `wo.z > 0`. A diffuse reflector's f and pdf inline where they are asked
//! for; every other BSDF's out of line.

use glam::{Vec2, Vec3, Vec3A};
use std::f32::consts::FRAC_1_PI;

use super::{flip, fresnel, microfacet, thin, AtWo, Bsdf, BsdfSample, COS_EPS};
use crate::math;

impl Bsdf {
    /// A sample of the base's lobes in the frame where `wo.z > 0` (the layers aside).
    #[inline(always)]
    pub(super) fn sample_base(
        &self,
        wo: Vec3,
        at: &AtWo,
        u_lobe: f32,
        u: Vec2,
    ) -> Option<BsdfSample> {
        // Choose a lobe; reuse the position of u_lobe within it for the reflect/refract
        // choice of the dielectric interface.
        let [p_ggx, p_diff, p_glass] = at.p;
        if u_lobe < p_ggx {
            self.sample_ggx(wo, u, at)
        } else if u_lobe < p_ggx + p_diff {
            let wi = microfacet::sample_cosine_hemisphere(u);
            // Diffuse transmission: the end of the lobe's share goes to the other side.
            let through = self.p_dt > 0.0 && (u_lobe - p_ggx) / p_diff >= 1.0 - self.p_dt;
            self.continuous_sample(wo, if through { flip(wi) } else { wi }, at)
        } else if p_glass > 0.0 {
            let uc = ((u_lobe - p_ggx - p_diff) / p_glass).clamp(0.0, 1.0);
            self.sample_glass(wo, uc, u, at)
        } else {
            None
        }
    }

    /// The diffuse lobe's f towards `wi`, reflected or transmitted.
    #[inline(always)]
    pub(super) fn diffuse_f(&self, wi: Vec3, at: &AtWo) -> Vec3 {
        let colour = if wi.z > 0.0 {
            self.diffuse_r
        } else {
            self.diffuse_t
        };
        self.w_plastic * at.diffuse_w * FRAC_1_PI * colour
    }

    /// The density of the diffuse lobe's samples at `wi`, reflected or transmitted.
    #[inline(always)]
    pub(super) fn diffuse_pdf(&self, wi: Vec3, at: &AtWo) -> f32 {
        let p_diff = at.p[1];
        if wi.z > 0.0 {
            p_diff * (1.0 - self.p_dt) * wi.z * FRAC_1_PI
        } else {
            p_diff * self.p_dt * -wi.z * FRAC_1_PI
        }
    }

    /// f for `wo.z > 0` (both directions already off the tangent plane). A diffuse
    /// reflector's, the commonest, inline where it is called; any other's out of line.
    #[inline(always)]
    pub(super) fn eval_local(&self, wo: Vec3, wi: Vec3, at: &AtWo) -> Vec3 {
        if self.diffuse_only {
            return self.diffuse_f(wi, at);
        }
        self.eval_general(wo, wi, at).into()
    }

    /// [`Bsdf::eval_local`] for any BSDF, out of line. Returned in memory as a `Vec3A`:
    /// one store that the caller's loads are forwarded from. (A `Vec3` is three stores,
    /// which made the inline diffuse value sharing its slot three stores too, and every
    /// wider load copying it wait for them to reach the cache.)
    #[inline(never)]
    pub(super) fn eval_general(&self, wo: Vec3, wi: Vec3, at: &AtWo) -> Vec3A {
        self.eval_any(wo, wi, at).into()
    }

    /// The body of [`Bsdf::eval_general`].
    #[inline(always)]
    fn eval_any(&self, wo: Vec3, wi: Vec3, at: &AtWo) -> Vec3 {
        let (mu_o, mu_i) = (wo.z, wi.z);
        if mu_i > 0.0 {
            let mut f = self.diffuse_f(wi, at);
            // (`smooth` implies `glass_smooth`: all microfacet lobes are delta together.)
            if self.microfacet {
                let wm = math::normalize_or(wo + wi, Vec3::Z);
                let cos_om = wo.dot(wm).clamp(0.0, 1.0);
                let lobe = self.ggx.d(wm) * self.ggx.g2(wo, wi) / (4.0 * mu_o * mu_i);
                let mut fresnel = self.reflection_fresnel(cos_om, at);
                if self.w_glass > 0.0 && !self.glass_smooth {
                    let fr = fresnel::dielectric(cos_om, at.eta_rel);
                    fresnel += self.w_glass
                        * self.glass_fresnel(fr, cos_om, at)
                        * self.glass_tint
                        * at.thin_comp;
                    f += self.w_glass * at.glass_ms * at.glass_ms_r * FRAC_1_PI * self.ms_tint();
                }
                f += lobe * fresnel;
            }
            f
        } else {
            let diffuse = self.diffuse_f(wi, at);
            if self.w_glass == 0.0 || self.glass_smooth {
                return diffuse;
            }
            if self.thin {
                return diffuse + thin::eval_transmission(self, wo, wi, at);
            }
            let radiance_scale = 1.0 / (at.eta_rel * at.eta_rel);
            let mut ft = Vec3::splat(at.glass_ms * (1.0 - at.glass_ms_r) * FRAC_1_PI);
            if let Some((wm, cos_om, cos_im, denom)) =
                Self::refraction_half_vector(wo, wi, at.eta_rel)
            {
                let fr = fresnel::dielectric(cos_om, at.eta_rel);
                let t = Vec3::ONE - self.glass_s * self.glass_fresnel(fr, cos_om, at);
                ft += t
                    * self.ggx.d(wm)
                    * self.ggx.g2(wo, wi)
                    * (cos_im.abs() * cos_om / (mu_o * -mu_i * denom));
            }
            diffuse + self.w_glass * ft * radiance_scale * self.base
        }
    }

    /// The weighted Fresnel terms of the metal and the specular layer at `cos` (between
    /// `wo` and the microfacet normal), with their compensation and the film over them.
    #[inline(always)]
    pub(super) fn reflection_fresnel(&self, cos: f32, at: &AtWo) -> Vec3 {
        let mut metal = fresnel::schlick(self.base, cos);
        let mut spec = fresnel::schlick(self.f0_spec, cos);
        if let Some(film) = &self.film {
            metal = film.mix(metal, cos, self.base);
            spec = film.mix(spec, cos, self.f0_spec);
        }
        self.w_metal * metal * at.metal_comp + self.w_plastic * self.spec * spec * at.spec_comp
    }

    /// Density of reaching `w` (either side) by reflecting `wo` about a sampled visible
    /// normal, D_wo(wm) / (4 wo·wm), with `wo·wm`; `None` where no visible normal does.
    pub(super) fn reflection_pdf(&self, wo: Vec3, w: Vec3) -> Option<(f32, f32)> {
        let wm = math::try_normalize(wo + w)?;
        let cos_om = wo.dot(wm);
        if wm.z <= 0.0 || cos_om <= 0.0 {
            return None;
        }
        let pdf = self.ggx.g1(wo) * self.ggx.d(wm) / (4.0 * wo.z);
        Some((pdf, cos_om))
    }

    /// pdf for `wo.z > 0`: the lobe mixture over the non-delta lobes. A sampled reflection
    /// that points below the horizon, or a refraction that points above it, is mirrored
    /// through the tangent plane (folded) instead of ending the path: every microfacet
    /// sample then carries energy, which keeps path weights near the albedo where light is
    /// trapped (rough glass of high IOR: about 200 bounces by total internal reflection,
    /// and the lost samples made the weights of the others heavy-tailed). A direction is
    /// thus reached two ways, and its density is the sum over both.
    #[inline(always)]
    pub(super) fn pdf_local(&self, wo: Vec3, wi: Vec3, at: &AtWo) -> f32 {
        if self.diffuse_only {
            return self.diffuse_pdf(wi, at);
        }
        self.pdf_general(wo, wi, at)
    }

    /// [`Bsdf::pdf_local`] for any BSDF.
    #[inline(never)]
    pub(super) fn pdf_general(&self, wo: Vec3, wi: Vec3, at: &AtWo) -> f32 {
        let [p_ggx, _, p_glass] = at.p;
        let glass_rough = p_glass > 0.0 && !self.glass_smooth;
        if wi.z > 0.0 {
            let mut pdf = self.diffuse_pdf(wi, at);
            if self.microfacet {
                // Reflections reach `wi` directly, or folded from below the horizon.
                let mut refl = 0.0;
                let mut glass_refl = 0.0;
                for w in [wi, flip(wi)] {
                    let Some((pdf_refl, cos_om)) = self.reflection_pdf(wo, w) else {
                        continue;
                    };
                    refl += pdf_refl;
                    if glass_rough {
                        glass_refl += fresnel::dielectric(cos_om, at.eta_rel) * pdf_refl;
                    }
                }
                pdf += p_ggx * refl;
                if glass_rough && self.thin {
                    pdf += p_glass * self.glass_s * glass_refl;
                } else if glass_rough {
                    pdf += p_glass
                        * ((1.0 - at.glass_ms) * self.glass_s * glass_refl
                            + at.glass_ms * at.glass_ms_r * wi.z * FRAC_1_PI);
                }
            }
            pdf
        } else {
            let diffuse = self.diffuse_pdf(wi, at);
            if !glass_rough {
                return diffuse;
            }
            if self.thin {
                return diffuse + p_glass * thin::pdf_transmission(self, wo, wi, at);
            }
            let mut pdf = at.glass_ms * (1.0 - at.glass_ms_r) * -wi.z * FRAC_1_PI;
            // Refractions reach `wi` directly, or folded from above the horizon.
            for w in [wi, flip(wi)] {
                if let Some((wm, cos_om, cos_im, denom)) =
                    Self::refraction_half_vector(wo, w, at.eta_rel)
                {
                    let fr = fresnel::dielectric(cos_om, at.eta_rel);
                    let t = 1.0 - self.glass_s * fr;
                    let dwm_dwi = cos_im.abs() / denom;
                    pdf += (1.0 - at.glass_ms) * t * self.ggx.pdf_visible_normal(wo, wm) * dwm_dwi;
                }
            }
            diffuse + p_glass * pdf
        }
    }

    /// A sample of a non-delta lobe: its value and pdf are those of the whole mixture.
    pub(super) fn continuous_sample(&self, wo: Vec3, wi: Vec3, at: &AtWo) -> Option<BsdfSample> {
        if !math::finite(wi) || wi.z.abs() < COS_EPS {
            return None;
        }
        let pdf = self.pdf_local(wo, wi, at);
        if !math::positive_finite(pdf) {
            return None;
        }
        Some(BsdfSample {
            wi,
            f: self.eval_local(wo, wi, at),
            pdf,
            delta: false,
        })
    }

    /// Samples the GGX reflection lobe shared by the metal and the specular layer.
    pub(super) fn sample_ggx(&self, wo: Vec3, u: Vec2, at: &AtWo) -> Option<BsdfSample> {
        if self.smooth {
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            let f = self.reflection_fresnel(wo.z, at);
            return Some(BsdfSample {
                wi,
                f: f / wo.z,
                pdf: at.p[0],
                delta: true,
            });
        }
        let wm = self.ggx.sample_visible_normal(wo, u);
        // A reflection below the horizon is folded back above it (see `pdf_local`).
        let wi = microfacet::reflect(wo, wm);
        self.continuous_sample(wo, if wi.z < 0.0 { flip(wi) } else { wi }, at)
    }
}
