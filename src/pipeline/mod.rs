//! Solving many frames: the solvers per frame size (shared by worker threads), the CPU path
//! (one frame at a time, on any thread) and the GPU path (batches of frames on the thread
//! that owns the GPU context, `gpu_runner.rs`). `batch::run` streams a directory through them.
//! Both paths end in the same `solve_with`/`Solvers::record`, so they build the same records.

mod camera_source;
mod gpu_runner;
mod hints;
pub mod star_lists;

use crate::catalog::Catalog;
use crate::error::Result;
use crate::gpu::Gpu;
use crate::io::dark::Darks;
use crate::io::fits::scale::PixelScale;
use crate::io::frame::Frame;
use crate::products::Products;
use crate::record::{Record, Timing};
use crate::solve::detect;
use crate::solve::{Outcome, Settings, Solution, Solver};
use crate::streaks::{self, StreakOptions, fit::StreakFit};
pub use camera_source::CameraSource;
pub use gpu_runner::*;
use hints::hint_record;
pub(crate) use hints::{Global, identify_hinted};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Which backend runs the kernels, as asked on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    /// The GPU if an adapter exists, else the CPU (with a warning).
    Auto,
    /// The GPU; an error when there is no adapter.
    Gpu,
    /// The CPU twins of the kernels.
    Cpu,
}

/// The smallest frame side gpustar solves: a few tiles of background and room for stars.
pub const MIN_SIDE: u32 = 16;

/// The `backend` field of records made on the CPU.
pub const BACKEND_CPU: &str = "cpu";

/// A frame size's solver, or why it could not be built: the message every record of that size
/// carries (shared between threads, so text rather than an [`crate::Error`]).
pub type SharedSolver = Arc<std::result::Result<Solver, String>>;

/// Frames of one size and bit depth (they share the detection parameters), with their
/// positions in the batch.
type SizeGroup<'a> = (DetectKey, Vec<(usize, Decoded<'a>)>);

/// Frame width, height and saturation level: frames alike in these share detection's
/// parameters.
type DetectKey = (u32, u32, u16);

/// The default of `--max-megapixels`, in pixels: 300 megapixels (a 17 000² plate scan; the
/// largest astronomy sensors have 150), under 1 GB while decoded.
pub const DEFAULT_MAX_PIXELS: u64 = 300_000_000;

/// Solvers per frame size, built on first use (one distance table per camera) and shared by
/// every worker thread.
pub struct Solvers {
    pub catalog: Catalog,
    pub settings: Settings,
    pub camera: CameraSource,
    /// Fixed-pattern removal applied to every decoded frame.
    pub darks: Darks,
    /// Per-frame files written beside the records (WCS headers, annotated PNGs).
    pub products: Products,
    /// `--streaks`: find satellite streaks, keep them out of star detection, reduce them.
    pub streaks: Option<StreakOptions>,
    /// `--hint`: solve each frame within its pointing hint's region first.
    pub hint: Option<crate::sky::hint::HintSource>,
    /// Frames with more pixels are refused from their headers (`--max-megapixels`): without
    /// a camera file's size to compare with, a small file can decode to gigabytes.
    pub max_pixels: u64,
    /// By frame size, and for [`CameraSource::Header`] the header's scale and aspect (bits).
    map: Mutex<HashMap<(u32, u32, u64, u64), SharedSolver>>,
}

/// A frame after its pixel stages (the sequence stage's input): its detections, or the
/// message of its error record.
pub struct Detected {
    pub decoded: Decoded<'static>,
    pub detections: std::result::Result<Vec<crate::solve::detect::Detection>, String>,
    pub detect_ms: f64,
    /// The `backend` field of its record.
    pub backend: String,
}

