//! Tile buffers. A tile accumulates per-pixel sums, not averages, so that the buffers of
//! two sample ranges of the same tile merge by addition and equal the buffer of the whole
//! range within float rounding.
//!
//! Each pixel also sums its odd-numbered samples apart (a "half buffer"): the difference
//! between the mean of all samples and the mean of that half estimates the pixel's error,
//! which adaptive sampling stops on and the `noise` layer reports. It sums the squares of
//! its samples too, for the `variance` layer.

use glam::{Vec2, Vec3, Vec4};

/// A rectangle of pixels in a frame; `x`, `y` from the top-left corner.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TileRect {
    /// Left column.
    pub x: u32,
    /// Top row.
    pub y: u32,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

impl TileRect {
    /// A rectangle.
    pub fn new(x: u32, y: u32, width: u32, height: u32) -> Self {
        Self {
            x,
            y,
            width,
            height,
        }
    }

    /// Number of pixels.
    pub fn area(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Whether `self` lies inside a `width`×`height` frame.
    pub fn fits_in(&self, width: u32, height: u32) -> bool {
        self.x as u64 + self.width as u64 <= width as u64
            && self.y as u64 + self.height as u64 <= height as u64
    }

    /// Splits the rectangle into tiles of at most `size`×`size`, row by row.
    pub fn tiles(&self, size: u32) -> Vec<TileRect> {
        let size = size.max(1);
        let mut out = Vec::new();
        for y in (self.y..self.y + self.height).step_by(size as usize) {
            for x in (self.x..self.x + self.width).step_by(size as usize) {
                let w = size.min(self.x + self.width - x);
                let h = size.min(self.y + self.height - y);
                out.push(TileRect::new(x, y, w, h));
            }
        }
        out
    }
}

/// A half-open range of sample indices `[start, end)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SampleRange {
    /// First sample index.
    pub start: u32,
    /// One past the last sample index.
    pub end: u32,
}

impl SampleRange {
    /// Samples `[start, end)`.
    pub fn new(start: u32, end: u32) -> Self {
        Self { start, end }
    }

    /// Number of samples.
    pub fn len(&self) -> u32 {
        self.end.saturating_sub(self.start)
    }

    /// Whether the range holds no sample.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// What one camera sample found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SampleValue {
    /// Radiance along the camera ray (linear RGB).
    pub radiance: Vec3,
    /// Coverage: 1 where the ray hit geometry, 0 where it saw the environment.
    pub alpha: f32,
    /// Albedo of the first non-specular surface seen (denoiser AOV).
    pub albedo: Vec3,
    /// World-space shading normal at the first hit (zero on a miss).
    pub normal: Vec3,
    /// Distance along the camera's view axis to the first hit; `None` on a miss.
    pub depth: Option<f32>,
    /// Screen-space motion of what the camera ray saw over the shutter, in pixels (zero
    /// where nothing in the frame moves).
    pub motion: Vec2,
    /// Rays traced for this sample (camera, bounce and shadow rays).
    pub rays: u32,
}

impl SampleValue {
    /// Nothing found yet: what a camera sample starts from. `default()` as a constant,
    /// which the path loop copies from read-only memory: built on the stack, it was zeroed
    /// in stores that its copy's wider loads could not be forwarded from (1% of the loop's
    /// `perf` samples sat on that copy).
    pub const EMPTY: SampleValue = SampleValue {
        radiance: Vec3::ZERO,
        alpha: 0.0,
        albedo: Vec3::ZERO,
        normal: Vec3::ZERO,
        depth: None,
        motion: Vec2::ZERO,
        rays: 0,
    };
}

/// The sums of [`TileBuffer`] for one pixel, over a run of its samples: what a thread
/// adds up while it traces them, in registers and without the buffer's bounds checks,
/// then adds to the buffer once ([`TileBuffer::add_pixel`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PixelSum {
    beauty: Vec4,
    albedo: Vec3,
    normal: Vec3,
    depth: f32,
    hits: u32,
    motion: Vec2,
    square: Vec3,
    samples: u32,
    half: Vec3,
    half_samples: u32,
    dropped: u64,
    rays: u64,
}

