//! Sampling tables: piecewise-constant 1D and 2D distributions (pbrt's
//! `PiecewiseConstant1D`/`2D`) and Vose's alias table for picking one of many items in O(1).
//!
//! Every table is built in O(n) and never produces NaN: an all-zero (or empty) input gives a
//! table that reports a zero integral, and samplers of such a table must not be called
//! (callers check [`Distribution1D::integral`] or get `None` from [`AliasTable::new`]).

/// Accumulates in f64 so that tables of millions of entries (a 4k environment map) keep
/// their small entries.
fn normalised_cdf(func: &[f32]) -> (Vec<f32>, f64) {
    let n = func.len();
    let mut acc = Vec::with_capacity(n + 1);
    let mut sum = 0.0f64;
    acc.push(0.0f64);
    for &f in func {
        sum += f as f64;
        acc.push(sum);
    }
    let mut cdf: Vec<f32> = if sum > 0.0 {
        acc.iter().map(|&a| (a / sum) as f32).collect()
    } else {
        // Nothing to prefer: a uniform CDF keeps the sampler defined.
        (0..=n).map(|i| i as f32 / n.max(1) as f32).collect()
    };
    // The last entry is exactly one, so `u < 1` always lands in a bin of non-zero width.
    if let Some(last) = cdf.last_mut() {
        *last = 1.0;
    }
    (cdf, sum)
}

/// A piecewise-constant density on [0, 1) with `len()` equal bins.
#[derive(Clone, Debug)]
pub struct Distribution1D {
    func: Vec<f32>,
    cdf: Vec<f32>,
    /// ∫ f over [0, 1): the mean of `func`.
    integral: f32,
}

impl Distribution1D {
    /// A distribution proportional to `func` (one value per bin). Negative and non-finite
    /// values count as zero.
    pub fn new(func: &[f32]) -> Self {
        let func: Vec<f32> = func
            .iter()
            .map(|&f| if f.is_finite() && f > 0.0 { f } else { 0.0 })
            .collect();
        let (cdf, sum) = normalised_cdf(&func);
        let integral = if func.is_empty() {
            0.0
        } else {
            (sum / func.len() as f64) as f32
        };
        Self {
            func,
            cdf,
            integral,
        }
    }

    /// Number of bins.
    pub fn len(&self) -> usize {
        self.func.len()
    }

