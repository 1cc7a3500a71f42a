//! Test utilities: a small deterministic RNG and a chi-square goodness-of-fit test for
//! direction samplers, after Mitsuba's `chi2` tests.
//!
//! The sphere is split into `n_cos × n_phi` cells of equal solid angle (uniform in cosθ
//! and φ). Sampled directions are counted per cell; the expected count of a cell is the
//! sample count times the pdf integrated over the cell by adaptive Simpson cubature
//! (in θ near the poles and in cosθ near the horizon, refined wherever the samples crowd,
//! so that lobes far narrower than a cell are resolved). Samples the sampler rejects
//! (`None`) form one more cell whose expected count is the pdf mass missing from the
//! sphere, so a pdf that disagrees with the sampler's failure rate is caught too. Cells
//! expecting fewer than 5 samples are pooled, and the statistic is compared with the χ²
//! distribution.

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
            n_cos: 16,
            n_phi: 32,
            samples: 100_000,
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

/// Simpson weights on three points.
const SIMPSON: [f64; 3] = [1.0, 4.0, 1.0];

/// `f` on the 3 × 3 grid of `r` (corners, edge midpoints, centre).
fn grid3(f: &impl Fn(f64, f64) -> f64, r: &Rect) -> [[f64; 3]; 3] {
    let mut v = [[0.0; 3]; 3];
    for (a, row) in v.iter_mut().enumerate() {
        for (b, x) in row.iter_mut().enumerate() {
            *x = f(
                r.t0 + (r.t1 - r.t0) * a as f64 * 0.5,
                r.p0 + (r.p1 - r.p0) * b as f64 * 0.5,
            );
        }
    }
    v
}

/// Simpson's rule over `r` from its 3 × 3 grid values.
fn simpson(r: &Rect, v: &[[f64; 3]; 3]) -> f64 {
    let mut acc = 0.0;
    for (a, row) in v.iter().enumerate() {
        for (b, x) in row.iter().enumerate() {
            acc += SIMPSON[a] * SIMPSON[b] * x;
        }
    }
    acc * (r.t1 - r.t0) * (r.p1 - r.p0) / 36.0
}

/// How the adaptive cubature refines.
struct Refine {
    /// Absolute tolerance of a start rectangle (halved per level).
    tol: f64,
    /// A rectangle holding more sampled directions than this is split regardless of the
    /// error estimate.
    max_points: usize,
}

/// Adaptive Simpson cubature over `r`, whose 3 × 3 grid values are `v`: split into
/// quadrants (16 new evaluations, the rest shared) until they agree with the whole to
/// `tol` or to 1e-3 of the whole. An error estimate cannot see a lobe that lies between
/// all the points it looked at, so a rectangle is also split while it holds more than
/// `max_points` of the sampled directions `points` (in the rectangle's coordinates): the
/// sampler shows where narrow lobes are. (This only picks where to refine; the integral
/// does not depend on the samples otherwise.)
fn adaptive(
    f: &impl Fn(f64, f64) -> f64,
    r: &Rect,
    v: &[[f64; 3]; 3],
    refine: &Refine,
    points: &[(f64, f64)],
    depth: u32,
) -> f64 {
    let whole = simpson(r, v);
    // The 5 × 5 grid: even indices are the parent's points.
    let mut g = [[0.0; 5]; 5];
    for (a, row) in g.iter_mut().enumerate() {
        for (b, x) in row.iter_mut().enumerate() {
            *x = if a % 2 == 0 && b % 2 == 0 {
                v[a / 2][b / 2]
            } else {
                f(
                    r.t0 + (r.t1 - r.t0) * a as f64 * 0.25,
                    r.p0 + (r.p1 - r.p0) * b as f64 * 0.25,
                )
            };
        }
    }
    let (tm, pm) = (0.5 * (r.t0 + r.t1), 0.5 * (r.p0 + r.p1));
    let quads = [
        (
            Rect {
                t1: tm,
                p1: pm,
                ..*r
            },
            0,
            0,
        ),
        (
            Rect {
                t0: tm,
                p1: pm,
                ..*r
            },
            2,
            0,
        ),
        (
            Rect {
                t1: tm,
                p0: pm,
                ..*r
            },
            0,
            2,
        ),
        (
            Rect {
                t0: tm,
                p0: pm,
                ..*r
            },
            2,
            2,
        ),
    ];
    let sub = |a0: usize, b0: usize| {
        let mut s = [[0.0; 3]; 3];
        for (a, row) in s.iter_mut().enumerate() {
            for (b, x) in row.iter_mut().enumerate() {
                *x = g[a0 + a][b0 + b];
            }
        }
        s
    };
    let parts = quads.map(|(q, a0, b0)| (q, sub(a0, b0)));
    let sum: f64 = parts.iter().map(|(q, s)| simpson(q, s)).sum();
    let tol = refine.tol * 0.5f64.powi(depth as i32);
    let converged = (sum - whole).abs() <= (15.0 * tol).max(1e-3 * sum.abs());
    if depth >= 10 || (converged && points.len() <= refine.max_points) {
        return sum + (sum - whole) / 15.0;
    }
    parts
        .iter()
        .map(|(q, s)| {
            let inside: Vec<(f64, f64)> = points
                .iter()
                .copied()
                .filter(|&(t, p)| t >= q.t0 && t < q.t1 && p >= q.p0 && p < q.p1)
                .collect();
            adaptive(f, q, s, refine, &inside, depth + 1)
        })
        .sum()
}

