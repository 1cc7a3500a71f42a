//! Multi-layer OpenEXR: one part, scan lines, ZIP (or uncompressed), `f32` channels.
//!
//! Every channel is `f32`, albedo, normal and depth included: half floats would halve
//! those layers, but depth at [`NO_HIT_DEPTH`](crate::film::NO_HIT_DEPTH) (1e10) does not
//! fit in a half, and one sample type keeps tiles bit-exact from worker to assembled frame.

use std::io::Cursor;
use std::path::Path;

use ::exr::block::writer::ChunksWriter;
use ::exr::block::{BlockIndex, UncompressedBlock};
use ::exr::compression::Compression;
use ::exr::error::UnitResult;
use ::exr::math::Vec2;
use ::exr::meta::attribute::{
    ChannelDescription, Chromaticities, IntegerBounds, LineOrder, SampleType, Text,
};
use ::exr::meta::header::{Header, ImageAttributes, LayerAttributes};
use ::exr::meta::{BlockDescription, MetaData};
use ::exr::prelude::traits::{read, ReadChannels, ReadLayers};
use rayon::prelude::*;
use smallvec::{smallvec, SmallVec};

use super::attributes::{set_attributes, string_attributes, ExrMetadata};
use super::{atomic, check_lengths, check_shape, rect_text, OutputError};
use crate::film::{Layers, TileRect};

/// The channels of a Tessera EXR, in the order of [`Layers`]' fields: beauty `R G B A`
/// (linear Rec.709, alpha is coverage), albedo, world-space shading normal, depth `Z`,
/// samples taken per pixel, the estimated relative error `noise`, the screen-space motion
/// over the shutter in pixels (x right, y down) and each pixel's estimated variance.
pub const CHANNEL_NAMES: [&str; 18] = [
    "R",
    "G",
    "B",
    "A",
    "albedo.R",
    "albedo.G",
    "albedo.B",
    "N.X",
    "N.Y",
    "N.Z",
    "Z",
    "samples",
    "noise",
    "motion.X",
    "motion.Y",
    "variance.R",
    "variance.G",
    "variance.B",
];

/// The channels of the denoised beauty, which only a whole frame can have (a denoiser
/// sees across tile edges): [`Layers::denoised`].
pub const DENOISED_CHANNELS: [&str; 3] = ["denoised.R", "denoised.G", "denoised.B"];

/// Where each of [`CHANNEL_NAMES`] lives in [`Layers`].
const SLOTS: [Slot; 18] = [
    Slot::Beauty(0),
    Slot::Beauty(1),
    Slot::Beauty(2),
    Slot::Beauty(3),
    Slot::Albedo(0),
    Slot::Albedo(1),
    Slot::Albedo(2),
    Slot::Normal(0),
    Slot::Normal(1),
    Slot::Normal(2),
    Slot::Depth,
    Slot::Samples,
    Slot::Noise,
    Slot::Motion(0),
    Slot::Motion(1),
    Slot::Variance(0),
    Slot::Variance(1),
    Slot::Variance(2),
];

/// A layer of a Tessera EXR: the channels of one of [`Layers`]' fields.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ImageLayer {
    /// `R G B A`: always written.
    Beauty,
    /// `albedo.R albedo.G albedo.B`.
    Albedo,
    /// `N.X N.Y N.Z`.
    Normal,
    /// `Z`.
    Depth,
    /// `samples`.
    Samples,
    /// `noise`.
    Noise,
    /// `motion.X motion.Y`.
    Motion,
    /// `variance.R variance.G variance.B`.
    Variance,
    /// `denoised.R denoised.G denoised.B`: written where the [`Layers`] have it.
    Denoised,
}

impl ImageLayer {
    /// The layers the tracer renders, in file order: every tile has them.
    pub const RENDERED: [ImageLayer; 8] = [
        ImageLayer::Beauty,
        ImageLayer::Albedo,
        ImageLayer::Normal,
        ImageLayer::Depth,
        ImageLayer::Samples,
        ImageLayer::Noise,
        ImageLayer::Motion,
        ImageLayer::Variance,
    ];

    /// Every layer, in file order.
    pub const ALL: [ImageLayer; 9] = [
        ImageLayer::Beauty,
        ImageLayer::Albedo,
        ImageLayer::Normal,
        ImageLayer::Depth,
        ImageLayer::Samples,
        ImageLayer::Noise,
        ImageLayer::Motion,
        ImageLayer::Variance,
        ImageLayer::Denoised,
    ];
}

