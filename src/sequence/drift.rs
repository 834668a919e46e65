//! The drift test: particles slower than the step test's Δ (issue 49).
//!
//! A particle moving at a few tenths of a pixel a frame takes steps no larger than a star's
//! centroid noise, so Wald's step test (`particles.rs`) calls it a star within a frame
//! or two. It still moves steadily where a star stands still. A track's last points
//! ([`POINTS`] at most, [`MIN_POINTS`] at least, each clear of the frame's edge) are fitted by
//! a straight line in time in this frame's pixels; the track is a particle when
//! - its velocity, less the stars' velocity field at its place ([`VelocityField`]), stands
//!   out of the noise: |Δv|² Σ(t − t̄)² / σ² above [`CHI2`] (χ² with 2 degrees of freedom
//!   beyond it once in 10⁴ for a star);
//! - it has moved [`MIN_PX`] pixels or more over the points' span: blends and the centroid
//!   biases they bring drift by a pixel or so, and a pixel of noise per point is no motion;
//! - the line fits the points (residuals' χ² per degree of freedom below [`FIT`]) and fits
//!   them better than any single jump between two places does: a star pulled aside for a few
//!   frames by a passing particle jumps and comes back, which no line fits, and while it is
//!   still aside two places fit it better than a line.
//!
//! The noise σ of a point is taken as the frame's step noise itself (√2 times a centroid's),
//! so the test errs towards "star".

use crate::camera::Camera;
use nalgebra::{Matrix3, Vector3};

/// A place in the frame or a velocity, in pixels (per second).
pub type Px = (f64, f64);
/// Projection of a reference-frame direction into this frame's pixels.
pub type Project<'a> = dyn Fn(&Vector3<f64>) -> Option<Px> + 'a;

/// Points a track keeps for the test.
pub const POINTS: usize = 12;
/// Fewest points the test is tried on.
const MIN_POINTS: usize = 3;
/// |Δv|²·Σ(t − t̄)²/σ² above which a track moves.
const CHI2: f64 = 18.4;
/// Largest residual χ² per degree of freedom (in σ²) of a track that moves along a line.
const FIT: f64 = 2.0;
/// Least motion against the stars over the points' span (pixels).
const MIN_PX: f64 = 2.0;
/// Points nearer the frame's border than this (pixels) are left out: a star entering or
/// leaving the field is cut by the edge and its centroid pulled inward by a pixel or more,
/// which looks like drift.
pub const EDGE_PX: f64 = 5.0;
/// Star tracks needed for the velocity field.
const MIN_STARS: usize = 8;

/// A straight line in time through a track's points, in the pixels of one frame.
#[derive(Clone, Copy, Debug)]
pub struct Line {
    /// Velocity (pixels per second).
    v: (f64, f64),
    /// Σ (t − t̄)² of the points' times: the velocity's variance is σ² over it.
    stt: f64,
    /// Time from the first point to the last (s).
    span: f64,
    /// The residuals' sum of squares (pixels², both axes) about the line, and about the best
    /// two places with one jump between them (each held by at least two points).
    ss_line: f64,
    ss_jump: f64,
    /// Degrees of freedom of `ss_line`.
    dof: f64,
}

/// The line through a track's points (reference-frame directions and times) in the pixels
/// `to_px` projects them into; `None` with fewer than [`MIN_POINTS`] or one outside.
pub fn line_fit(history: &[(Vector3<f64>, f64)], to_px: &Project) -> Option<Line> {
    if history.len() < MIN_POINTS {
        return None;
    }
    let pts = history
        .iter()
        .map(|(w, t)| to_px(w).map(|p| (*t, p)))
        .collect::<Option<Vec<_>>>()?;
    let n = pts.len() as f64;
    let t_mean = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let stt: f64 = pts.iter().map(|p| (p.0 - t_mean).powi(2)).sum();
    if stt <= 0.0 {
        return None;
    }
    let mut v = [0.0; 2];
    let mut ss_line = 0.0;
    for (axis, va) in v.iter_mut().enumerate() {
        let at = |p: &(f64, (f64, f64))| if axis == 0 { p.1.0 } else { p.1.1 };
        let mean = pts.iter().map(at).sum::<f64>() / n;
        *va = pts
            .iter()
            .map(|p| (p.0 - t_mean) * (at(p) - mean))
            .sum::<f64>()
            / stt;
        ss_line += pts
            .iter()
            .map(|p| (at(p) - mean - *va * (p.0 - t_mean)).powi(2))
            .sum::<f64>();
    }
    // Σ of squares about the mean of a run of points, both axes.
    let spread = |run: &[(f64, (f64, f64))]| {
        let m = run.len() as f64;
        let (mx, my) = run
            .iter()
            .fold((0.0, 0.0), |a, p| (a.0 + p.1.0 / m, a.1 + p.1.1 / m));
        run.iter()
            .map(|p| (p.1.0 - mx).powi(2) + (p.1.1 - my).powi(2))
            .sum::<f64>()
    };
    let ss_jump = (2..=pts.len() - 2)
        .map(|k| spread(&pts[..k]) + spread(&pts[k..]))
        .fold(f64::INFINITY, f64::min);
    Some(Line {
        v: (v[0], v[1]),
        stt,
        span: pts[pts.len() - 1].0 - pts[0].0,
        ss_line,
        ss_jump,
        dof: 2.0 * (n - 2.0),
    })
}

