//! The spectra a frame's lights and materials carry (TESSERA_lights_spectrum,
//! TESSERA_materials_fluorescence), tabulated once per frame for the spectral path.

use std::collections::BTreeMap;

use crate::scene::Scene;
use crate::spectrum::{DenseSpectrum, Fluorescence, SpectrumShape};

/// The spectra of a frame's lights and emissive materials (TESSERA_lights_spectrum),
/// tabulated once, and which light and material has which.
pub(super) struct FrameSpectra {
    pub dense: Vec<DenseSpectrum>,
    /// Scene light → index in `dense`.
    pub of_light: BTreeMap<u32, u32>,
    /// Per scene material, the index in `dense` of its emission's spectrum.
    pub of_material: Vec<Option<u32>>,
    /// The fluorescent paints (TESSERA_materials_fluorescence), and per scene material
    /// the index of its own in `paints`.
    pub paints: Vec<Fluorescence>,
    pub paint_of_material: Vec<Option<u32>>,
}

impl FrameSpectra {
    pub fn new(scene: &Scene) -> Self {
        let mut dense = Vec::new();
        // A shape with no power in the visible band (the loader refuses those) emits
        // white rather than nothing.
        let mut add = |shape: &SpectrumShape| {
            let spectrum = DenseSpectrum::light(shape)?;
            dense.push(spectrum);
            Some(dense.len() as u32 - 1)
        };
        let of_light = scene
            .light_spectra
            .iter()
            .filter_map(|(&light, shape)| Some((light, add(shape)?)))
            .collect();
        let of_material = scene
            .materials
            .iter()
            .map(|m| m.emission_spectrum.as_ref().and_then(&mut add))
            .collect();
        let mut paints = Vec::new();
        let paint_of_material = scene
            .materials
            .iter()
            .map(|m| {
                let paint =
                    Fluorescence::new(m.fluorescence.as_ref().filter(|_| m.is_fluorescent())?)?;
                paints.push(paint);
                Some(paints.len() as u32 - 1)
            })
            .collect();
        Self {
            dense,
            of_light,
            of_material,
            paints,
            paint_of_material,
        }
    }
}