/// A frame read from its file (or why it could not be), or held by the caller
/// ([`Decoded::in_memory`]: its pixels may be borrowed for `'a`).
pub struct Decoded<'a> {
    pub name: String,
    pub path: PathBuf,
    /// The frame's own observation epoch (FITS DATE-OBS), if the file has one.
    pub epoch: Option<f64>,
    /// The file's FITS header keywords (times and station of streak frames).
    pub keywords: std::collections::BTreeMap<String, String>,
    /// Warnings from reading the file, for its record.
    pub warnings: Vec<String>,
    /// The decoded frame, or the message its error record carries.
    pub frame: std::result::Result<Frame<'a>, String>,
    pub decode_ms: f64,
}

impl<'a> Decoded<'a> {
    /// A frame the caller holds in memory (from [`Frame::from_samples`]) under the record name
    /// `name`, with its epoch (Julian year) and header keywords (a streak frame's times and
    /// station) when the caller has them; without an epoch, the keywords' time gives it as a
    /// FITS file's does. A frame that could not be taken becomes the error its record
    /// carries, as an unreadable file's does.
    pub fn in_memory(
        name: &str,
        frame: Result<(Frame<'a>, Vec<String>)>,
        epoch: Option<f64>,
        keywords: std::collections::BTreeMap<String, String>,
    ) -> Decoded<'a> {
        let (frame, mut warnings) = match frame {
            Ok((f, w)) => (Ok(f), w),
            Err(e) => (Err(format!("{e:#}")), Vec::new()),
        };
        let epoch = match epoch {
            Some(e) => Some(e),
            None => {
                let (e, w) = crate::io::fits::epoch_of_keywords(&keywords);
                warnings.extend(w);
                e
            }
        };
        Decoded {
            name: name.to_string(),
            path: PathBuf::from(name),
            epoch,
            keywords,
            warnings,
            frame,
            decode_ms: 0.0,
        }
    }
}

impl Solvers {
    pub fn new(catalog: Catalog, settings: Settings, camera: CameraSource) -> Solvers {
        Solvers {
            catalog,
            settings,
            camera,
            darks: Darks::None,
            products: Products::default(),
            streaks: None,
            hint: None,
            max_pixels: DEFAULT_MAX_PIXELS,
            map: Mutex::new(HashMap::new()),
        }
    }

    /// An error record; under `--streaks` it carries `"streaks": []` as every other record
    /// of the run does, so that scripts read one shape.
    pub fn error_record(&self, name: &str, message: String, backend: &str) -> Record {
        let mut r = Record::error(name, message, backend);
        if self.streaks.is_some() {
            r.streaks = Some(Vec::new());
        }
        r
    }

