//! The common motion field between consecutive frames: the rotation that carries the star field
//! of one frame onto the next, found from the detections alone. Under rotation stars move along
//! conics, not uniformly across the frame, so the model is the rotation itself, applied to each
//! detection's direction through the camera model. Particles, each moving on its own, are the
//! outliers: the stars are the one large set that a single rotation explains.

use crate::camera::Camera;
use crate::solve::attitude::wahba;
use nalgebra::{Matrix3, Vector3};

/// How the motion between two frames is searched for.
#[derive(Clone, Copy, Debug)]
pub struct MotionSettings {
    /// A detection of one frame and the other frame's detection it is carried onto match
    /// within this distance (pixels).
    pub gate_px: f64,
    /// The fastest camera turn searched (radians per second): it bounds how far a star moves
    /// between frames.
    pub max_turn_rad_s: f64,
    /// The brightest this many detections of each frame form the pairs hypotheses come from.
    pub hypothesis_stars: usize,
    /// Fewer stars carried onto the next frame than this: no motion found.
    pub min_inliers: usize,
}

impl Default for MotionSettings {
    fn default() -> Self {
        MotionSettings {
            gate_px: 2.0,
            max_turn_rad_s: 1f64.to_radians(),
            hypothesis_stars: 100,
            min_inliers: 6,
        }
    }
}

/// The rotation between two frames.
#[derive(Clone, Debug)]
pub struct Motion {
    /// u_b ≈ d · u_a for a star seen at u_a in frame a and u_b in frame b (camera frames).
    pub d: Matrix3<f64>,
    /// (detection in a, detection in b) of the stars it carries onto each other.
    pub inliers: Vec<(usize, usize)>,
    /// Median distance of those pairs after the fit (pixels).
    pub median_px: f64,
}

/// A frame's detections as the motion search uses them: pixels and camera-frame directions.
pub struct Points<'a> {
    pub px: &'a [(f64, f64)],
    pub dirs: &'a [Vector3<f64>],
}

/// The rotation from frame a to frame b, `dt_s` seconds apart: first the `predicted` one (the
/// last motion at constant rate, when there is one), else the best of the hypotheses made by
/// pairs of bright detections of a and b with the same separation, each pair moving no farther
/// than the fastest turn allows. None: no rotation carries `min_inliers` detections onto
/// detections (the frames share too few stars, or the turn was faster than searched).
pub fn estimate(
    camera: &Camera,
    a: &Points,
    b: &Points,
    dt_s: f64,
    predicted: Option<Matrix3<f64>>,
    s: &MotionSettings,
) -> Option<Motion> {
    let grid = Grid::new(b.px, camera, s.gate_px);
    // A prediction that holds is taken as it is found: it carries as many as a search would.
    let enough = s.min_inliers.max(a.px.len().min(b.px.len()) / 5);
    if let Some(d) = predicted
        && let Some(m) = polish(camera, a, b, &grid, d, s)
        && m.inliers.len() >= enough
    {
        return Some(m);
    }
    let (na, nb) = (
        a.px.len().min(s.hypothesis_stars),
        b.px.len().min(s.hypothesis_stars),
    );
    // How far any point of the frame can move in dt: the turn's angle seen at the corners,
    // where the gnomonic scale is largest.
    let half_diag = camera.diagonal_rad() / 2.0;
    let f = camera.fx.max(camera.fy);
    let reach = s.max_turn_rad_s * dt_s.abs() * f * (1.0 + half_diag.tan().powi(2)) + s.gate_px;
    // Beyond a quarter of the frame's diagonal the frames share few stars and the search
    // would pair nearly everything with everything (Swarm's heads, 600 s and 25–39° apart):
    // no motion, the frames are solved one by one.
    let (w, h) = (camera.width as f64, camera.height as f64);
    if reach > 0.25 * w.hypot(h) {
        return None;
    }
    let tol = 2.0 * s.gate_px * camera.ifov_rad();
    let near = |p: (f64, f64), q: (f64, f64)| (p.0 - q.0).hypot(p.1 - q.1) <= reach;
    let mut best: Option<(usize, Matrix3<f64>)> = None;
    let mut tried = 0u64;
    for i in 0..na {
        for j in i + 1..na {
            let sep = a.dirs[i].angle(&a.dirs[j]);
            for k in (0..nb).filter(|&k| near(a.px[i], b.px[k])) {
                for l in (0..nb).filter(|&l| l != k && near(a.px[j], b.px[l])) {
                    if (b.dirs[k].angle(&b.dirs[l]) - sep).abs() > tol {
                        continue;
                    }
                    let Some(d) = wahba(&[b.dirs[k], b.dirs[l]], &[a.dirs[i], a.dirs[j]]) else {
                        continue;
                    };
                    tried += 1;
                    let n = count(camera, a, &grid, &d, s.gate_px);
                    if best.as_ref().is_none_or(|(m, _)| n > *m) {
                        best = Some((n, d));
                    }
                }
            }
        }
    }
    let (n, d) = best?;
    if n < s.min_inliers || !significant(camera, a, b, n, tried, s) {
        return None;
    }
    polish(camera, a, b, &grid, d, s).filter(|m| m.inliers.len() >= s.min_inliers)
}

