use super::cards::{BLOCK, CARD};
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
fn cubes_give_their_first_plane_and_lines_are_refused() {
    // stvid's frames are cubes of four planes, the first their mean.
    let planes: Vec<u8> = (0..48).collect();
    let f = decode(&image(8, &[4, 4, 3], &[], &planes));
    assert_eq!((f.width, f.height), (4, 4));
    assert_eq!(f.pixels, (0..16).collect::<Vec<u16>>());
    assert_eq!(
        f.warnings,
        ["FITS primary HDU is a cube (4×4×3): its first plane was read"]
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
fn a_tile_compressed_image_without_its_keywords_is_an_error() {
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
    // Read as one (src/io/fits/tiled.rs; tests/it/fz.rs), and this one lacks what it needs.
    assert!(e.contains("lacks ZBITPIX"), "{e}");
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
    for e in ["fits", "fit", "fts", "fz"] {
        assert!(is_fits_extension(e));
    }
    for e in ["gz", "png", "FITS", ""] {
        assert!(!is_fits_extension(e));
    }
}

#[test]
fn keywords_of_a_frame_in_memory_give_the_epoch_a_file_would() {
    let kw = |pairs: &[(&str, &str)]| -> BTreeMap<String, String> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    };
    let date = "2024-03-15T20:00:00.000";
    let (year, w) = epoch_of_keywords(&kw(&[("DATE-OBS", date)]));
    assert_eq!((year, w.len()), (julian_year(date), 0));
    // DATE-BEG first, as in a file; MJD as a number.
    let (year, _) = epoch_of_keywords(&kw(&[("DATE-OBS", "2010-01-01"), ("DATE-BEG", date)]));
    assert_eq!(year, julian_year(date));
    let (year, _) = epoch_of_keywords(&kw(&[("MJD-OBS", "51544.5")]));
    assert_eq!(year, Some(2000.0));
    // A placeholder date is passed over with the file's warning.
    let (year, w) = epoch_of_keywords(&kw(&[("DATE-OBS", "9999-12-31T00:00:00")]));
    assert!(
        year.is_none() && w[0].contains("outside 1960-2100"),
        "{w:?}"
    );
}

/// [`read_camera_frame`] with the file's first `head` bytes in hand and the rest to read.
fn camera_frame(bytes: &[u8], head: usize) -> Option<FitsFrame> {
    let head = head.min(bytes.len());
    let mut rest = std::io::Cursor::new(&bytes[head..]);
    read_camera_frame(&bytes[..head], &mut rest, bytes.len() as u64, 1 << 30)
}

/// The camera frame read straight into its pixels is what `decode_fits` makes of the file,
/// whatever part of it was read first (the header alone, part of its padding, part of the
/// data, or all of it) and across read chunks; other kinds and damaged files are left to
/// `decode_fits`.
#[test]
fn camera_frames_read_straight_equal_decode_fits() {
    let (w, h) = (300u64, 257u64);
    let stored: Vec<i16> = (0..w * h)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 7) as i16)
        .collect();
    let camera = [card("BZERO", 32768), card("BSCALE", 1)];
    let dated = [
        card("BZERO", 32768),
        text_card("DATE-OBS", "2019-07-29T20:47:26.5"),
        text_card("OBJECT", "M42"),
    ];
    for extra in [&camera[..], &dated[..]] {
        let bytes = image(16, &[w, h], extra, &be16(&stored));
        let want = decode(&bytes);
        for head in [
            BLOCK,
            BLOCK + 1,
            2 * BLOCK - 1,
            2 * BLOCK + 3,
            100_001,
            bytes.len(),
        ] {
            assert_eq!(
                camera_frame(&bytes, head),
                Some(want.clone()),
                "head {head}"
            );
        }
        // The pixels converted as built, not compiled for AVX2 (`crate::simd`): the same.
        let built = crate::simd::baseline(|| camera_frame(&bytes, bytes.len()));
        assert_eq!(built, Some(want.clone()));
        // The same image in an extension after an empty primary (the date in the primary).
        let ext = multi(
            &[extension("IMAGE", 16, &[w, h], &camera, &be16(&stored))],
            &dated[1..],
        );
        for head in [2 * BLOCK, 3 * BLOCK + 5, ext.len()] {
            assert_eq!(camera_frame(&ext, head), Some(decode(&ext)), "head {head}");
        }
        // A header not wholly in hand, or data cut short: left to decode_fits.
        assert_eq!(camera_frame(&bytes, 100), None);
        let cut = &bytes[..bytes.len() - BLOCK];
        assert_eq!(camera_frame(cut, BLOCK), None);
        assert!(error(cut).contains("truncated"));
    }
    // Other kinds: signed 16-bit, another BZERO, BLANK, 8-bit, 3-D.
    let small = be16(&[0, 5, 1234, 32767]);
    for bytes in [
        image(16, &[2, 2], &[], &small),
        image(16, &[2, 2], &[card("BZERO", 1000)], &small),
        image(
            16,
            &[2, 2],
            &[card("BZERO", 32768), card("BLANK", 5)],
            &small,
        ),
        image(8, &[2, 2], &[], &[1, 2, 3, 4]),
    ] {
        assert_eq!(camera_frame(&bytes, bytes.len()), None);
    }
    // A cube of camera frames: its first plane, as decode_fits reads it.
    let cube = image(16, &[2, 1, 2], &camera, &small);
    assert_eq!(camera_frame(&cube, cube.len()), Some(decode(&cube)));
}
