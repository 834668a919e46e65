//! FITS input: the primary image (or, when the primary HDU holds no data, the first IMAGE
//! extension) as a grey frame of u16 pixels, with the observation epoch from DATE-OBS or
//! MJD-OBS.
//!
//! Beside this file: `fits/scan.rs` (the header scan that guards fitsrs), `fits/pixels.rs`
//! (sample types, scaling, blanks, sentinels) and `fits/cards.rs` (the one FITS card writer).
//!
//! Pixel coordinates: rows stay in stored order, so gpustar's pixel (x, y) on a FITS frame is
//! FITS pixel (x + 1, y + 1), the convention of astropy (whose 0-based (x, y) is the same
//! pair) and astrometry.net, and a WCS written for the frame lines up with those tools. FITS
//! viewers such as DS9 draw the first stored row at the bottom, so the frame looks flipped
//! vertically next to them; it is not flipped, on purpose.
//!
//! Values: integer data whose physical values (BZERO + BSCALE × stored) all lie in 0..=65535
//! keep them exactly, and the saturation is the largest physical value the stored type can
//! hold (255 for BITPIX 8, 32767 for signed 16-bit, 65535 for unsigned 16-bit and wider types).
//! Anything else (negative values, larger integers, non-integral scaling, floating point) is
//! mapped linearly from [min, max] of the valid values onto [0, 65535], saturation 65535 (so
//! only the brightest pixel can be flagged); a constant image maps to 0. Blank pixels (NaN or
//! ±inf in float data, the BLANK value in integer data) take the median of the valid pixels,
//! so they make neither stars nor holes.
//!
//! Headers are parsed by the fitsrs crate, the data are read here straight from the input.
//! fitsrs 0.4.1 panics on some malformed headers (a value that is a lone quote; axis sizes
//! whose product overflows u64, in builds with overflow checks) and allocates from table
//! headers (TFIELDS, ZNAXIS) without bound. So a small scan checks every header first, and
//! fitsrs only ever sees copies of the headers of the HDUs used, both already checked.

use crate::error::{Result, fail};
use fitsrs::card::Value;
use fitsrs::hdu::header::Header;
use fitsrs::hdu::header::extension::image::Image;
use std::collections::BTreeMap;

mod bintable;
mod cards;
pub mod copy;
mod pixels;
mod rice;
pub mod scale;
mod scan;
pub mod star_list;
pub mod table;
mod tiled;

pub(crate) use cards::number_text;
pub use cards::{card, card_comment, card_end, card_raw, card_real, card_str, encode_u16};
use pixels::{Scaling, convert_float, convert_int, new_pixels};
use scan::{Scan, find_image_extension, parse_headers, scan_header};

/// A decoded FITS image.
#[derive(Clone, Debug, PartialEq)]
pub struct FitsFrame {
    pub width: u32,
    pub height: u32,
    /// Row-major pixels, row 0 = the first row stored (FITS y = 1).
    pub pixels: Vec<u16>,
    /// Pixels at this value are saturated.
    pub saturation: u16,
    /// Observation epoch as a Julian year (e.g. 2019.57), from DATE-BEG, DATE-OBS, MJD-BEG or
    /// MJD-OBS when present, parseable and plausible.
    pub epoch: Option<f64>,
    /// What a person should know about how the file was read (a time passed over, pixels
    /// taken as bad).
    pub warnings: Vec<String>,
    /// Every keyword with a value, as text: strings without their quotes and trailing blanks,
    /// numbers as written back by Rust, logicals as T or F. The image's own header wins over
    /// the primary header of a multi-extension file.
    pub keywords: BTreeMap<String, String>,
}

// gpustar's one writer of FITS header cards (frames, WCS headers, simulated sets): 80 columns,
// values in fixed format (FITS 4.0, 4.2), keyword names at most 8 characters.

/// Is this (lower-case) file extension a FITS file? Tile-compressed `.fz` files are FITS too
/// (`fits/tiled.rs` expands them).
pub fn is_fits_extension(ext_lowercase: &str) -> bool {
    matches!(ext_lowercase, "fits" | "fit" | "fts" | "fz")
}