/// One component of one layer.
#[derive(Clone, Copy)]
pub(super) enum Slot {
    Beauty(usize),
    Albedo(usize),
    Normal(usize),
    Depth,
    Samples,
    Noise,
    Motion(usize),
    Variance(usize),
    Denoised(usize),
}

/// Every channel a Tessera EXR can hold, with where it lives in [`Layers`].
fn all_channels() -> impl Iterator<Item = (&'static str, Slot)> {
    CHANNEL_NAMES.into_iter().zip(SLOTS).chain(
        DENOISED_CHANNELS
            .into_iter()
            .zip([0, 1, 2].map(Slot::Denoised)),
    )
}

impl Slot {
    /// The layer this component belongs to.
    fn layer(self) -> ImageLayer {
        match self {
            Slot::Beauty(_) => ImageLayer::Beauty,
            Slot::Albedo(_) => ImageLayer::Albedo,
            Slot::Normal(_) => ImageLayer::Normal,
            Slot::Depth => ImageLayer::Depth,
            Slot::Samples => ImageLayer::Samples,
            Slot::Noise => ImageLayer::Noise,
            Slot::Motion(_) => ImageLayer::Motion,
            Slot::Variance(_) => ImageLayer::Variance,
            Slot::Denoised(_) => ImageLayer::Denoised,
        }
    }

    /// The value of this component at pixel `i`.
    pub(super) fn get(self, layers: &Layers, i: usize) -> f32 {
        match self {
            Slot::Beauty(c) => layers.beauty[i][c],
            Slot::Albedo(c) => layers.albedo[i][c],
            Slot::Normal(c) => layers.normal[i][c],
            Slot::Depth => layers.depth[i],
            Slot::Samples => layers.samples[i],
            Slot::Noise => layers.noise[i],
            Slot::Motion(c) => layers.motion[i][c],
            Slot::Variance(c) => layers.variance[i][c],
            Slot::Denoised(c) => layers.denoised[i][c],
        }
    }

    /// Sets this component at pixel `i` (making the denoised layer when it is the first
    /// of its values).
    pub(super) fn set(self, layers: &mut Layers, i: usize, v: f32) {
        if let Slot::Denoised(_) = self {
            if layers.denoised.is_empty() {
                layers.denoised = vec![glam::Vec3::ZERO; layers.rect.area()];
            }
        }
        match self {
            Slot::Beauty(c) => layers.beauty[i][c] = v,
            Slot::Albedo(c) => layers.albedo[i][c] = v,
            Slot::Normal(c) => layers.normal[i][c] = v,
            Slot::Depth => layers.depth[i] = v,
            Slot::Samples => layers.samples[i] = v,
            Slot::Noise => layers.noise[i] = v,
            Slot::Motion(c) => layers.motion[i][c] = v,
            Slot::Variance(c) => layers.variance[i][c] = v,
            Slot::Denoised(c) => layers.denoised[i][c] = v,
        }
    }
}

/// Images of at least this many pixels are compressed and decompressed on several
/// threads. The `exr` crate builds a new thread pool for each parallel image, which costs
/// more than it saves on a typical 64×64 tile.
const PARALLEL_MIN_PIXELS: usize = 512 * 512;

/// An EXR file read back.
#[derive(Clone, Debug, PartialEq)]
pub struct ExrImage {
    /// Size of the display window: the whole frame.
    pub frame_size: (u32, u32),
    /// The data window's pixels; `layers.rect` is the data window, relative to the
    /// display window's corner.
    pub layers: Layers,
    /// Every string attribute of the header, sorted by name (custom ones, and standard
    /// text ones such as `software`).
    pub attributes: Vec<(String, String)>,
}

impl ExrImage {
    /// The value of the string attribute `name`, if present.
    pub fn attribute(&self, name: &str) -> Option<&str> {
        self.attributes
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }
}

/// How an EXR's scan lines are stored. Both are lossless and read by every EXR reader.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ExrCompression {
    /// Deflate over 16 scan lines: a rendered tile shrinks to about a third, at about
    /// 35 MB/s of raw data on one core.
    #[default]
    Zip,
    /// The raw `f32` values: ten times faster to write than ZIP, three times the bytes.
    Uncompressed,
}

/// Encodes `layers` as the data window of a `frame_size` frame: one EXR part, ZIP
/// compressed scan lines, the channels of [`CHANNEL_NAMES`] (and [`DENOISED_CHANNELS`]
/// where the layers have them) in `f32`, Rec.709 chromaticities, and `meta` as string
/// attributes.
pub fn encode_exr(
    frame_size: (u32, u32),
    layers: &Layers,
    meta: &ExrMetadata,
) -> Result<Vec<u8>, OutputError> {
    encode_exr_layers(
        frame_size,
        layers,
        meta,
        &ImageLayer::ALL,
        ExrCompression::Zip,
    )
}