/// Could the best of `tried` rotations carry `n` detections onto detections by chance? Each of
/// a's detections lands within the gate of one of b's with probability nb·πg²/area; the
/// binomial tail times the hypotheses tried (Bonferroni) must be below [`MAX_CHANCE`].
fn significant(
    camera: &Camera,
    a: &Points,
    b: &Points,
    n: usize,
    tried: u64,
    s: &MotionSettings,
) -> bool {
    let area = camera.width as f64 * camera.height as f64;
    let p = (b.px.len() as f64 * std::f64::consts::PI * s.gate_px * s.gate_px / area).min(1.0);
    crate::solve::refine::binomial_tail(a.px.len(), n, p) * tried.max(1) as f64 <= MAX_CHANCE
}

/// The largest chance probability a motion found by search may have.
pub const MAX_CHANCE: f64 = 1e-6;

/// Refit a rotation to the pairs it carries onto each other (mutual nearest within the gate),
/// twice; None when fewer than two pairs remain.
fn polish(
    camera: &Camera,
    a: &Points,
    b: &Points,
    grid: &Grid,
    mut d: Matrix3<f64>,
    s: &MotionSettings,
) -> Option<Motion> {
    for _ in 0..3 {
        let inliers = pairs(camera, a, b, grid, &d, s.gate_px);
        if inliers.len() < 2 {
            return None;
        }
        let cam_b: Vec<_> = inliers.iter().map(|&(_, j)| b.dirs[j]).collect();
        let cam_a: Vec<_> = inliers.iter().map(|&(i, _)| a.dirs[i]).collect();
        d = wahba(&cam_b, &cam_a)?;
    }
    let inliers = pairs(camera, a, b, grid, &d, s.gate_px);
    let mut dist: Vec<f64> = inliers
        .iter()
        .filter_map(|&(i, j)| {
            let (x, y) = camera.vector_to_pixel(&(d * a.dirs[i]))?;
            Some((x - b.px[j].0).hypot(y - b.px[j].1))
        })
        .collect();
    dist.sort_by(f64::total_cmp);
    let median_px = dist.get(dist.len() / 2).copied().unwrap_or(0.0);
    Some(Motion {
        d,
        inliers,
        median_px,
    })
}

/// Detections of a that `d` carries within `gate` of some detection of b.
fn count(camera: &Camera, a: &Points, grid: &Grid, d: &Matrix3<f64>, gate: f64) -> usize {
    a.dirs
        .iter()
        .filter(|u| {
            camera
                .vector_to_pixel(&(d * *u))
                .is_some_and(|p| grid.nearest(p, gate).is_some())
        })
        .count()
}

