//! Energy compensation for KHR_materials_anisotropy's GGX lobes.
//!
//! The compensation tables (`tables.rs`) hold isotropic lobes over (μ, α). An
//! anisotropic lobe's single-scattering albedo `E1` depends on the azimuth of `wo` too,
//! and on both roughnesses, and no isotropic α stands in for it by a formula: looked up
//! at the roughness the lobe shows to `wo` (Smith's α_w), a white furnace of anisotropic
//! metal reads from 0.53 to 1.58. So this table stores, per (μ, azimuth, α, strength),
//! the lobe's own `E1` and `Ew` (as `tables.rs` defines them for the conductor table)
//! and the **equivalent isotropic α**, the one whose `E1` at that μ equals the
//! anisotropic lobe's. Turquin's factor of the metal, the specular layer and the thin
//! wall and the diffuse base's albedo scaling use `E1` and `Ew` themselves (so a white
//! anisotropic metal stays white, and white plastic too); the rough refractive
//! interface's multiple scattering, which needs the dielectric table over (μ, α, η),
//! looks it up at the equivalent α (α = 1 where the anisotropic lobe loses more than the
//! roughest isotropic one at that μ).
//!
//! Axes: roughness `α` (the bitangent's, `ay`) as in the other tables; strength as `s²`,
//! uniform in `ax = ay + (1 − ay) s²`; the azimuth as `cos²φ` of `wo` from the
//! direction of anisotropy (the albedo is symmetric about both axes); μ through
//! [`tables::mu_axis`] for the roughness the lobe shows along that azimuth.
//! 16 × 12 × 8 × 24 entries of a 24 × 32-point quadrature each, then a bisection in the
//! conductor table: about 3 · 10⁷ lobe evaluations, 0.7 s, built when a scene first
//! shades an anisotropic material (or while its frame is prepared).

use std::sync::OnceLock;

use glam::{Vec2, Vec3};

use super::fresnel;
use super::microfacet::{self, Ggx};
use super::tables::{self, AxisCoord};
use super::ALPHA_MIN;

const N_ALPHA: usize = 16;
const N_STRENGTH: usize = 12;
const N_AZIMUTH: usize = 8;
const N_MU: usize = 24;
/// Quadrature points around the whole circle and along the visible-normal sample space
/// (an anisotropic lobe has no mirror symmetry about the plane of `wo` to halve it).
const Q_PHI: usize = 24;
const Q_Z: usize = 32;

/// The table of `[E1, Ew, equivalent isotropic α]`, indexed `[α][s][cos²φ][μ]`.
pub(crate) struct AnisotropicAlbedo {
    data: Vec<[f32; 3]>,
}

/// The μ-axis roughness of a table row: the roughness the lobe shows along the azimuth
/// (Smith's α_w), whose dip near grazing the nodes follow.
fn mu_axis_alpha(ggx: Ggx, c2: f32) -> f32 {
    (ggx.ax * ggx.ax * c2 + ggx.ay * ggx.ay * (1.0 - c2)).sqrt()
}

/// The strength axis position of a distribution: `s²`, with `ax = ay + (1 − ay) s²`
/// (uniform in `ax`, in which the albedo changes smoothly).
fn strength_axis(ggx: Ggx) -> f32 {
    if ggx.ay >= 1.0 {
        return 0.0;
    }
    ((ggx.ax - ggx.ay) / (1.0 - ggx.ay)).clamp(0.0, 1.0)
}

/// `cos²φ` of `w`'s azimuth from the x axis; ½ along the normal, where it is undefined
/// and the albedo does not depend on it.
fn cos2_azimuth(w: Vec3) -> f32 {
    let s2 = w.x * w.x + w.y * w.y;
    if s2 > 1e-12 {
        w.x * w.x / s2
    } else {
        0.5
    }
}

/// `[E1, Ew]` of the lobe at `wo` (the albedo with F = 1, and weighted by Schlick's
/// `(1 − wo·wm)^5`, as in `tables.rs`), by quadrature over visible normals (midpoints,
/// crowded towards the most tilted normals as there).
fn albedo(ggx: Ggx, wo: Vec3) -> [f32; 2] {
    let lambda_o = ggx.lambda(wo);
    let (mut e1, mut ew) = (0.0f64, 0.0f64);
    for b in 0..Q_Z {
        let v = (b as f32 + 0.5) / Q_Z as f32;
        let uy = 1.0 - (1.0 - v) * (1.0 - v);
        let jacobian = 2.0 * (1.0 - v);
        for a in 0..Q_PHI {
            let ux = (a as f32 + 0.5) / Q_PHI as f32;
            let wm = ggx.sample_visible_normal(wo, Vec2::new(ux, uy));
            let wi = microfacet::reflect(wo, wm);
            if wi.z > 0.0 {
                let g2_over_g1 = (1.0 + lambda_o) / (1.0 + lambda_o + ggx.lambda(wi));
                let w = jacobian * g2_over_g1;
                e1 += f64::from(w);
                ew += f64::from(w * fresnel::schlick_weight(wo.dot(wm)));
            }
        }
    }
    let n = (Q_PHI * Q_Z) as f64;
    [(e1 / n) as f32, (ew / n) as f32]
}

