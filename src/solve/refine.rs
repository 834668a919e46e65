//! Refinement and acceptance: from a first attitude, project the reference stars in view,
//! match detections to them one to one, refit, and judge the result by the probability that a
//! wrong attitude would match as many stars by chance.

use crate::camera::{Camera, angle};
use crate::catalog::RefCatalog;
use crate::solve::attitude::{wahba, wahba_weighted};
use crate::solve::detect::Detection;
use nalgebra::{Matrix3, Vector3};

/// Settings of refinement and acceptance.
#[derive(Clone, Copy, Debug)]
pub struct RefineSettings {
    /// A detection matches a projected catalog star within this distance (pixels).
    pub match_radius_px: f64,
    /// Accept a solution only when its false-match probability is below this.
    pub max_false_prob: f64,
    /// Refit rounds.
    pub rounds: usize,
    /// What of the camera to fit besides the attitude.
    pub fit: CameraFit,
}

crate::choice! {
    /// Camera parameters refinement may fit along with the attitude.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum CameraFit {
        None = "none", "The camera as given",
        Scale = "scale", "The focal length (one factor for fx and fy): the field of view",
        Distortion = "distortion", "The focal length and the radial distortion k1",
    }
}

/// Matches needed before the focal length is fitted, and before k1 is.
pub const MIN_MATCHES_SCALE: usize = 8;
pub const MIN_MATCHES_DISTORTION: usize = 16;

impl RefineSettings {
    /// The defaults (`Default`), as a constant: the run configuration's (`config`) come
    /// from here.
    pub const DEFAULT: RefineSettings = RefineSettings {
        match_radius_px: 2.0,
        max_false_prob: 1e-6,
        rounds: 4,
        fit: CameraFit::None,
    };
}

impl Default for RefineSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A detection matched to a reference star.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Match {
    /// Index into the detections.
    pub det: usize,
    pub ref_id: u32,
    /// Angle between the detection's direction and the star's (arcsec).
    pub residual_arcsec: f64,
    /// Distance between the detection and the projected star (pixels).
    pub residual_px: f64,
    /// The weight's 1σ per axis (pixels): the PSF fit's, with the frame's floor added in
    /// quadrature ([`match_sigmas`]); None when the detections carry no 1σ (centre of gravity)
    /// and the fit weighs every match alike.
    pub sigma_px: Option<f64>,
}

/// A refined solution.
#[derive(Clone, Debug)]
pub struct Refined {
    pub r: Matrix3<f64>,
    /// The camera the solution holds for (fitted when refinement fits it).
    pub camera: Camera,
    pub matches: Vec<Match>,
    /// Reference stars that project inside the image.
    pub in_view: usize,
    pub rmse_arcsec: f64,
    pub p90_arcsec: f64,
    pub max_arcsec: f64,
    pub false_match_prob: f64,
    /// What the false-match probability counted: the hypotheses a chance match could come
    /// from, and the stars that fixed the one accepted (2 for a pair or a predicted attitude,
    /// 3 for a triangle). Refining again from another start counts the same.
    pub hypotheses: u64,
    pub fixed: usize,
    /// The floor added in quadrature to the PSF fits' 1σ so that the residuals' χ² equals its
    /// degrees of freedom (pixels; `--centroid ml` only).
    pub sigma_floor_px: Option<f64>,
}

/// Reference stars projecting inside the image under `r`: (ref id, pixel).
pub fn stars_in_view(r: &Matrix3<f64>, refs: &RefCatalog, camera: &Camera) -> Vec<(u32, f64, f64)> {
    stars_around_view(r, refs, camera, 0.0)
}

/// Reference stars projecting within `margin` pixels of the image under `r`, its edges
/// included: (ref id, pixel). A star just beyond an edge still lights the pixels along it.
pub fn stars_around_view(
    r: &Matrix3<f64>,
    refs: &RefCatalog,
    camera: &Camera,
    margin: f64,
) -> Vec<(u32, f64, f64)> {
    let boresight = r.transpose() * camera.centre_vector();
    let cone = refs.within(&boresight, view_half_angle(camera));
    in_view_of(r, refs, camera, cone.into_iter(), margin)
}

