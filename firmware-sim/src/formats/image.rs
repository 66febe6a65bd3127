//! Gray images in and out: PNG, TIFF, BMP, 8- and 16-bit (the `image` crate).

use std::path::Path;

use image::{DynamicImage, ImageBuffer, Luma};

use super::FormatError;

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

/// Reads any gray or color image as gray; 16-bit sources stay 16-bit.
pub fn read_gray(path: &Path) -> Result<Gray, FormatError> {
    let img = image::open(path).map_err(img_err(path))?;
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
