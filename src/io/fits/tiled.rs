//! Tile-compressed images (FITS 4.0 §10, the tiled image convention; fpack's `.fz`, and what
//! astropy's `CompImageHDU` writes): expanded in memory into the plain FITS file funpack would
//! write, which the ordinary reader then decodes. So a frame read from `x.fits.fz` gives the
//! same pixels, keywords and record as `x.fits` (exactly, for integer data and lossless floats).
//!
//! Read: RICE_1, GZIP_1 and GZIP_2, of integer images and of floating-point images, quantized
//! (NO_DITHER, SUBTRACTIVE_DITHER_1 and _2, as CFITSIO restores them) or lossless. Not read:
//! HCOMPRESS_1 and PLIO_1 (an error says so). Of a cube, the first plane is read, as for plain
//! FITS cubes.
//!
//! Written here rather than taken from fitsrs (which gpustar uses for headers): fitsrs 0.4.1's
//! tile decompression, tried on astropy-written files, dropped a row of 16-bit RICE images,
//! misplaced square tiles, failed on GZIP and panicked on 64-bit floats.

use super::bintable::{Cards, Column, columns};
use super::cards::BLOCK;
use super::rice::rice;
use super::scan::Scan;
use crate::error::{Result, error, fail};
use std::io::Read;

/// The plain FITS file (primary header as it is, then an IMAGE extension) holding the image a
/// tile-compressed HDU `table` of `bytes` stores (its first plane), of at most `max_pixels`.
/// The primary header is copied as it is.
pub(crate) fn expand(
    bytes: &[u8],
    primary: &Scan,
    table: &Scan,
    max_pixels: u64,
) -> Result<(Vec<u8>, Option<String>)> {
    let what = &table.what;
    let cards = Cards::read(bytes, table);
    let z = Compressed::from_cards(&cards, what, max_pixels)?;
    let layout = Columns::read(&cards, table, what)?;
    let (w, h) = (z.naxes[0], z.naxes[1]);

    let width = z.out_bytes();
    let mut image = vec![0u8; w * h * width];
    let (tw, th) = (z.tile[0], z.tile[1]);
    let tiles_x = w.div_ceil(tw);
    let rows_needed = tiles_x * h.div_ceil(th);
    if (table.naxis[1] as usize) < rows_needed {
        fail!(
            Input,
            "{what}: the table holds {} tiles, the image needs {rows_needed}",
            table.naxis[1]
        );
    }
    let data = &bytes[table.data_start..];
    for row in 0..rows_needed {
        let (tx, ty) = (row % tiles_x, row / tiles_x);
        let (x0, y0) = (tx * tw, ty * th);
        let (cw, ch) = (tw.min(w - x0), th.min(h - y0));
        let values = layout.tile(data, row, cw * ch, &z, what)?;
        for r in 0..ch {
            let at = ((y0 + r) * w + x0) * width;
            let from = r * cw * width;
            image[at..at + cw * width].copy_from_slice(&values[from..from + cw * width]);
        }
    }

    let mut out = bytes[primary.start..primary.data_start].to_vec();
    let mut header = vec![
        super::card_str("XTENSION", "IMAGE", "Image extension (expanded by gpustar)"),
        super::card_raw("BITPIX", &z.out_bitpix().to_string(), ""),
        super::card_raw("NAXIS", "2", ""),
        super::card_raw("NAXIS1", &w.to_string(), ""),
        super::card_raw("NAXIS2", &h.to_string(), ""),
        super::card_raw("PCOUNT", "0", ""),
        super::card_raw("GCOUNT", "1", ""),
    ];
    for (key, card) in &cards.list {
        if !is_compression_keyword(key) {
            header.push(String::from_utf8_lossy(card).into_owned());
        }
    }
    header.push(super::card_end());
    let text: String = header.concat();
    out.extend_from_slice(text.as_bytes());
    out.resize(out.len().next_multiple_of(BLOCK), b' ');
    out.extend_from_slice(&image);
    out.resize(out.len().next_multiple_of(BLOCK), 0);
    let note = (z.naxes.len() > 2 && z.naxes[2..].iter().any(|&n| n > 1))
        .then(|| format!("{what} is a cube ({:?}): its first plane was read", z.naxes));
    Ok((out, note))
}