/// Those of the reference stars `ids` (rising) that project inside the image under `r`, or
/// within `margin` pixels of it.
fn in_view_of(
    r: &Matrix3<f64>,
    refs: &RefCatalog,
    camera: &Camera,
    ids: impl Iterator<Item = u32>,
    margin: f64,
) -> Vec<(u32, f64, f64)> {
    let boresight = r.transpose() * camera.centre_vector();
    let cos_half = view_half_angle(camera).cos();
    let (w, h) = (f64::from(camera.width), f64::from(camera.height));
    ids.map(|id| (id, refs.v(id as usize)))
        .filter(|(_, v)| v.dot(&boresight) >= cos_half)
        .filter_map(|(id, v)| {
            let (x, y) = camera.vector_to_pixel(&(r * v))?;
            let inside = x >= -0.5 - margin
                && y >= -0.5 - margin
                && x <= w - 0.5 + margin
                && y <= h - 0.5 + margin;
            inside.then_some((id, x, y))
        })
        .collect()
}

/// The half-angle of the cone [`stars_in_view`] tests around the boresight.
fn view_half_angle(camera: &Camera) -> f64 {
    (camera.diagonal_rad() * 0.5 + 0.01).min(std::f64::consts::PI)
}

/// How much wider than the view the stars kept for one refinement's later rounds reach
/// (radians): its rounds move the attitude by pixels, not by a quarter of a degree.
const NEARBY_MARGIN_RAD: f64 = 0.25 * std::f64::consts::PI / 180.0;

/// The reference stars within `reach` of `axis`, in id order: those a refinement's later
/// rounds test, where a scan of the whole selection took each round.
struct Nearby {
    axis: Vector3<f64>,
    reach: f64,
    ids: Vec<u32>,
}

/// [`stars_in_view`], testing only the stars of `nearby` when the view's cone lies inside
/// theirs (with a microradian to spare for rounding), else first keeping in `nearby` the stars
/// within [`NEARBY_MARGIN_RAD`] of the view: the same tests on a superset of the stars in
/// view, so the same stars in the same order.
fn stars_in_view_near(
    r: &Matrix3<f64>,
    refs: &RefCatalog,
    camera: &Camera,
    nearby: &mut Option<Nearby>,
) -> Vec<(u32, f64, f64)> {
    let boresight = r.transpose() * camera.centre_vector();
    let half = view_half_angle(camera);
    let inside = |n: &Nearby| angle(&n.axis, &boresight) + half <= n.reach - 1e-6;
    let near = match nearby {
        Some(n) if inside(n) => n,
        _ => {
            let reach = (half + NEARBY_MARGIN_RAD).min(std::f64::consts::PI);
            let ids = refs.within(&boresight, reach);
            nearby.insert(Nearby {
                axis: boresight,
                reach,
                ids,
            })
        }
    };
    in_view_of(r, refs, camera, near.ids.iter().copied(), 0.0)
}

/// One-to-one matches: a detection and a projected star that are each other's nearest, within
/// the radius.
fn mutual_nearest(dets: &[Detection], proj: &[(u32, f64, f64)], radius: f64) -> Vec<(usize, u32)> {
    let r2 = radius * radius;
    let d2 = |d: &Detection, p: &(u32, f64, f64)| (d.x - p.1).powi(2) + (d.y - p.2).powi(2);
    let nearest_proj: Vec<Option<usize>> = dets
        .iter()
        .map(|d| {
            (0..proj.len())
                .filter(|&k| d2(d, &proj[k]) <= r2)
                .min_by(|&a, &b| d2(d, &proj[a]).total_cmp(&d2(d, &proj[b])))
        })
        .collect();
    let mut out = Vec::new();
    for (di, np) in nearest_proj.iter().enumerate() {
        let Some(k) = *np else { continue };
        let back = (0..dets.len())
            .min_by(|&a, &b| d2(&dets[a], &proj[k]).total_cmp(&d2(&dets[b], &proj[k])))
            .unwrap();
        if back == di {
            out.push((di, proj[k].0));
        }
    }
    out
}

/// Smallest radius the false-match probability assumes (pixels): the confidence never rests on
/// a match being closer than typical centroid errors.
pub const CONFIDENCE_RADIUS_FLOOR_PX: f64 = 0.5;

