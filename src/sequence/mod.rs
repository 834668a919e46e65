//! Sequences (seed 003): consecutive frames of one camera head, solved together.
//!
//! Per frame, after detection: [`motion`] finds the rotation carrying the previous frame's star
//! field onto this one (detections alone; particles are its outliers); [`particles`] follows
//! every detection in the sequence's reference frame and decides, by Wald's sequential test on
//! its steps, star or particle; particles are left out; [`track`] identifies the rest from the
//! attitude the previous solutions predict, lost-in-space (the solver as without a sequence)
//! when it cannot. The pixel stages run as without a sequence (batched on the GPU); this stage
//! runs on one CPU thread in input order, because each frame starts from what the one before
//! it left.

mod drift;
pub mod motion;
pub mod particles;
pub mod simulate;
pub mod track;
pub mod uncatalogued;

use crate::camera::Camera;
pub use crate::pipeline::Detected;
use crate::pipeline::{Decoded, Solvers};
use crate::record::{ParticleRecord, Record, Timing};
use crate::sky::{Utc, exposure_from_header};
use crate::solve::attitude::attitude_error;
use crate::solve::detect::Detection;
use crate::solve::refine;
use crate::solve::{Outcome, Solution, Solver};
use motion::{MotionSettings, Points};
use nalgebra::{Matrix3, Vector3};
use particles::{Decision, ParticleSettings, Seen, Tracker};
use std::collections::BTreeMap;
use std::time::Instant;
use track::{Prediction, TrackSettings};

/// How sequences are solved.
#[derive(Clone, Copy, Debug)]
pub struct SequenceOptions {
    /// Seconds between frames, for frames without a time in their header.
    pub frame_interval_s: Option<f64>,
    /// Detection keeps this many of the brightest (instead of `max_stars`): particles can
    /// outnumber the stars, and once they are left out the brightest `max_stars` of the rest
    /// are identified.
    pub detect_stars: usize,
    pub motion: MotionSettings,
    pub particles: ParticleSettings,
    pub track: TrackSettings,
}

impl Default for SequenceOptions {
    fn default() -> Self {
        SequenceOptions {
            frame_interval_s: None,
            detect_stars: DETECT_STARS,
            motion: MotionSettings::default(),
            particles: ParticleSettings::default(),
            track: TrackSettings::default(),
        }
    }
}

/// Detections kept per frame of a sequence: room for 100 stars and 1.5 times as many
/// particles.
pub const DETECT_STARS: usize = 250;

/// `sequence_mode` of a record identified from the predicted attitude.
pub const TRACKING: &str = "tracking";
/// `sequence_mode` of a record identified (or tried) as without a sequence.
pub const LOST_IN_SPACE: &str = "lost_in_space";

/// The uncertainty cone of an attitude carried from the last solved frame through the motion
/// found between frames (pixels): the chain's error is a fraction of a pixel per frame.
pub const CHAIN_CONE_PX: f64 = 10.0;
/// Extrapolating at the rate of the last two solutions: the cone is this fraction of the angle
/// extrapolated, plus [`CHAIN_CONE_PX`], at most [`MAX_CONE_DEG`]. Swarm's heads turn 25–39°
/// in the 600 s between frames, at rates that change by about a tenth.
pub const EXTRAPOLATION_CONE: f64 = 0.2;
pub const MAX_CONE_DEG: f64 = 10.0;

/// The sequence a record name belongs to: its directory ("" for the top level).
pub fn sequence_of(name: &str) -> &str {
    name.rsplit_once('/').map_or("", |(dir, _)| dir)
}

/// A solution kept for predicting the next frames.
#[derive(Clone, Debug)]
struct Solved {
    r: Matrix3<f64>,
    camera: Camera,
    t: f64,
    /// The chain it was solved in, and its camera frame in the chain's reference frame.
    chain: Option<(u64, Matrix3<f64>)>,
}

/// Frames whose motion from one to the next is known: one reference frame for their tracks.
struct Chain {
    id: u64,
    /// The last frame: its camera frame in the reference frame, time, pixels and directions.
    c: Matrix3<f64>,
    t: f64,
    px: Vec<(f64, f64)>,
    dirs: Vec<Vector3<f64>>,
    /// The last motion found, and over how many seconds.
    motion: Option<(Matrix3<f64>, f64)>,
    tracker: Tracker,
    /// Frames in the chain.
    frames: usize,
}