/// Where the image's data end in a FITS file whose first `head` bytes hold its headers (the
/// same checks as [`decode_fits`]): how much of a compressed stream to inflate.
pub fn image_end(head: &[u8], max_pixels: u64) -> Result<u64> {
    let l = layout(head, max_pixels)?;
    Ok(l.image.data_start as u64 + l.width * l.height * l.image.bytes_per_value)
}

/// Decode the primary HDU of a FITS file held in memory. `max_pixels` caps width×height before any allocation.
///
/// When the primary HDU has no data (NAXIS = 0), as in multi-extension files, the first IMAGE
/// extension is decoded instead. Errors say what is wrong in words a person can act on; they
/// do not name the file, which the caller adds.
pub fn decode_fits(bytes: &[u8], max_pixels: u64) -> Result<FitsFrame> {
    if let Some((plain, note)) = expand_tiled(bytes, max_pixels)? {
        let mut f = decode_fits(&plain, max_pixels)?;
        f.warnings.extend(note);
        return Ok(f);
    }
    let Layout {
        image,
        headers,
        width: w,
        height: h,
        cube,
    } = layout(bytes, max_pixels)?;
    let Some(header) = headers.last() else {
        fail!(Input, "no FITS header");
    };
    let count = w * h;
    let need = count * image.bytes_per_value;
    let have = bytes.len().saturating_sub(image.data_start) as u64;
    if have < need {
        fail!(
            Input,
            "FITS data truncated: expected {need} bytes, file holds {have}"
        );
    }
    // `need` <= `have`, so these fit in usize.
    let data = &bytes[image.data_start..image.data_start + need as usize];

    let (scaling, blank) = scaling_and_blank(header, image.bitpix)?;
    let (epoch, mut warnings) = epoch(headers.iter().rev());
    warnings.extend(cube);
    let with_warning = |(p, s, w): (Vec<u16>, u16, Option<String>), all: &mut Vec<String>| {
        all.extend(w);
        (p, s)
    };
    let (mut pixels, saturation) = match image.bitpix {
        8 => convert_int::<u8>(data, scaling, blank, count)?,
        16 => convert_int::<i16>(data, scaling, blank, count)?,
        32 => convert_int::<i32>(data, scaling, blank, count)?,
        64 => convert_int::<i64>(data, scaling, blank, count)?,
        -32 => with_warning(convert_float::<f32>(data, scaling, count)?, &mut warnings),
        -64 => with_warning(convert_float::<f64>(data, scaling, count)?, &mut warnings),
        b => fail!(Input, "FITS BITPIX = {b} is not supported"),
    };
    let keywords = keywords(&headers);
    // A raw colour mosaic is detected on its luminance (see `bayer`).
    if super::bayer::mosaic(&keywords).is_some() {
        super::bayer::luminance(&mut pixels, w as usize, h as usize);
    }
    Ok(FitsFrame {
        width: w as u32,
        height: h as u32,
        pixels,
        saturation,
        // The image's own header first; DATE-OBS often sits only in the primary header of
        // multi-extension files.
        epoch,
        warnings,
        keywords,
    })
}

/// What the headers say of a FITS file's image, checked before any of its data are read.
struct Layout {
    /// The image's HDU (the primary, or the first IMAGE extension when the primary has no data).
    image: Scan,
    /// The headers used, the image's own last.
    headers: Vec<Header<Image>>,
    width: u64,
    height: u64,
    /// Said of a cube, whose first plane is read.
    cube: Option<String>,
}

/// The image of a file whose image is tile-compressed (fpack's `.fz`), expanded into a plain
/// FITS file, with what the reading should say; None for other files.
fn expand_tiled(bytes: &[u8], max_pixels: u64) -> Result<Option<(Vec<u8>, Option<String>)>> {
    if !bytes.starts_with(b"SIMPLE  =") {
        return Ok(None);
    }
    let primary = scan_header(bytes, 0, "FITS primary HDU".to_string())?;
    if !primary.naxis.is_empty() {
        return Ok(None);
    }
    let ext = find_image_extension(bytes, &primary)?;
    if !ext.zimage {
        return Ok(None);
    }
    tiled::expand(bytes, &primary, &ext, max_pixels).map(Some)
}

