//! FITS input: the primary image (or, when the primary HDU holds no data, the first IMAGE
//! extension) as a grey frame of u16 pixels, with the observation epoch from DATE-OBS or
//! MJD-OBS.
//!
//! Size: about 900 lines of code: the header scan that guards fitsrs, six sample types with
//! their scaling, blank and sentinel handling, the epoch, and the one FITS card writer; the
//! writer goes to `io/` with issue 23's layout step.
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

use crate::error::{Result, error, fail};
use fitsrs::card::Value;
use fitsrs::hdu::header::Header;
use fitsrs::hdu::header::extension::image::Image;
use fitsrs::{Fits, HDU};
use std::collections::BTreeMap;
use std::io::Cursor;

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

/// A FITS header card `KEYWORD = value` (value as FITS text: a string quoted, e.g.
/// `'2024-03-15T20:00:00.000'`, or a number), 80 columns.
pub fn card(key: &str, value: &str) -> String {
    card_raw(key, value, "")
}

/// A card with a value already formatted (logical, integer): right-justified to column 30.
pub fn card_raw(key: &str, value: &str, comment: &str) -> String {
    finish_card(format!("{key:<8}= {value:>20}"), comment)
}

/// A string card: quoted from column 11, padded to at least 8 characters (fixed format).
pub fn card_str(key: &str, value: &str, comment: &str) -> String {
    let quoted = format!("'{:<8}'", value.replace('\'', "''"));
    finish_card(format!("{key:<8}= {quoted:<20}"), comment)
}

/// A real card, right-justified to column 30, with enough digits to round-trip to ~1e-13.
pub fn card_real(key: &str, value: f64, comment: &str) -> String {
    let text = if value.fract() == 0.0 && value.abs() < 1e9 {
        format!("{value:.1}")
    } else {
        // 14 significant digits fit in 20 columns for exponents of up to two digits.
        (8..=13)
            .rev()
            .map(|digits| format!("{value:.digits$E}"))
            .find(|s| s.len() <= 20)
            .unwrap_or_else(|| format!("{value:.6E}"))
    };
    card_raw(key, &text, comment)
}

/// A COMMENT card (text past column 80 cut).
pub fn card_comment(text: &str) -> String {
    finish_card(format!("COMMENT {text}"), "")
}

/// The END card.
pub fn card_end() -> String {
    format!("{:<80}", "END")
}

/// A card with its comment, cut or padded to 80 columns (by characters: a non-ASCII comment
/// cannot split a character).
fn finish_card(mut card: String, comment: &str) -> String {
    if !comment.is_empty() {
        card.push_str(" / ");
        card.push_str(comment);
    }
    format!("{card:<80.80}")
}

/// A FITS file of one 16-bit image (BITPIX 16 with BZERO 32768, so the values are u16) with
/// these 80-column cards after the structural ones (cards of SIMPLE, BITPIX, NAXIS…, EXTEND,
/// BZERO, BSCALE and END among them are left out: this function writes its own).
pub fn encode_u16(width: u32, height: u32, pixels: &[u16], cards: &[String]) -> Vec<u8> {
    let mut head = vec![
        card("SIMPLE", "T"),
        card("BITPIX", "16"),
        card("NAXIS", "2"),
        card("NAXIS1", &width.to_string()),
        card("NAXIS2", &height.to_string()),
        card("BZERO", "32768"),
        card("BSCALE", "1"),
    ];
    let structural = |c: &str| {
        let key = c.get(..8).unwrap_or(c).trim_end();
        matches!(
            key,
            "SIMPLE" | "BITPIX" | "EXTEND" | "BZERO" | "BSCALE" | "END"
        ) || key.starts_with("NAXIS")
    };
    head.extend(
        cards
            .iter()
            .filter(|c| !structural(c))
            .map(|c| format!("{c:<80.80}")),
    );
    head.push(card_end());
    let mut out: Vec<u8> = head.iter().flat_map(|c| c.bytes()).collect();
    out.resize(out.len().div_ceil(BLOCK) * BLOCK, b' ');
    for &v in pixels {
        out.extend_from_slice(&((v as i32 - 32768) as i16).to_be_bytes());
    }
    out.resize(out.len().div_ceil(BLOCK) * BLOCK, 0);
    out
}

/// Is this (lower-case) file extension a FITS file? Tile-compressed `.fz` files are not:
/// gpustar does not decompress them.
pub fn is_fits_extension(ext_lowercase: &str) -> bool {
    matches!(ext_lowercase, "fits" | "fit" | "fts")
}

const BLOCK: usize = 2880;
const CARD: usize = 80;

