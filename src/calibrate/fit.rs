//! The joint fit: Levenberg–Marquardt over the camera and every frame's attitude.

use crate::camera::Camera;
use crate::error::{Result, fail};
use crate::solve::attitude::wahba;
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};

/// A detection and its catalog direction.
#[derive(Clone, Debug)]
pub struct Star {
    /// Detected pixel (column, row).
    pub x: f64,
    pub y: f64,
    /// ICRS direction of the matched catalog star (its length does not matter).
    pub v: Vector3<f64>,
}

/// The identified stars of one frame.
#[derive(Clone, Debug)]
pub struct FrameStars {
    pub name: String,
    /// The frame's solved attitude, v_cam = r · v_icrs: the starting point only.
    pub r: Matrix3<f64>,
    pub stars: Vec<Star>,
}

#[derive(Clone, Debug)]
pub struct FitOptions {
    /// Fit cx, cy (only with 3 or more usable frames; otherwise they stay as given).
    pub fit_principal_point: bool,
    /// A principal point the frames fix only to more than [`CENTRE_SD_PX`] is kept as given
    /// (the camera frame, and so every attitude, stays tied to it); false: fitted however
    /// loose (`calibrate --fit-centre`).
    pub keep_loose_centre: bool,
    pub fit_k2: bool,
    /// Reject stars whose residual exceeds this many robust per-axis sigmas; ∞ disables.
    pub outlier_sigma: f64,
    /// Levenberg–Marquardt iterations per fit (there is one fit per rejection round).
    pub max_iterations: usize,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            fit_principal_point: true,
            keep_loose_centre: true,
            fit_k2: true,
            outlier_sigma: 5.0,
            max_iterations: 50,
        }
    }
}

#[derive(Clone, Debug)]
pub struct Fit {
    /// The fitted camera (width, height and mirrored as given).
    pub camera: Camera,
    /// Fitted attitude per frame, in the order given.
    pub rotations: Vec<Matrix3<f64>>,
    /// RMS residual norm of the initial camera with each frame's attitude re-fitted alone, over
    /// the same stars as `rms_after_px`: what the attitudes alone could do, the fair "before".
    pub rms_before_px: f64,
    pub rms_after_px: f64,
    /// Per frame, over its stars kept; NaN for a frame with none.
    pub per_frame_rms_px: Vec<f64>,
    /// Stars in the final fit; frames with fewer than 3 stars kept take no part in the camera
    /// fit (their attitude alone is re-fitted) and their stars count as neither used nor rejected.
    pub stars_used: usize,
    pub stars_rejected: usize,
    /// (frame index, star index) of each star rejected as an outlier.
    pub rejected: Vec<(usize, usize)>,
    /// Levenberg–Marquardt iterations, all rejection rounds together.
    pub iterations: usize,
    /// Names of the fitted camera parameters, e.g. ["fx","fy","cx","cy","k1","k2"].
    pub fitted: Vec<&'static str>,
    /// Formal 1-σ uncertainty of each parameter in `fitted` (same order; pixels for fx, fy,
    /// cx, cy), from the covariance at the solution scaled by the residual variance.
    pub sigmas: Vec<f64>,
}

/// The least data a camera fit accepts: 24 equations for one frame's 6 unknowns (fx, fy, k1
/// and its attitude), four times over; fewer leave them poorly determined. (cedar-solve's
/// virgo.jpg, one 20° frame, shows 14 stars through its pinhole camera.)
pub const MIN_STARS: usize = 12;
/// A frame with fewer stars barely constrains its own attitude (3 unknowns) and tells
/// nothing about the camera.
pub const MIN_FRAME_STARS: usize = 3;
/// The principal point trades off against each frame's rotation; it is only fitted over
/// this many frames, so that it rests on many stars spread over the image.
pub const MIN_FRAMES_FOR_PRINCIPAL_POINT: usize = 3;
const MAX_REJECTION_ROUNDS: usize = 3;
/// No centroid is better than this: keeps noise-free (synthetic) data from rejecting everything.
const MIN_ROBUST_SIGMA_PX: f64 = 0.01;

const NAMES: [&str; 6] = ["fx", "fy", "cx", "cy", "k1", "k2"];

