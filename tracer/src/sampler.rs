//! Random numbers as a pure function of (pixel, sample index, dimension, frame, seed).
//!
//! Each pair of dimensions is a 2D Owen-scrambled Sobol sequence whose sample index is
//! itself shuffled by a hash of (pixel, dimension, frame, seed): Burley 2020, "Practical
//! Hash-based Owen Scrambling". Every pixel gets a decorrelated low-discrepancy sequence,
//! any prefix of it is well stratified (so spp need not be a power of two), and nothing
//! depends on the tile, the thread or the time of day: a frame split into any tiles is
//! bit-identical to the same frame rendered whole.

use glam::Vec2;

#[cfg(target_arch = "x86_64")]
mod sse;

/// A well-mixed 32-bit hash (Wellons' "lowbias32").
pub const fn hash_u32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// Combines a hash with another value (boost's hash_combine, on a mixed value).
pub fn hash_combine(seed: u32, v: u32) -> u32 {
    combine_hashed(seed, hash_u32(v))
}

/// [`hash_combine`] of a value whose [`hash_u32`] is `hashed`.
#[inline(always)]
fn combine_hashed(seed: u32, hashed: u32) -> u32 {
    seed ^ (hashed
        .wrapping_add(0x9e37_79b9)
        .wrapping_add(seed << 6)
        .wrapping_add(seed >> 2))
}

/// [`hash_u32`] of the dimensions below 128 (those of paths up to 25 bounces deep), at
/// compile time: every dimension a sample draws hashes its number first.
const DIMENSION_HASHES: [u32; 128] = {
    let mut h = [0; 128];
    let mut d = 0;
    while d < h.len() {
        h[d] = hash_u32(d as u32);
        d += 1;
    }
    h
};

/// Laine-Karras style permutation: a nested uniform scramble of the bit-reversed value.
fn laine_karras_permutation(mut x: u32, seed: u32) -> u32 {
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x
}

/// Owen scrambling of the 32-bit fixed-point value whose bits, reversed, are `reversed`:
/// Laine-Karras permutes the bit-reversed value, then the bits are put back in order.
/// (Callers that hold a value reversed already skip one reversal of two.)
fn scramble_reversed(reversed: u32, seed: u32) -> u32 {
    laine_karras_permutation(reversed, seed).reverse_bits()
}

/// Direction vectors of the second Sobol dimension (the Pascal matrix mod 2): bit `i` of
/// the index toggles `SOBOL1_DIRECTIONS[i]`.
const SOBOL1_DIRECTIONS: [u32; 32] = {
    let mut v = [0u32; 32];
    let mut d = 1u32 << 31;
    let mut i = 0;
    while i < 32 {
        v[i] = d;
        d ^= d >> 1;
        i += 1;
    }
    v
};

/// The same matrix applied a byte at a time, its result bit-reversed (as Owen scrambling
/// wants it): entry `[k][b]` is the XOR of the direction vectors of the set bits of byte
/// value `b` at byte position `k`, reversed. Scrambled indices use all 32 bits, so this
/// replaces a 32-step loop with four lookups.
const SOBOL1_BYTES_REVERSED: [[u32; 256]; 4] = {
    let mut t = [[0u32; 256]; 4];
    let mut k = 0;
    while k < 4 {
        let mut b = 0;
        while b < 256 {
            let mut x = 0u32;
            let mut bit = 0;
            while bit < 8 {
                if b & (1 << bit) != 0 {
                    x ^= SOBOL1_DIRECTIONS[k * 8 + bit];
                }
                bit += 1;
            }
            t[k][b] = x.reverse_bits();
            b += 1;
        }
        k += 1;
    }
    t
};

/// The second Sobol dimension (the Pascal matrix) of `index`, bit-reversed. (The first,
/// van der Corput, is the index reversed.)
fn sobol1_reversed(index: u32) -> u32 {
    let b = index.to_le_bytes();
    SOBOL1_BYTES_REVERSED[0][b[0] as usize]
        ^ SOBOL1_BYTES_REVERSED[1][b[1] as usize]
        ^ SOBOL1_BYTES_REVERSED[2][b[2] as usize]
        ^ SOBOL1_BYTES_REVERSED[3][b[3] as usize]
}