/// Refine a first attitude; None when nothing matches. `dets` come brightest first (as
/// `detect::star_list` orders them: the false-match test looks at the brightest first).
/// `hypotheses` and `fixed` (the stars that made the hypothesis: 2 for a pair, 3 for a
/// triangle) enter the false-match probability.
pub fn refine(
    r0: Matrix3<f64>,
    dets: &[Detection],
    refs: &RefCatalog,
    camera: &Camera,
    hypotheses: u64,
    fixed: usize,
    s: &RefineSettings,
) -> Option<Refined> {
    let mut r = r0;
    let mut camera = camera.clone();
    let vectors_of = |c: &Camera| -> Vec<Vector3<f64>> {
        dets.iter().map(|d| c.pixel_to_vector(d.x, d.y)).collect()
    };
    let mut det_vectors = vectors_of(&camera);
    let mut pairs: Vec<(usize, u32)> = Vec::new();
    let mut in_view = 0;
    let mut view: Vec<(u32, f64, f64)> = Vec::new();
    let mut nearby = None;
    for _ in 0..s.rounds.max(1) {
        let proj = stars_in_view_near(&r, refs, &camera, &mut nearby);
        in_view = proj.len();
        view.clone_from(&proj);
        let next = mutual_nearest(dets, &proj, s.match_radius_px);
        if next.len() < 2 {
            return None;
        }
        let fit = match s.fit {
            CameraFit::Distortion if next.len() >= MIN_MATCHES_DISTORTION => CameraFit::Distortion,
            CameraFit::Distortion | CameraFit::Scale if next.len() >= MIN_MATCHES_SCALE => {
                CameraFit::Scale
            }
            _ => CameraFit::None,
        };
        let weights = weights_at(&r, &camera, dets, &det_vectors, refs, &next);
        if fit == CameraFit::None {
            r = fit_attitude(&next, &det_vectors, refs, weights.as_deref())?;
        } else {
            (r, camera) = fit_camera(r, &camera, dets, &next, refs, fit, weights.as_deref());
            det_vectors = vectors_of(&camera);
        }
        let stable = next == pairs;
        pairs = next;
        if stable {
            break;
        }
    }
    // Weights from the final attitude's residuals (the loop's last fit used the previous one's).
    if let Some(w) = weights_at(&r, &camera, dets, &det_vectors, refs, &pairs)
        && (s.fit == CameraFit::None || pairs.len() < MIN_MATCHES_SCALE)
    {
        r = fit_attitude(&pairs, &det_vectors, refs, Some(&w))?;
    }
    let (mut matches, scatter) = residuals(&r, &camera, dets, &det_vectors, refs, &pairs);
    // The evidence of a match is how close it is: chance places a star within r of one of the
    // detections with probability N·πr²/area. r is three times the scatter of the residuals
    // (with 3 degrees of freedom taken by the fit), at least CONFIDENCE_RADIUS_FLOOR_PX, at
    // most the match radius; matches farther out count as unmatched. The test is made on the
    // brightest m detections against the brightest k catalog stars in view (m and k doubling
    // from 10, Bonferroni over both), as tetra3 verifies with the brightest catalog stars: a
    // sensor that shows 6 stars is judged by the catalog stars it can show, not by the 40 a
    // deeper selection puts in view, so an unknown or too deep magnitude limit costs little.
    let radius = (3.0 * scatter).clamp(CONFIDENCE_RADIUS_FLOOR_PX, s.match_radius_px);
    let area = camera.width as f64 * camera.height as f64;
    // Each match's place among the catalog stars in view, brightest first (ids are in
    // brightness order, and so is the list).
    let rank: std::collections::HashMap<u32, usize> = view
        .iter()
        .enumerate()
        .map(|(k, &(id, _, _))| (id, k))
        .collect();
    let false_match_prob = brightest_first(dets.len(), |m| {
        let p_single = (m as f64 * std::f64::consts::PI * radius * radius / area).min(1.0);
        brightest_first(in_view, |k| {
            let close = matches
                .iter()
                .filter(|x| x.det < m && x.residual_px <= radius)
                .filter(|x| rank.get(&x.ref_id).is_some_and(|&q| q < k))
                .count();
            false_match_probability(close, k, p_single, hypotheses, fixed)
        })
    });
    // Centroids scattered by more than a third of the match radius (blur, defocus) leave many
    // of their stars outside it: once the solution is accepted, the attitude is fitted again to
    // the mutual nearest stars within POLISH_RADIUS_MAX match radii, which recovers them.
    let accepted = false_match_prob <= s.max_false_prob;
    // An accepted solution whose matches have brighter unmatched copies (a double exposure's,
    // ghosts) is no solution: the search goes on.
    if accepted {
        let matched: Vec<usize> = matches.iter().map(|m| m.det).collect();
        let copied = super::explain::copied_matches(dets, &matched);
        if !super::explain::explained(copied, matches.len()) {
            tracing::debug!(
                "refused: {copied} of {} matches have a brighter unmatched copy in one relation",
                matches.len()
            );
            return None;
        }
    }
    if accepted && s.fit == CameraFit::None && 3.0 * scatter > s.match_radius_px {
        // The scatter of matches cut off at the match radius understates the true one.
        let wide = POLISH_RADIUS_MAX * s.match_radius_px;
        for _ in 0..s.rounds.max(1) {
            let proj = stars_in_view_near(&r, refs, &camera, &mut nearby);
            let next = mutual_nearest(dets, &proj, wide);
            if next.len() < pairs.len() {
                break;
            }
            let w = weights_at(&r, &camera, dets, &det_vectors, refs, &next);
            let Some(r1) = fit_attitude(&next, &det_vectors, refs, w.as_deref()) else {
                break;
            };
            r = r1;
            let stable = next == pairs;
            pairs = next;
            if stable {
                break;
            }
        }
        matches = residuals(&r, &camera, dets, &det_vectors, refs, &pairs).0;
    }
    let sigma_floor_px = match_sigmas(dets, &mut matches);
    let mut res: Vec<f64> = matches.iter().map(|m| m.residual_arcsec).collect();
    res.sort_by(f64::total_cmp);
    let rmse = (res.iter().map(|x| x * x).sum::<f64>() / res.len() as f64).sqrt();
    let p90 = res[((res.len() as f64 * 0.9).ceil() as usize).clamp(1, res.len()) - 1];
    Some(Refined {
        r,
        camera,
        in_view,
        rmse_arcsec: rmse,
        p90_arcsec: p90,
        max_arcsec: *res.last().unwrap(),
        matches,
        false_match_prob,
        hypotheses,
        fixed,
        sigma_floor_px,
    })
}