fn params_of(c: &Camera) -> [f64; 6] {
    [c.fx, c.fy, c.cx, c.cy, c.k1, c.k2]
}

fn camera_with(base: &Camera, p: &[f64; 6]) -> Camera {
    Camera {
        fx: p[0],
        fy: p[1],
        cx: p[2],
        cy: p[3],
        k1: p[4],
        k2: p[5],
        ..base.clone()
    }
}

/// The pixel of camera-frame direction `c` (as `Camera::vector_to_pixel`), its derivatives
/// with respect to the six camera parameters, and with respect to a small rotation ω applied
/// in the camera frame (c ← exp([ω]×) c). None behind the camera.
#[allow(clippy::type_complexity)]
fn project(cam: &Camera, c: &Vector3<f64>) -> Option<([f64; 2], [[f64; 6]; 2], [[f64; 3]; 2])> {
    if c.z <= 1e-9 {
        return None;
    }
    let (xu, yu) = (c.x / c.z, c.y / c.z);
    let r2 = xu * xu + yu * yu;
    let s = 1.0 + cam.k1 * r2 + cam.k2 * r2 * r2;
    let ds = cam.k1 + 2.0 * cam.k2 * r2; // ds/d(r²)
    let (xd, yd) = (xu * s, yu * s);
    let m = if cam.mirrored { -1.0 } else { 1.0 };
    let (fx, fym) = (cam.fx, cam.fy * m);
    let px = [cam.cx + fx * xd, cam.cy + fym * yd];
    let dcam = [
        [xd, 0.0, 1.0, 0.0, fx * xu * r2, fx * xu * r2 * r2],
        [0.0, m * yd, 0.0, 1.0, fym * yu * r2, fym * yu * r2 * r2],
    ];
    // d(xu, yu)/dω for c ← c + ω × c.
    let dxu = [-xu * yu, 1.0 + xu * xu, -yu];
    let dyu = [-1.0 - yu * yu, xu * yu, xu];
    let (a, b) = (s + 2.0 * xu * xu * ds, 2.0 * xu * yu * ds); // dxd/dxu, dxd/dyu
    let (c2, d) = (2.0 * xu * yu * ds, s + 2.0 * yu * yu * ds); // dyd/dxu, dyd/dyu
    let mut drot = [[0.0; 3]; 2];
    for k in 0..3 {
        drot[0][k] = fx * (a * dxu[k] + b * dyu[k]);
        drot[1][k] = fym * (c2 * dxu[k] + d * dyu[k]);
    }
    Some((px, dcam, drot))
}

/// Residual (projected − detected) of one star, or None behind the camera.
fn residual(cam: &Camera, r: &Matrix3<f64>, s: &Star) -> Option<[f64; 2]> {
    let (p, _, _) = project(cam, &(r * s.v))?;
    Some([p[0] - s.x, p[1] - s.y])
}

/// The unknowns of one Levenberg–Marquardt problem: which camera parameters are free, and
/// which frames have their attitude free (the others keep theirs and contribute no stars).
struct Problem<'a> {
    frames: &'a [FrameStars],
    inliers: &'a [Vec<bool>],
    free_cam: &'a [usize],
    active: &'a [bool],
}

