//! `gpustar simulate`: synthetic star-tracker frames with a truth file (seed 000's simulation:
//! random attitudes, pinhole projection, magnitude → flux, Gaussian PSF), plus what real frames
//! have: sky background with vignetting, Poisson and read noise, false stars, hot pixels.
//!
//! Frames are reproducible from `--seed`: frame k uses its own ChaCha8 stream.
//!
//! Brightness: a star of magnitude m gives `zero_point_e() × 10^(−0.4 m)` electrons. The zero
//! point is `flux_mag0_e` (2e6 e⁻: a magnitude-6 star peaks at SNR ≈ 47 over the default sky
//! and read noise, magnitude 9 at ≈ 3), or, with `limit_snr`, whatever puts the faintest star
//! drawn (`mag_limit`) at that peak SNR: a catalog of any depth then renders all of its stars
//! to the limit visibly, and the brightest saturate as they would on a real sensor.
//!
//! Pointings are uniform over the sphere, or near the catalog's own stars
//! ([`Pointing::Catalog`], for a catalog that covers a few patches of sky); [`hints`] writes
//! frames as FITS whose header carries the pointing, off by a set angle.

pub mod evaluate;
pub mod hints;

use crate::camera::Camera;
use crate::catalog::Catalog;
use crate::error::{Context, Error, IntoKind, Result, fail};
use crate::solve::attitude::{pointing, quaternion};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, Poisson};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// What to simulate.
#[derive(Clone, Debug)]
pub struct SimSettings {
    pub width: u32,
    pub height: u32,
    pub fov_x_deg: f64,
    /// Faintest catalog star drawn, in the catalog's own magnitude (Hp for the built-in one).
    pub mag_limit: f64,
    pub frames: usize,
    pub seed: u64,
    pub epoch: f64,
    /// Gaussian PSF sigma, pixels.
    pub psf_sigma_px: f64,
    /// Signal of a magnitude-0 star, electrons.
    pub flux_mag0_e: f64,
    /// Sky background at the centre, electrons per pixel.
    pub sky_e: f64,
    /// Fraction by which sky and stars fall off from the centre to the corners.
    pub vignetting: f64,
    /// Read noise, electrons rms.
    pub read_noise_e: f64,
    /// Electrons at the largest pixel value (255 or 65535): sets the gain, so 8- and 16-bit
    /// frames saturate at the same signal.
    pub full_well_e: f64,
    /// Bits per pixel of the PNG files: 8 or 16.
    pub bits: u8,
    /// False stars (spots of random magnitude at random places) per frame.
    pub false_stars: usize,
    /// Hot pixels (single bright pixels) per frame.
    pub hot_pixels: usize,
    /// Gaussian error (sigma, pixels, in x and in y) of where each catalog star is drawn,
    /// while the truth keeps its true place: the centroid noise of star-tracker studies.
    pub centroid_noise_px: f64,
    /// A full camera model (non-square pixels, principal point, distortion, mirror) instead
    /// of `width`, `height` and `fov_x_deg`.
    pub camera: Option<Camera>,
    /// Peak SNR (noise-free, centred on a pixel, over sky and read noise at the centre) of a
    /// star of `mag_limit`: sets the zero point instead of `flux_mag0_e`.
    pub limit_snr: Option<f64>,
    /// Where the frames point.
    pub pointing: Pointing,
    /// FITS frames with a pointing hint in the header (see [`hints`]) instead of PNG.
    pub hints: Option<hints::HintSim>,
}

crate::choice! {
    /// Where simulated frames point.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
    pub enum Pointing {
        #[default]
        Sphere = "sphere", "Uniformly random attitudes (boresight over the whole sphere, roll)",
        Catalog = "catalog", "Near a catalog star (one of those to the magnitude limit, drawn at \
            random): the boresight uniform within half the narrower field of view of it, the roll \
            uniform, so that the star is in the field",
    }
}

