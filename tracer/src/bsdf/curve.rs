//! Per-material albedo curves: the directional albedos of one rough transmissive
//! material, over μ alone, precise enough for light that stays trapped in it.
//!
//! The shared tables (`tables.rs`) interpolate over (μ, α, η) from a coarse quadrature:
//! their albedos are right to about 1e-3. That is invisible after a few bounces, but rough
//! glass of high IOR traps light by total internal reflection for about 200 bounces
//! (IOR 10: only directions within 6° of the normal can leave), and an albedo error of
//! 2e-4 per bounce darkens a white furnace by 4%. A material whose roughness and IOR are
//! not textured has one (α, η), so its albedos are curves over μ, and they can afford a
//! much finer quadrature:
//!
//! - 256 × 64 midpoint cells (rows along the visible normal's tilt, which the integrands
//!   follow most steeply; columns over φ ∈ [0, π]), the same sample space as the tables;
//! - a cell that straddles the critical angle (seen from inside, Fresnel jumps to total
//!   reflection there with an infinite slope) is split in four, [`REFINE_DEPTH`] times;
//! - 96 μ nodes on the tables' μ axis, interpolated by Catmull-Rom (exact for quadratics).
//!
//! Against a 1024 × 256-cell quadrature refined 6 levels deep, the curve's single
//! scattering albedo is right to 5e-5 at α = 1, IOR 10, both sides (see the tests; the
//! shared tables are off by up to 1e-3 there). A curve takes about 0.3 s to build on two
//! threads (0.7 s on one); curves are interned per (α, η) for the life of the process, so
//! animation frames and later jobs reuse them, and only scenes with rough glass pay.

use super::microfacet;
use super::tables::{
    conductor_albedo_with, interface_terms, mu_axis, node_mu, quad_points, reflection_masking,
    visible_normal, wo_at, QuadPoint,
};
use rayon::prelude::*;
use std::collections::HashMap;
use std::f64::consts::PI;
use std::sync::{Mutex, OnceLock};

/// μ nodes per curve.
const NODES: usize = 96;
/// Quadrature rows (along the tilt of the visible normal).
const ROWS: usize = 256;
/// Quadrature columns (over φ ∈ [0, π]).
const COLUMNS: usize = 64;
/// Levels of 2 × 2 splitting of a cell that straddles the critical angle.
const REFINE_DEPTH: u32 = 4;
/// Most curves interned: beyond this, new materials use the shared tables (a curve is
/// about 2 KiB, and a process that meets this many distinct rough glasses is unusual).
const MAX_CURVES: usize = 4096;

/// The albedos of one (α, η): the conductor table's `[E1, Ew]` and the dielectric table's
/// `[A, B, C]` for each side, at `NODES` μ nodes.
#[derive(Debug)]
pub struct AlbedoCurve {
    alpha: f32,
    eta: f32,
    conductor: Vec<[f32; 2]>,
    /// Outside, then inside.
    dielectric: [Vec<[f32; 3]>; 2],
}

impl AlbedoCurve {
    fn build(alpha: f32, eta: f32) -> Self {
        let mus: Vec<f32> = (0..NODES).map(|i| node_mu(i, NODES, alpha)).collect();
        let pts = quad_points::<COLUMNS, ROWS>();
        let conductor = mus
            .par_iter()
            .map(|&mu| conductor_albedo_with(mu, alpha, &pts))
            .collect();
        let side = |eta_rel: f32| -> Vec<[f32; 3]> {
            mus.par_iter()
                .map(|&mu| dielectric_albedo_refined(mu, alpha, eta_rel))
                .collect()
        };
        Self {
            alpha,
            eta,
            conductor,
            dielectric: [side(eta), side(1.0 / eta)],
        }
    }

    /// Whether this is the curve of (α, η).
    pub(crate) fn is_for(&self, alpha: f32, eta: f32) -> bool {
        self.alpha == alpha && self.eta == eta
    }

    /// `[E1, Ew]` of the GGX reflection lobe at cosine `mu`.
    pub(crate) fn conductor(&self, mu: f32) -> [f32; 2] {
        catmull_rom(&self.conductor, mu_axis(mu, self.alpha))
    }

    /// `[A, B, C]` of the dielectric interface at cosine `mu`, from inside or outside.
    pub(crate) fn dielectric(&self, mu: f32, inside: bool) -> [f32; 3] {
        catmull_rom(
            &self.dielectric[usize::from(inside)],
            mu_axis(mu, self.alpha),
        )
    }
}

