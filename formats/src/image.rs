//! Gray images in and out: PNG, TIFF, BMP, 8- and 16-bit (the `image` crate).

use std::path::Path;

use image::{DynamicImage, ImageBuffer, Luma};

use crate::{FormatError, MAX_FRAME_PIXELS};

/// A gray image, upright, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Gray {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Levels, `0..=max`.
    pub data: Vec<u16>,
    /// 8 or 16.
    pub bits: u8,
}

fn img_err(path: &Path) -> impl FnOnce(image::ImageError) -> FormatError + '_ {
    move |e| FormatError::Image {
        path: path.to_path_buf(),
        msg: e.to_string(),
    }
}

/// Writes 8-bit gray (format by extension: png, tif/tiff, bmp).
pub fn write_gray8(path: &Path, width: u32, height: u32, data: &[u8]) -> Result<(), FormatError> {
    let buf: ImageBuffer<Luma<u8>, Vec<u8>> = ImageBuffer::from_raw(width, height, data.to_vec())
        .ok_or_else(|| FormatError::Image {
        path: path.to_path_buf(),
        msg: "size mismatch".into(),
    })?;
    buf.save(path).map_err(img_err(path))
}

/// Writes 16-bit gray (PNG or TIFF; BMP has no 16-bit gray and is refused).
pub fn write_gray16(path: &Path, width: u32, height: u32, data: &[u16]) -> Result<(), FormatError> {
    let buf: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::from_raw(width, height, data.to_vec())
        .ok_or_else(|| FormatError::Image {
            path: path.to_path_buf(),
            msg: "size mismatch".into(),
        })?;
    buf.save(path).map_err(img_err(path))
}

/// Writes gray levels of a frame whose full scale is `full_scale`: 8-bit
/// when it is at most 255 (levels above 255 saturate), else 16-bit as they
/// are (PNG or TIFF; BMP has no 16-bit gray).
pub fn write_levels(
    path: &Path,
    width: u32,
    height: u32,
    levels: &[u16],
    full_scale: u16,
) -> Result<(), FormatError> {
    if full_scale <= 255 {
        let v: Vec<u8> = levels.iter().map(|&g| g.min(255) as u8).collect();
        write_gray8(path, width, height, &v)
    } else {
        write_gray16(path, width, height, levels)
    }
}

/// Reads any gray or color image as gray; 16-bit sources stay 16-bit. The
/// format is told by the content (the extension only where the content
/// does not tell), and the size is checked against [`MAX_FRAME_PIXELS`]
/// from the header, before the pixels are decoded.
pub fn read_gray(path: &Path) -> Result<Gray, FormatError> {
    let reader = image::ImageReader::open(path).map_err(|e| FormatError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    decode_gray(reader, path, MAX_FRAME_PIXELS)
}

/// [`read_gray`] over image bytes in memory; `name` names them in errors.
pub fn read_gray_bytes(bytes: &[u8], name: &Path) -> Result<Gray, FormatError> {
    read_gray_bytes_within(bytes, name, MAX_FRAME_PIXELS)
}

/// [`read_gray_bytes`] with a pixel limit of the caller's, at most
/// [`MAX_FRAME_PIXELS`] (the fuzz target uses a smaller one, so that
/// inputs declaring huge images cost it less time, through the same code).
pub fn read_gray_bytes_within(
    bytes: &[u8],
    name: &Path,
    max_pixels: u64,
) -> Result<Gray, FormatError> {
    decode_gray(
        image::ImageReader::new(std::io::Cursor::new(bytes)),
        name,
        max_pixels.min(MAX_FRAME_PIXELS),
    )
}

fn decode_gray<R: std::io::BufRead + std::io::Seek>(
    mut reader: image::ImageReader<R>,
    path: &Path,
    max_pixels: u64,
) -> Result<Gray, FormatError> {
    use image::ImageDecoder;
    // The decoders' own allocation cap: the largest frame at 8 bytes a
    // pixel (RGBA16), so no image within the pixel limit is refused by it.
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(max_pixels * 8);
    reader.limits(limits);
    let reader = reader.with_guessed_format().map_err(|e| FormatError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let decoder = reader.into_decoder().map_err(img_err(path))?;
    let (width, height) = decoder.dimensions();
    let px = u64::from(width) * u64::from(height);
    if px > max_pixels {
        return Err(FormatError::TooLarge {
            what: format!("{}: a {width}x{height} image", path.display()),
            got: px,
            limit: max_pixels,
        });
    }
    let img = DynamicImage::from_decoder(decoder).map_err(img_err(path))?;
    let (width, height) = (img.width(), img.height());
    let sixteen = matches!(
        img,
        DynamicImage::ImageLuma16(_)
            | DynamicImage::ImageLumaA16(_)
            | DynamicImage::ImageRgb16(_)
            | DynamicImage::ImageRgba16(_)
    );
    if sixteen {
        Ok(Gray {
            width,
            height,
            data: img.into_luma16().into_raw(),
            bits: 16,
        })
    } else {
        Ok(Gray {
            width,
            height,
            data: img
                .into_luma8()
                .into_raw()
                .into_iter()
                .map(u16::from)
                .collect(),
            bits: 8,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A valid 8 × 8 PNG whose header is then made to claim `w × h` (CRC
    /// fixed, so only the size is wrong).
    fn png_claiming(w: u32, h: u32) -> Vec<u8> {
        let mut bytes = Vec::new();
        image::GrayImage::new(8, 8)
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .unwrap();
        // Signature (8), IHDR length (4), "IHDR" (4), width, height, …, CRC.
        bytes[16..20].copy_from_slice(&w.to_be_bytes());
        bytes[20..24].copy_from_slice(&h.to_be_bytes());
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&bytes[12..29]);
        bytes[29..33].copy_from_slice(&crc.to_be_bytes());
        bytes
    }

    #[test]
    fn an_image_header_over_the_limit_is_refused_before_decoding() {
        let name = Path::new("big.png");
        let ok = read_gray_bytes(&png_claiming(8, 8), name).unwrap();
        assert_eq!((ok.width, ok.height, ok.bits), (8, 8, 8));
        for (w, h) in [(65535, 65535), (8193, 8192), (1 << 30, 1)] {
            let e = read_gray_bytes(&png_claiming(w, h), name).unwrap_err();
            assert!(
                matches!(e, FormatError::TooLarge { .. } | FormatError::Image { .. }),
                "{w}x{h}: {e}"
            );
        }
        let e = read_gray_bytes(&png_claiming(65535, 65535), name).unwrap_err();
        assert!(matches!(e, FormatError::TooLarge { .. }), "{e}");
        // Bytes of no image format, and a truncated PNG.
        assert!(read_gray_bytes(b"not an image at all", name).is_err());
        assert!(read_gray_bytes(&png_claiming(8, 8)[..40], name).is_err());
    }
}