impl Problem<'_> {
    fn cost(&self, p: &[f64; 6], base: &Camera, rots: &[Matrix3<f64>]) -> f64 {
        let cam = camera_with(base, p);
        let mut sum = 0.0;
        for (f, frame) in self.frames.iter().enumerate() {
            if !self.active[f] {
                continue;
            }
            for (s, star) in frame.stars.iter().enumerate() {
                if self.inliers[f][s] {
                    match residual(&cam, &rots[f], star) {
                        Some(e) => sum += e[0] * e[0] + e[1] * e[1],
                        None => return f64::INFINITY,
                    }
                }
            }
        }
        sum
    }

    /// Offsets of the rotation unknowns per frame, and the number of unknowns.
    fn layout(&self) -> (Vec<Option<usize>>, usize) {
        let mut n = self.free_cam.len();
        let offsets = self
            .active
            .iter()
            .map(|&a| {
                a.then(|| {
                    n += 3;
                    n - 3
                })
            })
            .collect();
        (offsets, n)
    }

    /// Normal equations JᵀJ, Jᵀe and the number of residuals, at (p, rots).
    fn normal(
        &self,
        p: &[f64; 6],
        base: &Camera,
        rots: &[Matrix3<f64>],
    ) -> (DMatrix<f64>, DVector<f64>, usize) {
        let cam = camera_with(base, p);
        let (offsets, n) = self.layout();
        let nc = self.free_cam.len();
        let mut a = DMatrix::<f64>::zeros(n, n);
        let mut g = DVector::<f64>::zeros(n);
        let mut m = 0;
        let mut idx = Vec::with_capacity(nc + 3);
        let mut row = Vec::with_capacity(nc + 3);
        for (f, frame) in self.frames.iter().enumerate() {
            let Some(o) = offsets[f] else { continue };
            for (s, star) in frame.stars.iter().enumerate() {
                if !self.inliers[f][s] {
                    continue;
                }
                let Some((px, dcam, drot)) = project(&cam, &(rots[f] * star.v)) else {
                    continue;
                };
                let e = [px[0] - star.x, px[1] - star.y];
                m += 2;
                for axis in 0..2 {
                    idx.clear();
                    row.clear();
                    for (k, &q) in self.free_cam.iter().enumerate() {
                        idx.push(k);
                        row.push(dcam[axis][q]);
                    }
                    for (k, d) in drot[axis].iter().enumerate() {
                        idx.push(o + k);
                        row.push(*d);
                    }
                    for (i, &ii) in idx.iter().enumerate() {
                        g[ii] += row[i] * e[axis];
                        for (j, &jj) in idx.iter().enumerate() {
                            a[(ii, jj)] += row[i] * row[j];
                        }
                    }
                }
            }
        }
        (a, g, m)
    }

    fn apply(
        &self,
        p: &[f64; 6],
        rots: &[Matrix3<f64>],
        delta: &DVector<f64>,
    ) -> ([f64; 6], Vec<Matrix3<f64>>) {
        let (offsets, _) = self.layout();
        let mut p2 = *p;
        for (k, &q) in self.free_cam.iter().enumerate() {
            p2[q] += delta[k];
        }
        let rots2 = rots
            .iter()
            .zip(&offsets)
            .map(|(r, o)| match o {
                Some(o) => {
                    let w = Vector3::new(delta[*o], delta[o + 1], delta[o + 2]);
                    Rotation3::new(w).into_inner() * r
                }
                None => *r,
            })
            .collect();
        (p2, rots2)
    }

    /// Levenberg–Marquardt with Marquardt's diagonal scaling (the unknowns mix pixels,
    /// radians and dimensionless distortion); returns the iterations taken.
    fn solve(
        &self,
        p: &mut [f64; 6],
        base: &Camera,
        rots: &mut [Matrix3<f64>],
        max_iterations: usize,
    ) -> usize {
        let mut cost = self.cost(p, base, rots);
        let mut lambda = 1e-3;
        let mut iterations = 0;
        while iterations < max_iterations && cost.is_finite() && cost > 0.0 {
            iterations += 1;
            let (a, g, _) = self.normal(p, base, rots);
            let n = g.len();
            let d: Vec<f64> = (0..n)
                .map(|i| {
                    let v = a[(i, i)].sqrt();
                    if v > 0.0 { v } else { 1.0 }
                })
                .collect();
            let scaled = DMatrix::from_fn(n, n, |i, j| a[(i, j)] / (d[i] * d[j]));
            let gs = DVector::from_fn(n, |i, _| g[i] / d[i]);
            let mut accepted = None;
            for _ in 0..16 {
                let mut m = scaled.clone();
                for i in 0..n {
                    m[(i, i)] += lambda;
                }
                if let Some(ch) = m.cholesky() {
                    let step = -ch.solve(&gs);
                    let delta = DVector::from_fn(n, |i, _| step[i] / d[i]);
                    let (p2, r2) = self.apply(p, rots, &delta);
                    let c2 = self.cost(&p2, base, &r2);
                    if c2 < cost {
                        accepted = Some((p2, r2, c2));
                        lambda = (lambda / 10.0).max(1e-12);
                        break;
                    }
                }
                lambda *= 10.0;
            }
            let Some((p2, r2, c2)) = accepted else { break };
            let decrease = cost - c2;
            *p = p2;
            rots.copy_from_slice(&r2);
            cost = c2;
            if decrease <= 1e-10 * cost {
                break;
            }
        }
        iterations
    }

    /// Formal 1-σ of the free camera parameters at the solution.
    fn sigmas(&self, p: &[f64; 6], base: &Camera, rots: &[Matrix3<f64>]) -> Vec<f64> {
        let (a, _, m) = self.normal(p, base, rots);
        let n = a.nrows();
        let nc = self.free_cam.len();
        let dof = m.saturating_sub(n).max(1) as f64;
        let var = self.cost(p, base, rots) / dof;
        let d: Vec<f64> = (0..n).map(|i| a[(i, i)].sqrt().max(1e-300)).collect();
        let scaled = DMatrix::from_fn(n, n, |i, j| a[(i, j)] / (d[i] * d[j]));
        let Some(ch) = scaled.cholesky() else {
            return vec![f64::NAN; nc];
        };
        (0..nc)
            .map(|k| {
                let e = DVector::from_fn(n, |i, _| if i == k { 1.0 } else { 0.0 });
                (ch.solve(&e)[k] * var).sqrt() / d[k]
            })
            .collect()
    }
}

