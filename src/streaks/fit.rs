//! Sub-pixel streak geometry: a least-squares fit (Levenberg–Marquardt, f64) of the image of
//! a point moving uniformly along a segment, seen through a Gaussian PSF:
//!
//! m(x, y) = B + A · exp(−δ²/2σ²) · ½[erf((t − t0)/√2σ) − erf((t − t1)/√2σ)]
//!
//! with δ the distance from the line and t the position along it. The ends t0, t1 are where
//! the along-track profile falls to half: for any symmetric PSF that is where the object was
//! at the exposure's start and end, not the last pixel above a threshold, which is a PSF
//! width beyond a bright streak's end and inside a faint one's. Pixels far off the model
//! (stars on the track, cosmic rays) are left out after a first fit and the fit is redone.

use super::chain::{self, Chain};
use super::segments::Segment;

// The along-track profile of a fitted track: modulation, local SNR, the chain test's input.
mod profile;
use nalgebra::{SMatrix, SVector};

/// The fitted streak, in pixels (x = column, y = row, 0-based pixel centres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreakFit {
    /// The two ends; an edge end is where the line leaves the frame.
    pub ends: [(f64, f64); 2],
    pub edge: [bool; 2],
    /// Gaussian σ of the profile across the track (pixels).
    pub sigma_px: f64,
    /// Peak amplitude above the background (ADU) and the noise of a pixel (ADU).
    pub amplitude: f64,
    pub noise: f64,
    /// Integrated flux of the part in the frame (ADU).
    pub flux: f64,
    /// Matched-filter signal-to-noise ratio of the part in the frame.
    pub snr: f64,
    /// RMS distance of the track's local centroids (4 px bins, less those holding a star: twice
    /// the track's light and more) from the fitted line (pixels).
    pub fit_rms_px: f64,
    /// Fraction of the track, in bins of 4 px where the fit expects a clear signal, where the
    /// data show less than a third of it: chains of stars have gaps, streaks do not.
    pub gap_fraction: f64,
    /// Excess scatter of the along-track profile over its median (robust, with the scatter of
    /// a parallel profile beside the track, noise alone, taken off): about 0 for a streak,
    /// 0.5 and more for a chain of stars.
    pub modulation: f64,
    /// The track's matched-filter sum against the same filter along six parallel tracks
    /// beside it (3σ + 4 px apart): how far it stands above them in their own scatter. Unlike
    /// `snr`, which takes the noise of single pixels, this holds where noise is correlated
    /// (fixed patterns, compression, diffuse light). Infinite where the neighbours leave the
    /// frame.
    pub local_snr: f64,
    /// What point sources make of the along-track profile: a chain of stars, or light that
    /// stars cannot make ([`chain`]).
    pub chain: Chain,
    /// Direction of the line (unit) and its angle from the frame's axes (degrees, 0–45).
    pub dir: (f64, f64),
    pub axis_angle_deg: f64,
}

/// Parameters: ρ (offset of the line along its normal), θ, t0, t1, A, σ, B.
type P = SVector<f64, 7>;

/// Every parameter fitted.
const FREE: [bool; 7] = [true; 7];
/// A pixel brighter than this many times the track's median at the start is a star's.
const STAR_OVER_TRACK: f64 = 3.0;
/// The ends (t0, t1) held, the rest fitted.
const HOLD_ENDS: [bool; 7] = [true, true, false, false, true, true, true];
/// A mask segment's end this close to the frame's last pixel (along the line) reaches the edge:
/// the binned mask and a start a few degrees off the line put it a few pixels short.
const MASK_AT_EDGE_PX: f64 = 8.0;

/// The pixels the fit sees: background-subtracted values around the segment.
struct Region {
    px: Vec<(f64, f64, f64)>,
    keep: Vec<bool>,
}

