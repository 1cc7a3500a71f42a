//! Directional-albedo tables for multiple-scattering energy compensation, computed once
//! on first use by deterministic quadrature (no data files, no randomness).
//!
//! - [`conductor`]: for the GGX reflection lobe with Schlick Fresnel,
//!   `E(μ, α; F0) = F0 · E1(μ, α) + (1 − F0) · Ew(μ, α)` where `E1` is the albedo with
//!   F = 1 and `Ew` the albedo weighted by the Schlick weight `(1 − wo·wm)^5`. 32 × 32
//!   entries, about 10⁶ lobe evaluations: a few milliseconds.
//! - [`dielectric`]: for the rough dielectric interface (exact Fresnel, reflection plus
//!   refraction, counted as energy, i.e. without the 1/η² radiance factor), per side of
//!   the interface, over (μ, α, η). 2 × 32 × 16 × 16 entries, about 8 · 10⁶ Fresnel
//!   evaluations on 2 · 10⁵ visible normals (a quarter of a second): built only when a
//!   scene first evaluates a rough transmissive surface.
//!
//! Axes: μ through [`mu_axis`], which follows the grazing-angle dip of the albedo as it
//! narrows with α (half of the nodes lie below μ = α); roughness
//! `r = √α` uniform on `[√ALPHA_MIN, 1]` (below that the BSDF is a delta lobe and needs no
//! table); and for the dielectric `y = √((η − 1)/(η + 1))` uniform on `[0, Y_MAX]`: near
//! η = 1 the cosine of the critical angle grows like `√(η − 1)`, and the albedo seen from
//! inside changes with it, so the nodes crowd there; the common IORs (1.3–2.5) still get
//! a third of the axis.
//!
//! The tables are built serially, not with rayon: the first lookup happens inside
//! rendering, on a rayon worker, and a parallel build there could steal a rendering job
//! that waits for the same `OnceLock`.

use super::fresnel;
use super::microfacet;
use super::ALPHA_MIN;
use crate::math;
use glam::Vec3;
use std::sync::OnceLock;

/// Nodes along μ and roughness for the conductor table.
const COND_N: usize = 32;
/// Nodes along μ and roughness for the dielectric table.
const DIEL_N: usize = 16;
/// Nodes along the IOR axis of the dielectric table. Seen from inside, the albedo
/// changes quickly with η where the critical angle sweeps through the visible normals;
/// the extra nodes are cheap because all IORs share one pass over the visible normals.
const DIEL_N_ETA: usize = 32;
/// Largest `y = √((η − 1)/(η + 1))` tabulated: η = 10.5. Larger IORs use the η = 10.5
/// entries (their albedo changes little beyond).
const Y_MAX: f32 = 0.909;
/// Quadrature points (φ × z) per dielectric table entry.
const DQ_PHI: usize = 16;
/// See [`DQ_PHI`].
const DQ_Z: usize = 32;
/// Smallest μ used when integrating a node: μ = 0 is the tangent plane itself.
pub(super) const MU_NODE_MIN: f32 = 1e-4;

/// A position on one table axis: the lower node and the weight of the upper one.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct AxisCoord {
    pub(super) i: usize,
    pub(super) t: f32,
}

impl AxisCoord {
    /// Coordinate of `v` in [0, 1] on an axis of `n` uniform nodes (clamped).
    pub(super) fn uniform(v: f32, n: usize) -> Self {
        let s = (v.clamp(0.0, 1.0) * (n - 1) as f32).min((n - 1) as f32);
        let i = (s as usize).min(n - 2);
        Self {
            i,
            t: (s - i as f32).clamp(0.0, 1.0),
        }
    }

    /// The two nodes around the position, each with its weight.
    pub(super) fn corners(self) -> [(usize, f32); 2] {
        [(self.i, 1.0 - self.t), (self.i + 1, self.t)]
    }
}

/// The normalised roughness-axis position for `alpha` (>= ALPHA_MIN).
pub(super) fn roughness_axis(alpha: f32) -> f32 {
    let r_min = ALPHA_MIN.sqrt();
    (alpha.max(0.0).sqrt() - r_min) / (1.0 - r_min)
}

/// The α of node `j` of `n` on the roughness axis.
pub(super) fn node_alpha(j: usize, n: usize) -> f32 {
    let r_min = ALPHA_MIN.sqrt();
    let r = r_min + (1.0 - r_min) * j as f32 / (n - 1) as f32;
    r * r
}