/// The attitude that best maps the matched stars onto their detections (Wahba, weighted when
/// `weights` are given).
fn fit_attitude(
    pairs: &[(usize, u32)],
    det_vectors: &[Vector3<f64>],
    refs: &RefCatalog,
    weights: Option<&[f64]>,
) -> Option<Matrix3<f64>> {
    let cam: Vec<_> = pairs.iter().map(|&(d, _)| det_vectors[d]).collect();
    let icrs: Vec<_> = pairs.iter().map(|&(_, id)| refs.v(id as usize)).collect();
    match weights {
        Some(w) => wahba_weighted(&cam, &icrs, w),
        None => wahba(&cam, &icrs),
    }
}

/// The weights (1/σ², pixels⁻²) of matched pairs under an attitude, when the detections carry
/// their 1σ: see [`match_sigmas`]. None when none does.
fn weights_at(
    r: &Matrix3<f64>,
    camera: &Camera,
    dets: &[Detection],
    det_vectors: &[Vector3<f64>],
    refs: &RefCatalog,
    pairs: &[(usize, u32)],
) -> Option<Vec<f64>> {
    dets.iter().find(|d| d.sigma_px.is_some())?;
    let mut matches = residuals(r, camera, dets, det_vectors, refs, pairs).0;
    match_sigmas(dets, &mut matches)?;
    Some(
        matches
            .iter()
            .map(|m| m.sigma_px.map_or(0.0, |s| 1.0 / (s * s)))
            .collect(),
    )
}

