//! Decoding image files into a grey frame of u16 pixels (8-bit images keep values 0–255).

use crate::error::{Context, Error, Result, error, fail};
use crate::io::fits::FitsFrame;
use image::{DynamicImage, ImageDecoder, ImageError, ImageFormat, ImageReader, Limits};
use std::borrow::Cow;
use std::io::{BufRead, Cursor, Seek};
use std::path::Path;

/// A decoded grey frame. Its pixels are its own when decoded from a file, or borrowed from the
/// caller's buffer when that holds them as they are ([`Frame::from_samples`] of u16 values):
/// a frame solved where it lies is not copied.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame<'a> {
    pub width: u32,
    pub height: u32,
    /// Row-major pixels.
    pub pixels: Cow<'a, [u16]>,
    /// The largest value the file's format can hold (255 or 65535): pixels there are saturated.
    pub saturation: u16,
}

/// What a file says about itself beside its pixels.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FileInfo {
    /// The observation epoch (Julian year), from FITS DATE-OBS or MJD-OBS.
    pub epoch: Option<f64>,
    /// FITS header keywords and their values as text (empty for other formats).
    pub keywords: std::collections::BTreeMap<String, String>,
    /// What a person should know about how the file was read (its record carries them).
    pub warnings: Vec<String>,
}

/// File extensions `batch` treats as images (lower case).
pub const IMAGE_EXTENSIONS: &[&str] = &[
    "png", "jpg", "jpeg", "tif", "tiff", "fits", "fit", "fts", "fz",
];

/// Is this path an image by its extension? Gzipped FITS (`x.fits.gz`, `.fit.gz`, `.fts.gz`)
/// is one too.
pub fn is_image_path(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        .unwrap_or(false)
        || is_gzipped_fits_name(path)
}

/// `x.fits.gz` and the like.
fn is_gzipped_fits_name(path: &Path) -> bool {
    let ext = |p: &Path| {
        p.extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
    };
    ext(path).as_deref() == Some("gz")
        && path
            .file_stem()
            .and_then(|stem| ext(Path::new(stem)))
            .is_some_and(|e| crate::io::fits::is_fits_extension(&e))
}

/// Largest frame accepted, in pixels per side, and its decoder memory budget: a header that
/// claims more is refused before anything is allocated.
pub(crate) const MAX_SIDE: u32 = 32768;
const MAX_ALLOC: u64 = 2 << 30;

impl Frame<'_> {
    /// The same frame owning its pixels (copied when they are borrowed).
    pub fn into_owned(self) -> Frame<'static> {
        Frame {
            pixels: Cow::Owned(self.pixels.into_owned()),
            ..self
        }
    }
}

