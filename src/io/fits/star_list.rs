//! Star lists given instead of images (`--xyls`): FITS tables of detections, as solve-field
//! takes them (`.xyls`, `.axy`, and what `--axy` writes): the first binary table holding `X`
//! and `Y` columns (any case), with `FLUX` when it has one (else the rows are taken as sorted
//! brightest first, as solve-field takes them), and the image size from `IMAGEW`/`IMAGEH` in
//! its header or the primary header.
//!
//! Pixels are FITS pixels, 1-based as astrometry.net writes them: gpustar's x = X − 1.

use super::CARD;
use super::scan::{Scan, ascii, scan_header, value_field};
use crate::error::{Context, Result, error, fail};
use std::path::Path;

/// A star list: positions (gpustar's 0-based pixels) and fluxes, brightest first or as the
/// file orders them, and the image's size when the file states it.
#[derive(Debug, PartialEq)]
pub struct StarList {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    /// None: the file has no FLUX column.
    pub flux: Option<Vec<f64>>,
    pub size: Option<(u32, u32)>,
}

/// The most rows read: more stars than any frame holds.
const MAX_ROWS: u64 = 10_000_000;

/// Read a star list file.
pub fn read_star_list(path: &Path) -> Result<StarList> {
    let shown = path.display();
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {shown}"))?;
    parse(&bytes).with_context(|| format!("cannot read the star list {shown}"))
}

fn parse(bytes: &[u8]) -> Result<StarList> {
    if !bytes.starts_with(b"SIMPLE  =") {
        fail!(
            Input,
            "not a FITS file (a star list is a FITS table with X and Y columns, as solve-field's \
             .xyls)"
        );
    }
    let primary = scan_header(bytes, 0, "FITS primary HDU".to_string())?;
    let mut size = image_size(bytes, &primary);
    let mut pos = primary.next_start(bytes.len())?;
    let mut index = 0;
    while pos < bytes.len() {
        index += 1;
        let scan = scan_header(bytes, pos, format!("FITS extension {index}"))?;
        if scan.xtension.as_deref() == Some("BINTABLE") && !scan.zimage {
            let cols = columns(bytes, &scan)?;
            let find = |name: &str| cols.iter().find(|c| c.name.eq_ignore_ascii_case(name));
            if let (Some(x), Some(y)) = (find("X"), find("Y")) {
                size = image_size(bytes, &scan).or(size);
                let rows = scan.naxis[1];
                if rows > MAX_ROWS {
                    fail!(
                        Input,
                        "{}: {rows} rows, more than any frame's stars",
                        scan.what
                    );
                }
                let data = bytes
                    .get(scan.data_start..scan.data_start + (scan.naxis[0] * rows) as usize)
                    .ok_or_else(|| error!(Input, "{}: the table is truncated", scan.what))?;
                let row_bytes = scan.naxis[0] as usize;
                let read = |c: &TableColumn| -> Vec<f64> {
                    data.chunks_exact(row_bytes.max(1))
                        .map(|row| c.value(row))
                        .collect()
                };
                let (x, y) = (read(x), read(y));
                if let Some(i) = (0..x.len()).find(|&i| !(x[i].is_finite() && y[i].is_finite())) {
                    fail!(Input, "{}: star {} has no finite X, Y", scan.what, i + 1);
                }
                return Ok(StarList {
                    x: x.iter().map(|v| v - 1.0).collect(),
                    y: y.iter().map(|v| v - 1.0).collect(),
                    flux: find("FLUX").map(read),
                    size,
                });
            }
        }
        pos = scan.next_start(bytes.len())?;
    }
    fail!(Input, "no binary table with X and Y columns")
}

/// IMAGEW and IMAGEH of a header, when both are positive integers.
fn image_size(bytes: &[u8], scan: &Scan) -> Option<(u32, u32)> {
    let get = |key: &str| {
        header_values(bytes, scan)
            .into_iter()
            .find(|(k, _)| k == key)
            .and_then(|(_, v)| v.parse::<f64>().ok())
            .filter(|v| *v >= 1.0 && *v <= u32::MAX as f64 && v.fract() == 0.0)
            .map(|v| v as u32)
    };
    Some((get("IMAGEW")?, get("IMAGEH")?))
}

/// The (keyword, value text) pairs of a header; strings keep their quotes.
fn header_values(bytes: &[u8], scan: &Scan) -> Vec<(String, String)> {
    let end = scan.data_start.min(bytes.len());
    bytes[scan.start..end]
        .chunks_exact(CARD)
        .take_while(|c| c[..8].trim_ascii() != b"END")
        .filter(|c| c[8..10] == *b"= ")
        .map(|c| (ascii(c[..8].trim_ascii()), value_field(&c[10..])))
        .collect()
}

