//! The KHR_materials_sheen lobe: Conty & Kulla's (2017) "Charlie" distribution of
//! micro-fibres with its matching visibility term, exactly as the extension's
//! implementation notes write them (α is the sheen roughness itself, not its square), and
//! the lobe's directional albedo `E(μ, α)`, integrated once on first use, for the albedo
//! scaling that takes the sheen's energy from the base.
//!
//! Sampling draws the half vector from `D(h) cos θh`, whose marginal in θh has the
//! closed-form inverse `sin θh = u^(1/(2 + 1/α))`, and reflects `wo` about it.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, TAU};
use std::sync::OnceLock;

use crate::math::{self, exp, powf};

/// Smallest sheen roughness: below it the fibres' lobe is narrower than the f32 powers of
/// `sin θh` resolve (glTF's sample viewer clamps at the same value).
pub(crate) const ALPHA_MIN: f32 = 0.07;
/// Nodes of the albedo table along μ and along α.
const N: usize = 32;
/// Quadrature cells per table entry over the hemisphere of incident directions
/// (cos θ × φ over half the circle: the lobe is symmetric about the plane of `wo`).
const Q_MU: usize = 96;
const Q_PHI: usize = 32;

/// The Charlie distribution `D(h) = (2 + 1/α) sin^(1/α) θh / 2π` for `cos θh = cos_h`.
pub(crate) fn d(cos_h: f32, alpha: f32) -> f32 {
    let inv = 1.0 / alpha;
    let sin2 = (1.0 - cos_h * cos_h).max(0.0);
    (2.0 + inv) * powf(sin2, 0.5 * inv) * (0.5 * FRAC_1_PI)
}

/// The exponent fit `l(x, α)` of the Charlie Λ (Conty & Kulla 2017, table 1).
fn l(x: f32, alpha: f32) -> f32 {
    let t = (1.0 - alpha) * (1.0 - alpha);
    let mix = |a: f32, b: f32| a + (b - a) * t;
    let (a, b, c) = (
        mix(21.5473, 25.3245),
        mix(3.82987, 3.32435),
        mix(0.19823, 0.16801),
    );
    let (d, e) = (mix(-1.97760, -1.27393), mix(-4.32054, -4.85967));
    a / (1.0 + b * powf(x, c)) + d * x + e
}

/// Λ of the Charlie distribution for a direction with cosine `mu` (> 0).
fn lambda(mu: f32, alpha: f32) -> f32 {
    // A unit vector's z may round past 1, and the fit's powers need x >= 0.
    let mu = mu.min(1.0);
    if mu < 0.5 {
        exp(l(mu, alpha))
    } else {
        exp(2.0 * l(0.5, alpha) - l(1.0 - mu, alpha))
    }
}

/// The lobe `D · V` with `V = 1 / ((1 + Λ(μo) + Λ(μi)) · 4 μo μi)`, for `wo`, `wi` above
/// the surface (colour not included).
pub(crate) fn eval(wo: Vec3, wi: Vec3, alpha: f32) -> f32 {
    let h = math::normalize_or(wo + wi, Vec3::Z);
    let v = 1.0 / ((1.0 + lambda(wo.z, alpha) + lambda(wi.z, alpha)) * (4.0 * wo.z * wi.z));
    d(h.z, alpha) * v
}

/// The density with which [`sample`] returns `wi` (zero below the surface).
pub(crate) fn pdf(wo: Vec3, wi: Vec3, alpha: f32) -> f32 {
    if wi.z <= 0.0 {
        return 0.0;
    }
    let Some(h) = math::try_normalize(wo + wi) else {
        return 0.0;
    };
    let cos_oh = wo.dot(h);
    if cos_oh <= 0.0 {
        return 0.0;
    }
    d(h.z, alpha) * h.z / (4.0 * cos_oh)
}

/// Reflects `wo` about a half vector drawn from `D(h) cos θh`; `None` when that leaves
/// the surface's upper side (the density of [`pdf`] leaves that mass out).
pub(crate) fn sample(wo: Vec3, alpha: f32, u: Vec2) -> Option<Vec3> {
    let sin_h = powf(u.x, 1.0 / (2.0 + 1.0 / alpha));
    let cos_h = (1.0 - sin_h * sin_h).max(0.0).sqrt();
    let (s, c) = crate::math::sin_cos(TAU * u.y);
    let h = Vec3::new(sin_h * c, sin_h * s, cos_h);
    let wi = super::microfacet::reflect(wo, h);
    (wi.z > 0.0 && wo.dot(h) > 0.0).then_some(wi)
}

