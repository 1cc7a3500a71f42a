//! Output files: multi-layer OpenEXR images and tone-mapped PNG previews.
//!
//! | file | what it holds |
//! |---|---|
//! | `output/attributes.rs` | [`ExrMetadata`]: the header's string attributes, written and read back |
//! | `output/exr.rs` | [`encode_exr`] / [`decode_exr`], their file twins, [`validate_tile`] |
//! | `output/preview.rs` | the ACES filmic curve, the sRGB OETF, 8-bit RGBA previews and PNGs |
//! | `output/bands.rs` | frames larger than memory: EXR and PNG written band by band, EXR rows read alone |
//! | `output/atomic.rs` | writing a file atomically: temp file, fsync, rename |
//!
//! An EXR holds one part, scan lines with ZIP compression (or none), every channel `f32`, named as
//! compositors and the OpenEXR tools expect ([`CHANNEL_NAMES`]). The display window is the
//! whole frame and the data window is the rectangle of the [`Layers`], so a tile or a
//! `--region` render keeps its place in the frame. Workers upload tiles as EXR bytes; the
//! server checks them with [`validate_tile`] and assembles frames with
//! [`Layers::paste`](crate::film::Layers::paste).

mod atomic;
mod attributes;
mod bands;
mod exr;
mod preview;

use std::path::PathBuf;

use crate::film::{Layers, TileRect};

pub use self::atomic::write as write_atomic;
pub use self::attributes::ExrMetadata;
pub use self::bands::{
    frame_bands, read_exr_rows, write_frame_in_bands, ExrTarget, PreviewTarget, BLOCK_ROWS,
};
pub use self::exr::{
    check_finite, decode_exr, encode_exr, encode_exr_layers, read_exr, validate_tile, write_exr,
    ExrCompression, ExrImage, ImageLayer, CHANNEL_NAMES, DENOISED_CHANNELS,
};
pub use self::preview::{
    aces_filmic, encode_preview_png, preview_rgba8, srgb_oetf, write_preview_png,
};

/// Why an image could not be written, read or accepted.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file (or, for a temp file, the file it was to become).
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// The content of a file was refused; `source` says why.
    #[error("{}: {source}", path.display())]
    File {
        /// The file read.
        path: PathBuf,
        /// What is wrong with it.
        #[source]
        source: Box<OutputError>,
    },
    /// The bytes are not a readable OpenEXR image: corrupt, truncated or not EXR at all.
    #[error("not a readable OpenEXR image: {0}")]
    Corrupt(#[source] ::exr::error::Error),
    /// Valid OpenEXR, but a kind Tessera does not read (deep data, subsampled channels).
    #[error("unsupported OpenEXR image: {0}")]
    Unsupported(String),
    /// The OpenEXR encoder refused the image.
    #[error("cannot encode OpenEXR image: {0}")]
    Encode(#[source] ::exr::error::Error),
    /// The PNG encoder failed.
    #[error("cannot encode PNG preview: {0}")]
    Png(#[source] png::EncodingError),
    /// A channel that must be present is not.
    #[error("no channel `{channel}` in the image (channels present: {})", present.join(", "))]
    MissingChannel {
        /// The channel looked for.
        channel: String,
        /// The channels the image has.
        present: Vec<String>,
    },
    /// The display window is not the frame expected.
    #[error(
        "display window is {}x{} but the frame is {}x{}",
        found.0, found.1, expected.0, expected.1
    )]
    WrongFrameSize {
        /// The frame size expected.
        expected: (u32, u32),
        /// The display window found.
        found: (u32, u32),
    },
    /// The data window is not the tile expected.
    #[error("data window is {} but the tile is {}", rect_text(*found), rect_text(*expected))]
    WrongDataWindow {
        /// The tile expected.
        expected: TileRect,
        /// The data window found.
        found: TileRect,
    },
    /// A window Tessera cannot represent or write: empty, negative, outside the frame.
    #[error("{0}")]
    BadWindow(String),
    /// A layer's buffer does not hold one value per pixel of its rectangle.
    #[error("layer `{layer}` holds {len} pixels but its rectangle {} has {expected}", rect_text(*rect))]
    LayerSize {
        /// `beauty`, `albedo`, `normal` or `depth`.
        layer: &'static str,
        /// The number of values held.
        len: usize,
        /// The number of pixels in the rectangle.
        expected: usize,
        /// The rectangle.
        rect: TileRect,
    },
    /// A pixel holds NaN or an infinity.
    #[error("channel `{channel}` holds {value} at pixel ({x}, {y})")]
    NonFinite {
        /// The channel, as named in the EXR file.
        channel: &'static str,
        /// Column in the frame.
        x: u32,
        /// Row in the frame.
        y: u32,
        /// The value found.
        value: f32,
    },
    /// A header attribute cannot be written.
    #[error("header attribute `{name}`: {reason}")]
    BadAttribute {
        /// The attribute's name.
        name: String,
        /// What is wrong with it.
        reason: &'static str,
    },
}

/// `64x32 at (128, 0)`: a rectangle as error messages show it.
fn rect_text(r: TileRect) -> String {
    format!("{}x{} at ({}, {})", r.width, r.height, r.x, r.y)
}

/// Checks that `layers` can be written as the data window of a `frame_size` frame: a
/// non-empty rectangle inside a non-empty frame that OpenEXR's `i32` coordinates can hold,
/// and one value per pixel in every layer.
fn check_shape(frame_size: (u32, u32), layers: &Layers) -> Result<(), OutputError> {
    check_frame_size(frame_size)?;
    let (w, h) = frame_size;
    let rect = layers.rect;
    if rect.area() == 0 {
        return Err(OutputError::BadWindow(format!(
            "data window {} is empty; an image needs at least one pixel",
            rect_text(rect)
        )));
    }
    if !rect.fits_in(w, h) {
        return Err(OutputError::BadWindow(format!(
            "data window {} lies outside the {w}x{h} frame",
            rect_text(rect)
        )));
    }
    check_lengths(layers)
}

/// Checks that a `frame_size` frame is not empty and that OpenEXR's `i32` coordinates
/// can hold it.
fn check_frame_size(frame_size: (u32, u32)) -> Result<(), OutputError> {
    let (w, h) = frame_size;
    if w == 0 || h == 0 {
        return Err(OutputError::BadWindow(format!("frame {w}x{h} is empty")));
    }
    if w > i32::MAX as u32 || h > i32::MAX as u32 {
        return Err(OutputError::BadWindow(format!(
            "frame {w}x{h} is too large for OpenEXR"
        )));
    }
    Ok(())
}

/// Checks that every layer holds one value per pixel of `layers.rect`.
fn check_lengths(layers: &Layers) -> Result<(), OutputError> {
    let rect = layers.rect;
    let expected = rect.area();
    let lens = [
        ("beauty", layers.beauty.len()),
        ("albedo", layers.albedo.len()),
        ("normal", layers.normal.len()),
        ("depth", layers.depth.len()),
        ("samples", layers.samples.len()),
        ("noise", layers.noise.len()),
        ("motion", layers.motion.len()),
        ("variance", layers.variance.len()),
    ];
    let denoised = match layers.denoised.len() {
        0 => None,
        len => Some(("denoised", len)),
    };
    for (layer, len) in lens.into_iter().chain(denoised) {
        if len != expected {
            return Err(OutputError::LayerSize {
                layer,
                len,
                expected,
                rect,
            });
        }
    }
    Ok(())
}