impl Frame<'static> {
    /// Decode an image file. Colour images become luma; alpha is ignored.
    ///
    /// Every failure is an error that names the file and the problem: a link that leads
    /// nowhere, something that is not a regular file (a FIFO would block the read forever),
    /// an empty or truncated file (JPEG decoders fill in missing data, so a JPEG must reach its
    /// end-of-image marker), an image larger than gpustar reads, or not enough memory.
    pub fn read(path: &Path) -> Result<Frame<'static>> {
        Frame::read_dated(path).map(|(f, _)| f)
    }

    /// Decode an image file, with its observation epoch (Julian year) when the file says
    /// (FITS `DATE-OBS` or `MJD-OBS`). FITS files are recognised by their first card, whatever
    /// their name.
    pub fn read_dated(path: &Path) -> Result<(Frame<'static>, Option<f64>)> {
        Frame::read_info(path).map(|(f, info)| (f, info.epoch))
    }

    /// Decode an image file, with what its header says ([`FileInfo`]).
    pub fn read_info(path: &Path) -> Result<(Frame<'static>, FileInfo)> {
        Frame::read_info_sized(path, None)
    }

    /// [`Frame::read_info`] for frames that must be `expect` (width, height) pixels, a camera
    /// file's size: a PNG, JPEG or TIFF of another size is refused from its header, before its
    /// pixels take memory (a 30000² PNG is 0.9 MB on disk, 1.8 GB decoded).
    pub fn read_info_sized(
        path: &Path,
        expect: Option<(u32, u32)>,
    ) -> Result<(Frame<'static>, FileInfo)> {
        Frame::read_info_within(path, expect, u64::MAX)
    }

    /// [`Frame::read_info_sized`] for frames of at most `max_pixels` pixels (`--max-megapixels`):
    /// a larger one is refused from its header, before its pixels take memory (a 0.9 MB PNG
    /// can hold 30000² pixels, 2.6 GB while decoded).
    pub fn read_info_within(
        path: &Path,
        size: Option<(u32, u32)>,
        max_pixels: u64,
    ) -> Result<(Frame<'static>, FileInfo)> {
        let expect = Expect { size, max_pixels };
        let shown = path.display().to_string();
        // Follows links: a dangling or looping one fails here, with where it leads.
        let meta = std::fs::metadata(path).map_err(|e| match std::fs::read_link(path) {
            Ok(to) => error!(
                Input,
                "cannot open {shown}: symbolic link to {} that cannot be followed: {e}",
                to.display()
            ),
            Err(_) => Error::Io {
                context: format!("cannot open {shown}"),
                error: e,
            },
        })?;
        // A directory listed because it could not be read (io::inputs::list): its frames
        // are unknown.
        if meta.is_dir()
            && let Err(why) = std::fs::read_dir(path)
        {
            fail!(
                Input,
                "cannot read the directory {shown} ({why}): the frames in it have no record; make \
                 it readable and rerun with --resume --retry-errors"
            );
        }
        if !meta.is_file() {
            fail!(
                Input,
                "cannot read {shown}: not a regular file but {}",
                crate::files::file_kind(&meta.file_type())
            );
        }
        if meta.len() == 0 {
            fail!(Input, "cannot decode {shown}: the file is empty (0 bytes)");
        }
        if is_gzipped_fits_name(path) {
            return read_gzipped_fits(path, &shown, max_pixels);
        }
        if is_fits(path)? {
            return read_fits(path, &shown, meta.len(), max_pixels);
        }
        let fits_name = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| crate::io::fits::is_fits_extension(&e.to_ascii_lowercase()));
        // The format from the extension, unless the first bytes say otherwise.
        let reader = ImageReader::open(path)
            .with_context(|| format!("cannot open {shown}"))?
            .with_guessed_format()
            .with_context(|| format!("cannot read {shown}"))?;
        // Named FITS, and not another format by its content either: say what is wrong with it
        // rather than that the extension is unknown to the image decoders.
        if fits_name && reader.format().is_none() {
            fail!(
                Input,
                "cannot decode {shown}: not a FITS file (it does not start with SIMPLE  =)"
            );
        }
        if reader.format() == Some(ImageFormat::Png)
            && let Some(frame) = read_grey_png(path, &shown, meta.len(), expect)?
        {
            return Ok((frame, FileInfo::default()));
        }
        let img = if reader.format() == Some(ImageFormat::Jpeg) {
            // The JPEG decoder reads the whole file anyway.
            let bytes = std::fs::read(path).with_context(|| format!("cannot read {shown}"))?;
            if !jpeg_reaches_end(&bytes) {
                fail!(
                    Input,
                    "cannot decode {shown}: the JPEG data stop before their end-of-image marker \
                     (truncated file?)"
                );
            }
            decode(
                ImageReader::with_format(Cursor::new(bytes), ImageFormat::Jpeg),
                &shown,
                expect,
            )?
        } else {
            decode(reader, &shown, expect)?
        };
        Ok((Frame::from_image(img)?, FileInfo::default()))
    }

    /// Convert a decoded image (grey or colour, 8 or 16 bits) into a frame.
    pub fn from_image(img: DynamicImage) -> Result<Frame<'static>> {
        let (width, height) = (img.width(), img.height());
        if width == 0 || height == 0 {
            fail!(Input, "the image is empty ({width}x{height})");
        }
        // Plain loops over the raw buffers: the compiler vectorises the widening.
        let widen = |v: Vec<u8>| -> Vec<u16> { v.into_iter().map(u16::from).collect() };
        let (pixels, saturation) = match img {
            DynamicImage::ImageLuma8(b) => (widen(b.into_raw()), 255),
            DynamicImage::ImageLuma16(b) => (b.into_raw(), u16::MAX),
            DynamicImage::ImageLumaA8(_)
            | DynamicImage::ImageRgb8(_)
            | DynamicImage::ImageRgba8(_) => (widen(img.to_luma8().into_raw()), 255),
            other => (other.to_luma16().into_raw(), u16::MAX),
        };
        Ok(Frame {
            width,
            height,
            pixels: pixels.into(),
            saturation,
        })
    }
}