impl PixelSum {
    /// Adds sample number `sample`; a sample with any non-finite value is dropped whole
    /// and counted.
    #[inline(always)]
    pub fn add(&mut self, sample: u32, s: &SampleValue) {
        self.rays += u64::from(s.rays);
        let finite = s.radiance.is_finite()
            && s.alpha.is_finite()
            && s.albedo.is_finite()
            && s.normal.is_finite()
            && s.depth.is_none_or(f32::is_finite)
            && s.motion.is_finite();
        if !finite {
            self.dropped += 1;
            return;
        }
        self.beauty += s.radiance.extend(s.alpha);
        self.albedo += s.albedo;
        self.normal += s.normal;
        self.motion += s.motion;
        self.square += s.radiance * s.radiance;
        if let Some(d) = s.depth {
            self.depth += d;
            self.hits += 1;
        }
        self.samples += 1;
        if sample % 2 == 1 {
            self.half += s.radiance;
            self.half_samples += 1;
        }
    }

    /// The estimated error of the pixel so far (see [`noise_estimate`]).
    pub fn noise(&self) -> f32 {
        pixel_noise(self.beauty, self.samples, self.half, self.half_samples)
    }
}

/// [`noise_estimate`] from a pixel's sums; [`NO_NOISE_ESTIMATE`] where its samples cannot
/// tell (fewer than two, or all of one parity).
fn pixel_noise(beauty: Vec4, samples: u32, half: Vec3, half_samples: u32) -> f32 {
    if half_samples == 0 || half_samples == samples {
        return NO_NOISE_ESTIMATE;
    }
    noise_estimate(
        beauty.truncate() / samples as f32,
        half / half_samples as f32,
    )
}

/// Depth written for pixels where no sample hit anything: large and finite, as
/// compositors expect (Cycles uses the same value), never infinity.
pub const NO_HIT_DEPTH: f32 = 1.0e10;

/// Per-pixel sums over the samples of one tile, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct TileBuffer {
    /// The pixels covered.
    pub rect: TileRect,
    /// Sum of RGB radiance and alpha.
    pub beauty: Vec<Vec4>,
    /// Sum of albedo.
    pub albedo: Vec<Vec3>,
    /// Sum of normals.
    pub normal: Vec<Vec3>,
    /// Sum of depths over the samples that hit.
    pub depth: Vec<f32>,
    /// Number of samples that hit, per pixel.
    pub hits: Vec<u32>,
    /// Sum of screen-space motions.
    pub motion: Vec<Vec2>,
    /// Sum of the squares of RGB radiance.
    pub square: Vec<Vec3>,
    /// Number of samples kept, per pixel (samples with NaN or infinity are dropped).
    pub samples: Vec<u32>,
    /// Sum of RGB radiance over the kept samples whose index is odd.
    pub half: Vec<Vec3>,
    /// Number of those samples, per pixel.
    pub half_samples: Vec<u32>,
    /// Samples dropped because they were NaN or infinite.
    pub dropped: u64,
    /// Rays traced, for throughput figures.
    pub rays: u64,
}

impl TileBuffer {
    /// An empty buffer for `rect`.
    pub fn new(rect: TileRect) -> Self {
        let n = rect.area();
        Self {
            rect,
            beauty: vec![Vec4::ZERO; n],
            albedo: vec![Vec3::ZERO; n],
            normal: vec![Vec3::ZERO; n],
            depth: vec![0.0; n],
            hits: vec![0; n],
            motion: vec![Vec2::ZERO; n],
            square: vec![Vec3::ZERO; n],
            samples: vec![0; n],
            half: vec![Vec3::ZERO; n],
            half_samples: vec![0; n],
            dropped: 0,
            rays: 0,
        }
    }

