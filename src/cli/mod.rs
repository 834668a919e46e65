//! The command line (clap derive). `main` calls [`run`].
//!
//! Size: about 1,500 lines because it holds every command (argument types, the solve driver,
//! `info`, `merge`, the calibration loop). Issue 23's layout step splits it into `cli/`, one
//! file per command; until then its sections follow the commands' order in [`Command`].

use crate::batch::{self, RunOptions};
use crate::camera::Camera;
use crate::catalog::{Catalog, DoubleStars};
use crate::io::dark::Darks;
use crate::io::inputs::{self, Input, Shard};
use crate::io::output::{self, Format, RecordWriter};
use crate::pipeline::{Backend, BackendChoice, BackendNote, CameraSource, Pipeline, Solvers};
use crate::products::Products;
use crate::record::Record;
use crate::sequence::SequenceOptions;
use crate::simulate::evaluate;
use crate::simulate::{self, SimSettings};
use crate::sky::{Station, parse_station};
use crate::solve::refine::CameraFit;
use crate::solve::{PassKind, Settings, Solver, scaled};
use crate::streaks::reduce::Astrometry;
use crate::streaks::{StreakOptions, StreakSettings, export::Exports};
use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

const AFTER_HELP: &str = "\
Examples:
  gpustar simulate --out sim -n 20 --fov-deg 18      # 20 synthetic frames + truth.jsonl
  gpustar batch sim --camera sim/camera.toml -o results.jsonl
  gpustar evaluate --truth sim/truth.jsonl results.jsonl
  gpustar solve frame.png --fov-deg 11.4 --epoch 2019.58
  gpustar batch tracking/ --camera cam.toml --streaks --station 35.7,51.4,1200 --tdm obs.tdm

Exit status: 0 when every input got a record and none is an error record (with --resume: none
in the whole file); 1 when some input has an error record; 2 when the run could not start (bad
options, unreadable camera or catalog, GPU asked for but absent, an --output that is not
gpustar's or that another gpustar is writing) or merge found inputs missing, repeated or torn;
3 when the records could not be written (a full disk: those written are whole; --resume
continues); 130 when interrupted (Ctrl-C, SIGTERM: the records written so far are complete;
--resume continues).";

/// Identify the stars in sky images and find the camera's attitude (lost in space).
#[derive(Parser, Debug)]
#[command(name = "gpustar", version, about, long_about = None, after_help = AFTER_HELP)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    /// Log more to stderr (-v: info, -vv: debug, -vvv: trace, e.g. every detection of a
    /// sequence with what it was judged).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Solve every image in DIR (sorted by name); one record per file, in that order.
    Batch {
        /// Directory of images (PNG, JPEG, TIFF, FITS).
        dir: PathBuf,
        #[command(flatten)]
        opts: SolveOpts,
        #[command(flatten)]
        run: RunArgs,
    },
    /// Solve one image; one record.
    Solve {
        /// The image file.
        image: PathBuf,
        #[command(flatten)]
        opts: SolveOpts,
    },
    /// Catalog summary and, for a camera, the reference stars and the distance table (of each
    /// band of a scale search).
    Info {
        #[command(flatten)]
        camera: CameraOpts,
        /// Image size for --fov-deg, as WIDTHxHEIGHT.
        #[arg(long, value_parser = parse_size)]
        size: Option<(u32, u32)>,
        #[command(flatten)]
        catalog: CatalogOpts,
    },
    /// Write synthetic frames, truth.jsonl and camera.toml into a directory.
    Simulate(SimulateArgs),
    /// Compare result records with a truth file: solved, correct, wrong, attitude errors.
    Evaluate {
        /// Results (JSON Lines, as written by batch).
        results: PathBuf,
        /// Truth file (truth.jsonl of simulate, or of ../shared/data/real/*).
        #[arg(long)]
        truth: PathBuf,
        /// A solution is correct when its attitude is within this angle of the truth.
        #[arg(long, default_value_t = 0.1)]
        tolerance_deg: f64,
        /// A star ID is false when the star is not within this many pixels of where the truth
        /// puts it (its listed position; for a star off the truth's list, its catalog position
        /// through the truth attitude and the lens the truth's list implies).
        #[arg(long, default_value_t = 3.0)]
        id_tolerance_px: f64,
        /// Also print one line per frame: status, correct, error_arcsec (rotation matrices),
        /// centre_error_arcsec and roll_error_arcsec (against the truth's ra/dec and
        /// roll_tetra3_deg), false_ids, correct_ids, identify_ms, stars_in_view.
        #[arg(long)]
        per_frame: bool,
    },
    /// Combine the outputs of `batch --shard K/N` runs into one, in input order, checking that
    /// every input of DIR appears exactly once.
    Merge {
        /// The shard outputs (JSON Lines).
        parts: Vec<PathBuf>,
        /// The directory the shards ran over: its inputs must each appear exactly once
        /// (required unless --no-check).
        #[arg(long, required_unless_present = "no_check")]
        dir: Option<PathBuf>,
        /// Combine the parts without a directory to check them against (duplicates are still
        /// refused; a missing input goes unnoticed).
        #[arg(long, conflicts_with = "dir")]
        no_check: bool,
        /// The shards ran with --recursive.
        #[arg(long)]
        recursive: bool,
        /// Write the merged records here (default: stdout).
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Fit the camera (fx, fy, cx, cy, k1, k2) to the identified stars of all solvable frames
    /// of DIR together (camera and attitudes adjusted jointly), re-identify with the fitted
    /// camera, fit again, and write a camera file `batch --camera` reads; residuals before and
    /// after on stderr.
    Calibrate {
        /// The directory of frames (one camera).
        dir: PathBuf,
        /// The camera file to start from (a focal length or FOV is enough).
        #[arg(long)]
        camera: PathBuf,
        /// The focal length is only known to within this fraction: search the scale at first.
        #[arg(long)]
        fov_tolerance: Option<f64>,
        /// Frames in subdirectories too.
        #[arg(short, long)]
        recursive: bool,
        /// Keep the principal point where the camera file puts it.
        #[arg(long)]
        fixed_centre: bool,
        /// Fit k1 only (k2 stays as the camera file gives it).
        #[arg(long)]
        no_k2: bool,
        /// Write the fitted camera here (TOML).
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        catalog: CatalogOpts,
    },
    /// Catalog maintenance.
    #[command(subcommand)]
    Catalog(CatalogCommand),
}

#[derive(Args, Debug, Clone)]
pub struct RunArgs {
    /// Also solve images in subdirectories (links to directories are not followed).
    #[arg(short, long)]
    pub recursive: bool,
    /// Skip inputs that already have a complete record in --output and append the rest (an
    /// incomplete last line, left by a crash, is cut off first). A file that is not gpustar
    /// output of this --format is refused untouched. Error records already there count in the
    /// exit status. An unfinished --sequence is tracked again from its first frame (its records
    /// not written twice), so the records that follow are an uninterrupted run's.
    #[arg(long, requires = "output")]
    pub resume: bool,
    /// With --resume: take the error records out of --output and try their inputs again.
    #[arg(long, requires = "resume")]
    pub retry_errors: bool,
    /// Only the inputs whose stable hash of the relative path falls in shard K of N (0-based),
    /// e.g. 3/16: run N processes (a job array) and `gpustar merge` their outputs.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<Shard>,
    /// Worker threads for decoding (and solving on the CPU) [default: all cores].
    #[arg(short = 'j', long, value_parser = count_within(1, 4096))]
    pub threads: Option<usize>,
    /// Each directory's frames (with -r, each subdirectory's) are one sequence of a camera
    /// head, in name order: detections moving against the stars are judged particles (they
    /// never vote or match), and frames are identified from the attitude the previous ones
    /// predict (lost-in-space when that fails). Records add sequence_mode and particles.
    /// A sequence is never split across shards.
    #[arg(long, help_heading = "Sequences")]
    pub sequence: bool,
    /// Seconds between frames, for frames without a time in their header (FITS DATE-OBS).
    #[arg(long, value_name = "SECONDS", requires = "sequence", help_heading = "Sequences",
          value_parser = parse_positive)]
    pub frame_interval: Option<f64>,
}

