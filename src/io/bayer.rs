//! Raw colour-filter mosaics (a one-shot colour camera's FITS, `BAYERPAT = 'GRBG'`): each pixel
//! sees one colour, so every star carries the mosaic's checker pattern, which splits it into
//! blobs and pulls centroids toward its brightest colour. gpustar detects on the luminance
//! instead, (R + 2G + B) / 4 at every pixel: the 3×3 binomial filter [1 2 1; 2 4 2; 1 2 1] / 16
//! gives that at any place of any 2×2 mosaic, without moving anything (it is symmetric), and
//! widens a star's image by 0.5 px² of variance per axis.

use std::collections::BTreeMap;

/// The mosaic a FITS header names (`BAYERPAT`, or `COLORTYP` as some capture programs write
/// it): four letters of R, G and B with two G, as in `RGGB`, `GRBG`, `GBRG`, `BGGR`.
pub fn mosaic(keywords: &BTreeMap<String, String>) -> Option<String> {
    let value = keywords
        .get("BAYERPAT")
        .or_else(|| keywords.get("COLORTYP"))?;
    let p = value.trim().trim_matches('\'').trim().to_ascii_uppercase();
    let valid = p.len() == 4
        && p.bytes().all(|c| matches!(c, b'R' | b'G' | b'B'))
        && p.bytes().filter(|&c| c == b'G').count() == 2
        && p.contains('R')
        && p.contains('B');
    valid.then_some(p)
}

/// The luminance of a `width` × `height` mosaic, in place. Edges reflect about their border
/// pixels (x = -1 reads x = 1), which keeps the mosaic's colours where repeating them would not.
pub fn luminance(pixels: &mut [u16], width: usize, height: usize) {
    if width < 2 || height < 2 || pixels.len() != width * height {
        return;
    }
    // Rows filtered [1 2 1] into u32, then columns, one row at a time.
    let horizontal = |row: &[u16], out: &mut [u32]| {
        for x in 0..width {
            let l = row[if x == 0 { 1 } else { x - 1 }] as u32;
            let r = row[if x + 1 == width { width - 2 } else { x + 1 }] as u32;
            out[x] = l + 2 * row[x] as u32 + r;
        }
    };
    let mut above = vec![0u32; width];
    let mut here = vec![0u32; width];
    let mut below = vec![0u32; width];
    horizontal(&pixels[..width], &mut here);
    horizontal(&pixels[width..2 * width], &mut above);
    for y in 0..height {
        // The last row reflects onto the row above it, already overwritten: reuse its filter.
        if y + 1 == height {
            below.copy_from_slice(&above);
        } else {
            horizontal(&pixels[(y + 1) * width..(y + 2) * width], &mut below);
        }
        let row = &mut pixels[y * width..(y + 1) * width];
        for x in 0..width {
            row[x] = ((above[x] + 2 * here[x] + below[x] + 8) / 16) as u16;
        }
        std::mem::swap(&mut above, &mut here);
        std::mem::swap(&mut here, &mut below);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_are_read_from_either_keyword() {
        let kw = |k: &str, v: &str| BTreeMap::from([(k.to_string(), v.to_string())]);
        assert_eq!(mosaic(&kw("BAYERPAT", "GRBG")), Some("GRBG".into()));
        assert_eq!(mosaic(&kw("BAYERPAT", "'rggb '")), Some("RGGB".into()));
        assert_eq!(mosaic(&kw("COLORTYP", "BGGR")), Some("BGGR".into()));
        assert_eq!(mosaic(&kw("BAYERPAT", "RGB")), None);
        assert_eq!(mosaic(&kw("BAYERPAT", "RRGB")), None);
        assert_eq!(mosaic(&BTreeMap::new()), None);
    }

    #[test]
    fn a_mosaic_of_a_flat_grey_becomes_flat_and_a_star_keeps_its_centre() {
        // GRBG mosaic of a uniform colour (R 400, G 1000, B 200): luminance (R + 2G + B) / 4.
        let (w, h) = (16usize, 12usize);
        let colour = |x: usize, y: usize| match (y % 2, x % 2) {
            (0, 0) | (1, 1) => 1000u16,
            (0, 1) => 400,
            _ => 200,
        };
        let mut p: Vec<u16> = (0..w * h).map(|i| colour(i % w, i / w)).collect();
        luminance(&mut p, w, h);
        assert!(p.iter().all(|&v| v == 650), "{p:?}");
        // A point on a flat mosaic spreads symmetrically: its centroid stays where it was.
        let mut q = vec![100u16; w * h];
        q[5 * w + 7] = 5000;
        luminance(&mut q, w, h);
        let (mut sx, mut sy, mut s) = (0.0, 0.0, 0.0);
        for (i, &v) in q.iter().enumerate() {
            let f = v as f64 - 100.0;
            sx += f * (i % w) as f64;
            sy += f * (i / w) as f64;
            s += f;
        }
        assert!((sx / s - 7.0).abs() < 1e-9 && (sy / s - 5.0).abs() < 1e-9);
    }
}