/// Keywords of the table that describe the compression, not the image: left out of the
/// expanded header (FITS 4.0 §10.1, and the checksums, which no longer hold).
fn is_compression_keyword(key: &str) -> bool {
    const EXACT: &[&str] = &[
        "XTENSION", "BITPIX", "NAXIS", "NAXIS1", "NAXIS2", "PCOUNT", "GCOUNT", "TFIELDS", "THEAP",
        "ZIMAGE", "ZCMPTYPE", "ZBITPIX", "ZNAXIS", "ZQUANTIZ", "ZDITHER0", "ZSIMPLE", "ZEXTEND",
        "ZBLOCKED", "ZTENSION", "ZPCOUNT", "ZGCOUNT", "ZHECKSUM", "ZDATASUM", "CHECKSUM",
        "DATASUM", "ZBLANK", "ZSCALE", "ZZERO",
    ];
    const NUMBERED: &[&str] = &[
        "ZNAXIS", "ZTILE", "ZNAME", "ZVAL", "TTYPE", "TFORM", "TUNIT", "TSCAL", "TZERO", "TNULL",
        "TDIM", "TDISP",
    ];
    EXACT.contains(&key)
        || NUMBERED.iter().any(|p| {
            key.strip_prefix(p)
                .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
        })
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Method {
    Rice { block: usize, bytepix: usize },
    Gzip { shuffled: bool },
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Dither {
    None,
    Subtractive1,
    Subtractive2,
}

/// What the table's keywords say of the image and its compression.
struct Compressed {
    bitpix: i64,
    naxes: Vec<usize>,
    tile: Vec<usize>,
    method: Method,
    /// Float data stored as scaled integers (None: lossless).
    quantized: Option<Quantized>,
    /// Integer values that stand for a missing pixel, when ZBLANK is a keyword.
    zblank: Option<i64>,
}

#[derive(Clone, Copy)]
struct Quantized {
    dither: Dither,
    seed: i64,
    /// ZSCALE and ZZERO when they are keywords rather than columns.
    scale: Option<f64>,
    zero: Option<f64>,
}

impl Compressed {
    fn from_cards(cards: &Cards, what: &str, max_pixels: u64) -> Result<Compressed> {
        let need = |key: &str| -> Result<i64> {
            cards
                .int(key, what)?
                .ok_or_else(|| error!(Input, "{what}: the compressed image lacks {key}"))
        };
        let bitpix = need("ZBITPIX")?;
        if ![8, 16, 32, 64, -32, -64].contains(&bitpix) {
            fail!(Input, "{what}: ZBITPIX = {bitpix} is not a FITS BITPIX");
        }
        let naxis = need("ZNAXIS")?;
        if !(2..=999).contains(&naxis) {
            fail!(
                Input,
                "{what} has ZNAXIS = {naxis}: gpustar needs a 2-D image"
            );
        }
        let mut naxes = Vec::new();
        let mut tile = Vec::new();
        for n in 1..=naxis {
            let size = need(&format!("ZNAXIS{n}"))?;
            let t = cards
                .int(&format!("ZTILE{n}"), what)?
                .unwrap_or(if n == 1 { size } else { 1 });
            if size < 1 || t < 1 || size > u32::MAX as i64 {
                fail!(Input, "{what}: ZNAXIS{n} = {size}, ZTILE{n} = {t}");
            }
            naxes.push(size as usize);
            tile.push(t.min(size) as usize);
        }
        let pixels = naxes[0] as u64 * naxes[1] as u64;
        if pixels > max_pixels {
            fail!(
                Input,
                "the FITS image is {}×{} ({pixels} pixels), larger than gpustar reads \
                 ({max_pixels} pixels at most)",
                naxes[0],
                naxes[1]
            );
        }
        if tile[2..].iter().any(|&t| t != 1) {
            fail!(
                Input,
                "{what}: tiles span several planes of the cube (ZTILE3 > 1); decompress it first"
            );
        }
        let name = cards.text("ZCMPTYPE").unwrap_or_default();
        // Parameters are ZNAMEi/ZVALi pairs.
        let param = |wanted: &str| -> Result<Option<i64>> {
            for i in 1..=999 {
                match cards.text(&format!("ZNAME{i}")) {
                    None => return Ok(None),
                    Some(n) if n.eq_ignore_ascii_case(wanted) => {
                        return cards.int(&format!("ZVAL{i}"), what);
                    }
                    Some(_) => {}
                }
            }
            Ok(None)
        };
        let method = match name.as_str() {
            "RICE_1" | "RICE_ONE" => {
                let block = param("BLOCKSIZE")?.unwrap_or(32);
                let bytepix = param("BYTEPIX")?.unwrap_or(4);
                if !(1..=4096).contains(&block) || ![1, 2, 4].contains(&bytepix) {
                    fail!(
                        Input,
                        "{what}: RICE_1 with BLOCKSIZE = {block}, BYTEPIX = {bytepix}"
                    );
                }
                Method::Rice {
                    block: block as usize,
                    bytepix: bytepix as usize,
                }
            }
            "GZIP_1" => Method::Gzip { shuffled: false },
            "GZIP_2" => Method::Gzip { shuffled: true },
            other => fail!(
                Input,
                "{what} is compressed with {other:?}, which gpustar does not read (RICE_1, GZIP_1 \
                 and GZIP_2 are read); decompress it first (e.g. funpack)"
            ),
        };
        let quantize = cards.text("ZQUANTIZ");
        let has_scale = cards
            .list
            .iter()
            .any(|(k, _)| k.starts_with("TTYPE") && cards.text(k).as_deref() == Some("ZSCALE"))
            || cards.values.contains_key("ZSCALE");
        let quantized = (bitpix < 0 && has_scale && quantize.as_deref() != Some("NONE"))
            .then(|| -> Result<Quantized> {
                Ok(Quantized {
                    dither: match quantize.as_deref() {
                        None | Some("NO_DITHER") => Dither::None,
                        Some("SUBTRACTIVE_DITHER_1") => Dither::Subtractive1,
                        Some("SUBTRACTIVE_DITHER_2") => Dither::Subtractive2,
                        Some(q) => fail!(Input, "{what}: ZQUANTIZ = {q:?} is not known"),
                    },
                    seed: cards.int("ZDITHER0", what)?.unwrap_or(1),
                    scale: cards.real("ZSCALE", what)?,
                    zero: cards.real("ZZERO", what)?,
                })
            })
            .transpose()?;
        if let (Some(_), Method::Rice { bytepix, .. }) = (quantized, method)
            && bytepix != 4
        {
            fail!(Input, "{what}: quantized floats with BYTEPIX = {bytepix}");
        }
        Ok(Compressed {
            bitpix,
            naxes,
            tile,
            method,
            quantized,
            zblank: cards.int("ZBLANK", what)?,
        })
    }

    /// BITPIX of the expanded image, and its bytes per value.
    fn out_bitpix(&self) -> i64 {
        self.bitpix
    }

    fn out_bytes(&self) -> usize {
        self.bitpix.unsigned_abs() as usize / 8
    }

    /// Bytes per value of a compressed tile's integers: the image's own for integer data,
    /// 4 for quantized floats.
    fn stored_bytes(&self) -> usize {
        match (self.quantized, self.method) {
            (_, Method::Rice { bytepix, .. }) => bytepix,
            (Some(_), _) => 4,
            (None, _) => self.out_bytes(),
        }
    }
}

/// The columns of the compressed table that hold a tile's data and parameters.
struct Columns {
    row_bytes: usize,
    rows: usize,
    heap: usize,
    data_len: usize,
    compressed: Column,
    gzip: Option<Column>,
    scale: Option<Column>,
    zero: Option<Column>,
    blank: Option<Column>,
}

impl Columns {
    fn read(cards: &Cards, table: &Scan, what: &str) -> Result<Columns> {
        let found = columns(cards, table, what)?;
        let row_bytes = table.naxis[0] as usize;
        let rows = table.naxis[1] as usize;
        let main = row_bytes * rows;
        let heap = cards.int("THEAP", what)?.unwrap_or(main as i64);
        let data_len = table.data_len as usize;
        if heap < main as i64 || heap as usize > data_len {
            fail!(Input, "{what}: THEAP = {heap} is outside the data");
        }
        let descriptor = |c: Option<&Column>| c.filter(|c| matches!(c.kind, b'P' | b'Q')).copied();
        let compressed = descriptor(found.get("COMPRESSED_DATA")).ok_or_else(|| {
            error!(
                Input,
                "{what}: a compressed image without a COMPRESSED_DATA array column"
            )
        })?;
        let scalar =
            |name: &str, kind: &[u8]| found.get(name).filter(|c| kind.contains(&c.kind)).copied();
        Ok(Columns {
            row_bytes,
            rows,
            heap: heap as usize,
            data_len,
            compressed,
            gzip: descriptor(found.get("GZIP_COMPRESSED_DATA")),
            scale: scalar("ZSCALE", b"D"),
            zero: scalar("ZZERO", b"D"),
            blank: scalar("ZBLANK", b"J"),
        })
    }

    /// The bytes of row `row`'s field `c` (a scalar's value).
    fn field<'d>(&self, data: &'d [u8], row: usize, c: Column, what: &str) -> Result<&'d [u8]> {
        let at = row * self.row_bytes + c.offset;
        let len = match c.kind {
            b'P' => 8,
            b'Q' => 16,
            _ => c.element,
        };
        data.get(at..at + len)
            .ok_or_else(|| error!(Input, "{what}: the table data are truncated"))
    }

    /// The bytes of the heap array a descriptor field points to.
    fn array<'d>(&self, data: &'d [u8], row: usize, c: Column, what: &str) -> Result<&'d [u8]> {
        let f = self.field(data, row, c, what)?;
        let (n, off) = if c.kind == b'P' {
            let n = i32::from_be_bytes(f[..4].try_into().unwrap_or_default());
            let o = i32::from_be_bytes(f[4..8].try_into().unwrap_or_default());
            (n as i64, o as i64)
        } else {
            let n = i64::from_be_bytes(f[..8].try_into().unwrap_or_default());
            let o = i64::from_be_bytes(f[8..16].try_into().unwrap_or_default());
            (n, o)
        };
        let bad = || error!(Input, "{what}: tile {} points outside the heap", row + 1);
        let len = usize::try_from(n)
            .ok()
            .and_then(|n| n.checked_mul(c.element))
            .ok_or_else(bad)?;
        let start = usize::try_from(off)
            .ok()
            .and_then(|o| o.checked_add(self.heap))
            .ok_or_else(bad)?;
        let end = start.checked_add(len).ok_or_else(bad)?;
        if end > self.data_len {
            return Err(bad());
        }
        data.get(start..end).ok_or_else(bad)
    }

    fn real(&self, data: &[u8], row: usize, c: Option<Column>, what: &str) -> Result<Option<f64>> {
        c.map(|c| {
            let f = self.field(data, row, c, what)?;
            Ok(f64::from_be_bytes(f.try_into().unwrap_or_default()))
        })
        .transpose()
    }

    /// Tile `row` (0-based) of `n` pixels, as big-endian values of the image's BITPIX.
    fn tile(
        &self,
        data: &[u8],
        row: usize,
        n: usize,
        z: &Compressed,
        what: &str,
    ) -> Result<Vec<u8>> {
        if row >= self.rows {
            fail!(Input, "{what}: tile {} is missing", row + 1);
        }
        let packed = self.array(data, row, self.compressed, what)?;
        let tile_what = || format!("{what}, tile {}", row + 1);
        if packed.is_empty() {
            // A float tile that could not be quantized is stored losslessly, gzipped.
            if let Some(g) = self.gzip {
                let raw = self.array(data, row, g, what)?;
                return inflate(raw, n * z.out_bytes(), &tile_what());
            }
            fail!(Input, "{}: no data", tile_what());
        }
        let stored = z.stored_bytes();
        let ints: Vec<i64> = match z.method {
            Method::Rice { block, bytepix } => rice(packed, n, bytepix, block)
                .ok_or_else(|| error!(Input, "{}: the RICE data are corrupt", tile_what()))?,
            Method::Gzip { shuffled } => {
                let mut raw = inflate(packed, n * stored, &tile_what())?;
                if shuffled {
                    raw = unshuffle(&raw, stored);
                }
                if z.quantized.is_none() {
                    // Integer or lossless float data: already the image's bytes.
                    return Ok(raw);
                }
                raw.chunks_exact(4)
                    .map(|b| i32::from_be_bytes([b[0], b[1], b[2], b[3]]) as i64)
                    .collect()
            }
        };
        let Some(q) = z.quantized else {
            return Ok(ints_to_bytes(&ints, z.bitpix));
        };
        let scale = self
            .real(data, row, self.scale, what)?
            .or(q.scale)
            .ok_or_else(|| error!(Input, "{what}: quantized floats without ZSCALE"))?;
        let zero = self
            .real(data, row, self.zero, what)?
            .or(q.zero)
            .unwrap_or(0.0);
        let blank = match self.blank {
            Some(c) => {
                let f = self.field(data, row, c, what)?;
                Some(i32::from_be_bytes(f.try_into().unwrap_or_default()) as i64)
            }
            None => z.zblank,
        };
        let values = unquantize(&ints, row, scale, zero, blank, q);
        Ok(if z.bitpix == -32 {
            values
                .iter()
                .flat_map(|&v| (v as f32).to_be_bytes())
                .collect()
        } else {
            values.iter().flat_map(|&v| v.to_be_bytes()).collect()
        })
    }
}