/// A number greater than zero.
/// A value parser for a number within `lo..=hi` (NaN and infinities refused): absurd values
/// are told at once (exit 2), not found out by a run that takes hours.
fn within(lo: f64, hi: f64) -> impl Fn(&str) -> std::result::Result<f64, String> + Clone {
    move |s: &str| match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (lo..=hi).contains(&v) => Ok(v),
        Ok(_) => Err(format!("{s} is outside {lo} to {hi}")),
        Err(_) => Err(format!("{s:?} is not a number")),
    }
}

/// [`within`] for single-precision options.
fn within_f32(lo: f64, hi: f64) -> impl Fn(&str) -> std::result::Result<f32, String> + Clone {
    move |s: &str| within(lo, hi)(s).map(|v| v as f32)
}

/// [`within`] for counts.
fn count_within(
    lo: usize,
    hi: usize,
) -> impl Fn(&str) -> std::result::Result<usize, String> + Clone {
    move |s: &str| match s.trim().parse::<usize>() {
        Ok(v) if (lo..=hi).contains(&v) => Ok(v),
        Ok(_) => Err(format!("{s} is outside {lo} to {hi}")),
        Err(_) => Err(format!("{s:?} is not a whole number")),
    }
}

fn parse_positive(s: &str) -> std::result::Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v > 0.0 && v.is_finite() => Ok(v),
        _ => Err(format!("expected a number of seconds above 0, got {s:?}")),
    }
}

#[derive(Subcommand, Debug)]
pub enum CatalogCommand {
    /// Make gpustar's catalog CSV from Hipparcos-2 hip2.dat (CDS I/311).
    Import {
        /// Path of hip2.dat.
        hip2: PathBuf,
        /// Keep stars with Hp at or below this.
        #[arg(long, default_value_t = 8.0)]
        max_mag: f64,
        /// Output file (default: stdout).
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
}

#[derive(Args, Debug, Clone)]
pub struct CameraOpts {
    /// Camera model (TOML: width, height, fov_x_deg or fx_px, fy_px, cx_px, cy_px, k1, k2,
    /// mirrored, mag_limit).
    #[arg(long, conflicts_with = "fov_deg")]
    pub camera: Option<PathBuf>,
    /// Horizontal field of view in degrees: square pixels, centred, no distortion. A range
    /// (e.g. 8..20) searches the scale; the records give the fitted FOV.
    #[arg(long, value_parser = parse_fov)]
    pub fov_deg: Option<FovArg>,
    /// The camera's focal length is only known to within this fraction (e.g. 0.01): search
    /// the scale within it and fit it.
    #[arg(long)]
    pub fov_tolerance: Option<f64>,
    /// What refinement fits besides the attitude: nothing, the scale (field of view), or the
    /// scale and radial distortion k1 (reported as distortion_k1).
    #[arg(long, value_enum, default_value_t = CameraFit::None)]
    pub fit: CameraFit,
}

/// Detection's matched filter (`--detect-filter`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DetectFilter {
    None,
    Binomial,
}

/// `--fov-deg`: one value or a range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FovArg {
    Exact(f64),
    Range(f64, f64),
}

fn parse_fov(s: &str) -> std::result::Result<FovArg, String> {
    let num = |v: &str| -> std::result::Result<f64, String> {
        let x: f64 = v
            .trim()
            .parse()
            .map_err(|_| format!("bad field of view {v:?}"))?;
        if x > 0.0 && x < 170.0 {
            Ok(x)
        } else {
            Err(format!(
                "field of view must be between 0 and 170 degrees, got {x}"
            ))
        }
    };
    match s.split_once("..") {
        Some((a, b)) => {
            let (a, b) = (num(a)?, num(b)?);
            if a >= b {
                return Err(format!("expected LOW..HIGH, got {s:?}"));
            }
            Ok(FovArg::Range(a, b))
        }
        None => Ok(FovArg::Exact(num(s)?)),
    }
}

#[derive(Args, Debug, Clone)]
pub struct CatalogOpts {
    /// Catalog CSV (default: the built-in Hipparcos-2 catalog, Hp ≤ 8).
    #[arg(long)]
    pub catalog: Option<PathBuf>,
    /// Observation epoch (decimal year) for proper motion.
    #[arg(long, default_value_t = 2000.0, value_parser = within(1000.0, 3000.0))]
    pub epoch: f64,
    /// Faintest catalog magnitude used [default: the camera file's mag_limit, else chosen from
    /// the field of view so that about 40 catalog stars are in view; in a scale search, each
    /// band's middle field's for the vote, the fitted field's for the final refinement].
    #[arg(long, value_parser = within(-2.0, 20.0), allow_negative_numbers = true)]
    pub mag_limit: Option<f64>,
    /// Stars the camera cannot separate: merge them into one at their photocentre, drop
    /// them, or keep them.
    #[arg(long, value_enum, default_value_t = DoubleStars::Merge)]
    pub double_stars: DoubleStars,
    /// Stars closer than this many pixels count as one.
    #[arg(long, default_value_t = 2.0, value_parser = within(0.0, 100.0))]
    pub double_star_px: f64,
    /// Do not read or write the distance-table cache.
    #[arg(long)]
    pub no_cache: bool,
}