/// The normalised μ-axis position of `mu` for roughness `alpha`: the mean of `√μ` and
/// `√(μ(1 + α)/(μ + α))`. The Fresnel terms change with μ itself, smoothly, and `√μ`
/// alone (nodes at `μ = t²`) serves them and rough surfaces well. But near grazing the
/// albedo of a smoother surface dips and recovers over a range of μ about as wide as α
/// (a smooth GGX surface is self-similar in μ/α); the second term follows μ/α and keeps
/// that feature on the same nodes for every α, so that interpolation along roughness
/// stays accurate too.
pub(super) fn mu_axis(mu: f32, alpha: f32) -> f32 {
    let mu = mu.clamp(0.0, 1.0);
    0.5 * (mu.sqrt() + (mu * (1.0 + alpha) / (mu + alpha)).sqrt())
}

/// The μ of node `i` of `n` on the μ axis for roughness `alpha` (inverse of [`mu_axis`],
/// by bisection: it is monotonic).
pub(super) fn node_mu(i: usize, n: usize, alpha: f32) -> f32 {
    let s = i as f32 / (n - 1) as f32;
    let (mut lo, mut hi) = (0.0f32, 1.0f32);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if mu_axis(mid, alpha) < s {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (0.5 * (lo + hi)).max(MU_NODE_MIN)
}

/// One quadrature point in the visible-normal sample space.
#[derive(Clone, Copy)]
pub(super) struct QuadPoint {
    pub(super) cos_phi: f32,
    pub(super) sin_phi: f32,
    pub(super) uy: f32,
    pub(super) weight: f32,
}

/// The quadrature rule over the visible-normal sample space `u ∈ [0, 1)²`: midpoints in
/// `N_PHI × N_Z` cells. Only φ ∈ [0, π] is visited (the integrands are symmetric in φ for
/// isotropic GGX), and `u.y = 1 − (1 − v)²` puts more points near the most tilted
/// visible normals, where reflected directions approach the horizon and the integrand
/// falls off steeply. Weights sum to 1.
pub(super) fn quad_points<const N_PHI: usize, const N_Z: usize>() -> Vec<QuadPoint> {
    let mut pts = Vec::with_capacity(N_PHI * N_Z);
    for b in 0..N_Z {
        let v = (b as f64 + 0.5) / N_Z as f64;
        let uy = 1.0 - (1.0 - v) * (1.0 - v);
        let jac = 2.0 * (1.0 - v);
        for a in 0..N_PHI {
            let phi = std::f64::consts::PI * (a as f64 + 0.5) / N_PHI as f64;
            let (sin_phi, cos_phi) = crate::math::sin_cos_f64(phi);
            pts.push(QuadPoint {
                cos_phi: cos_phi as f32,
                sin_phi: sin_phi as f32,
                uy: uy as f32,
                weight: (jac / (N_PHI * N_Z) as f64) as f32,
            });
        }
    }
    pts
}

/// The visible normal of quadrature point `q` for `wo` (same map as
/// [`microfacet::sample_visible_normal`], with the trigonometry precomputed).
pub(super) fn visible_normal(wo_std: Vec3, alpha: f32, q: &QuadPoint) -> Vec3 {
    let z = (1.0 - q.uy) * (1.0 + wo_std.z) - wo_std.z;
    let sin_theta = (1.0 - z * z).max(0.0).sqrt();
    let h = Vec3::new(sin_theta * q.cos_phi, sin_theta * q.sin_phi, z) + wo_std;
    math::normalize_or(Vec3::new(h.x * alpha, h.y * alpha, h.z.max(0.0)), Vec3::Z)
}

/// `wo` with cosine `mu` in the xz-plane, and its stretched (α = 1) counterpart.
pub(super) fn wo_at(mu: f32, alpha: f32) -> (Vec3, Vec3) {
    let wo = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let wo_std = math::normalize_or(Vec3::new(wo.x * alpha, 0.0, wo.z), Vec3::Z);
    (wo, wo_std)
}

/// `G2 / G1` of the reflection of `wo` about `wm` (zero below the horizon): the
/// estimator of `∫ f cos` with visible-normal sampling, without Fresnel.
pub(super) fn reflection_masking(wo: Vec3, wm: Vec3, alpha: f32, lambda_o: f32) -> f32 {
    let wi = microfacet::reflect(wo, wm);
    if wi.z > 0.0 {
        (1.0 + lambda_o) / (1.0 + lambda_o + microfacet::lambda(wi.z, alpha))
    } else {
        0.0
    }
}

/// `[E1, Ew]` of the GGX reflection lobe at (μ, α).
pub(super) fn conductor_albedo_with(mu: f32, alpha: f32, pts: &[QuadPoint]) -> [f32; 2] {
    let (wo, wo_std) = wo_at(mu, alpha);
    let lambda_o = microfacet::lambda(mu, alpha);
    let (mut e1, mut ew) = (0.0f64, 0.0f64);
    for q in pts {
        let wm = visible_normal(wo_std, alpha, q);
        // With visible-normal sampling the estimator of ∫ f cos is F · G2 / G1.
        let w = q.weight * reflection_masking(wo, wm, alpha, lambda_o);
        e1 += w as f64;
        ew += (w * fresnel::schlick_weight(wo.dot(wm))) as f64;
    }
    [e1 as f32, ew as f32]
}

/// `[E1, Ew]` of the GGX reflection lobe at (μ, α), by the table's quadrature rule
/// (error below 1e-3 against a 512 × 2048-point reference for every (μ, α)).
#[cfg(test)]
pub(crate) fn conductor_albedo(mu: f32, alpha: f32) -> [f32; 2] {
    conductor_albedo_with(mu, alpha, &quad_points::<16, 64>())
}

/// `[A, B, C]` of the rough dielectric interface at (μ, α) for each relative index in
/// `etas` (transmitted over incident side), with `A = ∫ F f_r cos`,
/// `B = ∫ (1 − F) f_t cos`, `C = ∫ F f_t cos` (f without Fresnel and without the 1/η²
/// radiance factor). With reflection weight `s·F` and transmission weight `1 − s·F` the
/// single-scattering albedo is `s·A + B + (1 − s)·C`. The visible normals are shared by
/// all indices, so one pass serves a whole row of the table.
fn dielectric_albedo_with(
    mu: f32,
    alpha: f32,
    etas: &[f32],
    pts: &[QuadPoint],
    out: &mut [[f32; 3]],
) {
    let (wo, wo_std) = wo_at(mu, alpha);
    let lambda_o = microfacet::lambda(mu, alpha);
    let mut acc = vec![[0.0f64; 3]; etas.len()];
    for q in pts {
        let wm = visible_normal(wo_std, alpha, q);
        let cos_om = wo.dot(wm).clamp(0.0, 1.0);
        let gr = reflection_masking(wo, wm, alpha, lambda_o);
        for (a, &eta) in acc.iter_mut().zip(etas) {
            let terms = interface_terms(mu, alpha, lambda_o, wm, cos_om, gr, eta);
            for (a, t) in a.iter_mut().zip(terms) {
                *a += q.weight as f64 * t as f64;
            }
        }
    }
    for (o, a) in out.iter_mut().zip(acc) {
        *o = a.map(|v| v as f32);
    }
}

/// The integrands `[F·Gr, (1 − F)·Gt, F·Gt]` of [`dielectric_albedo_with`] at one
/// visible normal `wm` (with `cos_om = wo·wm` and the reflection's masking ratio `gr`),
/// for relative index `eta`.
pub(super) fn interface_terms(
    mu: f32,
    alpha: f32,
    lambda_o: f32,
    wm: Vec3,
    cos_om: f32,
    gr: f32,
    eta: f32,
) -> [f32; 3] {
    let f = fresnel::dielectric(cos_om, eta);
    // The refracted direction's z, as `microfacet::refract` computes it.
    let sin2_t = (1.0 - cos_om * cos_om) / (eta * eta);
    let gt = if sin2_t < 1.0 {
        let cos_t = (1.0 - sin2_t).sqrt();
        let wt_z = if eta == 1.0 {
            -mu
        } else {
            -mu / eta + (cos_om / eta - cos_t) * wm.z
        };
        if wt_z < 0.0 {
            (1.0 + lambda_o) / (1.0 + lambda_o + microfacet::lambda(-wt_z, alpha))
        } else {
            0.0
        }
    } else {
        0.0
    };
    [f * gr, (1.0 - f) * gt, f * gt]
}

/// `[A, B, C]` of the rough dielectric interface at (μ, α, relative η), by the table's
/// quadrature rule.
#[cfg(test)]
pub(crate) fn dielectric_albedo(mu: f32, alpha: f32, eta: f32) -> [f32; 3] {
    let mut out = [[0.0; 3]];
    dielectric_albedo_with(mu, alpha, &[eta], &quad_points::<DQ_PHI, DQ_Z>(), &mut out);
    out[0]
}

/// The conductor table: `[E1, Ew]` per (μ node, roughness node).
pub(crate) struct ConductorTable {
    data: Vec<[f32; 2]>,
}

/// A conductor-table lookup position for one α, reusable for many μ.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct ConductorCoord {
    alpha: f32,
    r: AxisCoord,
}