/// Inflate a zlib or gzip stream into exactly `len` bytes.
fn inflate(packed: &[u8], len: usize, what: &str) -> Result<Vec<u8>> {
    let mut out = Vec::with_capacity(len);
    let read = if packed.starts_with(&[0x1f, 0x8b]) {
        flate2::read::GzDecoder::new(packed)
            .take(len as u64)
            .read_to_end(&mut out)
    } else {
        flate2::read::ZlibDecoder::new(packed)
            .take(len as u64)
            .read_to_end(&mut out)
    };
    match read {
        Ok(_) if out.len() == len => Ok(out),
        Ok(_) => fail!(
            Input,
            "{what}: the GZIP data hold {} bytes, the tile {len}",
            out.len()
        ),
        Err(e) => fail!(Input, "{what}: the GZIP data are corrupt ({e})"),
    }
}

/// Undo GZIP_2's shuffle: the values' first bytes, then their second bytes, and so on.
fn unshuffle(raw: &[u8], width: usize) -> Vec<u8> {
    let n = raw.len() / width;
    let mut out = vec![0u8; raw.len()];
    for b in 0..width {
        for i in 0..n {
            out[i * width + b] = raw[b * n + i];
        }
    }
    out
}

fn ints_to_bytes(values: &[i64], bitpix: i64) -> Vec<u8> {
    match bitpix {
        8 => values.iter().map(|&v| v as u8).collect(),
        16 => values
            .iter()
            .flat_map(|&v| (v as i16).to_be_bytes())
            .collect(),
        32 => values
            .iter()
            .flat_map(|&v| (v as i32).to_be_bytes())
            .collect(),
        _ => values.iter().flat_map(|&v| v.to_be_bytes()).collect(),
    }
}

