//! Stage `psf_fit` (CPU, f64; no GPU twin yet): the maximum-likelihood position of a star from a
//! pixel-integrated Gaussian fitted to a 9×9 window (seed 003 (b); notes/sequences.md 3.3).
//!
//! Model: μ_k = b + N·Px_k·Py_k, with Px_k = Φ((x_k + ½ − x₀)/σ) − Φ((x_k − ½ − x₀)/σ) the
//! Gaussian's share of pixel column k (Py likewise). Noise: Poisson on the signal plus the
//! background's own variance, var_k = σ_b² + κ·max(μ_k − b, 0), with σ_b from the window's
//! border and κ = σ_b²/b (the background taken as photon noise: gain and bias are unknown; it
//! only weighs the pixels). A fixed number of Fisher-scoring steps in θ = (x₀, y₀, N, b, σ);
//! the position's 1σ from the inverse Fisher information.

use nalgebra::{SMatrix, SVector};

/// Half the window's side: 9×9 pixels, ±4 px (3.3σ for σ = 1.2 px).
pub const HALF: i64 = 4;
/// Fisher-scoring steps.
pub const ITERATIONS: usize = 8;

/// A fitted star.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PsfFit {
    pub x: f64,
    pub y: f64,
    /// Total signal (ADU) and background (ADU per pixel).
    pub flux: f64,
    pub background: f64,
    /// The Gaussian's sigma (pixels).
    pub sigma: f64,
    /// 1σ of x and y (pixels), from the Fisher information.
    pub sx: f64,
    pub sy: f64,
}

type V5 = SVector<f64, 5>;
type M5 = SMatrix<f64, 5, 5>;

/// Fit the star whose centre of gravity is (x0, y0); None when its window leaves the frame or
/// the fit does not settle (it strays over a pixel from the start, or its width leaves
/// 0.3–4 px): the centre of gravity then stands.
pub fn psf_fit(pixels: &[u16], width: u32, height: u32, x0: f64, y0: f64) -> Option<PsfFit> {
    let (cx, cy) = (x0.round() as i64, y0.round() as i64);
    if cx - HALF < 0 || cy - HALF < 0 || cx + HALF >= width as i64 || cy + HALF >= height as i64 {
        return None;
    }
    let side = (2 * HALF + 1) as usize;
    let mut d = Vec::with_capacity(side * side);
    for y in cy - HALF..=cy + HALF {
        for x in cx - HALF..=cx + HALF {
            d.push(pixels[(y * width as i64 + x) as usize] as f64);
        }
    }
    // Background and its noise from the window's border.
    let mut border: Vec<f64> = (0..side * side)
        .filter(|&i| {
            let (x, y) = (i % side, i / side);
            x == 0 || y == 0 || x == side - 1 || y == side - 1
        })
        .map(|i| d[i])
        .collect();
    border.sort_by(f64::total_cmp);
    let b0 = border[border.len() / 2];
    let mut dev: Vec<f64> = border.iter().map(|v| (v - b0).abs()).collect();
    dev.sort_by(f64::total_cmp);
    let var_b = (1.4826 * dev[dev.len() / 2]).max(0.5).powi(2);
    let kappa = if b0 > var_b { var_b / b0 } else { 1.0 };
    let flux0: f64 = d.iter().map(|v| v - b0).sum::<f64>().max(1.0);
    let mut t = V5::new(x0, y0, flux0, b0, 1.0);
    let mut info = M5::zeros();
    for _ in 0..ITERATIONS {
        let (score, fisher) = score_and_fisher(&d, cx, cy, &t, var_b, kappa);
        info = fisher;
        let step = fisher.cholesky()?.solve(&score);
        // Damped: at most half a pixel, a third of the width, half the flux a step.
        let scale = [
            0.5 / step[0].abs().max(1e-12),
            0.5 / step[1].abs().max(1e-12),
            0.5 * t[2] / step[2].abs().max(1e-12),
            f64::INFINITY,
            t[4] / 3.0 / step[4].abs().max(1e-12),
        ]
        .into_iter()
        .fold(1.0f64, f64::min);
        t += step * scale;
        if !t.iter().all(|v| v.is_finite()) || t[2] <= 0.0 {
            return None;
        }
        t[4] = t[4].clamp(0.2, 5.0);
    }
    let settled =
        (t[0] - x0).abs() <= 1.0 && (t[1] - y0).abs() <= 1.0 && (0.3..=4.0).contains(&t[4]);
    let cov = info.cholesky()?.inverse();
    settled.then(|| PsfFit {
        x: t[0],
        y: t[1],
        flux: t[2],
        background: t[3],
        sigma: t[4],
        sx: cov[(0, 0)].max(0.0).sqrt(),
        sy: cov[(1, 1)].max(0.0).sqrt(),
    })
}