/// The [`Layout`] of a FITS file of which `bytes` hold at least the headers: what every
/// reading checks first (a FITS file, headers fitsrs can take, a 2-D image of at most
/// `max_pixels`).
fn layout(bytes: &[u8], max_pixels: u64) -> Result<Layout> {
    if bytes.is_empty() {
        fail!(Input, "the file is empty (0 bytes)");
    }
    if bytes.starts_with(&[0x1f, 0x8b]) {
        fail!(
            Input,
            "gzip-compressed FITS is not supported: gunzip the file first"
        );
    }
    if !bytes.starts_with(b"SIMPLE  =") {
        fail!(
            Input,
            "not a FITS file: it does not begin with the card SIMPLE = T"
        );
    }
    let primary = scan_header(bytes, 0, "FITS primary HDU".to_string())?;
    let ext = if primary.naxis.is_empty() {
        Some(find_image_extension(bytes, &primary)?)
    } else {
        None
    };
    if let Some(e) = ext.as_ref().filter(|e| e.zimage) {
        fail!(
            Input,
            "{} holds a tile-compressed image, which is read from .fz files, not from inside \
             a gzip file",
            e.what
        );
    }
    let headers = parse_headers(bytes, &primary, ext.as_ref())?;
    let image = ext.unwrap_or(primary);

    let dims = &image.naxis;
    if dims.len() < 2 {
        let shape = if dims.is_empty() {
            "no data".to_string()
        } else {
            dims.iter()
                .map(u64::to_string)
                .collect::<Vec<_>>()
                .join("×")
        };
        fail!(
            Input,
            "{} has NAXIS = {} ({shape}): gpustar needs a 2-D image",
            image.what,
            dims.len()
        );
    }
    let (w, h) = (dims[0], dims[1]);
    // A cube (stvid's four planes: mean, spread, maximum and its frame index): the first
    // plane, stvid's mean, is the sky.
    let cube = (dims[2..].iter().any(|&d| d != 1)).then(|| {
        format!(
            "{} is a cube ({}): its first plane was read",
            image.what,
            dims.iter()
                .map(u64::to_string)
                .collect::<Vec<_>>()
                .join("×")
        )
    });
    if w == 0 || h == 0 {
        fail!(Input, "{} has an empty image ({w}×{h} pixels)", image.what);
    }
    // The scan checked that all axes times 8 bytes fit in u64.
    let count = w * h;
    if count > max_pixels || w > u64::from(u32::MAX) || h > u64::from(u32::MAX) {
        fail!(
            Input,
            "the FITS image is {w}×{h} ({count} pixels), larger than gpustar reads \
             ({max_pixels} pixels at most)"
        );
    }
    Ok(Layout {
        image,
        headers,
        width: w,
        height: h,
        cube,
    })
}

/// BZERO and BSCALE of the image's header, and BLANK, which marks missing pixels of integer
/// data only (FITS 4.0, 4.4.2.5) and is compared before scaling.
fn scaling_and_blank(header: &Header<Image>, bitpix: i64) -> Result<(Scaling, Option<i64>)> {
    let scaling = Scaling::new(
        number(header, "BZERO")?.unwrap_or(0.0),
        number(header, "BSCALE")?.unwrap_or(1.0),
    );
    let blank = match header.get("BLANK") {
        Some(Value::Integer { value, .. }) if bitpix > 0 => Some(*value),
        _ => None,
    };
    Ok((scaling, blank))
}

