//! What a path carries: RGB, or values at the wavelengths it samples (the spectral path,
//! for wavelength-dependent features). The path loop is written once over [`Carrier`] and
//! compiled for each, so the RGB path stays what it was.
//!
//! Materials, textures and lights are RGB. The spectral path lifts each RGB quantity a
//! bounce produces to a smooth spectrum at the path's wavelengths (Jakob & Hanika 2019,
//! `spectrum::upsample`): a BSDF value or sample weight as a spectrum of that colour, light
//! as that colour times D65, or times the light's own spectrum where it has one. For a diffuse surface the weight is its albedo, so this is
//! lifting the material's colour; greys (every colourless lobe) lift to exactly flat
//! spectra, so a white surface under white light is the same in both paths.

use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign};

use glam::{Vec3, Vec4};

use crate::math;
use crate::spectrum::{
    self, DenseSpectrum, IlluminantSpectrum, SampledWavelengths, UnboundedSpectrum,
};

/// Arithmetic a path does on what it carries.
pub(crate) trait Colour:
    Copy
    + PartialEq
    + Add<Output = Self>
    + AddAssign
    + Mul<Output = Self>
    + MulAssign
    + Mul<f32, Output = Self>
    + Div<f32, Output = Self>
    + DivAssign<f32>
{
    const ZERO: Self;
    const ONE: Self;
    fn max_element(self) -> f32;
    fn is_finite(self) -> bool;
}

impl Colour for Vec3 {
    const ZERO: Self = Vec3::ZERO;
    const ONE: Self = Vec3::ONE;
    #[inline(always)]
    fn max_element(self) -> f32 {
        Vec3::max_element(self)
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        math::finite(self)
    }
}

impl Colour for Vec4 {
    const ZERO: Self = Vec4::ZERO;
    const ONE: Self = Vec4::ONE;
    #[inline(always)]
    fn max_element(self) -> f32 {
        Vec4::max_element(self)
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        Vec4::is_finite(self)
    }
}

/// How a path turns RGB quantities into what it carries, and back for the film.
pub(crate) trait Carrier: Copy {
    type Colour: Colour;
    /// Whether it carries wavelengths (so that the RGB path compiles out what only the
    /// spectral path does).
    const SPECTRAL: bool;
    /// A BSDF value, sample weight or transmittance of RGB colour `rgb` (any size).
    fn weight(&self, rgb: Vec3) -> Self::Colour;
    /// Radiance of light of RGB colour `rgb`: white is D65, or `spectrum` where the light
    /// has its own (TESSERA_lights_spectrum), which the colour then filters.
    fn light(&self, rgb: Vec3, spectrum: Option<&DenseSpectrum>) -> Self::Colour;
    /// Linear Rec. 709 of what a path gathered.
    fn to_rgb(&self, c: Self::Colour) -> Vec3;
    /// From here on carries the hero wavelength alone, and gives it (in nm): where a
    /// dispersive refraction sends each wavelength its own way, or fluorescence changes
    /// it. `None` for a carrier without wavelengths.
    fn keep_hero(&mut self) -> Option<f32>;
    /// `c` at the hero wavelength alone.
    fn hero_only(c: Self::Colour) -> Self::Colour;
    /// The hero now travels at `nm` (fluorescence, followed back from the camera), while
    /// the film still counts it at the wavelength it was sampled at.
    fn shift_hero(&mut self, nm: f32);
}

/// The RGB path: everything is already RGB.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Rgb;

impl Carrier for Rgb {
    type Colour = Vec3;
    const SPECTRAL: bool = false;
    #[inline(always)]
    fn weight(&self, rgb: Vec3) -> Vec3 {
        rgb
    }
    #[inline(always)]
    fn light(&self, rgb: Vec3, _: Option<&DenseSpectrum>) -> Vec3 {
        rgb
    }
    #[inline(always)]
    fn to_rgb(&self, c: Vec3) -> Vec3 {
        c
    }
    fn keep_hero(&mut self) -> Option<f32> {
        None
    }
    fn hero_only(c: Vec3) -> Vec3 {
        c
    }
    fn shift_hero(&mut self, _: f32) {}
}

impl Carrier for SampledWavelengths {
    type Colour = Vec4;
    const SPECTRAL: bool = true;
    fn weight(&self, rgb: Vec3) -> Vec4 {
        if rgb == Vec3::ZERO {
            return Vec4::ZERO;
        }
        let s = UnboundedSpectrum::new(rgb);
        Vec4::from_array(self.lambda.map(|nm| s.eval(nm)))
    }
    fn light(&self, rgb: Vec3, spectrum: Option<&DenseSpectrum>) -> Vec4 {
        if rgb == Vec3::ZERO {
            return Vec4::ZERO;
        }
        match spectrum {
            None => {
                let s = IlluminantSpectrum::new(rgb);
                Vec4::from_array(self.lambda.map(|nm| s.eval(nm)))
            }
            Some(white) => {
                let s = UnboundedSpectrum::new(rgb);
                Vec4::from_array(self.lambda.map(|nm| s.eval(nm) * white.eval(nm)))
            }
        }
    }
    fn to_rgb(&self, c: Vec4) -> Vec3 {
        spectrum::to_rec709(c, self)
    }
    fn keep_hero(&mut self) -> Option<f32> {
        self.terminate_secondary();
        Some(self.lambda[0])
    }
    fn hero_only(c: Vec4) -> Vec4 {
        Vec4::new(c.x, 0.0, 0.0, 0.0)
    }
    fn shift_hero(&mut self, nm: f32) {
        self.lambda[0] = nm;
    }
}