/// Fit one frame's attitude alone with the camera fixed: the better of the given attitude and
/// Wahba on the camera's directions, then Gauss–Newton on the pixels.
fn refit_attitude(
    cam: &Camera,
    frame: &FrameStars,
    inliers: &[bool],
    start: &Matrix3<f64>,
) -> Matrix3<f64> {
    let kept: Vec<&Star> = frame
        .stars
        .iter()
        .zip(inliers)
        .filter_map(|(s, &k)| k.then_some(s))
        .collect();
    if kept.len() < 2 {
        return *start;
    }
    let frames = std::slice::from_ref(frame);
    let inl = [inliers.to_vec()];
    let problem = Problem {
        frames,
        inliers: &inl,
        free_cam: &[],
        active: &[true],
    };
    let mut p = params_of(cam);
    let mut best = *start;
    let cam_dirs: Vec<Vector3<f64>> = kept.iter().map(|s| cam.pixel_to_vector(s.x, s.y)).collect();
    let icrs: Vec<Vector3<f64>> = kept.iter().map(|s| s.v.normalize()).collect();
    if let Some(w) = wahba(&cam_dirs, &icrs)
        && problem.cost(&p, cam, &[w]) < problem.cost(&p, cam, &[best])
    {
        best = w;
    }
    let mut rots = [best];
    problem.solve(&mut p, cam, &mut rots, 10);
    rots[0]
}

/// RMS residual norm over the kept stars of the given frames.
fn rms(
    cam: &Camera,
    frames: &[FrameStars],
    rots: &[Matrix3<f64>],
    keep: impl Fn(usize, usize) -> bool,
) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (f, frame) in frames.iter().enumerate() {
        for (s, star) in frame.stars.iter().enumerate() {
            if keep(f, s) {
                let e = residual(cam, &rots[f], star).unwrap_or([f64::INFINITY; 2]);
                sum += e[0] * e[0] + e[1] * e[1];
                n += 1;
            }
        }
    }
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}

