//! The safety scan of FITS headers, and the headers fitsrs then parses.

use super::cards::{BLOCK, CARD};
use crate::error::{Result, error, fail};
use fitsrs::hdu::header::Header;
use fitsrs::hdu::header::extension::image::Image;
use fitsrs::{Fits, HDU};
use std::collections::BTreeMap;
use std::io::Cursor;

/// What the safety scan reads from one header, before fitsrs sees it.
#[derive(Debug)]
pub(crate) struct Scan {
    /// "FITS primary HDU" or "FITS extension N", for messages.
    pub(crate) what: String,
    /// Where the header starts, and where its data start (past its last 2880-byte block).
    pub(crate) start: usize,
    pub(crate) data_start: usize,
    pub(crate) bitpix: i64,
    pub(crate) bytes_per_value: u64,
    pub(crate) naxis: Vec<u64>,
    /// Size of the data unit: |BITPIX|/8 × GCOUNT × (PCOUNT + NAXIS1 × … × NAXISn).
    pub(crate) data_len: u64,
    /// The XTENSION value (None in the primary header).
    pub(crate) xtension: Option<String>,
    /// ZIMAGE = T: a tile-compressed image stored in a binary table.
    pub(crate) zimage: bool,
}

impl Scan {
    /// Where the next HDU starts: data are padded to whole blocks.
    pub(crate) fn next_start(&self, file_len: usize) -> Result<usize> {
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
pub(crate) fn scan_header(bytes: &[u8], start: usize, what: String) -> Result<Scan> {
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
pub(crate) fn value_field(field: &[u8]) -> String {
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

pub(crate) fn ascii(key: &[u8]) -> String {
    String::from_utf8_lossy(key).into_owned()
}

/// With an empty primary HDU, the first IMAGE extension or tile-compressed image; other
/// tables before it are skipped.
pub(crate) fn find_image_extension(bytes: &[u8], primary: &Scan) -> Result<Scan> {
    let mut pos = primary.next_start(bytes.len())?;
    let mut index = 0;
    // Each HDU takes at least one block, so this ends.
    while pos < bytes.len() {
        index += 1;
        let scan = scan_header(bytes, pos, format!("FITS extension {index}"))?;
        match scan.xtension.as_deref() {
            // A tile-compressed image (fpack) is an image too: `tiled` expands it.
            Some("IMAGE" | "IUEIMAGE") => return Ok(scan),
            Some("BINTABLE") if scan.zimage => return Ok(scan),
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
pub(crate) fn parse_headers(
    bytes: &[u8],
    primary: &Scan,
    ext: Option<&Scan>,
) -> Result<Vec<Header<Image>>> {
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
