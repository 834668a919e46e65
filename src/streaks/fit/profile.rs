//! The along-track profile of a fitted track (a child of `fit`, whose model it reads):
//! [`StreakFit::modulation`](super::StreakFit::modulation),
//! [`StreakFit::local_snr`](super::StreakFit::local_snr) and the profile the chain test
//! (`streaks::chain`) reads.

use super::chain::{self, Chain};
use super::{Model, P};

impl Model {
    /// [`StreakFit::modulation`](super::StreakFit::modulation),
    /// [`StreakFit::local_snr`](super::StreakFit::local_snr) and
    /// [`StreakFit::chain`](super::StreakFit::chain) of the
    /// track between t = v0 and v1.
    pub(super) fn profile_stats(
        &self,
        q: &P,
        v0: f64,
        v1: f64,
        d: &dyn Fn(u32, u32) -> f64,
    ) -> (f64, f64, Chain) {
        let sg = q[5];
        let (s, c) = q[1].sin_cos();
        let (w, h) = (self.w as f64 - 1.0, self.h as f64 - 1.0);
        let profile = |t: f64, base: f64| -> Option<f64> {
            across(
                &|x, y| bilinear(d, (w, h), x, y),
                self.point(q, (s, c), t),
                (s, c),
                sg,
                base,
            )
        };
        let beside = 3.0 * sg + 4.0;
        let (mut on, mut off) = (Vec::new(), Vec::new());
        let mut t = v0 + 2.0 * sg;
        while t <= v1 - 2.0 * sg {
            if let Some(p) = profile(t, 0.0) {
                let o = profile(t, beside).or_else(|| profile(t, -beside));
                if let Some(o) = o {
                    on.push(p);
                    off.push(o);
                }
            }
            t += 1.0;
        }
        // The same filter along six parallel tracks beside this one (those wholly in the
        // frame), summed over the whole track; each track's samples above its own median by
        // more than 3 MADs (a star on it) taken at that bound, so that stars beside a short
        // track do not make the tracks' spread.
        let bases = [-3.0, -2.0, -1.0, 1.0, 2.0, 3.0].map(|k| k * beside);
        let (mut total, mut beside_samples, mut inside) =
            (0.0, [const { Vec::<f64>::new() }; 6], [true; 6]);
        let mut samples = 0usize;
        // At most about 150 positions along a long track.
        let step = ((v1 - v0) / 150.0).max(1.0);
        let mut t = v0;
        while t <= v1 {
            if let Some(p) = profile(t, 0.0) {
                total += p;
                samples += 1;
                for k in 0..6 {
                    match profile(t, bases[k]) {
                        Some(v) => beside_samples[k].push(v),
                        None => inside[k] = false,
                    }
                }
            }
            t += step;
        }
        let others: Vec<f64> = (0..6)
            .filter(|&k| inside[k])
            .map(|k| clipped_sum(&beside_samples[k]))
            .collect();
        // With fewer than three neighbour tracks in the frame (a streak along an edge) or a
        // handful of samples, there is nothing to compare with.
        // Median and MAD: a neighbour track may hold another streak of a train, or a star.
        let local_snr = if others.len() >= 3 && samples >= 4 {
            let mut o = others.clone();
            o.sort_by(f64::total_cmp);
            let level = o[o.len() / 2];
            let mut dev: Vec<f64> = o.iter().map(|v| (v - level).abs()).collect();
            dev.sort_by(f64::total_cmp);
            (total - level) / (1.4826 * dev[dev.len() / 2]).max(1e-9)
        } else {
            f64::INFINITY
        };
        let no_chain = chain::assess(&[], 0.0, sg, &|_| None);
        if on.len() < 8 {
            return (0.0, local_snr, no_chain);
        }
        // The whole track in 1 px steps, a PSF's reach beyond the ends included, for the
        // point-source model; its noise is the scatter of the profile beside the track. Both
        // without spikes: a pixel more than twice as high as every neighbour (a hot pixel, a
        // cosmic ray's) is taken at its highest neighbour's value; no PSF is that sharp, and on
        // a chain of stars a spike would pass for light no star makes.
        let med = |x: u32, y: u32| -> f64 {
            let v = d(x, y);
            let mut m = f64::MIN;
            for yy in y.saturating_sub(1)..=(y + 1).min(self.h - 1) {
                for xx in x.saturating_sub(1)..=(x + 1).min(self.w - 1) {
                    let a = d(xx, yy);
                    if (xx, yy) != (x, y) && a.is_finite() {
                        m = m.max(a);
                    }
                }
            }
            if m > f64::MIN && v > 2.0 * m.max(0.0) {
                m
            } else {
                v
            }
        };
        let profile_med = |t: f64, base: f64| -> Option<f64> {
            across(
                &|x, y| bilinear(&med, (w, h), x, y),
                self.point(q, (s, c), t),
                (s, c),
                sg,
                base,
            )
        };
        let (mut track, mut beside_med) = (Vec::new(), Vec::new());
        let mut t = v0 - 2.0 * sg;
        while t <= v1 + 2.0 * sg {
            track.push(profile_med(t, 0.0).unwrap_or(f64::NAN));
            if let Some(o) = profile_med(t, beside).or_else(|| profile_med(t, -beside)) {
                beside_med.push(o);
            }
            t += 1.0;
        }
        // Sample i of `track` lies at t = t0 + i.
        let t0 = v0 - 2.0 * sg;
        let across_at = |i: usize| {
            sigma_across(
                &|x, y| bilinear(&med, (w, h), x, y),
                self.point(q, (s, c), t0 + i as f64),
                (s, c),
            )
        };
        let chain = if beside_med.len() >= 8 {
            chain::assess(&track, mad(&beside_med), sg, &across_at)
        } else {
            no_chain
        };
        let level = median(&mut on.clone());
        if level <= 0.0 {
            return (f64::INFINITY, local_snr, chain);
        }
        let excess = (mad(&on).powi(2) - mad(&off).powi(2)).max(0.0).sqrt();
        (excess / level, local_snr, chain)
    }
}