#[derive(Args, Debug, Clone)]
pub struct SolveOpts {
    #[command(flatten)]
    pub camera: CameraOpts,
    #[command(flatten)]
    pub catalog: CatalogOpts,
    /// Write the records here instead of stdout.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Record format.
    #[arg(long, value_enum, default_value_t = Format::Jsonl)]
    pub format: Format,
    /// Where the kernels run: the GPU if there is a hardware one, else the CPU twins (auto;
    /// a software rasterizer such as lavapipe is slower than the twins), the GPU whatever it
    /// is, or the CPU. The adapter is the best one found, or the first whose name contains
    /// $GPUSTAR_ADAPTER.
    #[arg(long, value_enum, default_value_t = BackendChoice::Auto)]
    pub backend: BackendChoice,
    /// Frames per GPU batch (one submission for detection and one for voting per batch).
    #[arg(long, default_value_t = 32, value_parser = count_within(1, 4096))]
    pub batch_size: usize,
    /// Detection threshold above the local background, in noise sigmas.
    #[arg(long, default_value_t = 5.0, value_parser = within_f32(0.5, 100.0))]
    pub sigma: f32,
    /// Detection's matched filter: `binomial` thresholds each pixel's 3x3 binomial smoothing
    /// (about a star's PSF) at --sigma sigmas of the smoothed noise, and the pixel at 0.375 of
    /// that, which finds stars of about half the peak SNR; `none` thresholds the pixels alone.
    #[arg(long, value_enum, default_value_t = DetectFilter::None)]
    pub detect_filter: DetectFilter,
    /// How star positions are measured: a maximum-likelihood fit of a pixel-integrated
    /// Gaussian on a 9x9 window (the centre of gravity where it does not settle; matches then
    /// carry their 1-sigma and weigh the attitude by it), or the centre of gravity.
    #[arg(long, value_enum, default_value_t = crate::solve::detect::Centroid::Ml)]
    pub centroid: crate::solve::detect::Centroid,
    /// How stars are identified: geometric voting (triangles as its fallback), radial
    /// features as the candidate filter and triangles among the candidates (seed 002; for
    /// narrow, deep fields), or triangles alone (seed 002's baseline).
    #[arg(long, value_enum, default_value_t = crate::solve::radial::Method::Vote)]
    pub method: crate::solve::radial::Method,
    /// Brightest detected stars that take part in the vote.
    #[arg(long, default_value_t = 40, value_parser = count_within(4, 200))]
    pub vote_stars: usize,
    /// Pair distance tolerance from centroid errors, pixels.
    #[arg(long, default_value_t = 0.4, value_parser = within(0.01, 5.0))]
    pub pair_tol_px: f64,
    /// Do not retry frames that fail: first with up to 60 voting stars, then with the voters
    /// spread over a grid of 16 cells (both when there are more stars than --vote-stars), then
    /// with wide tolerances (pair 4 px, match radius 5 px).
    #[arg(long)]
    pub no_retry: bool,
    /// Pair distance tolerance from focal-length and distortion errors, relative.
    #[arg(long, default_value_t = 0.0002, value_parser = within(0.0, 0.05))]
    pub scale_tol: f64,
    /// A detection matches a catalog star within this many pixels in refinement.
    #[arg(long, default_value_t = 2.0, value_parser = within(0.1, 20.0))]
    pub match_radius_px: f64,
    /// Report `solved` only when the probability of a chance match is below this.
    #[arg(long, default_value_t = 1e-6, value_parser = within(1e-300, 0.5))]
    pub max_false_prob: f64,
    /// Subtract this dark frame (same size, any readable format) from every frame before
    /// detection: removes hot pixels and fixed-pattern noise.
    #[arg(long, value_name = "FILE", conflicts_with = "dark_median")]
    pub dark: Option<PathBuf>,
    /// Subtract from each frame the per-pixel median of up to 25 frames of its directory (of
    /// the same size): a dark made from the data, for cameras with fixed-pattern noise and
    /// no dark frame. Needs at least 3 frames per directory, pointing at different skies.
    #[arg(long)]
    pub dark_median: bool,
    /// Write a FITS WCS header (TAN, plus SIP when distortion is fitted or given) for each
    /// solved frame here, at the input's relative path with the extension .wcs.
    #[arg(long, value_name = "DIR")]
    pub wcs_dir: Option<PathBuf>,
    /// Write an annotated PNG of each readable frame here (identified stars circled in green
    /// with their HIP number, other detections in red, catalog stars in the frame that
    /// nothing matched as cyan crosses), at the input's relative path with the extension .png.
    #[arg(long, value_name = "DIR")]
    pub annotate_dir: Option<PathBuf>,
    /// No progress bar, warnings or summary on stderr.
    #[arg(short, long)]
    pub quiet: bool,
    #[command(flatten)]
    pub streaks: StreakOpts,
}

/// Satellite streaks (optical-tracking frames).
#[derive(Args, Debug, Clone)]
pub struct StreakOpts {
    /// Find satellite streaks: sub-pixel ends (edge-flagged where they leave the frame),
    /// width, flux, SNR, RA/Dec and Az/El of the ends; detections on a streak are kept out of
    /// star identification. Records get a "streaks" list.
    #[arg(long, help_heading = "Streaks")]
    pub streaks: bool,
    /// The station for Az/El (geodetic WGS-84, east longitude positive) [default: each FITS
    /// header's OBSGEO-B/L/H, OBSGEO-X/Y/Z or SITELAT/SITELONG/SITEELEV].
    #[arg(long, value_name = "LAT,LON,HEIGHT_M", value_parser = parse_station,
          requires = "streaks", help_heading = "Streaks")]
    pub station: Option<Station>,
    /// Where the RA/Dec of streak ends come from: gpustar's solution, the FITS header's
    /// TAN/TAN-SIP WCS, or the solution when the frame solves and else the header (auto).
    #[arg(long, value_enum, default_value_t = Astrometry::Auto, help_heading = "Streaks")]
    pub astrometry: Astrometry,
    /// UT1 − UTC in seconds for Az/El [default: interpolated in the bundled IERS table
    /// (catalog/eop.csv); beyond its end its last value, with a warning].
    #[arg(
        long,
        value_name = "SECONDS",
        allow_negative_numbers = true,
        requires = "streaks",
        help_heading = "Streaks",
        value_parser = within(-1.0, 1.0)
    )]
    pub dut1: Option<f64>,
    /// Streak mask threshold, noise sigmas of the smoothed frame.
    #[arg(long, default_value_t = 3.5, help_heading = "Streaks",
          value_parser = within_f32(0.5, 100.0))]
    pub streak_sigma: f32,
    /// Write the streaks' midpoints at mid-exposure as a CCSDS TDM (KVN): RADEC, and AZEL
    /// when the station is known.
    #[arg(
        long,
        value_name = "FILE",
        requires = "streaks",
        help_heading = "Streaks"
    )]
    pub tdm: Option<PathBuf>,
    /// Write the streaks' midpoints at mid-exposure as IOD lines (angle format 2, J2000).
    #[arg(
        long,
        value_name = "FILE",
        requires = "streaks",
        help_heading = "Streaks"
    )]
    pub iod: Option<PathBuf>,
    /// COSPAR station number for the IOD lines.
    #[arg(long, default_value_t = 9999, value_parser = clap::value_parser!(u16).range(0..=9999),
          help_heading = "Streaks")]
    pub iod_station: u16,
}