/// Directional albedo table of the lobe over (μ, α): `√μ` uniform, since the albedo
/// changes fastest near grazing, and α uniform.
struct Table {
    data: Vec<f32>,
}

/// Position `t` in [0, 1] of `v` on an axis from `lo` to 1.
fn axis(v: f32, lo: f32) -> f32 {
    ((v - lo) / (1.0 - lo)).clamp(0.0, 1.0)
}

/// The value at node `i` of an axis from `lo` to 1.
fn node(i: usize, lo: f32) -> f32 {
    lo + (1.0 - lo) * i as f32 / (N - 1) as f32
}

/// Smallest μ tabulated: at μ = 0 the lobe's `1/μo` meets a zero solid angle.
const MU_MIN: f32 = 1e-4;

impl Table {
    fn build() -> Self {
        let mut data = vec![0.0; N * N];
        let sqrt_min = MU_MIN.sqrt();
        for j in 0..N {
            let alpha = node(j, ALPHA_MIN);
            for i in 0..N {
                let mu = node(i, sqrt_min).powi(2);
                data[j * N + i] = albedo_by_quadrature(mu, alpha, Q_MU, Q_PHI);
            }
        }
        Self { data }
    }

    fn lookup(&self, mu: f32, alpha: f32) -> f32 {
        let pos = |t: f32| {
            let s = t * (N - 1) as f32;
            let i = (s as usize).min(N - 2);
            (i, s - i as f32)
        };
        let (i, ti) = pos(axis(mu.max(0.0).sqrt(), MU_MIN.sqrt()));
        let (j, tj) = pos(axis(alpha, ALPHA_MIN));
        let at = |j: usize, i: usize| self.data[j * N + i];
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        lerp(
            lerp(at(j, i), at(j, i + 1), ti),
            lerp(at(j + 1, i), at(j + 1, i + 1), ti),
            tj,
        )
    }
}

/// `∫ D V μi dωi` at `wo` with cosine `mu`, by the midpoint rule on `q_mu × q_phi` cells
/// of the hemisphere (cells crowded towards the horizon, where the fibres reflect most).
/// `V` depends on the two cosines only, so each row of cells shares it, and a cell costs
/// one power (in `D`).
pub(crate) fn albedo_by_quadrature(mu: f32, alpha: f32, q_mu: usize, q_phi: usize) -> f32 {
    let wo = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let lambda_o = lambda(mu, alpha);
    let mut sum = 0.0f64;
    for a in 0..q_mu {
        // μi = 1 − (1 − v)²: the cell widths shrink towards μi = 0.
        let v = (a as f64 + 0.5) / q_mu as f64;
        let mu_i = (1.0 - (1.0 - v) * (1.0 - v)) as f32;
        let d_mu = 2.0 * (1.0 - v) / q_mu as f64;
        let sin_i = (1.0 - mu_i * mu_i).max(0.0).sqrt();
        let vis = 1.0 / ((1.0 + lambda_o + lambda(mu_i, alpha)) * (4.0 * mu * mu_i));
        let mut row = 0.0f64;
        for b in 0..q_phi {
            let phi = std::f64::consts::PI * (b as f64 + 0.5) / q_phi as f64;
            let (s, c) = crate::math::sin_cos_f64(phi);
            let wi = Vec3::new(sin_i * c as f32, sin_i * s as f32, mu_i);
            row += d(math::normalize_or(wo + wi, Vec3::Z).z, alpha) as f64;
        }
        // Both halves of the φ circle: 2π / q_phi per cell over [0, π).
        sum += row * (vis * mu_i) as f64 * d_mu * (std::f64::consts::TAU / q_phi as f64);
    }
    sum as f32
}

/// The lobe's directional albedo at cosine `mu` for sheen roughness `alpha`.
pub(crate) fn albedo(mu: f32, alpha: f32) -> f32 {
    static TABLE: OnceLock<Table> = OnceLock::new();
    TABLE.get_or_init(Table::build).lookup(mu, alpha)
}

/// Builds the albedo table now (see [`super::precompute_tables`]).
pub(crate) fn precompute() {
    albedo(1.0, 1.0);
}