/// `d` at a point between pixel centres, bilinearly; None off the frame (`w`, `h`: the last
/// column and row) or where a pixel is not finite.
fn bilinear(d: &dyn Fn(u32, u32) -> f64, (w, h): (f64, f64), x: f64, y: f64) -> Option<f64> {
    if !(0.0..=w).contains(&x) || !(0.0..=h).contains(&y) {
        return None;
    }
    let (x0, y0) = (
        x.floor().min(w - 1.0).max(0.0),
        y.floor().min(h - 1.0).max(0.0),
    );
    let (fx, fy) = (x - x0, y - y0);
    let (xi, yi) = (x0 as u32, y0 as u32);
    let v = |dx: u32, dy: u32| d(xi + dx, yi + dy);
    let b = (1.0 - fx) * (1.0 - fy) * v(0, 0)
        + fx * (1.0 - fy) * v(1, 0)
        + (1.0 - fx) * fy * v(0, 1)
        + fx * fy * v(1, 1);
    b.is_finite().then_some(b)
}

/// How far across the track [`sigma_across`] looks, each way (pixels): beyond a PSF's
/// reach on the frames a streak search is for (σ up to about 2 px), short of most neighbours.
const ACROSS_REACH: f64 = 6.0;

/// The σ of the light across the track at the track point `(px, py)`: a Gaussian (amplitude,
/// centre, σ) fitted to `at` summed over three points along the track (1 px apart), in
/// half-pixel steps out to [`ACROSS_REACH`]; its centre need not be on the line (a star of a
/// chain sits a little off it). Started from the weighted log-parabola through the samples
/// above a fifth of the highest, then Gauss–Newton. None where a sample is off the frame, the
/// light is not a peak, or the fit leaves 0.3–5 px.
fn sigma_across(
    at: &dyn Fn(f64, f64) -> Option<f64>,
    (px, py): (f64, f64),
    (s, c): (f64, f64),
) -> Option<f64> {
    let n = (2.0 * ACROSS_REACH / 0.5) as usize + 1;
    let mut u = Vec::with_capacity(n);
    let mut y = Vec::with_capacity(n);
    for k in 0..n {
        let o = -ACROSS_REACH + 0.5 * k as f64;
        let mut sum = 0.0;
        for dt in [-1.0, 0.0, 1.0] {
            sum += at(px + dt * c - o * s, py + dt * s + o * c)?;
        }
        u.push(o);
        y.push(sum);
    }
    let top = y.iter().copied().fold(f64::MIN, f64::max);
    if top <= 0.0 {
        return None;
    }
    // ln y = α + β u + γ u², weighted by y² (noise in ln y goes as 1/y).
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut r = nalgebra::Vector3::<f64>::zeros();
    for (&ui, &yi) in u.iter().zip(&y) {
        if yi > 0.2 * top {
            let b = nalgebra::Vector3::new(1.0, ui, ui * ui);
            m += yi * yi * b * b.transpose();
            r += yi * yi * yi.ln() * b;
        }
    }
    let g = m.lu().solve(&r)?;
    if g[2] >= 0.0 {
        return None;
    }
    let mut sigma = (-0.5 / g[2]).sqrt();
    let mut centre = (g[1] * sigma * sigma).clamp(-1.5, 1.5);
    let mut amp = top;
    for _ in 0..8 {
        // Gauss–Newton in (amplitude, centre, σ).
        let mut jtj = nalgebra::Matrix3::<f64>::zeros();
        let mut jtr = nalgebra::Vector3::<f64>::zeros();
        for (&ui, &yi) in u.iter().zip(&y) {
            let d = ui - centre;
            let e = (-0.5 * d * d / (sigma * sigma)).exp();
            let j = nalgebra::Vector3::new(
                e,
                amp * e * d / (sigma * sigma),
                amp * e * d * d / (sigma * sigma * sigma),
            );
            jtj += j * j.transpose();
            jtr += j * (yi - amp * e);
        }
        let step = jtj.lu().solve(&jtr)?;
        amp += step[0];
        centre = (centre + step[1]).clamp(-ACROSS_REACH, ACROSS_REACH);
        sigma = (sigma + step[2]).clamp(0.2, 8.0);
    }
    (amp > 0.0 && centre.abs() <= 1.5 && (0.3..=5.0).contains(&sigma)).then_some(sigma)
}

