//! Smooth spectra for RGB colours (Jakob & Hanika 2019): a reflectance in [0, 1] per
//! channel becomes `s(λ) = sigmoid(c0 λ² + c1 λ + c2)`, whose three coefficients come from
//! a table fitted at build time (`tracer/build.rs`) so that, lit by D65 and seen through
//! the CIE 1931 observer, the spectrum has that colour again. Colours beyond 1 (emission,
//! KHR_materials_emissive_strength) are scaled into the table and back, and light is
//! reflectance times D65, as pbrt-v4 does.

use std::sync::LazyLock;

use glam::Vec3;

/// The table `build.rs` wrote (rgb2spec's format: "SPEC", the resolution, the z scale,
/// then three coefficients per colour, for each largest channel, z, y and x).
static TABLE: LazyLock<Table> = LazyLock::new(|| {
    Table::parse(include_bytes!(concat!(
        env!("OUT_DIR"),
        "/rgb2spec_rec709.bin"
    )))
});

struct Table {
    resolution: usize,
    /// The largest channel's value at each z index (denser near 0 and 1).
    scale: Vec<f32>,
    coefficients: Vec<[f32; 3]>,
}

impl Table {
    fn parse(bytes: &[u8]) -> Table {
        let floats = |from: usize, n: usize| -> Vec<f32> {
            bytes[from..from + 4 * n]
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect()
        };
        assert_eq!(&bytes[..4], b"SPEC", "the build script's table");
        let resolution = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]) as usize;
        let scale = floats(8, resolution);
        let n = 3 * resolution * resolution * resolution;
        let coefficients = floats(8 + 4 * resolution, 3 * n)
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        Table {
            resolution,
            scale,
            coefficients,
        }
    }

    /// The coefficients of a colour with channels in [0, 1], trilinear between the
    /// table's colours.
    fn fetch(&self, rgb: [f32; 3]) -> [f32; 3] {
        let res = self.resolution;
        // The largest channel picks the table and is its z; the others, divided by it,
        // are x and y.
        let i = (0..3).fold(0, |i, j| if rgb[j] >= rgb[i] { j } else { i });
        let z = rgb[i];
        let to_grid = (res - 1) as f32 / z;
        let x = rgb[(i + 1) % 3] * to_grid;
        let y = rgb[(i + 2) % 3] * to_grid;
        let xi = (x as usize).min(res - 2);
        let yi = (y as usize).min(res - 2);
        let zi = self.scale[1..res - 1].partition_point(|&s| s <= z);
        let (fx, fy) = (x - xi as f32, y - yi as f32);
        let fz = (z - self.scale[zi]) / (self.scale[zi + 1] - self.scale[zi]);
        let at = |dx: usize, dy: usize, dz: usize| {
            self.coefficients[((i * res + zi + dz) * res + yi + dy) * res + xi + dx]
        };
        let lerp =
            |a: [f32; 3], b: [f32; 3], t: f32| std::array::from_fn(|k| a[k] * (1.0 - t) + b[k] * t);
        let plane = |dz| {
            lerp(
                lerp(at(0, 0, dz), at(1, 0, dz), fx),
                lerp(at(0, 1, dz), at(1, 1, dz), fx),
                fy,
            )
        };
        lerp(plane(0), plane(1), fz)
    }
}

/// A smooth spectrum of values in [0, 1]: `sigmoid(c0 λ² + c1 λ + c2)`, λ in nm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SigmoidPolynomial {
    c: [f32; 3],
}

impl SigmoidPolynomial {
    /// The spectrum at `nm`.
    pub fn eval(&self, nm: f32) -> f32 {
        let x = (self.c[0] * nm + self.c[1]) * nm + self.c[2];
        if x.is_infinite() {
            return if x > 0.0 { 1.0 } else { 0.0 };
        }
        0.5 + x / (2.0 * (1.0 + x * x).sqrt())
    }

    /// The spectrum of a reflectance, each channel clamped to [0, 1]. A grey is a flat
    /// spectrum of exactly its value, so that a white furnace stays white.
    pub fn reflectance(rgb: Vec3) -> Self {
        let rgb = rgb.clamp(Vec3::ZERO, Vec3::ONE);
        if rgb.x == rgb.y && rgb.y == rgb.z {
            // sigmoid((r − ½) / √(r(1 − r))) = r; ±∞ at 0 and 1.
            let r = rgb.x;
            return Self {
                c: [0.0, 0.0, (r - 0.5) / (r * (1.0 - r)).sqrt()],
            };
        }
        Self {
            c: TABLE.fetch(rgb.to_array()),
        }
    }
}

/// The spectrum of a colour whose channels may exceed 1 (radiance, or an RGB light's
/// colour times its strength): a reflectance spectrum scaled back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnboundedSpectrum {
    shape: SigmoidPolynomial,
    scale: f32,
}

impl UnboundedSpectrum {
    /// The spectrum of `rgb` (negative channels count as 0), as pbrt-v4 scales it: by
    /// twice the largest channel, so that the shape's values stay near the middle.
    pub fn new(rgb: Vec3) -> Self {
        let rgb = rgb.max(Vec3::ZERO);
        let m = rgb.max_element();
        let scale = 2.0 * m;
        Self {
            shape: SigmoidPolynomial::reflectance(if scale > 0.0 {
                rgb / scale
            } else {
                Vec3::ZERO
            }),
            scale,
        }
    }

    /// The spectrum at `nm`.
    pub fn eval(&self, nm: f32) -> f32 {
        self.scale * self.shape.eval(nm)
    }
}

/// The spectrum of light of RGB colour `rgb`: [`UnboundedSpectrum`] times D65 at unit
/// luminance, so that (1, 1, 1) is the white of Rec. 709.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IlluminantSpectrum(pub UnboundedSpectrum);

impl IlluminantSpectrum {
    /// The spectrum of light of colour `rgb`.
    pub fn new(rgb: Vec3) -> Self {
        Self(UnboundedSpectrum::new(rgb))
    }

    /// The spectrum at `nm`.
    pub fn eval(&self, nm: f32) -> f32 {
        self.0.eval(nm) * super::d65(nm)
    }
}