/// Fit the segment's streak in `d(x, y)` (pixel − background) of a `w`×`h` frame.
pub fn fit(d: &dyn Fn(u32, u32) -> f64, w: u32, h: u32, seg: &Segment) -> Option<StreakFit> {
    let (cx, cy) = seg.mid();
    let th0 = seg.uy.atan2(seg.ux);
    let half = 0.5 * seg.length();
    let region = Region::around(d, w, h, (cx, cy), th0, -half - 15.0, half + 15.0, 8.0);
    if region.px.len() < 20 {
        return None;
    }
    let model = Model { c: (cx, cy), w, h };
    // Start: the mask's extent, the median of the pixels on the line as amplitude.
    let mut on: Vec<f64> = region
        .px
        .iter()
        .filter(|p| {
            let (dd, t) = model.coords(p.0, p.1, 0.0, th0.sin_cos());
            dd.abs() <= 0.7 && t.abs() <= half
        })
        .map(|p| p.2)
        .collect();
    if on.is_empty() {
        return None;
    }
    on.sort_by(f64::total_cmp);
    let a0 = on[on.len() / 2].max(1.0);
    // Pixels far brighter than the track's median (a star on it) are left out from the start:
    // a fit started with them can settle on the star and never come back to the track.
    let mut region = region;
    let values: Vec<f64> = region.px.iter().map(|p| p.2).collect();
    if let Some(spread) = robust_sigma(&values) {
        let bright = STAR_OVER_TRACK * a0 + 5.0 * spread;
        region.keep = region.px.iter().map(|p| p.2 <= bright).collect();
    }
    let rho0 = cross_offset(d, w, h, (cx, cy), th0, half);
    let mut q = P::from_column_slice(&[rho0, th0, -half, half, a0, 1.2, 0.0]);
    // Where the mask reaches the frame's edge, the line, width and amplitude first, the ends
    // held where the mask puts them: started on a line a little off the track, a free fit
    // shortens the segment to what the line explains, and the rejection below then takes the
    // rest of the track, lit to the edge, for outliers. (Not where both ends are inside: a
    // mask that runs on past an end, into a crossing streak, would be locked in instead.)
    let at_edge = model
        .frame_span(&q)
        .is_some_and(|(lo, hi)| -half <= lo + MASK_AT_EDGE_PX || half >= hi - MASK_AT_EDGE_PX);
    if at_edge {
        q = model.levenberg_marquardt(&region, q, 10, HOLD_ENDS)?;
    }
    for round in 0..3 {
        q = model.levenberg_marquardt(&region, q, if round == 0 { 20 } else { 10 }, FREE)?;
        // Leave out what the model cannot be (stars on the track, cosmic rays), then refit.
        let r: Vec<f64> = region
            .px
            .iter()
            .map(|p| p.2 - model.value(p.0, p.1, &q, q[1].sin_cos()))
            .collect();
        let noise = robust_sigma(&r)?;
        let keep: Vec<bool> = r.iter().map(|v| v.abs() <= 4.0 * noise).collect();
        if keep == region.keep {
            break;
        }
        region.keep = keep;
    }
    model.result(&region, &q, d)
}

/// Where across the line through `c` at angle `th` the data peak, from −6 to 6 px in whole
/// pixels (the mean of d along the middle of the track at each offset): the segment found on
/// the binned mask can be a pixel or two off the track, further than the fit reaches.
fn cross_offset(
    d: &dyn Fn(u32, u32) -> f64,
    w: u32,
    h: u32,
    c: (f64, f64),
    th: f64,
    half: f64,
) -> f64 {
    let (s, co) = th.sin_cos();
    let mut best = (f64::MIN, 0.0);
    for o in -6..=6 {
        let o = o as f64;
        let (mut sum, mut n) = (0.0, 0usize);
        let mut t = -0.8 * half;
        while t <= 0.8 * half {
            let (x, y) = (
                (c.0 + t * co - o * s).round(),
                (c.1 + t * s + o * co).round(),
            );
            if x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64 {
                let v = d(x as u32, y as u32);
                if v.is_finite() {
                    sum += v;
                    n += 1;
                }
            }
            t += 1.0;
        }
        if n > 0 && sum / n as f64 > best.0 {
            best = (sum / n as f64, o);
        }
    }
    best.1
}