/// Decode the primary HDU of a FITS file held in memory. `max_pixels` caps width×height before any allocation.
///
/// When the primary HDU has no data (NAXIS = 0), as in multi-extension files, the first IMAGE
/// extension is decoded instead. Errors say what is wrong in words a person can act on; they
/// do not name the file, which the caller adds.
pub fn decode_fits(bytes: &[u8], max_pixels: u64) -> Result<FitsFrame> {
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
    let headers = parse_headers(bytes, &primary, ext.as_ref())?;
    let image = ext.as_ref().unwrap_or(&primary);
    let header = headers
        .last()
        .ok_or_else(|| error!(Input, "no FITS header"))?;

    let dims = &image.naxis;
    if dims.len() < 2 || dims[2..].iter().any(|&d| d != 1) {
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

    let scaling = Scaling::new(
        number(header, "BZERO")?.unwrap_or(0.0),
        number(header, "BSCALE")?.unwrap_or(1.0),
    );
    // BLANK marks missing pixels of integer data only (FITS 4.0, 4.4.2.5), compared before
    // scaling.
    let blank = match header.get("BLANK") {
        Some(Value::Integer { value, .. }) if image.bitpix > 0 => Some(*value),
        _ => None,
    };
    let (epoch, mut warnings) = epoch(headers.iter().rev());
    let with_warning = |(p, s, w): (Vec<u16>, u16, Option<String>), all: &mut Vec<String>| {
        all.extend(w);
        (p, s)
    };
    let (pixels, saturation) = match image.bitpix {
        8 => convert_int::<u8>(data, scaling, blank, count)?,
        16 => convert_int::<i16>(data, scaling, blank, count)?,
        32 => convert_int::<i32>(data, scaling, blank, count)?,
        64 => convert_int::<i64>(data, scaling, blank, count)?,
        -32 => with_warning(convert_float::<f32>(data, scaling, count)?, &mut warnings),
        -64 => with_warning(convert_float::<f64>(data, scaling, count)?, &mut warnings),
        b => fail!(Input, "FITS BITPIX = {b} is not supported"),
    };
    Ok(FitsFrame {
        width: w as u32,
        height: h as u32,
        pixels,
        saturation,
        // The image's own header first; DATE-OBS often sits only in the primary header of
        // multi-extension files.
        epoch,
        warnings,
        keywords: keywords(&headers),
    })
}

/// A float keyword's value as text that reads back to the same number: plain digits, or an
/// exponent where plain digits would be long (1E300 would otherwise be 301 characters in
/// every warning that quotes it).
fn number_text(v: f64) -> String {
    if v != 0.0 && (v.abs() >= 1e16 || v.abs() < 1e-6) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

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

/// What the safety scan reads from one header, before fitsrs sees it.
#[derive(Debug)]
struct Scan {
    /// "FITS primary HDU" or "FITS extension N", for messages.
    what: String,
    /// Where the header starts, and where its data start (past its last 2880-byte block).
    start: usize,
    data_start: usize,
    bitpix: i64,
    bytes_per_value: u64,
    naxis: Vec<u64>,
    /// Size of the data unit: |BITPIX|/8 × GCOUNT × (PCOUNT + NAXIS1 × … × NAXISn).
    data_len: u64,
    /// The XTENSION value (None in the primary header).
    xtension: Option<String>,
    /// ZIMAGE = T: a tile-compressed image stored in a binary table.
    zimage: bool,
}

impl Scan {
    /// Where the next HDU starts: data are padded to whole blocks.
    fn next_start(&self, file_len: usize) -> Result<usize> {
        let have = file_len.saturating_sub(self.data_start) as u64;
        if have < self.data_len {
            fail!(
                Input,
                "FITS data truncated: {} expected {} bytes, file holds {have}",
                self.what,
                self.data_len
            );
        }
        // data_len <= have, so it fits in usize.
        Ok(self.data_start + (self.data_len as usize).next_multiple_of(BLOCK))
    }
}

/// Check one header: it ends with END, BITPIX is valid, and the size its axes give fits in
/// u64 (with room for fitsrs's own products). Reads the few keywords needed to walk the file.
fn scan_header(bytes: &[u8], start: usize, what: String) -> Result<Scan> {
    let mut ints: BTreeMap<String, Option<i64>> = BTreeMap::new();
    let mut xtension = None;
    let mut zimage = false;
    let mut end = None;
    for (i, card) in bytes[start..].chunks_exact(CARD).enumerate() {
        // Trimmed on both sides, as fitsrs does: both must read the same cards.
        let key = card[..8].trim_ascii();
        if key == b"END" {
            end = Some(start + (i + 1) * CARD);
            break;
        }
        if card[8..10] != *b"= " {
            continue;
        }
        let value = value_field(&card[10..]);
        match key {
            b"XTENSION" => {
                xtension = value
                    .strip_prefix('\'')
                    .and_then(|v| v.split('\'').next())
                    .map(|v| v.trim().to_string());
            }
            b"ZIMAGE" => zimage = value == "T",
            b"BITPIX" | b"NAXIS" | b"PCOUNT" | b"GCOUNT" => {
                ints.insert(ascii(key), value.parse().ok());
            }
            _ if key.starts_with(b"NAXIS") && key[5..].iter().all(u8::is_ascii_digit) => {
                ints.insert(ascii(key), value.parse().ok());
            }
            _ => {}
        }
    }
    let Some(end) = end else {
        fail!(
            Input,
            "{what}: the header has no END card (not a FITS file, or one cut short)"
        );
    };
    let int = |key: &str| -> Result<Option<i64>> {
        match ints.get(key) {
            None => Ok(None),
            Some(Some(v)) => Ok(Some(*v)),
            Some(None) => fail!(Input, "{what}: {key} is not an integer"),
        }
    };
    let bitpix = int("BITPIX")?.ok_or_else(|| error!(Input, "{what}: the header lacks BITPIX"))?;
    if ![8, 16, 32, 64, -32, -64].contains(&bitpix) {
        fail!(
            Input,
            "{what} has BITPIX = {bitpix}; FITS allows only 8, 16, 32, 64, -32 and -64"
        );
    }
    let naxis = int("NAXIS")?.ok_or_else(|| error!(Input, "{what}: the header lacks NAXIS"))?;
    if !(0..=999).contains(&naxis) {
        fail!(Input, "{what} has NAXIS = {naxis}; FITS allows 0 to 999");
    }
    let mut axes = Vec::new();
    for n in 1..=naxis {
        let key = format!("NAXIS{n}");
        match int(&key)? {
            None => fail!(Input, "{what}: the header lacks {key}"),
            Some(v) if v < 0 => fail!(Input, "{what} has {key} = {v}, a negative size"),
            Some(v) => axes.push(v as u64),
        }
    }
    let pcount = int("PCOUNT")?.unwrap_or(0);
    let gcount = int("GCOUNT")?.unwrap_or(1);
    if pcount < 0 || gcount < 0 {
        fail!(
            Input,
            "{what} has PCOUNT = {pcount}, GCOUNT = {gcount}: they cannot be negative"
        );
    }
    let bytes_per_value = bitpix.unsigned_abs() / 8;
    let values = if axes.is_empty() {
        Some(0)
    } else {
        axes.iter().try_fold(1u64, |p, &a| p.checked_mul(a))
    };
    // fitsrs multiplies the axes by 8 bytes at most, and by the group count and size here.
    let data_len = values
        .filter(|v| v.checked_mul(8).is_some())
        .and_then(|v| v.checked_add(pcount as u64))
        .and_then(|v| v.checked_mul(gcount as u64))
        .and_then(|v| v.checked_mul(bytes_per_value));
    let Some(data_len) = data_len else {
        let shape = axes
            .iter()
            .map(u64::to_string)
            .collect::<Vec<_>>()
            .join("×");
        fail!(
            Input,
            "{what} declares a data unit too large to exist ({shape})"
        );
    };
    Ok(Scan {
        what,
        start,
        data_start: end.next_multiple_of(BLOCK),
        bitpix,
        bytes_per_value,
        naxis: axes,
        data_len,
        xtension,
        zimage,
    })
}

/// The value part of a card (after "= "), up to a comment: trimmed, quotes kept. Comments
/// start at a '/' outside a quoted string.
fn value_field(field: &[u8]) -> String {
    let mut quoted = false;
    let end = field
        .iter()
        .position(|&b| {
            if b == b'\'' {
                quoted = !quoted;
            }
            b == b'/' && !quoted
        })
        .unwrap_or(field.len());
    String::from_utf8_lossy(&field[..end]).trim().to_string()
}

fn ascii(key: &[u8]) -> String {
    String::from_utf8_lossy(key).into_owned()
}

/// With an empty primary HDU, the first IMAGE extension; tables before it are skipped.
fn find_image_extension(bytes: &[u8], primary: &Scan) -> Result<Scan> {
    let mut pos = primary.next_start(bytes.len())?;
    let mut index = 0;
    // Each HDU takes at least one block, so this ends.
    while pos < bytes.len() {
        index += 1;
        let scan = scan_header(bytes, pos, format!("FITS extension {index}"))?;
        match scan.xtension.as_deref() {
            Some("IMAGE" | "IUEIMAGE") => return Ok(scan),
            Some("BINTABLE") if scan.zimage => fail!(
                Input,
                "FITS extension {index} holds a tile-compressed image (fpack): compressed FITS is \
                 not supported; decompress it first (e.g. funpack)"
            ),
            Some(_) => {}
            None => fail!(Input, "FITS extension {index}: the header lacks XTENSION"),
        }
        pos = scan.next_start(bytes.len())?;
    }
    fail!(
        Input,
        "FITS primary HDU holds no image (NAXIS = 0) and no IMAGE extension follows{}",
        if index > 0 { " (only tables)" } else { "" }
    )
}

/// Parse the primary header, and the image extension's if any, with fitsrs. It reads a copy
/// holding only those headers, in which cards fitsrs would panic on are blanked.
fn parse_headers(bytes: &[u8], primary: &Scan, ext: Option<&Scan>) -> Result<Vec<Header<Image>>> {
    let mut copy = Vec::new();
    for scan in std::iter::once(primary).chain(ext) {
        let from = copy.len();
        copy.extend_from_slice(&bytes[scan.start..scan.data_start.min(bytes.len())]);
        // A file may end inside the header's padding.
        copy.resize(from + scan.data_start - scan.start, b' ');
        for card in copy[from..].chunks_exact_mut(CARD) {
            let key = card[..8].trim_ascii();
            if key == b"END" {
                break;
            }
            // A value that is a lone quote makes fitsrs slice s[1..0]: exactly one quote, at
            // the end, is never a valid string value. HIERARCH cards can name any keyword
            // (NAXIS1 too), which the scan does not read: nothing gpustar uses is in them.
            let text = card[8..].trim_ascii_end();
            let lone_quote =
                text.ends_with(b"'") && text.iter().filter(|&&b| b == b'\'').count() == 1;
            if lone_quote || key == b"HIERARCH" {
                card.fill(b' ');
            }
        }
    }
    let mut fits = Fits::from_reader(Cursor::new(copy));
    let mut headers = Vec::new();
    for scan in std::iter::once(primary).chain(ext) {
        let header = match fits.next() {
            Some(Ok(HDU::Primary(hdu) | HDU::XImage(hdu))) => hdu.get_header().clone(),
            Some(Ok(_)) => fail!(Input, "{}: not an image HDU", scan.what),
            Some(Err(e)) => fail!(Input, "{}: cannot parse the header: {e}", scan.what),
            None => fail!(Input, "{}: the header is missing", scan.what),
        };
        // The data are sliced with the scan's sizes: both readings must agree.
        let x = header.get_xtension();
        if x.get_naxis() != scan.naxis.as_slice() || x.get_bitpix() as i64 != scan.bitpix {
            fail!(
                Input,
                "{}: the header is inconsistent (BITPIX or NAXISn read two ways)",
                scan.what
            );
        }
        headers.push(header);
    }
    Ok(headers)
}

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

/// BZERO and BSCALE. `int` holds them as integers when both are integral and small enough
/// for exact arithmetic in i128: unsigned 64-bit data have BZERO = 2^63, which f64
/// arithmetic on the stored values would round away.
#[derive(Clone, Copy, Debug)]
struct Scaling {
    scale: f64,
    int: Option<(i128, i128)>,
}

impl Scaling {
    fn new(zero: f64, scale: f64) -> Scaling {
        let limit = 2f64.powi(63);
        let integral = |v: f64| v.fract() == 0.0 && v.abs() <= limit;
        let int = (integral(zero) && integral(scale)).then_some((zero as i128, scale as i128));
        Scaling { scale, int }
    }
}

/// An integer stored type (BITPIX 8, 16, 32, 64), read as i64.
trait IntSample {
    const BYTES: usize;
    const MIN: i64;
    const MAX: i64;
    /// `b` holds BYTES big-endian bytes.
    fn read(b: &[u8]) -> i64;
}

/// A floating-point stored type (BITPIX −32, −64), read as f64.
trait FloatSample {
    const BYTES: usize;
    fn read(b: &[u8]) -> f64;
}

macro_rules! sample {
    ($trait:ident, $t:ty, $out:ty) => {
        impl $trait for $t {
            const BYTES: usize = size_of::<$t>();
            sample!(@range $trait, $t);
            fn read(b: &[u8]) -> $out {
                <$t>::from_be_bytes(b.try_into().unwrap_or_default()) as $out
            }
        }
    };
    (@range IntSample, $t:ty) => {
        const MIN: i64 = <$t>::MIN as i64;
        const MAX: i64 = <$t>::MAX as i64;
    };
    (@range FloatSample, $t:ty) => {};
}
sample!(IntSample, u8, i64);
sample!(IntSample, i16, i64);
sample!(IntSample, i32, i64);
sample!(IntSample, i64, i64);
sample!(FloatSample, f32, f64);
sample!(FloatSample, f64, f64);

/// Integer data to u16 pixels and the saturation (see the module documentation). Works on
/// stored values: BZERO/BSCALE are affine, so the physical range follows from the stored one,
/// and the linear map only needs BSCALE's sign.
fn convert_int<T: IntSample>(
    data: &[u8],
    s: Scaling,
    blank: Option<i64>,
    count: u64,
) -> Result<(Vec<u16>, u16)> {
    let stored = || data.chunks_exact(T::BYTES).map(T::read);
    let (mut lo, mut hi, mut blanks) = (i64::MAX, i64::MIN, 0u64);
    for v in stored() {
        if Some(v) == blank {
            blanks += 1;
        } else {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    let mut pixels = new_pixels(count, blanks)?;
    let exact = s.int.and_then(|(zero, scale)| {
        let physical = |v: i64| zero + scale * i128::from(v);
        let (a, b) = (physical(lo), physical(hi));
        (a.min(b) >= 0 && a.max(b) <= 65535).then(|| {
            let top = physical(T::MIN).max(physical(T::MAX));
            (zero, scale, top.clamp(0, 65535) as u16)
        })
    });
    let saturation = if let Some((zero, scale, saturation)) = exact {
        // Wrapping i64 arithmetic is exact modulo 2^64, and the results lie in 0..=65535.
        // Blanks come out as garbage here and are replaced below.
        let (zero, scale) = (zero as i64, scale as i64);
        pixels.extend(stored().map(|v| zero.wrapping_add(scale.wrapping_mul(v)) as u16));
        saturation
    } else {
        let k = if hi > lo && s.scale != 0.0 {
            65535.0 / hi.abs_diff(lo) as f64
        } else {
            0.0
        };
        // A negative BSCALE turns the stored order around. The distance fits in u64.
        let flip = s.scale < 0.0;
        let offset = |v: i64| if flip { hi.abs_diff(v) } else { v.abs_diff(lo) };
        pixels.extend(stored().map(|v| (offset(v) as f64 * k + 0.5) as u16));
        u16::MAX
    };
    if blanks > 0 {
        fill_blanks(&mut pixels, data, T::BYTES, |b| Some(T::read(b)) == blank);
    }
    Ok((pixels, saturation))
}

/// Floating-point data to u16 pixels: always the linear map, on stored values as above.
/// NaN and ±inf are blanks.
/// Float data to u16 pixels over the range of the valid values (see [`float_range`]): values
/// outside it (sentinels) and non-finite ones are bad pixels, given the median. Returns a
/// warning when sentinels were found.
fn convert_float<T: FloatSample>(
    data: &[u8],
    s: Scaling,
    count: u64,
) -> Result<(Vec<u16>, u16, Option<String>)> {
    let stored = || data.chunks_exact(T::BYTES).map(T::read);
    let (lo, hi) = float_range(stored);
    let bad = |v: f64| !(v >= lo && v <= hi);
    let (mut blanks, mut sentinels, mut example) = (0u64, 0u64, 0.0);
    for v in stored() {
        if bad(v) {
            blanks += 1;
            if v.is_finite() {
                sentinels += 1;
                example = v;
            }
        }
    }
    let mut pixels = new_pixels(count, blanks)?;
    // In halves, so that hi − lo cannot overflow.
    let (from, sign) = if s.scale < 0.0 {
        (hi * 0.5, -1.0)
    } else {
        (lo * 0.5, 1.0)
    };
    let span = (hi * 0.5 - lo * 0.5).abs();
    let k = if span > 0.0 && s.scale != 0.0 {
        65535.0 / span
    } else {
        0.0
    };
    // Bad values become anything (`as` saturates, NaN → 0) and are replaced below.
    pixels.extend(stored().map(|v| ((v * 0.5 - from) * sign * k + 0.5) as u16));
    if blanks > 0 {
        fill_blanks(&mut pixels, data, T::BYTES, |b| bad(T::read(b)));
    }
    let warning = (sentinels > 0).then(|| {
        format!(
            "{sentinels} pixels far outside the others' values (e.g. {example:e}; the rest lie \
             in {lo:e}..{hi:e}) were taken as bad pixels (sentinel values?)"
        )
    });
    Ok((pixels, u16::MAX, warning))
}

/// How far (in the spread of the 0.1–99.9 % quantiles) values may lie beyond those quantiles
/// and still be mapped whatever follows them; beyond it, see [`float_range`].
const FLOAT_TAIL_SPREADS: f64 = 1000.0;
/// A jump in the sorted tail by more than this factor (distances from the quantile) starts the
/// sentinels.
const FLOAT_SENTINEL_JUMP: f64 = 100.0;

/// The range of the finite values, less sentinels: a bad-pixel marker such as 1e9 or −1e30
/// stretched over the u16 range would leave the sky and every star in a level or two. Beyond
/// FLOAT_TAIL_SPREADS of the quantiles' spread, the tail's values are walked outward and cut
/// at the first jump by FLOAT_SENTINEL_JUMP: the peaks of bright and saturated stars rise by
/// degrees, sentinels jump. A tail of more than 1 % of the values is data, not sentinels.
fn float_range<I: Iterator<Item = f64>>(stored: impl Fn() -> I) -> (f64, f64) {
    let (mut lo, mut hi, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0usize);
    for v in stored() {
        if v.is_finite() {
            // Comparisons rather than f64::min/max, which spend time on NaN.
            if v < lo {
                lo = v;
            }
            if v > hi {
                hi = v;
            }
            n += 1;
        }
    }
    if n == 0 {
        return (lo, hi);
    }
    // Quantiles of a strided sample of at most ~65536 values.
    let stride = (n / 65_536).max(1);
    let mut sample: Vec<f64> = stored().filter(|v| v.is_finite()).step_by(stride).collect();
    sample.sort_unstable_by(f64::total_cmp);
    let cut = sample.len() / 1000;
    let (q_lo, q_hi) = (sample[cut], sample[sample.len() - 1 - cut]);
    let reach = FLOAT_TAIL_SPREADS * (q_hi - q_lo);
    if reach.is_nan() || reach <= 0.0 || reach.is_infinite() {
        return (lo, hi);
    }
    // Each tail: distances beyond the quantile, ascending; the last before a jump is the end.
    let end_of = |distances: Vec<f64>| -> Option<f64> {
        if distances.len() > n / 100 {
            return None;
        }
        let mut d = distances;
        d.sort_unstable_by(f64::total_cmp);
        let mut last = reach;
        for &x in &d {
            if x > FLOAT_SENTINEL_JUMP * last {
                return Some(last);
            }
            last = x;
        }
        None
    };
    // Both tails in one pass, then the range less their sentinels in another.
    let (mut above, mut below) = (Vec::new(), Vec::new());
    for v in stored().filter(|v| v.is_finite()) {
        if v - q_hi > reach {
            above.push(v - q_hi);
        } else if q_lo - v > reach {
            below.push(q_lo - v);
        }
    }
    let (cut_hi, cut_lo) = (end_of(above), end_of(below));
    if cut_hi.is_some() || cut_lo.is_some() {
        let (dh, dl) = (
            cut_hi.unwrap_or(f64::INFINITY),
            cut_lo.unwrap_or(f64::INFINITY),
        );
        (lo, hi) = stored()
            .filter(|&v| v.is_finite() && v - q_hi <= dh && q_lo - v <= dl)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                (l.min(v), h.max(v))
            });
    }
    (lo, hi)
}

/// The pixel buffer, or an error when there is no memory for it or nothing valid to put in.
fn new_pixels(count: u64, blanks: u64) -> Result<Vec<u16>> {
    if blanks == count {
        fail!(
            Input,
            "every pixel of the FITS image is blank (NaN or BLANK)"
        );
    }
    let mut pixels = Vec::new();
    if usize::try_from(count).map_or(true, |n| pixels.try_reserve_exact(n).is_err()) {
        fail!(
            Input,
            "not enough memory for a FITS image of {count} pixels"
        );
    }
    Ok(pixels)
}

/// Give blank pixels the median of the others (from a histogram: linear time, no copy).
fn fill_blanks(pixels: &mut [u16], data: &[u8], bytes: usize, is_blank: impl Fn(&[u8]) -> bool) {
    let mut histogram = vec![0u64; 65536];
    let mut valid = 0u64;
    for (p, b) in pixels.iter().zip(data.chunks_exact(bytes)) {
        if !is_blank(b) {
            histogram[usize::from(*p)] += 1;
            valid += 1;
        }
    }
    let rank = valid.saturating_sub(1) / 2;
    let mut seen = 0;
    let median = histogram
        .iter()
        .position(|&n| {
            seen += n;
            seen > rank
        })
        .unwrap_or(0) as u16;
    for (p, b) in pixels.iter_mut().zip(data.chunks_exact(bytes)) {
        if is_blank(b) {
            *p = median;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A card in fixed format: the value right-aligned in columns 11–30.
    fn card(key: &str, value: impl std::fmt::Display) -> String {
        format!("{key:<8}= {value:>20}")
    }

    fn text_card(key: &str, value: &str) -> String {
        format!("{key:<8}= '{value:<8}'")
    }

    /// Cards, END, padding with spaces to a block; data, padding with zeros to a block.
    fn hdu(cards: &[String], data: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        for c in cards.iter().map(String::as_str).chain(["END"]) {
            assert!(c.len() <= CARD, "card too long: {c}");
            let mut b = c.as_bytes().to_vec();
            b.resize(CARD, b' ');
            out.extend(b);
        }
        out.resize(out.len().next_multiple_of(BLOCK), b' ');
        out.extend_from_slice(data);
        out.resize(out.len().next_multiple_of(BLOCK), 0);
        out
    }

    fn axes_cards(first: String, bitpix: i64, dims: &[u64]) -> Vec<String> {
        let mut cards = vec![first, card("BITPIX", bitpix), card("NAXIS", dims.len())];
        for (i, d) in dims.iter().enumerate() {
            cards.push(card(&format!("NAXIS{}", i + 1), d));
        }
        cards
    }

    /// A single-HDU FITS file.
    fn image(bitpix: i64, dims: &[u64], extra: &[String], data: &[u8]) -> Vec<u8> {
        let mut cards = axes_cards(card("SIMPLE", "T"), bitpix, dims);
        cards.extend_from_slice(extra);
        hdu(&cards, data)
    }

    fn be16(v: &[i16]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_be_bytes()).collect()
    }
    fn be32(v: &[i32]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_be_bytes()).collect()
    }
    fn be64(v: &[i64]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_be_bytes()).collect()
    }
    fn bef32(v: &[f32]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_be_bytes()).collect()
    }
    fn bef64(v: &[f64]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_be_bytes()).collect()
    }

    fn decode(bytes: &[u8]) -> FitsFrame {
        decode_fits(bytes, 1 << 30).unwrap()
    }

    fn error(bytes: &[u8]) -> String {
        format!("{:#}", decode_fits(bytes, 1 << 30).unwrap_err())
    }

    #[test]
    fn bitpix8_keeps_values_and_saturates_at_255() {
        let f = decode(&image(8, &[3, 2], &[], &[0, 1, 2, 100, 200, 255]));
        assert_eq!((f.width, f.height, f.saturation), (3, 2, 255));
        assert_eq!(f.pixels, [0, 1, 2, 100, 200, 255]);
        assert_eq!(f.epoch, None);
    }

    #[test]
    fn unsigned16_with_bzero_keeps_values() {
        // Unsigned 16-bit as FITS stores it: stored = value − 32768.
        let values = [0u16, 1, 1000, 32768, 65534, 65535];
        let stored: Vec<i16> = values.iter().map(|&v| (v as i32 - 32768) as i16).collect();
        let extra = [card("BZERO", 32768), card("BSCALE", 1)];
        let f = decode(&image(16, &[2, 3], &extra, &be16(&stored)));
        assert_eq!(f.pixels, values);
        assert_eq!(f.saturation, 65535);
    }

    #[test]
    fn signed16_nonnegative_keeps_values_with_saturation_32767() {
        let f = decode(&image(16, &[2, 2], &[], &be16(&[0, 5, 1234, 32767])));
        assert_eq!(f.pixels, [0, 5, 1234, 32767]);
        assert_eq!(f.saturation, 32767);
    }

    #[test]
    fn negative_values_are_stretched() {
        let f = decode(&image(16, &[3, 1], &[], &be16(&[-100, 0, 100])));
        assert_eq!(f.pixels, [0, 32768, 65535]);
        assert_eq!(f.saturation, 65535);
    }

    #[test]
    fn int32_in_range_kept_and_out_of_range_stretched() {
        let f = decode(&image(32, &[2, 1], &[], &be32(&[7, 65535])));
        assert_eq!(
            (f.pixels.as_slice(), f.saturation),
            ([7, 65535].as_slice(), 65535)
        );
        // BSCALE 2 takes 40000 to 80000: out of range, stretched.
        let extra = [card("BSCALE", 2)];
        let f = decode(&image(32, &[3, 1], &extra, &be32(&[0, 20000, 40000])));
        assert_eq!(f.pixels, [0, 32768, 65535]);
        // A non-integral BSCALE never keeps values, even in range.
        let extra = [card("BSCALE", 0.5)];
        let f = decode(&image(32, &[3, 1], &extra, &be32(&[10, 20, 30])));
        assert_eq!(f.pixels, [0, 32768, 65535]);
    }

    #[test]
    fn int64_unsigned_convention_keeps_values() {
        // BZERO = 2^63: f64 arithmetic on the stored values would round them to multiples
        // of 2048.
        let values = [0i64, 1, 999, 65535];
        let stored: Vec<i64> = values.iter().map(|v| v ^ i64::MIN).collect();
        let extra = [card("BZERO", "9223372036854775808")];
        let f = decode(&image(64, &[4, 1], &extra, &be64(&stored)));
        assert_eq!(f.pixels, [0, 1, 999, 65535]);
        assert_eq!(f.saturation, 65535);
    }

    #[test]
    fn negative_bscale_is_honoured() {
        // Exact: 100 − stored.
        let extra = [card("BZERO", 100), card("BSCALE", -1)];
        let f = decode(&image(16, &[3, 1], &extra, &be16(&[0, 50, 100])));
        assert_eq!(f.pixels, [100, 50, 0]);
        // The largest physical value: stored −32768 → 32868.
        assert_eq!(f.saturation, 32868);
        // Stretched: physical 0, −20, −40.
        let extra = [card("BSCALE", -2)];
        let f = decode(&image(32, &[3, 1], &extra, &be32(&[0, 10, 20])));
        assert_eq!(f.pixels, [65535, 32768, 0]);
        let extra = [card("BSCALE", "-1.0")];
        let f = decode(&image(-32, &[3, 1], &extra, &bef32(&[1.0, 2.0, 3.0])));
        assert_eq!(f.pixels, [65535, 32768, 0]);
    }

    #[test]
    fn float32_with_bzero_bscale_is_stretched() {
        // Physical = 10 + 2 × stored: 10, 12, 14, 20.
        let extra = [card("BZERO", "1.0E1"), card("BSCALE", "2.0")];
        let f = decode(&image(-32, &[2, 2], &extra, &bef32(&[0.0, 1.0, 2.0, 5.0])));
        let k = 65535.0 / 10.0;
        let expect: Vec<u16> = [0.0, 2.0, 4.0, 10.0]
            .iter()
            .map(|v: &f64| (v * k).round() as u16)
            .collect();
        assert_eq!(f.pixels, expect);
        assert_eq!(f.saturation, 65535);
    }

    #[test]
    fn float64_values_are_stretched_even_when_huge() {
        let f = decode(&image(-64, &[3, 1], &[], &bef64(&[-1e300, 0.0, 1e300])));
        assert_eq!(f.pixels, [0, 32768, 65535]);
        let f = decode(&image(-64, &[3, 1], &[], &bef64(&[0.25, 0.5, 0.75])));
        assert_eq!(f.pixels, [0, 32768, 65535]);
    }

    #[test]
    fn float32_nan_and_inf_take_the_median() {
        let data = [0.0, f32::NAN, 10.0, 20.0, f32::INFINITY, 40.0];
        let f = decode(&image(-32, &[3, 2], &[], &bef32(&data)));
        // Valid 0, 10, 20, 40 → 0, 16384, 32768, 65535 (×65535/40); lower median 16384.
        let m = (10.0f64 * 65535.0 / 40.0).round() as u16;
        assert_eq!(f.pixels, [0, m, m, 32768, m, 65535]);
    }

    #[test]
    fn integer_blank_keyword_takes_the_median() {
        let extra = [card("BLANK", -32768)];
        let f = decode(&image(
            16,
            &[5, 1],
            &extra,
            &be16(&[3, -32768, 5, 9, -32768]),
        ));
        assert_eq!(f.pixels, [3, 5, 5, 9, 5]);
        assert_eq!(f.saturation, 32767);
        // BLANK compares stored values, before BZERO.
        let extra = [card("BZERO", 32768), card("BLANK", 0)];
        let f = decode(&image(16, &[3, 1], &extra, &be16(&[-32768, 0, -32767])));
        assert_eq!(f.pixels, [0, 0, 1]);
    }

    #[test]
    fn constant_image_maps_to_zero() {
        let f = decode(&image(-32, &[2, 2], &[], &bef32(&[-3.5; 4])));
        assert_eq!(f.pixels, [0; 4]);
    }

    #[test]
    fn all_blank_image_is_an_error() {
        let e = error(&image(-32, &[2, 1], &[], &bef32(&[f32::NAN; 2])));
        assert!(e.contains("every pixel"), "{e}");
    }

    #[test]
    fn rows_stay_in_stored_order() {
        // The first stored row (FITS y = 1) is row 0: no flip.
        let f = decode(&image(8, &[2, 3], &[], &[1, 2, 3, 4, 5, 6]));
        assert_eq!(f.pixels[..2], [1, 2]);
        assert_eq!(f.pixels[4..], [5, 6]);
    }

    #[test]
    fn naxis3_with_depth_1_is_accepted() {
        let f = decode(&image(8, &[2, 2, 1], &[], &[1, 2, 3, 4]));
        assert_eq!((f.width, f.height, f.pixels), (2, 2, vec![1, 2, 3, 4]));
    }

    #[test]
    fn cubes_and_lines_are_refused_with_their_shape() {
        let e = error(&image(8, &[4, 4, 3], &[], &[0; 48]));
        assert_eq!(
            e,
            "FITS primary HDU has NAXIS = 3 (4×4×3): gpustar needs a 2-D image"
        );
        let e = error(&image(8, &[10], &[], &[0; 10]));
        assert_eq!(
            e,
            "FITS primary HDU has NAXIS = 1 (10): gpustar needs a 2-D image"
        );
    }

    /// Primary HDU without data, then the given HDUs.
    fn multi(extensions: &[Vec<u8>], primary_extra: &[String]) -> Vec<u8> {
        let mut cards = axes_cards(card("SIMPLE", "T"), 8, &[]);
        cards.push(card("EXTEND", "T"));
        cards.extend_from_slice(primary_extra);
        let mut out = hdu(&cards, &[]);
        for e in extensions {
            out.extend_from_slice(e);
        }
        out
    }

    fn extension(kind: &str, bitpix: i64, dims: &[u64], extra: &[String], data: &[u8]) -> Vec<u8> {
        let mut cards = axes_cards(text_card("XTENSION", kind), bitpix, dims);
        cards.extend([card("PCOUNT", 0), card("GCOUNT", 1)]);
        cards.extend_from_slice(extra);
        hdu(&cards, data)
    }

    #[test]
    fn empty_primary_uses_the_first_image_extension() {
        let table = extension(
            "BINTABLE",
            8,
            &[4, 3],
            &[card("TFIELDS", 1), text_card("TFORM1", "J")],
            &[9; 12],
        );
        let img = extension("IMAGE", 16, &[2, 2], &[], &be16(&[1, 2, 3, 4]));
        let later = extension("IMAGE", 8, &[1, 1], &[], &[7]);
        let date = [text_card("DATE-OBS", "2000-01-01T12:00:00")];
        let f = decode(&multi(&[table, img, later], &date));
        assert_eq!((f.width, f.height, f.pixels), (2, 2, vec![1, 2, 3, 4]));
        // DATE-OBS from the primary header.
        assert_eq!(f.epoch, Some(2000.0));
    }

    #[test]
    fn empty_primary_without_an_image_is_an_error() {
        let e = error(&multi(&[], &[]));
        assert!(e.contains("no IMAGE extension"), "{e}");
        let table = extension("TABLE", 8, &[4, 1], &[card("TFIELDS", 0)], &[b' '; 4]);
        let e = error(&multi(&[table], &[]));
        assert!(e.contains("(only tables)"), "{e}");
        let empty = extension("IMAGE", 8, &[], &[], &[]);
        let e = error(&multi(&[empty], &[]));
        assert_eq!(
            e,
            "FITS extension 1 has NAXIS = 0 (no data): gpustar needs a 2-D image"
        );
    }

    #[test]
    fn tile_compressed_image_is_reported() {
        let extra = [
            card("TFIELDS", 1),
            text_card("TFORM1", "1PB(10)"),
            card("ZIMAGE", "T"),
            text_card("ZCMPTYPE", "RICE_1"),
        ];
        let e = error(&multi(
            &[extension("BINTABLE", 8, &[8, 1], &extra, &[0; 8])],
            &[],
        ));
        assert!(e.contains("compressed FITS is not supported"), "{e}");
    }

    #[test]
    fn epoch_from_date_obs_else_mjd_obs() {
        let extra = [
            text_card("DATE-OBS", "2019-07-29T20:47:26.5"),
            card("MJD-OBS", 1.0),
        ];
        let f = decode(&image(8, &[1, 1], &extra, &[0]));
        assert_eq!(f.epoch, julian_year("2019-07-29T20:47:26.5"));
        // MJD 51544.5 is J2000.0; an unreadable DATE-OBS falls back to it.
        let extra = [text_card("DATE-OBS", "01/01/00"), card("MJD-OBS", 51544.5)];
        let f = decode(&image(8, &[1, 1], &extra, &[0]));
        assert_eq!(f.epoch, Some(2000.0));
    }

    #[test]
    fn julian_year_of_j2000_is_exact() {
        assert_eq!(julian_year("2000-01-01T12:00:00"), Some(2000.0));
        assert_eq!(julian_year("2000-01-01T12:00:00.000Z"), Some(2000.0));
    }

    #[test]
    fn julian_year_matches_a_hand_computation() {
        // 2020-01-01 00:00 UT is JD 2458849.5; 2019-07-29 is 156 days before (3 days of July,
        // then 31 + 30 + 31 + 30 + 31); 20:47:26.5 is 74846.5 s into the day.
        let jd = 2_458_849.5 - 156.0 + 74_846.5 / 86_400.0;
        let expect = 2000.0 + (jd - 2_451_545.0) / 365.25;
        let got = julian_year("2019-07-29T20:47:26.5").unwrap();
        assert!((got - expect).abs() < 1e-9, "{got} vs {expect}");
        assert!((got - 2019.573898).abs() < 1e-6, "{got}");
        // Date only: 00:00 UT; a space works as the separator.
        let midnight = 2000.0 + (2_458_849.5 - 156.0 - 2_451_545.0) / 365.25;
        assert!((julian_year("2019-07-29").unwrap() - midnight).abs() < 1e-9);
        assert_eq!(julian_year("2019-07-29 20:47:26.5"), Some(got));
        // 29 February exists in 2000 and 2024, not in 1900.
        assert!(julian_year("2024-02-29").is_some());
        assert!(julian_year("2000-02-29").is_some());
    }

    #[test]
    fn julian_year_refuses_other_forms() {
        for s in [
            "29/07/19",
            "",
            "2019-13-01",
            "2019-02-29",
            "1900-02-29",
            "2019-04-31",
            "2019-7-29",
            "2019-07-29T",
            "2019-07-29T24:00:00",
            "2019-07-29T20:61:00",
            "2019-07-29T20:47:1e1",
            "2019-07-29T20:47:26.",
            "2019-07-29T20:47:26:01",
            "+2019-07-29",
        ] {
            assert_eq!(julian_year(s), None, "{s}");
        }
    }

    #[test]
    fn header_without_end_is_an_error() {
        let mut b = image(8, &[1, 1], &[], &[0]);
        let end = b.windows(3).position(|w| w == b"END").unwrap();
        b[end..end + 3].copy_from_slice(b"   ");
        let e = error(&b);
        assert!(e.contains("no END card"), "{e}");
        let e = error(b"SIMPLE  =                    T");
        assert!(e.contains("no END card"), "{e}");
    }

    #[test]
    fn bitpix_7_is_an_error() {
        let e = error(&image(7, &[1, 1], &[], &[0]));
        assert_eq!(
            e,
            "FITS primary HDU has BITPIX = 7; FITS allows only 8, 16, 32, 64, -32 and -64"
        );
    }

    #[test]
    fn naxis1_zero_is_an_error() {
        let e = error(&image(8, &[0, 5], &[], &[]));
        assert_eq!(e, "FITS primary HDU has an empty image (0×5 pixels)");
    }

    #[test]
    fn huge_axes_are_refused_before_allocating() {
        // The product overflows u64 (fitsrs itself would panic on it in debug builds).
        let e = error(&image(16, &[1 << 40, 1 << 40], &[], &[]));
        assert!(e.contains("too large to exist"), "{e}");
        // Large but representable: the pixel cap speaks before anything is read.
        let e = error(&image(16, &[100_000, 100_000], &[], &[]));
        assert_eq!(
            e,
            "the FITS image is 100000×100000 (10000000000 pixels), larger than gpustar reads \
             (1073741824 pixels at most)"
        );
        let e = format!(
            "{:#}",
            decode_fits(&image(8, &[4, 4], &[], &[0; 16]), 15).unwrap_err()
        );
        assert!(e.contains("16 pixels"), "{e}");
    }

    #[test]
    fn truncated_data_says_how_much() {
        let mut b = image(16, &[100, 100], &[], &[0; 20000]);
        b.truncate(BLOCK + 5000);
        assert_eq!(
            error(&b),
            "FITS data truncated: expected 20000 bytes, file holds 5000"
        );
        // Cut right after END, inside the header padding: no data at all.
        b.truncate(6 * CARD);
        assert_eq!(
            error(&b),
            "FITS data truncated: expected 20000 bytes, file holds 0"
        );
    }

    #[test]
    fn lone_quote_value_does_not_panic() {
        // fitsrs 0.4.1 panics on a value that is a single quote: the card is blanked.
        let extra = ["OBJECT  = '".to_string(), "CONTINUE  '".to_string()];
        let f = decode(&image(8, &[1, 1], &extra, &[42]));
        assert_eq!(f.pixels, [42]);
        // In an XTENSION card too.
        let mut b = multi(&[extension("IMAGE", 8, &[1, 1], &[], &[1])], &[]);
        b[BLOCK + 10..BLOCK + 30].copy_from_slice(b"'                   ");
        assert!(decode_fits(&b, 100).is_err());
    }

    #[test]
    fn fitsrs_sees_only_the_cards_the_scan_checked() {
        // Axes whose product overflows, where a scan reading other cards than fitsrs would
        // miss them: in a HIERARCH card, and before an indented END (fitsrs trims keywords).
        let big = 99_999_999_999u64;
        let hierarch = [
            format!("HIERARCH NAXIS1 = {big}"),
            format!("HIERARCH NAXIS2 = {big}"),
        ];
        let f = decode(&image(8, &[1, 1], &hierarch, &[3]));
        assert_eq!(f.pixels, [3]);
        let mut cards = axes_cards(card("SIMPLE", "T"), 8, &[big, big]);
        cards.extend(["  END".to_string(), card("NAXIS1", 1), card("NAXIS2", 1)]);
        let e = error(&hdu(&cards, &[0]));
        assert!(e.contains("too large to exist"), "{e}");
    }

    #[test]
    fn not_fits_inputs_are_errors() {
        assert!(error(&[]).contains("empty"));
        assert!(error(&[0x1f, 0x8b, 8, 0]).contains("gunzip"));
        assert!(error(b"\x89PNG\r\n\x1a\n").contains("not a FITS file"));
    }

    /// xorshift64*: deterministic bytes without a dependency.
    fn noise(seed: u64) -> impl FnMut() -> u64 {
        let mut x = seed | 1;
        move || {
            x ^= x >> 12;
            x ^= x << 25;
            x ^= x >> 27;
            x.wrapping_mul(0x2545_f491_4f6c_dd1d)
        }
    }

    #[test]
    fn garbage_never_panics() {
        let mut rng = noise(7);
        for len in [1, 79, 80, 2880, 5760, 10_000] {
            let mut b: Vec<u8> = (0..len).map(|_| rng() as u8).collect();
            assert!(decode_fits(&b, 1 << 24).is_err());
            // With a valid first card the header scan and fitsrs get to work.
            let head = card("SIMPLE", "T");
            let n = head.len().min(b.len());
            b[..n].copy_from_slice(&head.as_bytes()[..n]);
            let _ = decode_fits(&b, 1 << 24);
        }
        // Valid files with bytes changed to characters that matter in headers.
        let files = [
            image(
                16,
                &[4, 3],
                &[card("BZERO", 32768), text_card("DATE-OBS", "2019-07-29")],
                &be16(&[5; 12]),
            ),
            multi(
                &[extension(
                    "IMAGE",
                    -32,
                    &[2, 2],
                    &[card("BLANK", 3)],
                    &bef32(&[1.0; 4]),
                )],
                &[],
            ),
        ];
        let alphabet = b"' =/T0123456789-+.ENDXAIBLK\x00\xff";
        for file in &files {
            for _ in 0..3000 {
                let mut b = file.clone();
                for _ in 0..1 + rng() % 4 {
                    let at = (rng() as usize) % (2 * BLOCK).min(b.len());
                    b[at] = alphabet[(rng() as usize) % alphabet.len()];
                }
                if rng().is_multiple_of(8) {
                    b.truncate((rng() as usize) % b.len());
                }
                let _ = decode_fits(&b, 1 << 24);
            }
        }
    }

    #[test]
    fn fits_extensions() {
        for e in ["fits", "fit", "fts"] {
            assert!(is_fits_extension(e));
        }
        for e in ["fz", "gz", "png", "FITS", ""] {
            assert!(!is_fits_extension(e));
        }
    }
}