/// Each match's 1σ per axis for weighting: the PSF fit's (a detection without one, a centre of
/// gravity where the fit did not settle, takes the largest of the others'), with a floor σ_f
/// added in quadrature so that Σ r²/(σ² + σ_f²) equals the 2n − 3 degrees of freedom: what
/// the fit's photon noise does not explain (the camera model, the catalog, seeing) weighs
/// every star alike, so the bright stars' tiny 1σ do not take the whole weight. Sets
/// `sigma_px` of each match and returns σ_f; None (nothing set) without PSF fits.
pub fn match_sigmas(dets: &[Detection], matches: &mut [Match]) -> Option<f64> {
    let worst = matches
        .iter()
        .filter_map(|m| dets[m.det].sigma_px)
        .fold(None, |a: Option<f64>, s| Some(a.map_or(s, |a| a.max(s))))?;
    let fit: Vec<f64> = matches
        .iter()
        .map(|m| dets[m.det].sigma_px.unwrap_or(worst).powi(2))
        .collect();
    // A star that no longer projects has no residual to weigh: the fit stays unweighted.
    let r2: Vec<f64> = matches.iter().map(|m| m.residual_px.powi(2)).collect();
    if !r2.iter().all(|r| r.is_finite()) {
        return None;
    }
    let dof = (2 * matches.len()).saturating_sub(3).max(1) as f64;
    // χ²(f) = Σ r²/(σ² + f) falls with f; at f = Σr²/dof it is at most dof.
    let chi2 = |f: f64| -> f64 { r2.iter().zip(&fit).map(|(r, s)| r / (s + f)).sum() };
    let mut floor = 0.0;
    if chi2(0.0) > dof {
        let (mut lo, mut hi) = (0.0, r2.iter().sum::<f64>() / dof);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            // No double between them: every later step would leave both as they are.
            if mid <= lo || mid >= hi {
                break;
            }
            if chi2(mid) > dof { lo = mid } else { hi = mid }
        }
        floor = hi;
    }
    for (m, s) in matches.iter_mut().zip(&fit) {
        m.sigma_px = Some((s + floor).sqrt());
    }
    Some(floor.sqrt())
}

/// The polish's largest match radius, in match radii.
const POLISH_RADIUS_MAX: f64 = 3.0;

/// The matches with their residuals under `r`, and the scatter of the pixel residuals (with
/// 3 degrees of freedom taken by the fit).
fn residuals(
    r: &Matrix3<f64>,
    camera: &Camera,
    dets: &[Detection],
    det_vectors: &[Vector3<f64>],
    refs: &RefCatalog,
    pairs: &[(usize, u32)],
) -> (Vec<Match>, f64) {
    let matches: Vec<Match> = pairs
        .iter()
        .map(|&(det, ref_id)| {
            let v = r * refs.v(ref_id as usize);
            let residual_px = camera.vector_to_pixel(&v).map_or(f64::INFINITY, |(x, y)| {
                (x - dets[det].x).hypot(y - dets[det].y)
            });
            Match {
                det,
                ref_id,
                residual_arcsec: angle(&det_vectors[det], &v).to_degrees() * 3600.0,
                residual_px,
                sigma_px: None,
            }
        })
        .collect();
    let dof = (2 * matches.len()).saturating_sub(3).max(1) as f64;
    let scatter = (matches.iter().map(|m| m.residual_px.powi(2)).sum::<f64>() / dof).sqrt();
    (matches, scatter)
}