impl Region {
    /// Pixels with |δ| ≤ `r` and t in [t_lo, t_hi] of the line through `c` at angle `th`.
    #[allow(clippy::too_many_arguments)]
    fn around(
        d: &dyn Fn(u32, u32) -> f64,
        w: u32,
        h: u32,
        c: (f64, f64),
        th: f64,
        t_lo: f64,
        t_hi: f64,
        r: f64,
    ) -> Region {
        let (ux, uy) = (th.cos(), th.sin());
        let middle = (t_hi - t_lo - 2.0 * END_ZONE).max(0.0);
        let keep_every = (middle / MIDDLE_SAMPLES).ceil().max(1.0) as i64;
        let corners = [(t_lo, -r), (t_lo, r), (t_hi, -r), (t_hi, r)]
            .map(|(t, n)| (c.0 + t * ux - n * uy, c.1 + t * uy + n * ux));
        let y0 = corners
            .iter()
            .map(|p| p.1)
            .fold(f64::MAX, f64::min)
            .floor()
            .max(0.0) as u32;
        let y1 = corners
            .iter()
            .map(|p| p.1)
            .fold(f64::MIN, f64::max)
            .ceil()
            .min(h as f64 - 1.0);
        let mut px = Vec::new();
        if y1 < 0.0 {
            return Region { px, keep: vec![] };
        }
        for y in y0..=y1 as u32 {
            // The x interval of this row inside the rotated rectangle: two slabs, each linear
            // in x (|δ| ≤ r and t_lo ≤ t ≤ t_hi).
            let (mut lo, mut hi) = (0.0f64, w as f64 - 1.0);
            let dy = y as f64 - c.1;
            for (a, b, min, max) in [(-uy, dy * ux, -r, r), (ux, dy * uy, t_lo, t_hi)] {
                // a·(x − cx) + b in [min, max]
                if a.abs() < 1e-12 {
                    if b < min || b > max {
                        hi = -1.0;
                    }
                    continue;
                }
                let (e0, e1) = ((min - b) / a + c.0, (max - b) / a + c.0);
                lo = lo.max(e0.min(e1));
                hi = hi.min(e0.max(e1));
            }
            if hi < lo {
                continue;
            }
            for x in lo.ceil() as u32..=hi.floor() as u32 {
                // Along a long track, the middle fixes only the line, width and amplitude:
                // one pixel of `keep_every` along it is as good there, and all near the ends.
                let t = (x as f64 - c.0) * ux + dy * uy;
                let near_end = t - t_lo < END_ZONE || t_hi - t < END_ZONE;
                if !near_end && (t.floor() as i64).rem_euclid(keep_every) != 0 {
                    continue;
                }
                let v = d(x, y);
                if v.is_finite() {
                    px.push((x as f64, y as f64, v));
                }
            }
        }
        let keep = vec![true; px.len()];
        Region { px, keep }
    }
}

/// A track whose profile's excess scatter exceeds this share of its level has its ends fitted
/// again, each with its own brightness ([`Model::refine_end`]); a steady streak's is about 0.
const MODULATED: f64 = 0.3;

/// Pixels this far (along the track) from either end of the search are all fitted.
const END_ZONE: f64 = 20.0;
/// Positions along the track's middle that are fitted, at most (every k-th pixel of t).
const MIDDLE_SAMPLES: f64 = 80.0;

struct Model {
    /// Reference point of the parametrisation.
    c: (f64, f64),
    w: u32,
    h: u32,
}

const SQRT_2PI: f64 = 2.506_628_274_631_000_7;

impl Model {
    /// (δ, t) of a pixel for the line (ρ, θ), with (sin θ, cos θ) given: callers work them out
    /// once per parameter vector, not once per pixel.
    fn coords(&self, x: f64, y: f64, rho: f64, (s, c): (f64, f64)) -> (f64, f64) {
        let (dx, dy) = (x - self.c.0, y - self.c.1);
        (-dx * s + dy * c - rho, dx * c + dy * s)
    }

    fn value(&self, x: f64, y: f64, q: &P, sc: (f64, f64)) -> f64 {
        let (dd, t) = self.coords(x, y, q[0], sc);
        let (a, sg, b) = (q[4], q[5], q[6]);
        if dd.abs() > FAR * sg {
            return b;
        }
        let g = (-dd * dd / (2.0 * sg * sg)).exp();
        b + a * g * along(t, q[2], q[3], sg)
    }

