//! Centroid study (issue 16, item 3): the position error of gpustar's two centroid estimators
//! (`--centroid cog` and `--centroid ml`), measured through the whole detection pipeline
//! (`gpustar::solve::detect::detect`: threshold, components, centre of gravity, then the ML fit), against
//! the Cramér–Rao bound, over PSF width, SNR and sub-pixel phase.
//!
//!     cargo run --release --example centroid_study -- OUT.csv
//!
//! The frames come from this file's own renderer (independent of `gpustar::simulate`):
//! 512×512 pixels, a 17×17 grid of stars 28 px apart (32 px from the edges), each a
//! pixel-integrated circular Gaussian of width σ holding N electrons, on a background of
//! b e⁻/px. Pixel (i, j) covers [i − ½, i + ½] × [j − ½, j + ½]: gpustar's convention.
//! Each pixel gets Poisson noise on signal + background, Gaussian read noise σ_r, gain
//! 1 e⁻/ADU, a bias, rounding and the u16 clamp.
//!
//! SNR = N / sqrt(N + 4πσ²·(b + σ_r²)); N is chosen to hit it.
//!
//! CRB per axis: [I⁻¹]₀₀ and [I⁻¹]₁₁ over θ = (x₀, y₀, N, b, σ), with
//! I_ij = Σ_k ∂_iμ_k ∂_jμ_k / (μ_k + σ_r²) on the 9×9 window centred on the star's nearest
//! pixel (the window gpustar's fit uses), μ_k = b + N·Px_k·Py_k in electrons.
//!
//! Sweeps (σ list: 0.3, 0.35, 0.4, 0.45, 0.5, 0.6, 0.7, 0.8, 1.0, 1.2, 1.5, 2.0 px):
//!   sigma  the σ list at SNR 10, 20, 50, 100 (random sub-pixel phase);
//!   snr    SNR 5 … 300 at σ = 0.8 and 1.2 px (random phase);
//!   phase  phase 0, ⅛, ¼, ⅜, ½ px (the same in x and y) at σ = 0.5 and 1.2, SNR 20 and 100;
//!   flux   the σ list at a fixed N = 500, 1000, 3000, 10000 e⁻ (random phase): what a
//!          designer choosing the optics for a given star faces;
//!   bias0  as snr at SNR 20 … 200, with a bias of 0 ADU instead of 100 (gpustar's fit takes
//!          the background level in ADU as photon noise to weigh its pixels).
//!
//! Rows per point: `cog`, `ml`, and `ml_settled` (the ML rows' stars whose fit settled, i.e.
//! whose ML position differs from the centre of gravity; `ml_fallbacks` counts the others).
//! Errors are per axis, x and y pooled, over the stars matched within 1.5 px; the CRB column is
//! sqrt of the stars' mean per-axis CRB, so err_over_crb = RMS / sqrt(mean CRB).
//!
//! Each point uses FRAMES frames (289 stars each) from its own seed, so the result does not
//! depend on the number of threads.

use gpustar::io::frame::Frame;
use gpustar::solve::detect::{Centroid, DetectSettings, Detection, detect};
use nalgebra::{SMatrix, SVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, Poisson};
use std::f64::consts::{PI, SQRT_2};
use std::fmt::Write as _;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

const SIZE: u32 = 512;
const GRID: usize = 17;
const SPACING: f64 = 28.0;
const MARGIN: f64 = 32.0;
/// Background (e⁻/px) and read noise (e⁻).
const BACKGROUND: f64 = 50.0;
const READ_NOISE: f64 = 5.0;
/// Bias (ADU) of every sweep but `bias0`.
const BIAS: f64 = 100.0;
/// Frames per point: 10 × 289 = 2890 stars.
const FRAMES: usize = 10;
/// A detection within this distance of a star (px) is that star's.
const MATCH_RADIUS: f64 = 1.5;
/// Half the side of the CRB's window: 9×9.
const HALF: i64 = 4;
const SEED: u64 = 0x0C3E_7201_D57D_0016;

/// Sub-pixel phase of the stars: random (uniform over the pixel) or fixed in x and y.
#[derive(Clone, Copy)]
enum Phase {
    Random,
    Fixed(f64),
}

#[derive(Clone, Copy)]
struct Point {
    sweep: &'static str,
    sigma: f64,
    /// Signal (e⁻).
    n: f64,
    phase: Phase,
    bias: f64,
}

impl Point {
    fn snr(&self) -> f64 {
        snr_of(self.n, self.sigma)
    }
}

