//! The one FITS card writer, and 16-bit FITS files written with it.

/// A FITS file is blocks of 2880 bytes; a header, cards of 80.
pub(crate) const BLOCK: usize = 2880;
pub(crate) const CARD: usize = 80;

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
pub(crate) fn finish_card(mut card: String, comment: &str) -> String {
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

/// A float keyword's value as text that reads back to the same number: plain digits, or an
/// exponent where plain digits would be long (1E300 would otherwise be 301 characters in
/// every warning that quotes it).
pub(crate) fn number_text(v: f64) -> String {
    if v != 0.0 && (v.abs() >= 1e16 || v.abs() < 1e-6) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}