impl SimSettings {
    /// The camera the frames are taken with.
    pub fn camera(&self) -> Result<Camera> {
        match &self.camera {
            Some(c) => Ok(c.clone()),
            None => Camera::from_fov(self.width, self.height, self.fov_x_deg),
        }
    }

    /// Electrons of a magnitude-0 star: `flux_mag0_e`, or from `limit_snr` (see the module).
    pub fn zero_point_e(&self) -> f64 {
        match self.limit_snr {
            None => self.flux_mag0_e,
            Some(snr) => {
                snr * self.background_noise_e() / self.peak_fraction()
                    * 10f64.powf(0.4 * self.mag_limit)
            }
        }
    }

    /// Noise-free peak SNR of a star of magnitude `mag` centred on a pixel at the frame's
    /// centre (over the sky's Poisson noise and the read noise).
    pub fn peak_snr(&self, mag: f64) -> f64 {
        self.zero_point_e() * 10f64.powf(-0.4 * mag) * self.peak_fraction()
            / self.background_noise_e()
    }

    /// Fraction of a star's light in the pixel it is centred on.
    fn peak_fraction(&self) -> f64 {
        pixel_fraction(0.0, 0.0, self.psf_sigma_px).powi(2)
    }

    /// Noise of a pixel without a star at the centre, electrons.
    fn background_noise_e(&self) -> f64 {
        (self.sky_e.max(0.0) + self.read_noise_e * self.read_noise_e)
            .sqrt()
            .max(1e-9)
    }
}

impl Default for SimSettings {
    fn default() -> Self {
        SimSettings {
            width: 1024,
            height: 1024,
            fov_x_deg: 18.0,
            mag_limit: 6.0,
            frames: 10,
            seed: 1,
            epoch: 2000.0,
            psf_sigma_px: 1.0,
            flux_mag0_e: 2.0e6,
            sky_e: 400.0,
            vignetting: 0.3,
            read_noise_e: 15.0,
            full_well_e: 5100.0,
            bits: 8,
            false_stars: 3,
            hot_pixels: 5,
            centroid_noise_px: 0.0,
            camera: None,
            limit_snr: None,
            pointing: Pointing::Sphere,
            hints: None,
        }
    }
}

/// A star in a truth record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthStar {
    /// Hipparcos number; null for a star without one.
    pub hip: Option<u32>,
    /// The star's catalog id as records print it ("HIP 27989", "Gaia DR3 …"); absent in
    /// truth files that other tools wrote.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub catalog_id: Option<String>,
    pub x: f64,
    pub y: f64,
    pub mag: f64,
}

/// One line of `truth.jsonl` (the field names of ../shared/data/real/*/truth.jsonl).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    pub file: String,
    pub ra_deg: f64,
    pub dec_deg: f64,
    pub roll_tetra3_deg: f64,
    pub rotation_matrix: [[f64; 3]; 3],
    pub quaternion: [f64; 4],
    pub epoch: f64,
    #[serde(default)]
    pub mirrored: bool,
    pub width: u32,
    pub height: u32,
    pub fov_x_deg: f64,
    pub fov_y_deg: f64,
    /// Catalog stars whose centre falls on the frame, brightest first.
    #[serde(default)]
    pub stars: Vec<TruthStar>,
    /// Positions of the false stars (simulated frames only).
    #[serde(default)]
    pub false_stars: Vec<[f64; 2]>,
    /// The pointing hint written into the frame's header (`simulate --hint-offset-deg`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hint: Option<hints::TruthHint>,
}

/// A uniformly random rotation (Shoemake's method).
pub fn random_rotation(rng: &mut impl Rng) -> Matrix3<f64> {
    let (u1, u2, u3): (f64, f64, f64) = (rng.random(), rng.random(), rng.random());
    let tau = std::f64::consts::TAU;
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    let q = nalgebra::Quaternion::new(
        b * (tau * u3).cos(),
        a * (tau * u2).sin(),
        a * (tau * u2).cos(),
        b * (tau * u3).sin(),
    );
    *UnitQuaternion::from_quaternion(q)
        .to_rotation_matrix()
        .matrix()
}

