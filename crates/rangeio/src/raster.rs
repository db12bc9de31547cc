//! PNG and TIFF gray images decoded through the `image` crate, with size limits.

use crate::{Format, MAX_SIDE, ReadError};
use image::{DynamicImage, ImageFormat, ImageReader, Limits};
use rangeimage::Grid;
use std::io::Cursor;
use std::path::Path;

/// Decoder limits: sides up to [`MAX_SIDE`], at most 1 GiB of decoder allocations.
pub(crate) fn limits() -> Limits {
    let mut l = Limits::default();
    l.max_image_width = Some(MAX_SIDE);
    l.max_image_height = Some(MAX_SIDE);
    l.max_alloc = Some(1 << 30);
    l
}

/// Decodes a PNG or TIFF, after checking the header's size against [`MAX_SIDE`] and `max_pixels`.
pub(crate) fn decode_image(
    bytes: &[u8],
    path: &Path,
    format: ImageFormat,
    max_pixels: u64,
) -> Result<DynamicImage, ReadError> {
    let image_err = |error| ReadError::Image { path: path.to_path_buf(), error };
    let mut header = ImageReader::with_format(Cursor::new(bytes), format);
    header.limits(limits());
    let (w, h) = header.into_dimensions().map_err(image_err)?;
    crate::check_dims(path, w.into(), h.into(), max_pixels)?;
    let mut reader = ImageReader::with_format(Cursor::new(bytes), format);
    reader.limits(limits());
    let img = reader.decode().map_err(image_err)?;
    if img.width() == 0 || img.height() == 0 {
        return Err(ReadError::Dimensions {
            path: path.to_path_buf(),
            width: img.width().into(),
            height: img.height().into(),
        });
    }
    Ok(img)
}

/// Decodes a gray PNG or TIFF depth image into `(samples, bits per sample)`.
pub(crate) fn decode_gray(
    bytes: &[u8],
    path: &Path,
    format: Format,
    max_pixels: u64,
) -> Result<(Grid<u16>, u8), ReadError> {
    let image_format = if format == Format::Png { ImageFormat::Png } else { ImageFormat::Tiff };
    let img = decode_image(bytes, path, image_format, max_pixels)?;
    let (w, h) = (img.width(), img.height());
    let (data, bits): (Vec<u16>, u8) = match img {
        DynamicImage::ImageLuma8(b) => (b.into_raw().into_iter().map(u16::from).collect(), 8),
        DynamicImage::ImageLuma16(b) => (b.into_raw(), 16),
        other => {
            return Err(ReadError::Unsupported {
                path: path.to_path_buf(),
                what: format!(
                    "{format} pixel type {:?} (depth images must be 8 or 16-bit gray)",
                    other.color()
                ),
            });
        }
    };
    Ok((Grid::from_vec(w, h, data).expect("decoder returns w·h samples"), bits))
}