/// The bands (φ range left empty) to start integrating the row `[c0, c1]` of cosθ from,
/// each flagged whether it is in θ (else in cosθ). Bands are in θ, because a lobe around
/// the pole of width α has width α²/2 in cosθ but α in θ: `k` of them, or, in the rows
/// holding a pole, bands that shrink geometrically towards it, because a lobe at normal
/// incidence may be narrower than any fixed split. In the rows touching the horizon the
/// bands are in cosθ and shrink geometrically towards it, because lobes of grazing
/// directions hug the horizon within a fraction of a degree.
fn bands(c0: f64, c1: f64, k: usize) -> Vec<(Rect, bool)> {
    // Edges from `from` towards `to` at distances 0, 1e-6·4ⁿ, ..., |to − from|.
    let geometric = |from: f64, to: f64, in_theta: bool| {
        let span = (to - from).abs();
        let mut d = vec![0.0];
        let mut e = 1e-6;
        while e < span {
            d.push(e);
            e *= 4.0;
        }
        d.push(span);
        let sign = (to - from).signum();
        d.windows(2)
            .map(|w| {
                let (a, b) = (from + sign * w[0], from + sign * w[1]);
                let rect = Rect {
                    t0: a.min(b),
                    t1: a.max(b),
                    p0: 0.0,
                    p1: 0.0,
                };
                (rect, in_theta)
            })
            .collect::<Vec<_>>()
    };
    let (t_lo, t_hi) = (c1.clamp(-1.0, 1.0).acos(), c0.clamp(-1.0, 1.0).acos());
    if c0 == 0.0 {
        geometric(0.0, c1, false)
    } else if c1 == 0.0 {
        geometric(0.0, c0, false)
    } else if c1 >= 1.0 {
        geometric(0.0, t_hi, true)
    } else if c0 <= -1.0 {
        geometric(PI, t_lo, true)
    } else {
        (0..k)
            .map(|a| {
                let rect = Rect {
                    t0: t_lo + (t_hi - t_lo) * a as f64 / k as f64,
                    t1: t_lo + (t_hi - t_lo) * (a + 1) as f64 / k as f64,
                    p0: 0.0,
                    p1: 0.0,
                };
                (rect, true)
            })
            .collect()
    }
}

fn direction(cos_theta: f64, phi: f64) -> Vec3 {
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    Vec3::new(
        (sin_theta * phi.cos()) as f32,
        (sin_theta * phi.sin()) as f32,
        cos_theta as f32,
    )
}

fn phi_of(v: Vec3) -> f64 {
    let phi = f64::from(v.y).atan2(f64::from(v.x));
    if phi < 0.0 {
        phi + 2.0 * PI
    } else {
        phi
    }
}

fn cell_of(v: Vec3, cfg: &Config) -> usize {
    let c = ((f64::from(v.z).clamp(-1.0, 1.0) + 1.0) * 0.5 * cfg.n_cos as f64) as usize;
    let p = (phi_of(v) / (2.0 * PI) * cfg.n_phi as f64) as usize;
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
    // The sampled directions per cell, as (cosθ, φ).
    let mut points: Vec<Vec<(f64, f64)>> = vec![Vec::new(); cells];
    let mut rng = Rng::new(seed);
    for _ in 0..cfg.samples {
        match sample(&mut rng) {
            Some(v) if v.is_finite() => {
                let cell = cell_of(v, &cfg);
                observed[cell] += 1.0;
                points[cell].push((f64::from(v.z).clamp(-1.0, 1.0), phi_of(v)));
            }
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
        for pi in 0..cfg.n_phi {
            let cell = ci * cfg.n_phi + pi;
            let refine = Refine {
                tol: 1e-6,
                max_points: cfg.samples / 1000,
            };
            let mut integral = 0.0;
            for &(band, in_theta) in &bands(c0, c1, 2) {
                let f = |x: f64, p: f64| {
                    let (cos, jac) = if in_theta {
                        (x.cos(), x.sin())
                    } else {
                        (x, 1.0)
                    };
                    let v = f64::from(pdf(direction(cos, p)));
                    assert!(v.is_finite() && v >= 0.0, "pdf {v} at cos {cos} phi {p}");
                    v * jac
                };
                // The cell's samples in the band's coordinates.
                let pts: Vec<(f64, f64)> = points[cell]
                    .iter()
                    .map(|&(c, p)| (if in_theta { c.acos() } else { c }, p))
                    .collect();
                for b in 0..2 {
                    let sub = Rect {
                        p0: dp * (pi as f64 + b as f64 / 2.0),
                        p1: dp * (pi as f64 + (b + 1) as f64 / 2.0),
                        ..band
                    };
                    let inside: Vec<(f64, f64)> = pts
                        .iter()
                        .copied()
                        .filter(|&(t, p)| t >= sub.t0 && t <= sub.t1 && p >= sub.p0 && p < sub.p1)
                        .collect();
                    integral += adaptive(&f, &sub, &grid3(&f, &sub), &refine, &inside, 0);
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
    let bad = run(cfg, 1, sampler, |v| {
        (1.0 + 0.1 * v.z) * 0.25 / std::f32::consts::PI
    });
    assert!(bad.p_value < 1e-6, "{bad:?}");
}