    /// Adds sample number `sample` to the pixel at `index` (row-major within the tile); a
    /// sample with any non-finite value is dropped whole and counted.
    pub fn add(&mut self, index: usize, sample: u32, s: &SampleValue) {
        let mut sum = PixelSum::default();
        sum.add(sample, s);
        self.add_pixel(index, &sum);
    }

    /// Adds the sums of one pixel's samples to the pixel at `index`. (Added to a pixel
    /// that had none, they are its sums to the bit.)
    pub fn add_pixel(&mut self, index: usize, sum: &PixelSum) {
        self.rays += sum.rays;
        self.dropped += sum.dropped;
        self.beauty[index] += sum.beauty;
        self.albedo[index] += sum.albedo;
        self.normal[index] += sum.normal;
        self.motion[index] += sum.motion;
        self.square[index] += sum.square;
        self.depth[index] += sum.depth;
        self.hits[index] += sum.hits;
        self.samples[index] += sum.samples;
        self.half[index] += sum.half;
        self.half_samples[index] += sum.half_samples;
    }

    /// The estimated error of pixel `index` (see [`noise_estimate`]).
    pub fn noise(&self, index: usize) -> f32 {
        pixel_noise(
            self.beauty[index],
            self.samples[index],
            self.half[index],
            self.half_samples[index],
        )
    }

    /// The estimated variance of pixel `index`'s mean radiance (the square of its
    /// standard error), per channel: the samples' unbiased variance over their count;
    /// [`NO_NOISE_ESTIMATE`] with fewer than two samples.
    pub fn variance(&self, index: usize) -> Vec3 {
        let n = self.samples[index];
        if n < 2 {
            return Vec3::splat(NO_NOISE_ESTIMATE);
        }
        let n = n as f32;
        let mean = self.beauty[index].truncate() / n;
        // Rounding can take the difference of two close sums below zero.
        ((self.square[index] / n - mean * mean) / (n - 1.0)).max(Vec3::ZERO)
    }

    /// Adds another buffer of the same rectangle (another sample range).
    ///
    /// # Panics
    /// If the rectangles differ.
    pub fn merge(&mut self, other: &TileBuffer) {
        assert_eq!(
            self.rect, other.rect,
            "merging tiles of different rectangles"
        );
        for i in 0..self.beauty.len() {
            self.beauty[i] += other.beauty[i];
            self.albedo[i] += other.albedo[i];
            self.normal[i] += other.normal[i];
            self.depth[i] += other.depth[i];
            self.hits[i] += other.hits[i];
            self.motion[i] += other.motion[i];
            self.square[i] += other.square[i];
            self.samples[i] += other.samples[i];
            self.half[i] += other.half[i];
            self.half_samples[i] += other.half_samples[i];
        }
        self.dropped += other.dropped;
        self.rays += other.rays;
    }

    /// Copies a smaller buffer (a tile of this one) into its place.
    ///
    /// # Panics
    /// If `tile` does not lie inside `self`.
    pub fn paste(&mut self, tile: &TileBuffer) {
        for (src, dst, w) in row_spans(self.rect, tile.rect) {
            self.beauty[dst..dst + w].copy_from_slice(&tile.beauty[src..src + w]);
            self.albedo[dst..dst + w].copy_from_slice(&tile.albedo[src..src + w]);
            self.normal[dst..dst + w].copy_from_slice(&tile.normal[src..src + w]);
            self.depth[dst..dst + w].copy_from_slice(&tile.depth[src..src + w]);
            self.hits[dst..dst + w].copy_from_slice(&tile.hits[src..src + w]);
            self.motion[dst..dst + w].copy_from_slice(&tile.motion[src..src + w]);
            self.square[dst..dst + w].copy_from_slice(&tile.square[src..src + w]);
            self.samples[dst..dst + w].copy_from_slice(&tile.samples[src..src + w]);
            self.half[dst..dst + w].copy_from_slice(&tile.half[src..src + w]);
            self.half_samples[dst..dst + w].copy_from_slice(&tile.half_samples[src..src + w]);
        }
        self.dropped += tile.dropped;
        self.rays += tile.rays;
    }

