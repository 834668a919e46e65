//! The pixel scale a FITS header states, for frames solved without `--camera`, `--fov-deg` or
//! `--scale-arcsec` (as ASTAP solves most frames): from a WCS already there (CD matrix, or
//! CDELT with PC), else a scale keyword (PIXSCALE, SECPIX), else the focal length and the pixel
//! size (FOCALLEN with XPIXSZ/YPIXSZ). Only the scale is taken; the pointing the header may
//! also give is `--hint header`'s to use.

use std::collections::BTreeMap;

/// A pixel scale read from a header.
#[derive(Clone, Debug, PartialEq)]
pub struct PixelScale {
    /// The angle one pixel's width subtends, arcseconds.
    pub arcsec_per_px: f64,
    /// A pixel's height over its width (1 for square pixels).
    pub pixel_aspect: f64,
    /// The keywords it came from, e.g. "FOCALLEN, XPIXSZ", for the record.
    pub keywords: &'static str,
}

/// Scales outside this range (arcsec per pixel) are placeholders or mistakes (a CDELT of 1°
/// left by a program that wrote no solution), not a camera.
const PLAUSIBLE: std::ops::Range<f64> = 0.01..3600.0;

/// The pixel scale of a header's keywords, or None when they state none (or only an
/// implausible one).
pub fn pixel_scale(keywords: &BTreeMap<String, String>) -> Option<PixelScale> {
    let num = |k: &str| {
        keywords
            .get(k)
            .and_then(|v| v.trim().trim_matches('\'').trim().parse::<f64>().ok())
            .filter(|v| v.is_finite())
    };
    let celestial = keywords
        .get("CTYPE1")
        .is_some_and(|t| t.starts_with("RA--") || t.starts_with("GLON") || t.starts_with("ELON"));
    let found = |x: f64, y: f64, keywords: &'static str| {
        let (x, y) = (x.abs(), y.abs());
        (PLAUSIBLE.contains(&x) && PLAUSIBLE.contains(&y) && (0.5..=2.0).contains(&(y / x)))
            .then_some(PixelScale {
                arcsec_per_px: x,
                pixel_aspect: y / x,
                keywords,
            })
    };
    // A WCS: the length of each pixel axis's column of the CD (or PC × CDELT) matrix.
    if let (Some(a), Some(b), Some(c), Some(d)) =
        (num("CD1_1"), num("CD1_2"), num("CD2_1"), num("CD2_2"))
        && let Some(s) = found(a.hypot(c) * 3600.0, b.hypot(d) * 3600.0, "CD1_1..CD2_2")
    {
        return Some(s);
    }
    if let (true, Some(c1), Some(c2)) = (celestial, num("CDELT1"), num("CDELT2")) {
        let pc = |k: &str, default: f64| num(k).unwrap_or(default);
        let x = c1 * pc("PC1_1", 1.0).hypot(pc("PC2_1", 0.0));
        let y = c2 * pc("PC1_2", 0.0).hypot(pc("PC2_2", 1.0));
        if let Some(s) = found(x * 3600.0, y * 3600.0, "CDELT1, CDELT2") {
            return Some(s);
        }
    }
    for (k, name) in [
        ("PIXSCALE", "PIXSCALE"),
        ("SECPIX", "SECPIX"),
        ("SECPIX1", "SECPIX1"),
    ] {
        if let Some(s) = num(k).and_then(|v| found(v, v, name)) {
            return Some(s);
        }
    }
    // The focal length (mm) and the pixel size (µm, binned, as MaxIm DL, ASCOM and N.I.N.A.
    // write XPIXSZ): 206.265″ per µm per mm.
    if let (Some(f), Some(px)) = (num("FOCALLEN"), num("XPIXSZ"))
        && f > 0.0
        && px > 0.0
    {
        let py = num("YPIXSZ").filter(|v| *v > 0.0).unwrap_or(px);
        let arcsec = |p: f64| (p * 1e-3 / f).atan().to_degrees() * 3600.0;
        return found(arcsec(px), arcsec(py), "FOCALLEN, XPIXSZ");
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(cards: &[(&str, &str)]) -> BTreeMap<String, String> {
        cards
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    #[test]
    fn the_focal_length_and_pixel_size_give_the_scale() {
        // A Seestar S50: 250 mm, 2.9 µm pixels.
        let s = pixel_scale(&header(&[
            ("FOCALLEN", "250"),
            ("XPIXSZ", "2.9"),
            ("YPIXSZ", "2.9"),
        ]))
        .unwrap();
        assert!((s.arcsec_per_px - 2.392674).abs() < 1e-5, "{s:?}");
        assert_eq!((s.pixel_aspect, s.keywords), (1.0, "FOCALLEN, XPIXSZ"));
    }

    #[test]
    fn a_wcs_scale_comes_first_and_a_placeholder_is_passed_over() {
        // An SDSS frame's CD matrix: 0.396″ per pixel, rotated by 88°.
        let sdss = header(&[
            ("CD1_1", "4.04596711897E-06"),
            ("CD1_2", "0.000109916108842"),
            ("CD2_1", "0.000109941600092"),
            ("CD2_2", "-4.04276424395E-06"),
            ("FOCALLEN", "250"),
            ("XPIXSZ", "2.9"),
        ]);
        let s = pixel_scale(&sdss).unwrap();
        assert!((s.arcsec_per_px - 0.39608).abs() < 1e-4, "{s:?}");
        assert_eq!(s.keywords, "CD1_1..CD2_2");
        // ASTAP's Seestar frames carry CDELT1 = CDELT2 = 1.0 beside an unsolved CTYPE: not a
        // scale; the focal length gives it.
        let seestar = header(&[
            ("CTYPE1", "RA---TAN"),
            ("CDELT1", "1.0"),
            ("CDELT2", "1.0"),
            ("FOCALLEN", "250"),
            ("XPIXSZ", "2.90000009536743"),
        ]);
        assert_eq!(pixel_scale(&seestar).unwrap().keywords, "FOCALLEN, XPIXSZ");
        let cdelt = header(&[
            ("CTYPE1", "RA---TAN"),
            ("CDELT1", "-0.0005"),
            ("CDELT2", "0.0005"),
        ]);
        let s = pixel_scale(&cdelt).unwrap();
        assert!((s.arcsec_per_px - 1.8).abs() < 1e-9 && s.keywords == "CDELT1, CDELT2");
        let secpix = pixel_scale(&header(&[("SECPIX", "'1.25'")])).unwrap();
        assert_eq!((secpix.arcsec_per_px, secpix.keywords), (1.25, "SECPIX"));
    }

    #[test]
    fn headers_without_a_scale_give_none() {
        for cards in [
            &[][..],
            &[("FOCALLEN", "0"), ("XPIXSZ", "2.9")][..],
            &[("XPIXSZ", "2.9")][..],
            &[("CDELT1", "0.001"), ("CDELT2", "0.001")][..], // not a celestial axis
            &[("PIXSCALE", "nan")][..],
            &[("PIXSCALE", "1e9")][..],
        ] {
            assert_eq!(pixel_scale(&header(cards)), None, "{cards:?}");
        }
    }
}
