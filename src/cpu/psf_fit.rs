//! Stage `psf_fit` (CPU twin of `shaders/psf_fit.wgsl`, f64 where the kernel is f32): the
//! maximum-likelihood position of a star from a pixel-integrated Gaussian fitted to a 9×9
//! window (seed 003 (b); notes/sequences.md 3.3).
//!
//! Model: μ_k = b + N·Px_k·Py_k, with Px_k the Gaussian's share of pixel column k (Py likewise).
//! Noise: Poisson on the signal plus the background's own variance, var_k = σ_b² + κ·max(μ_k − b,
//! 0), with σ_b from the window's border and κ = σ_b²/b (the background taken as photon noise:
//! gain and bias are unknown; it only weighs the pixels). [`ITERATIONS`] Fisher-scoring steps in
//! θ = (x₀, y₀, N, b, σ), each solved by Cholesky on the Jacobi-scaled information (so that f32
//! keeps its digits on the GPU); the position's 1σ from the inverse Fisher information.
//!
//! Coordinates inside the fit are relative to the window's centre pixel, where f32 is as fine
//! as f64 needs to be; the host adds the centre back in f64.

/// Half the window's side: 9×9 pixels, ±4 px (3.3σ for σ = 1.2 px).
pub const HALF: i64 = 4;
/// The window's side and pixel count.
pub const SIDE: usize = 2 * HALF as usize + 1;
pub const WINDOW: usize = SIDE * SIDE;
/// Fisher-scoring steps.
pub const ITERATIONS: usize = 6;
/// The narrowest width a settled fit may have (pixels), and where the steps clamp it: an
/// undersampled spot (σ 0.3 px puts 86 % of a centred star's light in one pixel) fits widths
/// scattered below its own, and its position is still the best there is.
pub const MIN_WIDTH: f64 = 0.15;
/// The least width a Fisher step may leave.
pub const WIDTH_CLAMP: f64 = 0.1;

/// A star's window: what the kernel reads per star.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    /// The centre pixel (the start rounded).
    pub cx: i64,
    pub cy: i64,
    /// The 9×9 pixels in raster order.
    pub pixels: [u32; WINDOW],
    /// The start (the centre of gravity) relative to the centre pixel, |·| ≤ ½.
    pub start: [f64; 2],
}

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

/// The window around a start (x0, y0); None when it leaves the frame.
pub fn window(pixels: &[u16], width: u32, height: u32, x0: f64, y0: f64) -> Option<Window> {
    let (cx, cy) = (x0.round() as i64, y0.round() as i64);
    if cx - HALF < 0 || cy - HALF < 0 || cx + HALF >= width as i64 || cy + HALF >= height as i64 {
        return None;
    }
    let mut w = Window {
        cx,
        cy,
        pixels: [0; WINDOW],
        start: [x0 - cx as f64, y0 - cy as f64],
    };
    for (i, p) in w.pixels.iter_mut().enumerate() {
        let (x, y) = (cx - HALF + (i % SIDE) as i64, cy - HALF + (i / SIDE) as i64);
        *p = pixels[(y * width as i64 + x) as usize] as u32;
    }
    Some(w)
}

/// The fit of one window; None when the fit does not settle (it strays over a pixel from the
/// start, its width leaves [`MIN_WIDTH`]–4 px, or the information is singular): the centre of gravity
/// then stands.
pub fn psf_fit(win: &Window) -> Option<PsfFit> {
    crate::simd::fast!(psf_fit_in(win: &Window) -> Option<PsfFit>)
}