    /// Value and gradient with respect to the parameters.
    fn gradient(&self, x: f64, y: f64, q: &P, sc: (f64, f64)) -> (f64, P) {
        let (dd, t) = self.coords(x, y, q[0], sc);
        let (t0, t1, a, sg, b) = (q[2], q[3], q[4], q[5], q[6]);
        let far_end = t < t0 - FAR * sg || t > t1 + FAR * sg;
        if dd.abs() > FAR * sg || far_end {
            // Beyond the profile's reach (e^-32 of it): only the background counts.
            return (
                b,
                P::from_column_slice(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]),
            );
        }
        let g = (-dd * dd / (2.0 * sg * sg)).exp();
        if t > t0 + FAR * sg && t < t1 - FAR * sg {
            // Mid-track: the along-track factor is 1 and its derivatives vanish.
            let dg_dd = -dd / (sg * sg) * g;
            let dg_ds = dd * dd / (sg * sg * sg) * g;
            let grad =
                P::from_column_slice(&[-a * dg_dd, a * dg_dd * -t, 0.0, 0.0, g, a * dg_ds, 1.0]);
            return (b + a * g, grad);
        }
        let e = along(t, t0, t1, sg);
        let k = 1.0 / (SQRT_2PI * sg);
        let e0 = (-(t - t0).powi(2) / (2.0 * sg * sg)).exp();
        let e1 = (-(t - t1).powi(2) / (2.0 * sg * sg)).exp();
        let de_dt = k * (e0 - e1);
        let dg_dd = -dd / (sg * sg) * g;
        let dg_ds = dd * dd / (sg * sg * sg) * g;
        let de_ds = -k / sg * ((t - t0) * e0 - (t - t1) * e1);
        // dδ/dρ = −1, dδ/dθ = −t, dt/dθ = δ + ρ.
        let grad = P::from_column_slice(&[
            -a * e * dg_dd,
            a * (e * dg_dd * -t + g * de_dt * (dd + q[0])),
            -a * g * k * e0,
            a * g * k * e1,
            g * e,
            a * (e * dg_ds + g * de_ds),
            1.0,
        ]);
        (b + a * g * e, grad)
    }

    /// Where the line (ρ, θ) enters and leaves the frame's pixel-centre box, as t.
    fn frame_span(&self, q: &P) -> Option<(f64, f64)> {
        let (s, c) = q[1].sin_cos();
        let p0 = (self.c.0 - q[0] * s, self.c.1 + q[0] * c);
        let (mut lo, mut hi) = (f64::MIN, f64::MAX);
        for (p, u, max) in [
            (p0.0, c, self.w as f64 - 1.0),
            (p0.1, s, self.h as f64 - 1.0),
        ] {
            if u.abs() < 1e-12 {
                if p < 0.0 || p > max {
                    return None;
                }
                continue;
            }
            let (a, b) = ((0.0 - p) / u, (max - p) / u);
            lo = lo.max(a.min(b));
            hi = hi.min(a.max(b));
        }
        (hi > lo).then_some((lo, hi))
    }

    /// The point at t on the line (ρ, θ), (sin θ, cos θ) given.
    fn point(&self, q: &P, (s, c): (f64, f64), t: f64) -> (f64, f64) {
        (self.c.0 - q[0] * s + t * c, self.c.1 + q[0] * c + t * s)
    }

    /// Keep the parameters where the model means something: σ in [0.3, 15] px, the ends in
    /// order and no more than 4σ outside the frame (beyond, no pixel tells where they are).
    fn clamp(&self, q: &mut P) {
        q[5] = q[5].clamp(0.3, 15.0);
        if let Some((lo, hi)) = self.frame_span(q) {
            (q[2], q[3]) = clamp_ends(q[2], q[3], lo, hi, 4.0 * q[5]);
        }
    }

    fn cost(&self, r: &Region, q: &P) -> f64 {
        let sc = q[1].sin_cos();
        r.px.iter()
            .zip(&r.keep)
            .filter(|(_, k)| **k)
            .map(|(p, _)| (p.2 - self.value(p.0, p.1, q, sc)).powi(2))
            .sum()
    }

    /// Least squares from `q`, the parameters where `free` is false held.
    fn levenberg_marquardt(
        &self,
        r: &Region,
        mut q: P,
        iterations: usize,
        free: [bool; 7],
    ) -> Option<P> {
        let mut cost = self.cost(r, &q);
        let mut lambda = 1e-3;
        for _ in 0..iterations {
            let mut jtj = SMatrix::<f64, 7, 7>::zeros();
            let mut jtr = P::zeros();
            let sc = q[1].sin_cos();
            for (p, _) in r.px.iter().zip(&r.keep).filter(|(_, k)| **k) {
                let (m, mut g) = self.gradient(p.0, p.1, &q, sc);
                for (gi, f) in g.iter_mut().zip(free) {
                    if !f {
                        *gi = 0.0;
                    }
                }
                jtj += g * g.transpose();
                jtr += g * (p.2 - m);
            }
            let mut improved = false;
            while lambda < 1e10 {
                let mut a = jtj;
                let scale = (0..7).map(|i| jtj[(i, i)]).fold(0.0, f64::max) * 1e-12;
                for i in 0..7 {
                    a[(i, i)] += lambda * jtj[(i, i)] + scale + 1e-30;
                }
                let step = a.cholesky().map(|c| c.solve(&jtr));
                if let Some(step) = step {
                    let mut next = q + step;
                    self.clamp(&mut next);
                    let c = self.cost(r, &next);
                    if c.is_finite() && c <= cost {
                        let small = (cost - c) <= 1e-8 * cost;
                        q = next;
                        cost = c;
                        lambda = (lambda * 0.3).max(1e-9);
                        improved = true;
                        if small {
                            return Some(q);
                        }
                        break;
                    }
                }
                lambda *= 10.0;
            }
            if !improved {
                break;
            }
        }
        q.iter().all(|v| v.is_finite()).then_some(q)
    }

    fn result(&self, r: &Region, q: &P, d: &dyn Fn(u32, u32) -> f64) -> Option<StreakFit> {
        let sc = q[1].sin_cos();
        let (t0, t1, a, sg) = (q[2], q[3], q[4], q[5]);
        if a <= 0.0 {
            return None;
        }
        let (lo, hi) = self.frame_span(q)?;
        // An end the fit puts at or beyond the frame's last pixel is where the streak leaves.
        let edge = [t0 <= lo + 1.0, t1 >= hi - 1.0];
        let (v0, v1) = (if edge[0] { lo } else { t0 }, if edge[1] { hi } else { t1 });
        if v1 <= v0 {
            return None;
        }
        let resid: Vec<f64> =
            r.px.iter()
                .zip(&r.keep)
                .filter(|(_, k)| **k)
                .map(|(p, _)| p.2 - self.value(p.0, p.1, q, sc))
                .collect();
        let noise = robust_sigma(&resid)?;
        let g2: f64 =
            r.px.iter()
                .map(|p| ((self.value(p.0, p.1, q, sc) - q[6]) / a).powi(2))
                .sum();
        // Local centroids across the track, and how often the data fall short of the model.
        let (s, c) = sc;
        let (mut dev2, mut bins) = (0.0, 0usize);
        let (mut clear, mut gaps) = (0usize, 0usize);
        let half_width = (2.5 * sg).max(2.0);
        let mut t = v0 + 2.0 * sg;
        while t + 4.0 <= v1 - 2.0 * sg {
            let (mut sw, mut swd, mut sm, mut sd, mut n) = (0.0, 0.0, 0.0, 0.0, 0usize);
            let mut u = t;
            while u < t + 4.0 {
                let mut off = -half_width;
                while off <= half_width {
                    let (x, y) = self.point(q, sc, u);
                    let (x, y) = (x - off * s, y + off * c);
                    let (xi, yi) = (x.round(), y.round());
                    let inside = xi >= 0.0 && yi >= 0.0 && xi < self.w as f64 && yi < self.h as f64;
                    let v = if inside {
                        d(xi as u32, yi as u32) - q[6]
                    } else {
                        f64::NAN
                    };
                    if v.is_finite() {
                        let (dd, _) = self.coords(xi, yi, q[0], sc);
                        sw += v;
                        swd += v * dd;
                        sm += self.value(xi, yi, q, sc) - q[6];
                        sd += v;
                        n += 1;
                    }
                    off += 1.0;
                }
                u += 1.0;
            }
            let bin_noise = noise * (n as f64).sqrt();
            if sm > 4.0 * bin_noise {
                clear += 1;
                if sd < sm / 3.0 {
                    gaps += 1;
                }
            }
            // A bin holding twice the track's light and more is a star on it (or a glint): its
            // centroid is the star's, not the track's.
            let star = sd - sm > (5.0 * bin_noise).max(sm);
            if sw > 3.0 * bin_noise && !star {
                let cent = swd / sw;
                dev2 += cent * cent;
                bins += 1;
            }
            t += 4.0;
        }
        let axis = s.abs().min(c.abs()).asin().to_degrees();
        let (modulation, local_snr, chain) = self.profile_stats(q, v0, v1, d);
        // A tumbling object's brightness at an end is not the track's mean: an end where it
        // is brighter lies where the mean's half falls, outside the end (by 0.5σ at 1.6
        // times the mean). On a modulated track each end inside the frame is fitted again with
        // the brightness there.
        let (mut e0, mut e1) = (v0, v1);
        if modulation > MODULATED {
            if !edge[0] {
                e0 = self.refine_end(r, q, 0).unwrap_or(v0);
            }
            if !edge[1] {
                e1 = self.refine_end(r, q, 1).unwrap_or(v1);
            }
            if e1 <= e0 {
                (e0, e1) = (v0, v1);
            }
        }
        // An end whose PSF reaches the frame's last pixel (within 2σ of it) is where the
        // streak leaves: the object may have gone on past it. (A tumbling object's end fitted
        // again with its brightness there can land on the edge or past it.)
        let reach = (2.0 * sg).max(1.0);
        let mut edge = edge;
        if !edge[0] && e0 <= lo + reach {
            (edge[0], e0) = (true, lo);
        }
        if !edge[1] && e1 >= hi - reach {
            (edge[1], e1) = (true, hi);
        }
        // So is an end whose PSF reaches a side across the line, within 2σ of the last pixel
        // along the normal (−sin θ, cos θ): a streak grazing that side, which it leaves far
        // along its line. Flagged, and left where it is.
        let (w, h) = (self.w as f64 - 1.0, self.h as f64 - 1.0);
        let to = |room: f64, rate: f64| if rate > 1e-12 { room / rate } else { f64::MAX };
        let across =
            |(x, y): (f64, f64)| to(x.min(w - x), sc.0.abs()).min(to(y.min(h - y), sc.1.abs()));
        for (k, e) in [e0, e1].into_iter().enumerate() {
            edge[k] |= across(self.point(q, sc, e)) <= reach;
        }
        Some(StreakFit {
            ends: [self.point(q, sc, e0), self.point(q, sc, e1)],
            edge,
            sigma_px: sg,
            amplitude: a,
            noise,
            flux: a * SQRT_2PI * sg * (v1 - v0),
            snr: a * g2.sqrt() / noise,
            fit_rms_px: if bins > 0 {
                (dev2 / bins as f64).sqrt()
            } else {
                0.0
            },
            gap_fraction: if clear > 0 {
                gaps as f64 / clear as f64
            } else {
                0.0
            },
            modulation,
            local_snr,
            chain,
            dir: (c, s),
            axis_angle_deg: axis,
        })
    }

    /// End `which` (0: t0, 1: t1) of the fit `q` fitted again with its own brightness: the
    /// step of the along-track profile and its height, from the pixels within 2.5σ of the line
    /// and 3σ + 6 px of the end (inwards; 3σ + 3 px outwards), the line, width and background
    /// held. Gauss–Newton in the two, pixels more than 4 noise sigmas off the first fit left
    /// out (a star near the end). None when it does not settle within 3σ + 2 px of the end.
    fn refine_end(&self, r: &Region, q: &P, which: usize) -> Option<f64> {
        let (sg, b) = (q[5], q[6]);
        let sc = q[1].sin_cos();
        let end = q[2 + which];
        let (inward, outward) = (3.0 * sg + 6.0, 3.0 * sg + 3.0);
        // +1 going into the track from the end.
        let into = if which == 0 { 1.0 } else { -1.0 };
        let mut px: Vec<(f64, f64, f64)> =
            r.px.iter()
                .filter_map(|p| {
                    let (dd, t) = self.coords(p.0, p.1, q[0], sc);
                    let u = (t - end) * into;
                    (dd.abs() <= 2.5 * sg && u >= -outward && u <= inward)
                        .then(|| ((-dd * dd / (2.0 * sg * sg)).exp(), t, p.2 - b))
                })
                .collect();
        if px.len() < 12 {
            return None;
        }
        let k = 1.0 / (std::f64::consts::SQRT_2 * sg);
        // The model at (g, t) for end te and height a, and its derivatives.
        let model = |g: f64, t: f64, te: f64, a: f64| {
            let step = 0.5 * (1.0 + libm::erf((t - te) * k * into));
            let dstep = -into * k / std::f64::consts::PI.sqrt() * (-((t - te) * k).powi(2)).exp();
            (a * g * step, a * g * dstep, g * step)
        };
        let (mut te, mut a) = (end, q[4]);
        for round in 0..2 {
            for _ in 0..10 {
                let (mut jtj, mut jtr) = ([[0.0f64; 2]; 2], [0.0f64; 2]);
                for &(g, t, v) in &px {
                    let (m, dte, da) = model(g, t, te, a);
                    let (j, res) = ([dte, da], v - m);
                    for i in 0..2 {
                        jtr[i] += j[i] * res;
                        for l in 0..2 {
                            jtj[i][l] += j[i] * j[l];
                        }
                    }
                }
                let det = jtj[0][0] * jtj[1][1] - jtj[0][1] * jtj[1][0];
                if det.is_nan() || det.abs() <= 1e-30 {
                    return None;
                }
                let d_te = (jtj[1][1] * jtr[0] - jtj[0][1] * jtr[1]) / det;
                let d_a = (jtj[0][0] * jtr[1] - jtj[1][0] * jtr[0]) / det;
                te += d_te.clamp(-sg, sg);
                a += d_a;
                if d_te.abs() < 1e-4 {
                    break;
                }
            }
            if round == 0 {
                let res: Vec<f64> = px
                    .iter()
                    .map(|&(g, t, v)| v - model(g, t, te, a).0)
                    .collect();
                let noise = robust_sigma(&res)?;
                let mut k = 0;
                px.retain(|_| {
                    k += 1;
                    res[k - 1].abs() <= 4.0 * noise
                });
            }
        }
        (a > 0.0 && te.is_finite() && (te - end).abs() <= 3.0 * sg + 2.0).then_some(te)
    }
}

