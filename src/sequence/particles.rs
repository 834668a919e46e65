//! Particle rejection over frames (seed 003, criterion 2: projection velocities against the
//! common motion field, decided by Wald's sequential probability ratio test).
//!
//! Every detection belongs to a track. Tracks live in the reference frame of the sequence (the
//! first frame's camera frame, carried through the motion found between frames), where a star
//! stands still and a particle moves. Each time a track is continued, its step (where the
//! detection is, against where the track's last point would be had it stood still, in this
//! frame's pixels) is evidence: for a star the step is centroid noise, N(0, σ²) in x and y; for
//! a particle moving at Δ or more it is offset by Δ·dt. Wald's test on the step's length
//! (Rayleigh against Rice) accumulates the log-likelihood ratio until it crosses
//! ln((1 − β)/α) (particle) or ln(β/(1 − α)) (star), α being the probability of calling a star
//! a particle and β of calling a particle a star. Tracks not yet decided are stars for
//! identification (frames are solved as without a sequence); particles never vote or match.
//! A particle slower than Δ, whose steps are noise-sized, is told by the drift test
//! ([`super::drift`]) from the line its last points make.

use super::drift;
use crate::camera::Camera;
use nalgebra::{Matrix3, Vector3};

/// The particle test's settings.
#[derive(Clone, Copy, Debug)]
pub struct ParticleSettings {
    /// P(a star is called a particle): the test's false alarm.
    pub alpha: f64,
    /// P(a particle is called a star): the test's miss.
    pub beta: f64,
    /// Δ: the slowest motion against the stars the test is designed to catch (radians per
    /// second). Seed 003's particles move at 6′/s or more; half of that is the design point.
    pub min_speed_rad_s: f64,
    /// The fastest particle followed from one frame to the next (radians per second).
    pub max_speed_rad_s: f64,
    /// A star's detection is looked for within this distance of where it stood (pixels).
    pub static_gate_px: f64,
    /// Smallest step noise σ assumed (pixels, per axis): centroids are never taken as better.
    pub sigma_floor_px: f64,
    /// A track not continued for this many frames ends.
    pub max_gap_frames: usize,
    /// P(a star well above the detection limit is missing from a frame): a bright detection
    /// with nothing where it stood in the previous frame, which looked there, is a particle
    /// by ln(1/this) (a particle that has just appeared, or lost its track).
    pub star_miss_prob: f64,
    /// "Well above the detection limit": this many times the flux of the previous frame's
    /// faintest detection.
    pub bright_factor: f64,
    /// A track is continued only by a detection whose flux is within this factor of its last:
    /// a star merged with a passing particle is not the star, and its offset centroid must not
    /// count as a step.
    pub flux_ratio: f64,
    /// ... widened near the detection limit for a particle continued where its velocity puts
    /// it, as a component's sum rises and falls with the pixels that clear the threshold
    /// (defocused particles most: a third of those within twice the faintest flux change by
    /// more than 2× from one frame to the next): the bound on
    /// |ln(flux ratio)| is ln(`flux_ratio`) + this × q², q = (faintest flux of the two frames)
    /// / (the fainter of the two fluxes). Squared, so that a star a few times the limit merged
    /// with a particle as bright is still refused (at q = 1/5 the bound is 2.25×).
    pub faint_flux_widening: f64,
}

impl Default for ParticleSettings {
    fn default() -> Self {
        ParticleSettings {
            alpha: 5e-3,
            beta: 1e-2,
            min_speed_rad_s: (3.0f64 / 60.0).to_radians(),
            // 60′/s.
            max_speed_rad_s: 1f64.to_radians(),
            static_gate_px: 3.0,
            sigma_floor_px: 0.2,
            // A particle lost for two frames (behind a star, or below the limit) is found again
            // where its velocity puts it; with 2, it came back as a new track that looked
            // still for its first steps (docs/sequences.md, "Tracks that outlive a gap").
            max_gap_frames: 3,
            star_miss_prob: 2e-3,
            bright_factor: 3.0,
            flux_ratio: 2.0,
            faint_flux_widening: 3.0,
        }
    }
}