/// One sequence's state.
struct State {
    key: String,
    size: (u32, u32),
    /// The first frame's time (times are seconds after it).
    t0: Option<Utc>,
    /// Frames of the sequence handed in so far (the time without headers is this times the
    /// interval).
    count: usize,
    last_t: Option<f64>,
    chain: Option<Chain>,
    solved: Vec<Solved>,
}

/// The solvers a sequencer uses: a run's, borrowed, or shared with a library user's object
/// that feeds frames one at a time (the Python `Sequence`).
enum SolversRef<'a> {
    Borrowed(&'a Solvers),
    Shared(std::sync::Arc<Solvers>),
}

impl std::ops::Deref for SolversRef<'_> {
    type Target = Solvers;
    fn deref(&self) -> &Solvers {
        match self {
            SolversRef::Borrowed(s) => s,
            SolversRef::Shared(s) => s,
        }
    }
}

/// Solves sequences frame by frame, in input order.
pub struct Sequencer<'a> {
    solvers: SolversRef<'a>,
    opts: SequenceOptions,
    state: Option<State>,
    chains: u64,
}

impl<'a> Sequencer<'a> {
    pub fn new(solvers: &'a Solvers, opts: SequenceOptions) -> Sequencer<'a> {
        Sequencer {
            solvers: SolversRef::Borrowed(solvers),
            opts,
            state: None,
            chains: 0,
        }
    }

    /// A sequencer that holds its solvers, for a caller that feeds frames as they come
    /// rather than running a directory.
    pub fn shared(solvers: std::sync::Arc<Solvers>, opts: SequenceOptions) -> Sequencer<'static> {
        Sequencer {
            solvers: SolversRef::Shared(solvers),
            opts,
            state: None,
            chains: 0,
        }
    }