    /// Read and decode one file, and remove its fixed pattern when asked.
    pub fn decode(&self, path: &Path, name: &str) -> Decoded<'static> {
        // Fault injection (tests/it/faults.rs): the input of this name never finishes, as a
        // frame stuck in a bug would; the stop request must end the run all the same. Test
        // builds only: a release binary ignores the variable.
        if cfg!(debug_assertions)
            && std::env::var_os("GPUSTAR_FAULT_STALL").is_some_and(|v| v == name)
        {
            loop {
                std::thread::sleep(std::time::Duration::from_secs(1));
            }
        }
        let t0 = Instant::now();
        let expect = match &self.camera {
            CameraSource::Fixed(c) => Some((c.width, c.height)),
            _ => None,
        };
        let (frame, info) = match Frame::read_info_within(path, expect, self.max_pixels) {
            Ok((f, info)) => (self.darks.apply(path, f).map_err(|e| e.to_string()), info),
            Err(e) => (Err(format!("{e:#}")), Default::default()),
        };
        Decoded {
            name: name.to_string(),
            path: path.to_path_buf(),
            epoch: info.epoch,
            keywords: info.keywords,
            warnings: info.warnings,
            frame,
            decode_ms: t0.elapsed().as_secs_f64() * 1e3,
        }
    }

    /// The record of a solved or unsolved frame (with its streaks under `--streaks`), and its
    /// products when asked for.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn record(
        &self,
        solver: Option<&Solver>,
        d: &Decoded,
        frame: &Frame,
        sol: &Solution,
        found: Option<&[StreakFit]>,
        timing: Timing,
        backend: &str,
    ) -> Record {
        let mut r = match solver {
            Some(s) => s.record(&d.name, sol, timing, backend),
            // No camera: the outcome is unsolved, said as Solver::record says it.
            None => Record {
                reason: match sol.outcome {
                    Outcome::Unsolved(reason) => Some(reason.to_string()),
                    Outcome::Solved(..) => None,
                },
                stars_detected: Some(sol.detections.len()),
                timing_ms: timing,
                ..Record::empty(&d.name, backend)
            },
        };
        r.warnings.extend(d.warnings.iter().cloned());
        let (hint, notes) = self.hint_and_notes(d, frame);
        r.warnings.extend(notes);
        r.hint = hint.map(|h| hint_record(&h, &r));
        // A solved frame's catalog says which tracks are chains of its stars.
        let found = found.map(|f| streaks::catalog_chain::off_catalog_chains(f, sol));
        let found = found.as_deref();
        self.add_streaks(&mut r, d, (frame.width, frame.height), sol, found);
        let drawn = found.unwrap_or_default();
        if let Err(e) = self.products.write(&d.name, &d.path, frame, sol, drawn) {
            // The solution stands; the user learns which file is missing and why.
            tracing::warn!("{}: {e:#}", d.name);
            r.warnings.push(format!("{e:#}"));
        }
        r
    }

    /// With `--streaks`, the frame's streaks reduced into its record (and their warnings).
    fn add_streaks(
        &self,
        r: &mut Record,
        d: &Decoded,
        size: (u32, u32),
        sol: &Solution,
        found: Option<&[StreakFit]>,
    ) {
        if let (Some(opts), Some(found)) = (&self.streaks, found) {
            let (records, warnings) = streaks::reduce::records(found, sol, &d.keywords, size, opts);
            for w in &warnings {
                tracing::warn!("{}: {w}", d.name);
            }
            r.warnings.extend(warnings);
            r.streaks = Some(records);
        }
    }

    /// The solver for frames of this size, or why there is none (built once per size).
    pub fn get(&self, width: u32, height: u32) -> SharedSolver {
        self.get_scaled(width, height, None)
    }

    /// The solver of a decoded frame: by its size, and with [`CameraSource::Header`] by the
    /// pixel scale its header states.
    pub fn get_for(&self, d: &Decoded, frame: &Frame) -> SharedSolver {
        self.get_scaled(frame.width, frame.height, self.header_scale(d).as_ref())
    }

    /// The solver for frames of this size and (with [`CameraSource::Header`]) header scale.
    pub(crate) fn get_scaled(
        &self,
        width: u32,
        height: u32,
        scale: Option<&PixelScale>,
    ) -> SharedSolver {
        let scale = scale.map(CameraSource::shared_scale);
        let bits = scale.as_ref().map_or((0, 0), |s| {
            (s.arcsec_per_px.to_bits(), s.pixel_aspect.to_bits())
        });
        let mut map = self.map.lock().unwrap_or_else(|e| e.into_inner());
        map.entry((width, height, bits.0, bits.1))
            .or_insert_with(|| Arc::new(self.build(width, height, scale.as_ref())))
            .clone()
    }

    /// With [`CameraSource::Header`]: the pixel scale the frame's header states, if any.
    pub fn header_scale(&self, d: &Decoded) -> Option<PixelScale> {
        self.camera.header_scale(&d.keywords)
    }

    fn build(
        &self,
        width: u32,
        height: u32,
        scale: Option<&PixelScale>,
    ) -> std::result::Result<Solver, String> {
        let camera = self.camera.camera_for(width, height, scale)?;
        Solver::new(&self.catalog, camera, self.settings).map_err(|e| format!("{e:#}"))
    }

    /// The pixel stages alone on the CPU (`--sequence`), keeping the brightest `max_stars`.
    pub fn detect_cpu(&self, decoded: Decoded<'static>, max_stars: usize) -> Detected {
        let t0 = Instant::now();
        let s = self.settings.detect.for_sequence(max_stars);
        let detections = match &decoded.frame {
            Ok(f) => Ok(detect::detect(f, &s)),
            Err(e) => Err(e.clone()),
        };
        Detected {
            decoded,
            detections,
            detect_ms: t0.elapsed().as_secs_f64() * 1e3,
            backend: BACKEND_CPU.to_string(),
        }
    }

    /// Solve a decoded frame on the CPU: one record.
    pub fn solve_cpu(&self, d: Decoded) -> Record {
        let frame = match &d.frame {
            Ok(f) => f,
            Err(e) => return self.error_record(&d.name, e.clone(), BACKEND_CPU),
        };
        if matches!(self.camera, CameraSource::None) {
            return self.streaks_only(&d, frame);
        }
        // A frame with a hint needs the lost-in-space solver (its distance table: for a deep
        // catalog the largest thing a run builds) only when its region does not solve it.
        let scale = self.header_scale(&d);
        let mut record = if let Some(r) = self.regional(&d, frame) {
            let global = Global::Lazy(self, (frame.width, frame.height), scale.clone());
            solve_with(self, &r, Some(&r), &global, &d, frame)
        } else {
            let solver = self.get_scaled(frame.width, frame.height, scale.as_ref());
            match solver.as_ref() {
                Ok(s) => solve_with(self, s, None, &Global::Ready(s), &d, frame),
                Err(e) => self.error_record(&d.name, e.clone(), BACKEND_CPU),
            }
        };
        record.pixel_scale = scale.map(|s| crate::record::PixelScaleRecord {
            arcsec_per_px: s.arcsec_per_px,
            pixel_aspect: s.pixel_aspect,
            source: s.keywords.to_string(),
        });
        record
    }

    /// Identify stars the caller detected in a `width` × `height` frame (`stars`: pixel
    /// positions with fluxes; sorted here brightest first, as detection hands them on): the
    /// record the frame would get with these detections, without hints, streaks or products,
    /// which need the pixels.
    pub fn solve_detections(
        &self,
        name: &str,
        size: (u32, u32),
        stars: Vec<detect::Detection>,
        epoch: Option<f64>,
    ) -> Record {
        self.identify_detections(name, size, stars, epoch, 0.0).0
    }

    /// [`Solvers::solve_detections`], with the solution (None when there is no solver for
    /// the size: the record is an error); `read_ms` is the time the stars took to read.
    pub(crate) fn identify_detections(
        &self,
        name: &str,
        (width, height): (u32, u32),
        mut stars: Vec<detect::Detection>,
        epoch: Option<f64>,
        read_ms: f64,
    ) -> (Record, Option<Solution>) {
        let solver = self.get(width, height);
        let solver = match solver.as_ref() {
            Ok(s) => s,
            Err(e) => return (self.error_record(name, e.clone(), BACKEND_CPU), None),
        };
        let t0 = Instant::now();
        stars.sort_by(|a, b| b.flux.total_cmp(&a.flux));
        let sol = solver.identify(stars, epoch);
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let timing = Timing {
            decode: read_ms,
            detect: 0.0,
            identify: ms,
            total: read_ms + ms,
        };
        (solver.record(name, &sol, timing, BACKEND_CPU), Some(sol))
    }

    /// A frame without a camera: its streaks through the header's WCS, its stars detected
    /// (and kept off the streaks) but not identified.
    fn streaks_only(&self, d: &Decoded, frame: &Frame) -> Record {
        let t0 = Instant::now();
        let s = &self.settings.detect;
        let p = detect::params(frame, s);
        let (blobs, found) = match &self.streaks {
            Some(o) => streaks::detect_cpu(frame, &p, &o.settings, s.k_sigma),
            None => (detect::blobs_cpu(frame, &p), Vec::new()),
        };
        let sol = Solution {
            detections: detect::stars(frame, &blobs, s),
            outcome: Outcome::Unsolved("no_camera"),
            epoch: d.epoch,
        };
        let detect_ms = t0.elapsed().as_secs_f64() * 1e3;
        let timing = Timing {
            decode: d.decode_ms,
            detect: detect_ms,
            identify: 0.0,
            total: d.decode_ms + detect_ms,
        };
        self.record(None, d, frame, &sol, Some(&found), timing, BACKEND_CPU)
    }
}

