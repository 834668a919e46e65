//! A FITS frame copied with a new header (`--new-fits`): the image's HDU as it is stored, its
//! header cards and its data, whatever form the file has (plain, gzipped, tile-compressed).

use super::cards::{BLOCK, CARD, card_end, card_raw};
use super::scan::{find_image_extension, scan_header};
use crate::error::{Context, Result, error, fail};
use std::io::Read;
use std::path::Path;

/// The image of a FITS file as stored: the primary header's cards, the image extension's when
/// the image is in one, and the image's data bytes (all its planes).
pub struct StoredImage {
    pub primary: Vec<String>,
    pub extension: Option<Vec<String>>,
    pub data: Vec<u8>,
}

/// Read `path` (FITS, `.fits.gz` or tile-compressed) into its [`StoredImage`]: up to 2 GiB.
pub fn stored_image(path: &Path) -> Result<StoredImage> {
    const MAX: u64 = 2 << 30;
    let shown = path.display();
    let file = std::fs::File::open(path).with_context(|| format!("cannot open {shown}"))?;
    let mut bytes = Vec::new();
    let gz = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    let read = if gz {
        flate2::read::MultiGzDecoder::new(std::io::BufReader::new(file))
            .take(MAX)
            .read_to_end(&mut bytes)
    } else {
        file.take(MAX).read_to_end(&mut bytes)
    };
    read.with_context(|| format!("cannot read {shown}"))?;
    if let Some((plain, _)) = super::expand_tiled(&bytes, u64::MAX)? {
        bytes = plain;
    }
    parts(&bytes).with_context(|| format!("cannot copy {shown}"))
}

fn parts(bytes: &[u8]) -> Result<StoredImage> {
    if !bytes.starts_with(b"SIMPLE  =") {
        fail!(Input, "not a FITS file");
    }
    let primary = scan_header(bytes, 0, "FITS primary HDU".to_string())?;
    let image = if primary.naxis.is_empty() {
        Some(find_image_extension(bytes, &primary)?)
    } else {
        None
    };
    let cards = |start: usize, end: usize| -> Vec<String> {
        bytes[start..end]
            .chunks_exact(CARD)
            .map(|c| String::from_utf8_lossy(c).into_owned())
            .take_while(|c| c.trim_end() != "END")
            .collect()
    };
    let data_of = |s: &super::scan::Scan| -> Result<Vec<u8>> {
        let len = usize::try_from(s.data_len).map_err(|_| error!(Input, "data too large"))?;
        bytes
            .get(s.data_start..s.data_start + len)
            .map(<[u8]>::to_vec)
            .ok_or_else(|| error!(Input, "{}: the data are truncated", s.what))
    };
    Ok(match image {
        None => StoredImage {
            primary: cards(0, primary.data_start),
            extension: None,
            data: data_of(&primary)?,
        },
        Some(ext) => StoredImage {
            primary: cards(0, primary.data_start),
            extension: Some(cards(ext.start, ext.data_start)),
            data: data_of(&ext)?,
        },
    })
}

/// Keywords of a celestial WCS (and the distortions that go with one): a frame's old solution,
/// which a new one replaces.
pub fn is_wcs_keyword(key: &str) -> bool {
    const EXACT: &[&str] = &[
        "WCSAXES", "WCSNAME", "RADESYS", "RADECSYS", "EQUINOX", "LONPOLE", "LATPOLE", "A_ORDER",
        "B_ORDER", "AP_ORDER", "BP_ORDER", "A_DMAX", "B_DMAX", "CROTA1", "CROTA2",
    ];
    const PREFIX: &[&str] = &[
        "CTYPE", "CUNIT", "CRVAL", "CRPIX", "CDELT", "CD1_", "CD2_", "PC1_", "PC2_", "PV1_",
        "PV2_", "A_", "B_", "AP_", "BP_",
    ];
    EXACT.contains(&key) || PREFIX.iter().any(|p| key.starts_with(p))
}

/// One FITS file of the stored image with `wcs` (cards without the structural ones) in place of
/// the header's own WCS: the image's own header (made primary), the primary header's other
/// cards when the image was an extension, then `wcs`; the data unchanged.
pub fn with_header(image: &StoredImage, wcs: &[String]) -> Vec<u8> {
    let key = |c: &str| c.get(..8).unwrap_or(c).trim_end().to_string();
    let structural = |k: &str| {
        matches!(
            k,
            "SIMPLE" | "XTENSION" | "BITPIX" | "EXTEND" | "PCOUNT" | "GCOUNT" | "EXTNAME"
        ) || k.starts_with("NAXIS")
    };
    let own = image.extension.as_ref().unwrap_or(&image.primary);
    let mut out: Vec<String> = Vec::new();
    out.push(card_raw("SIMPLE", "T", "conforms to FITS standard"));
    // BITPIX and the axes, in the image header's order.
    out.extend(
        own.iter()
            .filter(|c| {
                let k = key(c);
                k == "BITPIX" || k.starts_with("NAXIS")
            })
            .cloned(),
    );
    let mut seen = std::collections::HashSet::new();
    let primary_too = image.extension.is_some().then_some(&image.primary);
    for c in own.iter().chain(primary_too.into_iter().flatten()) {
        let k = key(c);
        if structural(&k) || is_wcs_keyword(&k) || k == "END" {
            continue;
        }
        // A keyword in both headers: the image's own wins (COMMENT and HISTORY are all kept).
        let repeatable = k.is_empty() || k == "COMMENT" || k == "HISTORY";
        if repeatable || seen.insert(k) {
            out.push(c.clone());
        }
    }
    out.extend(wcs.iter().cloned());
    out.push(card_end());
    let mut bytes: Vec<u8> = out
        .iter()
        .flat_map(|c| format!("{c:<80.80}").into_bytes())
        .collect();
    bytes.resize(bytes.len().next_multiple_of(BLOCK), b' ');
    bytes.extend_from_slice(&image.data);
    bytes.resize(bytes.len().next_multiple_of(BLOCK), 0);
    bytes
}