/// The interned curve of (α, η), built on first request; `None` once [`MAX_CURVES`]
/// curves exist. The lock is not held while building: the build runs on rayon, and a
/// thread that waits for a lock inside a rayon job could be the one the build needs.
pub(crate) fn interned(alpha: f32, eta: f32) -> Option<&'static AlbedoCurve> {
    static CURVES: OnceLock<Mutex<HashMap<(u32, u32), &'static AlbedoCurve>>> = OnceLock::new();
    let curves = CURVES.get_or_init(Default::default);
    let key = (alpha.to_bits(), eta.to_bits());
    {
        let map = curves.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(&c) = map.get(&key) {
            return Some(c);
        }
        if map.len() >= MAX_CURVES {
            return None;
        }
    }
    let built = AlbedoCurve::build(alpha, eta);
    let mut map = curves.lock().unwrap_or_else(|e| e.into_inner());
    Some(*map.entry(key).or_insert_with(|| Box::leak(Box::new(built))))
}

/// Catmull-Rom interpolation of `nodes` (at least 3), uniform on `s ∈ [0, 1]` (clamped):
/// exact for quadratics.
fn catmull_rom<const K: usize>(nodes: &[[f32; K]], s: f32) -> [f32; K] {
    let last = nodes.len() - 1;
    let x = (s.clamp(0.0, 1.0) * last as f32).min(last as f32);
    let i = (x as usize).min(last - 1);
    let t = x - i as f32;
    // Beyond an end, the neighbour continues the quadratic through the last three nodes.
    let extrapolate = |a: [f32; K], b: [f32; K], c: [f32; K]| -> [f32; K] {
        std::array::from_fn(|k| 3.0 * a[k] - 3.0 * b[k] + c[k])
    };
    let before = if i == 0 {
        extrapolate(nodes[0], nodes[1], nodes[2])
    } else {
        nodes[i - 1]
    };
    let after = if i + 2 > last {
        extrapolate(nodes[last], nodes[last - 1], nodes[last - 2])
    } else {
        nodes[i + 2]
    };
    let p = [before, nodes[i], nodes[i + 1], after];
    let (t2, t3) = (t * t, t * t * t);
    let w = [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ];
    std::array::from_fn(|k| (0..4).map(|j| w[j] * p[j][k]).sum())
}

/// `[A, B, C]` of the rough dielectric interface at (μ, α, relative η), as
/// `tables::dielectric_albedo_with` defines them, by [`ROWS`] × [`COLUMNS`] midpoint
/// cells refined where they straddle the critical angle.
pub(super) fn dielectric_albedo_refined(mu: f32, alpha: f32, eta: f32) -> [f32; 3] {
    dielectric_albedo_cells(mu, alpha, eta, ROWS, COLUMNS, REFINE_DEPTH)
}

/// [`dielectric_albedo_refined`] with its resolution as arguments.
pub(super) fn dielectric_albedo_cells(
    mu: f32,
    alpha: f32,
    eta: f32,
    rows: usize,
    columns: usize,
    depth: u32,
) -> [f32; 3] {
    let integrand = Integrand::new(mu, alpha, eta);
    let mut sum = [0.0f64; 3];
    for b in 0..rows {
        let v = [b as f64 / rows as f64, (b + 1) as f64 / rows as f64];
        for a in 0..columns {
            let phi = [
                PI * a as f64 / columns as f64,
                PI * (a + 1) as f64 / columns as f64,
            ];
            integrand.cell(v, phi, depth, &mut sum);
        }
    }
    sum.map(|x| x as f32)
}

/// The dielectric integrands at one (μ, α, η) over the sample space (v, φ), where the
/// visible-normal sample is `u.y = 1 − (1 − v)²` (as in `tables::quad_points`).
struct Integrand {
    mu: f32,
    alpha: f32,
    eta: f32,
    lambda_o: f32,
    wo: glam::Vec3,
    wo_std: glam::Vec3,
    /// Cosine of the critical angle, or none (seen from the optically thinner side).
    cos_critical: Option<f32>,
}

impl Integrand {
    fn new(mu: f32, alpha: f32, eta: f32) -> Self {
        let (wo, wo_std) = wo_at(mu, alpha);
        Self {
            mu,
            alpha,
            eta,
            lambda_o: microfacet::lambda(mu, alpha),
            wo,
            wo_std,
            cos_critical: (eta < 1.0).then(|| (1.0 - eta * eta).sqrt()),
        }
    }

