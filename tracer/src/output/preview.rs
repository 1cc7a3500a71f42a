//! PNG previews: linear beauty, scaled by an exposure in stops, tone-mapped per channel
//! with the ACES filmic curve as fitted by Krzysztof Narkowicz (2015), encoded with the
//! sRGB OETF into 8 bits.
//!
//! Narkowicz's fit is used rather than Stephen Hill's fitted RRT+ODT: it is one rational
//! function per channel, cheap, and close to the reference curve in the range a preview
//! shows; the preview is for looking at, the EXR is the product. The curve is applied to
//! the exposure-scaled values with no further scale (some implementations multiply by 0.6
//! first; an exposure of log2(0.6) ≈ −0.74 stops gives that).

use std::io::Write;
use std::path::Path;

use glam::Vec4;
use rayon::prelude::*;

use super::{atomic, check_shape, OutputError};
use crate::film::Layers;

/// The ACES filmic curve (Narkowicz 2015): `x(2.51x + 0.03) / (x(2.43x + 0.59) + 0.14)`,
/// clamped to `[0, 1]`. It maps 0 to 0, rises monotonically and reaches 1 at x ≈ 7.24
/// (the rational function alone would level off at 2.51 / 2.43 > 1). Negative values and
/// NaN give 0.
pub fn aces_filmic(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        return 0.0;
    }
    // The curve reaches 1 at x = (0.56 + √0.3584) / 0.16 ≈ 7.2417; stopping at 8 also keeps
    // x² from overflowing into inf / inf for huge inputs.
    if x >= 8.0 {
        return 1.0;
    }
    let y = x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14);
    y.clamp(0.0, 1.0)
}

/// The sRGB opto-electronic transfer function (IEC 61966-2-1): linear `[0, 1]` to encoded
/// `[0, 1]`; inputs outside are clamped, NaN gives 0.
pub fn srgb_oetf(linear: f32) -> f32 {
    let x = if linear > 0.0 { linear } else { 0.0 };
    if x >= 1.0 {
        1.0 // exactly, where the formula gives 0.99999994 in f32
    } else if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * crate::math::powf(x, 1.0 / 2.4) - 0.055
    }
}

/// One preview pixel: tone-mapped, encoded, opaque.
fn preview_pixel(beauty: Vec4, scale: f32) -> [u8; 4] {
    let encode = |v: f32| (srgb_oetf(aces_filmic(v * scale)) * 255.0).round() as u8;
    [encode(beauty.x), encode(beauty.y), encode(beauty.z), 255]
}

/// 2^`exposure` (in stops); a non-finite exposure counts as 0 stops.
fn exposure_scale(exposure: f32) -> f32 {
    if exposure.is_finite() {
        crate::math::exp2(exposure)
    } else {
        1.0
    }
}

/// The beauty layer (its denoised RGB where the layers have one) as 8-bit sRGB RGBA,
/// row-major over `layers.rect`, 4 bytes a pixel: linear RGB times 2^`exposure` (stops; 0
/// leaves it as is), ACES filmic per channel, then the sRGB OETF, rounded.
///
/// Alpha is 255: the beauty RGB already holds what rays that missed saw (the
/// environment), so using the EXR's coverage alpha here would cut the sky out of the
/// preview. Coverage stays in the EXR's `A` channel for compositing.
pub fn preview_rgba8(layers: &Layers, exposure: f32) -> Vec<u8> {
    let scale = exposure_scale(exposure);
    let mut out = vec![0u8; layers.beauty.len() * 4];
    if layers.denoised.is_empty() {
        out.par_chunks_mut(4)
            .zip(layers.beauty.par_iter())
            .for_each(|(px, &b)| px.copy_from_slice(&preview_pixel(b, scale)));
    } else {
        out.par_chunks_mut(4)
            .zip(layers.denoised.par_iter())
            .for_each(|(px, &d)| px.copy_from_slice(&preview_pixel(d.extend(1.0), scale)));
    }
    out
}