/// Is this a FITS file (by its first card), or a gzipped one (by its name)?
pub fn is_fits_file(path: &Path) -> bool {
    is_gzipped_fits_name(path) || is_fits(path).unwrap_or(false)
}

/// Does the file start like FITS (`SIMPLE  =`)?
fn is_fits(path: &Path) -> Result<bool> {
    use std::io::Read;
    let mut head = [0u8; 9];
    let mut f =
        std::fs::File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let n = f
        .read(&mut head)
        .with_context(|| format!("cannot read {}", path.display()))?;
    Ok(n == head.len() && &head == b"SIMPLE  =")
}

/// The usual camera frame through [`crate::io::fits::read_camera_frame`] (its first 64 KiB
/// read for the header); None when the file is of another kind or cannot be read so (the
/// caller reads it whole, and reports what is wrong).
fn read_camera_fits(path: &Path, file_len: u64, max_pixels: u64) -> Option<FitsFrame> {
    use std::io::Read;
    let mut file = std::fs::File::open(path).ok()?;
    let mut head = Vec::with_capacity(HEAD_BYTES);
    file.by_ref()
        .take(HEAD_BYTES as u64)
        .read_to_end(&mut head)
        .ok()?;
    crate::io::fits::read_camera_frame(&head, &mut file, file_len, max_pixels)
}

/// How much of a FITS file is read for its header before its data: a few header blocks.
const HEAD_BYTES: usize = 64 << 10;

/// The most pixels a FITS image may have: `max_pixels`, within what gpustar allocates.
fn fits_max_pixels(max_pixels: u64) -> u64 {
    (MAX_SIDE as u64 * MAX_SIDE as u64)
        .min(MAX_ALLOC / 2)
        .min(max_pixels)
}

/// A decoded FITS image as a frame and what its header says.
fn fits_frame(f: FitsFrame) -> (Frame<'static>, FileInfo) {
    (
        Frame {
            width: f.width,
            height: f.height,
            pixels: f.pixels.into(),
            saturation: f.saturation,
        },
        FileInfo {
            epoch: f.epoch,
            keywords: f.keywords,
            warnings: f.warnings,
        },
    )
}

/// A FITS file's primary image (or first image extension), with its DATE-OBS.
fn read_fits(
    path: &Path,
    shown: &str,
    file_len: u64,
    max_pixels: u64,
) -> Result<(Frame<'static>, FileInfo)> {
    if file_len > MAX_ALLOC {
        fail!(
            Input,
            "cannot decode {shown}: the FITS file is larger than gpustar reads (2 GiB)"
        );
    }
    let max_pixels = fits_max_pixels(max_pixels);
    let f = match read_camera_fits(path, file_len, max_pixels) {
        Some(f) => f,
        None => {
            let bytes = std::fs::read(path).with_context(|| format!("cannot read {shown}"))?;
            crate::io::fits::decode_fits(&bytes, max_pixels)
                .with_context(|| format!("cannot decode {shown}"))?
        }
    };
    Ok(fits_frame(f))
}