fn snr_of(n: f64, sigma: f64) -> f64 {
    n / (n + 4.0 * PI * sigma * sigma * (BACKGROUND + READ_NOISE * READ_NOISE)).sqrt()
}

/// The signal N with SNR = N / sqrt(N + A), A = 4πσ²(b + σ_r²): N² − S²N − S²A = 0.
fn n_for_snr(snr: f64, sigma: f64) -> f64 {
    let a = 4.0 * PI * sigma * sigma * (BACKGROUND + READ_NOISE * READ_NOISE);
    let s2 = snr * snr;
    0.5 * (s2 + (s2 * s2 + 4.0 * s2 * a).sqrt())
}

/// Standard normal cdf of u/σ, and the Gaussian pdf of width σ at u.
fn cdf(u: f64, s: f64) -> f64 {
    0.5 * (1.0 + libm::erf(u / (s * SQRT_2)))
}
fn pdf(u: f64, s: f64) -> f64 {
    (-0.5 * (u / s).powi(2)).exp() / (s * (2.0 * PI).sqrt())
}

/// The share of a Gaussian centred on c (width s) falling in pixel i, and its derivatives in c
/// and s.
fn share(i: i64, c: f64, s: f64) -> (f64, f64, f64) {
    let (lo, hi) = (i as f64 - 0.5 - c, i as f64 + 0.5 - c);
    let (glo, ghi) = (pdf(lo, s), pdf(hi, s));
    (
        cdf(hi, s) - cdf(lo, s),
        glo - ghi,
        (lo * glo - hi * ghi) / s,
    )
}

/// Render one frame: the stars' positions, their width and signal, the bias.
fn render(
    stars: &[(f64, f64)],
    sigma: f64,
    n: f64,
    bias: f64,
    rng: &mut ChaCha8Rng,
) -> Frame<'static> {
    let (w, h) = (SIZE as usize, SIZE as usize);
    let mut signal = vec![0.0f64; w * h];
    let r = (6.0 * sigma + 2.0).ceil() as i64;
    for &(x0, y0) in stars {
        let (cx, cy) = (x0.round() as i64, y0.round() as i64);
        let px: Vec<f64> = (cx - r..=cx + r).map(|i| share(i, x0, sigma).0).collect();
        let py: Vec<f64> = (cy - r..=cy + r).map(|j| share(j, y0, sigma).0).collect();
        for (dj, &sy) in py.iter().enumerate() {
            let y = (cy - r) as usize + dj;
            for (di, &sx) in px.iter().enumerate() {
                let x = (cx - r) as usize + di;
                signal[y * w + x] += n * sx * sy;
            }
        }
    }
    let sky = Poisson::new(BACKGROUND).unwrap();
    let read = Normal::new(0.0, READ_NOISE).unwrap();
    let pixels = signal
        .iter()
        .map(|&s| {
            let photons = if s > 0.0 {
                Poisson::new(BACKGROUND + s).unwrap().sample(rng)
            } else {
                sky.sample(rng)
            };
            (photons + read.sample(rng) + bias)
                .round()
                .clamp(0.0, 65535.0) as u16
        })
        .collect();
    Frame {
        width: SIZE,
        height: SIZE,
        pixels,
        saturation: u16::MAX,
    }
}

type V5 = SVector<f64, 5>;
type M5 = SMatrix<f64, 5, 5>;

/// The CRB (variance, px²) of x₀ and y₀ for a star at (x0, y0) on the 9×9 window around its
/// nearest pixel, θ = (x₀, y₀, N, b, σ).
fn crb(x0: f64, y0: f64, sigma: f64, n: f64) -> (f64, f64) {
    let (cx, cy) = (x0.round() as i64, y0.round() as i64);
    let ax: Vec<_> = (cx - HALF..=cx + HALF)
        .map(|i| share(i, x0, sigma))
        .collect();
    let ay: Vec<_> = (cy - HALF..=cy + HALF)
        .map(|j| share(j, y0, sigma))
        .collect();
    let mut info = M5::zeros();
    for &(py, dpy, spy) in &ay {
        for &(px, dpx, spx) in &ax {
            let mu = BACKGROUND + n * px * py;
            let d = V5::new(
                n * dpx * py,
                n * px * dpy,
                px * py,
                1.0,
                n * (spx * py + px * spy),
            );
            info += d * d.transpose() / (mu + READ_NOISE * READ_NOISE);
        }
    }
    let cov = info.try_inverse().expect("Fisher information is singular");
    (cov[(0, 0)], cov[(1, 1)])
}

