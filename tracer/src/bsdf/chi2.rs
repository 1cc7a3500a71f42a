//! Test utilities: a small deterministic RNG and a chi-square goodness-of-fit test for
//! direction samplers, after Mitsuba's `chi2` tests.
//!
//! The sphere is split into `n_cos × n_phi` cells of equal solid angle (uniform in cosθ
//! and φ). Sampled directions are counted per cell; the expected count of a cell is the
//! sample count times the pdf integrated over the cell (adaptive Simpson cubature in
//! (θ, φ), so that narrow lobes are resolved). Samples the sampler rejects (`None`) form one more cell whose
//! expected count is the pdf mass missing from the sphere, so a pdf that does not match
//! the sampler's failure rate is caught too. Cells expecting fewer than 5 samples are
//! pooled, and the statistic is compared with the χ² distribution.

use glam::Vec3;
use std::f64::consts::PI;

/// PCG32 (O'Neill), enough for tests and deterministic from its seed.
pub(crate) struct Rng {
    state: u64,
}

impl Rng {
    /// A generator for `seed`.
    pub(crate) fn new(seed: u64) -> Self {
        let mut r = Self {
            state: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xDA3E_39CB_94B9_5BDB,
        };
        r.next_u32();
        r
    }

    /// The next 32 random bits.
    pub(crate) fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// A uniform float in [0, 1).
    pub(crate) fn f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }
}

/// Grid and sample count of one test.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Config {
    /// Cells along cosθ ∈ [−1, 1] (even, so the horizon is a cell boundary).
    pub n_cos: usize,
    /// Cells along φ ∈ [0, 2π).
    pub n_phi: usize,
    /// Samples drawn.
    pub samples: usize,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            n_cos: 32,
            n_phi: 64,
            samples: 200_000,
        }
    }
}

/// The outcome of one test.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Outcome {
    /// The χ² statistic.
    pub stat: f64,
    /// Degrees of freedom (cells after pooling, minus one).
    pub dof: usize,
    /// Probability of a statistic at least this large if the sampler matches the pdf.
    pub p_value: f64,
    /// The pdf integrated over the sphere.
    pub pdf_mass: f64,
    /// Fraction of samples the sampler rejected.
    pub rejected: f64,
    /// The cells contributing most to the statistic: (cell, observed, expected); the
    /// cell index is `cos_index * n_phi + phi_index`, `n_cos * n_phi` for rejections.
    pub worst: [(usize, f64, f64); 3],
}

/// A rectangle in (θ, φ) or (cosθ, φ).
#[derive(Clone, Copy)]
struct Rect {
    t0: f64,
    t1: f64,
    p0: f64,
    p1: f64,
}

/// Simpson's rule on a 3 × 3 grid over `r`.
fn simpson(f: &impl Fn(f64, f64) -> f64, r: &Rect) -> f64 {
    const W: [f64; 3] = [1.0, 4.0, 1.0];
    let mut acc = 0.0;
    for (a, wa) in W.iter().enumerate() {
        let t = r.t0 + (r.t1 - r.t0) * a as f64 * 0.5;
        for (b, wb) in W.iter().enumerate() {
            let p = r.p0 + (r.p1 - r.p0) * b as f64 * 0.5;
            acc += wa * wb * f(t, p);
        }
    }
    acc * (r.t1 - r.t0) * (r.p1 - r.p0) / 36.0
}

/// Adaptive Simpson cubature: split into quadrants until they agree with the whole to
/// `tol` (absolute; halved per level) or to 1e-4 of the whole. The absolute tolerance of
/// a cell, 16 · 1e-8 of probability, is 0.03 samples at 200 000 samples.
fn adaptive(f: &impl Fn(f64, f64) -> f64, r: &Rect, whole: f64, tol: f64, depth: u32) -> f64 {
    let (tm, pm) = (0.5 * (r.t0 + r.t1), 0.5 * (r.p0 + r.p1));
    let quads = [
        Rect { t1: tm, p1: pm, ..*r },
        Rect { t0: tm, p1: pm, ..*r },
        Rect { t1: tm, p0: pm, ..*r },
        Rect { t0: tm, p0: pm, ..*r },
    ];
    let parts = quads.map(|q| simpson(f, &q));
    let sum: f64 = parts.iter().sum();
    if depth >= 12 || (sum - whole).abs() <= (15.0 * tol).max(1e-4 * sum.abs()) {
        return sum + (sum - whole) / 15.0;
    }
    quads
        .iter()
        .zip(parts)
        .map(|(q, part)| adaptive(f, q, part, tol * 0.5, depth + 1))
        .sum()
}