/// What the test has decided about a track.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decision {
    Undecided,
    Star,
    Particle,
}

/// A detection's track.
#[derive(Clone, Debug)]
struct Track {
    /// Reference-frame direction of the last point, and its time (s).
    last: (Vector3<f64>, f64),
    /// The point before it, when the track has one.
    prev: Option<(Vector3<f64>, f64)>,
    last_frame: usize,
    /// The flux of the last point.
    flux: f64,
    llr: f64,
    decision: Decision,
    /// The track's last points clear of the frame's edge (reference-frame directions and
    /// times), at most [`drift::POINTS`], for the drift test.
    history: Vec<(Vector3<f64>, f64)>,
}

impl Track {
    /// Keep a point for the drift test: the reference-frame direction `w` at time `t`, seen at
    /// pixel `p` of this frame (left out within [`drift::EDGE_PX`] of the border).
    fn remember(&mut self, cam: &Camera, p: (f64, f64), w: Vector3<f64>, t: f64) {
        if !inside(cam, p.0, p.1, drift::EDGE_PX) {
            return;
        }
        if self.history.len() == drift::POINTS {
            self.history.remove(0);
        }
        self.history.push((w, t));
    }
}

/// The drift test ([`drift`]) on the tracks this frame continued (`owner[j]`: detection `j`'s
/// track): a track not yet called a particle whose points move steadily against the stars'
/// velocity field becomes one.
fn drift_test(
    tracks: &mut [Track],
    cam: &Camera,
    owner: &[Option<usize>],
    px: &[(f64, f64)],
    to_px: &drift::Project,
    sigma: f64,
) {
    let continued: Vec<drift::Continued> = owner
        .iter()
        .enumerate()
        .filter_map(|(j, k)| {
            k.map(|k| drift::Continued {
                at: px[j],
                star: tracks[k].decision == Decision::Star,
                line: drift::line_fit(&tracks[k].history, to_px),
            })
        })
        .collect();
    let continued_tracks = owner.iter().flatten();
    for (k, moving) in continued_tracks.zip(drift::drifting(&continued, cam, sigma)) {
        if moving {
            tracks[*k].decision = Decision::Particle;
        }
    }
}

/// A frame's detections: pixels, camera-frame directions and fluxes.
#[derive(Clone, Copy)]
pub struct Seen<'a> {
    pub px: &'a [(f64, f64)],
    pub dirs: &'a [Vector3<f64>],
    pub flux: &'a [f64],
}

/// What a frame's detections were judged to be.
#[derive(Clone, Debug, PartialEq)]
pub struct Judged {
    pub decision: Vec<Decision>,
    /// Velocity against the stars of each particle, in this frame's pixels per second (None
    /// for the others, and for particles seen once).
    pub velocity: Vec<Option<(f64, f64)>>,
    /// How far (pixels) a detection lies from where a star stood, when further than the noise
    /// allows: a star merged with a passing particle (its centroid pulled toward it, or a new
    /// detection where the star's track was not continued). Its position is biased by about
    /// this much, whatever its centroid's own 1σ says.
    pub pulled: Vec<Option<f64>>,
}

/// The tracks of one chain of frames whose motion is known.
pub struct Tracker {
    s: ParticleSettings,
    camera: Camera,
    tracks: Vec<Track>,
    /// The flux of the last frame's faintest detection.
    faintest: Option<f64>,
    /// The last frame's detections, in the reference frame.
    previous: Vec<Vector3<f64>>,
    /// The track of each of the last frame's detections.
    last_owner: Vec<usize>,
}

impl Tracker {
    pub fn new(camera: Camera, s: ParticleSettings) -> Tracker {
        Tracker {
            s,
            camera,
            tracks: Vec::new(),
            faintest: None,
            previous: Vec::new(),
            last_owner: Vec::new(),
        }
    }

