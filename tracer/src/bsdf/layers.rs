//! The layers glTF puts over the base BSDF: a sheen (KHR_materials_sheen) and, over that,
//! a clear coat (KHR_materials_clearcoat), as the extensions order them:
//!
//! ```text
//! f = f_coat + (1 − E_coat(μo)) · [ sheenColor · f_sheen + (1 − max(sheenColor) E_sheen(μo)) · f_base ]
//! ```
//!
//! Each layer takes from what lies under it the energy it reflects at `wo` (its
//! directional albedo: the coat's with its compensation, the sheen's by the table in
//! `sheen.rs`), so a white furnace stays at 1 where the base's does. For the sheen this
//! is the form of the scaling the extension allows "for performance" (the view
//! direction's albedo alone); its reciprocal form, `min` over both directions, loses
//! energy: 13% of a white sheen over a white diffuse base at normal incidence, measured.
//! The coat's follows its `fresnel_coat` at the view direction, with the coat's albedo in
//! place of Fresnel so that a rough coat conserves energy too. A unidirectional path
//! tracer needs no reciprocity: `wo` is always the camera's side. Under a refracting
//! base the layers apply from outside only: light inside the object meets the bare
//! interface.
//!
//! A bounce picks the coat, the sheen or the base in proportion to the energy each
//! returns at `wo`; a continuous sample then carries the value and density of the whole
//! mixture, as the base's lobes do among themselves.

use glam::{Vec2, Vec3, Vec3A};

use super::coat::{Coat, CoatAt};
use super::{mean, sheen, Bsdf, BsdfSample, COS_EPS, LOBE_FLOOR};
use crate::geometry::Frame;
use crate::math;

/// The sheen layer at one shading point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Sheen {
    /// sheenColor (× texture), each channel in [0, 1], not black.
    pub color: Vec3,
    /// Its largest channel.
    pub max: f32,
    /// The Charlie α (the sheen roughness, at least [`sheen::ALPHA_MIN`]).
    pub alpha: f32,
}

/// The layers over a base BSDF; at least one is present.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Layers {
    pub coat: Option<Coat>,
    pub sheen: Option<Sheen>,
}

impl Layers {
    /// The layers for these factors (clamped to their ranges), or `None` where neither
    /// the coat nor the sheen is there.
    pub(crate) fn new(
        clearcoat: f32,
        clearcoat_roughness: f32,
        sheen_color: Vec3,
        sheen_roughness: f32,
    ) -> Option<Self> {
        let coat = (clearcoat > 0.0).then(|| Coat::new(clearcoat.min(1.0), clearcoat_roughness));
        let sheen = (sheen_color.max_element() > 0.0).then(|| Sheen {
            color: sheen_color,
            max: sheen_color.max_element(),
            alpha: sheen_roughness.max(sheen::ALPHA_MIN),
        });
        (coat.is_some() || sheen.is_some()).then_some(Self { coat, sheen })
    }

    /// Whether they add nothing a continuous sample could find (a mirror coat alone).
    pub(crate) fn is_delta(&self) -> bool {
        self.sheen.is_none() && self.coat.is_none_or(|c| c.smooth)
    }
}

/// The layers seen from one `wo` (in the frame where `wo.z > 0`).
pub(crate) struct LayersAt {
    /// The coat's frame in the BSDF's local frame, where its normal differs from the base's.
    coat_frame: Option<Frame>,
    /// `wo` in the coat's frame.
    coat_wo: Vec3,
    /// The coat's terms at `wo`; `None` without a coat, or where `wo` lies behind the
    /// coat's normal (it reflects nothing towards it there).
    coat: Option<CoatAt>,
    /// `max(sheenColor) · E_sheen(μo)`: what the sheen takes from the base at `wo`.
    sheen_taken: f32,
    /// Probabilities of sampling the coat, the sheen and the base.
    p: [f32; 3],
}