/// Solve a decoded frame on the CPU: within its hinted region first when `regional` is given,
/// then lost-in-space through `global`. `solver` gives detection's settings and the record.
fn solve_with(
    solvers: &Solvers,
    solver: &Solver,
    regional: Option<&Solver>,
    global: &Global,
    d: &Decoded,
    frame: &Frame,
) -> Record {
    let (sol, found, detect_ms, identify_ms) = match &solvers.streaks {
        None => {
            let (sol, detect_ms, identify_ms) = match (regional, global.ready()) {
                // A searched scale: the scale-free pass on both detection stages first (as the
                // GPU batch does: `scale_free_first`).
                (None, Some(g)) if g.scale_free_first() => {
                    solver.solve_frame_scale_free_first(frame, g, d.epoch)
                }
                _ => solver.solve_frame_with(frame, |dets| {
                    identify_hinted(regional, global, dets, d.epoch)
                }),
            };
            (sol, None, detect_ms, identify_ms)
        }
        Some(o) => {
            let t0 = Instant::now();
            let s = &solver.settings.detect;
            let p = detect::params(frame, s);
            let (blobs, found) = streaks::detect_cpu(frame, &p, &o.settings, s.k_sigma);
            let dets = detect::stars(frame, &blobs, s);
            let t1 = Instant::now();
            let sol = identify_hinted(regional, global, dets, d.epoch);
            let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
            (sol, Some(found), ms(t0, t1), ms(t1, Instant::now()))
        }
    };
    let timing = Timing {
        decode: d.decode_ms,
        detect: detect_ms,
        identify: identify_ms,
        total: d.decode_ms + detect_ms + identify_ms,
    };
    solvers.record(
        Some(solver),
        d,
        frame,
        &sol,
        found.as_deref(),
        timing,
        BACKEND_CPU,
    )
}