/// 32-bit fixed point to a float in [0, 1): keep 24 bits so the result is never 1.0.
fn to_unit(x: u32) -> f32 {
    (x >> 8) as f32 * TO_UNIT
}

/// The step between 24-bit fixed-point values ([`to_unit`]).
const TO_UNIT: f32 = 1.0 / (1u32 << 24) as f32;

/// The random numbers of one camera sample of one pixel. Each call consumes the next
/// dimension, so the order of calls must itself be deterministic (it is: the integrator
/// draws dimensions in a fixed order per bounce).
#[derive(Clone, Debug)]
pub struct PixelSampler {
    pixel_seed: u32,
    /// The sample index with its bits reversed, as every dimension's scramble takes it.
    index_reversed: u32,
    dimension: u32,
}

impl PixelSampler {
    /// The sampler for sample `index` of pixel (`x`, `y`) in `frame`, with a user `seed`.
    pub fn new(x: u32, y: u32, index: u32, frame: i32, seed: u32) -> Self {
        let pixel_seed = hash_combine(
            hash_combine(hash_combine(hash_u32(x), y), frame as u32),
            seed,
        );
        Self {
            pixel_seed,
            index_reversed: index.reverse_bits(),
            dimension: 0,
        }
    }

    /// Continues at a given dimension (so a feature that is off need not shift the
    /// dimensions of the ones after it).
    pub fn start_dimension(&mut self, dimension: u32) {
        self.dimension = dimension;
    }

    /// An independent sampler for copy `branch` of a split path, at the same dimension:
    /// the copies must not repeat each other's choices, and remain a pure function of
    /// the sample and the order in which the path split.
    pub fn branch(&self, branch: u32) -> Self {
        Self {
            pixel_seed: hash_combine(self.pixel_seed, 0xb5ad_4ece ^ branch),
            ..*self
        }
    }

    /// The next dimension pair as a point in [0,1)².
    // Inlined, as `next_1d` is: left to itself the compiler called it out of line from one
    // place in the path loop, and the call cost more than the table below saved.
    #[inline(always)]
    pub fn next_2d(&mut self) -> Vec2 {
        let (shuffled, seed) = self.next_shuffled();
        let y = scramble_reversed(
            sobol1_reversed(shuffled),
            combine_hashed(seed, SECOND_COORDINATE),
        );
        Vec2::new(to_unit(Self::first(shuffled, seed)), to_unit(y))
    }

    /// Advances to the next dimension: its seed, and the sample index shuffled for it (Owen
    /// scrambled, so that each dimension visits the sequence in its own order).
    #[inline(always)]
    fn next_shuffled(&mut self) -> (u32, u32) {
        let d = self.dimension;
        let hashed = match DIMENSION_HASHES.get(d as usize) {
            Some(&h) => h,
            None => hash_u32(d),
        };
        let seed = combine_hashed(self.pixel_seed, hashed);
        self.dimension += 1;
        (scramble_reversed(self.index_reversed, seed), seed)
    }

    /// The first coordinate of the point: van der Corput of the shuffled index, which is
    /// that index reversed, scrambled (whose reversal undoes that one).
    fn first(shuffled: u32, seed: u32) -> u32 {
        scramble_reversed(shuffled, combine_hashed(seed, FIRST_COORDINATE))
    }

    /// The next dimension as a number in [0,1) (the first coordinate of a 2D point, so
    /// that 1D dimensions are stratified too; the second is not computed).
    #[inline(always)]
    pub fn next_1d(&mut self) -> f32 {
        let (shuffled, seed) = self.next_shuffled();
        to_unit(Self::first(shuffled, seed))
    }