/// The usual camera frame, read from the file straight into its pixels: an image (the one
/// [`decode_fits`] takes) of BITPIX 16 with BZERO 32768 and BSCALE 1 and no BLANK (every stored
/// value is its pixel exactly). `head` is the file's beginning, already read, holding the
/// headers up to the image's; `rest`
/// reads on from its end; `file_len` is the file's length. The data are read a chunk at a
/// time into the pixels' own memory and converted there while in cache: one pass over memory
/// where reading the file whole and converting it made three, half the time of a 2 MB frame.
///
/// None for any other file, and at any irregularity (headers not wholly in `head`, a short
/// read): the caller then decodes the file whole with [`decode_fits`], which reads every kind
/// and says what is wrong. Some(frame) is exactly what `decode_fits` returns for the file.
pub fn read_camera_frame(
    head: &[u8],
    rest: &mut impl std::io::Read,
    file_len: u64,
    max_pixels: u64,
) -> Option<FitsFrame> {
    use std::io::Read;
    let Layout {
        image,
        headers,
        width: w,
        height: h,
        cube,
    } = layout(head, max_pixels).ok()?;
    let count = w * h;
    let need = usize::try_from(count * 2).ok()?;
    if image.bitpix != 16 || (image.data_start + need) as u64 > file_len {
        return None;
    }
    let (scaling, blank) = scaling_and_blank(headers.last()?, image.bitpix).ok()?;
    if blank.is_some() || scaling.int != Some((32768, 1)) {
        return None;
    }
    let mut pixels = new_pixels(count, 0).ok()?;
    pixels.resize(count as usize, 0);
    let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut pixels);
    // The data in `head`, then the rest (past the header's padding, if `head` ends in it).
    let mut filled = head.len().saturating_sub(image.data_start).min(need);
    bytes[..filled].copy_from_slice(&head[image.data_start..image.data_start + filled]);
    let skip = image.data_start.saturating_sub(head.len()) as u64;
    if skip > 0 && std::io::copy(&mut rest.by_ref().take(skip), &mut std::io::sink()).ok()? != skip
    {
        return None;
    }
    let mut converted = 0;
    loop {
        let whole = filled / 2;
        big_endian_to_pixels(&mut pixels[converted..whole]);
        converted = whole;
        if filled == need {
            break;
        }
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut pixels);
        let end = (filled + READ_CHUNK).min(need);
        rest.read_exact(&mut bytes[filled..end]).ok()?;
        filled = end;
    }
    let (epoch, mut warnings) = epoch(headers.iter().rev());
    warnings.extend(cube);
    let keywords = keywords(&headers);
    if super::bayer::mosaic(&keywords).is_some() {
        super::bayer::luminance(&mut pixels, w as usize, h as usize);
    }
    Some(FitsFrame {
        width: w as u32,
        height: h as u32,
        pixels,
        saturation: u16::MAX,
        epoch,
        warnings,
        keywords,
    })
}

/// Stored big-endian i16 v becomes pixel 32768 + v (as `convert_int` maps it), in place.
fn big_endian_to_pixels(p: &mut [u16]) {
    crate::simd::fast!(big_endian_to_pixels_in(p: &mut [u16]) -> ())
}

/// [`big_endian_to_pixels`], compiled where it is inlined (see [`crate::simd`]).
#[inline(always)]
fn big_endian_to_pixels_in(p: &mut [u16]) {
    for v in p {
        *v = (32768 + i32::from(u16::from_be(*v) as i16)) as u16;
    }
}

/// Bytes [`read_camera_frame`] reads and converts at a time: inside the L2 cache of current
/// x86 cores (512 KiB and more), and 8 reads for a 2 MB frame where 64 KiB took 32 (each read
/// looks the file's pages up again: 1-2 % of a sparse 10° run, docs/speed.md).
const READ_CHUNK: usize = 256 << 10;

/// The keywords of the headers used, later headers over earlier ones.
fn keywords(headers: &[Header<Image>]) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for h in headers {
        for key in h.keywords() {
            let text = match h.get(key) {
                Some(Value::Integer { value, .. }) => value.to_string(),
                Some(Value::Float { value, .. }) => number_text(*value),
                Some(Value::Logical { value, .. }) => if *value { "T" } else { "F" }.to_string(),
                Some(Value::String { value, .. }) => value.trim_end().to_string(),
                Some(Value::Invalid(_) | Value::Undefined) | None => continue,
            };
            out.insert(key.clone(), text);
        }
    }
    out
}

use crate::sky::julian_year;