/// [`encode_exr`] with only the `wanted` layers' channels (beauty is always written; the
/// denoised beauty where `layers` have it), stored with `compression`.
pub fn encode_exr_layers(
    frame_size: (u32, u32),
    layers: &Layers,
    meta: &ExrMetadata,
    wanted: &[ImageLayer],
    compression: ExrCompression,
) -> Result<Vec<u8>, OutputError> {
    check_shape(frame_size, layers)?;
    let present: SmallVec<[ImageLayer; 7]> = wanted
        .iter()
        .copied()
        .filter(|&l| l != ImageLayer::Denoised || !layers.denoised.is_empty())
        .collect();
    let header = header(frame_size, layers.rect, meta, &present, compression)?;
    let mut out = Cursor::new(Vec::new());
    ::exr::block::write(&mut out, smallvec![header], true, |meta, chunks| {
        write_blocks(&meta, chunks, layers)
    })
    .map_err(OutputError::Encode)?;
    Ok(out.into_inner())
}

/// The one header of a Tessera EXR whose data window is `rect` in a `frame_size` frame:
/// scan lines in increasing y, the `wanted` layers' channels (beauty always) in `f32`,
/// sorted by name as OpenEXR requires, Rec.709 chromaticities, `meta` as string
/// attributes.
pub(super) fn header(
    frame_size: (u32, u32),
    rect: TileRect,
    meta: &ExrMetadata,
    wanted: &[ImageLayer],
    compression: ExrCompression,
) -> Result<Header, OutputError> {
    let mut channels: SmallVec<[ChannelDescription; 5]> = all_channels()
        .filter(|(_, slot)| slot.layer() == ImageLayer::Beauty || wanted.contains(&slot.layer()))
        .map(|(name, _)| ChannelDescription::named(name, SampleType::F32))
        .collect();
    channels.sort_unstable_by(|a, b| a.name.cmp(&b.name));

    let mut layer_attributes = LayerAttributes {
        layer_position: Vec2(rect.x as i32, rect.y as i32),
        software_name: Some(Text::from(concat!("Tessera ", env!("CARGO_PKG_VERSION")))),
        ..LayerAttributes::default()
    };
    set_attributes(&mut layer_attributes, meta)?;

    let display = IntegerBounds::new(
        Vec2(0, 0),
        Vec2(frame_size.0 as usize, frame_size.1 as usize),
    );
    let mut image_attributes = ImageAttributes::new(display);
    // The tracer works in linear sRGB (glTF's colour space): Rec.709 primaries, D65.
    image_attributes.chromaticities = Some(Chromaticities {
        red: Vec2(0.64, 0.33),
        green: Vec2(0.30, 0.60),
        blue: Vec2(0.15, 0.06),
        white: Vec2(0.3127, 0.3290),
    });

    let compression = match compression {
        // Deflate over 16 scan lines.
        ExrCompression::Zip => Compression::ZIP16,
        ExrCompression::Uncompressed => Compression::Uncompressed,
    };
    Ok(Header::new(
        Text::from(""),
        Vec2(rect.width as usize, rect.height as usize),
        channels,
    )
    .with_encoding(
        compression,
        BlockDescription::ScanLines,
        LineOrder::Increasing,
    )
    .with_shared_attributes(image_attributes)
    .with_attributes(layer_attributes))
}

/// Writes the scan-line blocks that `layers` covers: whole rows of the header's data
/// window, starting at a block boundary (or ending at the window's last row). Blocks are
/// compressed in parallel when there is enough of them to pay for it.
pub(super) fn write_blocks(
    meta: &MetaData,
    chunks: &mut impl ChunksWriter,
    layers: &Layers,
) -> UnitResult {
    let header = &meta.headers[0];
    let window = header.data_window();
    let rows = header.compression.scan_lines_per_block();
    let first = layers.rect.y as usize - window.position.1 as usize;
    let slots: Vec<Slot> = header
        .channels
        .list
        .iter()
        .map(|c| slot_named(&c.name.to_string()).expect("Tessera writes its own channels"))
        .collect();
    let blocks = (0..layers.rect.height as usize).step_by(rows).map(|row| {
        let index = BlockIndex {
            layer: 0,
            level: Vec2(0, 0),
            pixel_position: Vec2(0, first + row),
            pixel_size: Vec2(
                layers.rect.width as usize,
                rows.min(layers.rect.height as usize - row),
            ),
        };
        ((first + row) / rows, index)
    });
    let compress = |(number, index): (usize, BlockIndex)| {
        let block = UncompressedBlock::from_lines(&header.channels, index, |line| {
            let slot = slots[line.location.channel];
            let y = line.location.position.1 - first;
            let start = y * layers.rect.width as usize;
            line.write_samples(|i| slot.get(layers, start + i))
                .expect("a line holds one f32 per pixel");
        });
        block
            .compress_to_chunk(&meta.headers)
            .map(|chunk| (number, chunk))
    };
    let compressed: Vec<_> = if layers.rect.area() >= PARALLEL_MIN_PIXELS {
        blocks
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(compress)
            .collect()
    } else {
        blocks.map(compress).collect()
    };
    for result in compressed {
        let (number, chunk) = result?;
        chunks.write_chunk(number, chunk)?;
    }
    Ok(())
}