fn direction(cos_theta: f64, phi: f64) -> Vec3 {
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    Vec3::new(
        (sin_theta * phi.cos()) as f32,
        (sin_theta * phi.sin()) as f32,
        cos_theta as f32,
    )
}

fn cell_of(v: Vec3, cfg: &Config) -> usize {
    let c = ((f64::from(v.z).clamp(-1.0, 1.0) + 1.0) * 0.5 * cfg.n_cos as f64) as usize;
    let mut phi = f64::from(v.y).atan2(f64::from(v.x));
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let p = (phi / (2.0 * PI) * cfg.n_phi as f64) as usize;
    c.min(cfg.n_cos - 1) * cfg.n_phi + p.min(cfg.n_phi - 1)
}

/// Runs the test: `sample` draws one direction from the generator (or rejects), `pdf`
/// is the density the sampler claims, per unit solid angle.
pub(crate) fn run(
    cfg: Config,
    seed: u64,
    mut sample: impl FnMut(&mut Rng) -> Option<Vec3>,
    pdf: impl Fn(Vec3) -> f32,
) -> Outcome {
    let cells = cfg.n_cos * cfg.n_phi;
    // Observed counts, the last cell holding rejections.
    let mut observed = vec![0f64; cells + 1];
    let mut rng = Rng::new(seed);
    for _ in 0..cfg.samples {
        match sample(&mut rng) {
            Some(v) if v.is_finite() => observed[cell_of(v, &cfg)] += 1.0,
            Some(_) => panic!("sampler returned a non-finite direction"),
            None => observed[cells] += 1.0,
        }
    }

    // Expected counts: the pdf integrated over each cell, adaptively.
    let dc = 2.0 / cfg.n_cos as f64;
    let dp = 2.0 * PI / cfg.n_phi as f64;
    let mut expected = vec![0f64; cells + 1];
    let mut mass = 0.0;
    for ci in 0..cfg.n_cos {
        let (c0, c1) = (-1.0 + dc * ci as f64, -1.0 + dc * (ci + 1) as f64);
        // Sub-rectangles to start from, in (θ, φ) or in (cosθ, φ) with their Jacobians.
        // Away from the horizon integrate over θ: a lobe around the pole of width α has
        // width α²/2 in cosθ but α in θ. In the rows touching the horizon integrate over
        // cosθ on geometrically shrinking intervals: lobes of grazing directions hug the
        // horizon within a fraction of a degree and would slip between the samples.
        let mut starts: Vec<(Rect, bool)> = Vec::new();
        if c0 == 0.0 || c1 == 0.0 {
            let (lo, hi, sign) = if c0 == 0.0 { (0.0, c1, 1.0) } else { (0.0, -c0, -1.0) };
            let mut edges = vec![lo];
            let mut e = 1e-6;
            while e < hi {
                edges.push(e);
                e *= 3.0;
            }
            edges.push(hi);
            for w in edges.windows(2) {
                let (a, b) = if sign > 0.0 { (w[0], w[1]) } else { (-w[1], -w[0]) };
                starts.push((Rect { t0: a, t1: b, p0: 0.0, p1: 0.0 }, false));
            }
        } else {
            let t0 = c1.clamp(-1.0, 1.0).acos();
            let t1 = c0.clamp(-1.0, 1.0).acos();
            for a in 0..4 {
                let (x0, x1) = (t0 + (t1 - t0) * a as f64 / 4.0, t0 + (t1 - t0) * (a + 1) as f64 / 4.0);
                starts.push((Rect { t0: x0, t1: x1, p0: 0.0, p1: 0.0 }, true));
            }
        }
        for pi in 0..cfg.n_phi {
            let mut integral = 0.0;
            for &(band, in_theta) in &starts {
                let f = |x: f64, p: f64| {
                    let (cos, jac) = if in_theta { (x.cos(), x.sin()) } else { (x, 1.0) };
                    let v = f64::from(pdf(direction(cos, p)));
                    assert!(v.is_finite() && v >= 0.0, "pdf {v} at cos {cos} phi {p}");
                    v * jac
                };
                for b in 0..4 {
                    let sub = Rect {
                        p0: dp * (pi as f64 + b as f64 / 4.0),
                        p1: dp * (pi as f64 + (b + 1) as f64 / 4.0),
                        ..band
                    };
                    integral += adaptive(&f, &sub, simpson(&f, &sub), 1e-8, 0);
                }
            }
            mass += integral;
            expected[ci * cfg.n_phi + pi] = integral * cfg.samples as f64;
        }
    }
    expected[cells] = (1.0 - mass).max(0.0) * cfg.samples as f64;

    // Pool the cells expecting fewer than 5 samples, then sum (o − e)² / e.
    let mut order: Vec<usize> = (0..=cells).collect();
    order.sort_by(|&a, &b| expected[a].total_cmp(&expected[b]));
    let (mut stat, mut used) = (0.0, 0usize);
    let (mut pool_o, mut pool_e) = (0.0, 0.0);
    for &i in &order {
        let (o, e) = (observed[i], expected[i]);
        if e < 5.0 {
            pool_o += o;
            pool_e += e;
            if pool_e >= 5.0 {
                stat += (pool_o - pool_e).powi(2) / pool_e;
                used += 1;
                pool_o = 0.0;
                pool_e = 0.0;
            }
        } else {
            stat += (o - e).powi(2) / e;
            used += 1;
        }
    }
    if pool_e > 0.0 {
        // The leftover pool expects fewer than 5: count it as its own cell anyway when
        // something landed there that should not have.
        stat += (pool_o - pool_e).powi(2) / pool_e.max(1.0);
        used += 1;
    }
    let dof = used.saturating_sub(1).max(1);
    let mut worst = [(0, 0.0, 0.0); 3];
    let mut by_contribution: Vec<usize> = (0..=cells).filter(|&i| expected[i] >= 5.0).collect();
    by_contribution.sort_by(|&a, &b| {
        let c = |i: usize| (observed[i] - expected[i]).powi(2) / expected[i];
        c(b).total_cmp(&c(a))
    });
    for (w, &i) in worst.iter_mut().zip(&by_contribution) {
        *w = (i, observed[i], expected[i]);
    }
    Outcome {
        stat,
        dof,
        p_value: gamma_q(dof as f64 / 2.0, stat / 2.0),
        pdf_mass: mass,
        rejected: observed[cells] / cfg.samples as f64,
        worst,
    }
}