/// CFITSIO's table of 10000 pseudo-random numbers (Park and Miller's minimal standard
/// generator), stored as f32 as CFITSIO does, on which the dithering of quantized floats rests.
fn random_table() -> &'static [f32; RANDOMS] {
    static TABLE: std::sync::OnceLock<[f32; RANDOMS]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let (a, m) = (16807.0f64, 2147483647.0f64);
        let mut seed = 1.0f64;
        let mut t = [0f32; RANDOMS];
        for v in t.iter_mut() {
            let temp = a * seed;
            seed = temp - m * (temp / m).trunc();
            *v = (seed / m) as f32;
        }
        t
    })
}

const RANDOMS: usize = 10000;
/// SUBTRACTIVE_DITHER_2 stores exact zeros as this value.
const ZERO_VALUE: i64 = -2147483646;

/// Quantized integers back to floats, as CFITSIO's unquantize does (tile `row`, 0-based).
fn unquantize(
    ints: &[i64],
    row: usize,
    scale: f64,
    zero: f64,
    blank: Option<i64>,
    q: Quantized,
) -> Vec<f64> {
    let table = random_table();
    let mut seed = (row as i64 + q.seed - 1).rem_euclid(RANDOMS as i64) as usize;
    let mut next = (table[seed] as f64 * 500.0) as usize;
    ints.iter()
        .map(|&i| {
            let v = if Some(i) == blank {
                f64::NAN
            } else if q.dither == Dither::Subtractive2 && i == ZERO_VALUE {
                0.0
            } else if q.dither == Dither::None {
                i as f64 * scale + zero
            } else {
                (i as f64 - table[next] as f64 + 0.5) * scale + zero
            };
            if q.dither != Dither::None {
                next += 1;
                if next == RANDOMS {
                    seed = (seed + 1) % RANDOMS;
                    next = (table[seed] as f64 * 500.0) as usize;
                }
            }
            v
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_random_table_is_cfitsio_s() {
        // CFITSIO checks its own table by the seed it reaches: 1043618065 after 10000 draws,
        // i.e. the last value 1043618065 / (2^31 - 1).
        let t = random_table();
        assert_eq!(t[RANDOMS - 1], (1043618065.0f64 / 2147483647.0) as f32);
        assert_eq!(t[0], (16807.0f64 / 2147483647.0) as f32);
    }

    #[test]
    fn unshuffle_undoes_gzip_2() {
        assert_eq!(unshuffle(&[1, 3, 2, 4], 2), vec![1, 2, 3, 4]);
    }

    #[test]
    fn compression_keywords_are_told_from_the_image_s() {
        for k in [
            "ZTILE1", "TFORM2", "ZNAXIS", "ZCMPTYPE", "ZQUANTIZ", "TTYPE10",
        ] {
            assert!(is_compression_keyword(k), "{k}");
        }
        for k in ["BZERO", "BSCALE", "DATE-OBS", "ZTILE", "EXPTIME", "BLANK"] {
            assert!(!is_compression_keyword(k), "{k}");
        }
    }
}
