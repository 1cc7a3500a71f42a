//! The BSDF seen from one outgoing direction: what a bounce evaluates for its light
//! sample and samples for its continuation, with the work that depends on `wo` alone
//! (the compensation factors, the albedo scaling, the lobe probabilities) done once.

use glam::{Vec2, Vec3};

use super::{anisotropy, flip, fresnel, sane, tables, Bsdf, BsdfSample, COS_EPS, LOBE_FLOOR};
use super::{compensated_albedo, layers, mean};
use crate::math;

/// Everything about the BSDF that depends on `wo` alone, in the frame where `wo.z > 0`.
#[derive(Debug, PartialEq)]
pub(super) struct AtWo {
    /// Relative index across the interface, transmitted side over `wo`'s side.
    pub(super) eta_rel: f32,
    /// Turquin compensation factor of the metal, per channel.
    pub(super) metal_comp: Vec3,
    /// Turquin compensation factor of the specular layer, per channel.
    pub(super) spec_comp: Vec3,
    /// Diffuse weight `1 − E_spec(μo)` (albedo scaling).
    pub(super) diffuse_w: f32,
    /// Energy of the refractive interface's multiple-scattering lobe, `1 − E(μo)`, which
    /// is also the probability of sampling it within the interface.
    pub(super) glass_ms: f32,
    /// Fraction of `glass_ms` that is reflected (the rest is transmitted).
    pub(super) glass_ms_r: f32,
    /// Turquin factor of a rough thin wall, `1 / E1(μo)` (see `bsdf/thin.rs`).
    pub(super) thin_comp: f32,
    /// Whether the iridescent film lies over the refractive interface as `wo` meets it
    /// (from outside, or from either side of a thin wall).
    pub(super) film_glass: bool,
    /// Whether `wo` lies inside the transmitting object.
    pub(super) inside: bool,
    /// Lobe-selection probabilities: GGX reflection (metal and specular layer),
    /// diffuse, refractive interface. They sum to 1 (or are all 0: no lobe).
    pub(super) p: [f32; 3],
}
/// A BSDF seen from one outgoing direction ([`Bsdf::at`]): what a bounce evaluates for
/// its light sample and samples for its continuation, sharing the work that depends on
/// `wo`.
pub struct BsdfAt<'a> {
    bsdf: &'a Bsdf,
    /// `wo` in the frame where `wo.z > 0`.
    wo: Vec3,
    /// Whether `wo` lies below the surface (the frame is mirrored).
    inside: bool,
    at: AtWo,
    /// The layers' terms at `wo`, where the BSDF has layers and `wo` sees them.
    layers: Option<layers::LayersAt>,
}
impl BsdfAt<'_> {
    /// `wi` in the frame where `wo.z > 0`; `None` for a non-finite or grazing `wi`.
    #[inline(always)]
    fn incident(&self, wi: Vec3) -> Option<Vec3> {
        if !math::finite(wi) || wi.z.abs() < COS_EPS {
            return None;
        }
        Some(if self.inside { flip(wi) } else { wi })
    }

    /// f(wo, wi) without the cosine; zero for delta lobes.
    #[inline(always)]
    pub fn eval(&self, wi: Vec3) -> Vec3 {
        self.incident(wi)
            .map_or(Vec3::ZERO, |wi| self.eval_local(wi))
    }

    /// The solid-angle pdf with which [`BsdfAt::sample`] returns `wi`.
    #[inline(always)]
    pub fn pdf(&self, wi: Vec3) -> f32 {
        self.incident(wi).map_or(0.0, |wi| self.pdf_local(wi))
    }

    /// `eval(wi)` and `pdf(wi)` together.
    #[inline(always)]
    pub fn eval_and_pdf(&self, wi: Vec3) -> (Vec3, f32) {
        self.incident(wi).map_or((Vec3::ZERO, 0.0), |wi| {
            (self.eval_local(wi), self.pdf_local(wi))
        })
    }

    #[inline(always)]
    fn eval_local(&self, wi: Vec3) -> Vec3 {
        match &self.layers {
            None => self.bsdf.eval_local(self.wo, wi, &self.at),
            Some(l) => self.bsdf.layered_eval(self.wo, wi, &self.at, l).into(),
        }
    }

    #[inline(always)]
    fn pdf_local(&self, wi: Vec3) -> f32 {
        match &self.layers {
            None => self.bsdf.pdf_local(self.wo, wi, &self.at),
            Some(l) => self.bsdf.layered_pdf(self.wo, wi, &self.at, l),
        }
    }

    /// As [`Bsdf::sample`].
    #[inline(always)]
    pub fn sample(&self, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let u_lobe = sane(u_lobe, 0.0, 1.0, 0.0);
        let u = Vec2::new(sane(u.x, 0.0, 1.0, 0.0), sane(u.y, 0.0, 1.0, 0.0));
        let s = match &self.layers {
            None => self.bsdf.sample_base(self.wo, &self.at, u_lobe, u),
            Some(l) => self.bsdf.layered_sample(self.wo, &self.at, l, u_lobe, u),
        }?;
        Some(BsdfSample {
            wi: if self.inside { flip(s.wi) } else { s.wi },
            ..s
        })
    }
}