/// The isotropic α whose `E1` at `mu` is `e1` (by bisection: `E1` falls with α),
/// within [ALPHA_MIN, 1].
fn isotropic_alpha_for(mu: f32, e1: f32) -> f32 {
    let table = tables::conductor();
    let e1_at = |alpha: f32| table.lookup(mu, tables::ConductorTable::coord(alpha))[0];
    let (mut lo, mut hi) = (ALPHA_MIN, 1.0f32);
    if e1 <= e1_at(hi) {
        return hi;
    }
    if e1 >= e1_at(lo) {
        return lo;
    }
    for _ in 0..24 {
        let mid = 0.5 * (lo + hi);
        if e1_at(mid) > e1 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

impl AnisotropicAlbedo {
    fn build() -> Self {
        let mut data = Vec::with_capacity(N_ALPHA * N_STRENGTH * N_AZIMUTH * N_MU);
        for k in 0..N_ALPHA {
            let ay = tables::node_alpha(k, N_ALPHA);
            for l in 0..N_STRENGTH {
                let s2 = l as f32 / (N_STRENGTH - 1) as f32;
                let ggx = Ggx {
                    ax: ay + (1.0 - ay) * s2,
                    ay,
                };
                for j in 0..N_AZIMUTH {
                    let c2 = j as f32 / (N_AZIMUTH - 1) as f32;
                    for i in 0..N_MU {
                        let mu = tables::node_mu(i, N_MU, mu_axis_alpha(ggx, c2));
                        let sin = (1.0 - mu * mu).max(0.0).sqrt();
                        let wo = Vec3::new(sin * c2.sqrt(), sin * (1.0 - c2).sqrt(), mu);
                        let [e1, ew] = albedo(ggx, wo);
                        data.push([e1, ew, isotropic_alpha_for(mu, e1)]);
                    }
                }
            }
        }
        Self { data }
    }

    /// `[E1, Ew, equivalent isotropic α]` of `ggx` (anisotropic, `ax > ay`) seen from
    /// `wo` (`wo.z > 0`), multilinear in the table.
    pub(crate) fn lookup(&self, ggx: Ggx, wo: Vec3) -> [f32; 3] {
        let a = AxisCoord::uniform(tables::roughness_axis(ggx.ay), N_ALPHA);
        let s = AxisCoord::uniform(strength_axis(ggx), N_STRENGTH);
        let c2 = cos2_azimuth(wo);
        let c = AxisCoord::uniform(c2, N_AZIMUTH);
        let m = AxisCoord::uniform(tables::mu_axis(wo.z, mu_axis_alpha(ggx, c2)), N_MU);
        let mut out = [0.0; 3];
        for (da, wa) in a.corners() {
            for (ds, ws) in s.corners() {
                for (dc, wc) in c.corners() {
                    let row = ((da * N_STRENGTH + ds) * N_AZIMUTH + dc) * N_MU;
                    let [lo, hi] = [self.data[row + m.i], self.data[row + m.i + 1]];
                    for k in 0..3 {
                        out[k] += wa * ws * wc * (lo[k] + (hi[k] - lo[k]) * m.t);
                    }
                }
            }
        }
        out
    }
}

/// The table, built on first use.
pub(crate) fn table() -> &'static AnisotropicAlbedo {
    static TABLE: OnceLock<AnisotropicAlbedo> = OnceLock::new();
    TABLE.get_or_init(AnisotropicAlbedo::build)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At strength 0 the lobe's albedo is the isotropic one of the conductor table's
    /// reference quadrature, and the equivalent α is the lobe's own wherever the albedo
    /// determines it: not where E1 hardly changes with α, nor near grazing, where E1 dips
    /// and recovers as α grows past μ and several α share one albedo.
    #[test]
    fn strength_zero_gives_the_isotropic_lobe_back() {
        let start = std::time::Instant::now();
        let t = table();
        println!("built in {:?}", start.elapsed());
        for k in 0..N_ALPHA {
            let ay = tables::node_alpha(k, N_ALPHA);
            for j in 0..N_AZIMUTH {
                for i in 0..N_MU {
                    let mu = tables::node_mu(i, N_MU, ay);
                    let [e1, _, alpha] = t.data[((k * N_STRENGTH) * N_AZIMUTH + j) * N_MU + i];
                    let reference = tables::conductor_albedo(mu, ay)[0];
                    assert!(
                        (e1 - reference).abs() < 5e-3,
                        "α {ay} μ {mu}: E1 {e1}, reference {reference}"
                    );
                    let steep = tables::conductor_albedo(mu, (ay * 1.2).min(1.0))[0];
                    if mu > 0.1 && reference - steep > 1e-2 {
                        assert!((alpha / ay - 1.0).abs() < 0.05, "α {ay} μ {mu}: {alpha}");
                    }
                }
            }
        }
    }
}