impl ConductorTable {
    fn build() -> Self {
        let pts = quad_points::<16, 64>();
        let mut data = vec![[0.0; 2]; COND_N * COND_N];
        for j in 0..COND_N {
            let alpha = node_alpha(j, COND_N);
            for i in 0..COND_N {
                data[j * COND_N + i] =
                    conductor_albedo_with(node_mu(i, COND_N, alpha), alpha, &pts);
            }
        }
        Self { data }
    }

    /// The lookup position for `alpha`.
    pub(crate) fn coord(alpha: f32) -> ConductorCoord {
        ConductorCoord {
            alpha,
            r: AxisCoord::uniform(roughness_axis(alpha), COND_N),
        }
    }

    /// `[E1, Ew]` at cosine `mu`, bilinear.
    pub(crate) fn lookup(&self, mu: f32, c: ConductorCoord) -> [f32; 2] {
        let m = AxisCoord::uniform(mu_axis(mu, c.alpha), COND_N);
        let at = |j: usize, i: usize| self.data[j * COND_N + i];
        let mut out = [0.0; 2];
        for (k, o) in out.iter_mut().enumerate() {
            let lo = lerp(at(c.r.i, m.i)[k], at(c.r.i, m.i + 1)[k], m.t);
            let hi = lerp(at(c.r.i + 1, m.i)[k], at(c.r.i + 1, m.i + 1)[k], m.t);
            *o = lerp(lo, hi, c.r.t);
        }
        out
    }
}