/// Solve decoded frames on the CPU over `threads` threads: one record per frame, in the
/// order given (what `batch::run` does with files, for frames a library user already holds).
pub fn solve_cpu_many(solvers: &Solvers, frames: Vec<Decoded>, threads: usize) -> Vec<Record> {
    let n = frames.len();
    if n <= 1 || threads <= 1 {
        // On the caller's thread: a thread started per call costs a one-frame solve its
        // start-up (milliseconds on a loaded machine).
        return frames.into_iter().map(|d| solvers.solve_cpu(d)).collect();
    }
    let work: Vec<Mutex<Option<Decoded>>> =
        frames.into_iter().map(|d| Mutex::new(Some(d))).collect();
    let done: Vec<Mutex<Option<Record>>> = (0..n).map(|_| Mutex::new(None)).collect();
    let next = std::sync::atomic::AtomicUsize::new(0);
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, n.max(1)) {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    if i >= n {
                        break;
                    }
                    let d = work[i].lock().unwrap_or_else(|e| e.into_inner()).take();
                    let r = solvers.solve_cpu(d.expect("each frame taken once"));
                    *done[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(r);
                }
            });
        }
    });
    done.into_iter()
        .map(|r| {
            r.into_inner()
                .unwrap_or_else(|e| e.into_inner())
                .expect("one record per frame")
        })
        .collect()
}

/// The frame of a decoded input that was grouped for solving (only decoded ones are).
fn decoded_frame<'d>(d: &'d Decoded) -> &'d Frame<'d> {
    d.frame.as_ref().expect("grouped frames decoded")
}

/// The backend in use.
pub enum Backend {
    Cpu,
    Gpu(Box<GpuRunner>),
}

/// What opening the backend has to say: a warning (no GPU at all), or why `auto` chose the
/// CPU (for `-v`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BackendNote {
    Warning(String),
    Info(String),
}