/// Fraction of a unit-flux Gaussian (sigma s, centre c) falling in pixel [p − ½, p + ½].
fn pixel_fraction(p: f64, c: f64, s: f64) -> f64 {
    let k = 1.0 / (s * std::f64::consts::SQRT_2);
    0.5 * (libm::erf((p + 0.5 - c) * k) - libm::erf((p - 0.5 - c) * k))
}

/// Add a Gaussian spot of total `electrons` centred at (x, y), integrated over pixels.
pub fn add_spot(signal: &mut [f64], w: u32, h: u32, x: f64, y: f64, electrons: f64, sigma: f64) {
    let r = (4.0 * sigma).ceil() as i64 + 1;
    let (cx, cy) = (x.round() as i64, y.round() as i64);
    let fy: Vec<(i64, f64)> = (cy - r..=cy + r)
        .filter(|&py| py >= 0 && py < h as i64)
        .map(|py| (py, pixel_fraction(py as f64, y, sigma)))
        .collect();
    for px in (cx - r..=cx + r).filter(|&px| px >= 0 && px < w as i64) {
        let fx = pixel_fraction(px as f64, x, sigma) * electrons;
        for &(py, f) in &fy {
            signal[(py as usize) * w as usize + px as usize] += fx * f;
        }
    }
}

/// A rotation whose boresight (camera +z) is `boresight` (a unit vector, ICRS) and whose
/// camera +x lies at `roll_rad` from the plane of the boresight and the celestial pole.
pub fn rotation_towards(boresight: &Vector3<f64>, roll_rad: f64) -> Matrix3<f64> {
    let b = boresight.normalize();
    // Any axis across the boresight: the pole's, or x's near the poles.
    let helper = if b.z.abs() < 0.9 {
        Vector3::z()
    } else {
        Vector3::x()
    };
    let x0 = helper.cross(&b).normalize();
    let y0 = b.cross(&x0);
    let x = x0 * roll_rad.cos() + y0 * roll_rad.sin();
    let y = b.cross(&x);
    Matrix3::from_rows(&[x.transpose(), y.transpose(), b.transpose()])
}

/// A random attitude near a random catalog star to `s.mag_limit` ([`Pointing::Catalog`]).
fn near_catalog_star(
    catalog: &Catalog,
    s: &SimSettings,
    rng: &mut impl Rng,
) -> Result<Matrix3<f64>> {
    let eligible = |st: &&crate::catalog::Star| st.mag <= s.mag_limit;
    let n = catalog.stars.iter().filter(eligible).count();
    if n == 0 {
        fail!(
            Config,
            "--pointing catalog: {} has no star to magnitude {}",
            catalog.source,
            s.mag_limit
        );
    }
    let k = rng.random_range(0..n);
    let star = catalog
        .stars
        .iter()
        .filter(eligible)
        .nth(k)
        .expect("k < the number of eligible stars");
    let v = star.vector_at(s.epoch);
    let camera = s.camera()?;
    let radius = 0.5 * camera.fov_x_deg().min(camera.fov_y_deg()).to_radians();
    // Uniform in the cap: the cosine of the distance uniform in [cos radius, 1].
    let (u, azimuth, roll): (f64, f64, f64) = (
        rng.random(),
        rng.random_range(0.0..std::f64::consts::TAU),
        rng.random_range(0.0..std::f64::consts::TAU),
    );
    let cos_d = 1.0 - u * (1.0 - radius.cos());
    let sin_d = (1.0 - cos_d * cos_d).max(0.0).sqrt();
    // A direction across the star's, at a uniform angle about it.
    let across = rotation_towards(&v, azimuth).row(0).transpose();
    let boresight = v * cos_d + across * sin_d;
    Ok(rotation_towards(&boresight, roll))
}