/// [`psf_fit`], compiled where it is inlined (see [`crate::simd`]).
#[inline(always)]
fn psf_fit_in(win: &Window) -> Option<PsfFit> {
    let d: Vec<f64> = win.pixels.iter().map(|&v| v as f64).collect();
    // Background and its noise from the window's border (32 pixels: the upper median).
    let mut border: Vec<f64> = (0..WINDOW)
        .filter(|&i| {
            let (x, y) = (i % SIDE, i / SIDE);
            x == 0 || y == 0 || x == SIDE - 1 || y == SIDE - 1
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
    let mut t = [win.start[0], win.start[1], flux0, b0, 1.0];
    let mut info = [[0.0; 5]; 5];
    for _ in 0..ITERATIONS {
        let score;
        (score, info) = score_and_fisher(&d, &t, var_b, kappa);
        let step = solve(&info, &score)?;
        // Damped: at most half a pixel, a third of the width, half the flux a step.
        let limits = [0.5, 0.5, 0.5 * t[2], f64::INFINITY, t[4] / 3.0];
        let scale = (0..5)
            .map(|i| limits[i] / step[i].abs().max(1e-12))
            .fold(1.0f64, f64::min);
        for i in 0..5 {
            t[i] += step[i] * scale;
        }
        if !t.iter().all(|v| v.is_finite()) || t[2] <= 0.0 {
            return None;
        }
        t[4] = t[4].clamp(WIDTH_CLAMP, 5.0);
    }
    let settled = (t[0] - win.start[0]).abs() <= 1.0
        && (t[1] - win.start[1]).abs() <= 1.0
        && (MIN_WIDTH..=4.0).contains(&t[4]);
    let var_x = solve(&info, &[1.0, 0.0, 0.0, 0.0, 0.0])?[0];
    let var_y = solve(&info, &[0.0, 1.0, 0.0, 0.0, 0.0])?[1];
    settled.then(|| PsfFit {
        x: win.cx as f64 + t[0],
        y: win.cy as f64 + t[1],
        flux: t[2],
        background: t[3],
        sigma: t[4],
        sx: var_x.max(0.0).sqrt(),
        sy: var_y.max(0.0).sqrt(),
    })
}

/// Per column (or row) k of the window: the Gaussian's share P_k of the pixel, dP_k/dcentre and
/// dP_k/dσ, from the 10 pixel edges e_j = j − 4.5 − centre: at each the tail beyond |e_j|,
/// q_j = ½·erfc(|e_j|/(σ√2)) (from the side it is on: no cancellation in the tails, which
/// f32 needs), and the density g_j.
#[inline(always)]
fn axis(centre: f64, s: f64) -> [(f64, f64, f64); SIDE] {
    let mut e = [0.0; SIDE + 1];
    let mut q = [0.0; SIDE + 1];
    let mut g = [0.0; SIDE + 1];
    for j in 0..=SIDE {
        e[j] = j as f64 - HALF as f64 - 0.5 - centre;
        q[j] = 0.5 * libm::erfc(e[j].abs() / (s * std::f64::consts::SQRT_2));
        g[j] = (-0.5 * (e[j] / s).powi(2)).exp() / (s * (2.0 * std::f64::consts::PI).sqrt());
    }
    std::array::from_fn(|k| {
        let (lo, hi) = (k, k + 1);
        let share = if e[lo] >= 0.0 {
            q[lo] - q[hi]
        } else if e[hi] <= 0.0 {
            q[hi] - q[lo]
        } else {
            1.0 - q[hi] - q[lo]
        };
        (share, g[lo] - g[hi], (e[lo] * g[lo] - e[hi] * g[hi]) / s)
    })
}

/// The score (gradient of the log-likelihood) and the Fisher information at θ (its upper
/// triangle summed, then mirrored).
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn score_and_fisher(d: &[f64], t: &[f64; 5], var_b: f64, kappa: f64) -> ([f64; 5], [[f64; 5]; 5]) {
    let (n, b, s) = (t[2], t[3], t[4]);
    let (ax, ay) = (axis(t[0], s), axis(t[1], s));
    let mut score = [0.0; 5];
    let mut fisher = [[0.0; 5]; 5];
    for (i, v) in d.iter().enumerate() {
        let ((px, dpx, spx), (py, dpy, spy)) = (ax[i % SIDE], ay[i / SIDE]);
        let signal = n * px * py;
        let mu = b + signal;
        let w = 1.0 / (var_b + kappa * signal.max(0.0));
        let j = [
            n * dpx * py,
            n * px * dpy,
            px * py,
            1.0,
            n * (spx * py + px * spy),
        ];
        for a in 0..5 {
            let wa = j[a] * w;
            score[a] += wa * (v - mu);
            for c in a..5 {
                fisher[a][c] += wa * j[c];
            }
        }
    }
    for a in 0..5 {
        for c in 0..a {
            fisher[a][c] = fisher[c][a];
        }
    }
    (score, fisher)
}

/// Solve F·z = g for a symmetric positive definite F: Cholesky of D^-½·F·D^-½ (D = diag F);
/// None when F is not positive definite. Index loops, as the kernel's.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn solve(f: &[[f64; 5]; 5], g: &[f64; 5]) -> Option<[f64; 5]> {
    let mut dinv = [0.0; 5];
    for i in 0..5 {
        if f[i][i] <= 0.0 {
            return None;
        }
        dinv[i] = 1.0 / f[i][i].sqrt();
    }
    let mut l = [[0.0; 5]; 5];
    for i in 0..5 {
        for j in 0..=i {
            let mut sum = f[i][j] * dinv[i] * dinv[j];
            for k in 0..j {
                sum -= l[i][k] * l[j][k];
            }
            if i == j {
                if sum <= 0.0 {
                    return None;
                }
                l[i][i] = sum.sqrt();
            } else {
                l[i][j] = sum / l[j][j];
            }
        }
    }
    // L·y = D^-½·g, then Lᵀ·u = y, z = D^-½·u.
    let mut y = [0.0; 5];
    for i in 0..5 {
        let mut sum = g[i] * dinv[i];
        for k in 0..i {
            sum -= l[i][k] * y[k];
        }
        y[i] = sum / l[i][i];
    }
    let mut z = [0.0; 5];
    for i in (0..5).rev() {
        let mut sum = y[i];
        for k in i + 1..5 {
            sum -= l[k][i] * z[k];
        }
        z[i] = sum / l[i][i];
    }
    Some(std::array::from_fn(|i| z[i] * dinv[i]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit_at(pixels: &[u16], width: u32, height: u32, x0: f64, y0: f64) -> Option<PsfFit> {
        psf_fit(&window(pixels, width, height, x0, y0)?)
    }

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
        let f = fit_at(&px, w, h, 15.0, 17.0).unwrap();
        assert!((f.x - x0).abs() < 0.01 && (f.y - y0).abs() < 0.01, "{f:?}");
        assert!(
            (f.sigma - s).abs() < 0.02 && (f.flux / n - 1.0).abs() < 0.02,
            "{f:?}"
        );
        assert!(f.sx > 0.0 && f.sx < 0.1, "{f:?}");
        // At the frame's edge there is no window: None.
        assert!(fit_at(&px, w, h, 2.0, 16.0).is_none());
    }

    /// The scaled Cholesky solve inverts a known system.
    #[test]
    fn solve_inverts_a_positive_definite_system() {
        let f = [
            [4.0e6, 1.0e3, 2.0, 0.0, 5.0e2],
            [1.0e3, 3.0e6, 0.0, 1.0, 0.0],
            [2.0, 0.0, 1.0e-3, 1.0e-4, 0.0],
            [0.0, 1.0, 1.0e-4, 2.0, 0.0],
            [5.0e2, 0.0, 0.0, 0.0, 1.0e5],
        ];
        let z = [1.0, -2.0, 3.0, 0.5, -1.0];
        let g: [f64; 5] = std::array::from_fn(|i| (0..5).map(|j| f[i][j] * z[j]).sum());
        let got = solve(&f, &g).unwrap();
        for i in 0..5 {
            assert!(
                (got[i] - z[i]).abs() < 1e-9 * z[i].abs().max(1.0),
                "{got:?}"
            );
        }
        let mut bad = f;
        bad[3][3] = -1.0;
        assert!(solve(&bad, &g).is_none());
    }
}