/// The profile across the track at the track point `(px, py)` around offset `base`: `at`
/// weighted by the fitted profile (σ `sg`), ±1.5σ in half-pixel steps.
fn across(
    at: &dyn Fn(f64, f64) -> Option<f64>,
    (px, py): (f64, f64),
    (s, c): (f64, f64),
    sg: f64,
    base: f64,
) -> Option<f64> {
    let mut sum = 0.0;
    let mut o = -1.5 * sg;
    while o <= 1.5 * sg {
        let g = (-o * o / (2.0 * sg * sg)).exp();
        sum += g * at(px - (base + o) * s, py + (base + o) * c)?;
        o += 0.5;
    }
    Some(sum)
}

/// The sum of `v`, each value above the median by more than 3 MADs (1.4826 · the median
/// absolute deviation) taken at that bound: noise alone passes it once in 700.
fn clipped_sum(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let top = median(&mut v.to_vec()) + 3.0 * mad(v);
    v.iter().map(|&x| x.min(top)).sum()
}

/// The median of `v` (its upper middle value; `v` reordered). `v` is not empty.
fn median(v: &mut [f64]) -> f64 {
    let m = v.len() / 2;
    *v.select_nth_unstable_by(m, f64::total_cmp).1
}

/// 1.4826 · the median absolute deviation of `v` from its median. `v` is not empty.
fn mad(v: &[f64]) -> f64 {
    let m = median(&mut v.to_vec());
    let mut dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    1.4826 * median(&mut dev)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sigma_across_measures_the_light_not_the_line() {
        // A star of σ 1.3 px, 0.4 px off a track along x = y (the light falls as a Gaussian
        // in the distance from the star's centre).
        let (s, c) = std::f64::consts::FRAC_1_SQRT_2.sin_cos();
        let (sx, sy) = (50.0 - 0.4 * s, 50.0 + 0.4 * c);
        let star = |x: f64, y: f64| {
            let r2 = (x - sx).powi(2) + (y - sy).powi(2);
            Some(40.0 * (-0.5 * r2 / 1.69).exp())
        };
        let sigma = sigma_across(&star, (50.0, 50.0), (s, c)).unwrap();
        assert!((sigma - 1.3).abs() < 0.01, "{sigma}");
        // No light, or the track off the frame: nothing measured.
        assert_eq!(sigma_across(&|_, _| Some(0.0), (50.0, 50.0), (s, c)), None);
        assert_eq!(sigma_across(&|_, _| None, (50.0, 50.0), (s, c)), None);
    }
}