/// Render one frame: the pixels (as u16 in ADU) and its truth.
pub fn render(catalog: &Catalog, s: &SimSettings, index: usize) -> Result<(Vec<u16>, Truth)> {
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(index as u64);
    let r = match s.pointing {
        Pointing::Sphere => random_rotation(&mut rng),
        Pointing::Catalog => near_catalog_star(catalog, s, &mut rng)?,
    };
    render_with(catalog, s, index, &mut rng, &r, &[])
}

/// Indices of the catalog stars that may lie within `radius` (radians) of `centre` at
/// `epoch`: the catalog's cone, widened by the farthest any star moves from its own epoch.
/// Ascending, as the catalog holds them.
fn stars_near(catalog: &Catalog, centre: &Vector3<f64>, radius: f64, epoch: f64) -> Vec<u32> {
    let fastest = catalog
        .stars
        .iter()
        .map(|st| (st.pmra_mas_yr.abs() + st.pmdec_mas_yr.abs()) * (epoch - st.epoch).abs())
        .fold(0.0, f64::max);
    let moved = (fastest / 3.6e6).to_radians();
    catalog.cone(centre, radius + 1.01 * moved + 1e-4)
}

/// A spot drawn besides the stars (a particle of `simulate --sequence`): where, how many
/// electrons, its Gaussian sigma (pixels).
#[derive(Clone, Copy, Debug)]
pub struct Spot {
    pub x: f64,
    pub y: f64,
    pub electrons: f64,
    pub sigma_px: f64,
}