#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of frames.
    #[arg(short = 'n', long, default_value_t = 10)]
    pub frames: usize,
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 18.0)]
    pub fov_deg: f64,
    /// Frame size, WIDTHxHEIGHT.
    #[arg(long, value_parser = parse_size, default_value = "1024x1024")]
    pub size: (u32, u32),
    /// Faintest catalog star drawn (Hp).
    #[arg(long, default_value_t = 6.0)]
    pub mag_limit: f64,
    /// False stars per frame.
    #[arg(long, default_value_t = 3)]
    pub false_stars: usize,
    /// Hot pixels per frame.
    #[arg(long, default_value_t = 5)]
    pub hot_pixels: usize,
    /// Centroid noise: draw each catalog star this far off its true place (Gaussian sigma in
    /// x and in y, pixels); the truth keeps the true places.
    #[arg(long, default_value_t = 0.0)]
    pub centroid_noise_px: f64,
    /// Bits per pixel: 8 or 16.
    #[arg(long, default_value_t = 8)]
    pub bits: u8,
    /// Random seed: the same seed gives the same frames.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Epoch of the star positions (decimal year).
    #[arg(long, default_value_t = 2000.0)]
    pub epoch: f64,
    /// Gaussian PSF sigma, pixels.
    #[arg(long, default_value_t = 1.0)]
    pub psf_sigma: f64,
    /// Sky background at the centre, electrons per pixel.
    #[arg(long, default_value_t = 400.0)]
    pub sky: f64,
    /// Read noise, electrons.
    #[arg(long, default_value_t = 15.0)]
    pub read_noise: f64,
    /// Fall-off of sky and stars from centre to corner (0 = none).
    #[arg(long, default_value_t = 0.3)]
    pub vignetting: f64,
    /// Catalog CSV to draw stars from (default: built-in).
    #[arg(long)]
    pub catalog: Option<PathBuf>,
    /// Take the frames with this camera model (TOML, as for batch: non-square pixels,
    /// principal point, distortion, mirror) instead of --size and --fov-deg.
    #[arg(long, conflicts_with_all = ["size", "fov_deg"])]
    pub camera: Option<PathBuf>,
    /// Satellite streaks of known ends: 16-bit FITS frames with DATE-BEG, DATE-END, EXPTIME
    /// and the station (OBSGEO-B/L/H) in the header; truth.jsonl adds each streak's ends.
    /// Every fifth frame has none, the others one or two, many crossing the frame's edge.
    #[arg(long, conflicts_with = "camera", help_heading = "Streaks")]
    pub streaks: bool,
    /// Exposure start of the first frame (UTC); each next frame starts a minute later. With
    /// --sequence: mid-exposure of each sequence's first frame.
    #[arg(long, default_value = "2024-03-15T20:00:00", help_heading = "Streaks")]
    pub start_utc: String,
    /// Exposure time, seconds.
    #[arg(long, default_value_t = 5.0, help_heading = "Streaks")]
    pub exposure: f64,
    /// The station written into the headers: LAT,LON,HEIGHT_M.
    #[arg(long, default_value = "35.7,51.4,1200", value_parser = parse_station,
          help_heading = "Streaks")]
    pub station: Station,
    /// Peak SNR per pixel of the streaks, LOW..HIGH (drawn uniformly).
    #[arg(long, default_value = "4..25", value_parser = parse_range, help_heading = "Streaks")]
    pub streak_snr: (f64, f64),
    /// Sequences of a turning star tracker with moving particles: --sequences directories
    /// seq_NNN of -n frames each, 16-bit FITS with DATE-OBS, DATE-END and EXPTIME;
    /// truth.jsonl adds each frame's sequence, index, time and particles.
    #[arg(long, conflicts_with_all = ["camera", "streaks"], help_heading = "Sequences")]
    pub sequence: bool,
    /// Number of sequences.
    #[arg(long, default_value_t = 2, help_heading = "Sequences")]
    pub sequences: usize,
    /// Seconds between frames.
    #[arg(long, default_value_t = 1.0, value_parser = parse_positive,
          help_heading = "Sequences")]
    pub frame_interval: f64,
    /// The camera's turn rate, LOW..HIGH degrees per second (drawn per sequence).
    #[arg(long, default_value = "0.05..0.5", value_parser = parse_range,
          help_heading = "Sequences")]
    pub turn_rate: (f64, f64),
    /// Particles per catalog star in view of the first frame (0: none).
    #[arg(long, default_value_t = 1.5, help_heading = "Sequences")]
    pub particle_ratio: f64,
    /// Particle speeds against the stars, LOW..HIGH arcmin per second.
    #[arg(long, default_value = "6..40", value_parser = parse_range,
          help_heading = "Sequences")]
    pub particle_speed: (f64, f64),
    /// Particle magnitudes, LOW..HIGH (on the stars' scale: most are brighter than most
    /// stars).
    #[arg(long, default_value = "1.5..5", value_parser = parse_range,
          help_heading = "Sequences")]
    pub particle_mag: (f64, f64),
}

/// `LOW..HIGH`, two positive numbers.
fn parse_range(s: &str) -> std::result::Result<(f64, f64), String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("expected LOW..HIGH, got {s:?}"))?;
    let num = |v: &str| v.trim().parse::<f64>().ok().filter(|x| *x > 0.0);
    match (num(a), num(b)) {
        (Some(a), Some(b)) if a < b => Ok((a, b)),
        _ => Err(format!("expected LOW..HIGH with 0 < LOW < HIGH, got {s:?}")),
    }
}

fn parse_size(s: &str) -> std::result::Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WIDTHxHEIGHT, got {s:?}"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| format!("bad size {s:?}"))
    };
    Ok((p(w)?, p(h)?))
}

