//! Spectra a scene describes itself, rather than as RGB colours: a light's emission
//! (TESSERA_lights_spectrum) and a fluorescent paint's excitation and emission
//! (TESSERA_materials_fluorescence). `docs/TESSERA_lights_spectrum.md` gives the JSON.

use super::{d65, LAMBDA_MAX, LAMBDA_MIN};

/// Most (nm, value) pairs a table spectrum may have.
pub const MAX_TABLE_ENTRIES: usize = 4096;
/// The blackbody temperatures accepted, in kelvin: from a candle's glow far below
/// visible red to far past any star's white.
pub const BLACKBODY_KELVIN: std::ops::RangeInclusive<f32> = 100.0..=100_000.0;
/// The wavelengths a Gaussian's peak and a table's entries may name, in nm: the near
/// ultraviolet and infrared around the visible band (the renderer carries 360–830 nm; a
/// shape may reach past it, as an LED's band does).
pub const WAVELENGTH_RANGE: std::ops::RangeInclusive<f32> = 300.0..=1000.0;

/// A spectrum's shape over wavelength, in relative units.
#[derive(Clone, Debug, PartialEq)]
pub enum SpectrumShape {
    /// Planck's law at this temperature in kelvin.
    Blackbody(f32),
    /// A Gaussian peak, as an LED's or a dye's band.
    Gaussian {
        /// Where it peaks, in nm.
        peak: f32,
        /// Its full width at half maximum, in nm (what data sheets give).
        width: f32,
    },
    /// (nm, value) pairs at strictly increasing wavelengths, linear between them and 0
    /// outside.
    Table(Vec<(f32, f32)>),
}

impl SpectrumShape {
    /// Its value at `nm`.
    pub fn eval(&self, nm: f32) -> f32 {
        match self {
            SpectrumShape::Blackbody(kelvin) => planck(f64::from(*kelvin), f64::from(nm)) as f32,
            SpectrumShape::Gaussian { peak, width } => {
                // FWHM = 2 √(2 ln 2) σ.
                let sigma = width / 2.354_82;
                let x = (nm - peak) / sigma;
                crate::math::exp(-0.5 * x * x)
            }
            SpectrumShape::Table(entries) => {
                let i = entries.partition_point(|&(at, _)| at <= nm);
                if i == 0 || i == entries.len() {
                    // Before the first entry, or at or past the last.
                    return match entries.last() {
                        Some(&(at, v)) if at == nm => v,
                        _ => 0.0,
                    };
                }
                let ((a, va), (b, vb)) = (entries[i - 1], entries[i]);
                va + (vb - va) * (nm - a) / (b - a)
            }
        }
    }

    /// Why the shape is no spectrum, if it is not one: a temperature, a peak, a width or
    /// a table out of range or out of order.
    pub fn check(&self) -> Result<(), String> {
        match self {
            SpectrumShape::Blackbody(kelvin) if !BLACKBODY_KELVIN.contains(kelvin) => Err(format!(
                "blackbody temperature {kelvin} K is outside {BLACKBODY_KELVIN:?} K"
            )),
            SpectrumShape::Gaussian { peak, .. } if !WAVELENGTH_RANGE.contains(peak) => Err(
                format!("Gaussian peak {peak} nm is outside {WAVELENGTH_RANGE:?} nm"),
            ),
            SpectrumShape::Gaussian { width, .. } if !(*width > 0.0 && width.is_finite()) => {
                Err(format!("Gaussian width {width} nm is not above 0"))
            }
            SpectrumShape::Table(entries) => {
                if !(2..=MAX_TABLE_ENTRIES).contains(&entries.len()) {
                    return Err(format!(
                        "a table of {} entries: it needs 2 to {MAX_TABLE_ENTRIES}",
                        entries.len()
                    ));
                }
                if let Some(&(nm, _)) = entries
                    .iter()
                    .find(|(nm, _)| !WAVELENGTH_RANGE.contains(nm))
                {
                    return Err(format!(
                        "table wavelength {nm} nm is outside {WAVELENGTH_RANGE:?} nm"
                    ));
                }
                if let Some(&(nm, v)) = entries.iter().find(|(_, v)| !(*v >= 0.0 && v.is_finite()))
                {
                    return Err(format!(
                        "table value {v} at {nm} nm is not a finite number of at least 0"
                    ));
                }
                if let Some(w) = entries.windows(2).find(|w| !(w[1].0 > w[0].0)) {
                    return Err(format!(
                        "table wavelengths {} then {} nm do not increase",
                        w[0].0, w[1].0
                    ));
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }
}

/// Planck's spectral radiance at `nm` of a blackbody at `kelvin` (W·sr⁻¹·m⁻³).
fn planck(kelvin: f64, nm: f64) -> f64 {
    const H: f64 = 6.626_070_15e-34;
    const C: f64 = 299_792_458.0;
    const K: f64 = 1.380_649e-23;
    let l = nm * 1e-9;
    2.0 * H * C * C / (l.powi(5) * crate::math::exp_m1_f64(H * C / (l * K * kelvin)))
}

/// Samples per nm of [`DenseSpectrum`].
const DENSE: usize = (LAMBDA_MAX - LAMBDA_MIN) as usize + 1;

/// A spectrum over the visible band, tabulated every nm for the path's lookups.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseSpectrum {
    values: Box<[f32; DENSE]>,
}

impl DenseSpectrum {
    /// `f` every nm from 360 to 830.
    fn from_fn(f: impl Fn(f32) -> f32) -> Self {
        let mut values = Box::new([0.0; DENSE]);
        for (i, v) in values.iter_mut().enumerate() {
            *v = f(LAMBDA_MIN + i as f32);
        }
        Self { values }
    }

    /// The spectrum of a light of this shape, scaled so that it carries over the visible
    /// band the radiant power of the white (D65) that an RGB colour of (1, 1, 1) is: a
    /// light's intensity keeps its meaning whatever its spectrum, down to an ultraviolet
    /// lamp the camera cannot see. `None` for a shape with no power in 360–830 nm.
    pub fn light(shape: &SpectrumShape) -> Option<Self> {
        let mut spectrum = Self::from_fn(|nm| shape.eval(nm));
        let scale = (Self::from_fn(d65).sum() / spectrum.sum()) as f32;
        if !(scale.is_finite() && scale > 0.0) {
            return None;
        }
        spectrum.values.iter_mut().for_each(|v| *v *= scale);
        Some(spectrum)
    }

    /// Σ of its values: its integral over 360–830 nm, in steps of 1 nm.
    fn sum(&self) -> f64 {
        self.values.iter().map(|&v| f64::from(v)).sum()
    }

    /// Its value at `nm`, linear between its samples; 0 outside 360–830 nm.
    pub fn eval(&self, nm: f32) -> f32 {
        let x = nm - LAMBDA_MIN;
        if !(x >= 0.0 && x <= (DENSE - 1) as f32) {
            return 0.0;
        }
        let i = (x as usize).min(DENSE - 2);
        let t = x - i as f32;
        self.values[i] * (1.0 - t) + self.values[i + 1] * t
    }
}
