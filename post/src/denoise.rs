//! Denoising a frame's layers.

use glam::Vec3;
use tracer::film::Layers;

use crate::oidn::{NoisyImage, Oidn, OidnError};

/// The denoised beauty of `layers` (a whole frame: the denoiser sees across tile edges),
/// guided by their albedo and normal, on `threads` threads (0: all cores).
pub fn denoise_layers(oidn: &Oidn, layers: &Layers, threads: u32) -> Result<Vec<Vec3>, OidnError> {
    oidn.denoise(
        &NoisyImage {
            width: layers.rect.width as usize,
            height: layers.rect.height as usize,
            beauty: &layers.beauty,
            albedo: &layers.albedo,
            normal: &layers.normal,
        },
        threads,
    )
}