    /// Averages the sums into displayable layers.
    pub fn resolve(&self) -> Layers {
        let n = self.rect.area();
        let mut out = Layers::new(self.rect);
        for i in 0..n {
            let inv = if self.samples[i] > 0 {
                1.0 / self.samples[i] as f32
            } else {
                0.0
            };
            out.beauty[i] = self.beauty[i] * inv;
            out.albedo[i] = self.albedo[i] * inv;
            out.motion[i] = self.motion[i] * inv;
            out.variance[i] = self.variance(i);
            let nrm = self.normal[i];
            out.normal[i] = if nrm.length_squared() > 0.0 {
                nrm.normalize()
            } else {
                Vec3::ZERO
            };
            out.depth[i] = if self.hits[i] > 0 {
                self.depth[i] / self.hits[i] as f32
            } else {
                NO_HIT_DEPTH
            };
            out.samples[i] = self.samples[i] as f32;
            out.noise[i] = self.noise(i);
        }
        out
    }
}

/// Samples and estimated error over a set of pixels (see [`Layers::sampling`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplingSummary {
    /// Mean samples per pixel.
    pub mean_samples: f64,
    /// Fewest samples a pixel took.
    pub min_samples: u32,
    /// Most samples a pixel took.
    pub max_samples: u32,
    /// Mean estimated error over the pixels that have an estimate; `None` if none has.
    pub mean_noise: Option<f64>,
}

/// A [`SamplingSummary`] gathered over pixels that arrive in parts (a frame assembled band
/// by band): adding every part in pixel order gives the summary of the whole, to the bit.
#[derive(Clone, Copy, Debug, Default)]
pub struct SamplingTally {
    pixels: u64,
    samples_sum: f64,
    min_samples: Option<f32>,
    max_samples: f32,
    noise_sum: f64,
    estimated: u64,
}

impl SamplingTally {
    /// Counts the pixels of `layers`.
    pub fn add(&mut self, layers: &Layers) {
        self.pixels += layers.samples.len() as u64;
        for &s in &layers.samples {
            self.samples_sum += f64::from(s);
            self.min_samples = Some(self.min_samples.map_or(s, |m| m.min(s)));
            self.max_samples = self.max_samples.max(s);
        }
        for &e in &layers.noise {
            if e < NO_NOISE_ESTIMATE {
                self.noise_sum += f64::from(e);
                self.estimated += 1;
            }
        }
    }

    /// What the pixels counted so far reached.
    pub fn summary(&self) -> SamplingSummary {
        SamplingSummary {
            mean_samples: self.samples_sum / self.pixels.max(1) as f64,
            min_samples: self.min_samples.unwrap_or(0.0) as u32,
            max_samples: self.max_samples as u32,
            mean_noise: (self.estimated > 0).then(|| self.noise_sum / self.estimated as f64),
        }
    }
}

/// Written as the noise of a pixel with too few samples to estimate it (fewer than two,
/// or all of one parity): large and finite, like [`NO_HIT_DEPTH`].
pub const NO_NOISE_ESTIMATE: f32 = 1.0e10;

/// A pixel's estimated relative error from the mean of all its samples and the mean of
/// its odd-numbered half, as Cycles' adaptive sampling measures it (after Dammertz et al.
/// 2010, "A hierarchical automatic stopping condition for Monte Carlo global
/// illumination"): `Σ|I − A| / (1e-4 + sqrt(Σ I))` over R, G, B. `I − A` is half the
/// difference of the two halves' means, so it is distributed as the error of `I` itself;
/// dividing by the square root of the intensity weighs it as the eye does, so dark
/// pixels need not reach the absolute error of bright ones.
pub fn noise_estimate(mean: Vec3, half_mean: Vec3) -> f32 {
    let difference = (mean - half_mean).abs().element_sum();
    difference / (1e-4 + mean.element_sum().max(0.0).sqrt())
}

