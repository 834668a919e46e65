//! Decoding image files into a grey frame of u16 pixels (8-bit images keep values 0–255).

use anyhow::{Context, Result, bail};
use image::{DynamicImage, ImageReader, Limits};
use std::path::Path;

/// A decoded grey frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// Row-major pixels.
    pub pixels: Vec<u16>,
    /// The largest value the file's format can hold (255 or 65535): pixels there are saturated.
    pub saturation: u16,
}

/// File extensions `batch` treats as images (lower case).
pub const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "tif", "tiff"];

/// Is this path an image by its extension?
pub fn is_image_path(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        .unwrap_or(false)
}

/// Largest frame accepted, in pixels per side, and its decoder memory budget: a header that
/// claims more is refused before anything is allocated.
const MAX_SIDE: u32 = 32768;
const MAX_ALLOC: u64 = 2 << 30;

impl Frame {
    /// Decode an image file. Colour images become luma; alpha is ignored.
    pub fn read(path: &Path) -> Result<Frame> {
        let mut reader = ImageReader::open(path)
            .with_context(|| format!("cannot open {}", path.display()))?
            .with_guessed_format()
            .with_context(|| format!("cannot read {}", path.display()))?;
        let mut limits = Limits::default();
        limits.max_image_width = Some(MAX_SIDE);
        limits.max_image_height = Some(MAX_SIDE);
        limits.max_alloc = Some(MAX_ALLOC);
        reader.limits(limits);
        let img = reader
            .decode()
            .with_context(|| format!("cannot decode {}", path.display()))?;
        Frame::from_image(img)
    }

    /// Convert a decoded image (grey or colour, 8 or 16 bits) into a frame.
    pub fn from_image(img: DynamicImage) -> Result<Frame> {
        let (width, height) = (img.width(), img.height());
        if width == 0 || height == 0 {
            bail!("the image is empty ({width}x{height})");
        }
        let (pixels, saturation) = match img {
            DynamicImage::ImageLuma8(b) => (b.pixels().map(|p| p.0[0] as u16).collect(), 255),
            DynamicImage::ImageLumaA8(b) => (b.pixels().map(|p| p.0[0] as u16).collect(), 255),
            DynamicImage::ImageLuma16(b) => (b.into_raw(), u16::MAX),
            DynamicImage::ImageLumaA16(b) => (b.pixels().map(|p| p.0[0]).collect(), u16::MAX),
            DynamicImage::ImageRgb8(_) | DynamicImage::ImageRgba8(_) => (
                img.to_luma8().pixels().map(|p| p.0[0] as u16).collect(),
                255,
            ),
            other => (other.to_luma16().into_raw(), u16::MAX),
        };
        Ok(Frame {
            width,
            height,
            pixels,
            saturation,
        })
    }
}