/// Reject a camera whose radial map r_d = r (1 + k1 r² + k2 r⁴) stops increasing before the
/// farthest image corner: such a camera folds the image and cannot be inverted.
fn check_monotonic(cam: &Camera) -> Result<()> {
    let (w, h) = (cam.width as f64 - 0.5, cam.height as f64 - 0.5);
    let rd_max = [(-0.5, -0.5), (w, -0.5), (-0.5, h), (w, h)]
        .iter()
        .map(|&(x, y)| ((x - cam.cx) / cam.fx).hypot((y - cam.cy) / cam.fy))
        .fold(0.0, f64::max);
    // dr_d/dr = 1 + 3 k1 u + 5 k2 u² with u = r²: its smallest positive root, if any.
    let (a, b) = (5.0 * cam.k2, 3.0 * cam.k1);
    let root = if a == 0.0 {
        (b < 0.0).then(|| -1.0 / b)
    } else {
        let disc = b * b - 4.0 * a;
        if disc < 0.0 {
            None
        } else {
            let q = -0.5 * (b + b.signum() * disc.sqrt());
            [q / a, if q != 0.0 { 1.0 / q } else { f64::NAN }]
                .into_iter()
                .filter(|u| *u > 0.0)
                .reduce(f64::min)
        }
    };
    if let Some(u) = root {
        let r = u.sqrt();
        let rd = r * (1.0 + cam.k1 * u + cam.k2 * u * u);
        if rd <= rd_max {
            fail!(
                Config,
                "the fitted distortion k1 = {:.5}, k2 = {:.5} folds the image: r(1 + k1 r² + k2 r⁴) \
                 stops increasing {:.0} px from the principal point, inside the image corner at {:.0} px; \
                 the stars do not constrain the distortion (fit without k2, or use frames with stars \
                 nearer the corners)",
                cam.k1,
                cam.k2,
                rd * cam.fx.min(cam.fy),
                rd_max * cam.fx.min(cam.fy)
            );
        }
    }
    Ok(())
}

