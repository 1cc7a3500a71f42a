//! Fluorescent paint: the diffuse fluorescent BBRRDF of Jung et al. 2018 ("A Simple
//! Diffuse Fluorescent BBRRDF Model"), light absorbed at one wavelength and re-emitted at
//! a longer one:
//!
//! `f(λi → λo) = [δ(λi − λo) (1 − c a(λi)) r(λi) + c a(λi) Q e(λo) [λo > λi]] / π`
//!
//! with the excitation (absorption) spectrum `a` (its peak 1), the emission spectrum `e`
//! (a density over wavelength), the paint's concentration `c` and quantum yield `Q`, and
//! the reflectance `r` of the material's base colour. The bracket `[λo > λi]` is the
//! Stokes shift: no light is re-emitted at a shorter wavelength than it was absorbed at,
//! so what the emission spectrum has below the absorbed wavelength is lost, and the paint
//! re-emits at most `Q` of what it absorbs. A camera path, which knows `λo`, chooses
//! between reflecting and fluorescing and samples `λi` from `a` below `λo`, as the paper
//! does. Both spectra are binned every nm over 360–830 nm, so that the density sampled is
//! the one evaluated.

use super::{SpectrumShape, LAMBDA_MAX, LAMBDA_MIN};

/// Bins of 1 nm over the band the renderer carries.
const BINS: usize = (LAMBDA_MAX - LAMBDA_MIN) as usize;

/// The paint's description (TESSERA_materials_fluorescence).
#[derive(Clone, Debug, PartialEq)]
pub struct FluorescenceDef {
    /// The shape of the excitation (absorption) spectrum; its peak is scaled to 1.
    pub excitation: SpectrumShape,
    /// The shape of the emission spectrum; scaled to a density over 360–830 nm.
    pub emission: SpectrumShape,
    /// The concentration `c` in [0, 1]: the share of light absorbed at the excitation peak.
    pub concentration: f32,
    /// The quantum yield `Q` in [0, 1]: the share of absorbed light re-emitted.
    pub quantum_yield: f32,
}

impl FluorescenceDef {
    /// Why it is no paint, if it is not one.
    pub fn check(&self) -> Result<(), String> {
        for (name, v) in [
            ("concentration", self.concentration),
            ("quantumYield", self.quantum_yield),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(format!("{name} {v} is outside [0, 1]"));
            }
        }
        self.excitation
            .check()
            .map_err(|why| format!("excitation: {why}"))?;
        self.emission
            .check()
            .map_err(|why| format!("emission: {why}"))?;
        if Fluorescence::new(self).is_none() {
            return Err(format!(
                "the excitation or the emission spectrum is 0 over {LAMBDA_MIN}–{LAMBDA_MAX} nm, \
                 the band the renderer carries"
            ));
        }
        Ok(())
    }

    /// Whether it changes anything: some light is absorbed and re-emitted.
    pub fn is_active(&self) -> bool {
        self.concentration > 0.0 && self.quantum_yield > 0.0
    }
}

/// A paint ready for the path: both spectra binned, and the running sum of the
/// absorption that sampling inverts.
#[derive(Clone, Debug)]
pub struct Fluorescence {
    /// `a` per bin, its largest 1.
    absorption: Box<[f32; BINS]>,
    /// `Σ a` over the bins before each bin (one more entry: the total).
    absorbed_below: Box<[f64; BINS + 1]>,
    /// `e` per bin, summing to 1 (a density per nm).
    emission: Box<[f32; BINS]>,
    concentration: f32,
    quantum_yield: f32,
}

/// The bin of `nm`, if it is in the band.
fn bin(nm: f32) -> Option<usize> {
    let x = nm - LAMBDA_MIN;
    (x >= 0.0 && x < BINS as f32).then(|| (x as usize).min(BINS - 1))
}

/// `shape` at each bin's middle.
fn binned(shape: &SpectrumShape) -> Box<[f32; BINS]> {
    let mut out = Box::new([0.0; BINS]);
    for (i, v) in out.iter_mut().enumerate() {
        *v = shape.eval(LAMBDA_MIN + i as f32 + 0.5);
    }
    out
}