    /// Add frame `frame` (taken at `t` s) whose camera frame is `c` · reference: detections at
    /// `seen`; `sigma_px` is the noise per axis of its stars'
    /// steps from the previous frame (from the motion fit). `prev_c` is the previous frame's `c` (to tell a star that
    /// has just come into view, which was outside the previous frame, from one that moved).
    pub fn add(
        &mut self,
        frame: usize,
        t: f64,
        c: &Matrix3<f64>,
        prev_c: Option<&Matrix3<f64>>,
        seen: &Seen,
        sigma_px: f64,
    ) -> Judged {
        let Seen { px, dirs, flux } = *seen;
        let s = self.s;
        let sigma = sigma_px.max(s.sigma_floor_px);
        let ifov = self.camera.ifov_rad();
        let cam = &self.camera;
        let to_px = |w: &Vector3<f64>| cam.vector_to_pixel(&(c * w));
        self.tracks
            .retain(|tr| frame.saturating_sub(tr.last_frame) <= s.max_gap_frames);
        let n = px.len();
        let mut owner: Vec<Option<usize>> = vec![None; n];
        let mut taken = vec![false; self.tracks.len()];
        let dist = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).hypot(a.1 - b.1);
        // The detection limit: the faintest detection of this frame or the previous one (the
        // brighter of the two).
        let limit = flux
            .iter()
            .copied()
            .reduce(f64::min)
            .into_iter()
            .chain(self.faintest)
            .reduce(f64::max)
            .unwrap_or(0.0);
        // Widened only where a particle's velocity already says where its next point is;
        // strict for a track standing still (a faint star continued by a particle passing
        // over it would be taken for one) and for a first step to the nearest detection within
        // reach (a faint star flickering at the limit taken for a particle's next point): on
        // scripts/sim_sequence.py's seed-1 set widened everywhere, 22 more stars were flagged.
        let alike_within = |tr: &Track, j: usize, widen: bool| {
            let near_limit = limit / flux[j].min(tr.flux);
            let widening = if widen {
                s.faint_flux_widening * near_limit * near_limit
            } else {
                0.0
            };
            (flux[j] / tr.flux).ln().abs() <= s.flux_ratio.ln() + widening
        };