/// Averaged image layers of a rectangle, ready to write: the content of one EXR data
/// window.
#[derive(Clone, Debug, PartialEq)]
pub struct Layers {
    /// The pixels covered.
    pub rect: TileRect,
    /// Linear RGB radiance and alpha.
    pub beauty: Vec<Vec4>,
    /// Albedo.
    pub albedo: Vec<Vec3>,
    /// Unit world-space shading normal (zero where nothing was hit).
    pub normal: Vec<Vec3>,
    /// Depth along the view axis ([`NO_HIT_DEPTH`] where nothing was hit).
    pub depth: Vec<f32>,
    /// Samples taken per pixel (adaptive sampling stops pixels at different counts).
    pub samples: Vec<f32>,
    /// Estimated relative error per pixel (see [`noise_estimate`];
    /// [`NO_NOISE_ESTIMATE`] where there were too few samples).
    pub noise: Vec<f32>,
    /// Screen-space motion over the shutter in pixels, x right and y down, averaged over
    /// the samples (zero where nothing moves).
    pub motion: Vec<Vec2>,
    /// Estimated variance of each pixel's RGB (see [`TileBuffer::variance`];
    /// [`NO_NOISE_ESTIMATE`] where there were too few samples).
    pub variance: Vec<Vec3>,
    /// The beauty's RGB after a denoiser ran over the whole frame; empty where none did
    /// (the tracer never makes it: tiles and direct renders have none).
    pub denoised: Vec<Vec3>,
}

impl Layers {
    /// Black layers for `rect`: depth at [`NO_HIT_DEPTH`], no samples, noise and variance
    /// at [`NO_NOISE_ESTIMATE`].
    pub fn new(rect: TileRect) -> Self {
        let n = rect.area();
        Self {
            rect,
            beauty: vec![Vec4::ZERO; n],
            albedo: vec![Vec3::ZERO; n],
            normal: vec![Vec3::ZERO; n],
            depth: vec![NO_HIT_DEPTH; n],
            samples: vec![0.0; n],
            noise: vec![NO_NOISE_ESTIMATE; n],
            motion: vec![Vec2::ZERO; n],
            variance: vec![Vec3::splat(NO_NOISE_ESTIMATE); n],
            denoised: Vec::new(),
        }
    }

    /// Copies `tile` into its place inside `self` (tiles assemble into frames); its
    /// denoised layer too where it has one.
    ///
    /// # Panics
    /// If `tile` does not lie inside `self`.
    pub fn paste(&mut self, tile: &Layers) {
        if !tile.denoised.is_empty() && self.denoised.is_empty() {
            self.denoised = vec![Vec3::ZERO; self.rect.area()];
        }
        for (src, dst, w) in row_spans(self.rect, tile.rect) {
            if !tile.denoised.is_empty() {
                self.denoised[dst..dst + w].copy_from_slice(&tile.denoised[src..src + w]);
            }
            self.beauty[dst..dst + w].copy_from_slice(&tile.beauty[src..src + w]);
            self.albedo[dst..dst + w].copy_from_slice(&tile.albedo[src..src + w]);
            self.normal[dst..dst + w].copy_from_slice(&tile.normal[src..src + w]);
            self.depth[dst..dst + w].copy_from_slice(&tile.depth[src..src + w]);
            self.samples[dst..dst + w].copy_from_slice(&tile.samples[src..src + w]);
            self.noise[dst..dst + w].copy_from_slice(&tile.noise[src..src + w]);
            self.motion[dst..dst + w].copy_from_slice(&tile.motion[src..src + w]);
            self.variance[dst..dst + w].copy_from_slice(&tile.variance[src..src + w]);
        }
    }

    /// What the samples reached over these pixels: for a frame's status and metadata.
    pub fn sampling(&self) -> SamplingSummary {
        let mut tally = SamplingTally::default();
        tally.add(self);
        tally.summary()
    }