    /// What a bounce draws, from dimension `dimension` on: the values of five calls
    /// `next_1d`, `next_2d`, `next_1d`, `next_2d`, `next_1d`, the same bits, computed
    /// together in lanes: the scrambles of the five dimensions in one pass, then the seven
    /// coordinates in another. Leaves the sampler where those calls would.
    #[inline(always)]
    pub fn next_bounce(&mut self, dimension: u32) -> BounceDimensions {
        let hashed = bounce_hashes(dimension);
        self.dimension = dimension + BOUNCE_DIMENSIONS;
        let seed = hashed.map(|h| combine_hashed(self.pixel_seed, h));
        let shuffled = seed.map(|s| scramble_reversed(self.index_reversed, s));
        let value: Lanes = std::array::from_fn(|k| {
            if k < FIRST_LANES {
                shuffled[k]
            } else {
                sobol1_reversed(shuffled[k])
            }
        });
        let u: [f32; LANES] = std::array::from_fn(|k| {
            to_unit(scramble_reversed(
                value[k],
                combine_hashed(seed[k], lane_seed(k)),
            ))
        });
        BounceDimensions::from_lanes(u)
    }

    /// [`Self::next_bounce`] with its lanes in SSE registers (`sampler/sse.rs`): the same
    /// bits. Left to itself, the compiler computed some lanes in SSE and the rest one at a
    /// time, in twice the instructions.
    ///
    /// # Safety
    /// The CPU must have SSE4.1 and SSSE3 (every CPU with AVX has).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) unsafe fn next_bounce_sse41(&mut self, dimension: u32) -> BounceDimensions {
        let hashed = bounce_hashes(dimension);
        self.dimension = dimension + BOUNCE_DIMENSIONS;
        // SAFETY: the caller's promise.
        unsafe { sse::bounce(self.pixel_seed, self.index_reversed, hashed) }
    }
}

/// Which of a bounce's dimensions each lane of [`PixelSampler::next_bounce`] draws: lanes
/// 0 to 4 the five dimensions' first coordinates, lanes 5 and 6 the second coordinates of
/// the two 2D ones (1 and 3), and lane 7 lane 6 again. Every lane does the same work, so
/// that the passes run in SIMD lanes whole.
const LANE_DIMENSION: Lanes = [0, 1, 2, 3, 4, 1, 3, 3];

/// Lanes of [`LANE_DIMENSION`] that hold first coordinates.
const FIRST_LANES: usize = BOUNCE_DIMENSIONS as usize;

/// The hashes that seed a dimension's first and second coordinates, combined with the
/// dimension's seed.
const FIRST_COORDINATE: u32 = hash_u32(0x5851_f42d);
const SECOND_COORDINATE: u32 = hash_u32(0x4c95_7f2d);

/// The hash that seeds the coordinate lane `k` draws.
#[inline(always)]
fn lane_seed(k: usize) -> u32 {
    if k < FIRST_LANES {
        FIRST_COORDINATE
    } else {
        SECOND_COORDINATE
    }
}

/// The dimension hashes of a bounce's lanes from `dimension` on: from the table where all
/// five are in it (one branch, not one per lane).
#[inline(always)]
fn bounce_hashes(dimension: u32) -> Lanes {
    match DIMENSION_HASHES
        .get(dimension as usize..)
        .and_then(|h| h.get(..FIRST_LANES))
    {
        Some(h) => LANE_DIMENSION.map(|k| h[k as usize]),
        None => LANE_DIMENSION.map(|k| hash_u32(dimension + k)),
    }
}

impl BounceDimensions {
    /// The dimensions from the coordinates in the lanes of [`LANE_DIMENSION`].
    #[inline(always)]
    fn from_lanes(u: [f32; LANES]) -> Self {
        Self {
            light: u[0],
            light_point: Vec2::new(u[1], u[5]),
            lobe: u[2],
            direction: Vec2::new(u[3], u[6]),
            roulette: u[4],
        }
    }
}

/// Sampler dimensions consumed by each bounce: light choice, light point, lobe choice,
/// direction, Russian roulette ([`PixelSampler::next_bounce`]).
pub const BOUNCE_DIMENSIONS: u32 = 5;