/// Run the command line; errors are printed once by `main`.
pub fn execute(cli: Cli) -> Result<ExitCode> {
    init_logging(cli.verbose);
    if cli.verbose == 0 {
        give_the_driver_a_runtime_dir();
    }
    match cli.command {
        Command::Batch { dir, opts, run } => {
            let mut inputs = inputs::list(&dir, run.recursive)?;
            if let Some(shard) = run.shard {
                // A sequence goes to one shard whole: its frames depend on each other.
                inputs.retain(|i| {
                    shard.takes(if run.sequence {
                        crate::sequence::sequence_of(&i.name)
                    } else {
                        &i.name
                    })
                });
            }
            run_solve(inputs, &opts, &run)
        }
        Command::Solve { image, opts } => {
            let name = image.display().to_string();
            let run = RunArgs {
                recursive: false,
                resume: false,
                retry_errors: false,
                shard: None,
                threads: Some(1),
                sequence: false,
                frame_interval: None,
            };
            run_solve(
                vec![Input {
                    path: image,
                    name,
                    replay: false,
                }],
                &opts,
                &run,
            )
        }
        Command::Merge {
            parts,
            dir,
            no_check: _,
            recursive,
            output,
        } => {
            let records: Vec<_> = parts
                .iter()
                .map(|p| output::read_records(p))
                .collect::<Result<_>>()?;
            let expected: Option<Vec<String>> = match &dir {
                Some(d) => Some(
                    inputs::list(d, recursive)?
                        .into_iter()
                        .map(|i| i.name)
                        .collect(),
                ),
                None => None,
            };
            let merged = match output::merge(&records, expected.as_deref()) {
                Ok(m) => m,
                Err(e) => {
                    eprintln!("gpustar: error: {e:#}");
                    return Ok(ExitCode::from(2));
                }
            };
            let out: Box<dyn Write + Send> = match &output {
                Some(p) => Box::new(output::open_output(p, Format::Jsonl, false, false)?.file),
                None => Box::new(std::io::stdout()),
            };
            let mut w = RecordWriter::new(out, Format::Jsonl, false);
            for r in &merged {
                w.write(r);
            }
            w.flush()?;
            eprintln!(
                "gpustar: merged {} records from {} files{}",
                merged.len(),
                parts.len(),
                if dir.is_some() {
                    "; every input exactly once"
                } else {
                    ""
                }
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Info {
            camera,
            size,
            catalog,
        } => info(&camera, size, &catalog),
        Command::Simulate(a) => simulate_cmd(a),
        Command::Calibrate {
            dir,
            camera,
            fov_tolerance,
            recursive,
            fixed_centre,
            no_k2,
            output,
            catalog,
        } => calibrate_cmd(
            &dir,
            &camera,
            fov_tolerance,
            recursive,
            crate::calibrate::FitOptions {
                fit_principal_point: !fixed_centre,
                fit_k2: !no_k2,
                ..Default::default()
            },
            &output,
            &catalog,
        ),
        Command::Evaluate {
            results,
            truth,
            tolerance_deg,
            id_tolerance_px,
            per_frame,
        } => {
            let truth = simulate::read_truth(&truth)?;
            let records = output::read_records(&results)?;
            let (s, frames) = evaluate::evaluate(&truth, &records, tolerance_deg, id_tolerance_px);
            let mut text = String::new();
            if per_frame {
                for f in &frames {
                    text += &serde_json::to_string(f)?;
                    text.push('\n');
                }
            }
            text += &serde_json::to_string_pretty(&s)?;
            text.push('\n');
            print_all(&text)
        }
        Command::Catalog(CatalogCommand::Import {
            hip2,
            max_mag,
            output,
        }) => {
            let text = std::fs::read_to_string(&hip2)
                .with_context(|| format!("cannot read {}", hip2.display()))?;
            let csv = crate::catalog::import_hip2(&text, max_mag)?;
            match output {
                Some(p) => std::fs::write(&p, csv)
                    .with_context(|| format!("cannot write {}", p.display()))?,
                None => std::io::stdout().write_all(csv.as_bytes())?,
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// Range of focal-length factors (low, high) to search when the scale is uncertain.
type ScaleRange = (f64, f64);

/// The camera source, its optional magnitude limit, and the scale range to search. With
/// `header_only` (`--streaks --astrometry header`) no camera is needed.
fn camera_source(
    c: &CameraOpts,
    header_only: bool,
) -> Result<(CameraSource, Option<f64>, Option<ScaleRange>)> {
    let tolerance = match c.fov_tolerance {
        Some(t) if !(t > 0.0 && t < 0.5) => bail!("--fov-tolerance must be between 0 and 0.5"),
        Some(t) => Some((1.0 - t, 1.0 + t)),
        None => None,
    };
    match (&c.camera, c.fov_deg) {
        (Some(path), _) => {
            let (cam, mag) = Camera::from_toml_file(path)?;
            Ok((CameraSource::Fixed(cam), mag, tolerance))
        }
        (None, Some(FovArg::Exact(fov))) => Ok((CameraSource::Fov(fov), None, tolerance)),
        (None, Some(FovArg::Range(lo, hi))) => {
            // The camera of the middle FOV; focal lengths scale as 1 / tan(FOV / 2).
            let mid = (lo + hi) / 2.0;
            let f = |fov: f64| 1.0 / (fov.to_radians() / 2.0).tan();
            Ok((
                CameraSource::Fov(mid),
                None,
                Some((f(hi) / f(mid), f(lo) / f(mid))),
            ))
        }
        (None, None) if header_only => Ok((CameraSource::None, None, None)),
        (None, None) => bail!(
            "give the camera: --camera FILE or --fov-deg DEG (or, for streaks reduced through \
             each FITS header's WCS alone, --streaks --astrometry header)"
        ),
    }
}

fn settings(c: &CatalogOpts, camera_mag: Option<f64>) -> Settings {
    Settings {
        epoch: c.epoch,
        mag_limit: c.mag_limit.or(camera_mag),
        double_stars: c.double_stars,
        double_star_px: c.double_star_px,
        table_cache: !c.no_cache,
        ..Settings::default()
    }
}

fn run_solve(inputs: Vec<Input>, o: &SolveOpts, b: &RunArgs) -> Result<ExitCode> {
    if b.sequence && o.streaks.streaks {
        anyhow::bail!(
            "--sequence and --streaks do not go together yet: run the sequences and the \
             streak frames separately"
        );
    }
    let header_only = o.streaks.streaks && o.streaks.astrometry == Astrometry::Header;
    let (camera, camera_mag, scale_range) = camera_source(&o.camera, header_only)?;
    let catalog = Catalog::load(o.catalog.catalog.as_deref())?;
    let mut s = settings(&o.catalog, camera_mag);
    s.detect.k_sigma = o.sigma;
    s.detect.matched_filter = o.detect_filter == DetectFilter::Binomial;
    s.detect.centroid = o.centroid;
    s.method = o.method;
    s.identify.vote_stars = o.vote_stars;
    s.retry = !o.no_retry;
    s.identify.pair_tol_px = o.pair_tol_px;
    s.identify.scale_tol = o.scale_tol;
    s.refine.match_radius_px = o.match_radius_px;
    s.refine.max_false_prob = o.max_false_prob;
    s.refine.fit = o.camera.fit;
    s.scale_range = scale_range;
    let so = &o.streaks;
    let mut exports = Exports::new(
        so.tdm.clone(),
        so.iod.clone(),
        so.iod_station,
        so.station.map_or_else(
            || "STATION".to_string(),
            |s| format!("{:.5},{:.5},{:.1}", s.lat_deg, s.lon_deg, s.height_m),
        ),
    );
    exports.check_paths()?;
    // The output, and what an earlier run already wrote to it.
    let mut inputs = inputs;
    let mut header = true;
    let mut errors_before = 0;
    let out: Box<dyn Write + Send> = match &o.output {
        Some(p) => {
            let opened = output::open_output(p, o.format, b.resume, b.retry_errors)?;
            let prev = opened.previous;
            let before = inputs.len();
            let already = inputs
                .iter()
                .filter(|i| prev.done.contains(&i.name))
                .count();
            inputs = resumed_inputs(inputs, &prev.done, b.sequence);
            if b.resume && !o.quiet {
                if prev.truncated > 0 {
                    eprintln!(
                        "gpustar: cut an incomplete last record ({} bytes) off {}",
                        prev.truncated,
                        p.display()
                    );
                }
                let replayed = inputs.iter().filter(|i| i.replay).count();
                eprintln!(
                    "gpustar: resuming: {already} of {before} inputs already have a record{}{}{}",
                    match prev.errors {
                        0 => String::new(),
                        n => format!(" ({n} of them errors; --retry-errors tries them again)"),
                    },
                    match prev.retried {
                        0 => String::new(),
                        n => format!("; {n} error records taken out to be tried again"),
                    },
                    match replayed {
                        0 => String::new(),
                        n => format!(
                            "; {n} of those are tracked again, unwritten, so that unfinished \
                             sequences go on as an uninterrupted run does"
                        ),
                    }
                );
            }
            // The exports are written whole at the end: they take the streaks of the records
            // already in the file too, or a resumed run's TDM would hold only its own part.
            if b.resume && exports.wanted() {
                for r in &prev.streaks {
                    exports.add(r);
                }
            }
            errors_before = prev.errors;
            header = !prev.has_header;
            Box::new(opened.file)
        }
        None => Box::new(std::io::stdout()),
    };
    let (mut backend, note) = Backend::open(o.backend)?;
    match note {
        Some(BackendNote::Warning(w)) => tracing::warn!("{w}"),
        Some(BackendNote::Info(i)) => tracing::info!("{i}"),
        None => {}
    }
    let mut solvers = Solvers::new(catalog, s, camera);
    solvers.darks = match (&o.dark, o.dark_median) {
        (Some(path), _) => Darks::from_file(path).context("--dark")?,
        (None, true) => Darks::directory_median(),
        (None, false) => Darks::None,
    };
    solvers.products = Products {
        wcs_dir: o.wcs_dir.clone(),
        annotate_dir: o.annotate_dir.clone(),
    };
    solvers.streaks = so.streaks.then_some(StreakOptions {
        settings: StreakSettings {
            k_sigma: so.streak_sigma,
            ..StreakSettings::default()
        },
        station: so.station,
        dut1_s: so.dut1,
        astrometry: so.astrometry,
    });
    let mut writer = RecordWriter::new(out, o.format, header);
    let stop = interrupt_flag();
    let to_do = inputs.iter().filter(|i| !i.replay).count();
    let bar = progress_bar(to_do as u64, o.quiet);
    let threads = b
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let opts = RunOptions {
        threads,
        batch_size: o.batch_size,
        flush_every: std::time::Duration::from_millis(250),
        sequence: b.sequence.then(|| SequenceOptions {
            frame_interval_s: b.frame_interval,
            ..SequenceOptions::default()
        }),
    };
    let summary = batch::run(
        inputs,
        &solvers,
        &mut backend,
        &mut writer,
        opts,
        stop,
        |r, c| {
            exports.add(r);
            bar.inc(1);
            bar.set_message(format!(
                "{} solved, {} unsolved, {} errors",
                c.solved, c.unsolved, c.errors
            ));
            tracing::debug!("{}: {:?}", r.file, r.status);
        },
    )?;
    bar.finish_and_clear();
    if exports.wanted() && summary.write_error.is_none() {
        let said = exports.finish(&crate::sky::now_utc_iso())?;
        if !o.quiet {
            eprintln!("gpustar: wrote {said}");
        }
    }
    let c = summary.counts;
    if !o.quiet {
        eprintln!(
            "gpustar: {} files: {} solved, {} unsolved, {} errors in {:.2} s ({:.1} images/s, {}){}",
            c.total(),
            c.solved,
            c.unsolved,
            c.errors,
            summary.seconds,
            c.total() as f64 / summary.seconds.max(1e-9),
            backend.name(),
            match (&summary.write_error, summary.interrupted, c.total() < to_do) {
                (Some(e), ..) => format!(
                    "; stopped: {e}; records before it are whole: make room and rerun with \
                     --resume"
                ),
                (None, true, true) => "; interrupted: rerun with --resume to finish".into(),
                (None, true, false) => {
                    "; interrupted after the last input: every input has a record".into()
                }
                (None, false, _) => String::new(),
            }
        );
    }
    Ok(if summary.write_error.is_some() {
        ExitCode::from(3)
    } else if summary.interrupted {
        ExitCode::from(130)
    } else if c.errors + errors_before > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}

/// The inputs still to do after an earlier run recorded `done`. Sequences are tracked frame
/// to frame, so an unfinished sequence is taken from its first frame, the recorded ones marked
/// `replay` (tracked, not written): the records that follow are those of an uninterrupted run.
fn resumed_inputs(
    inputs: Vec<Input>,
    done: &std::collections::HashSet<String>,
    sequence: bool,
) -> Vec<Input> {
    use crate::sequence::sequence_of;
    let unfinished: std::collections::HashSet<&str> = inputs
        .iter()
        .filter(|i| sequence && !done.contains(&i.name))
        .map(|i| sequence_of(&i.name))
        .collect();
    inputs
        .iter()
        .filter(|i| !done.contains(&i.name) || unfinished.contains(sequence_of(&i.name)))
        .map(|i| Input {
            replay: done.contains(&i.name),
            ..i.clone()
        })
        .collect()
}

/// How long frames in flight may take to finish after a stop request before the process ends
/// without them (their inputs get no record; `--resume` does them).
const STOP_GRACE: std::time::Duration = std::time::Duration::from_secs(5);

/// Set by Ctrl-C (SIGINT) or SIGTERM: the run stops handing out inputs, leaves queued ones
/// without a record, and writes the records of frames in flight that finish within
/// [`STOP_GRACE`]; after that the process ends with 130 whatever a frame is doing, as it does
/// at once on a second signal. Either way it ends between two whole lines of the output.
fn interrupt_flag() -> &'static std::sync::atomic::AtomicBool {
    static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
    static ONCE: std::sync::Once = std::sync::Once::new();
    fn exit_between_lines(why: &str) -> ! {
        let _writing = output::WRITING.lock().unwrap_or_else(|e| e.into_inner());
        eprintln!("gpustar: {why}; inputs without a record are done by --resume");
        std::process::exit(130);
    }
    ONCE.call_once(|| {
        let _ = ctrlc::set_handler(|| {
            if STOP.swap(true, std::sync::atomic::Ordering::SeqCst) {
                exit_between_lines("interrupted again: exiting without waiting");
            }
            std::thread::spawn(|| {
                std::thread::sleep(STOP_GRACE);
                exit_between_lines(&format!(
                    "interrupted: frames still in flight after {} s were abandoned",
                    STOP_GRACE.as_secs()
                ));
            });
        });
    });
    &STOP
}

/// A progress bar on stderr: rate, ETA and counts; hidden with -q or when stderr is not a
/// terminal.
fn progress_bar(len: u64, quiet: bool) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if quiet || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} {rate} ETA {eta} {msg}",
        )
        .expect("a valid template")
        .with_key(
            "rate",
            |s: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = write!(w, "{:.0} images/s", s.per_sec());
            },
        )
        .progress_chars("=> "),
    );
    bar
}

/// Mesa's Vulkan drivers print "error: XDG_RUNTIME_DIR is invalid or not set in the
/// environment." on stderr, twice, where the environment has no runtime directory (containers,
/// batch jobs, cron): give them one of gpustar's own in the temp directory. Left alone with
/// `-v`, so that the driver's own words can be seen.
fn give_the_driver_a_runtime_dir() {
    let set = std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| Path::new(&d).is_dir());
    if set {
        return;
    }
    let dir = std::env::temp_dir().join("gpustar-runtime");
    if std::fs::create_dir_all(&dir).is_err() {
        return;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let _ = std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700));
    }
    // SAFETY: called first thing in `run`, before any thread of gpustar's exists, so no other
    // thread can read the environment while it changes.
    unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
}

