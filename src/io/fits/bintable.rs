//! Reading FITS binary tables (FITS 4.0 §7.3): a header's cards by key, and where each column
//! of a row sits. Tile-compressed images (`tiled.rs`) and star lists (`star_list.rs`) are both
//! such tables.

use super::cards::CARD;
use super::scan::{Scan, ascii, value_field};
use crate::error::{Result, error, fail};
use std::collections::HashMap;

/// The cards of a header in order (key, the 80 bytes), and their values by key.
pub(crate) struct Cards<'a> {
    pub(crate) list: Vec<(String, &'a [u8])>,
    pub(crate) values: HashMap<String, String>,
}

impl<'a> Cards<'a> {
    pub(crate) fn read(bytes: &'a [u8], scan: &Scan) -> Cards<'a> {
        let mut list = Vec::new();
        let mut values = HashMap::new();
        for card in bytes[scan.start..scan.data_start.min(bytes.len())].chunks_exact(CARD) {
            let key = ascii(card[..8].trim_ascii());
            if key == "END" {
                break;
            }
            if card[8..10] == *b"= " {
                values.insert(key.clone(), value_field(&card[10..]));
            }
            list.push((key, card));
        }
        Cards { list, values }
    }

    pub(crate) fn text(&self, key: &str) -> Option<String> {
        let v = self.values.get(key)?;
        Some(match v.strip_prefix('\'') {
            Some(s) => s.split('\'').next().unwrap_or("").trim().to_string(),
            None => v.clone(),
        })
    }

    pub(crate) fn int(&self, key: &str, what: &str) -> Result<Option<i64>> {
        match self.values.get(key) {
            None => Ok(None),
            Some(v) => v
                .parse()
                .map(Some)
                .map_err(|_| error!(Input, "{what}: {key} = {v} is not an integer")),
        }
    }

    pub(crate) fn real(&self, key: &str, what: &str) -> Result<Option<f64>> {
        match self.values.get(key) {
            None => Ok(None),
            Some(v) => v
                .replace(['D', 'd'], "E")
                .parse()
                .map(Some)
                .map_err(|_| error!(Input, "{what}: {key} = {v} is not a number")),
        }
    }
}

/// A column's place in a row and its element type.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Column {
    pub(crate) offset: usize,
    /// 'P' or 'Q' (array descriptors) or the scalar type letter.
    pub(crate) kind: u8,
    /// Bytes per element of the array (descriptors) or of the scalar.
    pub(crate) element: usize,
    /// Elements in the field (TFORM's repeat count).
    pub(crate) repeat: usize,
}

/// The columns of a binary table by their upper-case names (TTYPE; unnamed ones are left
/// out), from TFIELDS and each TFORM; an error when a TFORM is not read or the widths do not
/// add up to NAXIS1.
pub(crate) fn columns(cards: &Cards, table: &Scan, what: &str) -> Result<HashMap<String, Column>> {
    let fields = cards.int("TFIELDS", what)?.unwrap_or(0);
    if !(0..=999).contains(&fields) || table.naxis.len() != 2 {
        fail!(
            Input,
            "{what}: not a table gpustar reads (TFIELDS = {fields})"
        );
    }
    let mut offset = 0usize;
    let mut found = HashMap::new();
    for n in 1..=fields {
        let form = cards.text(&format!("TFORM{n}")).unwrap_or_default();
        let bad = || error!(Input, "{what}: TFORM{n} = {form:?} is not read");
        let digits = form.bytes().take_while(u8::is_ascii_digit).count();
        let repeat: usize = if digits == 0 {
            1
        } else {
            form[..digits].parse().map_err(|_| bad())?
        };
        let letter = *form.as_bytes().get(digits).ok_or_else(bad)?;
        let size = |t: u8| -> Option<usize> {
            Some(match t {
                b'L' | b'B' | b'A' => 1,
                b'I' => 2,
                b'J' | b'E' => 4,
                b'K' | b'D' | b'C' => 8,
                b'M' => 16,
                _ => return None,
            })
        };
        let (width, element) = match letter {
            b'P' | b'Q' => {
                let t = *form.as_bytes().get(digits + 1).ok_or_else(bad)?;
                let d = if letter == b'P' { 8 } else { 16 };
                (d * repeat, size(t).ok_or_else(bad)?)
            }
            b'X' => (repeat.div_ceil(8), 1),
            t => {
                let s = size(t).ok_or_else(bad)?;
                (s.checked_mul(repeat).ok_or_else(bad)?, s)
            }
        };
        if let Some(name) = cards.text(&format!("TTYPE{n}")) {
            let column = Column {
                offset,
                kind: letter,
                element,
                repeat,
            };
            found.insert(name.to_ascii_uppercase(), column);
        }
        offset = offset.checked_add(width).ok_or_else(bad)?;
    }
    if offset as u64 != table.naxis[0] {
        fail!(
            Input,
            "{what}: the columns take {offset} bytes a row, NAXIS1 says {}",
            table.naxis[0]
        );
    }
    Ok(found)
}