/// A track the frame continued, as the test sees it.
pub struct Continued {
    /// Its detection in this frame (pixels).
    pub at: (f64, f64),
    /// Whether the step test has called it a star (those make the velocity field).
    pub star: bool,
    /// Its line, where it has one.
    pub line: Option<Line>,
}

/// Which of the `tracks` move against the stars (`false` where too few stars have lines to
/// fit their field); `sigma` is the frame's step noise per axis (pixels). A star track is
/// measured against the field of the others: one far from the rest (at the border) would
/// otherwise bend the field towards itself.
pub fn drifting(tracks: &[Continued], cam: &Camera, sigma: f64) -> Vec<bool> {
    let stars: Vec<(usize, Px, Px)> = tracks
        .iter()
        .enumerate()
        .filter(|(_, c)| c.star)
        .filter_map(|(i, c)| c.line.map(|l| (i, c.at, l.v)))
        .collect();
    let centre = (0.5 * f64::from(cam.width), 0.5 * f64::from(cam.height));
    let field_without = |i: Option<usize>| {
        let others: Vec<_> = stars
            .iter()
            .filter(|s| Some(s.0) != i)
            .map(|s| (s.1, s.2))
            .collect();
        VelocityField::fit(&others, centre)
    };
    let common = field_without(None);
    let s2 = sigma * sigma;
    tracks
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let Some(l) = c.line else { return false };
            let own;
            let field = if c.star {
                own = field_without(Some(i));
                own.as_ref()
            } else {
                common.as_ref()
            };
            let Some(field) = field else { return false };
            let (fx, fy) = field.at(c.at);
            let (dvx, dvy) = (l.v.0 - fx, l.v.1 - fy);
            (dvx * dvx + dvy * dvy) * l.stt / s2 > CHI2
                && dvx.hypot(dvy) * l.span >= MIN_PX
                && l.ss_line / l.dof / s2 < FIT
                && l.ss_line < l.ss_jump
        })
        .collect()
}

/// The star tracks' velocities across the frame, v = a + B (p − centre) per axis: the
/// reference frame carried through the motion found between frames turns and stretches a
/// little as the stars cross the field, so stars drift too, by an amount that grows across
/// the field (a local median of neighbours, all on one side of a star at the border, misses
/// it there). Fitted by least squares, then again without the stars beyond 4.45 times the
/// median residual (5σ for noise alone: a star pulled by a particle, a slow particle not yet
/// told).
struct VelocityField {
    centre: (f64, f64),
    coef: [Vector3<f64>; 2],
}

impl VelocityField {
    /// `None` with fewer than [`MIN_STARS`] stars or a degenerate spread of them.
    fn fit(stars: &[(Px, Px)], centre: Px) -> Option<Self> {
        let row = |p: Px| terms(centre, p);
        let solve = |keep: &dyn Fn(usize) -> bool| -> Option<[Vector3<f64>; 2]> {
            let (mut a, mut b) = (Matrix3::zeros(), [Vector3::zeros(); 2]);
            let mut n = 0;
            for (_, (p, v)) in stars.iter().enumerate().filter(|(i, _)| keep(*i)) {
                let r = row(*p);
                a += r * r.transpose();
                b[0] += r * v.0;
                b[1] += r * v.1;
                n += 1;
            }
            if n < MIN_STARS {
                return None;
            }
            let lu = a.lu();
            Some([lu.solve(&b[0])?, lu.solve(&b[1])?])
        };
        let first = solve(&|_| true)?;
        let resid: Vec<f64> = stars
            .iter()
            .map(|(p, v)| {
                let r = row(*p);
                (v.0 - first[0].dot(&r)).hypot(v.1 - first[1].dot(&r))
            })
            .collect();
        let mut sorted = resid.clone();
        sorted.sort_by(f64::total_cmp);
        let cut = 3.0 * 1.4826 * sorted[sorted.len() / 2];
        let coef = solve(&|i| resid[i] <= cut).unwrap_or(first);
        Some(VelocityField { centre, coef })
    }