/// Render frame `index` at attitude `r` with `extra` spots, drawing its false stars and noise
/// from `rng`.
pub fn render_with(
    catalog: &Catalog,
    s: &SimSettings,
    index: usize,
    rng: &mut ChaCha8Rng,
    r: &Matrix3<f64>,
    extra: &[Spot],
) -> Result<(Vec<u16>, Truth)> {
    let camera = s.camera()?;
    let r = *r;
    let (w, h) = (camera.width, camera.height);
    let vig = |x: f64, y: f64| {
        let (dx, dy) = (x - camera.cx, y - camera.cy);
        let rmax2 = camera.cx * camera.cx + camera.cy * camera.cy;
        1.0 - s.vignetting * (dx * dx + dy * dy) / rmax2.max(1.0)
    };
    let margin = 4.0 * s.psf_sigma_px;
    let mut noise_rng = ChaCha8Rng::seed_from_u64(s.seed);
    noise_rng.set_stream(index as u64 | 1 << 63);
    let noise = (s.centroid_noise_px > 0.0)
        .then(|| Normal::new(0.0, s.centroid_noise_px))
        .transpose()
        .into_kind(Error::Config)
        .context("centroid noise")?;
    let mut signal = vec![0f64; (w * h) as usize];
    let mut stars = Vec::new();
    let boresight = r.transpose() * Vector3::z();
    let reach = camera.diagonal_rad() / 2.0 + 0.02;
    let cos_reach = reach.cos();
    let zero_point = s.zero_point_e();
    // The stars of the cone, in catalog order (the order they are drawn in, so that the
    // sums of overlapping spots are those of a walk through the whole catalog).
    let near = stars_near(catalog, &boresight, reach, s.epoch);
    for star in near
        .iter()
        .map(|&i| &catalog.stars[i as usize])
        .filter(|st| st.mag <= s.mag_limit)
    {
        let v = star.vector_at(s.epoch);
        if v.dot(&boresight) < cos_reach {
            continue;
        }
        let Some((x, y)) = camera.vector_to_pixel(&(r * v)) else {
            continue;
        };
        if x < -margin || y < -margin || x > w as f64 - 1.0 + margin || y > h as f64 - 1.0 + margin
        {
            continue;
        }
        let e = zero_point * 10f64.powf(-0.4 * star.mag) * vig(x, y);
        // Drawn off its true place by the centroid noise, from a stream of its own: the
        // frame is otherwise the same as without noise (sky, false stars, hot pixels).
        let (dx, dy) = match noise {
            Some(n) => (n.sample(&mut noise_rng), n.sample(&mut noise_rng)),
            None => (0.0, 0.0),
        };
        add_spot(&mut signal, w, h, x + dx, y + dy, e, s.psf_sigma_px);
        if camera.contains(x, y) {
            stars.push(TruthStar {
                hip: star.hip,
                catalog_id: Some(star.id.display(&catalog.names)),
                x,
                y,
                mag: star.mag,
            });
        }
    }
    stars.sort_by(|a, b| {
        a.mag
            .total_cmp(&b.mag)
            .then(a.hip.cmp(&b.hip))
            .then(a.catalog_id.cmp(&b.catalog_id))
    });
    let mut false_stars = Vec::new();
    for _ in 0..s.false_stars {
        let x = rng.random_range(0.0..w as f64 - 1.0);
        let y = rng.random_range(0.0..h as f64 - 1.0);
        let mag = rng.random_range(s.mag_limit - 3.0..s.mag_limit);
        add_spot(
            &mut signal,
            w,
            h,
            x,
            y,
            zero_point * 10f64.powf(-0.4 * mag),
            s.psf_sigma_px,
        );
        false_stars.push([x, y]);
    }
    for e in extra {
        add_spot(&mut signal, w, h, e.x, e.y, e.electrons, e.sigma_px);
    }
    let full = if s.bits == 8 { 255.0 } else { 65535.0 };
    let read = Normal::new(0.0, s.read_noise_e)
        .into_kind(Error::Config)
        .context("read noise")?;
    let mut pixels = vec![0u16; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let mean = signal[i] + s.sky_e * vig(x as f64, y as f64);
            let e = if mean > 0.0 {
                Poisson::new(mean).map(|p| p.sample(rng)).unwrap_or(mean)
            } else {
                0.0
            };
            let adu = (e + read.sample(rng)) * full / s.full_well_e;
            pixels[i] = adu.round().clamp(0.0, full) as u16;
        }
    }
    for _ in 0..s.hot_pixels {
        let i = rng.random_range(0..pixels.len());
        pixels[i] = (full * rng.random_range(0.5..1.0)) as u16;
    }
    let p = pointing(&r, &camera);
    let truth = Truth {
        file: frame_name(index),
        ra_deg: p.ra_deg,
        dec_deg: p.dec_deg,
        roll_tetra3_deg: p.roll_deg,
        rotation_matrix: std::array::from_fn(|i| std::array::from_fn(|j| r[(i, j)])),
        quaternion: quaternion(&r),
        epoch: s.epoch,
        mirrored: camera.mirrored,
        width: w,
        height: h,
        fov_x_deg: camera.fov_x_deg(),
        fov_y_deg: camera.fov_y_deg(),
        stars,
        false_stars,
        hint: None,
    };
    Ok((pixels, truth))
}

/// File name of frame k.
pub fn frame_name(index: usize) -> String {
    format!("sim_{index:05}.png")
}