    /// The record of the next frame in input order.
    pub fn next(&mut self, f: Detected) -> Record {
        let key = sequence_of(&f.decoded.name).to_string();
        if self.state.as_ref().is_none_or(|s| s.key != key) {
            self.state = Some(State {
                key,
                size: (0, 0),
                t0: None,
                count: 0,
                last_t: None,
                chain: None,
                solved: Vec::new(),
            });
        }
        let index = {
            let st = self.state.as_mut().expect("a state");
            st.count += 1;
            st.count - 1
        };
        let d = &f.decoded;
        let (frame, dets) = match (&d.frame, &f.detections) {
            (Ok(frame), Ok(dets)) => (frame, dets),
            (Err(e), _) | (_, Err(e)) => {
                return Record::error(&d.name, e.to_string(), &f.backend);
            }
        };
        let solver = match self.solvers.get_for(d, frame) {
            Ok(s) => s,
            Err(e) => return Record::error(&d.name, e.to_string(), &f.backend),
        };
        let solver = &*solver;
        let t_start = Instant::now();
        let mut warnings = Vec::new();
        let t = self.time_of(d, index, &mut warnings);
        let st = self.state.as_mut().expect("a state");
        if st.size != (frame.width, frame.height) {
            st.size = (frame.width, frame.height);
            st.chain = None;
            st.solved.clear();
        }
        if let Some(last) = st.last_t.filter(|&last| t <= last) {
            // A frame out of place (a copy, a clock error): the sequence goes on without it.
            warnings.push(format!(
                "this frame's time is {} the previous frame's{}: solved on its own, and the \
                 sequence goes on from the frame before it",
                if t == last { "the same as" } else { "before" },
                if t == last {
                    String::new()
                } else {
                    format!(" by {:.3} s", last - t)
                }
            ));
            let t0 = Instant::now();
            let alone = &dets[..dets.len().min(solver.settings.detect.max_stars)];
            let sol = solver.identify(alone.to_vec(), d.epoch);
            let sol = Solution {
                detections: dets.clone(),
                ..sol
            };
            let identify_ms = t0.elapsed().as_secs_f64() * 1e3;
            let mut rec = self.record(solver, &f, frame, &sol, identify_ms, warnings);
            rec.sequence_mode = Some(LOST_IN_SPACE.to_string());
            rec.particles = Some(Vec::new());
            return rec;
        }
        st.last_t = Some(t);
        let camera = solver.camera.clone();
        let px: Vec<(f64, f64)> = dets.iter().map(|d| (d.x, d.y)).collect();
        let dirs: Vec<Vector3<f64>> = px
            .iter()
            .map(|&(x, y)| camera.pixel_to_vector(x, y))
            .collect();
        let flux: Vec<f64> = dets.iter().map(|d| d.flux).collect();
        let mut judged = self.judge(t, &camera, &px, &dirs, &flux);
        let dets = &weighed_for_pulls(dets, &judged.pulled);
        let st = self.state.as_mut().expect("a state");
        let chain = st.chain.as_ref().map(|c| (c.id, c.c));
        // Identification of everything not judged a particle.
        let mut keep: Vec<usize> = (0..dets.len())
            .filter(|&i| judged.decision[i] != Decision::Particle)
            .collect();
        keep.truncate(solver.settings.detect.max_stars);
        let kept: Vec<Detection> = keep.iter().map(|&i| dets[i]).collect();
        let prediction = predict(&st.solved, chain, t, &camera);
        let t_identify = Instant::now();
        let tracked = prediction
            .as_ref()
            .and_then(|p| track::identify(solver, &kept, p, d.epoch, &self.opts.track));
        let mode = if tracked.is_some() {
            TRACKING
        } else {
            LOST_IN_SPACE
        };
        let outcome = match tracked {
            Some((r, refs)) => Outcome::Solved(r, refs),
            None => solver.identify(kept.clone(), d.epoch).outcome,
        };
        let mut outcome = with_all_detections(solver, outcome, dets, &keep);
        if let (Outcome::Solved(r, refs), Some(ch)) = (&outcome, st.chain.as_mut()) {
            let mut flags = uncatalogued::uncatalogued(r, refs, dets);
            outcome = without_blends(&solver.settings, outcome, dets, &mut flags);
            ch.tracker.not_stars(&flags, &ch.c, &mut judged);
        }
        for ((p, dec), fl) in px.iter().zip(&judged.decision).zip(&flux) {
            tracing::trace!(
                "{}: detection ({:.2}, {:.2}) flux {fl:.0}: {dec:?}",
                d.name,
                p.0,
                p.1
            );
        }
        let identify_ms = t_identify.elapsed().as_secs_f64() * 1e3;
        if let Outcome::Solved(r, _) = &outcome {
            st.solved.push(Solved {
                r: r.r,
                camera: r.camera.clone(),
                t,
                chain,
            });
            if st.solved.len() > 2 {
                st.solved.remove(0);
            }
        }
        let matched: Vec<usize> = match &outcome {
            Outcome::Solved(r, _) => r.matches.iter().map(|m| m.det).collect(),
            Outcome::Unsolved(_) => Vec::new(),
        };
        let particles: Vec<ParticleRecord> = (0..dets.len())
            .filter(|&i| judged.decision[i] == Decision::Particle && !matched.contains(&i))
            .map(|i| ParticleRecord {
                x: dets[i].x,
                y: dets[i].y,
                vx_px_s: judged.velocity[i].map(|v| v.0),
                vy_px_s: judged.velocity[i].map(|v| v.1),
            })
            .collect();
        // Identification's time includes the sequence work before it (motion, the particle
        // test): seed 003's pre-selection is part of its recognition time.
        let identify_ms = identify_ms + t_identify.duration_since(t_start).as_secs_f64() * 1e3;
        let sol = Solution {
            detections: dets.clone(),
            outcome,
            epoch: d.epoch,
        };
        let mut rec = self.record(solver, &f, frame, &sol, identify_ms, warnings);
        rec.sequence_mode = Some(mode.to_string());
        rec.particles = Some(particles);
        rec
    }

    /// The record of a frame identified as `sol` in `identify_ms`, with its warnings (logged).
    fn record(
        &self,
        solver: &Solver,
        f: &Detected,
        frame: &crate::io::frame::Frame,
        sol: &Solution,
        identify_ms: f64,
        warnings: Vec<String>,
    ) -> Record {
        let d = &f.decoded;
        let timing = Timing::of(d.decode_ms, f.detect_ms, identify_ms);
        let mut rec = self
            .solvers
            .record(Some(solver), d, frame, sol, None, timing, &f.backend);
        for w in &warnings {
            tracing::warn!("{}: {w}", d.name);
        }
        rec.warnings.extend(warnings);
        rec
    }

