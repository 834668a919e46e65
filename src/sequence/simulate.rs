//! `gpustar simulate --sequence`: sequences of a turning star tracker with luminous particles
//! (seed 003's set-up), as 16-bit FITS with DATE-OBS, DATE-END and EXPTIME, one directory per
//! sequence, and a truth file with each frame's attitude and particles.
//!
//! The stars are drawn as `simulate` draws them. The camera turns at a constant rate about an
//! axis fixed in the camera frame. A particle moves along a great circle of the sky at a
//! constant angular speed against the stars, out of focus (a wider Gaussian); one that leaves
//! the frame is replaced by a new one at a random place. Smear during the exposure is not drawn.

use crate::catalog::Catalog;
use crate::error::{Context, Error, IntoKind, Result, error};
use crate::simulate::{SimSettings, Spot, Truth, random_rotation, render_with};
use crate::sky::Utc;
use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// What the sequences are like.
#[derive(Clone, Copy, Debug)]
pub struct SequenceSim {
    pub sequences: usize,
    /// Frames per sequence.
    pub frames: usize,
    /// Seconds between frames (mid-exposure to mid-exposure).
    pub interval_s: f64,
    pub exposure_s: f64,
    /// The camera's turn rate, drawn uniformly per sequence (degrees per second).
    pub rate_deg_s: (f64, f64),
    /// Particles per catalog star in the first frame.
    pub particle_ratio: f64,
    /// Particle magnitudes (on the stars' scale), drawn uniformly.
    pub particle_mag: (f64, f64),
    /// Particle speeds against the stars (arcmin per second), drawn uniformly.
    pub particle_speed_arcmin_s: (f64, f64),
    /// Particle PSF widths, in star PSF widths, drawn uniformly.
    pub particle_blur: (f64, f64),
    /// Mid-exposure of every sequence's first frame.
    pub start: Utc,
}

impl Default for SequenceSim {
    fn default() -> Self {
        SequenceSim {
            sequences: 2,
            frames: 30,
            interval_s: 1.0,
            exposure_s: 0.05,
            rate_deg_s: (0.05, 0.5),
            particle_ratio: 1.5,
            particle_mag: (1.5, 5.0),
            particle_speed_arcmin_s: (6.0, 40.0),
            particle_blur: (1.0, 2.5),
            start: Utc {
                jd1: 2_460_385.5,
                jd2: 0.5,
            },
        }
    }
}

/// A particle in a truth record: where it is at mid-exposure, and its velocity on the sensor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthParticle {
    pub x: f64,
    pub y: f64,
    pub vx_px_s: f64,
    pub vy_px_s: f64,
    pub mag: f64,
}

/// A truth record of a sequence frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SequenceTruth {
    #[serde(flatten)]
    pub stars: Truth,
    pub sequence: usize,
    pub index: usize,
    /// Mid-exposure, UTC.
    pub time_utc: String,
    pub particles: Vec<TruthParticle>,
}

/// The record name of frame `k` of sequence `j`.
pub fn frame_name(j: usize, k: usize) -> String {
    format!("seq_{j:03}/frame_{k:03}.fits")
}

/// A particle: its direction on the sky when it appeared, the axis it turns about, its angular
/// speed (rad/s), when it appeared (s), magnitude and PSF sigma (pixels).
#[derive(Clone, Copy, Debug)]
struct Particle {
    v0: Vector3<f64>,
    axis: Vector3<f64>,
    speed: f64,
    born: f64,
    mag: f64,
    sigma: f64,
}

impl Particle {
    fn at(&self, t: f64) -> Vector3<f64> {
        Rotation3::new(self.axis * self.speed * (t - self.born)) * self.v0
    }
}

/// One frame to render: its attitude, time and particles.
struct Plan {
    j: usize,
    k: usize,
    r: Matrix3<f64>,
    t: f64,
    particles: Vec<(Spot, TruthParticle)>,
}