/// A gzipped FITS file (`x.fits.gz`), decompressed in memory: its headers first, then no more
/// than the image they declare (within `max_pixels`), so that a small file cannot inflate
/// without bound.
fn read_gzipped_fits(
    path: &Path,
    shown: &str,
    max_pixels: u64,
) -> Result<(Frame<'static>, FileInfo)> {
    use std::io::Read;
    let max_pixels = fits_max_pixels(max_pixels);
    let file = std::fs::File::open(path).with_context(|| format!("cannot open {shown}"))?;
    let mut gz = flate2::read::MultiGzDecoder::new(std::io::BufReader::new(file));
    let inflate_error = |e: std::io::Error| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof || e.to_string().contains("incomplete") {
            error!(
                Input,
                "cannot decode {shown}: the compressed data end early (truncated file?)"
            )
        } else {
            error!(
                Input,
                "cannot decode {shown}: not a readable gzip file ({e}; a FITS file named .gz \
                 must be gzip-compressed)"
            )
        }
    };
    // Headers of up to 13,000 cards (a plate's hold a few hundred); the data follow.
    const GZ_HEAD_BYTES: usize = 1 << 20;
    let mut bytes = Vec::with_capacity(GZ_HEAD_BYTES);
    gz.by_ref()
        .take(GZ_HEAD_BYTES as u64)
        .read_to_end(&mut bytes)
        .map_err(inflate_error)?;
    let end = crate::io::fits::image_end(&bytes, max_pixels)
        .with_context(|| format!("cannot decode {shown}"))?;
    if end > MAX_ALLOC {
        fail!(
            Input,
            "cannot decode {shown}: the FITS data are larger than gpustar reads (2 GiB)"
        );
    }
    let more = end.saturating_sub(bytes.len() as u64);
    bytes.try_reserve_exact(more as usize).map_err(|_| {
        error!(
            Input,
            "cannot decode {shown}: not enough memory for its data"
        )
    })?;
    gz.take(more)
        .read_to_end(&mut bytes)
        .map_err(inflate_error)?;
    let f = crate::io::fits::decode_fits(&bytes, max_pixels)
        .with_context(|| format!("cannot decode {shown}"))?;
    Ok(fits_frame(f))
}

/// Grey PNGs (the usual star-tracker frame) straight through the png crate, a fifth faster
/// than through `image`; None for other PNGs (colour, palette, low bit depths), which take the
/// general path. The same size and memory limits apply.
fn read_grey_png(
    path: &Path,
    shown: &str,
    file_len: u64,
    expect: Expect,
) -> Result<Option<Frame<'static>>> {
    // Read whole (one system call; a fifth faster than through a BufReader) unless huge.
    if file_len > 256 << 20 {
        return Ok(None);
    }
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {shown}"))?;
    let mut decoder = png::Decoder::new(Cursor::new(bytes));
    decoder.set_limits(png::Limits {
        bytes: MAX_ALLOC as usize,
    });
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = match decoder.read_info() {
        Ok(r) => r,
        // Let the general path report it in its words.
        Err(_) => return Ok(None),
    };
    let info = reader.info();
    let (w, h) = (info.width, info.height);
    check_size(shown, w, h, expect)?;
    let grey = info.color_type == png::ColorType::Grayscale;
    let depth = info.bit_depth;
    if !grey
        || !matches!(depth, png::BitDepth::Eight | png::BitDepth::Sixteen)
        || info.interlaced
        || w > MAX_SIDE
        || h > MAX_SIDE
        || w == 0
        || h == 0
    {
        return Ok(None);
    }
    let size = reader.output_buffer_size().ok_or_else(|| {
        error!(
            Input,
            "cannot decode {shown}: the image is {w}x{h}, too large"
        )
    })?;
    let no_memory = || {
        error!(
            Input,
            "cannot decode {shown}: not enough memory for a {w}x{h} image"
        )
    };
    let decode_error = |e| match e {
        png::DecodingError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            error!(
                Input,
                "cannot decode {shown}: the file ends before the image does (truncated file?)"
            )
        }
        e => error!(Input, "cannot decode {shown}: {e}"),
    };
    let (pixels, saturation) = if depth == png::BitDepth::Eight {
        // Each row widened into the pixels as it is unfiltered, while in cache: no frame of
        // bytes to zero, fill and read again.
        let mut px: Vec<u16> = Vec::new();
        px.try_reserve_exact(size).map_err(|_| no_memory())?;
        while let Some(row) = reader.next_row().map_err(decode_error)? {
            px.extend(row.data().iter().map(|&v| u16::from(v)));
        }
        if px.len() != size {
            fail!(
                Input,
                "cannot decode {shown}: the image has fewer rows than its header says"
            );
        }
        (px, 255)
    } else {
        // Decoded into the pixels' own bytes and swapped in place: no second buffer (row by
        // row, the byte pairs' conversion is not vectorised, and 16-bit frames decode slower).
        let mut px: Vec<u16> = Vec::new();
        px.try_reserve_exact(size / 2).map_err(|_| no_memory())?;
        px.resize(size / 2, 0);
        reader
            .next_frame(bytemuck::cast_slice_mut(&mut px))
            .map_err(decode_error)?;
        for v in &mut px {
            *v = u16::from_be(*v);
        }
        (px, u16::MAX)
    };
    Ok(Some(Frame {
        width: w,
        height: h,
        pixels: pixels.into(),
        saturation,
    }))
}