/// A numeric keyword: None when absent or blank, an error when it holds something else.
fn number(header: &Header<Image>, key: &str) -> Result<Option<f64>> {
    let v = match header.get(key) {
        None | Some(Value::Undefined) => return Ok(None),
        Some(Value::Integer { value, .. }) => *value as f64,
        Some(Value::Float { value, .. }) => *value,
        Some(Value::String { value, .. } | Value::Invalid(value)) => {
            fail!(Input, "FITS keyword {key} is not a number: {value}")
        }
        Some(Value::Logical { value, .. }) => {
            fail!(Input, "FITS keyword {key} is not a number: {value}")
        }
    };
    if !v.is_finite() {
        fail!(Input, "FITS keyword {key} is not a finite number: {v}");
    }
    Ok(Some(v))
}

use crate::sky::plausible_mjd;

/// The epoch of proper motion (Julian year) from the first of DATE-BEG, DATE-OBS, MJD-BEG and
/// MJD-OBS (the order the exposure times are read in) that a header holds in a form read and
/// within the years any time is taken from ([`plausible_mjd`]); a value outside them (a
/// 9999-12-31 placeholder, a JD in MJD-OBS) is passed over with a warning.
fn epoch<'a>(
    headers: impl Iterator<Item = &'a Header<Image>> + Clone,
) -> (Option<f64>, Vec<String>) {
    // MJD 51544.5 = JD 2451545.0 = J2000.0.
    const J2000_MJD: f64 = 51_544.5;
    let mut warnings = Vec::new();
    for key in ["DATE-BEG", "DATE-OBS", "MJD-BEG", "MJD-OBS"] {
        let read = |h: &Header<Image>| -> Option<(f64, String)> {
            match (h.get(key), key.starts_with("MJD")) {
                (Some(Value::String { value, .. }), false) => {
                    julian_year(value).map(|y| (y, value.clone()))
                }
                (Some(Value::Float { value, .. }), true) => {
                    Some((2000.0 + (value - J2000_MJD) / 365.25, number_text(*value)))
                }
                (Some(Value::Integer { value, .. }), true) => Some((
                    2000.0 + (*value as f64 - J2000_MJD) / 365.25,
                    value.to_string(),
                )),
                _ => None,
            }
        };
        let Some((year, text)) = headers.clone().find_map(read) else {
            continue;
        };
        let mjd = J2000_MJD + (year - 2000.0) * 365.25;
        if year.is_finite() && plausible_mjd(mjd) {
            return (Some(year), warnings);
        }
        warnings.push(format!(
            "{key} = '{text}' is outside 1960-2100: not used as the epoch of proper motion"
        ));
    }
    (None, warnings)
}

/// The epoch (Julian year) of a frame held in memory whose caller gives FITS-like keywords
/// as text (the Python `header=`, `time=`): the same keywords in the same order, and the same
/// plausibility rule and warning, as [`decode_fits`] applies to a file's header.
pub fn epoch_of_keywords(keywords: &BTreeMap<String, String>) -> (Option<f64>, Vec<String>) {
    const J2000_MJD: f64 = 51_544.5;
    let mut warnings = Vec::new();
    for key in ["DATE-BEG", "DATE-OBS", "MJD-BEG", "MJD-OBS"] {
        let Some(text) = keywords.get(key) else {
            continue;
        };
        let year = if key.starts_with("MJD") {
            text.trim()
                .parse::<f64>()
                .ok()
                .map(|mjd| 2000.0 + (mjd - J2000_MJD) / 365.25)
        } else {
            julian_year(text)
        };
        let Some(year) = year else { continue };
        if year.is_finite() && plausible_mjd(J2000_MJD + (year - 2000.0) * 365.25) {
            return (Some(year), warnings);
        }
        warnings.push(format!(
            "{key} = '{text}' is outside 1960-2100: not used as the epoch of proper motion"
        ));
    }
    (None, warnings)
}

/// 32-bit float values to u16 pixels and the saturation, exactly as a BITPIX −32 file of these
/// values (BZERO 0, BSCALE 1) is read, with its sentinel warning (for `io::array`).
pub(crate) fn float_pixels(values: &[f32]) -> Result<(Vec<u16>, u16, Option<String>)> {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    convert_float::<f32>(&bytes, Scaling::new(0.0, 1.0), values.len() as u64)
}

#[cfg(test)]
mod tests;