/// The component of [`Layers`] that the channel `name` holds, if it is one of
/// [`CHANNEL_NAMES`] or [`DENOISED_CHANNELS`].
pub(super) fn slot_named(name: &str) -> Option<Slot> {
    all_channels()
        .find(|&(n, _)| n == name)
        .map(|(_, slot)| slot)
}

/// [`encode_exr`] written atomically to `path` (a temp file in the same folder, fsync,
/// rename), so that a reader never sees half a file.
pub fn write_exr(
    path: &Path,
    frame_size: (u32, u32),
    layers: &Layers,
    meta: &ExrMetadata,
) -> Result<(), OutputError> {
    let bytes = encode_exr(frame_size, layers, meta)?;
    atomic::write(path, &bytes)
}

/// Decodes an EXR image: Tessera's own files, and any single-part EXR with at least
/// `R`, `G`, `B` channels. Absent channels take the values of [`Layers::new`] (black,
/// depth at [`NO_HIT_DEPTH`](crate::film::NO_HIT_DEPTH)), except `A`, which defaults
/// to 1 (opaque). Channels may be `f16`, `f32` or `u32`; a multi-part file is read from
/// its first part.
pub fn decode_exr(bytes: &[u8]) -> Result<ExrImage, OutputError> {
    let meta = MetaData::read_from_buffered(bytes, false).map_err(OutputError::Corrupt)?;
    let header = first_header(&meta)?;
    decode(bytes, header.layer_size.area(), false, &["R", "G", "B"])
}

