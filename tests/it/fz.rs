//! Tile-compressed FITS (`.fits.fz`, issue 47): the frames of tests/data/fz, compressed by
//! astropy and by fpack itself (CFITSIO's code; scripts/make_fz_fixtures.py), decode to the
//! pixels and header of the plain FITS file astropy or funpack expands each to.

use gpustar::io::frame::Frame;
use std::path::{Path, PathBuf};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fz")
}

/// Every compressed fixture beside its plain twin, and the one kind gpustar refuses.
#[test]
fn tile_compressed_frames_decode_to_their_plain_twins() {
    let mut pairs = 0;
    let mut names: Vec<PathBuf> = std::fs::read_dir(fixtures())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_str().unwrap().ends_with(".fits.fz"))
        .collect();
    names.sort();
    for fz in names {
        let shown = fz.file_name().unwrap().to_str().unwrap().to_string();
        let plain = fz.with_extension("");
        if !plain.exists() {
            // HCOMPRESS: an error that names the method and what to do.
            let e = Frame::read_info(&fz).unwrap_err().to_string();
            assert!(
                e.contains("HCOMPRESS_1") && e.contains("funpack"),
                "{shown}: {e}"
            );
            continue;
        }
        let (a, ia) = Frame::read_info(&fz).unwrap_or_else(|e| panic!("{shown}: {e}"));
        let (b, ib) = Frame::read_info(&plain).unwrap();
        assert_eq!((a.width, a.height), (b.width, b.height), "{shown}");
        assert_eq!(a.saturation, b.saturation, "{shown}");
        assert!(a.pixels == b.pixels, "{shown}: the pixels differ");
        assert_eq!(ia.epoch, ib.epoch, "{shown}");
        assert!(ia.epoch.is_some(), "{shown}: DATE-OBS kept");
        assert_eq!(ia.warnings, ib.warnings, "{shown}");
        // The image's keywords come through; the compression's do not.
        for k in ["DATE-OBS", "BITPIX", "NAXIS1", "NAXIS2", "BZERO", "BSCALE"] {
            assert_eq!(ia.keywords.get(k), ib.keywords.get(k), "{shown}: {k}");
        }
        assert!(
            !ia.keywords
                .keys()
                .any(|k| k.starts_with("ZTILE") || k == "ZCMPTYPE"),
            "{shown}: {:?}",
            ia.keywords.keys()
        );
        pairs += 1;
    }
    // RICE (bytes, shorts, ints, quantized floats), GZIP_1, GZIP_2, square tiles, three
    // dither methods, lossless floats, and fpack's own files.
    assert!(pairs >= 13, "only {pairs} fixtures");
}

/// A damaged compressed file is an error, never a panic or a wrong frame: every cut, and
/// bytes flipped all over the table and heap.
#[test]
fn damaged_tile_compressed_files_are_errors() {
    let whole = std::fs::read(fixtures().join("u16_rice.fits.fz")).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("x.fits.fz");
    let header_end = 2880 * 2;
    // Cut anywhere before the last byte of data (the zeros after it are padding).
    let data_end = whole.iter().rposition(|&b| b != 0).unwrap() + 1;
    for cut in (header_end..data_end).step_by(97) {
        std::fs::write(&path, &whole[..cut]).unwrap();
        assert!(Frame::read(&path).is_err(), "cut at {cut} read");
    }
    let reference = Frame::read(&fixtures().join("u16_rice.fits")).unwrap();
    let mut flipped_ok = 0;
    for at in (header_end..whole.len()).step_by(61) {
        let mut bad = whole.clone();
        bad[at] ^= 0x5a;
        std::fs::write(&path, &bad).unwrap();
        // Damage in padding or in a descriptor's unused bits may leave the image intact.
        if let Ok(f) = Frame::read(&path)
            && f == reference
        {
            flipped_ok += 1;
        }
    }
    assert!(flipped_ok < (whole.len() - header_end) / 61);
}