/// The error of a frame of `width`×`height` where the camera file says `expect`.
pub fn wrong_size(width: u32, height: u32, expect: (u32, u32)) -> String {
    format!(
        "image is {width}x{height} but the camera file says {}x{}: pass the camera of this \
         image (--camera FILE), or --fov-deg",
        expect.0, expect.1
    )
}

/// Refuse a header's size that is not `expect` (one beyond the decoders' limits is left to
/// their own refusal, which says more).
fn check_size(shown: &str, w: u32, h: u32, expect: Expect) -> Result<()> {
    match expect.size {
        Some(e) if (w, h) != e && w.max(h) <= MAX_SIDE => fail!(Input, "{}", wrong_size(w, h, e)),
        _ if u64::from(w) * u64::from(h) > expect.max_pixels => fail!(
            Input,
            "cannot decode {shown}: the image is {w}x{h} ({:.0} megapixels), more than \
             --max-megapixels {:.0}: raise \
             it to read such frames (each takes 2 to 3 bytes a pixel while it is decoded)",
            (u64::from(w) * u64::from(h)) as f64 / 1e6,
            expect.max_pixels as f64 / 1e6
        ),
        _ => Ok(()),
    }
}

/// What a frame's header must say before its pixels are decoded: its size (a camera file's),
/// and at most how many pixels it has.
#[derive(Clone, Copy, Debug)]
struct Expect {
    size: Option<(u32, u32)>,
    max_pixels: u64,
}

/// Decode with limits: the header is read first, and an image larger than gpustar reads, or
/// one whose pixels do not fit in memory, is refused before its buffer is allocated.
fn decode<R: BufRead + Seek>(
    reader: ImageReader<R>,
    shown: &str,
    expect: Expect,
) -> Result<DynamicImage> {
    // The decoders are other crates' code: one that panics on a malformed file (tiff 0.10.3
    // indexes an empty SampleFormat tag, found by the fuzz suite) costs this file, with a
    // decoding error, not an internal one.
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        decode_checked(reader, shown, expect)
    }))
    .unwrap_or_else(|_| {
        Err(error!(
            Input,
            "cannot decode {shown}: the image decoder failed on a malformed file"
        ))
    })
}

fn decode_checked<R: BufRead + Seek>(
    mut reader: ImageReader<R>,
    shown: &str,
    expect: Expect,
) -> Result<DynamicImage> {
    // No side limit here: the header is read, so the refusal below can give the size.
    let mut limits = Limits::default();
    limits.max_alloc = Some(MAX_ALLOC);
    reader.limits(limits);
    let mut decoder = reader.into_decoder().map_err(|e| decode_error(shown, e))?;
    let (w, h) = decoder.dimensions();
    let bytes = decoder.total_bytes();
    if w > MAX_SIDE || h > MAX_SIDE || bytes > MAX_ALLOC {
        fail!(
            Input,
            "cannot decode {shown}: the image is {w}x{h} ({} MiB of pixels), larger than gpustar \
             reads (at most {MAX_SIDE} pixels a side and {} MiB)",
            bytes >> 20,
            MAX_ALLOC >> 20
        );
    }
    check_size(shown, w, h, expect)?;
    // The decoder allocates its buffer with no way to fail but aborting the process: ask
    // first whether the memory is there, with room for the frame of u16 pixels, so that a
    // shortage is this file's error and the run goes on.
    let need = bytes.saturating_add(2 * u64::from(w) * u64::from(h));
    let available = usize::try_from(need)
        .ok()
        .is_some_and(|n| Vec::<u8>::new().try_reserve_exact(n).is_ok());
    if !available {
        fail!(
            Input,
            "cannot decode {shown}: not enough memory for a {w}x{h} image ({} MiB)",
            need >> 20
        );
    }
    // As `ImageReader::decode` does: the pixels come out of the budget of the decoder's own
    // buffers.
    let mut limits = Limits::default();
    limits.max_alloc = Some(MAX_ALLOC);
    limits
        .reserve(bytes)
        .and_then(|()| decoder.set_limits(limits))
        .map_err(|e| decode_error(shown, e))?;
    DynamicImage::from_decoder(decoder).map_err(|e| decode_error(shown, e))
}