/// Errors of one estimator at one point.
#[derive(Default)]
struct Tally {
    ex: Vec<f64>,
    ey: Vec<f64>,
    duplicates: usize,
    false_det: usize,
    /// ML only, per matched star: its ML position is the centre of gravity (the fit did not
    /// settle).
    fell_back: Vec<bool>,
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Match a frame's detections to its stars (the nearest grid star within MATCH_RADIUS; where a
/// star gets two, the nearer counts and the other is a duplicate); `cog` is the same list by
/// centre of gravity, to tell the ML fit's fallbacks.
fn tally(t: &mut Tally, stars: &[(f64, f64)], dets: &[Detection], cog: Option<&[Detection]>) {
    let mut best: Vec<Option<(f64, usize)>> = vec![None; stars.len()];
    for (k, d) in dets.iter().enumerate() {
        let gx = ((d.x - MARGIN) / SPACING).round();
        let gy = ((d.y - MARGIN) / SPACING).round();
        let on_grid = (0.0..GRID as f64).contains(&gx) && (0.0..GRID as f64).contains(&gy);
        let i = gy as usize * GRID + gx as usize;
        let dist = if on_grid {
            (d.x - stars[i].0).hypot(d.y - stars[i].1)
        } else {
            f64::INFINITY
        };
        if dist > MATCH_RADIUS {
            t.false_det += 1;
            continue;
        }
        match best[i] {
            Some((bd, _)) if bd <= dist => t.duplicates += 1,
            Some(_) => {
                t.duplicates += 1;
                best[i] = Some((dist, k));
            }
            None => best[i] = Some((dist, k)),
        }
    }
    for (i, b) in best.iter().enumerate() {
        if let Some((_, k)) = *b {
            let d = dets[k];
            t.ex.push(d.x - stars[i].0);
            t.ey.push(d.y - stars[i].1);
            if let Some(c) = cog {
                // The two lists are the same stars in the same order (`detect::star_list`).
                t.fell_back.push(c[k].x == d.x && c[k].y == d.y);
            }
        }
    }
}

/// Run one point: its CSV rows (cog, ml, ml_settled).
fn run_point(index: usize, p: &Point) -> String {
    let mut rng =
        ChaCha8Rng::seed_from_u64(SEED ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let settings = |centroid| DetectSettings {
        centroid,
        max_stars: usize::MAX,
        ..Default::default()
    };
    let (s_cog, s_ml) = (settings(Centroid::Cog), settings(Centroid::Ml));
    let mut tallies = [Tally::default(), Tally::default()];
    let (mut crb_x, mut crb_y, mut total) = (0.0, 0.0, 0usize);
    for _ in 0..FRAMES {
        let stars: Vec<(f64, f64)> = (0..GRID * GRID)
            .map(|i| {
                let (gx, gy) = (i % GRID, i / GRID);
                let (fx, fy) = match p.phase {
                    Phase::Random => (rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5),
                    Phase::Fixed(f) => (f, f),
                };
                (
                    MARGIN + SPACING * gx as f64 + fx,
                    MARGIN + SPACING * gy as f64 + fy,
                )
            })
            .collect();
        for &(x, y) in &stars {
            let (cxx, cyy) = crb(x, y, p.sigma, p.n);
            crb_x += cxx;
            crb_y += cyy;
        }
        total += stars.len();
        let frame = render(&stars, p.sigma, p.n, p.bias, &mut rng);
        let cog = detect(&frame, &s_cog);
        let ml = detect(&frame, &s_ml);
        tally(&mut tallies[0], &stars, &cog, None);
        tally(&mut tallies[1], &stars, &ml, Some(&cog));
    }
    let (crb_x, crb_y) = ((crb_x / total as f64).sqrt(), (crb_y / total as f64).sqrt());
    // Per axis: the mean of the two axes' variances.
    let crb_axis = (0.5 * (crb_x * crb_x + crb_y * crb_y)).sqrt();
    let phase = match p.phase {
        Phase::Random => "random".to_string(),
        Phase::Fixed(f) => format!("{f}"),
    };
    let settled = |v: &[f64], t: &Tally| -> Vec<f64> {
        v.iter()
            .zip(&t.fell_back)
            .filter(|(_, f)| !**f)
            .map(|(e, _)| *e)
            .collect()
    };
    let (cog, ml) = (&tallies[0], &tallies[1]);
    let fallbacks = ml.fell_back.iter().filter(|f| **f).count();
    let (sx, sy) = (settled(&ml.ex, ml), settled(&ml.ey, ml));
    let rows = [
        ("cog", &cog.ex[..], &cog.ey[..], cog, String::new()),
        ("ml", &ml.ex[..], &ml.ey[..], ml, fallbacks.to_string()),
        ("ml_settled", &sx[..], &sy[..], ml, String::new()),
    ];
    let mut out = String::new();
    for (name, ex, ey, t, fallback) in rows {
        let all: Vec<f64> = ex.iter().chain(ey).copied().collect();
        let rms = |v: &[f64]| (v.iter().map(|e| e * e).sum::<f64>() / v.len() as f64).sqrt();
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let centre = median(&mut all.clone());
        let med_abs = median(&mut all.iter().map(|e| e.abs()).collect::<Vec<_>>());
        let robust =
            1.4826 * median(&mut all.iter().map(|e| (e - centre).abs()).collect::<Vec<_>>());
        let rms_all = rms(&all);
        writeln!(
            out,
            "{},{},{:.4},{},{},{:.2},{},{},{},{},{},{},{},{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.4},{:.4}",
            p.sweep,
            p.sigma,
            p.snr(),
            phase,
            name,
            p.n,
            BACKGROUND,
            READ_NOISE,
            p.bias,
            total,
            ex.len(),
            t.duplicates,
            t.false_det,
            fallback,
            FRAMES,
            med_abs,
            rms_all,
            rms(ex),
            rms(ey),
            mean(ex),
            mean(ey),
            robust,
            crb_axis,
            crb_x,
            crb_y,
            centre,
            rms_all / crb_axis,
            robust / crb_axis,
        )
        .unwrap();
    }
    out
}

const HEADER: &str = "sweep,sigma_px,snr,phase_px,estimator,signal_e,background_e,read_noise_e,bias_adu,\
stars,detected,duplicates,false_detections,ml_fallbacks,frames,median_abs_err_px,rms_err_px,\
rms_x_px,rms_y_px,bias_x_px,bias_y_px,robust_sigma_px,crb_px,crb_x_px,crb_y_px,median_err_px,\
err_over_crb,robust_over_crb";

fn points() -> Vec<Point> {
    let sigmas = [0.3, 0.35, 0.4, 0.45, 0.5, 0.6, 0.7, 0.8, 1.0, 1.2, 1.5, 2.0];
    let mut v = Vec::new();
    let at_snr = |sweep, sigma, snr, phase, bias| Point {
        sweep,
        sigma,
        n: n_for_snr(snr, sigma),
        phase,
        bias,
    };
    for snr in [10.0, 20.0, 50.0, 100.0] {
        for s in sigmas {
            v.push(at_snr("sigma", s, snr, Phase::Random, BIAS));
        }
    }
    for s in [0.8, 1.2] {
        for snr in [
            5.0, 7.0, 10.0, 15.0, 20.0, 30.0, 50.0, 70.0, 100.0, 150.0, 200.0, 300.0,
        ] {
            v.push(at_snr("snr", s, snr, Phase::Random, BIAS));
        }
    }
    for s in [0.5, 1.2] {
        for snr in [20.0, 100.0] {
            for f in [0.0, 0.125, 0.25, 0.375, 0.5] {
                v.push(at_snr("phase", s, snr, Phase::Fixed(f), BIAS));
            }
        }
    }
    for n in [500.0, 1000.0, 3000.0, 10000.0] {
        for s in sigmas {
            v.push(Point {
                sweep: "flux",
                sigma: s,
                n,
                phase: Phase::Random,
                bias: BIAS,
            });
        }
    }
    for s in [0.8, 1.2] {
        for snr in [20.0, 50.0, 100.0, 200.0] {
            v.push(at_snr("bias0", s, snr, Phase::Random, 0.0));
        }
    }
    v
}

fn main() {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "centroid_study.csv".to_string());
    let points = points();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let started = Instant::now();
    let next = AtomicUsize::new(0);
    let rows = Mutex::new(vec![String::new(); points.len()]);
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(p) = points.get(i) else { break };
                    let r = run_point(i, p);
                    rows.lock().unwrap()[i] = r;
                }
            });
        }
    });
    let mut csv = String::from(HEADER);
    csv.push('\n');
    for r in rows.into_inner().unwrap() {
        csv.push_str(&r);
    }
    std::fs::write(&out, csv).unwrap_or_else(|e| panic!("cannot write {out}: {e}"));
    eprintln!(
        "{} points × {} frames × {} stars on {} threads in {:.1} s: {}",
        points.len(),
        FRAMES,
        GRID * GRID,
        threads,
        started.elapsed().as_secs_f64(),
        out
    );
}