        // Where each track's last point is in this frame had it stood still.
        let still: Vec<Option<(f64, f64)>> =
            self.tracks.iter().map(|tr| to_px(&tr.last.0)).collect();
        // 1. Stars and undecided tracks stand still: the nearest detection within the gate.
        let mut cand: Vec<(f64, usize, usize)> = Vec::new();
        for (k, tr) in self.tracks.iter().enumerate() {
            let Some(p) = still[k] else { continue };
            if tr.decision == Decision::Particle {
                continue;
            }
            for (j, &q) in px.iter().enumerate() {
                let d = dist(p, q);
                if d <= s.static_gate_px && alike_within(tr, j, false) {
                    cand.push((d, k, j));
                }
            }
        }
        assign(&mut cand, &mut taken, &mut owner);
        // 2. Particles go on at their velocity (with room for a tenth of it in a change).
        let mut cand = Vec::new();
        for (k, tr) in self.tracks.iter().enumerate() {
            if taken[k] || tr.decision != Decision::Particle {
                continue;
            }
            let (Some(p), Some(v)) = (still[k], self.velocity(k, c)) else {
                continue;
            };
            let dt = t - tr.last.1;
            let pred = (p.0 + v.0 * dt, p.1 + v.1 * dt);
            let gate = s.static_gate_px + 0.1 * v.0.hypot(v.1) * dt.abs();
            for (j, &q) in px.iter().enumerate() {
                let d = dist(pred, q);
                if owner[j].is_none() && d <= gate && alike_within(tr, j, true) {
                    cand.push((d, k, j));
                }
            }
        }
        assign(&mut cand, &mut taken, &mut owner);
        // 3. A track seen once in the previous frame that did not stand still may have moved:
        // its nearest unclaimed detection within the fastest particle's reach, unless that
        // detection is where the previous frame did not look (a star coming into view).
        let mut cand = Vec::new();
        let seen_before: Vec<bool> = match prev_c {
            Some(pc) => dirs
                .iter()
                .map(|u| {
                    cam.vector_to_pixel(&(pc * c.transpose() * u))
                        .is_some_and(|(x, y)| inside(cam, x, y, s.static_gate_px))
                })
                .collect(),
            None => vec![false; n],
        };
        if prev_c.is_some() {
            for (k, tr) in self.tracks.iter().enumerate() {
                if taken[k] || tr.prev.is_some() || tr.last_frame + 1 != frame {
                    continue;
                }
                let Some(p) = still[k] else { continue };
                let reach = s.max_speed_rad_s / ifov * (t - tr.last.1).abs() + s.static_gate_px;
                for (j, &q) in px.iter().enumerate() {
                    let d = dist(p, q);
                    if owner[j].is_none()
                        && seen_before[j]
                        && d <= reach
                        && alike_within(tr, j, false)
                    {
                        cand.push((d, k, j));
                    }
                }
            }
        }
        assign(&mut cand, &mut taken, &mut owner);
        // Stars pulled by a passing particle: a star's track continued by a step beyond
        // PULLED_SIGMAS of the noise, or not continued at all with an unclaimed detection
        // within the gate of where it stood.
        let pulled: Vec<Option<f64>> = (0..n)
            .map(|j| match owner[j] {
                Some(k) => still[k]
                    .filter(|_| self.tracks[k].decision == Decision::Star)
                    .map(|p| dist(p, px[j]))
                    .filter(|&d| d > PULLED_SIGMAS * sigma),
                None => self
                    .tracks
                    .iter()
                    .enumerate()
                    .filter(|(k, tr)| !taken[*k] && tr.decision == Decision::Star)
                    .filter_map(|(k, _)| still[k].map(|p| dist(p, px[j])))
                    .filter(|&d| d <= s.static_gate_px)
                    .reduce(f64::min),
            })
            .collect();
        // The steps: evidence for the tracks not yet decided.
        let (ln_a, ln_b) = (
            ((1.0 - s.beta) / s.alpha).ln(),
            (s.beta / (1.0 - s.alpha)).ln(),
        );
        for (j, k) in owner.iter().enumerate() {
            let Some(k) = *k else { continue };
            let w = c.transpose() * dirs[j];
            let tr = &mut self.tracks[k];
            if tr.decision == Decision::Undecided
                && let Some(p) = still[k]
            {
                let dt = (t - tr.last.1).abs();
                let nu = s.min_speed_rad_s / ifov * dt;
                tr.llr += step_llr(dist(p, px[j]), nu, sigma);
                if tr.llr >= ln_a {
                    tr.decision = Decision::Particle;
                } else if tr.llr <= ln_b {
                    tr.decision = Decision::Star;
                }
            }
            tr.prev = Some(tr.last);
            tr.last = (w, t);
            tr.last_frame = frame;
            tr.flux = flux[j];
            tr.remember(cam, px[j], w, t);
        }
        drift_test(&mut self.tracks, cam, &owner, px, &to_px, sigma);
        // Detections no track claims start tracks of their own; a bright one where the previous
        // frame looked and saw nothing (no detection within twice the gate of where it would
        // have stood) starts with that evidence.
        let bright = self.faintest.map(|f| s.bright_factor * f);
        let before: Vec<(f64, f64)> = match prev_c {
            Some(_) => self
                .previous
                .iter()
                .filter_map(|w| cam.vector_to_pixel(&(c * w)))
                .collect(),
            None => Vec::new(),
        };
        for j in 0..n {
            if owner[j].is_none() {
                let empty = !before
                    .iter()
                    .any(|&q| dist(q, px[j]) <= 2.0 * s.static_gate_px);
                let unseen = seen_before[j] && empty && bright.is_some_and(|b| flux[j] >= b);
                let llr = if unseen { -s.star_miss_prob.ln() } else { 0.0 };
                owner[j] = Some(self.tracks.len());
                let w = c.transpose() * dirs[j];
                let mut tr = Track {
                    last: (w, t),
                    prev: None,
                    last_frame: frame,
                    flux: flux[j],
                    llr,
                    history: Vec::new(),
                    decision: if llr >= ln_a {
                        Decision::Particle
                    } else {
                        Decision::Undecided
                    },
                };
                tr.remember(cam, px[j], w, t);
                self.tracks.push(tr);
            }
        }
        self.faintest = flux.iter().copied().reduce(f64::min);
        self.previous = dirs.iter().map(|u| c.transpose() * u).collect();
        let decision: Vec<Decision> = owner
            .iter()
            .map(|k| self.tracks[k.expect("every detection has a track")].decision)
            .collect();
        let velocity = owner
            .iter()
            .zip(&decision)
            .map(|(k, d)| {
                (*d == Decision::Particle)
                    .then(|| self.velocity(k.expect("owned"), c))
                    .flatten()
            })
            .collect();
        self.last_owner = owner.iter().map(|k| k.expect("owned")).collect();
        Judged {
            decision,
            velocity,
            pulled,
        }
    }

    /// Detections of the last frame added known to be no star (`flags`, in its order; from the
    /// catalog test, `sequence/uncatalogued.rs`): their tracks are particles from now on, and
    /// `judged` (that frame's, whose camera frame is `c`) says so, with their velocities.
    pub fn not_stars(&mut self, flags: &[bool], c: &Matrix3<f64>, judged: &mut Judged) {
        for (j, _) in flags.iter().enumerate().filter(|(_, f)| **f) {
            let Some(&k) = self.last_owner.get(j) else {
                continue;
            };
            if judged.decision[j] == Decision::Particle {
                continue;
            }
            self.tracks[k].decision = Decision::Particle;
            judged.decision[j] = Decision::Particle;
            judged.velocity[j] = self.velocity(k, c);
        }
    }

    /// A track's velocity against the stars in the pixels of the frame `c` (pixels per second),
    /// from its last two points.
    fn velocity(&self, k: usize, c: &Matrix3<f64>) -> Option<(f64, f64)> {
        let tr = &self.tracks[k];
        let (w0, t0) = tr.prev?;
        let (w1, t1) = tr.last;
        let dt = t1 - t0;
        if dt.abs() < 1e-9 {
            return None;
        }
        let p0 = self.camera.vector_to_pixel(&(c * w0))?;
        let p1 = self.camera.vector_to_pixel(&(c * w1))?;
        Some(((p1.0 - p0.0) / dt, (p1.1 - p0.1) / dt))
    }
}

