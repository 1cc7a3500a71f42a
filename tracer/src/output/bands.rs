//! Frames larger than memory. [`write_frame_in_bands`] writes a frame's EXR and its PNG
//! preview band by band: full-width runs of rows that the caller makes one at a time, so
//! that a 16384² frame (14 GB of layers) is never held whole. [`read_exr_rows`] reads
//! some rows of an EXR and decompresses only the blocks that hold them.

use std::fs::File;
use std::io::{BufReader, Write};
use std::ops::Range;
use std::path::Path;

use ::exr::block::UncompressedBlock;
use ::exr::meta::attribute::SampleType;
use rayon::prelude::*;
use smallvec::smallvec;

use super::atomic::AtomicFile;
use super::attributes::string_attributes;
use super::exr::{first_header, header, slot_named, windows, write_blocks};
use super::preview::{png_writer, preview_rgba8};
use super::{check_frame_size, check_lengths, rect_text, ExrCompression, ExrImage};
use super::{ExrMetadata, ImageLayer, OutputError};
use crate::film::{Layers, TileRect};

/// Rows of one OpenEXR ZIP block: bands are a whole number of them, so that no block
/// spans two bands.
pub const BLOCK_ROWS: u32 = 16;

/// The EXR that [`write_frame_in_bands`] writes.
#[derive(Clone, Copy, Debug)]
pub struct ExrTarget<'a> {
    /// Where it goes (atomically).
    pub path: &'a Path,
    /// Its string attributes.
    pub meta: &'a ExrMetadata,
    /// The layers written (beauty always).
    pub layers: &'a [ImageLayer],
    /// How its scan lines are stored.
    pub compression: ExrCompression,
}

/// The PNG preview that [`write_frame_in_bands`] writes.
#[derive(Clone, Copy, Debug)]
pub struct PreviewTarget<'a> {
    /// Where it goes (atomically).
    pub path: &'a Path,
    /// Exposure in stops.
    pub exposure: f32,
}

/// The full-width bands of `band_rows` rows (rounded up to whole [`BLOCK_ROWS`]) that
/// cover a `frame_size` frame, top to bottom; the last one may be shorter.
pub fn frame_bands(frame_size: (u32, u32), band_rows: u32) -> impl Iterator<Item = TileRect> {
    let (w, h) = frame_size;
    let rows = band_rows.max(1).div_ceil(BLOCK_ROWS) * BLOCK_ROWS;
    (0..h)
        .step_by(rows as usize)
        .map(move |y| TileRect::new(0, y, w, rows.min(h - y)))
}

/// Writes a `frame_size` frame as an EXR, a PNG preview, or both, in one pass over its
/// [`frame_bands`]: `band` is asked for each band's layers in turn, top to bottom, and
/// only one band is held at a time. Each file appears whole or not at all (the EXR is
/// renamed into place before the PNG). An error from `band` stops the writing and is
/// returned as it is; nothing is left behind.
pub fn write_frame_in_bands<E: From<OutputError>>(
    frame_size: (u32, u32),
    band_rows: u32,
    exr: Option<ExrTarget>,
    preview: Option<PreviewTarget>,
    mut band: impl FnMut(TileRect) -> Result<Layers, E>,
) -> Result<(), E> {
    check_frame_size(frame_size)?;
    let Some(preview) = preview else {
        return write_exr_in_bands(frame_size, band_rows, exr, band);
    };
    let io = |source| OutputError::Io {
        path: preview.path.to_path_buf(),
        source,
    };
    let png_error = |e| match e {
        png::EncodingError::IoError(source) => io(source),
        e => OutputError::Png(e),
    };
    let mut file = AtomicFile::create(preview.path)?;
    {
        let mut writer = png_writer(&mut file, frame_size)?;
        {
            let mut rows = writer.stream_writer().map_err(OutputError::Png)?;
            write_exr_in_bands(frame_size, band_rows, exr, |rect| -> Result<Layers, E> {
                let layers = band(rect)?;
                if layers.rect == rect {
                    rows.write_all(&preview_rgba8(&layers, preview.exposure))
                        .map_err(io)?;
                }
                Ok(layers)
            })?;
            rows.finish().map_err(png_error)?;
        }
        writer.finish().map_err(png_error)?;
    }
    file.commit()?;
    Ok(())
}

