//! Star lists given instead of images (`--xyls`): FITS tables of detections, as solve-field
//! takes them (`.xyls`, `.axy`, and what `--axy` writes): the first binary table holding `X`
//! and `Y` columns (any case), with `FLUX` when it has one (else the rows are taken as sorted
//! brightest first, as solve-field takes them), and the image size from `IMAGEW`/`IMAGEH` in
//! its header or the primary header.
//!
//! Pixels are FITS pixels, 1-based as astrometry.net writes them: gpustar's x = X − 1.

use super::bintable::{Cards, Column, columns};
use super::scan::scan_header;
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
    let mut size = image_size(&Cards::read(bytes, &primary));
    let mut pos = primary.next_start(bytes.len())?;
    let mut index = 0;
    while pos < bytes.len() {
        index += 1;
        let scan = scan_header(bytes, pos, format!("FITS extension {index}"))?;
        if scan.xtension.as_deref() == Some("BINTABLE") && !scan.zimage {
            let cards = Cards::read(bytes, &scan);
            let cols = columns(&cards, &scan, &scan.what)?;
            // Scalar numbers only: a column of another kind is not a star's X, Y or flux.
            let find = |name: &str| {
                cols.get(name)
                    .filter(|c| c.repeat == 1 && b"BIJKED".contains(&c.kind))
            };
            if let (Some(x), Some(y)) = (find("X"), find("Y")) {
                size = image_size(&cards).or(size);
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
                let read = |c: &Column| -> Vec<f64> {
                    data.chunks_exact(row_bytes.max(1))
                        .map(|row| value(c, row))
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
fn image_size(cards: &Cards) -> Option<(u32, u32)> {
    let get = |key: &str| {
        cards
            .text(key)
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|v| *v >= 1.0 && *v <= u32::MAX as f64 && v.fract() == 0.0)
            .map(|v| v as u32)
    };
    Some((get("IMAGEW")?, get("IMAGEH")?))
}

/// A scalar number of a row.
fn value(c: &Column, row: &[u8]) -> f64 {
    let at = |n: usize| &row[c.offset..c.offset + n];
    match c.kind {
        b'D' => f64::from_be_bytes(at(8).try_into().unwrap_or_default()),
        b'E' => f32::from_be_bytes(at(4).try_into().unwrap_or_default()) as f64,
        b'K' => i64::from_be_bytes(at(8).try_into().unwrap_or_default()) as f64,
        b'J' => i32::from_be_bytes(at(4).try_into().unwrap_or_default()) as f64,
        b'I' => i16::from_be_bytes(at(2).try_into().unwrap_or_default()) as f64,
        _ => row[c.offset] as f64,
    }
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