/// A star's step longer than this many σ (per axis) of the noise is a pull, not noise: a
/// Rayleigh step goes beyond 4σ once in 3,000.
pub const PULLED_SIGMAS: f64 = 4.0;

/// Is (x, y) inside the frame by `margin` pixels?
fn inside(camera: &Camera, x: f64, y: f64, margin: f64) -> bool {
    x >= margin
        && y >= margin
        && x <= camera.width as f64 - 1.0 - margin
        && y <= camera.height as f64 - 1.0 - margin
}

/// Candidates (distance, track, detection) assigned one to one, nearest first (ties by track,
/// then detection: the same whatever the order they were found in).
fn assign(cand: &mut [(f64, usize, usize)], taken: &mut [bool], owner: &mut [Option<usize>]) {
    cand.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    for &(_, k, j) in cand.iter() {
        if !taken[k] && owner[j].is_none() {
            taken[k] = true;
            owner[j] = Some(k);
        }
    }
}

/// Log-likelihood ratio of a step of length `r` (pixels) between "moved by ν" and "stood still",
/// with noise σ per axis of the step: ln Rice(r; ν, σ) − ln Rayleigh(r; σ) = ln I₀(rν/σ²) −
/// ν²/(2σ²).
pub fn step_llr(r: f64, nu: f64, sigma: f64) -> f64 {
    let s2 = sigma * sigma;
    ln_i0(r * nu / s2) - nu * nu / (2.0 * s2)
}

