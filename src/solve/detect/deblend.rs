//! Deblending (`DetectSettings::deblend`, on in `--sequence`): a detection whose component
//! holds two or more sources (a particle beside a star or another particle, joined by their
//! wings above the threshold) is split into one detection per source, each then fitted on its
//! own (the PSF fit's window at its own centre).
//!
//! On the CPU, after the components' moments and before the PSF fits, for both backends alike:
//! it reads the frame's pixels and the detection list, the same integers on either. Around
//! each unsaturated detection of [`MIN_AREA`] pixels or more: background and noise from the
//! border of a window of side 2·[`HALF`]+1 (median and MAD, as the PSF fit takes them), the
//! source pixels connected to the detection's brightest (raw value at least `k_sigma` noise
//! sigmas above the background, 8-connected: the component as far as the window sees it; one
//! that reaches another detection is left alone), the local maxima among them of the window
//! smoothed by the 3×3 binomial (the matched filter). A maximum is a source of its own when it
//! stands `k_sigma` smoothed-noise sigmas above the background, at least [`MIN_SEPARATION_PX`]
//! from the sources kept before it (brightest first), and the smoothed image dips between it
//! and each of them, on the straight line, by at least [`SADDLE_SIGMAS`] smoothed-noise sigmas
//! below it: a saddle deeper than the noise could make.
//! The source pixels are then shared among the sources by their symmetric templates (SDSS's
//! deblender: a neighbour's wing on one side of a source is not matched on the other); each
//! part's centre of gravity, sum, area and peak make its detection. A detection with one
//! source is left as it is.

use super::detection::Detection;
use crate::io::frame::Frame;

/// Half the side of the window a detection is deblended in (pixels): sources up to about 12 px
/// apart, each with its wings.
pub const HALF: i64 = 16;
/// Smallest component (pixels) looked at: two sources take more.
pub const MIN_AREA: u32 = 10;
/// Depth of the saddle between two sources below the fainter's smoothed peak, in sigmas of the
/// smoothed noise.
pub const SADDLE_SIGMAS: f64 = 5.0;
/// Closest two sources are told apart (pixels).
pub const MIN_SEPARATION_PX: f64 = 3.0;
/// The 3×3 binomial's noise gain: √(Σ w²) for w = [1 2 1]ᵀ[1 2 1] / 16.
const SMOOTH_NOISE: f64 = 0.375;

/// `list` with every detection that holds more than one source replaced by one per source,
/// brightest first again (a stable order: ties keep the list's), at most `max_stars`.
pub fn deblend(
    frame: &Frame,
    list: &[Detection],
    k_sigma: f64,
    max_stars: usize,
) -> Vec<Detection> {
    let mut out: Vec<Detection> = Vec::with_capacity(list.len());
    for (i, d) in list.iter().enumerate() {
        match split(frame, d, i, list, k_sigma) {
            Some(parts) => out.extend(parts),
            None => out.push(*d),
        }
    }
    out.sort_by(|a, b| b.flux.total_cmp(&a.flux));
    out.truncate(max_stars);
    out
}