/// The random numbers of one bounce, in the order the integrator draws them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BounceDimensions {
    /// Which light next-event estimation samples.
    pub light: f32,
    /// The point on that light.
    pub light_point: Vec2,
    /// Which lobe of the BSDF the path continues by.
    pub lobe: f32,
    /// The direction within that lobe.
    pub direction: Vec2,
    /// Russian roulette's draw.
    pub roulette: f32,
}

/// The width of [`PixelSampler::next_bounce`]'s passes.
const LANES: usize = 8;
type Lanes = [u32; LANES];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_tables_match_the_bit_by_bit_sobol_matrix() {
        for i in [0u32, 1, 2, 3, 255, 256, 0x1234_5678, u32::MAX, 0x8000_0001] {
            let mut y = 0;
            for (bit, v) in SOBOL1_DIRECTIONS.iter().enumerate() {
                if i & (1 << bit) != 0 {
                    y ^= v;
                }
            }
            assert_eq!(sobol1_reversed(i).reverse_bits(), y, "index {i:#x}");
        }
        // The first points of the second dimension: 0, 1/2, 3/4, 1/4.
        let firsts: Vec<u32> = (0..4)
            .map(|i| sobol1_reversed(i).reverse_bits() >> 30)
            .collect();
        assert_eq!(firsts, [0, 2, 3, 1]);
    }

    #[test]
    fn one_dimension_is_the_first_coordinate_of_two() {
        for i in 0..256 {
            let (mut a, mut b) = (
                PixelSampler::new(5, 8, i, 2, 9),
                PixelSampler::new(5, 8, i, 2, 9),
            );
            for _ in 0..6 {
                assert_eq!(a.next_1d(), b.next_2d().x);
            }
        }
    }

    /// Each dimension is seeded by `hash_combine(pixel seed, dimension)`, whether its
    /// hash comes from the table or is computed (past the table's end, and far past it as
    /// the spectral dimensions are).
    #[test]
    fn dimensions_in_and_past_the_table_are_seeded_alike() {
        let n = DIMENSION_HASHES.len() as u32;
        for start in [0, n - 2, 0xffff_0000] {
            let mut s = PixelSampler::new(3, 4, 77, 1, 5);
            s.start_dimension(start);
            for d in start..start + 4 {
                let seed = hash_combine(s.pixel_seed, d);
                let shuffled = scramble_reversed(s.index_reversed, seed);
                let y =
                    scramble_reversed(sobol1_reversed(shuffled), hash_combine(seed, 0x4c95_7f2d));
                let x = scramble_reversed(shuffled, hash_combine(seed, 0x5851_f42d));
                assert_eq!(
                    s.next_2d(),
                    Vec2::new(to_unit(x), to_unit(y)),
                    "dimension {d}"
                );
            }
        }
    }

    /// A bounce's dimensions drawn together are those of one call per dimension, in and
    /// past the dimension hashes' table.
    #[test]
    fn a_bounce_drawn_in_lanes_is_its_dimensions_drawn_one_by_one() {
        let n = DIMENSION_HASHES.len() as u32;
        for start in [0, 3, n - 6, n - 5, n - 4, n, 0xffff_0000] {
            for index in [0, 1, 77, 4095, 0x8000_0001, u32::MAX] {
                let mut one_by_one = PixelSampler::new(3, 4, index, 1, 5);
                one_by_one.start_dimension(start);
                let expected = BounceDimensions {
                    light: one_by_one.next_1d(),
                    light_point: one_by_one.next_2d(),
                    lobe: one_by_one.next_1d(),
                    direction: one_by_one.next_2d(),
                    roulette: one_by_one.next_1d(),
                };
                let next = one_by_one.next_1d();
                let mut portable = PixelSampler::new(3, 4, index, 1, 5);
                let key = format!("dimension {start}, index {index}");
                assert_eq!(portable.next_bounce(start), expected, "{key}");
                assert_eq!(portable.next_1d(), next, "{key}");
                #[cfg(target_arch = "x86_64")]
                if is_x86_feature_detected!("sse4.1") && is_x86_feature_detected!("ssse3") {
                    let mut sse = PixelSampler::new(3, 4, index, 1, 5);
                    // SAFETY: the CPU has SSE4.1 and SSSE3.
                    let drawn = unsafe { sse.next_bounce_sse41(start) };
                    assert_eq!(drawn, expected, "SSE, {key}");
                    assert_eq!(sse.next_1d(), next, "SSE, {key}");
                }
            }
        }
    }

    #[test]
    fn values_lie_in_the_unit_square() {
        for i in 0..4096 {
            let mut s = PixelSampler::new(7, 9, i, 3, 0);
            for _ in 0..8 {
                let p = s.next_2d();
                assert!((0.0..1.0).contains(&p.x) && (0.0..1.0).contains(&p.y));
            }
        }
    }

    #[test]
    fn samples_are_a_pure_function_of_their_key() {
        let draw = |x, y, i, f, seed| {
            let mut s = PixelSampler::new(x, y, i, f, seed);
            [s.next_2d(), s.next_2d(), s.next_2d()]
        };
        assert_eq!(draw(1, 2, 3, 4, 5), draw(1, 2, 3, 4, 5));
        assert_ne!(draw(1, 2, 3, 4, 5), draw(2, 2, 3, 4, 5));
        assert_ne!(draw(1, 2, 3, 4, 5), draw(1, 2, 3, 5, 5));
        assert_ne!(draw(1, 2, 3, 4, 5), draw(1, 2, 3, 4, 6));
    }

    #[test]
    fn sixteen_samples_are_stratified_in_a_four_by_four_grid() {
        // Owen-scrambled Sobol is a (0,2)-sequence: every power-of-two prefix puts exactly
        // one point in each elementary interval, e.g. each cell of a 4×4 grid.
        for dim in 0..6 {
            let mut cells = [0u32; 16];
            for i in 0..16 {
                let mut s = PixelSampler::new(3, 5, i, 0, 11);
                s.start_dimension(dim);
                let p = s.next_2d();
                cells[(p.y * 4.0) as usize * 4 + (p.x * 4.0) as usize] += 1;
            }
            assert!(cells.iter().all(|&c| c == 1), "dimension {dim}: {cells:?}");
        }
    }

    #[test]
    fn sixteen_samples_fill_every_elementary_interval() {
        // The 4x4 grid is one of five shapes of 16 cells: 1x16, 2x8, 4x4, 8x2 and 16x1.
        // The thin ones are what make an edge across a pixel (a lamp's) converge fast.
        for (pixel, dim) in [((3, 5), 0), ((128, 27), 0), ((17, 200), 4), ((0, 0), 9)] {
            for log_rows in 0..=4 {
                let (rows, columns) = (1 << log_rows, 16 >> log_rows);
                let mut cells = [0u32; 16];
                for i in 0..16 {
                    let mut s = PixelSampler::new(pixel.0, pixel.1, i, 0, 11);
                    s.start_dimension(dim);
                    let p = s.next_2d();
                    let (r, c) = (
                        (p.y * rows as f32) as usize,
                        (p.x * columns as f32) as usize,
                    );
                    cells[r * columns + c] += 1;
                }
                assert!(
                    cells.iter().all(|&c| c == 1),
                    "pixel {pixel:?}, dimension {dim}, {rows} rows: {cells:?}"
                );
            }
        }
    }

    #[test]
    fn integrates_a_smooth_function_better_than_random() {
        // ∫∫ sin(πx) sin(πy) = 4/π²; with 256 stratified samples the error should be far
        // below the ~1/16 of independent random sampling.
        let exact = 4.0 / (std::f64::consts::PI * std::f64::consts::PI);
        let mut worst = 0.0f64;
        for pixel in 0..32 {
            let mut sum = 0.0f64;
            for i in 0..256 {
                let p = PixelSampler::new(pixel, 0, i, 0, 0).next_2d();
                sum += (std::f64::consts::PI * p.x as f64).sin()
                    * (std::f64::consts::PI * p.y as f64).sin();
            }
            worst = worst.max((sum / 256.0 - exact).abs());
        }
        assert!(worst < 0.005, "worst error {worst}");
    }
}