/// ln I₀(z), the modified Bessel function of the first kind, for z ≥ 0: its power series below
/// 40 (terms fall fast), the asymptotic series above, summed while its terms fall (relative
/// error below 1e-12 there).
pub fn ln_i0(z: f64) -> f64 {
    if z < 40.0 {
        let q = z * z / 4.0;
        let (mut term, mut sum) = (1.0, 1.0);
        for k in 1..400 {
            term *= q / (k * k) as f64;
            sum += term;
            if term < sum * 1e-17 {
                break;
            }
        }
        sum.ln()
    } else {
        // I₀(z) ~ e^z / √(2πz) · Σ ((2k−1)!!)² / (k! (8z)^k).
        let (mut term, mut sum) = (1.0f64, 1.0f64);
        for k in 1..30 {
            let next = term * ((2 * k - 1) as f64).powi(2) / (k as f64 * 8.0 * z);
            if next >= term || next < 1e-17 {
                break;
            }
            term = next;
            sum += term;
        }
        z - 0.5 * (2.0 * std::f64::consts::PI * z).ln() + sum.ln()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An 18° camera of 1024² pixels, and a tracker of it with the default settings.
    fn camera_and_tracker() -> (Camera, Tracker) {
        let camera = Camera::from_fov(1024, 1024, 18.0).unwrap();
        let tracker = Tracker::new(camera.clone(), ParticleSettings::default());
        (camera, tracker)
    }

    /// Frame `f` (at time f seconds, 0.1 px centroid noise) of detections at `px` with `flux`.
    fn add_frame(
        tracker: &mut Tracker,
        camera: &Camera,
        f: usize,
        c: &Matrix3<f64>,
        last: Option<&Matrix3<f64>>,
        px: &[(f64, f64)],
        flux: &[f64],
    ) -> Judged {
        let dirs: Vec<_> = px
            .iter()
            .map(|&(x, y)| camera.pixel_to_vector(x, y))
            .collect();
        let seen = Seen {
            px,
            dirs: &dirs,
            flux,
        };
        tracker.add(f, f as f64, c, last, &seen, 0.1)
    }

    #[test]
    fn ln_i0_matches_known_values_across_the_switch() {
        // I0(1) = 1.2660658777520082, I0(10) = 2815.716628466254, I0(20) = 4.355828255955353e7,
        // I0(50) = 2.9325537838493362e20 (the power series summed in exact rationals).
        assert!((ln_i0(0.0)).abs() < 1e-15);
        assert!((ln_i0(1.0) - 1.2660658777520082f64.ln()).abs() < 1e-12);
        assert!((ln_i0(10.0) - 2815.716628466254f64.ln()).abs() < 1e-12);
        assert!((ln_i0(20.0) - 4.355828255955353e7f64.ln()).abs() < 1e-9);
        assert!((ln_i0(50.0) - 2.9325537838493362e20f64.ln()).abs() < 1e-12);
        // Continuous where the two forms meet.
        assert!((ln_i0(40.0 - 1e-9) - ln_i0(40.0)).abs() < 1e-8);
    }

    #[test]
    fn steps_weigh_for_the_right_hypothesis() {
        // A star's step of one σ is evidence for standing still, a particle's step of 2ν for
        // moving; a step of ν/2 (between) tips slightly to "still".
        assert!(step_llr(0.3, 1.5, 0.3) < -5.0);
        assert!(step_llr(3.0, 1.5, 0.3) > 20.0);
        assert!(step_llr(0.75, 1.5, 0.3) < 0.0);
    }

    /// Faint particles near the detection limit whose flux swings 3× from frame to frame (a
    /// component's sum near the threshold) are still followed once their velocity is known,
    /// while a bright star whose flux triples (merged with a particle) is not continued by it.
    #[test]
    fn faint_particles_are_followed_through_flux_swings() {
        let (camera, mut tracker) = camera_and_tracker();
        let speed_px = (10.0f64 / 60.0).to_radians() / camera.ifov_rad();
        let mut last = None;
        for f in 0..6 {
            let c = Matrix3::identity();
            let mut px = vec![(300.0, 300.0), (600.0, 500.0)];
            let mut flux = vec![1e5, if f == 3 { 3e5 } else { 1e5 }];
            for p in 0..6 {
                px.push((100.0 + 120.0 * p as f64 + speed_px * f as f64, 800.0));
                // Alike for the first step, swinging 3× from the third frame on.
                flux.push(if f < 2 || (f + p) % 2 == 0 {
                    100.0
                } else {
                    300.0
                });
            }
            let j = add_frame(&mut tracker, &camera, f, &c, last.as_ref(), &px, &flux);
            last = Some(c);
            if f >= 1 {
                assert!(
                    j.decision[2..].iter().all(|d| *d == Decision::Particle),
                    "frame {f}: {j:?}"
                );
            }
            if f >= 2 {
                assert!(j.velocity[2].is_some(), "frame {f}: {j:?}");
            }
            if f == 1 || f == 2 {
                assert_eq!(j.decision[..2], [Decision::Star; 2], "frame {f}");
            }
            if f == 3 {
                // The tripled star starts a track of its own: undecided, not a star's step.
                assert_eq!(j.decision[1], Decision::Undecided, "{j:?}");
            }
        }
    }

    /// A track said to be no star (the catalog lacks it) is a particle in that frame's
    /// judgement and from then on, though its steps of a fifth of a pixel look like a star's;
    /// the tracks beside it are left as they are.
    #[test]
    fn a_track_found_to_be_no_star_stays_a_particle() {
        let (camera, mut tracker) = camera_and_tracker();
        let mut last = None;
        for f in 0..5 {
            let c = Matrix3::identity();
            let px = vec![
                (300.0, 300.0),
                (600.0, 500.0),
                (400.0 + 0.2 * f as f64, 700.0),
            ];
            let mut j = add_frame(&mut tracker, &camera, f, &c, last.as_ref(), &px, &[1e4; 3]);
            last = Some(c);
            if f == 1 {
                assert_eq!(j.decision, [Decision::Star; 3]);
                tracker.not_stars(&[false, false, true], &c, &mut j);
                assert_eq!(j.decision[2], Decision::Particle);
                assert!(j.velocity[2].is_some());
            }
            if f >= 2 {
                assert_eq!(j.decision[..2], [Decision::Star; 2], "frame {f}");
                assert_eq!(j.decision[2], Decision::Particle, "frame {f}: {j:?}");
            }
        }
    }

    /// A particle lost for two frames (hidden, or below the limit) is found again where its
    /// velocity puts it, and is a particle at once: not a new track that has to prove it moves.
    #[test]
    fn a_particle_lost_for_two_frames_keeps_its_track() {
        let (camera, mut tracker) = camera_and_tracker();
        let speed_px = (10.0f64 / 60.0).to_radians() / camera.ifov_rad();
        let mut last = None;
        for f in 0..8 {
            let c = Matrix3::identity();
            let mut px = vec![(300.0, 300.0), (600.0, 500.0), (800.0, 200.0)];
            let hidden = f == 4 || f == 5;
            if !hidden {
                px.push((100.0 + speed_px * f as f64, 700.0));
            }
            let flux = vec![1e4; px.len()];
            let j = add_frame(&mut tracker, &camera, f, &c, last.as_ref(), &px, &flux);
            last = Some(c);
            if f >= 2 && !hidden {
                assert_eq!(j.decision[3], Decision::Particle, "frame {f}: {j:?}");
            }
            if f == 6 {
                assert!(j.velocity[3].is_some(), "continued, not new: {j:?}");
            }
        }
    }

    /// A star whose centroid a passing particle pulls 1.5 px is still the star's track, and
    /// its pull is told; one whose flux triples starts a track of its own where the star
    /// stood, told as a pull of that distance; the other stars are not pulled.
    #[test]
    fn stars_pulled_by_a_particle_are_told() {
        let (camera, mut tracker) = camera_and_tracker();
        let mut last = None;
        for f in 0..4 {
            let c = Matrix3::identity();
            let mut px: Vec<(f64, f64)> = (0..8)
                .map(|i| (100.0 + 100.0 * i as f64, 300.0 + 50.0 * (i % 3) as f64))
                .collect();
            let mut flux = vec![1e4; px.len()];
            if f == 3 {
                px[0].0 += 1.5;
                px[1].1 += 0.8;
                flux[1] *= 3.0;
            }
            let j = add_frame(&mut tracker, &camera, f, &c, last.as_ref(), &px, &flux);
            last = Some(c);
            if f < 3 {
                assert!(j.pulled.iter().all(|p| p.is_none()), "frame {f}: {j:?}");
            } else {
                assert!((j.pulled[0].unwrap() - 1.5).abs() < 1e-6, "{j:?}");
                assert!((j.pulled[1].unwrap() - 0.8).abs() < 1e-6, "{j:?}");
                assert!(j.pulled[2..].iter().all(|p| p.is_none()), "{j:?}");
                assert_eq!(j.decision[0], Decision::Star, "{j:?}");
            }
        }
    }

    /// A particle moving 0.3 px a frame (about 0.3′/s, a tenth of the step test's Δ) is
    /// called a star by Wald's test at once, and a particle by the drift test once its line
    /// stands out; a star pulled 1 px aside for three frames by a passing particle, and the
    /// stars around it, stay stars.
    #[test]
    fn slow_particles_drift_and_pulled_stars_do_not() {
        let (camera, mut tracker) = camera_and_tracker();
        let stars: Vec<(f64, f64)> = (0..24)
            .map(|i| (100.0 + 35.0 * i as f64, 300.0 + 60.0 * (i % 5) as f64))
            .collect();
        let mut last = None;
        let mut called = Vec::new();
        for f in 0..12 {
            let c = Matrix3::identity();
            let mut px = stars.clone();
            if (4..7).contains(&f) {
                px[3].0 += 1.0;
            }
            px.push((500.0 + 0.3 * f as f64, 520.0 + 0.1 * f as f64));
            let flux = vec![1e4; px.len()];
            let j = add_frame(&mut tracker, &camera, f, &c, last.as_ref(), &px, &flux);
            last = Some(c);
            assert!(
                j.decision[..24].iter().all(|d| *d != Decision::Particle),
                "frame {f}: {:?}",
                j.decision
            );
            called.push(j.decision[24]);
        }
        assert_eq!(called[1], Decision::Star, "{called:?}");
        let first = called.iter().position(|d| *d == Decision::Particle);
        assert!(first.is_some_and(|k| k <= 8), "{called:?}");
        assert!(
            called[first.unwrap()..]
                .iter()
                .all(|d| *d == Decision::Particle)
        );
    }

    /// Stars standing still and particles moving at 10′/s through a turning reference: after
    /// two frames every star is a star and every particle a particle.
    #[test]
    fn tracker_tells_stars_from_particles() {
        let camera = Camera::from_fov(1024, 1024, 18.0).unwrap();
        let ifov = camera.ifov_rad();
        let speed_px = (10.0f64 / 60.0).to_radians() / ifov;
        let stars: Vec<(f64, f64)> = (0..20)
            .map(|i| (100.0 + 40.0 * i as f64, 200.0 + 30.0 * (i % 7) as f64))
            .collect();
        let mut tracker = Tracker::new(camera.clone(), ParticleSettings::default());
        let mut last = None;
        for f in 0..4 {
            // The camera frame is the reference frame: stars stand still in pixels.
            let c = Matrix3::identity();
            let mut px = stars.clone();
            for p in 0..10 {
                let (x0, y0) = (150.0 + 70.0 * p as f64, 700.0);
                px.push((x0 + speed_px * f as f64, y0 - 0.5 * speed_px * f as f64));
            }
            let flux = vec![1000.0; px.len()];
            let j = add_frame(&mut tracker, &camera, f, &c, last.as_ref(), &px, &flux);
            last = Some(c);
            if f >= 1 {
                assert!(
                    j.decision[..20].iter().all(|d| *d == Decision::Star),
                    "{j:?}"
                );
                assert!(
                    j.decision[20..].iter().all(|d| *d == Decision::Particle),
                    "{j:?}"
                );
            }
            if f >= 2 {
                let (vx, vy) = j.velocity[20].unwrap();
                assert!((vx - speed_px).abs() < 0.01 && (vy + 0.5 * speed_px).abs() < 0.01);
            }
        }
    }
}