/// The pairs (a, b) that are each other's nearest within `gate` once a is carried by `d`.
fn pairs(
    camera: &Camera,
    a: &Points,
    b: &Points,
    grid: &Grid,
    d: &Matrix3<f64>,
    gate: f64,
) -> Vec<(usize, usize)> {
    let moved: Vec<Option<(f64, f64)>> = a
        .dirs
        .iter()
        .map(|u| camera.vector_to_pixel(&(d * u)))
        .collect();
    let forward: Vec<Option<usize>> = moved
        .iter()
        .map(|p| p.and_then(|p| grid.nearest(p, gate)))
        .collect();
    let mut back: Vec<Option<(usize, f64)>> = vec![None; b.px.len()];
    for (i, (p, j)) in moved.iter().zip(&forward).enumerate() {
        let (Some(p), Some(j)) = (p, j) else { continue };
        let dist = (p.0 - b.px[*j].0).hypot(p.1 - b.px[*j].1);
        if back[*j].is_none_or(|(_, e)| dist < e) {
            back[*j] = Some((i, dist));
        }
    }
    forward
        .iter()
        .enumerate()
        .filter_map(|(i, j)| {
            let j = (*j)?;
            (back[j].map(|(k, _)| k) == Some(i)).then_some((i, j))
        })
        .collect()
}

/// Detections in square cells of the gate's size: the nearest within the gate is in the cell
/// of the point or one of its eight neighbours.
struct Grid<'a> {
    px: &'a [(f64, f64)],
    cell: f64,
    nx: i64,
    ny: i64,
    cells: Vec<Vec<usize>>,
}