/// Fit one camera and an attitude per frame to the identified stars of all frames.
///
/// Stars are rejected as outliers (then the fit is repeated, up to 3 rounds) when their
/// residual norm exceeds `outlier_sigma` robust per-axis sigmas (median norm / √ln 4, the
/// Rayleigh median). Errors when there are too few stars, or when the fitted distortion folds
/// the image.
pub fn fit(initial: &Camera, frames: &[FrameStars], opts: &FitOptions) -> Result<Fit> {
    let finite = params_of(initial).iter().all(|v| v.is_finite());
    if !(finite && initial.fx > 0.0 && initial.fy > 0.0) {
        fail!(
            Config,
            "the initial camera must have finite parameters and positive focal lengths"
        );
    }
    let usable = |inl: &[Vec<bool>]| -> (Vec<bool>, usize) {
        let counts: Vec<usize> = inl
            .iter()
            .map(|f| f.iter().filter(|&&k| k).count())
            .collect();
        let active: Vec<bool> = counts.iter().map(|&c| c >= MIN_FRAME_STARS).collect();
        let n = counts
            .iter()
            .zip(&active)
            .filter(|(_, a)| **a)
            .map(|(c, _)| c)
            .sum();
        (active, n)
    };
    let need = |active: &[bool], n: usize, what: &str| -> Result<()> {
        let nf = active.iter().filter(|&&a| a).count();
        if n < MIN_STARS || nf == 0 {
            fail!(
                Config,
                "calibration needs at least {MIN_STARS} identified stars over at least 1 frame \
                 (counting frames with {MIN_FRAME_STARS} or more stars); got {n} stars over {nf} \
                 frames{what} ({} frames given)",
                frames.len()
            );
        }
        Ok(())
    };
    let mut inliers: Vec<Vec<bool>> = frames
        .iter()
        .map(|f| {
            f.stars
                .iter()
                .map(|s| {
                    [s.x, s.y, s.v.x, s.v.y, s.v.z]
                        .iter()
                        .all(|v| v.is_finite())
                })
                .collect()
        })
        .collect();
    let (active, n) = usable(&inliers);
    need(&active, n, "")?;

    let n_frames = active.iter().filter(|&&a| a).count();
    let fit_pp = opts.fit_principal_point && n_frames >= MIN_FRAMES_FOR_PRINCIPAL_POINT;
    let free_cam: Vec<usize> = (0..6)
        .filter(|&q| match q {
            2 | 3 => fit_pp,
            5 => opts.fit_k2,
            _ => true,
        })
        .collect();

    // Start: each frame's attitude re-fitted alone with the initial camera.
    let mut rots: Vec<Matrix3<f64>> = frames
        .iter()
        .zip(&inliers)
        .map(|(f, inl)| refit_attitude(initial, f, inl, &f.r))
        .collect();
    // A star behind the camera under its frame's starting attitude is a gross mismatch; it can
    // come back in a rejection round if the fitted attitude brings it in front.
    for (f, frame) in frames.iter().enumerate() {
        for (s, star) in frame.stars.iter().enumerate() {
            if residual(initial, &rots[f], star).is_none() {
                inliers[f][s] = false;
            }
        }
    }
    let (mut active, n) = usable(&inliers);
    need(&active, n, "")?;
    let mut p = params_of(initial);
    let mut iterations = 0;
    for round in 0..=MAX_REJECTION_ROUNDS {
        let problem = Problem {
            frames,
            inliers: &inliers,
            free_cam: &free_cam,
            active: &active,
        };
        iterations += problem.solve(&mut p, initial, &mut rots, opts.max_iterations);
        if round == MAX_REJECTION_ROUNDS
            || !(opts.outlier_sigma.is_finite() && opts.outlier_sigma > 0.0)
        {
            break;
        }
        // Residual norms of all stars of the fitted frames, kept or not, so that a star
        // rejected early under a poorer fit can come back.
        let cam = camera_with(initial, &p);
        let norms: Vec<Vec<f64>> = frames
            .iter()
            .zip(&rots)
            .map(|(f, r)| {
                f.stars
                    .iter()
                    .map(|s| residual(&cam, r, s).map_or(f64::INFINITY, |e| e[0].hypot(e[1])))
                    .collect()
            })
            .collect();
        let mut kept: Vec<f64> = Vec::new();
        for f in (0..frames.len()).filter(|&f| active[f]) {
            kept.extend(
                norms[f]
                    .iter()
                    .zip(&inliers[f])
                    .filter(|(_, k)| **k)
                    .map(|(n, _)| *n),
            );
        }
        kept.sort_by(f64::total_cmp);
        let median = kept[kept.len() / 2];
        let sigma = (median / 4f64.ln().sqrt()).max(MIN_ROBUST_SIGMA_PX);
        let limit = opts.outlier_sigma * sigma;
        let mut next = inliers.clone();
        for f in (0..frames.len()).filter(|&f| active[f]) {
            for (s, star) in frames[f].stars.iter().enumerate() {
                let finite = [star.x, star.y, star.v.x, star.v.y, star.v.z]
                    .iter()
                    .all(|v| v.is_finite());
                next[f][s] = finite && norms[f][s] <= limit;
            }
        }
        if next == inliers {
            break;
        }
        let (act, n) = usable(&next);
        need(&act, n, " after rejecting outliers")?;
        inliers = next;
        active = act;
    }
    let camera = camera_with(initial, &p);
    check_monotonic(&camera)?;

    // Frames out of the joint fit keep only their own attitude fitted.
    for f in (0..frames.len()).filter(|&f| !active[f]) {
        rots[f] = refit_attitude(&camera, &frames[f], &inliers[f], &rots[f]);
    }
    let problem = Problem {
        frames,
        inliers: &inliers,
        free_cam: &free_cam,
        active: &active,
    };
    let sigmas = problem.sigmas(&p, initial, &rots);

    let used = |f: usize, s: usize| active[f] && inliers[f][s];
    let rms_after_px = rms(&camera, frames, &rots, used);
    let before_rots: Vec<Matrix3<f64>> = frames
        .iter()
        .enumerate()
        .map(|(f, fr)| {
            if active[f] {
                refit_attitude(initial, fr, &inliers[f], &fr.r)
            } else {
                fr.r
            }
        })
        .collect();
    let rms_before_px = rms(initial, frames, &before_rots, used);
    let per_frame_rms_px = (0..frames.len())
        .map(|f| rms(&camera, &frames[f..=f], &rots[f..=f], |_, s| inliers[f][s]))
        .collect();
    let rejected: Vec<(usize, usize)> = (0..frames.len())
        .flat_map(|f| (0..frames[f].stars.len()).map(move |s| (f, s)))
        .filter(|&(f, s)| !inliers[f][s])
        .collect();
    let stars_used = (0..frames.len())
        .filter(|&f| active[f])
        .map(|f| inliers[f].iter().filter(|&&k| k).count())
        .sum();
    Ok(Fit {
        camera,
        rotations: rots,
        rms_before_px,
        rms_after_px,
        per_frame_rms_px,
        stars_used,
        stars_rejected: rejected.len(),
        rejected,
        iterations,
        fitted: free_cam.iter().map(|&q| NAMES[q]).collect(),
        sigmas,
    })
}

#[cfg(test)]
#[path = "tests.rs"]
mod tests;