impl LayersAt {
    /// `v` (BSDF frame) in the coat's frame.
    fn bsdf_to_coat(&self, v: Vec3) -> Vec3 {
        self.coat_frame.map_or(v, |f| f.to_local(v))
    }

    /// `v` (coat frame) in the BSDF's frame.
    fn coat_to_bsdf(&self, v: Vec3) -> Vec3 {
        self.coat_frame.map_or(v, |f| f.to_world(v))
    }
}

impl Bsdf {
    /// The layers' terms at `wo` (`wo.z > 0`), with the coat's normal `coat_normal` in
    /// the same frame (`None`: the base's), given whether the base has a lobe to sample
    /// (`base_present`: its lobe probabilities sum above 0); `None` without layers.
    // Out of line: the hot path of materials without layers stays as small as before.
    #[inline(never)]
    pub(super) fn layers_at(
        &self,
        wo: Vec3,
        coat_normal: Option<Vec3>,
        base_present: bool,
    ) -> Option<LayersAt> {
        let layers = self.layers.as_ref()?;
        let coat_frame = coat_normal
            .filter(|n| *n != Vec3::Z && n.is_finite() && n.z > 0.0)
            .map(Frame::from_normal);
        let coat_wo = coat_frame.map_or(wo, |f| f.to_local(wo));
        let coat = layers
            .coat
            .filter(|_| coat_wo.z > COS_EPS)
            .map(|c| c.at(coat_wo));
        let coat_e = coat.map_or(0.0, |c| c.albedo);
        let sheen_taken = layers.sheen.map_or(0.0, |s| {
            (s.max * sheen::albedo(wo.z, s.alpha)).clamp(0.0, 1.0)
        });
        // Energy each returns at wo, with a floor for the present ones, as among the
        // base's own lobes.
        let mut e = [
            coat_e,
            (1.0 - coat_e) * sheen_taken,
            (1.0 - coat_e) * (1.0 - sheen_taken) * mean(self.albedo()),
        ];
        let present = [
            layers
                .coat
                .filter(|_| coat.is_some())
                .map_or(0.0, |c| c.weight),
            layers.sheen.map_or(0.0, |s| s.max),
            if base_present { 1.0 } else { 0.0 },
        ];
        for (e, w) in e.iter_mut().zip(present) {
            *e = if w > 0.0 { e.max(LOBE_FLOOR * w) } else { 0.0 };
        }
        let total: f32 = e.iter().sum();
        let p = if total > 0.0 {
            e.map(|x| x / total)
        } else {
            [0.0; 3]
        };
        Some(LayersAt {
            coat_frame,
            coat_wo,
            coat,
            sheen_taken,
            p,
        })
    }

    /// The factor the layers leave on the base's value at `wo`.
    fn base_scale(&self, l: &LayersAt) -> f32 {
        (1.0 - l.coat.map_or(0.0, |c| c.albedo)) * (1.0 - l.sheen_taken)
    }

    /// f of the layered BSDF (`wo.z > 0`; `wi` off the tangent plane), as a `Vec3A` for
    /// the reason [`Bsdf::eval_general`] gives.
    // Out of line: the hot path of materials without layers stays as small as before.
    #[inline(never)]
    pub(super) fn layered_eval(&self, wo: Vec3, wi: Vec3, at: &super::AtWo, l: &LayersAt) -> Vec3A {
        let layers = self.layers.as_ref().expect("layered");
        let mut f = self.eval_local(wo, wi, at) * self.base_scale(l);
        if wi.z > 0.0 {
            let under_coat = 1.0 - l.coat.map_or(0.0, |c| c.albedo);
            if let Some(s) = &layers.sheen {
                f += under_coat * s.color * sheen::eval(wo, wi, s.alpha);
            }
        }
        if let (Some(coat), Some(coat_at)) = (&layers.coat, &l.coat) {
            f += Vec3::splat(self.coat_eval(coat, coat_at, wi, l));
        }
        f.into()
    }