    /// The frame's time in seconds after the sequence's first: mid-exposure from its header,
    /// else its place in the sequence times `--frame-interval` (1 s, with a warning, without).
    fn time_of(&mut self, d: &Decoded, index: usize, warnings: &mut Vec<String>) -> f64 {
        let st = self.state.as_mut().expect("a state");
        if let Some(utc) = header_time(&d.keywords) {
            let t0 = *st.t0.get_or_insert(utc);
            return utc.seconds_since(&t0);
        }
        match self.opts.frame_interval_s {
            Some(dt) => index as f64 * dt,
            None => {
                warnings.push(
                    "no frame time in the header (DATE-OBS): frames taken as 1 s apart; pass \
                     --frame-interval SECONDS"
                        .into(),
                );
                index as f64
            }
        }
    }

    /// Motion from the previous frame, then the particle test: what each detection is.
    fn judge(
        &mut self,
        t: f64,
        camera: &Camera,
        px: &[(f64, f64)],
        dirs: &[Vector3<f64>],
        flux: &[f64],
    ) -> particles::Judged {
        let opts = self.opts;
        let st = self.state.as_mut().expect("a state");
        let found = st.chain.as_ref().and_then(|ch| {
            let dt = t - ch.t;
            let predicted = ch.motion.map(|(d, over)| motion::at_rate(&d, over, dt));
            let a = Points {
                px: &ch.px,
                dirs: &ch.dirs,
            };
            let b = Points { px, dirs };
            let m = motion::estimate(camera, &a, &b, dt, predicted, &opts.motion);
            match &m {
                Some(m) => tracing::debug!(
                    "motion over {dt:.3} s: {:.1}\" turn, {} stars carried, median {:.2} px",
                    attitude_error(&m.d, &Matrix3::identity()).to_degrees() * 3600.0,
                    m.inliers.len(),
                    m.median_px
                ),
                None => tracing::debug!("no motion found over {dt:.3} s: a new chain"),
            }
            m.map(|m| (m, dt))
        });
        let chain = match (found, st.chain.take()) {
            (Some((m, dt)), Some(mut ch)) => {
                // Rayleigh: the median step length is σ·√(2 ln 2).
                let sigma = m.median_px / (2.0 * std::f64::consts::LN_2).sqrt();
                let c = m.d * ch.c;
                let seen = Seen { px, dirs, flux };
                let judged = ch.tracker.add(ch.frames, t, &c, Some(&ch.c), &seen, sigma);
                ch.c = c;
                ch.motion = Some((m.d, dt));
                ch.frames += 1;
                (ch, judged)
            }
            _ => {
                // A new chain: this frame's camera frame is its reference frame.
                self.chains += 1;
                let mut tracker = Tracker::new(camera.clone(), opts.particles);
                let c = Matrix3::identity();
                let judged = tracker.add(0, t, &c, None, &Seen { px, dirs, flux }, 0.0);
                let ch = Chain {
                    id: self.chains,
                    c,
                    t,
                    px: Vec::new(),
                    dirs: Vec::new(),
                    motion: None,
                    tracker,
                    frames: 1,
                };
                (ch, judged)
            }
        };
        let (mut ch, judged) = chain;
        ch.t = t;
        ch.px = px.to_vec();
        ch.dirs = dirs.to_vec();
        st.chain = Some(ch);
        judged
    }
}

/// The attitude the previous solutions predict at `t`: carried through the chain's motion when
/// the last solution is in the current chain (`chain`: its id and this frame's camera frame),
/// else extrapolated at the rate of the last two, else the last one if the camera cannot have
/// turned beyond [`MAX_CONE_DEG`] at the fastest turn searched.
fn predict(
    solved: &[Solved],
    chain: Option<(u64, Matrix3<f64>)>,
    t: f64,
    camera: &Camera,
) -> Option<Prediction> {
    let last = solved.last()?;
    let px_cone = CHAIN_CONE_PX * camera.ifov_rad();
    // The camera as the last solution fitted it (scale, distortion): the same camera.
    let camera = last.camera.clone();
    if let (Some((id, c)), Some((last_id, last_c))) = (chain, last.chain)
        && id == last_id
    {
        return Some(Prediction {
            r: c * last_c.transpose() * last.r,
            camera,
            cone_rad: px_cone,
        });
    }
    let max_cone = MAX_CONE_DEG.to_radians();
    if let [before, last] = solved {
        let dt = last.t - before.t;
        if dt > 0.0 {
            let step = motion::at_rate(&(last.r * before.r.transpose()), dt, t - last.t);
            let angle = attitude_error(&step, &Matrix3::identity());
            let cone = EXTRAPOLATION_CONE * angle + px_cone;
            return (cone <= max_cone).then(|| Prediction {
                r: step * last.r,
                camera,
                cone_rad: cone,
            });
        }
    }
    let cone = MotionSettings::default().max_turn_rad_s * (t - last.t).abs() + px_cone;
    (cone <= max_cone).then_some(Prediction {
        r: last.r,
        camera,
        cone_rad: cone,
    })
}

