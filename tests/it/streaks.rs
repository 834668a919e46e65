//! Streaks: the pixel stage (`streak_filter`: CPU twin, and GPU = CPU on lavapipe) and what
//! the whole detection finds on frames drawn here: ends, edges, several streaks, faint and
//! short ones, and nothing on noise, stars, chains of stars, bad columns or bleed trails.

use crate::common;

use gpustar::cpu::streak_filter::{
    StreakParams, mask_runs, streak_filter, streak_mask, streak_rows,
};
use gpustar::cpu::threshold::{DetectParams, background_at, tile_stats};
use gpustar::io::frame::Frame;
use gpustar::streaks::{self, StreakSettings, fit::StreakFit};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const SKY: f64 = 1000.0;
const NOISE: f64 = 10.0;

/// What is drawn on a test frame.
enum Thing {
    /// A streak from (x0, y0) to (x1, y1) with this peak SNR, PSF σ 1.2 px.
    Streak(f64, f64, f64, f64, f64),
    /// A streak of a tumbling object: as `Streak`, its brightness along the track given in
    /// pieces (from, to, brightness), from and to as fractions of the track from (x0, y0).
    Tumbling(f64, f64, f64, f64, f64, Vec<(f64, f64, f64)>),
    /// A star of this peak SNR.
    Star(f64, f64, f64),
    /// A defective column: +ADU on column x from row y0 to y1.
    Column(u32, u32, u32, f64),
    /// A saturated star bleeding up and down its column over `len` rows.
    Bleed(u32, u32, u32),
}

fn erf(x: f64) -> f64 {
    libm::erf(x)
}

/// Add a track from (x0, y0) to (x1, y1) of peak SNR `snr` (PSF σ 1.2 px) to `v`, its
/// brightness along it the sum of uniform `pieces` (from, to, brightness; fractions of the
/// track), each blurred at its ends as a whole streak is.
fn track(
    v: &mut [f64],
    (w, h): (u32, u32),
    (x0, y0, x1, y1): (f64, f64, f64, f64),
    snr: f64,
    pieces: &[(f64, f64, f64)],
) {
    let sg = 1.2f64;
    let (dx, dy) = (x1 - x0, y1 - y0);
    let len = (dx * dx + dy * dy).sqrt();
    let (ux, uy) = (dx / len, dy / len);
    let k = 1.0 / (2f64.sqrt() * sg);
    for y in 0..h {
        for x in 0..w {
            let (px, py) = (x as f64 - x0, y as f64 - y0);
            let t = px * ux + py * uy;
            let d = -px * uy + py * ux;
            if d.abs() > 8.0 || t < -8.0 || t > len + 8.0 {
                continue;
            }
            let along: f64 = pieces
                .iter()
                .map(|&(a, b, m)| m * 0.5 * (erf((t - a * len) * k) - erf((t - b * len) * k)))
                .sum();
            v[(y * w + x) as usize] += snr * NOISE * (-d * d / (2.0 * sg * sg)).exp() * along;
        }
    }
}