    /// Whether there are no bins.
    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }

    /// ∫ f(x) dx over [0, 1); zero when nothing can be sampled.
    pub fn integral(&self) -> f32 {
        self.integral
    }

    /// The (non-negative) function value of bin `i`.
    pub fn func(&self, i: usize) -> f32 {
        self.func[i]
    }

    /// Index of the bin whose CDF interval holds `u`, never one of zero width.
    fn find(&self, u: f32) -> usize {
        // Largest i with cdf[i] <= u; cdf[n] == 1 > u, so i < n and cdf[i + 1] > u.
        let i = self.cdf.partition_point(|&c| c <= u);
        i.saturating_sub(1).min(self.func.len().saturating_sub(1))
    }

    /// Samples x in [0, 1) for `u` in [0, 1). Returns (x, density at x, bin index).
    pub fn sample_continuous(&self, u: f32) -> (f32, f32, usize) {
        let i = self.find(u);
        let (c0, c1) = (self.cdf[i], self.cdf[i + 1]);
        let du = if c1 > c0 {
            ((u - c0) / (c1 - c0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let n = self.func.len() as f32;
        let x = ((i as f32 + du) / n).min(1.0 - f32::EPSILON / 2.0);
        (x, self.pdf_bin(i), i)
    }

    /// Picks bin `i` with probability func(i) / Σ func. Returns (i, that probability, `u`
    /// re-stretched to [0, 1) within the bin, for reuse).
    pub fn sample_discrete(&self, u: f32) -> (usize, f32, f32) {
        let i = self.find(u);
        let (c0, c1) = (self.cdf[i], self.cdf[i + 1]);
        let remapped = if c1 > c0 {
            ((u - c0) / (c1 - c0)).clamp(0.0, 1.0 - f32::EPSILON)
        } else {
            0.0
        };
        (i, self.discrete_probability(i), remapped)
    }

    /// Probability of bin `i` under [`Self::sample_discrete`].
    pub fn discrete_probability(&self, i: usize) -> f32 {
        self.pdf_bin(i) / self.func.len() as f32
    }

    /// Density of [`Self::sample_continuous`] at x in [0, 1).
    pub fn pdf(&self, x: f32) -> f32 {
        if self.func.is_empty() || !(0.0..=1.0).contains(&x) {
            return 0.0;
        }
        let i = ((x * self.func.len() as f32) as usize).min(self.func.len() - 1);
        self.pdf_bin(i)
    }

    fn pdf_bin(&self, i: usize) -> f32 {
        if self.integral > 0.0 {
            self.func[i] / self.integral
        } else {
            0.0
        }
    }
}

/// A piecewise-constant density on [0, 1)² over a `width` × `height` grid: a marginal
/// distribution over rows (v) and one conditional distribution over columns (u) per row.
#[derive(Clone, Debug)]
pub struct Distribution2D {
    conditional: Vec<Distribution1D>,
    marginal: Distribution1D,
}

impl Distribution2D {
    /// A distribution proportional to `func`, stored row by row (`func[v * width + u]`).
    ///
    /// # Panics
    /// When `func.len() != width * height`; callers validate sizes first.
    pub fn new(func: &[f32], width: usize, height: usize) -> Self {
        assert_eq!(func.len(), width * height, "Distribution2D: size mismatch");
        let conditional: Vec<Distribution1D> = if width == 0 {
            Vec::new()
        } else {
            func.chunks_exact(width).map(Distribution1D::new).collect()
        };
        let row_integrals: Vec<f32> = conditional.iter().map(|c| c.integral()).collect();
        let marginal = Distribution1D::new(&row_integrals);
        Self {
            conditional,
            marginal,
        }
    }

    /// ∫∫ f over [0, 1)²; zero when nothing can be sampled.
    pub fn integral(&self) -> f32 {
        self.marginal.integral()
    }

    /// Samples (u, v) in [0, 1)². Returns the point and its density (0 if the table is
    /// all zero).
    pub fn sample(&self, u: glam::Vec2) -> (glam::Vec2, f32) {
        let (v, pdf_v, row) = self.marginal.sample_continuous(u.y);
        let (x, pdf_u, _) = self.conditional[row].sample_continuous(u.x);
        (glam::Vec2::new(x, v), pdf_u * pdf_v)
    }

    /// Density of [`Self::sample`] at (u, v).
    pub fn pdf(&self, uv: glam::Vec2) -> f32 {
        let h = self.conditional.len();
        if h == 0 || self.marginal.integral() <= 0.0 {
            return 0.0;
        }
        let row = ((uv.y.clamp(0.0, 1.0) * h as f32) as usize).min(h - 1);
        let c = &self.conditional[row];
        let col = ((uv.x.clamp(0.0, 1.0) * c.len() as f32) as usize).min(c.len() - 1);
        c.func(col) / self.marginal.integral()
    }
}

/// Vose's alias table: picks item i with probability w_i / Σ w in O(1), built in O(n).
#[derive(Clone, Debug)]
pub struct AliasTable {
    /// (probability of keeping this bin, alias index) per bin.
    bins: Vec<(f32, u32)>,
    /// Normalised probability of each item.
    probability: Vec<f32>,
}

impl AliasTable {
    /// A table over `weights`; `None` when there is nothing to pick (no weight is positive
    /// and finite). Negative and non-finite weights count as zero.
    pub fn new(weights: &[f64]) -> Option<Self> {
        let clean = |w: f64| if w.is_finite() && w > 0.0 { w } else { 0.0 };
        let total: f64 = weights.iter().map(|&w| clean(w)).sum();
        if !(total > 0.0 && total.is_finite()) || weights.len() > u32::MAX as usize {
            return None;
        }
        let n = weights.len();
        let probability: Vec<f32> = weights.iter().map(|&w| (clean(w) / total) as f32).collect();
        // Scaled weights: mean 1. Split into bins below and above the mean.
        let mut scaled: Vec<f64> = weights
            .iter()
            .map(|&w| clean(w) / total * n as f64)
            .collect();
        let mut small = Vec::new();
        let mut large = Vec::new();
        for (i, &s) in scaled.iter().enumerate() {
            if s < 1.0 {
                small.push(i as u32);
            } else {
                large.push(i as u32);
            }
        }
        let mut bins = vec![(1.0f32, 0u32); n];
        for (i, bin) in bins.iter_mut().enumerate() {
            bin.1 = i as u32;
        }
        while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
            small.pop();
            large.pop();
            bins[s as usize] = (scaled[s as usize] as f32, l);
            // The large item gives away what fills the small bin.
            scaled[l as usize] -= 1.0 - scaled[s as usize];
            if scaled[l as usize] < 1.0 {
                small.push(l);
            } else {
                large.push(l);
            }
        }
        // What remains is 1 up to rounding: those bins keep themselves.
        for i in small.into_iter().chain(large) {
            bins[i as usize] = (1.0, i);
        }
        Some(Self { bins, probability })
    }

    /// Number of items.
    pub fn len(&self) -> usize {
        self.bins.len()
    }

    /// Whether the table holds no items (never true for a built table).
    pub fn is_empty(&self) -> bool {
        self.bins.is_empty()
    }

    /// Picks an item for `u` in [0, 1). Returns (index, its probability).
    pub fn sample(&self, u: f32) -> (usize, f32) {
        let n = self.bins.len();
        let scaled = u.clamp(0.0, 1.0) * n as f32;
        let bin = (scaled as usize).min(n - 1);
        let rest = scaled - bin as f32;
        let (keep, alias) = self.bins[bin];
        let i = if rest < keep { bin } else { alias as usize };
        (i, self.probability[i])
    }

    /// Probability of item `i` (0 for an index out of range).
    pub fn probability(&self, i: usize) -> f32 {
        self.probability.get(i).copied().unwrap_or(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_rng::Rng;

    #[test]
    fn one_d_samples_follow_the_function_and_skip_zero_bins() {
        let d = Distribution1D::new(&[0.0, 1.0, 3.0, 0.0, 4.0, 0.0]);
        assert!((d.integral() - 8.0 / 6.0).abs() < 1e-6);
        let mut counts = [0usize; 6];
        let mut rng = Rng(1);
        let n = 200_000;
        for _ in 0..n {
            let (x, pdf, i) = d.sample_continuous(rng.next_f32());
            assert!((0.0..1.0).contains(&x));
            assert_eq!(i, (x * 6.0) as usize);
            assert!(pdf > 0.0);
            assert_eq!(pdf, d.pdf(x));
            counts[i] += 1;
        }
        for (i, &w) in [0.0, 1.0, 3.0, 0.0, 4.0, 0.0].iter().enumerate() {
            let frac = counts[i] as f64 / n as f64;
            assert!((frac - w / 8.0).abs() < 0.005, "bin {i}: {frac}");
        }
        // Edge values of u never land in a zero bin.
        for u in [0.0, 1.0 - f32::EPSILON, 0.125, 0.5] {
            let (_, pdf, _) = d.sample_continuous(u);
            assert!(pdf > 0.0, "u = {u}");
        }
    }

    #[test]
    fn zero_and_empty_tables_report_zero() {
        let d = Distribution1D::new(&[0.0, 0.0, f32::NAN, -1.0]);
        assert_eq!(d.integral(), 0.0);
        assert_eq!(d.pdf(0.3), 0.0);
        let d2 = Distribution2D::new(&[0.0; 6], 3, 2);
        assert_eq!(d2.integral(), 0.0);
        assert_eq!(d2.pdf(glam::Vec2::splat(0.5)), 0.0);
        assert!(AliasTable::new(&[]).is_none());
        assert!(AliasTable::new(&[0.0, -2.0, f64::NAN]).is_none());
    }

    #[test]
    fn two_d_pdf_integrates_to_one_and_matches_samples() {
        let (w, h) = (7, 5);
        let func: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 11) as f32).collect();
        let d = Distribution2D::new(&func, w, h);
        // Midpoint rule over the grid is exact for a piecewise-constant density.
        let mut sum = 0.0;
        for y in 0..h {
            for x in 0..w {
                let uv = glam::Vec2::new((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
                sum += d.pdf(uv) / (w * h) as f32;
            }
        }
        assert!((sum - 1.0).abs() < 1e-5, "{sum}");
        let mut rng = Rng(7);
        for _ in 0..10_000 {
            let (uv, pdf) = d.sample(glam::Vec2::new(rng.next_f32(), rng.next_f32()));
            assert!(pdf > 0.0);
            assert!(
                (pdf - d.pdf(uv)).abs() <= 1e-5 * pdf,
                "{pdf} vs {}",
                d.pdf(uv)
            );
        }
    }

    #[test]
    fn alias_table_frequencies_match_weights() {
        let weights = [1e-3, 5.0, 0.0, 2.0, 3.0, 0.5];
        let t = AliasTable::new(&weights).unwrap();
        let total: f64 = weights.iter().sum();
        let mut counts = vec![0usize; weights.len()];
        let mut rng = Rng(3);
        let n = 400_000;
        for _ in 0..n {
            let (i, p) = t.sample(rng.next_f32());
            assert!((p as f64 - weights[i] / total).abs() < 1e-6);
            counts[i] += 1;
        }
        assert_eq!(counts[2], 0);
        for (i, &w) in weights.iter().enumerate() {
            let frac = counts[i] as f64 / n as f64;
            assert!(
                (frac - w / total).abs() < 0.004,
                "item {i}: {frac} vs {}",
                w / total
            );
        }
    }

    #[test]
    fn alias_table_builds_for_many_items_of_wild_range() {
        let weights: Vec<f64> = (0..20_000)
            .map(|i| if i % 2 == 0 { 1e-6 } else { 1e6 })
            .collect();
        let t = AliasTable::new(&weights).unwrap();
        let sum: f64 = (0..t.len()).map(|i| t.probability(i) as f64).sum();
        assert!((sum - 1.0).abs() < 1e-4);
        let (i, p) = t.sample(0.999_999_9);
        assert!(i < t.len() && p > 0.0);
    }
}