impl Bsdf {
    /// The BSDF seen from `wo`, its work that depends on `wo` alone done once for the
    /// light sample and the continuation a bounce takes; `None` for a non-finite or
    /// grazing `wo`, from which nothing scatters.
    #[inline(always)]
    pub fn at(&self, wo: Vec3) -> Option<BsdfAt<'_>> {
        self.at_coated(wo, None)
    }

    /// [`Bsdf::at`] with the clear coat's own normal `coat_normal` (unit, in the same
    /// local frame; KHR_materials_clearcoat's normal map, or the unmapped normal where
    /// the base's normal is mapped); `None` puts the coat on the base's normal.
    #[inline(always)]
    pub fn at_coated(&self, wo: Vec3, coat_normal: Option<Vec3>) -> Option<BsdfAt<'_>> {
        if !math::finite(wo) || wo.z.abs() < COS_EPS {
            return None;
        }
        let inside = wo.z < 0.0;
        let wo = if inside { flip(wo) } else { wo };
        let view = |at: AtWo| {
            // Light inside a refracting object meets the bare interface; an opaque surface
            // or a thin wall is two-sided, its layers mirrored with it.
            let layers = if self.layers.is_none() || (inside && self.w_glass > 0.0 && !self.thin) {
                None
            } else {
                let coat_normal = coat_normal.map(|n| if inside { flip(n) } else { n });
                self.layers_at(wo, coat_normal, at.p.iter().sum::<f32>() > 0.0)
            };
            Some(BsdfAt {
                bsdf: self,
                wo,
                inside,
                at,
                layers,
            })
        };
        // The view made in each branch, not from one `AtWo` merged from both: that was
        // written to memory field by field and copied into the view in wide loads, which
        // the CPU cannot forward from those stores (a stall at every bounce).
        match self.lambertian {
            Some(p) => view(self.lambertian_at(p, inside)),
            None => view(self.at_wo_general(wo, inside)),
        }
    }

    /// The `wo`-dependent factors of the commonest surface, a Lambertian one with lobe
    /// probabilities `p`: nothing depends on `wo`, and the general case
    /// ([`Bsdf::at_wo_general`]) comes to the same numbers (a test checks).
    #[inline(always)]
    pub(super) fn lambertian_at(&self, p: [f32; 3], inside: bool) -> AtWo {
        AtWo {
            eta_rel: if inside { 1.0 / self.eta } else { self.eta },
            thin_comp: 1.0,
            film_glass: false,
            inside,
            metal_comp: Vec3::ONE,
            spec_comp: Vec3::ONE,
            diffuse_w: 1.0,
            glass_ms: 0.0,
            glass_ms_r: 0.0,
            p,
        }
    }

    /// Whether the BSDF is a diffuse lobe alone: no metal, no specular layer, no glass.
    pub(super) fn is_lambertian(&self) -> bool {
        self.lambertian.is_some()
    }

    /// A Lambertian BSDF's lobe probabilities (see [`AtWo::p`]), the same from every
    /// `wo`; `None` for any other BSDF. Set once, when the BSDF is made.
    pub(super) fn lambertian_lobes(&self) -> Option<[f32; 3]> {
        if self.w_metal != 0.0 || self.w_plastic * self.spec != 0.0 || self.w_glass != 0.0 {
            return None;
        }
        let diffuse = self.w_plastic
            * self
                .diffuse_r
                .max_element()
                .max(self.diffuse_t.max_element())
            > 0.0;
        Some([0.0, if diffuse { 1.0 } else { 0.0 }, 0.0])
    }

    /// The `wo`-dependent factors (compensation, albedo scaling, lobe probabilities) of
    /// any BSDF.
    pub(super) fn at_wo_general(&self, wo: Vec3, inside: bool) -> AtWo {
        let mu_o = wo.z;
        // The tables hold isotropic lobes: an anisotropic one has its own albedos, and
        // the dielectric table is looked up at the α of the isotropic lobe with its
        // albedo at `wo` (see `bsdf/anisotropy.rs`).
        let anisotropic = self
            .ggx
            .is_anisotropic()
            .then(|| anisotropy::table().lookup(self.ggx, wo));
        // `[E1, Ew]` of the GGX reflection lobe at `wo`.
        let lobe_albedo = || match (anisotropic, self.curve) {
            (Some([e1, ew, _]), _) => [e1, ew],
            (None, Some(c)) => c.conductor(mu_o),
            (None, None) => tables::conductor().lookup(mu_o, self.cond),
        };
        // A thin wall has air on both sides.
        let eta_rel = if inside && !self.thin {
            1.0 / self.eta
        } else {
            self.eta
        };
        let f0_max = self.f0_spec.max_element();
        let f0_mean = mean(self.f0_spec);
        let c_mean = mean(self.base);

        // Metal and specular layer: Turquin factor and albedo estimates.
        let (metal_comp, spec_comp, e_metal, e_spec_max, e_spec_mean) =
            if self.w_metal == 0.0 && self.w_plastic * self.spec == 0.0 {
                // No GGX reflection lobe: nothing to compensate, and no energy taken.
                (Vec3::ONE, Vec3::ONE, 0.0, 0.0, 0.0)
            } else if self.smooth {
                (
                    Vec3::ONE,
                    Vec3::ONE,
                    fresnel::schlick_scalar(c_mean, mu_o),
                    self.spec * fresnel::schlick_scalar(f0_max, mu_o),
                    self.spec * fresnel::schlick_scalar(f0_mean, mu_o),
                )
            } else {
                let [e1, ew] = lobe_albedo();
                let e1 = e1.clamp(0.05, 1.0);
                let ew = ew.clamp(0.0, e1);
                let k = (1.0 - e1) / e1;
                (
                    Vec3::ONE + self.base * k,
                    Vec3::ONE + self.f0_spec * k,
                    compensated_albedo(c_mean, e1, ew, k),
                    self.spec * compensated_albedo(f0_max, e1, ew, k),
                    self.spec * compensated_albedo(f0_mean, e1, ew, k),
                )
            };
        // Albedo scaling: the base gets what the specular layer leaves. Using the
        // largest F0 channel keeps every channel at or below 1 (as glTF's
        // `max_value(fr)` does).
        let e_spec_max = match &self.film {
            // The film changes the layer's Fresnel; its albedo follows by the ratio of the
            // two, at the view direction (exact for a smooth layer, whose albedo that is)
            // or, where larger, at the microfacet that sends the view to the normal (a
            // rough layer's facets lie between): the base gets no more than is left.
            Some(film) if e_spec_max > 0.0 => {
                let ratio = |cos: f32| {
                    let plain = fresnel::schlick(self.f0_spec, cos);
                    let filmed = film.mix(plain, cos, self.f0_spec);
                    filmed.max_element() / plain.max_element().max(1e-6)
                };
                let facet = if self.smooth {
                    mu_o
                } else {
                    (0.5 + 0.5 * mu_o).sqrt()
                };
                e_spec_max * ratio(mu_o).max(ratio(facet))
            }
            _ => e_spec_max,
        };
        let diffuse_w = (1.0 - e_spec_max).clamp(0.0, 1.0);

        // Refractive interface: the energy single scattering misses goes to a diffuse
        // multiple-scattering lobe, split between reflection and refraction as the
        // single-scattered energy is.
        let (glass_ms, glass_ms_r) = if self.w_glass > 0.0 && !self.glass_smooth && !self.thin {
            let [a, b, c] = match self.curve {
                Some(curve) => curve.dielectric(mu_o, inside),
                None => {
                    let coord = match anisotropic {
                        Some([_, _, alpha]) => {
                            tables::DielectricTable::coord(alpha, self.eta, inside)
                        }
                        None => self.diel[usize::from(inside)],
                    };
                    tables::dielectric().lookup(mu_o, coord)
                }
            };
            let reflected = self.glass_s * a;
            let single = reflected + b + (1.0 - self.glass_s) * c;
            let r = if single > 0.0 {
                (reflected / single).clamp(0.0, 1.0)
            } else {
                0.0
            };
            ((1.0 - single).clamp(0.0, 1.0), r)
        } else {
            (0.0, 0.0)
        };

        // Lobe selection in proportion to each lobe's albedo estimate at wo.
        let glass = if self.w_glass > 0.0 {
            let reflect_macro = self.glass_s * fresnel::dielectric(mu_o, eta_rel);
            self.w_glass * (reflect_macro + (1.0 - reflect_macro) * c_mean)
        } else {
            0.0
        };
        let mut e = [
            self.w_metal * e_metal + self.w_plastic * e_spec_mean,
            self.w_plastic * (mean(self.diffuse_r) + mean(self.diffuse_t)) * diffuse_w,
            glass,
        ];
        // A lobe that can carry energy keeps a floor, so that it is always sampled.
        let present = [
            self.w_metal + self.w_plastic * self.spec,
            self.w_plastic
                * self
                    .diffuse_r
                    .max_element()
                    .max(self.diffuse_t.max_element()),
            if self.glass_s > 0.0 || self.base.max_element() > 0.0 {
                self.w_glass
            } else {
                0.0
            },
        ];
        for (e, w) in e.iter_mut().zip(present) {
            *e = if w > 0.0 { e.max(LOBE_FLOOR * w) } else { 0.0 };
        }
        let total = e[0] + e[1] + e[2];
        let p = if total > 0.0 {
            e.map(|x| x / total)
        } else {
            [0.0; 3]
        };
        let thin_comp = if self.w_glass > 0.0 && self.thin && !self.glass_smooth {
            1.0 / lobe_albedo()[0].clamp(0.05, 1.0)
        } else {
            1.0
        };
        AtWo {
            eta_rel,
            thin_comp,
            film_glass: self.film.is_some() && self.w_glass > 0.0 && (!inside || self.thin),
            inside,
            metal_comp,
            spec_comp,
            diffuse_w,
            glass_ms,
            glass_ms_r,
            p,
        }
    }
}