/// A solution found without the particles, refined again from its attitude with the
/// detections the frame would have alone (the brightest `max_stars`, particles or not) and
/// counted as it was: a star the test took for a particle is matched again, and where the
/// particles hid no star the solution is the one the frame has alone, so no frame matches
/// fewer stars than it would alone. Kept only if it matches at least as many and passes the
/// same test; else the solution stands, its matches renumbered into `all`.
fn with_all_detections(
    solver: &Solver,
    outcome: Outcome,
    all: &[Detection],
    kept: &[usize],
) -> Outcome {
    let Outcome::Solved(mut r, refs) = outcome else {
        return outcome;
    };
    for m in &mut r.matches {
        m.det = kept[m.det];
    }
    let s = &solver.settings.refine;
    let alone = &all[..all.len().min(solver.settings.detect.max_stars)];
    // No particle among the frame's own detections: the solution is already theirs.
    if kept.iter().take(alone.len()).copied().eq(0..alone.len()) {
        return Outcome::Solved(r, refs);
    }
    match refine::refine(r.r, alone, &refs, &r.camera, r.hypotheses, r.fixed, s) {
        Some(again)
            if again.false_match_prob <= s.max_false_prob
                && again.matches.len() >= r.matches.len() =>
        {
            Outcome::Solved(again, refs)
        }
        _ => Outcome::Solved(r, refs),
    }
}

/// A solution some of whose matches are on detections found to be no star (`flags`: blends of a
/// particle over a faint star, the particle's light at the particle's place), refined again
/// from its attitude without the flagged detections, as [`with_all_detections`] refines (the
/// brightest `max_stars` of the rest, particles or not). Kept if it passes the same test and
/// loses no match but the blends'; else the solution stands and its blends are unflagged (a
/// matched detection is a star of the record).
fn without_blends(
    settings: &crate::solve::Settings,
    outcome: Outcome,
    all: &[Detection],
    flags: &mut [bool],
) -> Outcome {
    let Outcome::Solved(r, refs) = &outcome else {
        return outcome;
    };
    let blends: Vec<usize> = r
        .matches
        .iter()
        .map(|m| m.det)
        .filter(|&j| flags[j])
        .collect();
    if blends.is_empty() {
        return outcome;
    }
    let s = &settings.refine;
    let rest: Vec<usize> = (0..all.len())
        .filter(|&j| !flags[j])
        .take(settings.detect.max_stars)
        .collect();
    let dets: Vec<Detection> = rest.iter().map(|&j| all[j]).collect();
    match refine::refine(r.r, &dets, refs, &r.camera, r.hypotheses, r.fixed, s) {
        Some(mut again)
            if again.false_match_prob <= s.max_false_prob
                && again.matches.len() + blends.len() >= r.matches.len() =>
        {
            for m in &mut again.matches {
                m.det = rest[m.det];
            }
            let refs = refs.clone();
            Outcome::Solved(again, refs)
        }
        _ => {
            for j in blends {
                flags[j] = false;
            }
            outcome
        }
    }
}