    /// The sub-rectangle `sub` of `self` as its own layers.
    ///
    /// # Panics
    /// If `sub` does not lie inside `self`.
    pub fn crop(&self, sub: TileRect) -> Layers {
        let mut out = Layers::new(sub);
        if !self.denoised.is_empty() {
            out.denoised = vec![Vec3::ZERO; sub.area()];
        }
        for (dst, src, w) in row_spans(self.rect, sub) {
            if !self.denoised.is_empty() {
                out.denoised[dst..dst + w].copy_from_slice(&self.denoised[src..src + w]);
            }
            out.beauty[dst..dst + w].copy_from_slice(&self.beauty[src..src + w]);
            out.albedo[dst..dst + w].copy_from_slice(&self.albedo[src..src + w]);
            out.normal[dst..dst + w].copy_from_slice(&self.normal[src..src + w]);
            out.depth[dst..dst + w].copy_from_slice(&self.depth[src..src + w]);
            out.samples[dst..dst + w].copy_from_slice(&self.samples[src..src + w]);
            out.noise[dst..dst + w].copy_from_slice(&self.noise[src..src + w]);
            out.motion[dst..dst + w].copy_from_slice(&self.motion[src..src + w]);
            out.variance[dst..dst + w].copy_from_slice(&self.variance[src..src + w]);
        }
        out
    }
}

