//! Light carried per wavelength, for the spectral path: the CIE 1931 observer and
//! illuminant D65 (`cie_tables`), RGB colours lifted to smooth spectra (`upsample`),
//! hero-wavelength sampling (Wilkie et al. 2014: four wavelengths per path, one drawn and
//! the others at equal steps of the same distribution), and the samples' estimate of CIE
//! XYZ and of linear Rec. 709, the colour space the RGB path writes.

use std::sync::LazyLock;

use glam::{Mat3, Vec3, Vec4};

use crate::math;

mod cie_tables;
mod described;
mod fluorescence;
mod upsample;

use cie_tables::{D65, SAMPLES, STEP, X_BAR, Y_BAR, Z_BAR};
pub use cie_tables::{LAMBDA_MAX, LAMBDA_MIN};
pub use described::{
    DenseSpectrum, SpectrumShape, BLACKBODY_KELVIN, MAX_TABLE_ENTRIES, WAVELENGTH_RANGE,
};
pub use fluorescence::{Fluorescence, FluorescenceDef, Reradiation};
pub use upsample::{IlluminantSpectrum, SigmoidPolynomial, UnboundedSpectrum};

/// Wavelengths one path carries.
pub const WAVELENGTHS: usize = 4;

/// XYZ to linear Rec. 709 (D65 white), as the sRGB standard gives it.
pub const XYZ_TO_REC709: Mat3 = Mat3::from_cols_array(&[
    3.240_454_2,
    -0.969_266,
    0.055_643_4,
    -1.537_138_5,
    1.876_010_8,
    -0.204_025_9,
    -0.498_531_4,
    0.041_556,
    1.057_225_2,
]);

/// A table's value at `nm`, linear between its entries; 0 outside 360–830 nm.
fn lookup(table: &[f32; SAMPLES], nm: f32) -> f32 {
    let x = (nm - LAMBDA_MIN) / STEP;
    if !(x >= 0.0 && x <= (SAMPLES - 1) as f32) {
        return 0.0;
    }
    let i = (x as usize).min(SAMPLES - 2);
    let t = x - i as f32;
    table[i] * (1.0 - t) + table[i + 1] * t
}

/// The CIE 1931 2° colour-matching functions (x̄, ȳ, z̄) at `nm`.
pub fn cmf(nm: f32) -> Vec3 {
    Vec3::new(lookup(&X_BAR, nm), lookup(&Y_BAR, nm), lookup(&Z_BAR, nm))
}

/// ∫ a(λ) b(λ) dλ for two tables, each linear between its entries (exact for those).
fn integral(a: &[f32; SAMPLES], b: &[f32; SAMPLES]) -> f64 {
    let (a, b) = (a.map(f64::from), b.map(f64::from));
    (0..SAMPLES - 1)
        .map(|i| {
            let (a0, a1, b0, b1) = (a[i], a[i + 1], b[i], b[i + 1]);
            (a0 * b0 / 3.0 + (a0 * b1 + a1 * b0) / 6.0 + a1 * b1 / 3.0) * f64::from(STEP)
        })
        .sum()
}

/// ∫ ȳ(λ) dλ: the luminance of a flat spectrum of 1, which [`to_xyz`] divides by so that
/// such a spectrum has Y = 1.
static Y_INTEGRAL: LazyLock<f32> = LazyLock::new(|| integral(&Y_BAR, &[1.0; SAMPLES]) as f32);

/// D65's relative power divided by its luminance: the spectrum of the white of Rec. 709,
/// (1, 1, 1), which carries an RGB colour of light into the spectral path.
static D65_SCALE: LazyLock<f32> =
    LazyLock::new(|| (integral(&Y_BAR, &[1.0; SAMPLES]) / integral(&D65, &Y_BAR)) as f32);

/// Illuminant D65 at `nm`, scaled to a luminance of 1.
pub fn d65(nm: f32) -> f32 {
    lookup(&D65, nm) * *D65_SCALE
}

/// The density over wavelength of [`sample_visible`]: proportional to 1/cosh² around
/// 538 nm, which follows the eye's sensitivity (pbrt-v4's `VisibleWavelengthsPDF`, after
/// Radziszewski et al. 2009), over 360–830 nm.
pub fn visible_pdf(nm: f32) -> f32 {
    if !(LAMBDA_MIN..=LAMBDA_MAX).contains(&nm) {
        return 0.0;
    }
    let c = math::cosh(0.0072 * (nm - 538.0));
    0.003_939_804 / (c * c)
}

/// A wavelength in 360–830 nm with density [`visible_pdf`], by inverting its
/// distribution at `u` in [0, 1).
pub fn sample_visible(u: f32) -> f32 {
    let nm = 538.0 - 138.888_89 * math::atanh(0.856_910_6 - 1.827_502 * u);
    nm.clamp(LAMBDA_MIN, LAMBDA_MAX)
}

/// The wavelengths one path carries and the density each was drawn with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampledWavelengths {
    /// In nm; the first is the hero, which decides where a path splits by wavelength.
    pub lambda: [f32; WAVELENGTHS],
    /// Each one's density, 0 for one a path no longer carries.
    pub pdf: [f32; WAVELENGTHS],
}

impl SampledWavelengths {
    /// The hero wavelength at `u` and the others at `u + i/4` (wrapped) of the same
    /// distribution: together they stratify it.
    pub fn sample_visible(u: f32) -> Self {
        let lambda = std::array::from_fn(|i| {
            let ui = u + i as f32 / WAVELENGTHS as f32;
            sample_visible(if ui >= 1.0 { ui - 1.0 } else { ui })
        });
        Self {
            lambda,
            pdf: lambda.map(visible_pdf),
        }
    }

    /// Keeps the hero wavelength alone (after a dispersive refraction, which sends each
    /// wavelength its own way): its density now counts the choice among four.
    pub fn terminate_secondary(&mut self) {
        if self.secondary_terminated() {
            return;
        }
        self.pdf[0] /= WAVELENGTHS as f32;
        self.pdf[1..].fill(0.0);
    }

    /// Whether only the hero wavelength is left.
    pub fn secondary_terminated(&self) -> bool {
        self.pdf[1..].iter().all(|&p| p == 0.0)
    }
}

/// The estimate of CIE XYZ from radiance `s` at the wavelengths `w` (one value each),
/// scaled so that a flat spectrum of 1 has Y = 1.
pub fn to_xyz(s: Vec4, w: &SampledWavelengths) -> Vec3 {
    let mut xyz = Vec3::ZERO;
    for i in 0..WAVELENGTHS {
        if w.pdf[i] > 0.0 {
            xyz += cmf(w.lambda[i]) * (s[i] / w.pdf[i]);
        }
    }
    xyz / (WAVELENGTHS as f32 * *Y_INTEGRAL)
}

/// [`to_xyz`] in linear Rec. 709, the RGB path's colour space.
pub fn to_rec709(s: Vec4, w: &SampledWavelengths) -> Vec3 {
    XYZ_TO_REC709 * to_xyz(s, w)
}

#[cfg(test)]
mod tests;