/// The detections with each pulled star's 1σ widened by its pull (in quadrature): a star
/// merged with a passing particle keeps its identity but its biased centroid weighs in the
/// attitude as what it is, not as its photon noise says (a 1.3 px pull at a PSF fit's 0.1 px
/// would otherwise count as much as any other star). A centre of gravity among PSF fits (a
/// blend the fit did not settle on) gets the pull as its 1σ; where every detection is a
/// centre of gravity the fit is unweighted and they are left as they are.
fn weighed_for_pulls(dets: &[Detection], pulled: &[Option<f64>]) -> Vec<Detection> {
    let weighted = dets.iter().any(|d| d.sigma_px.is_some());
    dets.iter()
        .zip(pulled)
        .map(|(d, p)| match (d.sigma_px, p) {
            (Some(s), Some(p)) => Detection {
                sigma_px: Some(s.hypot(*p)),
                ..*d
            },
            (None, Some(p)) if weighted => Detection {
                sigma_px: Some(*p),
                ..*d
            },
            _ => *d,
        })
        .collect()
}

/// Mid-exposure from the header's times, else the start alone (DATE-BEG or DATE-OBS).
fn header_time(keywords: &BTreeMap<String, String>) -> Option<Utc> {
    let get = |k: &str| keywords.get(k).cloned();
    if let (Some(e), _) = exposure_from_header(&get) {
        return Some(e.mid());
    }
    ["DATE-BEG", "DATE-OBS"]
        .iter()
        .find_map(|k| get(k).and_then(|v| Utc::parse(&v).ok()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalog::{Catalog, DoubleStars, RefCatalog, Selection};
    use rand::SeedableRng;
    use std::sync::Arc;

    /// A particle 2.5 mag brighter than the faint star it passes over, 1.5 px from it: the
    /// blend is matched to the star. The catalog test flags it, and the solution is refined
    /// again without it: every other match kept, the attitude within a hundredth of an
    /// arcsecond of the truth, the blend still flagged (a particle of the record).
    #[test]
    fn a_match_on_a_blend_is_taken_out() {
        let selection = Selection {
            epoch: 2025.0,
            mag_limit: 6.5,
            double_stars: DoubleStars::Keep,
            double_sep_rad: 0.0,
        };
        let refs = Arc::new(RefCatalog::select(&Catalog::builtin(), selection).unwrap());
        let camera = Camera::from_fov(1024, 1024, 18.0).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let r_true = crate::simulate::random_rotation(&mut rng);
        let in_view = refine::stars_in_view(&r_true, &refs, &camera);
        let mag = |id: u32| refs.star(id as usize).mag;
        let mut order: Vec<usize> = (0..in_view.len()).collect();
        order.sort_by(|&a, &b| mag(in_view[a].0).total_cmp(&mag(in_view[b].0)));
        let mut dets: Vec<Detection> = order
            .iter()
            .map(|&i| {
                let (id, x, y) = in_view[i];
                Detection {
                    x,
                    y,
                    flux: 10f64.powf(-0.4 * (mag(id) - 20.0)),
                    area: 9,
                    peak: 100,
                    saturated: false,
                    sigma_px: None,
                }
            })
            .collect();
        let settings = crate::solve::Settings::default();
        dets.truncate(settings.detect.max_stars);
        // The faintest star clear of the border and of other stars gets the particle.
        let blend = (0..dets.len())
            .rev()
            .find(|&j| {
                let d = dets[j];
                (50.0..970.0).contains(&d.x)
                    && (50.0..970.0).contains(&d.y)
                    && dets
                        .iter()
                        .all(|o| o.x == d.x || (o.x - d.x).hypot(o.y - d.y) > 20.0)
            })
            .unwrap();
        dets[blend].x += 1.5;
        dets[blend].flux *= 10.0;
        let r = refine::refine(r_true, &dets, &refs, &camera, 1, 2, &settings.refine).unwrap();
        assert!(r.matches.iter().any(|m| m.det == blend));
        let matches = r.matches.len();
        let mut flags = uncatalogued::uncatalogued(&r, &refs, &dets);
        assert_eq!(
            (0..dets.len()).filter(|&j| flags[j]).collect::<Vec<_>>(),
            vec![blend]
        );
        let outcome = without_blends(
            &settings,
            Outcome::Solved(r, refs.clone()),
            &dets,
            &mut flags,
        );
        let Outcome::Solved(again, _) = outcome else {
            panic!("unsolved")
        };
        assert!(flags[blend]);
        assert!(again.matches.iter().all(|m| m.det != blend));
        assert_eq!(again.matches.len(), matches - 1);
        let off = attitude_error(&again.r, &r_true).to_degrees() * 3600.0;
        assert!(off < 0.01, "{off}\"");
    }
}