/// The score (gradient of the log-likelihood) and the Fisher information at θ.
fn score_and_fisher(d: &[f64], cx: i64, cy: i64, t: &V5, var_b: f64, kappa: f64) -> (V5, M5) {
    let (x0, y0, n, b, s) = (t[0], t[1], t[2], t[3], t[4]);
    let side = (2 * HALF + 1) as usize;
    // Per column and per row: the share P, dP/dcentre, dP/dσ.
    let axis = |c: i64, centre: f64| -> Vec<(f64, f64, f64)> {
        (-HALF..=HALF)
            .map(|k| {
                let (lo, hi) = ((c + k) as f64 - 0.5 - centre, (c + k) as f64 + 0.5 - centre);
                let cdf = |u: f64| 0.5 * (1.0 + libm::erf(u / (s * std::f64::consts::SQRT_2)));
                let pdf = |u: f64| {
                    (-0.5 * (u / s).powi(2)).exp() / (s * (2.0 * std::f64::consts::PI).sqrt())
                };
                let p = cdf(hi) - cdf(lo);
                let dp_dc = pdf(lo) - pdf(hi);
                let dp_ds = (lo * pdf(lo) - hi * pdf(hi)) / s;
                (p, dp_dc, dp_ds)
            })
            .collect()
    };
    let (ax, ay) = (axis(cx, x0), axis(cy, y0));
    let mut score = V5::zeros();
    let mut fisher = M5::zeros();
    for (i, v) in d.iter().enumerate() {
        let ((px, dpx, spx), (py, dpy, spy)) = (ax[i % side], ay[i / side]);
        let signal = n * px * py;
        let mu = b + signal;
        let w = 1.0 / (var_b + kappa * signal.max(0.0));
        let j = V5::new(
            n * dpx * py,
            n * px * dpy,
            px * py,
            1.0,
            n * (spx * py + px * spy),
        );
        score += j * (w * (v - mu));
        fisher += j * j.transpose() * w;
    }
    (score, fisher)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A noise-free pixel-integrated Gaussian: the fit returns its centre, width and flux.
    #[test]
    fn recovers_a_noise_free_star() {
        let (w, h) = (32u32, 32u32);
        let (x0, y0, s, n, b) = (15.3, 16.7, 1.2, 5000.0, 100.0);
        let phi = |u: f64| 0.5 * (1.0 + libm::erf(u / (s * std::f64::consts::SQRT_2)));
        let px: Vec<u16> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let p = (phi(x + 0.5 - x0) - phi(x - 0.5 - x0))
                    * (phi(y + 0.5 - y0) - phi(y - 0.5 - y0));
                (b + n * p).round() as u16
            })
            .collect();
        let f = psf_fit(&px, w, h, 15.0, 17.0).unwrap();
        assert!((f.x - x0).abs() < 0.01 && (f.y - y0).abs() < 0.01, "{f:?}");
        assert!(
            (f.sigma - s).abs() < 0.02 && (f.flux / n - 1.0).abs() < 0.02,
            "{f:?}"
        );
        assert!(f.sx > 0.0 && f.sx < 0.1, "{f:?}");
        // At the frame's edge there is no window: None.
        assert!(psf_fit(&px, w, h, 2.0, 16.0).is_none());
    }
}