    /// The visible normal at (v, φ) and its cosine with `wo`.
    fn normal(&self, v: f64, phi: f64) -> (glam::Vec3, f32) {
        let (sin_phi, cos_phi) = crate::math::sin_cos_f64(phi);
        let q = QuadPoint {
            cos_phi: cos_phi as f32,
            sin_phi: sin_phi as f32,
            uy: (1.0 - (1.0 - v) * (1.0 - v)) as f32,
            weight: 0.0,
        };
        let wm = visible_normal(self.wo_std, self.alpha, &q);
        (wm, self.wo.dot(wm).clamp(0.0, 1.0))
    }

    /// Adds the cell `v × phi` to `sum`: its midpoint value times its measure, or its four
    /// quarters when it straddles the critical angle and `depth` allows.
    fn cell(&self, v: [f64; 2], phi: [f64; 2], depth: u32, sum: &mut [f64; 3]) {
        let (vm, pm) = (0.5 * (v[0] + v[1]), 0.5 * (phi[0] + phi[1]));
        if let (Some(cos_c), true) = (self.cos_critical, depth > 0) {
            let corners = [
                (v[0], phi[0]),
                (v[0], phi[1]),
                (v[1], phi[0]),
                (v[1], phi[1]),
            ];
            let above = corners
                .iter()
                .chain([&(vm, pm)])
                .filter(|&&(a, b)| self.normal(a, b).1 > cos_c)
                .count();
            if above != 0 && above != 5 {
                for vs in [[v[0], vm], [vm, v[1]]] {
                    for ps in [[phi[0], pm], [pm, phi[1]]] {
                        self.cell(vs, ps, depth - 1, sum);
                    }
                }
                return;
            }
        }
        let (wm, cos_om) = self.normal(vm, pm);
        let gr = reflection_masking(self.wo, wm, self.alpha, self.lambda_o);
        let terms = interface_terms(self.mu, self.alpha, self.lambda_o, wm, cos_om, gr, self.eta);
        // Measure: du.y = 2 (1 − v) dv, and φ over [0, π] stands for the whole circle.
        let weight = 2.0 * (1.0 - vm) * (v[1] - v[0]) * (phi[1] - phi[0]) / PI;
        for (s, t) in sum.iter_mut().zip(terms) {
            *s += weight * f64::from(t);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The curve against a quadrature 16 times finer and refined 6 levels deep, at μ
    /// between the nodes: the single-scattering albedo A + B (a white interface's)
    /// must be right to 5e-5 on both sides at IOR 10, roughness 1, where light is trapped
    /// for about 200 bounces.
    #[test]
    fn curve_matches_a_finer_quadrature_at_ior_10() {
        let (alpha, eta) = (1.0, 10.0);
        let curve = AlbedoCurve::build(alpha, eta);
        let mut worst = [0.0f32; 2];
        for k in 0..24 {
            let mu = (k as f32 + 0.37) / 24.0;
            for inside in [false, true] {
                let eta_rel = if inside { 1.0 / eta } else { eta };
                let [a, b, _] = dielectric_albedo_cells(mu, alpha, eta_rel, 1024, 256, 6);
                let [ca, cb, _] = curve.dielectric(mu, inside);
                let err = ((ca + cb) - (a + b)).abs();
                let w = &mut worst[usize::from(inside)];
                *w = w.max(err);
            }
        }
        println!(
            "worst albedo error, outside {:.2e}, inside {:.2e}",
            worst[0], worst[1]
        );
        assert!(worst[0] <= 5e-5 && worst[1] <= 5e-5, "{worst:?}");
    }

    #[test]
    fn catmull_rom_reproduces_nodes_and_quadratics() {
        let f = |s: f32| [s * s - 0.5 * s, 1.0];
        let nodes: Vec<[f32; 2]> = (0..9).map(|i| f(i as f32 / 8.0)).collect();
        for s in [0.0f32, 0.125, 0.3, 0.5, 0.61, 0.97, 1.0] {
            let [v, one] = catmull_rom(&nodes, s);
            assert!((v - f(s)[0]).abs() <= 1e-6, "{s}: {v} vs {}", f(s)[0]);
            assert!((one - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn curves_are_interned() {
        let a = interned(0.5, 2.0).unwrap();
        let b = interned(0.5, 2.0).unwrap();
        assert!(std::ptr::eq(a, b));
        assert!(a.is_for(0.5, 2.0) && !a.is_for(0.5, 2.1));
    }
}