/// For each row of `inner` (which must lie inside `outer`): the row's start index in
/// `inner`'s buffer, its start index in `outer`'s buffer, and its width.
fn row_spans(outer: TileRect, inner: TileRect) -> impl Iterator<Item = (usize, usize, usize)> {
    assert!(
        inner.x >= outer.x
            && inner.y >= outer.y
            && inner.x + inner.width <= outer.x + outer.width
            && inner.y + inner.height <= outer.y + outer.height,
        "rectangle {inner:?} outside {outer:?}"
    );
    (0..inner.height as usize).map(move |row| {
        let in_inner = row * inner.width as usize;
        let in_outer = ((inner.y - outer.y) as usize + row) * outer.width as usize
            + (inner.x - outer.x) as usize;
        (in_inner, in_outer, inner.width as usize)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_rectangle_exactly_once() {
        let r = TileRect::new(3, 5, 37, 20);
        let tiles = r.tiles(16);
        assert_eq!(tiles.len(), 3 * 2);
        assert_eq!(tiles.iter().map(|t| t.area()).sum::<usize>(), r.area());
        assert!(tiles
            .iter()
            .all(|t| t.x >= 3 && t.x + t.width <= 40 && t.y + t.height <= 25));
    }

    #[test]
    fn non_finite_samples_are_dropped_and_counted() {
        let mut b = TileBuffer::new(TileRect::new(0, 0, 1, 1));
        b.add(
            0,
            0,
            &SampleValue {
                radiance: Vec3::ONE,
                alpha: 1.0,
                ..Default::default()
            },
        );
        b.add(
            0,
            0,
            &SampleValue {
                radiance: Vec3::NAN,
                ..Default::default()
            },
        );
        b.add(
            0,
            0,
            &SampleValue {
                depth: Some(f32::INFINITY),
                ..Default::default()
            },
        );
        assert_eq!(b.dropped, 2);
        assert_eq!(b.resolve().beauty[0], Vec4::ONE);
        assert_eq!(b.resolve().depth[0], NO_HIT_DEPTH);
    }

    #[test]
    fn a_pixels_sums_added_at_once_are_its_samples_added_one_by_one() {
        let mut samples: Vec<SampleValue> = (0..7)
            .map(|i| SampleValue {
                radiance: Vec3::new(0.1 * i as f32, 1.0 / (i as f32 + 3.0), 0.7),
                alpha: 1.0,
                albedo: Vec3::splat(0.3 + 0.01 * i as f32),
                normal: Vec3::Z,
                depth: (i % 3 != 0).then_some(2.0 + 0.37 * i as f32),
                motion: Vec2::new(0.5, -0.25 * i as f32),
                rays: 3 + i,
            })
            .collect();
        // One of them NaN, dropped by both.
        samples[4].radiance.x = f32::NAN;
        let rect = TileRect::new(0, 0, 2, 1);
        let (mut one_by_one, mut at_once) = (TileBuffer::new(rect), TileBuffer::new(rect));
        let mut sum = PixelSum::default();
        for (i, s) in samples.iter().enumerate() {
            one_by_one.add(1, i as u32, s);
            sum.add(i as u32, s);
            assert_eq!(sum.noise().to_bits(), one_by_one.noise(1).to_bits());
        }
        at_once.add_pixel(1, &sum);
        assert_eq!(at_once, one_by_one);
        assert_eq!((at_once.dropped, at_once.samples[1]), (1, 6));
    }

    #[test]
    fn the_noise_estimate_compares_the_odd_half_with_the_whole() {
        let mut b = TileBuffer::new(TileRect::new(0, 0, 2, 1));
        let sample = |v: f32| SampleValue {
            radiance: Vec3::splat(v),
            ..Default::default()
        };
        // Pixel 0: samples 0..4 are 1, 3, 1, 3: mean 2, odd half 3.
        for (i, v) in [1.0, 3.0, 1.0, 3.0].into_iter().enumerate() {
            b.add(0, i as u32, &sample(v));
        }
        // |2 − 3| · 3 channels / sqrt(2 · 3).
        let expected = 3.0 / (1e-4 + 6f32.sqrt());
        assert!((b.noise(0) - expected).abs() < 1e-6, "{}", b.noise(0));
        // Pixel 1: one sample, or only even ones, cannot tell.
        b.add(1, 0, &sample(1.0));
        assert_eq!(b.noise(1), NO_NOISE_ESTIMATE);
        b.add(1, 2, &sample(5.0));
        assert_eq!(b.noise(1), NO_NOISE_ESTIMATE);
        let layers = b.resolve();
        assert_eq!(layers.samples, [4.0, 2.0]);
        let s = layers.sampling();
        assert_eq!((s.min_samples, s.max_samples, s.mean_samples), (2, 4, 3.0));
        // Only pixel 0 has an estimate.
        assert_eq!(s.mean_noise, Some(f64::from(expected)));
        // Equal halves: no difference, no error.
        assert_eq!(noise_estimate(Vec3::ONE, Vec3::ONE), 0.0);
    }

    #[test]
    fn the_variance_is_the_samples_variance_over_their_count() {
        let mut b = TileBuffer::new(TileRect::new(0, 0, 2, 1));
        for (i, v) in [1.0, 3.0, 1.0, 3.0].into_iter().enumerate() {
            let s = SampleValue {
                radiance: Vec3::new(v, 2.0, -v),
                motion: Vec2::new(v, 0.5),
                ..Default::default()
            };
            b.add(0, i as u32, &s);
        }
        b.add(1, 0, &SampleValue::default());
        // Mean 2, unbiased variance 4/3 of the samples, 1/3 of their mean; none for a
        // constant channel; no estimate from one sample.
        let layers = b.resolve();
        assert!(
            (layers.variance[0] - Vec3::new(1.0, 0.0, 1.0) / 3.0)
                .abs()
                .max_element()
                < 1e-6
        );
        assert_eq!(layers.variance[1], Vec3::splat(NO_NOISE_ESTIMATE));
        assert_eq!(layers.motion[0], Vec2::new(2.0, 0.5));
    }

    #[test]
    fn paste_then_crop_round_trips() {
        let mut frame = Layers::new(TileRect::new(0, 0, 8, 6));
        let mut tile = Layers::new(TileRect::new(2, 3, 4, 2));
        for (i, b) in tile.beauty.iter_mut().enumerate() {
            *b = Vec4::splat(i as f32);
        }
        frame.paste(&tile);
        assert_eq!(frame.crop(tile.rect), tile);
        assert_eq!(frame.beauty[3 * 8 + 2], Vec4::splat(0.0));
        assert_eq!(
            frame.beauty[3 * 8 + 1],
            Vec4::ZERO,
            "outside the tile stays black"
        );
        assert_eq!(frame.beauty[4 * 8 + 5], Vec4::splat(7.0));
    }
}