/// Fit attitude and camera (focal scale, and k1 with `Distortion`) to matched stars by
/// Gauss–Newton on pixel residuals, from the current values. Parameters: a small rotation ω
/// (R ← exp(ω)·R), the log of the focal scale, and k1. The result is kept only if it lowers
/// the squared residuals.
fn fit_camera(
    r: Matrix3<f64>,
    camera: &Camera,
    dets: &[Detection],
    pairs: &[(usize, u32)],
    refs: &RefCatalog,
    fit: CameraFit,
    weights: Option<&[f64]>,
) -> (Matrix3<f64>, Camera) {
    // Residuals scaled by √w: least squares weighted.
    let root: Vec<f64> = match weights {
        Some(w) => w.iter().map(|w| w.sqrt()).collect(),
        None => vec![1.0; pairs.len()],
    };
    let n_par = if fit == CameraFit::Distortion { 5 } else { 4 };
    let apply = |p: &[f64]| -> (Matrix3<f64>, Camera) {
        let rot = nalgebra::Rotation3::new(Vector3::new(p[0], p[1], p[2])).into_inner() * r;
        let mut c = camera.clone();
        c.fx *= p[3].exp();
        c.fy *= p[3].exp();
        if n_par == 5 {
            c.k1 = camera.k1 + p[4];
        }
        (rot, c)
    };
    let residuals = |p: &[f64]| -> Option<Vec<f64>> {
        let (rot, c) = apply(p);
        let mut out = Vec::with_capacity(2 * pairs.len());
        for (&(d, id), w) in pairs.iter().zip(&root) {
            let (x, y) = c.vector_to_pixel(&(rot * refs.v(id as usize)))?;
            out.push(w * (x - dets[d].x));
            out.push(w * (y - dets[d].y));
        }
        Some(out)
    };
    let cost = |f: &[f64]| f.iter().map(|x| x * x).sum::<f64>();
    let mut p = vec![0.0; n_par];
    let Some(mut f) = residuals(&p) else {
        return (r, camera.clone());
    };
    let start = cost(&f);
    let steps = [1e-7, 1e-7, 1e-7, 1e-7, 1e-5];
    for _ in 0..8 {
        // Jacobian by forward differences.
        let m = f.len();
        let mut j = nalgebra::DMatrix::<f64>::zeros(m, n_par);
        for k in 0..n_par {
            let mut q = p.clone();
            q[k] += steps[k];
            let Some(fk) = residuals(&q) else {
                return (r, camera.clone());
            };
            for row in 0..m {
                j[(row, k)] = (fk[row] - f[row]) / steps[k];
            }
        }
        let jt = j.transpose();
        let Some(delta) = (&jt * &j)
            .lu()
            .solve(&(-(&jt * nalgebra::DVector::from_vec(f.clone()))))
        else {
            break;
        };
        let q: Vec<f64> = p.iter().zip(delta.iter()).map(|(a, b)| a + b).collect();
        match residuals(&q) {
            Some(fq) if cost(&fq) < cost(&f) => {
                p = q;
                f = fq;
            }
            _ => break,
        }
        if delta.norm() < 1e-12 {
            break;
        }
    }
    if cost(&f) < start {
        apply(&p)
    } else {
        (r, camera.clone())
    }
}

/// The smallest false-match probability `prob(m)` over the brightest m = 10, 20, 40, … and
/// all `n` (detections, or catalog stars in view), times the number of m tried (Bonferroni). Real stars are among the
/// brightest detections: 6 matches among the brightest 10 are far stronger evidence than 6
/// among 100 in a frame of faint stars and noise detections (openstartracker's img7.png: 2.6e-4
/// instead of 0.052, all else the same), while a frame whose matches spread over all its
/// detections pays a factor of at most 5 (100 detections).
pub fn brightest_first(n: usize, prob: impl Fn(usize) -> f64) -> f64 {
    let mut counts: Vec<usize> = std::iter::successors(Some(10), |m| Some(2 * m))
        .take_while(|&m| m < n)
        .collect();
    counts.push(n);
    let best = counts.iter().map(|&m| prob(m)).fold(1.0, f64::min);
    (best * counts.len() as f64).min(1.0)
}

/// Probability that a wrong attitude matches `matched` of the `in_view` catalog stars by chance
/// (tetra3's binomial test): `fixed` stars (two for a voted pair, three for a triangle) fix a
/// hypothesis, each other star in view lands within the radius of some detection with
/// probability `p_single`; the tail is multiplied by the number of hypotheses considered
/// (Bonferroni).
pub fn false_match_probability(
    matched: usize,
    in_view: usize,
    p_single: f64,
    hypotheses: u64,
    fixed: usize,
) -> f64 {
    if matched <= fixed || in_view < matched {
        return 1.0;
    }
    let tail = binomial_tail(in_view - fixed, matched - fixed, p_single);
    (tail * hypotheses.max(1) as f64).min(1.0)
}

