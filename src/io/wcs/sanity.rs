//! Sanity of a header WCS (issue 45): bounds no telescope's WCS leaves, so that a typo or a
//! placeholder (CRVAL2 = 95, CD = 1e10, SIP terms of 1e300) is refused naming its keyword
//! rather than turned into confident RA/Dec.

/// Pixel scales (arcsec per pixel, each axis) a header WCS may have. Wide on both sides of
/// every real telescope: adaptive-optics imagers reach 1.5 mas/px (ELT MICADO), all-sky
/// cameras a fraction of a degree. Beyond them the linear terms are a typo or a placeholder
/// (1e10, 1e-300) and the RA/Dec they give mean nothing.
pub(super) const WCS_SCALE_ARCSEC: (f64, f64) = (1e-4, 36_000.0);
/// Largest ratio of a header WCS's two axis scales: pixels are near square (binning 1x2
/// gives 2); rows of the linear terms this close to parallel make them singular in effect.
pub(super) const WCS_MAX_ASPECT: f64 = 1000.0;
/// Largest |CRPIX| (pixels): a mosaic's chip may have its reference pixel several frames
/// away, not a million pixels.
pub(super) const WCS_MAX_CRPIX: f64 = 1e6;
/// CRVAL1 beyond ±2 turns is a placeholder, whatever its value modulo 360.
pub(super) const WCS_MAX_CRVAL1: f64 = 720.0;

/// The linear terms' two axis scales (singular values of CD, degrees per pixel) within
/// [`WCS_SCALE_ARCSEC`] and [`WCS_MAX_ASPECT`] of each other; `given` names the keywords.
pub(super) fn check_scales(
    cd: &[[f64; 2]; 2],
    given: impl Fn() -> String,
) -> std::result::Result<(), String> {
    // Singular values of a 2x2 matrix through hypot: no overflow for any finite entries.
    let [[a, b], [c, d]] = *cd;
    let q = (0.5 * (a + d)).hypot(0.5 * (c - b));
    let r = (0.5 * (a - d)).hypot(0.5 * (c + b));
    let (big, small) = ((q + r) * 3600.0, (q - r).abs() * 3600.0);
    let (lo, hi) = WCS_SCALE_ARCSEC;
    let range = || format!("pixel scales from {lo:e} to {hi} arcsec are read");
    // Entries near f64::MAX overflow the sums to inf; with `big` finite, `small` is too.
    let problem = if !big.is_finite() || big > hi {
        range()
    } else if small * WCS_MAX_ASPECT < big {
        "singular or nearly so".to_string()
    } else if small < lo {
        range()
    } else {
        return Ok(());
    };
    Err(format!(
        "{}: axis scales {} and {} arcsec per pixel, {problem}",
        given(),
        short(big),
        short(small)
    ))
}

/// The SIP distortion at the frame's corners under the frame's diagonal: a real camera's is
/// a few pixels, and 1e300 coefficients (or a high order's corner powers) would move a
/// streak's ends anywhere on the sky.
pub(super) fn check_distortion(
    crpix: (f64, f64),
    (w, h): (u32, u32),
    sip_a: &[(i32, i32, f64)],
    sip_b: &[(i32, i32, f64)],
    said: &dyn Fn(&str) -> String,
) -> std::result::Result<(), String> {
    let diagonal = f64::from(w).hypot(f64::from(h));
    // FITS pixel edges: the frame spans 0.5 .. w + 0.5.
    let corners = [(0.5, 0.5), (w as f64 + 0.5, 0.5), (0.5, h as f64 + 0.5)];
    let corners = corners
        .into_iter()
        .chain([(w as f64 + 0.5, h as f64 + 0.5)]);
    for (x, y) in corners {
        let (u, v) = (x - crpix.0, y - crpix.1);
        let term = |&(p, q, c): &(i32, i32, f64)| c * u.powi(p) * v.powi(q);
        let (du, dv) = (
            sip_a.iter().map(term).sum::<f64>(),
            sip_b.iter().map(term).sum::<f64>(),
        );
        let shift = du.hypot(dv);
        if shift <= diagonal {
            continue;
        }
        // Name the term that moves this corner most.
        let sets = [("A", sip_a), ("B", sip_b)];
        let terms = sets
            .iter()
            .flat_map(|(name, t)| t.iter().map(move |x| (*name, x)));
        let worst = terms
            .max_by(|a, b| term(a.1).abs().total_cmp(&term(b.1).abs()))
            .map_or(String::new(), |(name, x)| {
                said(&format!("{name}_{}_{}", x.0, x.1))
            });
        return Err(format!(
            "{worst}: the SIP distortion at the frame's corner ({x}, {y}) is {} px, more than \
             the frame's diagonal ({diagonal:.0} px)",
            short(shift)
        ));
    }
    Ok(())
}

/// A number for a message: 4 significant digits, in exponent form when far from 1.
fn short(v: f64) -> String {
    if v != 0.0 && !(1e-3..1e6).contains(&v.abs()) {
        format!("{v:.3e}")
    } else {
        format!("{}", (v * 1e4).round() / 1e4)
    }
}