/// Logs to stderr: warnings by default, more with -v.
fn init_logging(verbose: u8) {
    let level = match verbose {
        0 => tracing::Level::WARN,
        1 => tracing::Level::INFO,
        2 => tracing::Level::DEBUG,
        _ => tracing::Level::TRACE,
    };
    use std::io::IsTerminal;
    let terminal = std::io::stderr().is_terminal();
    let _ = tracing_subscriber::fmt()
        .with_max_level(level)
        .with_writer(std::io::stderr)
        .with_ansi(terminal)
        .with_target(false)
        .without_time()
        .try_init();
    // A panic on one frame becomes that frame's error record; into a log file (stderr not a
    // terminal) it is said in one line, without the backtrace RUST_BACKTRACE would add
    // (-vv keeps Rust's own report).
    if !terminal && verbose < 2 {
        std::panic::set_hook(Box::new(|info| {
            let at = info
                .location()
                .map(|l| format!(" at {}:{}", l.file(), l.line()))
                .unwrap_or_default();
            let what = info
                .payload()
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| info.payload().downcast_ref::<String>().cloned())
                .unwrap_or_default();
            eprintln!("gpustar: internal error{at}: {what} (-vv for Rust's report)");
        }));
    }
}

fn info(c: &CameraOpts, size: Option<(u32, u32)>, o: &CatalogOpts) -> Result<ExitCode> {
    use std::fmt::Write as _;
    // Written at the end in one piece, so that `| head` ends it quietly (see `print_all`).
    let mut out = String::new();
    let adapters = crate::gpu::adapters();
    writeln!(out, "GPU adapters: {}", adapters.len())?;
    for a in &adapters {
        writeln!(
            out,
            "  {} ({}, {}, driver {})",
            a.name, a.backend, a.device_type, a.driver
        )?;
    }
    match crate::gpu::Gpu::new(std::env::var("GPUSTAR_ADAPTER").ok().as_deref()) {
        Ok(g) => {
            writeln!(out, "chosen: {}", g.backend_name())?;
            writeln!(
                out,
                "  limits: Limits::default() with max_storage_buffer_binding_size {} MB, \
                 max_buffer_size {} MB (the adapter's); no optional features",
                g.limits.max_storage_buffer_binding_size >> 20,
                g.limits.max_buffer_size >> 20
            )?;
        }
        Err(e) => writeln!(out, "chosen: none ({e:#})")?,
    }
    let catalog = Catalog::load(o.catalog.as_deref())?;
    writeln!(out, "catalog: {}", catalog.source)?;
    writeln!(
        out,
        "  stars: {} (Hp {:.2} to {:.2}), positions at J1991.25, propagated to epoch {}",
        catalog.stars.len(),
        catalog.stars.iter().map(|s| s.mag).fold(f64::MAX, f64::min),
        catalog.faintest(),
        o.epoch
    )?;
    if c.camera.is_none() && c.fov_deg.is_none() {
        writeln!(
            out,
            "(give --camera FILE, or --fov-deg DEG --size WxH, to see the distance table)"
        )?;
        return print_all(&out);
    }
    let (source, camera_mag, scale_range) = camera_source(c, false)?;
    let camera = match source {
        CameraSource::Fixed(cam) => cam,
        CameraSource::None => bail!("give the camera: --camera FILE or --fov-deg DEG"),
        CameraSource::Fov(fov) => {
            let (w, h) = size.context("--fov-deg needs --size WIDTHxHEIGHT here")?;
            Camera::from_fov(w, h, fov)?
        }
    };
    let s = Settings {
        scale_range,
        ..settings(o, camera_mag)
    };
    writeln!(
        out,
        "camera: {}x{} px, FOV {:.4} x {:.4} deg, diagonal {:.4} deg, {:.2} arcsec/px",
        camera.width,
        camera.height,
        camera.fov_x_deg(),
        camera.fov_y_deg(),
        camera.diagonal_rad().to_degrees(),
        camera.ifov_rad().to_degrees() * 3600.0
    )?;
    // What a run with these options votes with: the solver's own selections and tables.
    let solver = Solver::new(&catalog, camera.clone(), s)?;
    for (k, band) in solver.bands.iter().enumerate() {
        if Some(k) == solver.shallow_band {
            writeln!(
                out,
                "shallow pass (frames that show few stars): {} stars in view on average",
                crate::solve::SHALLOW_STARS_IN_VIEW
            )?;
        } else if scale_range.is_some() {
            writeln!(
                out,
                "scale band: FOV {:.4} to {:.4} deg ({} scales tried)",
                scaled(&camera, band.hi).fov_x_deg(),
                scaled(&camera, band.lo).fov_x_deg(),
                solver
                    .passes
                    .iter()
                    .filter(|p| p.band == k && p.kind == PassKind::First)
                    .count()
            )?;
        }
        let (refs, t, origin) = (&band.refs, &band.table, &band.table_origin);
        writeln!(
            out,
            "reference stars: {} with Hp <= {}{}; double stars ({:?}, < {} px): {} removed",
            refs.len(),
            refs.selection.mag_limit,
            if s.mag_limit.is_none() {
                " (chosen from the FOV)"
            } else {
                ""
            },
            s.double_stars,
            s.double_star_px,
            refs.doubles_removed
        )?;
        writeln!(
            out,
            "distance table: {} rows, {} bytes (keys + pairs + k-vector of {} bins), pairs closer than {:.4} deg",
            t.len(),
            t.bytes(),
            t.kvector.len() - 1,
            t.max_sep_rad.to_degrees()
        )?;
        writeln!(
            out,
            "  {} in {:.1} ms{}",
            if origin.built {
                "built"
            } else {
                "read from cache"
            },
            origin.seconds * 1e3,
            origin
                .cache_file
                .as_ref()
                .map(|f| format!("; cache {}", f.display()))
                .unwrap_or_default()
        )?;
        if let Some(n) = &origin.cache_note {
            writeln!(out, "  note: {n}")?;
        }
        // What `--method radial` would keep besides: built here from the table.
        let t0 = std::time::Instant::now();
        let middle = scaled(&camera, 0.5 * (band.lo + band.hi));
        let radial = crate::solve::radial::RadialTable::build(
            refs,
            t,
            s.identify.pair_tol_px * middle.ifov_rad(),
            s.identify.scale_tol,
        );
        writeln!(
            out,
            "radial features (--method radial): {} bytes ({} rings of {:.2} arcsec to {:.4} deg), built in {:.1} ms",
            radial.bytes(),
            crate::solve::radial::BITS,
            radial.ring_rad.to_degrees() * 3600.0,
            radial.radius_rad.to_degrees(),
            t0.elapsed().as_secs_f64() * 1e3
        )?;
    }
    print_all(&out)
}