/// The significance each of `tests` tests must pass for an overall significance of
/// `alpha` (Šidák correction).
pub(crate) fn sidak(alpha: f64, tests: usize) -> f64 {
    1.0 - (1.0 - alpha).powf(1.0 / tests as f64)
}

/// ln Γ(x) for x > 0 (Lanczos, g = 7, 9 terms; ~1e-15 relative).
fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection formula.
        return (PI / (PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The regularised upper incomplete gamma function Q(a, x) = Γ(a, x)/Γ(a): the series
/// for P when x < a + 1, else Lentz's continued fraction (Numerical Recipes §6.2).
pub(crate) fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let ln_pre = -x + a * x.ln() - ln_gamma(a);
    if x < a + 1.0 {
        let (mut sum, mut term, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..100_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        (1.0 - sum * ln_pre.exp()).clamp(0.0, 1.0)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..100_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (ln_pre.exp() * h).clamp(0.0, 1.0)
    }
}

#[test]
fn gamma_q_matches_known_chi2_quantiles() {
    // χ² critical values at significance 0.01: dof 1 → 6.635, dof 10 → 23.209,
    // dof 100 → 135.807; and Q(1, x) = e^(−x).
    let q = |dof: f64, x: f64| gamma_q(dof / 2.0, x / 2.0);
    assert!((q(1.0, 6.635) - 0.01).abs() < 1e-4);
    assert!((q(10.0, 23.209) - 0.01).abs() < 1e-4);
    assert!((q(100.0, 135.807) - 0.01).abs() < 1e-4);
    assert!((gamma_q(1.0, 2.0) - (-2.0f64).exp()).abs() < 1e-12);
    assert!((gamma_q(3.0, 0.5) - 0.985_612_3).abs() < 1e-6);
}

#[test]
fn chi2_rejects_a_wrong_pdf() {
    // Uniform sphere sampling against the uniform pdf passes; against a cosine-skewed
    // pdf it fails.
    let sampler = |rng: &mut Rng| {
        let z = 1.0 - 2.0 * rng.f32();
        let phi = 2.0 * std::f32::consts::PI * rng.f32();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Some(Vec3::new(r * phi.cos(), r * phi.sin(), z))
    };
    let cfg = Config {
        samples: 100_000,
        ..Config::default()
    };
    let good = run(cfg, 1, sampler, |_| 0.25 / std::f32::consts::PI);
    assert!(good.p_value > 1e-3, "{good:?}");
    let bad = run(cfg, 1, sampler, |v| (1.0 + 0.1 * v.z) * 0.25 / std::f32::consts::PI);
    assert!(bad.p_value < 1e-6, "{bad:?}");
}

#[test]
fn scratch_adaptive_vs_brute() {
    use super::*;
    let bsdf = Bsdf::new(SurfaceParams { metallic: 0.0, transmission: 1.0, ..SurfaceParams::default() });
    let wo = Vec3::new(0.99999845, 0.0, -0.0017452986);
    let pdf = |v: Vec3| bsdf.pdf(wo, v);
    let (nc, np) = (32usize, 64usize);
    let dc = 2.0 / nc as f64;
    let dp = 2.0 * PI / np as f64;
    let mut diffs = Vec::new();
    for ci in 16..nc { for pi in 0..np {
        let theta_hi = (-1.0 + dc * ci as f64).clamp(-1.0, 1.0).acos();
        let theta_lo = (-1.0 + dc * (ci + 1) as f64).clamp(-1.0, 1.0).acos();
        let cell = Rect { t0: theta_lo, t1: theta_hi, p0: dp * pi as f64, p1: dp * (pi + 1) as f64 };
        let f = |t: f64, p: f64| f64::from(pdf(direction(t.cos(), p))) * t.sin();
        let mut integral = 0.0;
        for a in 0..4 { for b in 0..4 {
            let sub = Rect {
                t0: cell.t0 + (cell.t1 - cell.t0) * a as f64 / 4.0,
                t1: cell.t0 + (cell.t1 - cell.t0) * (a + 1) as f64 / 4.0,
                p0: cell.p0 + (cell.p1 - cell.p0) * b as f64 / 4.0,
                p1: cell.p0 + (cell.p1 - cell.p0) * (b + 1) as f64 / 4.0,
            };
            integral += adaptive(&f, &sub, simpson(&f, &sub), 1e-8, 0);
        }}
        let k = 64;
        let mut acc = 0.0;
        for a in 0..k { for b in 0..k {
            let c = -1.0 + dc * (ci as f64 + (a as f64 + 0.5) / k as f64);
            let p = dp * (pi as f64 + (b as f64 + 0.5) / k as f64);
            acc += f64::from(pdf(direction(c, p)));
        }}
        let brute = acc / (k * k) as f64 * dc * dp;
        diffs.push(((integral - brute).abs() * 2e5, ci, pi, integral * 2e5, brute * 2e5));
    }}
    diffs.sort_by(|a, b| b.0.total_cmp(&a.0));
    for d in &diffs[..10] { println!("{d:?}"); }
}
