//! The solvers per frame size, shared by the worker threads, and a frame as read from its
//! file: what the CPU and GPU runners both start from.

use super::camera_source::CameraSource;
use crate::catalog::Catalog;
use crate::error::Result;
use crate::io::dark::Darks;
use crate::io::fits::scale::PixelScale;
use crate::io::frame::Frame;
use crate::products::Products;
use crate::record::Record;
use crate::solve::{Settings, Solver, detect};
use crate::streaks::StreakOptions;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The `backend` field of records made on the CPU.
pub const BACKEND_CPU: &str = "cpu";

/// A frame size's solver, or why it could not be built: the error every record of that size
/// carries.
pub type SharedSolver = Result<Arc<Solver>>;

/// Frame width, height and saturation level: frames alike in these share detection's
/// parameters.
pub(super) type DetectKey = (u32, u32, u16);

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

/// A frame after its pixel stages (the sequence stage's input): its detections, or the error
/// its record carries.
pub struct Detected {
    pub decoded: Decoded<'static>,
    pub detections: Result<Vec<crate::solve::detect::Detection>>,
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
    /// The decoded frame, or the error its record carries.
    pub frame: Result<Frame<'a>>,
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
            Err(e) => (Err(e), Vec::new()),
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
    pub fn error_record(&self, name: &str, error: &crate::Error, backend: &str) -> Record {
        let mut r = Record::error(name, error.to_string(), backend);
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
            Ok((f, info)) => (self.darks.apply(path, f), info),
            Err(e) => (Err(e), Default::default()),
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
            .or_insert_with(|| {
                let camera = self.camera.camera_for(width, height, scale.as_ref())?;
                Solver::new(&self.catalog, camera, self.settings).map(Arc::new)
            })
            .clone()
    }

    /// With [`CameraSource::Header`]: the pixel scale the frame's header states, if any.
    pub fn header_scale(&self, d: &Decoded) -> Option<PixelScale> {
        self.camera.header_scale(&d.keywords)
    }

    /// The pixel stages alone on the CPU (`--sequence`): the brightest `max_stars`, completed by
    /// the matched filter's faint sources (`detect::faint`).
    pub fn detect_cpu(&self, decoded: Decoded<'static>, max_stars: usize) -> Detected {
        let t0 = Instant::now();
        let s = self.settings.detect.for_sequence(max_stars);
        let detections = match &decoded.frame {
            Ok(f) => Ok(detect::faint::detect_with_faint(f, &s)),
            Err(e) => Err(e.clone()),
        };
        Detected {
            decoded,
            detections,
            detect_ms: t0.elapsed().as_secs_f64() * 1e3,
            backend: BACKEND_CPU.to_string(),
        }
    }
}

/// A frame's lost-in-space solver: at hand, or the size's, built when first needed.
pub(crate) enum Global<'a> {
    Ready(Arc<Solver>),
    Lazy(&'a Solvers, (u32, u32), Option<PixelScale>),
}

impl Global<'_> {
    /// The solver when it is at hand (not built on demand).
    pub(crate) fn ready(&self) -> Option<&Solver> {
        match self {
            Global::Ready(s) => Some(s),
            Global::Lazy(..) => None,
        }
    }

    /// The solver, built now if it is lazy and was not yet; None when the size has none (the
    /// catalog or camera cannot make one: the message is in the records of frames without a
    /// hint).
    pub(crate) fn solver(&self) -> Option<Arc<Solver>> {
        match self {
            Global::Ready(s) => Some(s.clone()),
            Global::Lazy(solvers, (w, h), scale) => solvers
                .get_scaled(*w, *h, scale.as_ref())
                .inspect_err(|e| tracing::debug!("no lost-in-space search after the hint's: {e}"))
                .ok(),
        }
    }
}
