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
        // frame), summed over the whole track.
        let bases = [-3.0, -2.0, -1.0, 1.0, 2.0, 3.0].map(|k| k * beside);
        let (mut total, mut totals, mut inside) = (0.0, [0.0f64; 6], [true; 6]);
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
                        Some(v) => totals[k] += v,
                        None => inside[k] = false,
                    }
                }
            }
            t += step;
        }
        let others: Vec<f64> = (0..6).filter(|&k| inside[k]).map(|k| totals[k]).collect();
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
        let no_chain = chain::assess(&[], 0.0, sg);
        if on.len() < 8 {
            return (0.0, local_snr, no_chain);
        }
        let median = |v: &mut Vec<f64>| {
            let m = v.len() / 2;
            *v.select_nth_unstable_by(m, f64::total_cmp).1
        };
        let mad = |v: &Vec<f64>| {
            let mut c = v.clone();
            let m = median(&mut c);
            let mut dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
            1.4826 * median(&mut dev)
        };
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
        let chain = if beside_med.len() >= 8 {
            chain::assess(&track, mad(&beside_med), sg)
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