    /// The field's velocity at `p` (pixels per second).
    fn at(&self, p: Px) -> Px {
        let r = terms(self.centre, p);
        (self.coef[0].dot(&r), self.coef[1].dot(&r))
    }
}

/// The affine field's terms at `p`: 1 and the offsets from `centre` in kilopixels, so that the
/// normal equations are well scaled.
fn terms(centre: Px, p: Px) -> Vector3<f64> {
    Vector3::new(1.0, (p.0 - centre.0) / 1e3, (p.1 - centre.1) / 1e3)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A turning, stretching reference (v = a + B p) is fitted exactly across the frame, a
    /// star pulled aside does not bend it, and a star at the border moving with the field
    /// is not drifting while a slow particle there is.
    #[test]
    fn the_stars_velocity_field_is_affine_and_robust() {
        let field = |p: (f64, f64)| {
            let (x, y) = (p.0 - 512.0, p.1 - 512.0);
            (0.05 + 4e-4 * x - 6e-4 * y, -0.02 + 6e-4 * x + 2e-4 * y)
        };
        let mut stars: Vec<(Px, Px)> = (0..20)
            .map(|i| {
                let p = (
                    200.0 + 31.0 * i as f64,
                    150.0 + 37.0 * ((i * 7) % 20) as f64,
                );
                (p, field(p))
            })
            .collect();
        stars[4].1.0 += 3.0;
        let fit = VelocityField::fit(&stars, (512.0, 512.0)).expect("enough stars");
        for p in [(0.0, 0.0), (1023.0, 512.0), (512.0, 1023.0)] {
            let (a, b) = (fit.at(p), field(p));
            assert!(
                (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9,
                "{p:?}"
            );
        }
        assert!(VelocityField::fit(&stars[..MIN_STARS - 1], (512.0, 512.0)).is_none());

        // Lines of six points a second apart at the border (x = 8), with the field's velocity
        // and with 0.5 px/s more.
        let cam = Camera::from_fov(1024, 1024, 18.0).unwrap();
        let line = |v: (f64, f64)| Line {
            v,
            stt: 17.5,
            span: 5.0,
            ss_line: 0.0,
            ss_jump: 1.0,
            dof: 8.0,
        };
        let mut tracks: Vec<Continued> = stars
            .iter()
            .map(|(p, v)| Continued {
                at: *p,
                star: true,
                line: Some(line(*v)),
            })
            .collect();
        let edge = (8.0, 900.0);
        let v = field(edge);
        for dv in [0.0, 0.5] {
            tracks.push(Continued {
                at: edge,
                star: true,
                line: Some(line((v.0, v.1 + dv))),
            });
        }
        let moving = drifting(&tracks, &cam, 0.2);
        let n = moving.len();
        assert_eq!(&moving[n - 2..], &[false, true]);
        assert!(
            moving[..n - 2]
                .iter()
                .enumerate()
                .all(|(i, m)| *m == (i == 4))
        );
    }

    /// A steady line fits better than a jump; a star pulled aside (a jump) does not.
    #[test]
    fn a_line_and_a_jump_are_told_apart() {
        let cam = Camera::from_fov(1024, 1024, 18.0).unwrap();
        let to_px = |w: &Vector3<f64>| cam.vector_to_pixel(w);
        let points = |xs: &[f64]| -> Vec<(Vector3<f64>, f64)> {
            xs.iter()
                .enumerate()
                .map(|(i, x)| (cam.pixel_to_vector(*x, 400.0), i as f64))
                .collect()
        };
        let steady = line_fit(&points(&[500.0, 500.4, 500.8, 501.2, 501.6, 502.0]), &to_px)
            .expect("six points");
        assert!(steady.ss_line < steady.ss_jump);
        assert!((steady.v.0 - 0.4).abs() < 1e-6 && steady.v.1.abs() < 1e-6);
        let pulled = line_fit(&points(&[500.0, 500.0, 500.0, 501.0, 501.0, 501.0]), &to_px)
            .expect("six points");
        assert!(pulled.ss_jump < pulled.ss_line);
        assert!(line_fit(&points(&[500.0, 500.4]), &to_px).is_none());
    }
}