/// The frames of sequence `j`: the camera's path and every particle's, frame by frame.
fn plan(catalog: &Catalog, s: &SimSettings, q: &SequenceSim, j: usize) -> Result<Vec<Plan>> {
    let camera = s.camera()?;
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed ^ 0x5345_5155_454E_4345);
    rng.set_stream(j as u64);
    let r0 = random_rotation(&mut rng);
    let axis = random_unit(&mut rng);
    let rate = rng
        .random_range(q.rate_deg_s.0..=q.rate_deg_s.1)
        .to_radians();
    let attitude = |t: f64| Rotation3::new(axis * rate * t).into_inner() * r0;
    let stars_in_view = catalog
        .stars
        .iter()
        .filter(|st| st.mag <= s.mag_limit)
        .filter_map(|st| camera.vector_to_pixel(&(r0 * st.vector_at(s.epoch))))
        .filter(|&(x, y)| camera.contains(x, y))
        .count();
    let count = (q.particle_ratio * stars_in_view as f64).round() as usize;
    let spawn = |rng: &mut ChaCha8Rng, t: f64| {
        let (x, y) = (
            rng.random_range(0.0..camera.width as f64 - 1.0),
            rng.random_range(0.0..camera.height as f64 - 1.0),
        );
        let v0 = attitude(t).transpose() * camera.pixel_to_vector(x, y);
        let axis = v0.cross(&random_unit(rng)).normalize();
        Particle {
            v0,
            axis,
            speed: (rng.random_range(q.particle_speed_arcmin_s.0..=q.particle_speed_arcmin_s.1)
                / 60.0)
                .to_radians(),
            born: t,
            mag: rng.random_range(q.particle_mag.0..=q.particle_mag.1),
            sigma: s.psf_sigma_px * rng.random_range(q.particle_blur.0..=q.particle_blur.1),
        }
    };
    let mut particles: Vec<Particle> = (0..count).map(|_| spawn(&mut rng, 0.0)).collect();
    let pixel = |p: &Particle, t: f64| camera.vector_to_pixel(&(attitude(t) * p.at(t)));
    let mut plans = Vec::new();
    for k in 0..q.frames {
        let t = k as f64 * q.interval_s;
        let mut drawn = Vec::new();
        for p in particles.iter_mut() {
            if !pixel(p, t).is_some_and(|(x, y)| camera.contains(x, y)) {
                *p = spawn(&mut rng, t);
            }
            let (Some((x, y)), Some(a), Some(b)) =
                (pixel(p, t), pixel(p, t - 0.01), pixel(p, t + 0.01))
            else {
                continue;
            };
            let spot = Spot {
                x,
                y,
                electrons: s.zero_point_e() * 10f64.powf(-0.4 * p.mag),
                sigma_px: p.sigma,
            };
            let truth = TruthParticle {
                x,
                y,
                vx_px_s: (b.0 - a.0) / 0.02,
                vy_px_s: (b.1 - a.1) / 0.02,
                mag: p.mag,
            };
            drawn.push((spot, truth));
        }
        plans.push(Plan {
            j,
            k,
            r: attitude(t),
            t,
            particles: drawn,
        });
    }
    Ok(plans)
}

/// A uniformly random unit vector.
fn random_unit(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    let z: f64 = rng.random_range(-1.0..=1.0);
    let phi: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let r = (1.0 - z * z).sqrt();
    Vector3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Render one planned frame and write it as FITS; its truth record.
fn write_frame(
    catalog: &Catalog,
    s: &SimSettings,
    q: &SequenceSim,
    p: &Plan,
    out: &Path,
) -> Result<SequenceTruth> {
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(((p.j as u64) << 32) | p.k as u64);
    let spots: Vec<Spot> = p.particles.iter().map(|(s, _)| *s).collect();
    let (pixels, mut truth) = render_with(catalog, s, p.k, &mut rng, &p.r, &spots)?;
    truth.file = frame_name(p.j, p.k);
    let mid = q.start.add_seconds(p.t);
    let begin = mid.add_seconds(-q.exposure_s / 2.0);
    let quote = |v: &str| format!("'{v}'");
    let cards = [
        ("DATE-OBS", quote(&begin.iso())),
        (
            "DATE-END",
            quote(&mid.add_seconds(q.exposure_s / 2.0).iso()),
        ),
        ("EXPTIME", format!("{}", q.exposure_s)),
        ("TIMESYS", quote("UTC")),
    ]
    .map(|(k, v)| crate::io::fits::card(k, &v));
    let bytes = crate::io::fits::encode_u16(truth.width, truth.height, &pixels, &cards);
    let path = out.join(&truth.file);
    std::fs::write(&path, bytes).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(SequenceTruth {
        stars: truth,
        sequence: p.j,
        index: p.k,
        time_utc: mid.iso(),
        particles: p.particles.iter().map(|(_, t)| t.clone()).collect(),
    })
}

/// Write the sequences (`seq_NNN/frame_NNN.fits`), `truth.jsonl` and `camera.toml` into `out`,
/// rendering on `threads` threads (each frame has its own random stream: the files do not
/// depend on the thread count).
pub fn write_set(
    catalog: &Catalog,
    s: &SimSettings,
    q: &SequenceSim,
    out: &Path,
    threads: usize,
) -> Result<()> {
    let s = &SimSettings {
        bits: 16,
        ..s.clone()
    };
    let mut plans = Vec::new();
    for j in 0..q.sequences {
        let dir = out.join(format!("seq_{j:03}"));
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        plans.extend(plan(catalog, s, q, j)?);
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<std::sync::Mutex<Option<Result<SequenceTruth>>>> =
        plans.iter().map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, plans.len().max(1)) {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some(p) = plans.get(i) else { break };
                    let done = write_frame(catalog, s, q, p, out);
                    *results[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(done);
                }
            });
        }
    });
    let mut truth_file = std::io::BufWriter::new(
        std::fs::File::create(out.join("truth.jsonl")).context("cannot create truth.jsonl")?,
    );
    for r in results {
        let truth = r
            .into_inner()
            .unwrap_or_else(|e| e.into_inner())
            .ok_or_else(|| error!(Config, "a frame was not rendered"))??;
        writeln!(
            truth_file,
            "{}",
            serde_json::to_string(&truth).into_kind(Error::Output)?
        )?;
    }
    truth_file.flush()?;
    let text = format!(
        "# written by gpustar simulate --sequence\nwidth = {}\nheight = {}\nfov_x_deg = {}\n\
         mag_limit = {}\n",
        s.width, s.height, s.fov_x_deg, s.mag_limit
    );
    std::fs::write(out.join("camera.toml"), text).context("cannot write camera.toml")?;
    Ok(())
}