/// [`write_frame_in_bands`] without a preview: the EXR if there is one, else only the
/// calls to `band`.
fn write_exr_in_bands<E: From<OutputError>>(
    frame_size: (u32, u32),
    band_rows: u32,
    exr: Option<ExrTarget>,
    mut band: impl FnMut(TileRect) -> Result<Layers, E>,
) -> Result<(), E> {
    let bands = frame_bands(frame_size, band_rows);
    // Each band as the caller made it, checked.
    let mut next = |rect: TileRect| -> Result<Layers, E> {
        let layers = band(rect)?;
        if layers.rect != rect {
            return Err(OutputError::BadWindow(format!(
                "band {} was asked for, {} was given",
                rect_text(rect),
                rect_text(layers.rect)
            ))
            .into());
        }
        check_lengths(&layers)?;
        if layers.denoised.is_empty()
            && exr.is_some_and(|t| t.layers.contains(&ImageLayer::Denoised))
        {
            return Err(OutputError::Unsupported(format!(
                "band {} has no denoised layer for the frame's `denoised` channels",
                rect_text(rect)
            ))
            .into());
        }
        Ok(layers)
    };
    let Some(target) = exr else {
        for rect in bands {
            next(rect)?;
        }
        return Ok(());
    };
    let full = TileRect::new(0, 0, frame_size.0, frame_size.1);
    let header = header(
        frame_size,
        full,
        target.meta,
        target.layers,
        target.compression,
    )?;
    let mut file = AtomicFile::create(target.path)?;
    let mut failure = None;
    let written = ::exr::block::write(&mut file, smallvec![header], true, |meta, chunks| {
        for rect in bands {
            match next(rect) {
                Ok(layers) => write_blocks(&meta, chunks, &layers)?,
                Err(e) => {
                    failure = Some(e);
                    return Err(::exr::error::Error::Aborted);
                }
            }
        }
        Ok(())
    });
    if let Some(e) = failure {
        return Err(e);
    }
    written.map_err(|e| match e {
        ::exr::error::Error::Io(source) => file.error(source),
        e => OutputError::Encode(e),
    })?;
    file.commit()?;
    Ok(())
}

/// The rows `rows` (frame coordinates) of the EXR at `path`, with its attributes: the
/// layers cover the data window's part of those rows (an empty rectangle where they miss
/// it), and only the scan-line blocks that hold them are read and decompressed. For
/// Tessera's own files (tiles, frames): scan lines, every channel `f32`; absent channels
/// read as [`Layers::new`] leaves them, `A` as 1.
pub fn read_exr_rows(path: &Path, rows: Range<u32>) -> Result<ExrImage, OutputError> {
    let in_file = |e: OutputError| OutputError::File {
        path: path.to_path_buf(),
        source: Box::new(e),
    };
    let file = File::open(path).map_err(|source| OutputError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let reader = ::exr::block::read(BufReader::new(file), false)
        .map_err(|e| in_file(OutputError::Corrupt(e)))?;
    let meta = reader.meta_data().clone();
    let header = first_header(&meta).map_err(in_file)?;
    let (frame_size, window) = windows(
        header.shared_attributes.display_window,
        header.data_window(),
    )
    .map_err(in_file)?;
    if let Some(c) = header
        .channels
        .list
        .iter()
        .find(|c| c.sample_type != SampleType::F32)
    {
        return Err(in_file(OutputError::Unsupported(format!(
            "channel `{}` is not f32: rows are read from Tessera's own files only",
            c.name
        ))));
    }
    let top = rows.start.clamp(window.y, window.y + window.height);
    let bottom = rows.end.clamp(top, window.y + window.height);
    let sub = TileRect::new(window.x, top, window.width, bottom - top);
    let mut layers = Layers::new(sub);
    if !header.channels.list.iter().any(|c| c.name.eq("A")) {
        layers.beauty.iter_mut().for_each(|b| b.w = 1.0);
    }

    // Block rows are relative to the data window.
    let (first, last) = ((top - window.y) as usize, (bottom - window.y) as usize);
    let chunks: Vec<_> = reader
        .filter_chunks(false, |_, _, block| {
            let y = block.pixel_position.1;
            y < last && y + block.pixel_size.1 > first
        })
        .map_err(|e| in_file(OutputError::Corrupt(e)))?
        .collect::<Result<_, _>>()
        .map_err(|e| in_file(OutputError::Corrupt(e)))?;
    let blocks: Vec<UncompressedBlock> = chunks
        .into_par_iter()
        .map(|chunk| UncompressedBlock::decompress_chunk(chunk, &meta, false))
        .collect::<Result<_, _>>()
        .map_err(|e| in_file(OutputError::Corrupt(e)))?;

    let slots: Vec<_> = header
        .channels
        .list
        .iter()
        .map(|c| slot_named(&c.name.to_string()))
        .collect();
    let width = window.width as usize;
    for block in &blocks {
        for line in block.lines(&header.channels) {
            let y = line.location.position.1;
            if y < first || y >= last || line.location.sample_count != width {
                continue;
            }
            let (Some(slot), start) = (slots[line.location.channel], (y - first) * width) else {
                continue;
            };
            for (i, v) in line.read_samples::<f32>().enumerate() {
                slot.set(
                    &mut layers,
                    start + i,
                    v.map_err(|e| in_file(OutputError::Corrupt(e)))?,
                );
            }
        }
    }
    Ok(ExrImage {
        frame_size,
        layers,
        attributes: string_attributes(&header.shared_attributes, &header.own_attributes),
    })
}