/// The sources of detection `d` (index `own` in `list`), or None when it holds one.
fn split(
    frame: &Frame,
    d: &Detection,
    own: usize,
    list: &[Detection],
    k_sigma: f64,
) -> Option<Vec<Detection>> {
    if d.saturated || d.area < MIN_AREA {
        return None;
    }
    let (w, h) = (frame.width as i64, frame.height as i64);
    let (cx, cy) = (d.x.round() as i64, d.y.round() as i64);
    let (x0, y0) = ((cx - HALF).max(0), (cy - HALF).max(0));
    let (x1, y1) = ((cx + HALF).min(w - 1), (cy + HALF).min(h - 1));
    let (nx, ny) = ((x1 - x0 + 1) as usize, (y1 - y0 + 1) as usize);
    if nx < 7 || ny < 7 {
        return None;
    }
    let px = |x: usize, y: usize| -> f64 {
        frame.pixels[((y0 + y as i64) * w + x0 + x as i64) as usize] as f64
    };
    // Background and noise from the window's border.
    let mut border: Vec<f64> = (0..nx * ny)
        .map(|i| (i % nx, i / nx))
        .filter(|&(x, y)| x == 0 || y == 0 || x == nx - 1 || y == ny - 1)
        .map(|(x, y)| px(x, y))
        .collect();
    border.sort_by(f64::total_cmp);
    let b = border[border.len() / 2];
    let mut dev: Vec<f64> = border.iter().map(|v| (v - b).abs()).collect();
    dev.sort_by(f64::total_cmp);
    let sigma = (1.4826 * dev[dev.len() / 2]).max(0.5);
    // The smoothed window (its outer ring left at the background).
    let mut s = vec![b; nx * ny];
    for y in 1..ny - 1 {
        for x in 1..nx - 1 {
            let mut acc = 0.0;
            for (dy, wy) in [(0, 1.0), (1, 2.0), (2, 1.0)] {
                for (dx, wx) in [(0, 1.0), (1, 2.0), (2, 1.0)] {
                    acc += wx * wy * px(x + dx - 1, y + dy - 1);
                }
            }
            s[y * nx + x] = acc / 16.0;
        }
    }
    // The source pixels: connected to the brightest raw pixel within 2 px of the centre.
    let at = |x: i64, y: i64| ((y - y0) as usize) * nx + (x - x0) as usize;
    let seed = (-2..=2)
        .flat_map(|dy| (-2..=2).map(move |dx| (cx + dx, cy + dy)))
        .filter(|&(x, y)| (x0..=x1).contains(&x) && (y0..=y1).contains(&y))
        .max_by(|a, c| {
            px((a.0 - x0) as usize, (a.1 - y0) as usize)
                .total_cmp(&px((c.0 - x0) as usize, (c.1 - y0) as usize))
                .then((c.1, c.0).cmp(&(a.1, a.0)))
        })?;
    let threshold = b + k_sigma * sigma;
    let mut inside = vec![false; nx * ny];
    let mut stack = vec![seed];
    inside[at(seed.0, seed.1)] = px((seed.0 - x0) as usize, (seed.1 - y0) as usize) >= threshold;
    if !inside[at(seed.0, seed.1)] {
        return None;
    }
    while let Some((x, y)) = stack.pop() {
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (u, v) = (x + dx, y + dy);
                if (x0..=x1).contains(&u)
                    && (y0..=y1).contains(&v)
                    && !inside[at(u, v)]
                    && px((u - x0) as usize, (v - y0) as usize) >= threshold
                {
                    inside[at(u, v)] = true;
                    stack.push((u, v));
                }
            }
        }
    }
    // A region that reaches another detection joins components the threshold kept apart (a
    // brighter neighbour's wings raise the border's background less than the tiles'): not
    // this detection's to split.
    let reaches = |(ox, oy): (f64, f64)| {
        let (u, v) = (ox.round() as i64, oy.round() as i64);
        (x0..=x1).contains(&u) && (y0..=y1).contains(&v) && inside[at(u, v)]
    };
    if list
        .iter()
        .enumerate()
        .any(|(k, o)| k != own && reaches((o.x, o.y)))
    {
        return None;
    }
    // Local maxima of the smoothed image among them (ties to the earlier pixel), brightest
    // first.
    let mut maxima: Vec<(usize, usize)> = Vec::new();
    for y in 1..ny - 1 {
        for x in 1..nx - 1 {
            let i = y * nx + x;
            if !inside[i] {
                continue;
            }
            let is_max = (-1i64..=1).all(|dy| {
                (-1i64..=1).all(|dx| {
                    let j = ((y as i64 + dy) as usize) * nx + (x as i64 + dx) as usize;
                    j == i || s[i] > s[j] || (s[i] == s[j] && i < j)
                })
            });
            if is_max {
                maxima.push((x, y));
            }
        }
    }
    if maxima.len() < 2 {
        return None;
    }
    maxima.sort_by(|a, c| s[c.1 * nx + c.0].total_cmp(&s[a.1 * nx + a.0]));
    let noise = SMOOTH_NOISE * sigma;
    let mut sources: Vec<(usize, usize)> = vec![maxima[0]];
    for &m in &maxima[1..] {
        let peak = s[m.1 * nx + m.0];
        let (mx, my) = (m.0 as f64, m.1 as f64);
        let apart = |(x, y): (f64, f64)| ((mx - x).powi(2) + (my - y).powi(2)).sqrt();
        let separate = peak - b >= k_sigma * noise
            && sources.iter().all(|&a| {
                let (ax, ay) = (a.0 as f64, a.1 as f64);
                let dist = apart((ax, ay));
                let steps = (2.0 * dist).ceil() as usize;
                let dip = (0..=steps)
                    .map(|k| {
                        let t = k as f64 / steps as f64;
                        let (x, y) = (ax + t * (mx - ax), ay + t * (my - ay));
                        s[(y.round() as usize) * nx + x.round() as usize]
                    })
                    .fold(f64::INFINITY, f64::min);
                dist >= MIN_SEPARATION_PX && peak - dip >= SADDLE_SIGMAS * noise
            });
        if separate {
            sources.push(m);
        }
    }
    if sources.len() < 2 {
        return None;
    }
    // Each source's symmetric template (SDSS's deblender): a pixel's value or its mirror
    // image's through the source's peak, the smaller (a neighbour's wing on one side is not
    // matched on the other). Every source pixel's value is shared among the sources in
    // proportion to their templates there (to the nearest source where none has one), and the
    // pixel counts for the source with the largest share.
    let value = |x: i64, y: i64| -> f64 {
        if (0..nx as i64).contains(&x) && (0..ny as i64).contains(&y) {
            (px(x as usize, y as usize) - b).max(0.0)
        } else {
            0.0
        }
    };
    let mut parts = vec![(0.0f64, 0.0f64, 0.0f64, 0u32, 0u32); sources.len()];
    let mut shares = vec![0.0f64; sources.len()];
    for y in 0..ny {
        for x in 0..nx {
            if !inside[y * nx + x] {
                continue;
            }
            let (xi, yi) = (x as i64, y as i64);
            let v = px(x, y);
            let wgt = (v - b).max(0.0);
            for (k, &(sx, sy)) in sources.iter().enumerate() {
                let (mx, my) = (2 * sx as i64 - xi, 2 * sy as i64 - yi);
                shares[k] = wgt.min(value(mx, my));
            }
            let total: f64 = shares.iter().sum();
            if total > 0.0 {
                shares.iter_mut().for_each(|t| *t /= total);
            } else {
                let near = (0..sources.len())
                    .min_by_key(|&k| {
                        let (sx, sy) = (sources[k].0 as i64, sources[k].1 as i64);
                        (xi - sx).pow(2) + (yi - sy).pow(2)
                    })
                    .expect("two sources or more");
                shares
                    .iter_mut()
                    .enumerate()
                    .for_each(|(k, t)| *t = f64::from(k == near));
            }
            let owner = (0..sources.len())
                .fold(0, |best, k| if shares[k] > shares[best] { k } else { best });
            for (k, p) in parts.iter_mut().enumerate() {
                let w = wgt * shares[k];
                p.0 += w;
                p.1 += w * x as f64;
                p.2 += w * y as f64;
            }
            parts[owner].3 += 1;
            parts[owner].4 = parts[owner].4.max(v as u32);
        }
    }
    if parts.iter().any(|p| p.0 <= 0.0 || p.3 < 2) {
        return None;
    }
    Some(
        parts
            .iter()
            .map(|&(m0, mx, my, area, peak)| Detection {
                x: x0 as f64 + mx / m0,
                y: y0 as f64 + my / m0,
                flux: m0,
                area,
                peak,
                saturated: false,
                sigma_px: None,
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame of background 100 with Gaussian sources (x, y, flux, sigma) and uniform noise
    /// of ±5 (σ 2.9) from a fixed hash of the pixel.
    fn frame(sources: &[(f64, f64, f64, f64)]) -> Frame<'static> {
        let (w, h) = (96u32, 96u32);
        let mut pixels = vec![0u16; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let hash = (x * 7919 + y * 104_729).wrapping_mul(2_654_435_761) >> 16;
                let mut v = 100.0 + (hash % 11) as f64 - 5.0;
                for &(sx, sy, f, s) in sources {
                    let r2 = (x as f64 - sx).powi(2) + (y as f64 - sy).powi(2);
                    v += f / (2.0 * std::f64::consts::PI * s * s) * (-r2 / (2.0 * s * s)).exp();
                }
                pixels[(y * w + x) as usize] = v.round() as u16;
            }
        }
        Frame {
            width: w,
            height: h,
            pixels: pixels.into(),
            saturation: 65535,
        }
    }

    fn merged(x: f64, y: f64) -> Detection {
        Detection {
            x,
            y,
            flux: 1.0,
            area: 60,
            peak: 0,
            saturated: false,
            sigma_px: None,
        }
    }

    /// Two sources 7 px apart in one component become two detections at their centres; one
    /// source, two 2 px apart, or a component that reaches another detection stay as they are.
    #[test]
    fn two_sources_split_and_one_stays() {
        let f = frame(&[(40.0, 48.0, 8000.0, 2.0), (47.0, 48.5, 4000.0, 2.0)]);
        let d = merged(42.3, 48.2);
        let out = deblend(&f, &[d], 5.0, 100);
        assert_eq!(out.len(), 2, "{out:?}");
        assert!(
            (out[0].x - 40.0).abs() < 0.3 && (out[0].y - 48.0).abs() < 0.3,
            "{out:?}"
        );
        assert!(
            (out[1].x - 47.0).abs() < 0.3 && (out[1].y - 48.5).abs() < 0.3,
            "{out:?}"
        );
        assert!(out[0].flux > out[1].flux);
        let other = merged(47.0, 48.5);
        assert_eq!(deblend(&f, &[d, other], 5.0, 100), vec![d, other]);
        for one in [
            frame(&[(40.0, 48.0, 8000.0, 2.0)]),
            frame(&[(40.0, 48.0, 8000.0, 2.0), (42.0, 48.0, 4000.0, 2.0)]),
        ] {
            let d = merged(40.5, 48.0);
            assert_eq!(deblend(&one, &[d], 5.0, 100), vec![d]);
        }
    }
}