/// A PNG of the whole `frame_size` frame: the data window `layers.rect` as
/// [`preview_rgba8`], every pixel outside it transparent (a `--region` render shows where
/// its region lies).
pub fn encode_preview_png(
    frame_size: (u32, u32),
    layers: &Layers,
    exposure: f32,
) -> Result<Vec<u8>, OutputError> {
    check_shape(frame_size, layers)?;
    let (fw, fh) = (frame_size.0 as usize, frame_size.1 as usize);
    let rect = layers.rect;
    let region = preview_rgba8(layers, exposure);

    let canvas = if (rect.x, rect.y, rect.width, rect.height) == (0, 0, frame_size.0, frame_size.1)
    {
        region
    } else {
        let mut canvas = vec![0u8; fw * fh * 4];
        let row_bytes = rect.width as usize * 4;
        for (row, src) in region.chunks_exact(row_bytes).enumerate() {
            let start = ((rect.y as usize + row) * fw + rect.x as usize) * 4;
            canvas[start..start + row_bytes].copy_from_slice(src);
        }
        canvas
    };

    let mut png = Vec::new();
    let mut writer = png_writer(&mut png, frame_size)?;
    let mut stream = writer.stream_writer().map_err(OutputError::Png)?;
    stream
        .write_all(&canvas)
        .map_err(|e| OutputError::Png(e.into()))?;
    stream.finish().map_err(OutputError::Png)?;
    writer.finish().map_err(OutputError::Png)?;
    Ok(png)
}

/// A PNG of a `frame_size` frame being written to `w`, its header written: 8-bit sRGB
/// RGBA, to be given rows of [`preview_rgba8`] in order through its stream writer, then
/// finished. Whole previews and frames written band by band go through it alike, so they
/// come out byte for byte the same.
pub(super) fn png_writer<W: Write>(
    w: W,
    frame_size: (u32, u32),
) -> Result<png::Writer<W>, OutputError> {
    let mut encoder = png::Encoder::new(w, frame_size.0, frame_size.1);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Balanced);
    encoder.set_filter(png::Filter::Adaptive);
    encoder.write_header().map_err(OutputError::Png)
}

/// [`encode_preview_png`] written atomically to `path` (temp file, fsync, rename).
pub fn write_preview_png(
    path: &Path,
    frame_size: (u32, u32),
    layers: &Layers,
    exposure: f32,
) -> Result<(), OutputError> {
    let png = encode_preview_png(frame_size, layers, exposure)?;
    atomic::write(path, &png)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::film::TileRect;

    /// The curve as written in Narkowicz's post, in f64.
    fn narkowicz(x: f64) -> f64 {
        (x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0)
    }

    #[test]
    fn aces_maps_zero_to_zero_and_mid_grey_to_the_formula() {
        assert_eq!(aces_filmic(0.0), 0.0);
        // 0.18·(2.51·0.18 + 0.03) / (0.18·(2.43·0.18 + 0.59) + 0.14) = 0.086724 / 0.324932
        let expected = 0.086_724 / 0.324_932;
        assert!((aces_filmic(0.18) as f64 - expected).abs() < 1e-6);
        assert!((aces_filmic(0.18) as f64 - narkowicz(0.18)).abs() < 1e-6);
    }

    #[test]
    fn aces_is_monotone_and_saturates_at_one() {
        let mut last = 0.0;
        for i in 1..=20_000 {
            let y = aces_filmic(i as f32 * 1e-3);
            assert!(y >= last, "not monotone at {}", i as f32 * 1e-3);
            assert!(y <= 1.0);
            last = y;
        }
        assert!(
            aces_filmic(7.0) < 1.0,
            "still below white just under x ≈ 7.24"
        );
        assert!(aces_filmic(7.24) < 1.0 && aces_filmic(7.25) == 1.0);
        assert_eq!(aces_filmic(7.5), 1.0);
        assert_eq!(aces_filmic(1e30), 1.0);
        assert_eq!(aces_filmic(f32::INFINITY), 1.0);
        assert_eq!(aces_filmic(f32::NAN), 0.0);
        assert_eq!(aces_filmic(-1.0), 0.0);
    }

    #[test]
    fn srgb_oetf_matches_the_standard() {
        assert_eq!(srgb_oetf(0.0), 0.0);
        assert_eq!(srgb_oetf(1.0), 1.0);
        assert!((srgb_oetf(0.002) - 0.02584).abs() < 1e-6, "linear toe");
        assert!((srgb_oetf(0.5) - 0.735_357).abs() < 1e-5);
        assert_eq!(srgb_oetf(2.0), 1.0);
        assert_eq!(srgb_oetf(f32::NAN), 0.0);
    }

    #[test]
    fn exposure_is_in_stops() {
        let mut layers = Layers::new(TileRect::new(0, 0, 1, 1));
        layers.beauty[0] = Vec4::new(0.09, 0.09, 0.09, 1.0);
        assert_eq!(
            preview_rgba8(&layers, 1.0),
            preview_rgba8(
                &Layers {
                    beauty: vec![Vec4::splat(0.18)],
                    ..layers.clone()
                },
                0.0
            )
        );
        assert_eq!(
            preview_rgba8(&layers, f32::NAN),
            preview_rgba8(&layers, 0.0)
        );
    }
}