/// Print `text` to stdout; a reader that stops early (`| head`) is not an error.
fn print_all(text: &str) -> Result<ExitCode> {
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(ExitCode::SUCCESS),
    }
}

fn simulate_cmd(a: SimulateArgs) -> Result<ExitCode> {
    let catalog = Catalog::load(a.catalog.as_deref())?;
    let s = SimSettings {
        width: a.size.0,
        height: a.size.1,
        fov_x_deg: a.fov_deg,
        mag_limit: a.mag_limit,
        frames: a.frames,
        seed: a.seed,
        epoch: a.epoch,
        psf_sigma_px: a.psf_sigma,
        sky_e: a.sky,
        read_noise_e: a.read_noise,
        vignetting: a.vignetting,
        bits: a.bits,
        false_stars: a.false_stars,
        hot_pixels: a.hot_pixels,
        centroid_noise_px: a.centroid_noise_px,
        camera: match &a.camera {
            Some(p) => Some(Camera::from_toml_file(p)?.0),
            None => None,
        },
        ..SimSettings::default()
    };
    let t0 = Instant::now();
    if a.streaks {
        let start = crate::sky::Utc::parse(&a.start_utc)
            .map_err(|e| anyhow::anyhow!("--start-utc: {e}"))?;
        let st = crate::streaks::simulate::StreakSim {
            start,
            cadence_s: 60.0,
            exposure_s: a.exposure,
            station: a.station,
            snr: a.streak_snr,
            length_px: (40.0, 1.5 * f64::from(a.size.0.max(a.size.1))),
        };
        // The stars where they are on the frames' date.
        let s = SimSettings {
            bits: 16,
            epoch: crate::io::fits::julian_year(&a.start_utc).unwrap_or(a.epoch),
            ..s
        };
        crate::streaks::simulate::write_set(&catalog, &s, &st, &a.out)?;
        eprintln!(
            "gpustar: wrote {} FITS frames with streaks, truth.jsonl and camera.toml to {} in {:.1} s",
            a.frames,
            a.out.display(),
            t0.elapsed().as_secs_f64()
        );
        return Ok(ExitCode::SUCCESS);
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    if a.sequence {
        let q = crate::sequence::simulate::SequenceSim {
            sequences: a.sequences,
            frames: a.frames,
            interval_s: a.frame_interval,
            rate_deg_s: a.turn_rate,
            particle_ratio: a.particle_ratio,
            particle_speed_arcmin_s: a.particle_speed,
            particle_mag: a.particle_mag,
            start: crate::sky::Utc::parse(&a.start_utc)
                .map_err(|e| anyhow::anyhow!("--start-utc: {e}"))?,
            ..Default::default()
        };
        let s = SimSettings {
            epoch: crate::io::fits::julian_year(&a.start_utc).unwrap_or(a.epoch),
            ..s
        };
        crate::sequence::simulate::write_set(&catalog, &s, &q, &a.out, threads)?;
        eprintln!(
            "gpustar: wrote {} sequences of {} FITS frames, truth.jsonl and camera.toml to {} \
             in {:.1} s",
            a.sequences,
            a.frames,
            a.out.display(),
            t0.elapsed().as_secs_f64()
        );
        return Ok(ExitCode::SUCCESS);
    }
    simulate::write_set(&catalog, &s, &a.out, threads, |_| {})?;
    eprintln!(
        "gpustar: wrote {} frames, truth.jsonl and camera.toml to {} in {:.1} s",
        a.frames,
        a.out.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(ExitCode::SUCCESS)
}

/// The largest 1σ (pixels) of a fitted principal point that calibration keeps.
const CALIBRATE_CENTRE_SD_PX: f64 = 1.0;

/// `gpustar calibrate`: solve DIR, fit the camera to every solved frame's identified stars,
/// re-identify with the fitted camera and fit again, then write the camera file.
fn calibrate_cmd(
    dir: &Path,
    camera_path: &Path,
    fov_tolerance: Option<f64>,
    recursive: bool,
    opts: crate::calibrate::FitOptions,
    out: &Path,
    c: &CatalogOpts,
) -> Result<ExitCode> {
    use crate::calibrate::{self, FrameStars, Star};
    let inputs: Vec<(PathBuf, String)> = inputs::list(dir, recursive)?
        .into_iter()
        .map(|i| (i.path, i.name))
        .collect();
    if inputs.is_empty() {
        bail!("{}: no image files to calibrate with", dir.display());
    }
    let (start, camera_mag) = Camera::from_toml_file(camera_path)?;
    let catalog = Catalog::load(c.catalog.as_deref())?;
    let solve = |camera: &Camera, search: bool| -> Result<Vec<Record>> {
        let mut s = settings(c, camera_mag);
        if search && let Some(t) = fov_tolerance {
            if !(t > 0.0 && t < 0.5) {
                bail!("--fov-tolerance must be between 0 and 0.5");
            }
            s.scale_range = Some((1.0 - t, 1.0 + t));
        }
        let mut p = Pipeline::new(
            catalog.clone(),
            s,
            CameraSource::Fixed(camera.clone()),
            Backend::Cpu,
        );
        Ok(p.process_batch(&inputs))
    };
    let stars_of = |records: &[Record]| -> Vec<FrameStars> {
        records
            .iter()
            .filter_map(|r| {
                let m = r.rotation_matrix?;
                let stars = r
                    .matches
                    .as_ref()?
                    .iter()
                    .map(|m| Star {
                        x: m.x,
                        y: m.y,
                        v: crate::catalog::radec_to_vector(m.ra_deg, m.dec_deg),
                    })
                    .collect();
                Some(FrameStars {
                    name: r.file.clone(),
                    r: nalgebra::Matrix3::from_fn(|i, j| m[i][j]),
                    stars,
                })
            })
            .collect()
    };
    let summary = |what: &str, records: &[Record]| {
        let solved: Vec<&Record> = records
            .iter()
            .filter(|r| r.status == crate::record::Status::Solved)
            .collect();
        let mut rmse: Vec<f64> = solved.iter().filter_map(|r| r.rmse_arcsec).collect();
        rmse.sort_by(f64::total_cmp);
        let stars: usize = solved.iter().filter_map(|r| r.stars_matched).sum();
        eprintln!(
            "gpustar: {what}: {} of {} frames solved, {stars} stars identified, median rmse {}",
            solved.len(),
            records.len(),
            rmse.get(rmse.len() / 2)
                .map_or("-".to_string(), |v| format!("{v:.2}\"")),
        );
    };
    let before = solve(&start, true)?;
    summary("with the camera given", &before);
    // k2 only where the field is wide enough to tell it from k1 (r⁴ at the corner ≥ 1 % of
    // r²'s reach: a half-diagonal of about 18°); the principal point only where the frames
    // fix it to a pixel (a narrow field trades it for the attitudes).
    let corner = (start.diagonal_rad() / 2.0).tan().powi(2);
    let mut opts = calibrate::FitOptions {
        fit_k2: opts.fit_k2 && corner >= 0.1,
        ..opts
    };
    let mut first = calibrate::fit(&start, &stars_of(&before), &opts)?;
    let centre_sd = first
        .fitted
        .iter()
        .zip(&first.sigmas)
        .filter(|(n, _)| **n == "cx" || **n == "cy")
        .map(|(_, sd)| *sd)
        .fold(0.0, f64::max);
    if centre_sd > CALIBRATE_CENTRE_SD_PX {
        eprintln!(
            "gpustar: the principal point is only known to {centre_sd:.1} px from these frames: \
             kept where the camera file puts it"
        );
        opts.fit_principal_point = false;
        first = calibrate::fit(&start, &stars_of(&before), &opts)?;
    }
    // Edge stars a rough camera missed come in with the fitted one: fit again.
    let again = solve(&first.camera, false)?;
    let fit = calibrate::fit(&first.camera, &stars_of(&again), &opts)?;
    let after = solve(&fit.camera, false)?;
    summary("with the fitted camera", &after);
    for (name, (v, sd)) in fit.fitted.iter().zip(
        fit.fitted
            .iter()
            .map(|n| match *n {
                "fx" => fit.camera.fx,
                "fy" => fit.camera.fy,
                "cx" => fit.camera.cx,
                "cy" => fit.camera.cy,
                "k1" => fit.camera.k1,
                _ => fit.camera.k2,
            })
            .zip(&fit.sigmas),
    ) {
        eprintln!("  {name} = {v:.6} ± {sd:.2e}");
    }
    eprintln!(
        "  pixel residuals rms: {:.3} px with the camera given (its frames' stars, each \
         frame's attitude fitted alone), {:.3} px fitted; {} stars used, {} rejected, {} frames",
        first.rms_before_px,
        fit.rms_after_px,
        fit.stars_used,
        fit.stars_rejected,
        fit.rotations.len()
    );
    let k = &fit.camera;
    let mut text = format!(
        "# written by gpustar calibrate from {} solved frames of {} ({} stars; rms {:.3} px)\n\
         width = {}\nheight = {}\nfx_px = {}\nfy_px = {}\ncx_px = {}\ncy_px = {}\nk1 = {}\n\
         k2 = {}\nmirrored = {}\n",
        fit.rotations.len(),
        dir.display(),
        fit.stars_used,
        fit.rms_after_px,
        k.width,
        k.height,
        k.fx,
        k.fy,
        k.cx,
        k.cy,
        k.k1,
        k.k2,
        k.mirrored
    );
    if let Some(m) = camera_mag {
        text.push_str(&format!("mag_limit = {m}\n"));
    }
    std::fs::write(out, text).with_context(|| format!("cannot write {}", out.display()))?;
    eprintln!("gpustar: wrote {}", out.display());
    Ok(ExitCode::SUCCESS)
}

/// Used by tests and `main`: parse arguments and run.
pub fn main_with_args<I, T>(args: I) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
        }
    };
    match execute(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("gpustar: error: {e:#}");
            ExitCode::from(2)
        }
    }
}