/// Write `s.frames` frames, `truth.jsonl` and `camera.toml` into `out`, rendering on
/// `threads` threads (frames are independent: each has its own random stream, so the files do
/// not depend on the thread count). `progress` gets the number of frames written so far.
pub fn write_set(
    catalog: &Catalog,
    s: &SimSettings,
    out: &Path,
    threads: usize,
    mut progress: impl FnMut(usize),
) -> Result<()> {
    if s.bits != 8 && s.bits != 16 {
        fail!(Config, "--bits must be 8 or 16, got {}", s.bits);
    }
    if s.hints.is_some() && s.bits != 16 {
        fail!(
            Config,
            "frames with header hints are 16-bit FITS: give --bits 16"
        );
    }
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let camera = s.camera()?;
    let next = std::sync::atomic::AtomicUsize::new(0);
    let (tx, rx) = crossbeam_channel::unbounded::<(usize, Result<Truth>)>();
    let mut truths: Vec<Option<Truth>> = vec![None; s.frames];
    std::thread::scope(|scope| -> Result<()> {
        for _ in 0..threads.clamp(1, s.frames.max(1)) {
            let (tx, next, camera) = (tx.clone(), &next, &camera);
            scope.spawn(move || {
                loop {
                    let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    if k >= s.frames {
                        break;
                    }
                    let done = render(catalog, s, k).and_then(|(pixels, mut truth)| {
                        if let Some(h) = &s.hints {
                            truth.file = hints::frame_name(k);
                            let hint = hints::hint_for(truth.ra_deg, truth.dec_deg, s.seed, h, k);
                            let cards = hints::header_cards(&hint, s.epoch, h.exposure_s);
                            truth.hint = Some(hint);
                            let bytes = crate::io::fits::encode_u16(
                                camera.width,
                                camera.height,
                                &pixels,
                                &cards,
                            );
                            let path = out.join(&truth.file);
                            std::fs::write(&path, bytes)
                                .with_context(|| format!("cannot write {}", path.display()))?;
                            return Ok(truth);
                        }
                        let path = out.join(&truth.file);
                        write_png(&path, camera.width, camera.height, &pixels, s.bits)
                            .with_context(|| format!("cannot write {}", path.display()))?;
                        Ok(truth)
                    });
                    let failed = done.is_err();
                    if tx.send((k, done)).is_err() || failed {
                        // Stop taking frames; the receiver reports the error.
                        next.store(s.frames, std::sync::atomic::Ordering::Relaxed);
                        break;
                    }
                }
            });
        }
        drop(tx);
        for (written, (k, truth)) in rx.iter().enumerate() {
            truths[k] = Some(truth?);
            progress(written + 1);
        }
        Ok(())
    })?;
    let mut truth_file = std::io::BufWriter::new(
        std::fs::File::create(out.join("truth.jsonl")).context("cannot create truth.jsonl")?,
    );
    for truth in truths.iter().flatten() {
        writeln!(
            truth_file,
            "{}",
            serde_json::to_string(truth).into_kind(Error::Output)?
        )?;
    }
    truth_file.flush()?;
    // The camera file carries the limiting magnitude, so that batch uses the catalog as deep
    // as the frames are and no deeper.
    let text = match &s.camera {
        None => format!(
            "# written by gpustar simulate\nwidth = {}\nheight = {}\nfov_x_deg = {}\n\
             mag_limit = {}\n",
            s.width, s.height, s.fov_x_deg, s.mag_limit
        ),
        Some(c) => format!(
            "# written by gpustar simulate\nwidth = {}\nheight = {}\nfx_px = {}\nfy_px = {}\n\
             cx_px = {}\ncy_px = {}\nk1 = {}\nk2 = {}\nmirrored = {}\nmag_limit = {}\n",
            c.width, c.height, c.fx, c.fy, c.cx, c.cy, c.k1, c.k2, c.mirrored, s.mag_limit
        ),
    };
    std::fs::write(out.join("camera.toml"), text).context("cannot write camera.toml")?;
    Ok(())
}

/// Write a grey PNG, 8 or 16 bits, with fast deflate and the Sub filter: star fields are
/// mostly flat rows, and such files decode about a third faster than the encoder's defaults.
fn write_png(path: &Path, width: u32, height: u32, pixels: &[u16], bits: u8) -> Result<()> {
    use image::ImageEncoder;
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let encoder = PngEncoder::new_with_quality(file, CompressionType::Fast, FilterType::Sub);
    if bits == 8 {
        let buf: Vec<u8> = pixels.iter().map(|&p| p as u8).collect();
        encoder
            .write_image(&buf, width, height, image::ExtendedColorType::L8)
            .into_kind(Error::Output)?;
    } else {
        let buf: Vec<u8> = pixels.iter().flat_map(|p| p.to_ne_bytes()).collect();
        encoder
            .write_image(&buf, width, height, image::ExtendedColorType::L16)
            .into_kind(Error::Output)?;
    }
    Ok(())
}

/// Read a truth file (JSON Lines).
pub fn read_truth(path: &Path) -> Result<Vec<Truth>> {
    crate::record::read_jsonl(path, "truth record")
}
