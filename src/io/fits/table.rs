//! FITS binary tables (FITS 4.0 §7.3) as astrometry.net writes its star lists and matches
//! (`.axy`, `.corr`): an empty primary HDU, then one BINTABLE of fixed-width columns.

use super::cards::{BLOCK, card, card_end, card_raw, card_str};

/// One column's values.
pub enum Values {
    /// 64-bit floats (TFORM `D`).
    F64(Vec<f64>),
    /// 32-bit integers (TFORM `J`).
    I32(Vec<i32>),
    /// 64-bit integers (TFORM `K`): catalog numbers beyond 2^31 (Gaia source ids).
    I64(Vec<i64>),
    /// Text, ASCII, padded with blanks to the longest value (TFORM `nA`).
    Text(Vec<String>),
}

impl Values {
    fn len(&self) -> usize {
        match self {
            Values::F64(v) => v.len(),
            Values::I32(v) => v.len(),
            Values::I64(v) => v.len(),
            Values::Text(v) => v.len(),
        }
    }

    /// TFORM and bytes per row.
    fn form(&self) -> (String, usize) {
        match self {
            Values::F64(_) => ("D".into(), 8),
            Values::I32(_) => ("J".into(), 4),
            Values::I64(_) => ("K".into(), 8),
            Values::Text(v) => {
                let w = v.iter().map(|s| s.len()).max().unwrap_or(0).max(1);
                (format!("{w}A"), w)
            }
        }
    }

    fn put(&self, row: usize, width: usize, out: &mut Vec<u8>) {
        match self {
            Values::F64(v) => out.extend_from_slice(&v[row].to_be_bytes()),
            Values::I32(v) => out.extend_from_slice(&v[row].to_be_bytes()),
            Values::I64(v) => out.extend_from_slice(&v[row].to_be_bytes()),
            Values::Text(v) => {
                let s: Vec<u8> = v[row]
                    .bytes()
                    .map(|b| if b.is_ascii_graphic() { b } else { b' ' })
                    .collect();
                out.extend_from_slice(&s[..s.len().min(width)]);
                out.resize(out.len() + width - s.len().min(width), b' ');
            }
        }
    }
}

/// A column: its name (TTYPE), unit (TUNIT, may be empty) and values.
pub struct Column {
    pub name: &'static str,
    pub unit: &'static str,
    pub values: Values,
}

/// A FITS file of one binary table with `columns` (all of one length), and `cards` (80
/// columns each, e.g. from [`card_str`]) in the table's header after the structural ones.
pub fn encode_table(columns: &[Column], cards: &[String]) -> Vec<u8> {
    let rows = columns.first().map_or(0, |c| c.values.len());
    assert!(
        columns.iter().all(|c| c.values.len() == rows),
        "table columns of unequal length"
    );
    let forms: Vec<(String, usize)> = columns.iter().map(|c| c.values.form()).collect();
    let row_bytes: usize = forms.iter().map(|f| f.1).sum();

    let primary = [
        card("SIMPLE", "T"),
        card("BITPIX", "8"),
        card("NAXIS", "0"),
        card("EXTEND", "T"),
        card_end(),
    ];
    let mut head = vec![
        card_str("XTENSION", "BINTABLE", "binary table extension"),
        card_raw("BITPIX", "8", ""),
        card_raw("NAXIS", "2", ""),
        card_raw("NAXIS1", &row_bytes.to_string(), "bytes per row"),
        card_raw("NAXIS2", &rows.to_string(), "rows"),
        card_raw("PCOUNT", "0", ""),
        card_raw("GCOUNT", "1", ""),
        card_raw("TFIELDS", &columns.len().to_string(), ""),
    ];
    for (i, (c, (form, _))) in columns.iter().zip(&forms).enumerate() {
        let n = i + 1;
        head.push(card_str(&format!("TTYPE{n}"), c.name, ""));
        head.push(card_str(&format!("TFORM{n}"), form, ""));
        if !c.unit.is_empty() {
            head.push(card_str(&format!("TUNIT{n}"), c.unit, ""));
        }
    }
    head.extend(cards.iter().map(|c| format!("{c:<80.80}")));
    head.push(card_end());

    let mut out: Vec<u8> = primary.iter().flat_map(|c| c.bytes()).collect();
    out.resize(out.len().next_multiple_of(BLOCK), b' ');
    out.extend(head.iter().flat_map(|c| c.bytes()));
    out.resize(out.len().next_multiple_of(BLOCK), b' ');
    for row in 0..rows {
        for (c, (_, width)) in columns.iter().zip(&forms) {
            c.values.put(row, *width, &mut out);
        }
    }
    out.resize(out.len().next_multiple_of(BLOCK), 0);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_table_has_its_rows_where_its_header_says() {
        let t = encode_table(
            &[
                Column {
                    name: "X",
                    unit: "pix",
                    values: Values::F64(vec![1.5, -2.0]),
                },
                Column {
                    name: "ID",
                    unit: "",
                    values: Values::Text(vec!["HIP 1".into(), "TYC 1-2-3".into()]),
                },
                Column {
                    name: "N",
                    unit: "",
                    values: Values::I32(vec![7, -1]),
                },
            ],
            &[card_str("CREATOR", "gpustar", "")],
        );
        assert_eq!(t.len() % BLOCK, 0);
        let head = String::from_utf8_lossy(&t[BLOCK..2 * BLOCK]);
        assert!(head.contains("NAXIS1  =                   21"), "{head}");
        assert!(head.contains("TFORM2  = '9A      '"), "{head}");
        let row0 = &t[2 * BLOCK..2 * BLOCK + 21];
        assert_eq!(&row0[..8], &1.5f64.to_be_bytes());
        assert_eq!(&row0[8..17], b"HIP 1    ");
        assert_eq!(&row0[17..21], &7i32.to_be_bytes());
    }
}