/// The message of a decoder error: said once (the image crate's messages repeat their
/// source), with a hint for a file that ends early.
fn decode_error(shown: &str, e: ImageError) -> crate::error::Error {
    match &e {
        ImageError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            error!(
                Input,
                "cannot decode {shown}: the file ends before the image does (truncated file?)"
            )
        }
        ImageError::Limits(_) => error!(
            Input,
            "cannot decode {shown}: {e} (gpustar reads at most {MAX_SIDE} pixels a side and \
             {} MiB)",
            MAX_ALLOC >> 20
        ),
        _ => error!(Input, "cannot decode {shown}: {e}"),
    }
}

/// Does this JPEG stream reach its end-of-image marker (FF D9)? Marker segments are skipped
/// up to the first scan, so the EOI of a thumbnail inside EXIF does not count; after that,
/// FF D9 can only be the EOI, since entropy-coded data escape each FF byte (FF 00) and restart
/// markers are FF D0–D7. Anything unexpected in the headers is left to the decoder to judge.
fn jpeg_reaches_end(b: &[u8]) -> bool {
    let mut i = 2; // after SOI
    while i + 4 <= b.len() {
        if b[i] != 0xFF {
            return true;
        }
        match b[i + 1] {
            0xFF => i += 1,               // fill byte
            0xD9 => return true,          // EOI before any scan: the decoder judges
            0x01 | 0xD0..=0xD7 => i += 2, // markers without a length
            marker => {
                let next = i + 2 + u16::from_be_bytes([b[i + 2], b[i + 3]]) as usize;
                if marker == 0xDA {
                    // Searched from the end, where a whole file has its EOI.
                    return b
                        .get(next..)
                        .is_some_and(|scan| scan.windows(2).rev().any(|w| w == [0xFF, 0xD9]));
                }
                i = next;
            }
        }
    }
    false // the headers themselves are cut short
}

#[cfg(test)]
mod decoder_panic_tests {
    /// A TIFF whose SampleFormat tag holds no value: the tiff crate (0.10.3) indexes it and
    /// panics; the file gets a decoding error instead.
    #[test]
    fn a_tiff_that_panics_its_decoder_is_a_decoding_error() {
        let entry = |tag: u16, kind: u16, count: u32, value: u32| {
            let mut e = Vec::new();
            e.extend(tag.to_le_bytes());
            e.extend(kind.to_le_bytes());
            e.extend(count.to_le_bytes());
            e.extend(value.to_le_bytes());
            e
        };
        let entries = [
            entry(256, 3, 1, 1),
            entry(257, 3, 1, 1),
            entry(258, 3, 1, 8),
            entry(259, 3, 1, 1),
            entry(262, 3, 1, 1),
            entry(273, 4, 1, 8),
            entry(278, 3, 1, 1),
            entry(279, 4, 1, 1),
            entry(339, 3, 0, 0),
        ];
        let ifd = 8 + 4;
        let mut b = b"II*\0".to_vec();
        b.extend((ifd as u32).to_le_bytes());
        b.extend([0u8; 4]); // the pixel at offset 8, and padding
        b.extend((entries.len() as u16).to_le_bytes());
        for e in &entries {
            b.extend(e);
        }
        b.extend([0u8; 4]);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.tif");
        std::fs::write(&path, b).unwrap();
        let e = super::Frame::read(&path)
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.tif") && e.contains("malformed"), "{e}");
    }
}