/// A 16-bit frame: flat sky, Gaussian noise of NOISE ADU, the things drawn analytically
/// (PSF σ 1.2 px).
fn frame(w: u32, h: u32, things: &[Thing], seed: u64) -> Frame<'static> {
    let sg = 1.2f64;
    let mut v = vec![SKY; (w * h) as usize];
    let mut sat = vec![false; (w * h) as usize];
    for t in things {
        match *t {
            Thing::Tumbling(x0, y0, x1, y1, snr, ref pieces) => {
                track(&mut v, (w, h), (x0, y0, x1, y1), snr, pieces)
            }
            Thing::Streak(x0, y0, x1, y1, snr) => {
                track(&mut v, (w, h), (x0, y0, x1, y1), snr, &[(0.0, 1.0, 1.0)])
            }
            Thing::Star(sx, sy, snr) => {
                for y in 0..h {
                    for x in 0..w {
                        let r2 = (x as f64 - sx).powi(2) + (y as f64 - sy).powi(2);
                        if r2 < 100.0 {
                            v[(y * w + x) as usize] += snr * NOISE * (-r2 / (2.0 * sg * sg)).exp();
                        }
                    }
                }
            }
            Thing::Column(x, y0, y1, adu) => {
                for y in y0..y1 {
                    v[(y * w + x) as usize] += adu;
                }
            }
            Thing::Bleed(x, y, len) => {
                for yy in y.saturating_sub(len)..(y + len).min(h) {
                    sat[(yy * w + x) as usize] = true;
                }
                for yy in y.saturating_sub(3)..(y + 4).min(h) {
                    for xx in x.saturating_sub(3)..(x + 4).min(w) {
                        sat[(yy * w + xx) as usize] = true;
                    }
                }
            }
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = Normal::new(0.0, NOISE).unwrap();
    let pixels = v
        .iter()
        .zip(&sat)
        .map(|(&s, &st)| {
            if st {
                u16::MAX
            } else {
                (s + n.sample(&mut rng)).round().clamp(0.0, 65535.0) as u16
            }
        })
        .collect();
    Frame {
        width: w,
        height: h,
        pixels,
        saturation: u16::MAX,
    }
}

fn params(f: &Frame) -> DetectParams {
    DetectParams::new(f.width, f.height, 32, 5.0, f.saturation as u32)
}

fn find(f: &Frame) -> Vec<StreakFit> {
    streaks::find_cpu(f, &params(f), &StreakSettings::default(), 5.0)
}

fn dist(a: (f64, f64), b: (f64, f64)) -> f64 {
    ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt()
}

/// The fit's ends against the truth, in the better of the two orders.
fn end_errors(f: &StreakFit, a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    let (e0, e1) = (dist(f.ends[0], a), dist(f.ends[1], b));
    let (g0, g1) = (dist(f.ends[0], b), dist(f.ends[1], a));
    if e0 + e1 <= g0 + g1 {
        (e0, e1)
    } else {
        (g0, g1)
    }
}

#[test]
fn streak_rows_and_filter_smooth_the_residual_as_written() {
    // One bright pixel on a flat frame: its 2×2 block holds it, and the smoothed sum around
    // that block is the binomial kernel.
    let mut f = frame(64, 64, &[], 1);
    f.pixels.to_mut().fill(100);
    f.pixels.to_mut()[(21 * 64 + 30) as usize] = 100 + 1000;
    let p = params(&f);
    let tiles = tile_stats(&f.pixels, &p);
    assert!(tiles.iter().all(|t| t.background == 100));
    // Offset of a flat tile: ceil(5 · 1.4826 · max(MAD, 1)) = 8, so the level is 3.5 · 140 /
    // 5 · 8 = 784: the kernel's centre (36,000) and its corners (1,000) exceed it.
    let sp = StreakParams::new(&p, 3.5, 5.0);
    assert_eq!((sp.width, sp.height, sp.words), (32, 32, 32));
    assert_eq!(sp.level(8), 784);
    let rows = streak_rows(&f.pixels, &tiles, &p, &sp);
    // Block (15, 10) holds pixel (30, 21).
    assert_eq!(
        &rows[(10 * 32 + 13) as usize..][..5],
        &[1000, 4000, 6000, 4000, 1000]
    );
    let mask = streak_filter(&rows, &tiles, &p, &sp);
    let runs = mask_runs(&mask, 32, 32);
    assert_eq!(runs.len(), 5);
    assert!(runs.iter().all(|r| (r.x0, r.x1) == (13, 18)), "{runs:?}");
    assert_eq!((runs[0].y, runs[4].y), (8, 12));
    // Residuals are taken from the interpolated background, as star detection does.
    assert_eq!(background_at(&tiles, &p, 30, 20), 100);
}

#[test]
fn a_streak_inside_the_frame_has_sub_pixel_ends() {
    let (a, b) = ((100.3, 120.7), (390.6, 260.2));
    let f = frame(512, 512, &[Thing::Streak(a.0, a.1, b.0, b.1, 8.0)], 2);
    let found = find(&f);
    assert_eq!(found.len(), 1, "{found:?}");
    let s = &found[0];
    let (e0, e1) = end_errors(s, a, b);
    assert!(e0 < 0.5 && e1 < 0.5, "end errors {e0:.3} {e1:.3} px: {s:?}");
    assert_eq!(s.edge, [false, false]);
    assert!((s.sigma_px - 1.2).abs() < 0.1, "width {}", s.sigma_px);
    assert!((s.amplitude / (8.0 * NOISE) - 1.0).abs() < 0.1);
    assert!(s.fit_rms_px < 0.3, "{}", s.fit_rms_px);
}

#[test]
fn a_streak_across_the_frame_has_two_edge_ends() {
    let f = frame(
        400,
        300,
        &[Thing::Streak(-50.0, 40.0, 450.0, 230.0, 6.0)],
        3,
    );
    let found = find(&f);
    assert_eq!(found.len(), 1, "{found:?}");
    let s = &found[0];
    assert_eq!(s.edge, [true, true]);
    // The edge ends lie on the frame's border, on the line.
    for (x, y) in s.ends {
        let on_border = x.abs() < 1e-6 || (x - 399.0).abs() < 1e-6;
        assert!(on_border, "({x}, {y})");
        let y_line = 40.0 + (x + 50.0) * 190.0 / 500.0;
        assert!((y - y_line).abs() < 0.3, "{y} vs {y_line}");
    }
}

/// A streak grazing a side, its PSF cut by it along its length, leaves the frame only far
/// along its line: each end whose PSF reaches the side across the line is an edge end (the
/// object may have left the frame there). The same streak 10 px in has two inside ends.
#[test]
fn ends_of_a_streak_grazing_a_side_are_edge_ends() {
    for (x0, edge) in [(298.4, true), (289.0, false)] {
        let (a, b) = ((x0, 60.3), (x0 - 1.5, 220.6));
        let f = frame(300, 300, &[Thing::Streak(a.0, a.1, b.0, b.1, 12.0)], 5);
        let found = find(&f);
        assert_eq!(found.len(), 1, "x {x0}: {found:?}");
        assert_eq!(found[0].edge, [edge, edge], "x {x0}: {:?}", found[0]);
    }
}

#[test]
fn one_end_inside_one_at_the_edge() {
    let (a, b) = ((150.2, 140.8), (-100.0, 20.0));
    let f = frame(300, 300, &[Thing::Streak(a.0, a.1, b.0, b.1, 10.0)], 4);
    let found = find(&f);
    assert_eq!(found.len(), 1, "{found:?}");
    let s = &found[0];
    let inside = if s.edge[0] { 1 } else { 0 };
    assert!(s.edge[1 - inside]);
    assert!(!s.edge[inside]);
    assert!(dist(s.ends[inside], a) < 0.5, "{:?}", s.ends);
}

#[test]
fn short_faint_streaks_are_found() {
    // 40 px at peak SNR 3 per pixel, and 60 px at 4.
    let mut hits = 0;
    for seed in 0..5u64 {
        let f = frame(
            256,
            256,
            &[
                Thing::Streak(40.0, 50.0, 79.0, 61.0, 3.0),
                Thing::Streak(120.0, 200.0, 170.0, 166.0, 4.0),
            ],
            10 + seed,
        );
        hits += find(&f).len();
    }
    assert!(hits >= 9, "{hits} of 10 found");
}

/// A star on a short streak's track, far brighter than the track and a little off its line,
/// does not take the fit: the streak is found with its ends.
#[test]
fn a_bright_star_on_the_track_leaves_the_streak() {
    let (a, b) = ((60.0, 60.0), (126.0, 84.0));
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len = f64::hypot(dx, dy);
    let mut wrong = Vec::new();
    for (k, (at, across, snr)) in [
        (0.3, 2.0, 150.0),
        (0.5, 2.8, 200.0),
        (0.6, -2.5, 300.0),
        (0.5, 2.0, 400.0),
    ]
    .into_iter()
    .enumerate()
    {
        let star = (
            a.0 + at * dx - across * dy / len,
            a.1 + at * dy + across * dx / len,
        );
        let f = frame(
            200,
            150,
            &[
                Thing::Streak(a.0, a.1, b.0, b.1, 12.0),
                Thing::Star(star.0, star.1, snr),
            ],
            60 + k as u64,
        );
        let found = find(&f);
        let right = found.len() == 1 && {
            let (e0, e1) = end_errors(&found[0], a, b);
            e0.max(e1) < 1.0
        };
        if !right {
            let ends: Vec<_> = found.iter().map(|s| s.ends).collect();
            wrong.push(format!(
                "star at {at}, {across} px off, SNR {snr}: {ends:?}"
            ));
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

#[test]
fn noise_stars_and_defects_give_no_streak() {
    let mut things = vec![
        Thing::Column(37, 0, 256, 200.0),
        Thing::Column(200, 30, 180, 60.0),
        Thing::Bleed(120, 128, 60),
    ];
    // A chain of stars 8 px apart, and a field of stars.
    for k in 0..7 {
        things.push(Thing::Star(
            60.0 + 8.0 * k as f64,
            200.0 + 3.0 * k as f64,
            40.0,
        ));
    }
    for k in 0..30 {
        let (x, y) = ((k * 37 % 240 + 8) as f64, (k * 71 % 240 + 8) as f64);
        things.push(Thing::Star(x, y, 5.0 + (k % 7) as f64 * 20.0));
    }
    for seed in 0..4u64 {
        let f = frame(256, 256, &things, 30 + seed);
        let found = find(&f);
        assert!(found.is_empty(), "seed {seed}: {found:?}");
        let noise = frame(256, 256, &[], 40 + seed);
        assert!(find(&noise).is_empty());
    }
}

/// Issue 26: a tumbling object's streak breaks, rises and falls, and flashes; it is one
/// streak with both ends all the same (the rule that refused modulated tracks as chains of
/// stars refused every one of these).
#[test]
fn broken_modulated_and_flashing_streaks_are_one_streak_with_both_ends() {
    let (a, b) = ((60.4, 80.2), (420.7, 250.9));
    // Dark over 18 % of the track in the middle (and 8 % nearer an end).
    let broken = vec![(0.0, 0.3, 1.0), (0.38, 0.56, 1.0), (0.74, 1.0, 1.0)];
    // Bright and faint in turn every 12 px (about 30 of them).
    let n = 33;
    let periodic: Vec<_> = (0..n)
        .map(|k| {
            let m = if k % 2 == 0 { 1.6 } else { 0.4 };
            (k as f64 / n as f64, (k + 1) as f64 / n as f64, m)
        })
        .collect();
    // Level, with five glints under a pixel long, each as much light as 6 px of the track.
    let mut flashes = vec![(0.0, 1.0, 1.0)];
    for c in [0.12, 0.31, 0.5, 0.66, 0.9] {
        flashes.push((c, c + 0.002, 6.0 / 0.002 / 400.0));
    }
    for (what, pieces, snr) in [
        ("broken", broken, 6.0),
        ("periodic", periodic, 6.0),
        ("flashing", flashes, 5.0),
    ] {
        let f = frame(
            512,
            400,
            &[Thing::Tumbling(a.0, a.1, b.0, b.1, snr, pieces)],
            7,
        );
        let found = find(&f);
        assert_eq!(found.len(), 1, "{what}: {found:?}");
        let (e0, e1) = end_errors(&found[0], a, b);
        assert!(
            e0 < 1.0 && e1 < 1.0,
            "{what}: end errors {e0:.2} {e1:.2} px"
        );
        assert!(!found[0].chain.is_chain, "{what}: {:?}", found[0].chain);
    }
}

/// A bright tumbling object's short streak, dark twice: its lit pieces after the first are
/// as wide in the mask as a third of their length, no line of their own; they extend the
/// first piece's line and the streak has both ends (before: the first 33 of 107 px, so
/// `--tle` found it moving at a third of its rate and did not name it).
#[test]
fn short_bright_pieces_extend_the_streak_they_lie_on() {
    let (a, b) = ((68.2, 42.2), (97.6, 145.6));
    let pieces = vec![(0.0, 0.31, 1.0), (0.445, 0.65, 1.0), (0.755, 1.0, 1.0)];
    for seed in 0..3u64 {
        let f = frame(
            200,
            200,
            &[Thing::Tumbling(a.0, a.1, b.0, b.1, 22.0, pieces.clone())],
            80 + seed,
        );
        let found = find(&f);
        assert_eq!(found.len(), 1, "seed {seed}: {found:?}");
        let (e0, e1) = end_errors(&found[0], a, b);
        assert!(
            e0 < 1.0 && e1 < 1.0,
            "seed {seed}: end errors {e0:.2} {e1:.2} px"
        );
    }
}

/// Dense chains of stars, 5 px (1.8 FWHM) apart, bright and faint, with a streak beside one:
/// no streak but the streak.
#[test]
fn dense_chains_of_stars_are_no_streak() {
    let mut things = vec![Thing::Streak(30.0, 230.0, 240.0, 180.0, 6.0)];
    for k in 0..12 {
        let t = k as f64;
        things.push(Thing::Star(
            40.0 + 5.0 * t,
            40.0 + 1.5 * t,
            15.0 + (k % 3) as f64 * 10.0,
        ));
        things.push(Thing::Star(150.0 + 2.0 * t, 60.0 + 4.6 * t, 60.0));
    }
    for seed in 0..3u64 {
        let f = frame(256, 256, &things, 50 + seed);
        let found = find(&f);
        assert_eq!(found.len(), 1, "seed {seed}: {found:?}");
        assert!(found[0].ends.iter().all(|e| e.1 > 170.0), "{found:?}");
    }
}

#[test]
fn parallel_and_crossing_streaks_are_each_found() {
    let train = frame(
        400,
        400,
        &[
            Thing::Streak(20.0, 100.0, 380.0, 160.0, 8.0),
            Thing::Streak(20.0, 125.0, 380.0, 185.0, 8.0),
            Thing::Streak(50.0, 350.0, 350.0, 20.0, 12.0),
        ],
        50,
    );
    let found = find(&train);
    assert_eq!(found.len(), 3, "{found:?}");
}

#[test]
fn the_cpu_backend_s_fused_mask_is_the_two_kernels_mask() {
    let f = frame(
        300,
        200,
        &[
            Thing::Streak(-20.0, 30.0, 320.0, 170.0, 5.0),
            Thing::Star(40.0, 150.0, 80.0),
        ],
        60,
    );
    let p = params(&f);
    let tiles = tile_stats(&f.pixels, &p);
    let sp = StreakParams::new(&p, 3.5, 5.0);
    let two = streak_filter(&streak_rows(&f.pixels, &tiles, &p, &sp), &tiles, &p, &sp);
    assert_eq!(streak_mask(&f.pixels, &tiles, &p, &sp), two);
    assert!(two.iter().map(|w| w.count_ones()).sum::<u32>() > 300);
}

#[test]
fn streak_mask_gpu_equals_cpu() {
    let Some(gpu) = common::gpu("streak_mask_gpu_equals_cpu") else {
        return;
    };
    // A batch of frames of one size with streaks, stars, a bad column; odd sizes so that
    // rows do not fill whole mask words, and 8-bit frames too.
    let things = [
        Thing::Streak(-20.0, 30.0, 340.0, 150.0, 6.0),
        Thing::Streak(50.0, 190.0, 120.0, 120.0, 3.5),
        Thing::Star(40.0, 150.0, 80.0),
        Thing::Column(200, 0, 100, 90.0),
    ];
    for (w, h, bits8) in [(333, 211, false), (256, 256, true)] {
        let frames: Vec<Frame<'static>> = (0..3u64)
            .map(|k| {
                let mut f = frame(w, h, &things, 70 + k);
                if bits8 {
                    for v in f.pixels.to_mut() {
                        *v = (*v / 8).min(255);
                    }
                    f.saturation = 255;
                }
                f
            })
            .collect();
        let refs: Vec<&Frame> = frames.iter().collect();
        let p = params(&frames[0]);
        let sp = StreakParams::new(&p, 3.5, 5.0);
        let (blobs, pixels) = gpu.detect_streaks(&refs, &p, &sp).unwrap();
        for (k, f) in frames.iter().enumerate() {
            let tiles = gpustar::cpu::tile_clip::clipped_tile_stats(&f.pixels, &p);
            assert_eq!(pixels[k].tiles, tiles, "{w}x{h} frame {k}: tiles");
            let cpu = streak_mask(&f.pixels, &tiles, &p, &sp);
            assert_eq!(pixels[k].mask, cpu, "{w}x{h} frame {k}: streak mask");
            // And the rest of detection is what it is without streaks.
            assert_eq!(blobs[k], gpustar::solve::detect::blobs_cpu(f, &p));
            let s = StreakSettings::default();
            assert_eq!(
                streaks::measure(f, &pixels[k].tiles, &pixels[k].mask, &p, &s),
                find(f)
            );
        }
    }
}

#[test]
fn correlated_noise_makes_no_streak() {
    // Noise correlated over a few pixels (fixed patterns, compression blocks): the per-pixel
    // noise under-rates a filter's scatter, so lines of it look significant by `snr`; the
    // test against the same filter beside the track refuses them.
    let (w, h) = (512u32, 512u32);
    let mut rng = ChaCha8Rng::seed_from_u64(90);
    let n = Normal::new(0.0, 1.0).unwrap();
    let white: Vec<f64> = (0..w * h).map(|_| n.sample(&mut rng)).collect();
    // A 5×5 box average, scaled back to NOISE per pixel.
    let mut v = vec![SKY; (w * h) as usize];
    for y in 2..h - 2 {
        for x in 2..w - 2 {
            let mut s = 0.0;
            for dy in 0..5 {
                for dx in 0..5 {
                    s += white[((y + dy - 2) * w + x + dx - 2) as usize];
                }
            }
            v[(y * w + x) as usize] += s / 5.0 * NOISE * 2.0;
        }
    }
    let f = Frame {
        width: w,
        height: h,
        pixels: v
            .iter()
            .map(|&x| x.round().clamp(0.0, 65535.0) as u16)
            .collect(),
        saturation: u16::MAX,
    };
    let p = params(&f);
    assert!(find(&f).is_empty(), "{:?}", find(&f));
    let loose = StreakSettings {
        min_local_snr: f64::NEG_INFINITY,
        ..StreakSettings::default()
    };
    let without = streaks::find_cpu(&f, &p, &loose, 5.0);
    assert!(
        !without.is_empty(),
        "the frame tests nothing without the local test"
    );
}