impl Backend {
    /// Open the chosen backend; the adapter is picked by `GPUSTAR_ADAPTER` (a substring of its
    /// name) when set. `auto` takes the CPU twins when there is no adapter (with a warning) or
    /// when the best one is a software rasterizer (lavapipe runs the kernels on the CPU, about
    /// 15 times slower than the twins on 2 cores): ask for it with `--backend gpu` or by name.
    pub fn open(choice: BackendChoice) -> Result<(Backend, Option<BackendNote>)> {
        let name = std::env::var("GPUSTAR_ADAPTER").ok();
        let gpu = |g| Backend::Gpu(Box::new(GpuRunner::new(g)));
        match choice {
            BackendChoice::Cpu => Ok((Backend::Cpu, None)),
            BackendChoice::Gpu => Ok((gpu(Gpu::new(name.as_deref())?), None)),
            BackendChoice::Auto => {
                let fallback = |e: crate::error::Error| {
                    let w = BackendNote::Warning(format!("{e:#}; using the CPU"));
                    Ok((Backend::Cpu, Some(w)))
                };
                // The adapter is looked at before a device is made (that takes a third of a
                // second on lavapipe).
                match crate::gpu::best_adapter(name.as_deref()) {
                    Ok(a) if a.software && name.is_none() => {
                        let why = format!(
                            "the only GPU adapter, {}, is a software rasterizer: the CPU twins \
                             of the kernels are faster (--backend gpu uses it anyway)",
                            a.name
                        );
                        Ok((Backend::Cpu, Some(BackendNote::Info(why))))
                    }
                    Ok(_) => match Gpu::new(name.as_deref()) {
                        Ok(g) => Ok((gpu(g), None)),
                        Err(e) => fallback(e),
                    },
                    Err(e) => fallback(e),
                }
            }
        }
    }

    /// The records' `backend` field.
    pub fn name(&self) -> String {
        match self {
            Backend::Cpu => BACKEND_CPU.to_string(),
            Backend::Gpu(g) => g.name(),
        }
    }
}

/// A single-threaded pipeline: decode the files in turn, then solve them as one batch on the
/// backend given. `batch::run` streams large runs over threads (the `batch` and
/// `solve` commands go through it); this serves `calibrate`, tests and library users:
///
/// ```no_run
/// use gpustar::{Backend, Camera, CameraSource, Catalog, Pipeline, Settings};
/// let camera = Camera::from_fov(1024, 1024, 10.0)?;
/// let mut p = Pipeline::new(Catalog::load(None)?, Settings::default(), CameraSource::Fixed(camera), Backend::Cpu);
/// for r in p.process_batch(&[("frame.png".into(), "frame.png".to_string())]) {
///     println!("{}: {:?} {:?}", r.file, r.status, r.ra_deg);
/// }
/// # Ok::<(), gpustar::Error>(())
/// ```
pub struct Pipeline {
    pub solvers: Solvers,
    pub backend: Backend,
}

impl Pipeline {
    pub fn new(
        catalog: Catalog,
        settings: Settings,
        camera: CameraSource,
        backend: Backend,
    ) -> Self {
        Pipeline {
            solvers: Solvers::new(catalog, settings, camera),
            backend,
        }
    }

    /// One record per input, in input order.
    pub fn process_batch(&mut self, inputs: &[(PathBuf, String)]) -> Vec<Record> {
        let decoded: Vec<Decoded> = inputs
            .iter()
            .map(|(p, n)| self.solvers.decode(p, n))
            .collect();
        match &mut self.backend {
            Backend::Cpu => decoded
                .into_iter()
                .map(|d| self.solvers.solve_cpu(d))
                .collect(),
            Backend::Gpu(g) => g.solve(&self.solvers, decoded),
        }
    }
}

/// Counts over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    pub solved: usize,
    pub unsolved: usize,
    pub errors: usize,
}

impl Counts {
    pub fn add(&mut self, r: &Record) {
        use crate::record::Status;
        match r.status {
            Status::Solved => self.solved += 1,
            Status::Unsolved => self.unsolved += 1,
            Status::Error => self.errors += 1,
        }
    }

    pub fn total(&self) -> usize {
        self.solved + self.unsolved + self.errors
    }
}
