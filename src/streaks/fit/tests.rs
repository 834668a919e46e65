use super::*;

/// A track that leaves the frame, the fit started from a segment up to 3° off its line (as
/// the binned mask can give): the end is the edge's, at every angle and width. A free fit
/// from such a start shortened the track by up to 27 px, or fitted another line.
#[test]
fn a_start_off_the_line_still_reaches_the_edge() {
    let (w, h) = (300u32, 300u32);
    let mut wrong = Vec::new();
    for angle in [20.0f64, 35.0, 50.0, 65.0] {
        for off in [1.0f64, 2.0, 3.0, -2.0] {
            for sg in [0.9, 1.4, 1.9] {
                // From (200, 150) out through the left or top edge, peak 60 in noise of 10.
                let (ux, uy) = (-angle.to_radians().cos(), -angle.to_radians().sin());
                let d = |x: u32, y: u32| {
                    let (px, py) = (x as f64 - 200.0, y as f64 - 150.0);
                    let (t, across) = (px * ux + py * uy, -px * uy + py * ux);
                    let hash = (x.wrapping_mul(7919) ^ y.wrapping_mul(104_729)) % 1000;
                    60.0 * (-across * across / (2.0 * sg * sg)).exp() * along(t, 0.0, 400.0, sg)
                        + 34.6 * (hash as f64 / 1000.0 - 0.5)
                };
                let visible = (200.0 / -ux).min(150.0 / -uy);
                let turn = off.to_radians();
                let seg = Segment {
                    cx: 200.0 + 0.5 * visible * ux,
                    cy: 150.0 + 0.5 * visible * uy,
                    ux: ux * turn.cos() - uy * turn.sin(),
                    uy: ux * turn.sin() + uy * turn.cos(),
                    t_min: -0.5 * visible,
                    t_max: 0.5 * visible,
                    pixels: 200,
                };
                let f = fit(&d, w, h, &seg).expect("a fit");
                let inside = (0..2).find(|&k| !f.edge[k]);
                let right = match inside {
                    Some(k) => {
                        let (x, y) = f.ends[k];
                        let (ex, ey) = f.ends[1 - k];
                        f.edge[1 - k]
                            && (x - 200.0).hypot(y - 150.0) < 1.0
                            && ex.min(ey).abs() < 1e-6
                    }
                    None => false,
                };
                if !right {
                    wrong.push(format!("{angle}° {off}° σ {sg}: {:?} {:?}", f.ends, f.edge));
                }
            }
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// A frame's span whose end plus the margin is −1.484292886511039: t0 at its upper bound
/// plus one pixel rounds to −1.4842928865110387, past t1's bound (f64::clamp panicked
/// there, on every Swarm frame once).
#[test]
fn clamping_the_ends_survives_bounds_that_cross_by_an_ulp() {
    // No margin, so that hi + m is that value exactly.
    let end = -1.484292886511039;
    assert!((end - 1.0) + 1.0 > end, "the rounding this test is about");
    let (t0, t1) = clamp_ends(1e6, 0.0, -100.0, end, 0.0);
    assert!(t0 <= end - 1.0 && t1 >= t0 + 1.0, "{t0} {t1}");
    let (t0, t1) = clamp_ends(-1e6, 1e6, -100.0, 50.0, 4.0);
    assert_eq!((t0, t1), (-104.0, 54.0));
}

/// A bright star on a short track, a little off its line: the bins it falls in give the
/// star's centroid, not the track's, and are left out of the track's straightness.
#[test]
fn a_star_on_the_track_is_not_a_bend() {
    let (w, h) = (160u32, 100u32);
    let mut rms = Vec::new();
    for (across, peak) in [(2.0, 400.0), (2.5, 800.0), (-2.5, 1000.0)] {
        let d = |x: u32, y: u32| {
            let (px, py) = (x as f64, y as f64);
            let g = |dx: f64, dy: f64, s: f64| (-(dx * dx + dy * dy) / (2.0 * s * s)).exp();
            let track = 60.0 * g(0.0, py - 50.0, 1.2) * along(px, 30.0, 100.0, 1.2);
            let star = peak
                * (0.9 * g(px - 62.0, py - 50.0 - across, 1.2)
                    + 0.1 * g(px - 62.0, py - 50.0 - across, 3.0));
            let hash = (x.wrapping_mul(7919) ^ y.wrapping_mul(104_729)) % 1000;
            track + star + 34.6 * (hash as f64 / 1000.0 - 0.5)
        };
        let seg = Segment {
            cx: 65.0,
            cy: 50.0,
            ux: 1.0,
            uy: 0.0,
            t_min: -35.0,
            t_max: 35.0,
            pixels: 70,
        };
        let f = fit(&d, w, h, &seg).expect("a fit");
        rms.push((across, peak, f.fit_rms_px, f.ends));
    }
    // Before, 0.36, 0.50 and 0.59 px: the star's bins alone, each about its offset.
    let straight =
        |r: &(f64, f64, f64, [(f64, f64); 2])| r.2 < 0.3 && (r.3[1].0 - r.3[0].0).abs() > 60.0;
    assert!(rms.iter().all(straight), "{rms:?}");
}

/// An end within two σ of the frame's last pixel is an edge end (the PSF reaches the edge:
/// the object may have gone on past it), reported where the line leaves the frame; one
/// further in is not.
#[test]
fn an_end_whose_psf_reaches_the_edge_is_an_edge_end() {
    for (end_x, edge) in [(1.8, true), (2.2, true), (4.5, false)] {
        let d = |x: u32, y: u32| {
            let (px, py) = (x as f64, y as f64);
            let hash = (x.wrapping_mul(7919) ^ y.wrapping_mul(104_729)) % 1000;
            60.0 * (-(py - 50.0).powi(2) / (2.0 * 1.2 * 1.2)).exp() * along(px, end_x, 120.0, 1.2)
                + 17.3 * (hash as f64 / 1000.0 - 0.5)
        };
        let seg = Segment {
            cx: 0.5 * (end_x + 120.0),
            cy: 50.0,
            ux: 1.0,
            uy: 0.0,
            t_min: -0.5 * (120.0 - end_x),
            t_max: 0.5 * (120.0 - end_x),
            pixels: 100,
        };
        let f = fit(&d, 200, 100, &seg).expect("a fit");
        let left = if f.ends[0].0 < f.ends[1].0 { 0 } else { 1 };
        assert_eq!(
            f.edge[left], edge,
            "end at {end_x}: {:?} {:?}",
            f.ends, f.edge
        );
        assert!(!f.edge[1 - left], "{:?}", f.edge);
        if edge {
            assert_eq!(f.ends[left].0, 0.0, "{:?}", f.ends);
        } else {
            assert!((f.ends[left].0 - end_x).abs() < 0.3, "{:?}", f.ends);
        }
    }
}

/// Bright stars beside a short, faint track, on the parallel tracks the local-SNR test compares
/// it with, do not make it "stand only a few sigmas above" them.
#[test]
fn stars_beside_a_track_leave_its_local_snr() {
    let beside = 3.0 * 1.2 + 4.0;
    let g = |dx: f64, dy: f64, s: f64| (-(dx * dx + dy * dy) / (2.0 * s * s)).exp();
    let mut snr = Vec::new();
    for (k1, k2, k3, peak) in [
        (1.0, -2.0, 2.0, 100.0),
        (-1.0, 1.0, -2.0, 150.0),
        (2.0, -3.0, -1.0, 200.0),
    ] {
        let d = |x: u32, y: u32| {
            let (px, py) = (x as f64, y as f64);
            let track = 25.0 * g(0.0, py - 50.0, 1.2) * along(px, 30.0, 110.0, 1.2);
            let star = |sx: f64, sy: f64| {
                peak * (0.9 * g(px - sx, py - sy, 1.2) + 0.1 * g(px - sx, py - sy, 3.0))
            };
            let hash = (x.wrapping_mul(7919) ^ y.wrapping_mul(104_729)) % 1000;
            track
                + star(50.0, 50.0 + k1 * beside)
                + star(85.0, 50.0 + k2 * beside)
                + star(100.0, 50.0 + k3 * beside)
                + 34.6 * (hash as f64 / 1000.0 - 0.5)
        };
        let model = Model {
            c: (70.0, 50.0),
            w: 160,
            h: 100,
        };
        let q = P::from_column_slice(&[0.0, 0.0, -40.0, 40.0, 25.0, 1.2, 0.0]);
        let (_, local_snr, _) = model.profile_stats(&q, -40.0, 40.0, &d);
        snr.push(local_snr);
    }
    // Before, 3.6, 1.9 and 1.3: all under the test's threshold.
    let least = crate::streaks::StreakSettings::DEFAULT.min_local_snr;
    assert!(snr.iter().all(|&s| s > least), "{snr:?}");
}