/// A numeric column of a binary table: its name, offset in the row and type.
struct TableColumn {
    name: String,
    offset: usize,
    kind: u8,
}

impl TableColumn {
    fn value(&self, row: &[u8]) -> f64 {
        let at = |n: usize| &row[self.offset..self.offset + n];
        match self.kind {
            b'D' => f64::from_be_bytes(at(8).try_into().unwrap_or_default()),
            b'E' => f32::from_be_bytes(at(4).try_into().unwrap_or_default()) as f64,
            b'K' => i64::from_be_bytes(at(8).try_into().unwrap_or_default()) as f64,
            b'J' => i32::from_be_bytes(at(4).try_into().unwrap_or_default()) as f64,
            b'I' => i16::from_be_bytes(at(2).try_into().unwrap_or_default()) as f64,
            _ => row[self.offset] as f64,
        }
    }
}

/// The table's scalar numeric columns (others are skipped over); their rows must fit NAXIS1.
fn columns(bytes: &[u8], scan: &Scan) -> Result<Vec<TableColumn>> {
    let values = header_values(bytes, scan);
    let get = |key: &str| {
        values
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.trim_matches('\'').trim().to_string())
    };
    let fields: usize = get("TFIELDS").and_then(|v| v.parse().ok()).unwrap_or(0);
    if fields > 999 || scan.naxis.len() != 2 {
        fail!(Input, "{}: not a table gpustar reads", scan.what);
    }
    let mut offset = 0usize;
    let mut out = Vec::new();
    for n in 1..=fields {
        let form = get(&format!("TFORM{n}")).unwrap_or_default();
        let digits = form.bytes().take_while(u8::is_ascii_digit).count();
        let repeat: usize = if digits == 0 {
            1
        } else {
            form[..digits].parse().unwrap_or(0)
        };
        let kind = form.as_bytes().get(digits).copied().unwrap_or(b'?');
        let width = match kind {
            b'L' | b'B' | b'A' => 1,
            b'I' => 2,
            b'J' | b'E' => 4,
            b'K' | b'D' | b'C' | b'P' => 8,
            b'M' | b'Q' => 16,
            b'X' => {
                offset += repeat.div_ceil(8);
                continue;
            }
            _ => fail!(Input, "{}: TFORM{n} = {form:?} is not read", scan.what),
        };
        if repeat == 1 && matches!(kind, b'B' | b'I' | b'J' | b'K' | b'E' | b'D') {
            let name = get(&format!("TTYPE{n}")).unwrap_or_default();
            out.push(TableColumn { name, offset, kind });
        }
        offset = offset
            .checked_add(width * repeat)
            .ok_or_else(|| error!(Input, "{}: TFORM{n} too wide", scan.what))?;
    }
    if offset as u64 != scan.naxis[0] {
        fail!(
            Input,
            "{}: the columns take {offset} bytes a row, NAXIS1 says {}",
            scan.what,
            scan.naxis[0]
        );
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::fits::card_raw;
    use crate::io::fits::table::{Column, Values, encode_table};

    #[test]
    fn a_table_written_as_axy_reads_back() {
        let t = encode_table(
            &[
                Column {
                    name: "X",
                    unit: "pix",
                    values: Values::F64(vec![11.0, 2.5]),
                },
                Column {
                    name: "ID",
                    unit: "",
                    values: Values::Text(vec!["a".into(), "bb".into()]),
                },
                Column {
                    name: "flux",
                    unit: "",
                    values: Values::I32(vec![9, 4]),
                },
                Column {
                    name: "y",
                    unit: "pix",
                    values: Values::F64(vec![1.0, 7.0]),
                },
            ],
            &[card_raw("IMAGEW", "640", ""), card_raw("IMAGEH", "480", "")],
        );
        let s = parse(&t).unwrap();
        assert_eq!(s.x, [10.0, 1.5]);
        assert_eq!(s.y, [0.0, 6.0]);
        assert_eq!(s.flux, Some(vec![9.0, 4.0]));
        assert_eq!(s.size, Some((640, 480)));
        // Cut short, or without X: errors.
        assert!(parse(&t[..2 * 2880 + 10]).is_err());
        let no_x = encode_table(
            &[Column {
                name: "RA",
                unit: "",
                values: Values::F64(vec![1.0]),
            }],
            &[],
        );
        assert!(parse(&no_x).unwrap_err().to_string().contains("X and Y"));
    }
}