/// [`decode_exr`] of the file at `path`; errors name the file.
pub fn read_exr(path: &Path) -> Result<ExrImage, OutputError> {
    let bytes = std::fs::read(path).map_err(|source| OutputError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    decode_exr(&bytes).map_err(|e| OutputError::File {
        path: path.to_path_buf(),
        source: Box::new(e),
    })
}

/// Checks a tile uploaded by a worker and returns its pixels: the bytes must be one
/// EXR part whose display window is the `frame_size` frame, whose data window is
/// `expected_rect`, which has every channel of [`CHANNEL_NAMES`], and whose values are
/// all finite. The header is checked before any pixel is decompressed, and reading is
/// strict (OpenEXR's "pedantic" mode).
pub fn validate_tile(
    bytes: &[u8],
    expected_rect: TileRect,
    frame_size: (u32, u32),
) -> Result<Layers, OutputError> {
    let meta = MetaData::read_from_buffered(bytes, true).map_err(OutputError::Corrupt)?;
    if meta.headers.len() != 1 {
        return Err(OutputError::Unsupported(format!(
            "a tile has one part, this file has {}",
            meta.headers.len()
        )));
    }
    let header = first_header(&meta)?;
    let (frame, rect) = windows(
        header.shared_attributes.display_window,
        header.data_window(),
    )?;
    if frame != frame_size {
        return Err(OutputError::WrongFrameSize {
            expected: frame_size,
            found: frame,
        });
    }
    if rect != expected_rect {
        return Err(OutputError::WrongDataWindow {
            expected: expected_rect,
            found: rect,
        });
    }
    for name in CHANNEL_NAMES {
        if !header.channels.list.iter().any(|c| c.name.eq(name)) {
            return Err(OutputError::MissingChannel {
                channel: name.to_string(),
                present: header
                    .channels
                    .list
                    .iter()
                    .map(|c| c.name.to_string())
                    .collect(),
            });
        }
    }

    let image = decode(bytes, expected_rect.area(), true, &CHANNEL_NAMES)?;
    if !image.layers.denoised.is_empty() {
        return Err(OutputError::Unsupported(
            "a tile has no denoised layer: only a whole frame is denoised".to_string(),
        ));
    }
    check_finite(&image.layers)?;
    Ok(image.layers)
}

/// Checks that every value of `layers` is finite (and that each layer holds one value per
/// pixel); the error names the first channel and pixel, in frame coordinates, that is not.
pub fn check_finite(layers: &Layers) -> Result<(), OutputError> {
    check_lengths(layers)?;
    let rect = layers.rect;
    let w = rect.width.max(1) as usize;
    for i in 0..rect.area() {
        for (channel, slot) in all_channels() {
            if slot.layer() == ImageLayer::Denoised && layers.denoised.is_empty() {
                continue;
            }
            let value = slot.get(layers, i);
            if !value.is_finite() {
                return Err(OutputError::NonFinite {
                    channel,
                    x: rect.x + (i % w) as u32,
                    y: rect.y + (i / w) as u32,
                    value,
                });
            }
        }
    }
    Ok(())
}

/// The header of the first part, refusing deep data.
pub(super) fn first_header(meta: &MetaData) -> Result<&Header, OutputError> {
    let header = meta
        .headers
        .first()
        .ok_or_else(|| OutputError::Unsupported("the file has no part".to_string()))?;
    if header.deep {
        return Err(OutputError::Unsupported("deep data".to_string()));
    }
    Ok(header)
}

/// The frame size and the data window relative to the display window's corner, refusing
/// a data window that is empty or reaches outside the display window.
pub(super) fn windows(
    display: IntegerBounds,
    data: IntegerBounds,
) -> Result<((u32, u32), TileRect), OutputError> {
    let size = |v: usize| u32::try_from(v).ok();
    let frame = match (size(display.size.0), size(display.size.1)) {
        (Some(w), Some(h)) if w > 0 && h > 0 => (w, h),
        _ => {
            return Err(OutputError::BadWindow(format!(
                "display window {}x{} is empty or too large",
                display.size.0, display.size.1
            )))
        }
    };
    let dx = i64::from(data.position.0) - i64::from(display.position.0);
    let dy = i64::from(data.position.1) - i64::from(display.position.1);
    let rect = match (
        u32::try_from(dx).ok(),
        u32::try_from(dy).ok(),
        size(data.size.0),
        size(data.size.1),
    ) {
        (Some(x), Some(y), Some(w), Some(h)) if w > 0 && h > 0 => TileRect::new(x, y, w, h),
        _ => {
            return Err(OutputError::BadWindow(format!(
                "data window {}x{} at ({dx}, {dy}) is empty or starts outside the display window",
                data.size.0, data.size.1
            )))
        }
    };
    if !rect.fits_in(frame.0, frame.1) {
        return Err(OutputError::BadWindow(format!(
            "data window {} reaches outside the {}x{} display window",
            rect_text(rect),
            frame.0,
            frame.1
        )));
    }
    Ok((frame, rect))
}

/// Decodes the first flat part of `bytes` into layers, requiring the channels named in
/// `required`. `pixels` (from the header) decides whether to decompress on several threads.
fn decode(
    bytes: &[u8],
    pixels: usize,
    pedantic: bool,
    required: &[&str],
) -> Result<ExrImage, OutputError> {
    let read = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes();
    let read = if pedantic { read.pedantic() } else { read };
    let read = if pixels >= PARALLEL_MIN_PIXELS {
        read
    } else {
        read.non_parallel()
    };
    let image = read
        .from_buffered(Cursor::new(bytes))
        .map_err(OutputError::Corrupt)?;

    let layer = &image.layer_data;
    let data = IntegerBounds::new(layer.attributes.layer_position, layer.size);
    let (frame_size, rect) = windows(image.attributes.display_window, data)?;

    let channels = &layer.channel_data.list;
    let find = |name: &str| channels.iter().find(|c| c.name.eq(name));
    for &name in required {
        if find(name).is_none() {
            return Err(OutputError::MissingChannel {
                channel: name.to_string(),
                present: channels.iter().map(|c| c.name.to_string()).collect(),
            });
        }
    }

    let mut layers = Layers::new(rect);
    if find("A").is_none() {
        layers.beauty.iter_mut().for_each(|b| b.w = 1.0);
    }
    for (name, slot) in all_channels() {
        let Some(channel) = find(name) else { continue };
        if channel.sample_data.len() != rect.area() {
            return Err(OutputError::Unsupported(format!(
                "channel `{name}` holds {} samples for {} pixels (subsampled)",
                channel.sample_data.len(),
                rect.area()
            )));
        }
        for (i, v) in channel.sample_data.values_as_f32().enumerate() {
            slot.set(&mut layers, i, v);
        }
    }

    Ok(ExrImage {
        frame_size,
        layers,
        attributes: string_attributes(&image.attributes, &layer.attributes),
    })
}