/// The dielectric table: `[A, B, C]` per (side, η node, roughness node, μ node).
pub(crate) struct DielectricTable {
    data: Vec<[f32; 3]>,
}

/// A dielectric-table lookup position for one (α, η, side), reusable for many μ.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct DielectricCoord {
    alpha: f32,
    r: AxisCoord,
    y: AxisCoord,
    inside: bool,
}

impl DielectricTable {
    fn index(inside: bool, xi: usize, rj: usize, mi: usize) -> usize {
        ((usize::from(inside) * DIEL_N_ETA + xi) * DIEL_N + rj) * DIEL_N + mi
    }

    fn build() -> Self {
        let pts = quad_points::<DQ_PHI, DQ_Z>();
        // Relative indices of every (side, IOR node), in table order.
        let etas: Vec<f32> = [false, true]
            .into_iter()
            .flat_map(|inside| {
                (0..DIEL_N_ETA).map(move |xi| {
                    let y = Y_MAX * xi as f32 / (DIEL_N_ETA - 1) as f32;
                    let x = y * y;
                    let eta = (1.0 + x) / (1.0 - x);
                    if inside {
                        1.0 / eta
                    } else {
                        eta
                    }
                })
            })
            .collect();
        let mut data = vec![[0.0; 3]; 2 * DIEL_N_ETA * DIEL_N * DIEL_N];
        let mut row = vec![[0.0; 3]; etas.len()];
        for rj in 0..DIEL_N {
            let alpha = node_alpha(rj, DIEL_N);
            for mi in 0..DIEL_N {
                dielectric_albedo_with(node_mu(mi, DIEL_N, alpha), alpha, &etas, &pts, &mut row);
                for (k, v) in row.iter().enumerate() {
                    let (inside, xi) = (k >= DIEL_N_ETA, k % DIEL_N_ETA);
                    data[Self::index(inside, xi, rj, mi)] = *v;
                }
            }
        }
        Self { data }
    }

    /// The lookup position for `alpha`, the material IOR `eta` (>= 1) and the side of
    /// the outgoing direction.
    pub(crate) fn coord(alpha: f32, eta: f32, inside: bool) -> DielectricCoord {
        let y = ((eta - 1.0) / (eta + 1.0)).max(0.0).sqrt();
        DielectricCoord {
            alpha,
            r: AxisCoord::uniform(roughness_axis(alpha), DIEL_N),
            y: AxisCoord::uniform(y / Y_MAX, DIEL_N_ETA),
            inside,
        }
    }

    /// `[A, B, C]` at cosine `mu`, trilinear.
    pub(crate) fn lookup(&self, mu: f32, c: DielectricCoord) -> [f32; 3] {
        let m = AxisCoord::uniform(mu_axis(mu, c.alpha), DIEL_N);
        let mut out = [0.0; 3];
        for (dx, wx) in [(0, 1.0 - c.y.t), (1, c.y.t)] {
            for (dr, wr) in [(0, 1.0 - c.r.t), (1, c.r.t)] {
                for (dm, wm) in [(0, 1.0 - m.t), (1, m.t)] {
                    let w = wx * wr * wm;
                    let v = self.data[Self::index(c.inside, c.y.i + dx, c.r.i + dr, m.i + dm)];
                    for k in 0..3 {
                        out[k] += w * v[k];
                    }
                }
            }
        }
        out
    }
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// The conductor table, built on first use.
pub(crate) fn conductor() -> &'static ConductorTable {
    static TABLE: OnceLock<ConductorTable> = OnceLock::new();
    TABLE.get_or_init(ConductorTable::build)
}

/// The dielectric table, built on first use.
pub(crate) fn dielectric() -> &'static DielectricTable {
    static TABLE: OnceLock<DielectricTable> = OnceLock::new();
    TABLE.get_or_init(DielectricTable::build)
}