/// What a fluorescent vertex of a camera path does at the wavelength `λo` it carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reradiation {
    /// The wavelength the path carries on (λi; `λo` where it reflects).
    pub nm: f32,
    /// The factor on the path's throughput at `λo`: the diffuse albedo over both events,
    /// `(1 − c a(λo)) r(λo) + c Q e(λo) ∫_{λ<λo} a`, the same whichever was chosen.
    pub weight: f32,
}

impl Fluorescence {
    /// The paint of `def`; `None` where either spectrum is 0 over the band.
    pub fn new(def: &FluorescenceDef) -> Option<Self> {
        let mut absorption = binned(&def.excitation);
        let peak = absorption.iter().copied().fold(0.0, f32::max);
        let mut emission = binned(&def.emission);
        let total: f64 = emission.iter().map(|&e| f64::from(e)).sum();
        if !(peak > 0.0 && peak.is_finite() && total > 0.0 && total.is_finite()) {
            return None;
        }
        absorption.iter_mut().for_each(|a| *a /= peak);
        emission
            .iter_mut()
            .for_each(|e| *e = (f64::from(*e) / total) as f32);
        let mut absorbed_below = Box::new([0.0; BINS + 1]);
        for i in 0..BINS {
            absorbed_below[i + 1] = absorbed_below[i] + f64::from(absorption[i]);
        }
        Some(Self {
            absorption,
            absorbed_below,
            emission,
            concentration: def.concentration,
            quantum_yield: def.quantum_yield,
        })
    }

    /// The absorption `a` at `nm` (0 outside the band).
    pub fn absorption(&self, nm: f32) -> f32 {
        bin(nm).map_or(0.0, |i| self.absorption[i])
    }

    /// The emission density `e` at `nm`, per nm (0 outside the band).
    pub fn emission(&self, nm: f32) -> f32 {
        bin(nm).map_or(0.0, |i| self.emission[i])
    }

    /// `∫ a(λ) dλ` from 360 nm up to `nm`.
    fn absorbed_up_to(&self, nm: f32) -> f64 {
        match bin(nm) {
            None if nm < LAMBDA_MIN => 0.0,
            None => self.absorbed_below[BINS],
            Some(i) => {
                let within = f64::from(nm - LAMBDA_MIN) - i as f64;
                self.absorbed_below[i] + within * f64::from(self.absorption[i])
            }
        }
    }

    /// The BBRRDF times π (it is diffuse): the share of light arriving at `from` nm that
    /// leaves at `to` nm, per nm of `to` where the wavelength changes; `r` is the
    /// reflectance at `from`. The reflected part is a Dirac delta in wavelength and is
    /// given apart, as `(reflected, reradiated)`.
    pub fn bbrrdf(&self, from: f32, to: f32, r: f32) -> (f32, f32) {
        let ca = self.concentration * self.absorption(from);
        let reflected = (1.0 - ca) * r;
        let reradiated = if to > from {
            ca * self.quantum_yield * self.emission(to)
        } else {
            0.0
        };
        (reflected, reradiated)
    }

    /// For a camera path carrying `nm` onto the paint, whose base reflects `r` there:
    /// reflect, or fluoresce from a wavelength drawn below `nm` in proportion to the
    /// absorption, each in proportion to what it contributes (`u_choice`, `u_nm` in
    /// [0, 1)).
    pub fn sample(&self, nm: f32, r: f32, u_choice: f32, u_nm: f32) -> Reradiation {
        let reflected = (1.0 - self.concentration * self.absorption(nm)) * r;
        let below = self.absorbed_up_to(nm);
        let reradiated = self.concentration * self.quantum_yield * self.emission(nm) * below as f32;
        let weight = reflected + reradiated;
        if !(reradiated > 0.0) || u_choice * weight < reflected {
            return Reradiation { nm, weight };
        }
        // Invert the running sum of the absorption below `nm`.
        let target = f64::from(u_nm) * below;
        let i = self
            .absorbed_below
            .partition_point(|&s| s <= target)
            .clamp(1, BINS)
            - 1;
        let a = f64::from(self.absorption[i]);
        let within = if a > 0.0 {
            ((target - self.absorbed_below[i]) / a).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let from = (LAMBDA_MIN + i as f32 + within as f32).min(nm.next_down());
        Reradiation { nm: from, weight }
    }
}