/// P(X ≥ k) for X ~ Binomial(n, p), summed in log space.
pub fn binomial_tail(n: usize, k: usize, p: f64) -> f64 {
    if k == 0 {
        return 1.0;
    }
    if k > n || p <= 0.0 {
        return 0.0;
    }
    if p >= 1.0 {
        return 1.0;
    }
    let ln_fact: Vec<f64> = std::iter::once(0.0)
        .chain((1..=n).scan(0.0, |acc, i| {
            *acc += (i as f64).ln();
            Some(*acc)
        }))
        .collect();
    let (lp, lq) = (p.ln(), (-p).ln_1p());
    let terms: Vec<f64> = (k..=n)
        .map(|i| ln_fact[n] - ln_fact[i] - ln_fact[n - i] + i as f64 * lp + (n - i) as f64 * lq)
        .collect();
    let m = terms.iter().copied().fold(f64::MIN, f64::max);
    (m + terms.iter().map(|t| (t - m).exp()).sum::<f64>().ln()).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A refinement's later rounds, which test only the stars kept nearby, see the stars a
    /// whole scan sees, in the same order: attitudes moved by up to a tenth of a degree (kept
    /// stars reused), by a degree (scanned again), and a field of view half as wide again
    /// (scanned again).
    #[test]
    fn the_stars_kept_nearby_are_the_stars_in_view() {
        use crate::catalog::{Catalog, DoubleStars, Selection};
        use rand::{Rng, SeedableRng};
        let selection = Selection {
            epoch: 2025.0,
            mag_limit: 6.5,
            double_stars: DoubleStars::Keep,
            double_sep_rad: 0.0,
        };
        let refs = RefCatalog::select(&Catalog::builtin(), selection).unwrap();
        let narrow = Camera::from_fov(1024, 768, 10.0).unwrap();
        let wide = Camera::from_fov(1024, 768, 15.0).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (mut reused, mut seen) = (0, 0);
        for _ in 0..20 {
            let r0 = crate::simulate::random_rotation(&mut rng);
            let mut nearby = None;
            for step_deg in [0.0f64, 0.02, 0.1, 0.05, 1.0, 0.0] {
                let axis = Vector3::new(rng.random(), rng.random(), rng.random()).normalize();
                let turn = nalgebra::Rotation3::from_axis_angle(
                    &nalgebra::Unit::new_normalize(axis),
                    step_deg.to_radians(),
                );
                let r = turn.matrix() * r0;
                for camera in [&narrow, &narrow, &wide] {
                    let before = nearby.as_ref().map(|n: &Nearby| n.axis);
                    let got = stars_in_view_near(&r, &refs, camera, &mut nearby);
                    assert_eq!(got, stars_in_view(&r, &refs, camera), "{step_deg}°");
                    reused += (before == nearby.as_ref().map(|n| n.axis)) as usize;
                    seen += got.len();
                }
            }
        }
        assert!(reused > 100 && seen > 1000, "{reused} reuses, {seen} stars");
    }

    #[test]
    fn binomial_tail_matches_direct_sums() {
        // n = 5, p = 0.5: P(X ≥ 3) = (10 + 5 + 1) / 32.
        assert!((binomial_tail(5, 3, 0.5) - 0.5).abs() < 1e-12);
        assert!((binomial_tail(10, 1, 0.1) - (1.0 - 0.9f64.powi(10))).abs() < 1e-12);
        // Tiny tails stay accurate: P(X ≥ 20) for n = 20 is p^20.
        assert!((binomial_tail(20, 20, 1e-3) / 1e-60 - 1.0).abs() < 1e-9);
        assert_eq!(binomial_tail(3, 4, 0.5), 0.0);
    }

    #[test]
    fn brightest_first_tries_doubling_counts_and_pays_for_each() {
        // 100 detections: 10, 20, 40, 80 and 100 tried, the best times 5.
        let tried = std::cell::RefCell::new(Vec::new());
        let p = brightest_first(100, |m| {
            tried.borrow_mut().push(m);
            if m == 20 { 1e-9 } else { 1e-3 }
        });
        assert_eq!(*tried.borrow(), vec![10, 20, 40, 80, 100]);
        assert!((p - 5e-9).abs() < 1e-20);
        // Ten or fewer: all of them, once.
        assert_eq!(brightest_first(7, |m| m as f64 * 1e-3), 7e-3);
        assert_eq!(brightest_first(10, |_| 0.5), 0.5);
    }

    #[test]
    fn the_detection_retrys_same_star_is_the_radius_floor() {
        assert_eq!(
            crate::solve::detect::SAME_STAR_PX,
            CONFIDENCE_RADIUS_FLOOR_PX
        );
    }

    #[test]
    fn false_match_probability_needs_three_stars() {
        assert_eq!(false_match_probability(2, 10, 1e-4, 1, 2), 1.0);
        assert!(false_match_probability(6, 10, 1e-4, 1000, 2) < 1e-9);
    }
}