impl<'a> Grid<'a> {
    fn new(px: &'a [(f64, f64)], camera: &Camera, gate: f64) -> Grid<'a> {
        let cell = gate.max(0.5);
        let nx = (camera.width as f64 / cell).ceil() as i64 + 2;
        let ny = (camera.height as f64 / cell).ceil() as i64 + 2;
        let mut cells = vec![Vec::new(); (nx * ny) as usize];
        let mut g = Grid {
            px,
            cell,
            nx,
            ny,
            cells: Vec::new(),
        };
        for (i, &p) in px.iter().enumerate() {
            if let Some(c) = g.cell_of(p) {
                cells[c].push(i);
            }
        }
        g.cells = cells;
        g
    }

    fn cell_of(&self, (x, y): (f64, f64)) -> Option<usize> {
        let (cx, cy) = (
            (x / self.cell).floor() as i64 + 1,
            (y / self.cell).floor() as i64 + 1,
        );
        (cx >= 0 && cy >= 0 && cx < self.nx && cy < self.ny).then(|| (cy * self.nx + cx) as usize)
    }

    /// The nearest detection within `gate` of p (the lowest index among equals).
    fn nearest(&self, p: (f64, f64), gate: f64) -> Option<usize> {
        let (cx, cy) = (
            (p.0 / self.cell).floor() as i64 + 1,
            (p.1 / self.cell).floor() as i64 + 1,
        );
        let mut best: Option<(f64, usize)> = None;
        for y in cy - 1..=cy + 1 {
            for x in cx - 1..=cx + 1 {
                if x < 0 || y < 0 || x >= self.nx || y >= self.ny {
                    continue;
                }
                for &i in &self.cells[(y * self.nx + x) as usize] {
                    let d = (self.px[i].0 - p.0).hypot(self.px[i].1 - p.1);
                    if d <= gate && best.is_none_or(|(e, k)| d < e || (d == e && i < k)) {
                        best = Some((d, i));
                    }
                }
            }
        }
        best.map(|(_, i)| i)
    }
}

/// The rotation `d` (over `dt` seconds) scaled to `dt_new` seconds at the same rate.
pub fn at_rate(d: &Matrix3<f64>, dt: f64, dt_new: f64) -> Matrix3<f64> {
    if dt.abs() < 1e-9 {
        return Matrix3::identity();
    }
    let axis_angle = nalgebra::Rotation3::from_matrix_unchecked(*d).scaled_axis();
    nalgebra::Rotation3::new(axis_angle * (dt_new / dt)).into_inner()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    /// A field of 40 stars turned by 0.8° about an axis with a roll component, and 60 points
    /// that each move on their own: the rotation is found from the detections alone.
    #[test]
    fn finds_the_turn_among_more_movers_than_stars() {
        let camera = Camera::from_fov(1024, 1024, 18.0).unwrap();
        let turn = Rotation3::new(Vector3::new(0.3, -0.8, 0.5).normalize() * 0.8f64.to_radians())
            .into_inner();
        let mut state = 12345u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut pa, mut pb) = (Vec::new(), Vec::new());
        for _ in 0..40 {
            let (x, y) = (50.0 + 924.0 * rnd(), 50.0 + 924.0 * rnd());
            let u = camera.pixel_to_vector(x, y);
            if let Some(q) = camera.vector_to_pixel(&(turn * u)) {
                pa.push((x, y));
                pb.push((q.0 + 0.2 * (rnd() - 0.5), q.1 + 0.2 * (rnd() - 0.5)));
            }
        }
        let stars = pa.len();
        for _ in 0..60 {
            let (x, y) = (1024.0 * rnd(), 1024.0 * rnd());
            pa.push((x, y));
            pb.push((x + 60.0 * (rnd() - 0.5), y + 60.0 * (rnd() - 0.5)));
        }
        // Frame b lists its detections in another order: movers and stars taking turns (as
        // bright particles push stars down a brightness order).
        let movers: Vec<usize> = (stars..pb.len()).collect();
        let mut order = Vec::new();
        for k in 0..pb.len() {
            if k < movers.len() {
                order.push(movers[k]);
            }
            if k < stars {
                order.push(k);
            }
        }
        let pb: Vec<(f64, f64)> = order.iter().map(|&k| pb[k]).collect();
        let place = |i: usize| order.iter().position(|&k| k == i).unwrap();
        let dirs = |p: &[(f64, f64)]| -> Vec<Vector3<f64>> {
            p.iter()
                .map(|&(x, y)| camera.pixel_to_vector(x, y))
                .collect()
        };
        let (da, db) = (dirs(&pa), dirs(&pb));
        let a = Points { px: &pa, dirs: &da };
        let b = Points { px: &pb, dirs: &db };
        let m = estimate(&camera, &a, &b, 1.0, None, &MotionSettings::default()).unwrap();
        let err = crate::solve::attitude::attitude_error(&m.d, &turn).to_degrees() * 3600.0;
        assert!(err < 5.0, "rotation off by {err} arcsec");
        let right = m
            .inliers
            .iter()
            .filter(|&&(i, j)| i < stars && j == place(i))
            .count();
        assert!(right >= stars - 2 && m.inliers.len() <= right + 2, "{m:?}");
        // The same motion predicted is taken as it is.
        let again = estimate(&camera, &a, &b, 1.0, Some(m.d), &MotionSettings::default()).unwrap();
        assert_eq!(again.inliers, m.inliers);
        // Frames with nothing in common: no motion.
        let pc: Vec<(f64, f64)> = (0..50).map(|_| (1024.0 * rnd(), 1024.0 * rnd())).collect();
        let dc = dirs(&pc);
        let c = Points { px: &pc, dirs: &dc };
        assert!(estimate(&camera, &a, &c, 1.0, None, &MotionSettings::default()).is_none());
    }

    #[test]
    fn at_rate_scales_the_angle() {
        let d = Rotation3::new(Vector3::new(0.0, 0.01, 0.0)).into_inner();
        let e = at_rate(&d, 1.0, 2.5);
        let want = Rotation3::new(Vector3::new(0.0, 0.025, 0.0)).into_inner();
        assert!(crate::solve::attitude::attitude_error(&e, &want) < 1e-12);
    }
}
