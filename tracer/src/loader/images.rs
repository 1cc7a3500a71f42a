//! Image decoding: PNG, JPEG and WebP (EXT_texture_webp) bytes into RGBA8 texels, whatever their channel layout
//! (grey, grey-alpha, RGB, RGBA) or depth (8 or 16 bits). The transfer function is left
//! alone: base colour stays sRGB-encoded and is decoded when sampled
//! ([`crate::texture::Texture::sample`]), data textures stay linear.

use std::io::Cursor;

use image::{ImageFormat, ImageReader};

/// A decoded image: width, height and row-major RGBA texels, top row first.
pub(crate) struct Decoded {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<[u8; 4]>,
}

/// Decodes `bytes`; `mime` is the type the document declares, used only when the bytes
/// themselves do not say.
pub(crate) fn decode(bytes: &[u8], mime: Option<&str>) -> Result<Decoded, String> {
    let sniffed = image::guess_format(bytes).ok();
    let format = sniffed.or_else(|| mime.and_then(ImageFormat::from_mime_type));
    let format = match format {
        Some(f @ (ImageFormat::Png | ImageFormat::Jpeg | ImageFormat::WebP)) => f,
        Some(f) => {
            return Err(format!(
                "{f:?} images are not supported (only PNG, JPEG and WebP)"
            ))
        }
        None => {
            return Err(format!(
                "unrecognised image data{} (only PNG, JPEG and WebP are supported)",
                mime.map(|m| format!(" declared as '{m}'"))
                    .unwrap_or_default()
            ))
        }
    };
    // The reader's default limits (512 MiB per allocation) guard against images whose
    // header claims absurd dimensions.
    let mut reader = ImageReader::new(Cursor::new(bytes));
    reader.set_format(format);
    let img = reader
        .decode()
        .map_err(|e| format!("cannot decode {format:?}: {e}"))?;
    let rgba = img.into_rgba8();
    let (width, height) = rgba.dimensions();
    if width == 0 || height == 0 {
        return Err(format!("image is empty ({width}x{height})"));
    }
    let texels = rgba
        .into_raw()
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    Ok(Decoded {
        width,
        height,
        texels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png(img: image::DynamicImage) -> Vec<u8> {
        let mut out = Cursor::new(Vec::new());
        img.write_to(&mut out, ImageFormat::Png).unwrap();
        out.into_inner()
    }

    #[test]
    fn grey_grey_alpha_and_16_bit_become_rgba8() {
        let grey = png(image::DynamicImage::ImageLuma8(
            image::GrayImage::from_pixel(2, 1, image::Luma([77])),
        ));
        let d = decode(&grey, None).unwrap();
        assert_eq!((d.width, d.height), (2, 1));
        assert_eq!(d.texels[1], [77, 77, 77, 255]);

        let la = png(image::DynamicImage::ImageLumaA8(
            image::GrayAlphaImage::from_pixel(1, 1, image::LumaA([10, 20])),
        ));
        assert_eq!(
            decode(&la, Some("image/png")).unwrap().texels[0],
            [10, 10, 10, 20]
        );

        let rgb16 = png(image::DynamicImage::ImageRgb16(
            image::ImageBuffer::from_pixel(1, 1, image::Rgb([65535u16, 0, 32896])),
        ));
        assert_eq!(decode(&rgb16, None).unwrap().texels[0], [255, 0, 128, 255]);
    }

    #[test]
    fn garbage_is_refused_with_a_reason() {
        let e = decode(b"not an image", Some("image/ktx2")).err().unwrap();
        assert!(
            e.contains("not supported") || e.contains("unrecognised"),
            "{e}"
        );
        // Declared WebP, but not: the decoder's own reason.
        let e = decode(b"not an image", Some("image/webp")).err().unwrap();
        assert!(e.starts_with("cannot decode WebP"), "{e}");
        let mut bad = png(image::DynamicImage::new_rgb8(4, 4));
        bad.truncate(30);
        assert!(decode(&bad, None).is_err());
    }
}