/// The ends t0 < t1 kept within `m` of the frame's span [lo, hi] along the line and at least
/// a pixel apart. max/min, not clamp: the bounds come from rounding arithmetic and may cross
/// by an ulp (t0 at its upper bound plus 1 px can exceed t1's), where clamp panics.
fn clamp_ends(t0: f64, t1: f64, lo: f64, hi: f64, m: f64) -> (f64, f64) {
    let t0 = t0.max(lo - m).min(hi + m - 1.0);
    (t0, t1.min(hi + m).max(t0 + 1.0))
}

/// Distances (in σ) beyond which the profile is taken as 0 and the along-track factor as 0
/// or 1: e^(−5²/2) ≈ 4e-6 of the peak, below the noise of any streak short of SNR 10^5.
const FAR: f64 = 5.0;

/// The along-track factor: a unit step at t0 down again at t1, blurred by σ.
fn along(t: f64, t0: f64, t1: f64, sg: f64) -> f64 {
    if t > t0 + FAR * sg && t < t1 - FAR * sg {
        return 1.0;
    }
    if t < t0 - FAR * sg || t > t1 + FAR * sg {
        return 0.0;
    }
    let k = 1.0 / (std::f64::consts::SQRT_2 * sg);
    0.5 * (libm::erf((t - t0) * k) - libm::erf((t - t1) * k))
}

/// 1.4826 · median |v|: the noise of residuals that are mostly noise.
fn robust_sigma(v: &[f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    // Every k-th of a long streak's residuals: the median of a few thousand is as good.
    let step = (v.len() / 4096).max(1);
    let mut a: Vec<f64> = v.iter().step_by(step).map(|x| x.abs()).collect();
    let mid = a.len() / 2;
    let m = *a.select_nth_unstable_by(mid, f64::total_cmp).1;
    Some((1.4826 * m).max(1e-6))
}

/// The length between the ends in the frame (pixels).
pub fn length(f: &StreakFit) -> f64 {
    let [(x0, y0), (x1, y1)] = f.ends;
    ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt()
}

#[cfg(test)]
mod tests;