    /// The coat's value at `wi`, reflecting into the upper side only. On its own normal
    /// the coat's cosine is its own: the value carries `cos_coat / cos`, so that
    /// `f · |cos|`, all a bounce uses, is the coat's `f · cos_coat` and the coat returns
    /// exactly its albedo, however its normal leans.
    fn coat_eval(&self, coat: &Coat, coat_at: &CoatAt, wi: Vec3, l: &LayersAt) -> f32 {
        if wi.z <= 0.0 {
            return 0.0;
        }
        let coat_wi = l.bsdf_to_coat(wi);
        let f = coat.eval(l.coat_wo, coat_wi, coat_at);
        if l.coat_frame.is_some() && f > 0.0 {
            f * coat_wi.z / wi.z
        } else {
            f
        }
    }

    /// pdf of the layered BSDF (`wo.z > 0`; `wi` off the tangent plane).
    // Out of line: the hot path of materials without layers stays as small as before.
    #[inline(never)]
    pub(super) fn layered_pdf(&self, wo: Vec3, wi: Vec3, at: &super::AtWo, l: &LayersAt) -> f32 {
        let layers = self.layers.as_ref().expect("layered");
        let [p_coat, p_sheen, p_base] = l.p;
        let mut pdf = 0.0;
        if p_base > 0.0 {
            pdf += p_base * self.pdf_local(wo, wi, at);
        }
        if let Some(s) = &layers.sheen {
            pdf += p_sheen * sheen::pdf(wo, wi, s.alpha);
        }
        if let Some(c) = layers.coat.as_ref().filter(|_| wi.z > 0.0) {
            pdf += p_coat * c.pdf(l.coat_wo, l.bsdf_to_coat(wi));
        }
        pdf
    }

    /// A sample of the layered BSDF in the frame where `wo.z > 0`.
    // Out of line: the hot path of materials without layers stays as small as before.
    #[inline(never)]
    pub(super) fn layered_sample(
        &self,
        wo: Vec3,
        at: &super::AtWo,
        l: &LayersAt,
        u_lobe: f32,
        u: Vec2,
    ) -> Option<BsdfSample> {
        let layers = self.layers.as_ref().expect("layered");
        let [p_coat, p_sheen, p_base] = l.p;
        let continuous = |wi: Vec3| {
            if !wi.is_finite() || wi.z.abs() < COS_EPS {
                return None;
            }
            let pdf = self.layered_pdf(wo, wi, at, l);
            math::positive_finite(pdf).then(|| BsdfSample {
                wi,
                f: self.layered_eval(wo, wi, at, l).into(),
                pdf,
                delta: false,
            })
        };
        if u_lobe < p_coat {
            let coat = layers
                .coat
                .as_ref()
                .expect("a coat is sampled only where present");
            let wi = l.coat_to_bsdf(coat.sample(l.coat_wo, u)?);
            // The coat reflects to the upper side only.
            if wi.z < COS_EPS {
                return None;
            }
            if !coat.smooth {
                return continuous(wi);
            }
            return Some(BsdfSample {
                wi,
                f: Vec3::splat(coat.mirror_weight(l.coat_wo) / wi.z),
                pdf: p_coat,
                delta: true,
            });
        }
        if u_lobe < p_coat + p_sheen {
            let s = layers
                .sheen
                .as_ref()
                .expect("a sheen is sampled only where present");
            return continuous(sheen::sample(wo, s.alpha, u)?);
        }
        let u_base = ((u_lobe - p_coat - p_sheen) / p_base).clamp(0.0, 1.0);
        let s = self.sample_base(wo, at, u_base, u)?;
        if s.delta {
            // The layers add nothing to one direction; they only take their share.
            return Some(BsdfSample {
                f: s.f * self.base_scale(l),
                pdf: s.pdf * p_base,
                ..s
            });
        }
        continuous(s.wi)
    }
}
